"""
Inverse dynamics of a spatial linkage: shaking wrench, driving torque, bearing reactions.

Reactions: the force and moment on each joint's link b from its link a, about the joint
point, frame axes.  The derivation: docs/core.md#spatial-inverse-dynamics.
"""

from dataclasses import dataclass

from mech_balance.core.spatial.vectors import component_major, cross_c as _cross_c
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
    """Per linkage: the incidence matrix and index arrays of the bearing reactions (once)."""

    mix: np.ndarray       # (nj, nb + 2 q): joint wrenches from [Phi, W_b, W_a] (q wrenches)
    body: np.ndarray      # (nj,) each joint's link b
    point: np.ndarray     # (nj, 3) its joint point in b's axes
    spin_rows: np.ndarray  # the rows of the idle-spin convention

    def __post_init__(self):
        """Keep the points component-major too, ``(3, nj, 1)``."""
        self.point_c = np.ascontiguousarray(self.point.T)[:, :, None]


def _reaction_constants(lk):
    """Return the :class:`_ReactionConstants` of a linkage (cached while its rows stand)."""
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
    # on the row wrenches of Linkage.row_wrenches (a point's three rows as one): their columns
    rep = lk.wrench_rows
    inc_b, inc_a, cut_rows = inc_b[:, rep], inc_a[:, rep], cut_rows[:, rep]
    tree = np.concatenate([below, -below @ inc_b, -below @ inc_a], 1)
    cuts = np.concatenate([np.zeros((len(lk.cut_joints), lk.nb)), cut_rows,
                           np.zeros((len(lk.cut_joints), rep.size))], 1)
    stacked = np.concatenate([tree, cuts], 0)
    where = {t.joint: (i, -1.0 if t.flipped else 1.0) for i, t in enumerate(lk.tree)}
    where.update({ji: (len(lk.tree) + i, 1.0) for i, ji in enumerate(lk.cut_joints)})
    order = [where[i][0] for i in range(len(sc.joints))]
    sign = np.array([where[i][1] for i in range(len(sc.joints))])
    idx = {name: i for i, name in enumerate(lk.body_names)}
    out = _ReactionConstants(
        np.ascontiguousarray(stacked[order] * sign[:, None]),
        np.array([idx[jt.link_b] for jt in sc.joints], dtype=int),
        np.array([lk._points[jt.link_b][jt.point_b] for jt in sc.joints]).reshape(-1, 3),
        np.array([i for i, j in enumerate(lk.row_joint) if j.startswith('spin:')], dtype=int))
    lk._reaction_constants = (m, out)
    return out


def body_motion(state, inertia):
    """Return ``(x_c, v_c, a_c, omega, I_w omega, I_w alpha)`` ``(3, nb - 1, n)`` (cached)."""
    cached = getattr(state, '_motion', None)
    if cached is not None and cached[0] is inertia:
        return cached[1]
    out = _body_motion(state, inertia)
    state._motion = (inertia, out)
    return out


def _body_constants(inertia):
    """Return the component-major mass centres, masses and inertia of the moving bodies."""
    cached = getattr(inertia, '_component_major', None)
    if cached is None:
        cached = (np.ascontiguousarray(inertia.com[1:].T)[:, :, None],
                  inertia.mass[1:, None].copy(),
                  np.ascontiguousarray(inertia.inertia[1:].transpose(1, 2, 0))[:, :, :, None])
        inertia._component_major = cached
    return cached


def _body_motion(state, inertia):
    ac = state.accel
    com, _, inl = _body_constants(inertia)
    rot, org, t = state.component_major()
    rot = rot[:, :, 1:]                            # (3, 3, b, n): the moving bodies
    t = t[:, 1:]                                   # (6, b, n)
    # matrix-vector products as one broadcast product and one sum each (few numpy calls)
    xc = org[:, 1:] + (rot * com).sum(1)
    w = t[:3]
    vc = t[3:] + _cross_c(w, xc)
    if ac is None:  # kinematics only (kinetic energy)
        x = w[:, None]
        a_c = None
    else:
        a = component_major(ac)[:, 1:]            # a view when ac is one already
        al = a[:3]
        a_c = a[3:] + _cross_c(al, xc)
        a_c += _cross_c(w, vc)
        x = np.stack([w, al], 1)                   # (3, 2, b, n): both in one pass
    rot = rot[:, :, None]                          # (3, 3, 1, b, n)
    loc = (rot * x[:, None]).sum(0)                # R^T x
    hl = (inl[:, :, None] * loc).sum(1)            # I R^T x
    hw = (rot * hl).sum(1)                         # R I R^T x
    if ac is None:
        return xc, vc, None, w, hw[:, 0], None
    return xc, vc, a_c, w, hw[:, 0], hw[:, 1]


def _momentum_rates_c(state, inertia):
    """Return ``Phi`` component-major ``(6, nb, n)`` (N about the origin, F; frame: 0)."""
    cached = getattr(state, '_phi_c', None)
    if cached is not None and cached[0] is inertia:
        return cached[1]
    xc, _, a_c, w, h, i_al = body_motion(state, inertia)
    _, mass, _ = _body_constants(inertia)
    phi = np.empty((6,) + state.frames.origin.shape[1::-1])
    phi[:, 0] = 0.0
    f = phi[3:, 1:]
    np.multiply(mass, a_c, out=f)
    dh = phi[:3, 1:]
    np.add(i_al, _cross_c(w, h), out=dh)
    dh += _cross_c(xc, f)
    state._phi_c = (inertia, phi)
    return phi


def momentum_rates(state, inertia):
    """Return ``Phi`` ``(n, nb, 6)`` = (N about the origin, F) of every body (frame: 0)."""
    return np.ascontiguousarray(_momentum_rates_c(state, inertia).T)


def kinetic_energy(state, inertia):
    """Return T = sum (m |v_c|^2 + omega . I_w omega) / 2, ``(n,)`` J."""
    _, vc, _, w, h, _ = body_motion(state, inertia)
    _, mass, _ = _body_constants(inertia)
    return 0.5 * (((vc * vc).sum(0) * mass).sum(0) + (w * h).sum(0).sum(0))


def inverse_dynamics(linkage, state, inertia, moment_point, need):
    """Return the :class:`SpatialWrenches` the outputs in ``need`` require."""
    phi = _momentum_rates_c(state, inertia)         # (6, nb, n)
    total = phi.sum(axis=1)                          # (6, n)
    p = np.asarray(moment_point, dtype=float)
    force = -total[3:].T
    moment = -(total[:3] - _cross_c(p[:, None], total[3:])).T
    out = SpatialWrenches(force, moment)
    if 'driving_torque' not in need:
        return out
    lk = linkage
    # generalized forces: the rates of momentum of the bodies below each coordinate
    q_gen = (np.matmul(lk.path, phi) * state.frames.cols_c).sum(0).T    # (n, ndof)
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
    c = _reaction_constants(lk)
    spin = c.spin_rows
    if spin.size:
        out.spin_moment = lam[:, spin]
    if 'bearing_reactions' not in need:
        return out
    wb, wa = lk.row_wrenches(state.frames, lam)
    # [Phi, W_b, W_a]: every joint's wrench in one product
    w = np.matmul(c.mix, np.concatenate([phi, wb, wa], axis=1))    # (6, nj, n)
    rot, org, _ = state.component_major()
    body = c.body
    x = org[:, body] + (rot[:, :, body] * c.point_c).sum(1)     # joint points (3, nj, n)
    force = w[3:]
    moment = w[:3] - _cross_c(x, force)
    force, moment = np.ascontiguousarray(force.T), np.ascontiguousarray(moment.T)  # (n, nj, 3)
    res = {jt.name: (force[:, i], moment[:, i]) for i, jt in enumerate(lk.scene.joints)}
    out.reactions = res
    return out
