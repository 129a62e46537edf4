"""
Inverse dynamics of a spatial linkage: shaking wrench, driving torque, bearing reactions.

Per moving body k (frame axes, SI): mass centre ``x_c = p + R c``, its acceleration
``a_c`` (point acceleration of :meth:`Linkage.bias`), world inertia ``I_w = R I R^T`` and
the rate of angular momentum ``dH_c/dt = I_w alpha + omega x I_w omega``.  The rate of
momentum as a wrench about the frame origin, ``Phi_k = (N_k, F_k)`` with ``F_k = m a_c`` and
``N_k = dH_c/dt + x_c x F_k``, is what the joints must apply to the body (no gravity: the
conventions consider inertia effects only).

Shaking wrench (:mod:`mech_balance.conventions`): ``f = -sum F_k = -dp/dt`` and
``n_P = -sum (N_k - P x F_k) = -dH_P/dt`` about the scene's moment point P, the motor's
reaction included.

Driving torque and reactions (virtual power in tree coordinates)
    ``Q_d = sum over the bodies below coordinate d of Phi_k . S_d`` must equal ``tau_d + (J^T
    lambda)_d``: tau only on the crank, lambda the closure rows' multipliers.  The unknown
    coordinates give ``J_u^T lambda = Q_u`` (square: the unique solution; redundant rows:
    the minimum-norm one, reactions *not unique*), the crank ``tau = Q_0 - J_0^T lambda``.
    Row r exerts the wrench ``lambda_r G_b(r)`` on its body b (and ``lambda_r G_a(r)`` on a);
    a tree joint carries the sum of ``Phi_k`` minus the cut-joint wrenches over the bodies
    below it.  Reactions are reported as the force and moment on the joint's link b from its
    link a, the moment about the joint point, frame axes; the crank joint's moment includes
    the driving torque about its axis.
"""

from dataclasses import dataclass

from mech_balance.core.spatial.kinematics import cross, mv
import numpy as np


@dataclass
class Inertia:
    """The links' inertia (bodies 1.. of the linkage; local axes)."""

    mass: np.ndarray       # (nb,)  (frame: 0)
    com: np.ndarray        # (nb, 3)
    inertia: np.ndarray    # (nb, 3, 3) about the mass centre

    @classmethod
    def from_scene(cls, scene):
        """Return the inertia of a spatial scene's links (the frame first, all zero)."""
        links = scene.links
        mass = np.array([0.0] + [lk.mass_kg for lk in links])
        com = np.array([(0.0, 0.0, 0.0)] + [lk.com_m for lk in links], dtype=float)
        inertia = np.array([np.zeros((3, 3))] + [np.array(lk.inertia_matrix())
                                                 for lk in links])
        return cls(mass, com, inertia)


@dataclass
class SpatialWrenches:
    """The inverse dynamics over n samples (SI, frame axes)."""

    force_N: np.ndarray
    moment_Nm: np.ndarray
    driving_torque: np.ndarray = None
    multipliers: np.ndarray = None
    reactions: dict = None
    reactions_unique: bool = True
    spin_moment: np.ndarray = None


@dataclass
class _ReactionConstants:
    """Per linkage: the index and incidence arrays of the bearing reactions (built once)."""

    inc_b: np.ndarray     # (nb, m): row r acts on body row_b[r]
    inc_a: np.ndarray
    below: np.ndarray     # (nt, nb): the bodies below each tree joint
    cut_rows: np.ndarray  # (nc, m): the rows of each cut joint
    order: np.ndarray     # scene joint i -> its index in [tree..., cuts...]
    sign: np.ndarray      # -1 for a flipped tree joint
    body: np.ndarray      # (nj,) each joint's link b
    point: np.ndarray     # (nj, 3) its joint point in b's axes


def _reaction_constants(lk):
    cached = getattr(lk, '_reaction_constants', None)
    if cached is not None and cached[0] == lk.m:
        return cached[1]
    sc = lk.scene
    m = lk.m
    inc_b, inc_a = np.zeros((lk.nb, m)), np.zeros((lk.nb, m))
    inc_b[lk.row_b, np.arange(m)] = 1.0
    inc_a[lk.row_a, np.arange(m)] = 1.0
    below = np.array([lk.path[t.dofs[0]] for t in lk.tree]).reshape(len(lk.tree), lk.nb)
    cut_rows = np.zeros((len(lk.cut_joints), m))
    for i, ji in enumerate(lk.cut_joints):
        cut_rows[i] = [j == sc.joints[ji].name for j in lk.row_joint]
    where = {t.joint: (i, -1.0 if t.flipped else 1.0) for i, t in enumerate(lk.tree)}
    where.update({ji: (len(lk.tree) + i, 1.0) for i, ji in enumerate(lk.cut_joints)})
    idx = {name: i for i, name in enumerate(lk.body_names)}
    out = _ReactionConstants(
        inc_b, inc_a, below, cut_rows,
        np.array([where[i][0] for i in range(len(sc.joints))], dtype=int),
        np.array([where[i][1] for i in range(len(sc.joints))]),
        np.array([idx[jt.link_b] for jt in sc.joints], dtype=int),
        np.array([lk._points[jt.link_b][jt.point_b] for jt in sc.joints]).reshape(-1, 3))
    lk._reaction_constants = (m, out)
    return out


def body_motion(state, inertia):
    """
    Return ``(x_c, v_c, a_c, I_w, omega, alpha, I_w omega, I_w alpha)`` (cached).

    Of the moving bodies only (bodies 1..; the frame is at rest), batch-first ``(n, nb - 1,
    ...)``; ``a_c``, ``alpha`` and ``I_w alpha`` are None without accelerations.
    """
    cached = getattr(state, '_motion', None)
    if cached is not None and cached[0] is inertia:
        return cached[1]
    out = _body_motion(state, inertia)
    state._motion = (inertia, out)
    return out


def _body_motion(state, inertia):
    fr, tw, ac = state.frames, state.twist, state.accel
    rot = fr.rot[:, 1:]
    xc = fr.origin[:, 1:] + mv(rot, inertia.com[1:])
    w = tw[:, 1:, :3]
    vc = tw[:, 1:, 3:] + cross(w, xc)
    # R I R^T; numpy's matmul is several times slower on a transposed view: copy R^T first
    iw = np.matmul(rot, inertia.inertia[1:]) @ np.ascontiguousarray(np.swapaxes(rot, -1, -2))
    if ac is None:  # kinematics only (kinetic energy)
        return xc, vc, None, iw, w, None, mv(iw, w), None
    al = ac[:, 1:, :3]
    a_c = ac[:, 1:, 3:] + cross(al, xc)
    a_c += cross(w, vc)
    both = np.matmul(iw, np.stack([w, al], -1))   # I_w omega and I_w alpha in one product
    return xc, vc, a_c, iw, w, al, both[..., 0], both[..., 1]


def momentum_rates(state, inertia):
    """Return ``Phi`` ``(n, nb, 6)`` = (N about the origin, F) of every body (frame: 0)."""
    xc, _, a_c, _, w, _, h, i_al = body_motion(state, inertia)
    n, nb = state.frames.origin.shape[:2]
    phi = np.zeros((n, nb, 6))
    f = phi[:, 1:, 3:]
    np.multiply(inertia.mass[1:, None], a_c, out=f)
    dh = i_al + cross(w, h)
    dh += cross(xc, f)
    phi[:, 1:, :3] = dh
    return phi


def kinetic_energy(state, inertia):
    """Return T = sum (m |v_c|^2 + omega . I_w omega) / 2, ``(n,)`` J."""
    _, vc, _, _, w, _, h, _ = body_motion(state, inertia)
    return 0.5 * (np.einsum('nbi,nbi,b->n', vc, vc, inertia.mass[1:])
                  + np.einsum('nbi,nbi->n', w, h))


def inverse_dynamics(linkage, state, inertia, moment_point, need):
    """Return the :class:`SpatialWrenches` the outputs in ``need`` require."""
    phi = momentum_rates(state, inertia)
    total = phi.sum(axis=1)
    p = np.asarray(moment_point, dtype=float)
    force = -total[:, 3:]
    moment = -(total[:, :3] - cross(p, total[:, 3:]))
    out = SpatialWrenches(force, moment)
    if 'driving_torque' not in need:
        return out
    lk = linkage
    q_gen = (np.matmul(lk.path, phi) * state.frames.cols).sum(-1)
    jac = state.jac
    n = state.size
    if lk.nu:
        rhs = q_gen[:, lk.unknown] * lk.col_scale[lk.unknown]
        lam = lk.solve_ut(state.solver, state.refine, rhs) * lk.row_scale
    else:
        lam = np.zeros((n, lk.m))
    out.multipliers = lam
    out.driving_torque = q_gen[:, 0] - np.einsum('nm,nm->n', jac[:, :, 0], lam)
    out.reactions_unique = lk.redundant == 0
    if 'bearing_reactions' not in need and not lk.m:
        return out
    gb, ga = lk.gradients(state.frames)
    wb, wa = gb * lam[:, :, None], ga * lam[:, :, None]
    spin = [i for i, j in enumerate(lk.row_joint) if j.startswith('spin:')]
    if spin:
        out.spin_moment = lam[:, spin]
    if 'bearing_reactions' not in need:
        return out
    c = _reaction_constants(lk)
    on_body = np.matmul(c.inc_b, wb) + np.matmul(c.inc_a, wa)   # the rows' wrenches per body
    # tree joints: the bodies below minus the cut-joint wrenches on them; cut joints: on b
    w = np.concatenate([np.matmul(c.below, phi - on_body), np.matmul(c.cut_rows, wb)], 1)
    w = w[:, c.order] * c.sign[:, None]
    fr = state.frames
    x = fr.origin[:, c.body] + mv(fr.rot[:, c.body], c.point)   # joint points (n, nj, 3)
    force = w[..., 3:]
    moment = w[..., :3] - cross(x, force)
    res = {jt.name: (force[:, i], moment[:, i]) for i, jt in enumerate(lk.scene.joints)}
    out.reactions = res
    return out
