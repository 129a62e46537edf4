"""
Inverse dynamics of a planar linkage: driving torque, bearing reactions, shaking wrench.

Newton-Euler per link about its origin (seed 001 eqs. 23-26), the driving torque by the
natural orthogonal complement (seed 000 eq. 37), the reactions from the leaves to the frame
(seed 001 eqs. 32-38); the equations: docs/core.md#module-overviews.
"""

from dataclasses import dataclass

from mech_balance.core.linalg import matvec_t as _matvec_t
from mech_balance.core.planar.algebra import cross as _cross, dot as _dot, \
    max_reduce as _MAX, rmat as _rmat, Tiles as _Tiles
import numpy as np

SPEED_FLOOR_RAD_S = 1e-300
"""Crank speeds at or below this magnitude take the torque path that does not divide by it."""
PARAMS_PER_LINK = 4
"""Inertial parameters per link: m, m*c_x, m*c_y (link frame), I about the link origin."""
_INERTIA_DTYPE = {'mass': float, 'first_moment': complex, 'inertia_origin': float}


@dataclass
class Inertia:
    """Inertial parameters of every body (row 0: the frame, all zeros), SI."""

    mass: np.ndarray            # (nb,) kg
    first_moment: np.ndarray    # (nb,) complex, m*c in the link frame, kg*m
    inertia_origin: np.ndarray  # (nb,) kg*m^2 about the link origin

    def __setattr__(self, name, value):
        """Store the fields as read-only float (``first_moment``: complex) copies."""
        if name in _INERTIA_DTYPE:
            value = np.array(value, dtype=_INERTIA_DTYPE[name])
            value.setflags(write=False)     # changed by replacing, never in place: the
        object.__setattr__(self, name, value)   # tiles below stay those of the fields

    def tiles(self, p):
        """Return the columns ``h``, ``m`` (complex) and ``I_O`` as ``(nb, p)`` :class:`Tiles`."""
        m, h, i_o = self.mass, self.first_moment, self.inertia_origin
        cached = self.__dict__.get('_tiles')
        if cached is None or not (cached[0] is m and cached[1] is h and cached[2] is i_o):
            cached = (m, h, i_o, _Tiles(h=h[:, None], m=m.astype(complex)[:, None],
                                        i_o=i_o[:, None]))
            self.__dict__['_tiles'] = cached
        return cached[3].at(p)

    @classmethod
    def from_links(cls, links):
        """Build from scene links (frame row prepended)."""
        m = np.array([0.0] + [lk.mass_kg for lk in links])
        h = np.array([0j] + [complex(*lk.first_moment_kg_m) for lk in links])
        i_o = np.array([0.0] + [lk.inertia_origin_kg_m2 for lk in links])
        return cls(m, h, i_o)


def parameter_vector(inertia):
    """Return the ``(4 n,)`` vector [m, hx, hy, I_O] per moving link."""
    return np.column_stack([inertia.mass[1:], inertia.first_moment[1:].real,
                            inertia.first_moment[1:].imag, inertia.inertia_origin[1:]]).ravel()


def inertia_from_vector(theta):
    """Return the :class:`Inertia` of a ``(4 n,)`` parameter vector."""
    theta = np.asarray(theta, dtype=float).reshape(-1, PARAMS_PER_LINK)
    return Inertia(np.concatenate([[0.0], theta[:, 0]]),
                   np.concatenate([[0j], theta[:, 1] + 1j * theta[:, 2]]),
                   np.concatenate([[0.0], theta[:, 3]]))


@dataclass
class Wrenches:
    """Inertia wrenches of every body about its origin, and what follows from them."""

    f_star: np.ndarray        # (nb, p) complex, N
    n_star: np.ndarray        # (nb, p) N*m about the link origin
    shaking_force: np.ndarray  # (p,) complex, N
    shaking_moment: np.ndarray  # (p,) N*m about the crank pivot
    driving_torque: np.ndarray = None  # (p,) N*m on the crank
    reaction_force: dict = None   # joint name -> (p,) complex force on link b from link a, N
    reaction_moment: dict = None  # joint name -> (p,) moment on link b from link a, N*m
    reaction_point: dict = None   # joint name -> (p,) complex point the moment is taken about
    multipliers: np.ndarray = None  # (m, p) cut-joint Lagrange multipliers
    consistency: float = None       # max |revolute joint moment| + |tau_recursion - tau|, N*m


def inverse_dynamics(linkage, state, inertia, gravity=0j, need=('shaking_wrench',)):
    """Return the :class:`Wrenches` of a solved state (only what ``need`` asks for)."""
    pose = state.pose
    omega, alpha, acc = state.omega, state.alpha, state.acc
    tiles = inertia.tiles(omega.shape[1])
    world_h = pose.rot * tiles['h']
    # seed 001 eq. 26: f* = m a + (i alpha - omega^2) R h,  n* = I_O alpha + cross(R h, a)
    # (as m a - (omega^2 - i alpha) R h: no negation of its own)
    spin = np.empty(world_h.shape, dtype=complex)
    np.multiply(omega, omega, out=spin.real)
    np.negative(alpha, out=spin.imag)
    spin *= world_h
    f_star = tiles['m'] * acc
    f_star -= spin
    n_star = _cross(world_h, acc)
    n_star += tiles['i_o'] * alpha
    arm = pose.origin - linkage.pivot if linkage.pivot else pose.origin   # (read only)
    m_net = _cross(arm, f_star)                # inertia moments about the crank pivot
    m_net += n_star
    # seed 001 eq. 39: the reaction of the resultant inertia wrench, about the crank pivot
    # (minus the column sums as one product with -1s each: a third quicker than a reduction
    # and a negation)
    minus = linkage.minus_ones
    shaking_force = np.dot(minus, f_star.view(np.float64)).view(np.complex128)
    shaking_moment = np.dot(minus, m_net)
    out = Wrenches(f_star, n_star, shaking_force, shaking_moment)
    gravity = complex(gravity)
    if 'bearing_reactions' in need:
        _reactions(linkage, state, inertia, world_h, arm, gravity, out, m_net)
    elif 'driving_torque' in need and not np.all(np.abs(state.psi_d) > SPEED_FLOOR_RAD_S):
        # at rest the power balance below is 0/0: take the torque from the generalized
        # forces of the tree (the same NOC projection, without dividing by the speed)
        _reactions(linkage, state, inertia, world_h, arm, gravity, out, m_net)
        out.reaction_force = out.reaction_moment = out.reaction_point = None
    elif 'driving_torque' in need:
        # seed 000 eq. 37: tau = u^T (w* - w^E), u = t / psi_dot (power balance per unit speed)
        power = np.sum(omega * n_star + _dot(state.vel, f_star), axis=0)
        if gravity:
            power -= gravity_power(state, inertia, gravity)
        out.driving_torque = power / state.psi_d
    return out


def _reactions(linkage, state, inertia, world_h, arm, gravity, out, m_net):
    """Fill in the driving torque, multipliers and joint reactions (seed 001 eqs. 32-38)."""
    pose = state.pose
    pivot = linkage.pivot
    f_net = out.f_star
    if gravity:
        weight = inertia.mass[:, None] * gravity
        f_net = f_net - weight
        m_net = m_net - _cross(arm, weight) - _cross(world_h, gravity)
    lever = pose.joint_at - pivot if pivot else pose.joint_at
    # generalized forces of the tree coordinates, Q = N^T (w* - w^E) (seed 001 eq. 32)
    if linkage.dense_tree:                                 # (nt, nb): bodies below joint t
        f_sub = _rmat(linkage.below, f_net)                # net force of each subtree
        m_sub = np.dot(linkage.below, m_net)               # and its moment about the pivot
    else:                                                  # the same, level by level
        f_sub = linkage._up(f_net)
        m_sub = linkage._up(m_net)
    q_gen = m_sub - _cross(lever, f_sub)
    if linkage.has_pri:
        q_gen = np.where(linkage.is_prismatic[:, None], _dot(pose.axis, f_sub), q_gen)
    # cut-joint multipliers, seed 001 eqs. 33-38: lambda = J_u^-T Q_u (scaled Jacobian)
    q_u = q_gen[linkage.unknown_rows]
    if linkage.has_pri:
        q_u = q_u * linkage.col_scale[:, None]
    if state.jac_factors is not None:
        lam_scaled = state.jac_factors.solve_t(q_u)
    else:
        lam_scaled = _matvec_t(state.jac_inv, q_u)
    lam = lam_scaled * (linkage.row_scale[:, None] if linkage.npc or linkage.has_pri
                        else linkage.scale0)   # (uniform: one 0-d factor)
    jac_psi = state.jac[:, 0, :] if state.jac_psi is None else state.jac_psi
    tau = q_gen[0] - np.add.reduce(jac_psi * lam_scaled, axis=0)   # (einsum: slower set-up)
    out.driving_torque = tau
    out.multipliers = lam
    nr, npc = linkage.nr, linkage.npc
    pa, pb = linkage.cut_points(pose)
    if npc:
        force = np.empty((nr + npc, state.size), dtype=complex)  # on b from a
        force.real[:nr] = lam[:nr]                        # at the common point
        force.imag[:nr] = lam[nr:2 * nr]
    else:   # (x rows, y rows) interleaved into complex in one copy
        force = np.ascontiguousarray(lam.reshape(2, nr, state.size).transpose(1, 2, 0)).view(
            np.complex128)[:, :, 0]
    cut_moment = np.zeros((nr + npc, state.size))
    if npc:
        ia = linkage.cut_a[nr:]
        mu, nu = lam[2 * nr:2 * nr + npc], lam[2 * nr + npc:]
        force[nr:] = nu * (1j * pose.rot[ia] * linkage.cut_axis)   # along the normal
        cut_moment[nr:] = mu
    m_on_b = _cross(pb - pivot if pivot else pb, force)   # about the pivot
    if npc:
        m_on_a = _cross(pa - pivot, force)
        np.negative(m_on_a, out=m_on_a)
        m_on_b[nr:] += cut_moment[nr:]
        m_on_a[nr:] = -m_on_b[nr:]
    # tree joint t carries what its subtree needs beyond the cut loads on that subtree
    # (all-revolute cuts: the moment of the pair about the pivot with the common point
    # taken on b, the two points agreeing to the loop residual)
    if linkage.dense_tree:
        f_req = f_sub - _rmat(linkage.below_cut, force)
        m_req = m_sub - np.dot(linkage.below_cut_b, m_on_b) \
            - np.dot(linkage.below_cut_a, m_on_a) if npc \
            else m_sub - np.dot(linkage.below_cut, m_on_b)
    else:
        f_req = f_sub - linkage._up_cut(force, force)
        m_req = m_sub - linkage._up_cut(m_on_b, -m_on_a if npc else m_on_b)
    moment = m_req - _cross(lever, f_req)                 # about each tree joint
    # consistency: the crank joint's moment against tau, and the passive revolute joints'
    # moments (zero up to round-off), in one stacked reduction (nan propagates)
    check = moment.take(linkage.check_rows, axis=0)
    check[0] -= tau
    np.abs(check, out=check)
    worst = float(_MAX(check, axis=None, initial=0.0))   # (0.0: an empty batch)
    if linkage.rev_passive.size:
        moment[linkage.rev_passive_rows] = 0.0
    if linkage.tree_flip.size:
        f_req *= linkage.tree_sign_col
        moment *= linkage.tree_sign_col
    # joint order of the scene: (tree row or cut row) of each joint
    rf, rm, rp = {}, {}, {}
    joint_at = pose.joint_at
    for n, tree, i in linkage.joint_rows:
        if tree:
            rf[n], rm[n], rp[n] = f_req[i], moment[i], joint_at[i]
        else:
            rf[n], rm[n], rp[n] = force[i], cut_moment[i], pb[i]
    out.reaction_force, out.reaction_moment, out.reaction_point = rf, rm, rp
    out.consistency = worst


def gravity_power(state, inertia, gravity):
    """Return the power of the links' weights ``(p,)``, W (seed 000 eq. 43)."""
    world_h = state.pose.rot * inertia.first_moment[:, None]
    return np.sum(inertia.mass[:, None] * _dot(state.vel, gravity)
                  + state.omega * _cross(world_h, gravity), axis=0)


def potential_energy(state, inertia, gravity):
    """Return the links' potential energy in the gravity field, ``(p,)`` J: -sum m g . c."""
    world_h = state.pose.rot * inertia.first_moment[:, None]
    return -np.sum(inertia.mass[:, None] * _dot(state.pose.origin, gravity)
                   + _dot(world_h, gravity), axis=0)


def generalized_inertia(state, inertia):
    """Return I(psi) = u^T M u (seed 000 eq. 39) per crank angle, kg*m^2."""
    u_w = state.omega / state.psi_d
    u_v = state.vel / state.psi_d
    world_h = state.pose.rot * inertia.first_moment[:, None]
    return np.sum(inertia.inertia_origin[:, None] * u_w ** 2
                  + inertia.mass[:, None] * np.abs(u_v) ** 2
                  + 2.0 * u_w * _cross(world_h, u_v), axis=0)


def coriolis_term(state, inertia, wrenches):
    """Return C psi_dot = I psi_ddot - u^T w* (seed 000 eq. 39) per crank angle, N*m."""
    u_w = state.omega / state.psi_d
    u_v = state.vel / state.psi_d
    inertial = np.sum(u_w * wrenches.n_star + _dot(u_v, wrenches.f_star), axis=0)
    return generalized_inertia(state, inertia) * state.psi_dd - inertial
