"""
Position, velocity and acceleration of a single-input spatial linkage (``kind: spatial``).

Formulation
    The joint graph is opened into a spanning tree rooted at the frame (breadth first, the
    crank joint first); the other joints are *cut joints*.  The unknowns are the tree
    joints' relative coordinates: revolute (angle), prismatic (slide), cylindrical (angle,
    slide), universal (two angles), spherical (a relative rotation, updated multiplicatively
    ``M <- exp(d^) M`` with ``d`` in the parent's axes).  A tree joint places its child from
    its parent: ``R_c = R_p M(q)``, ``p_c = p_p + R_p (s_p + d(q)) - R_c s_c``.  Each cut
    joint contributes closure rows g = 0: three for a coincident point (R, U, S), two
    *dot* rows per aligned axis (R, C, P: the b-axis normal to two a-vectors), one dot row
    for a universal's crossed axes, two *line* rows (C, P: the b-point on the a-line) and one
    more dot row locking a prismatic joint's turn.  Every row's gradient with respect to a
    body's twist (angular velocity, velocity of the body point at the frame origin) is
    analytic; the Jacobian with respect to the tree coordinates is that gradient applied to
    each coordinate's twist column (its screw) on the bodies below it: one formula gives
    Newton's Jacobian, the velocities and the accelerations (``J q'' = -g''|q''=0``).  Arrays
    are batch-first (one row per crank angle) so that a whole cycle is one numpy pass.

Joint coordinates (zero convention, also the URDF's)
    Revolute and cylindrical angle: ``M = Rot(a, theta) Z`` with ``Z`` the smallest rotation
    taking the b-axis onto the a-axis (0 where the link frames are related by ``Z`` alone);
    prismatic: ``M = Rot(a, angle_deg) Z`` fixed, the slide of b's point from a's along a;
    universal: ``M = Rot(a, theta1) U Rot(b, theta2)`` with ``U`` the smallest rotation taking
    b onto the unit vector of b normal to a; spherical: ``M = Rz(yaw) Ry(pitch) Rx(roll) A``
    with ``A`` the relative rotation at the assembly (the URDF's three revolute joints).

The input and the cycle
    The crank joint is tree coordinate 0.  A revolute input is the crank angle psi itself;
    a prismatic input is its slide ``s(psi)`` (:func:`mech_balance.schema.spatial.stroke_law`,
    the ideal Scotch yoke: ``s_min`` at psi = 0, ``s_max`` at psi = 180 deg), with rates by
    the chain rule, ``s' = ds/dpsi psi'`` and ``s'' = d2s/dpsi2 psi'^2 + ds/dpsi psi''``
    (:meth:`Linkage.input_motion`).  Everything inside the linkage (the branch trace, the
    nodes, the predictor, Newton) works in tree coordinate 0: a revolute input's branch is
    traced over one turn and must close; a prismatic input's over its stroke, from the
    assembly to both ends, refusing a singular position on the way as for a turn, and a
    cycle of psi runs it forth and back.

The assembly
    The tree coordinates are read from the scene's ``assembly.poses``, the loops closed
    from there (Levenberg-Marquardt) and every stated link's solved pose compared with its
    stated one, refused beyond the tolerances (:mod:`.assembly`): the branch analysed is
    always the one the scene states.

Idle freedoms and redundancy
    A link held only by two spherical joints spins freely about the line through them; the
    assembled Jacobian's null space shows it.  Convention (:data:`IDLE_INERTIA_RTOL`): its
    spin is fixed by one more row, ``(R v) . n = 0`` (v normal to the line in the link, n the
    frame axis most normal to the line at assembly; seed 002 eq. 42 takes n = z), which is
    legitimate only if its inertia about that line is zero (a slender rod): otherwise the
    scene is refused, naming the two joints and the way out (replace one S by a U).  More
    rows than independent ones (Bennett's linkage) are solved in the least-squares sense
    with the rank-revealing pseudo-inverse; the reactions are then not unique and the
    minimum-norm ones are reported.
"""

from dataclasses import dataclass
import math
from typing import NamedTuple
import warnings

from mech_balance.conventions import crank_angle_text
from mech_balance.core import continuation, linalg
from mech_balance.core.planar.kinematics import COND_WARN, NEWTON_TOL, PRINTED_RTOL  # noqa
from mech_balance.core.spatial import assembly
from mech_balance.schema.scene import FRAME
from mech_balance.schema.spatial import stroke_law
import numpy as np

NEWTON_MAX_ITER = 10
"""Newton iterations per batched evaluation or continuation step."""
ASSEMBLY_MAX_ITER = 200
"""Levenberg-Marquardt iterations allowed to assemble the linkage from the scene's poses."""
COND_LIMIT = 1e10
"""Scaled Jacobian condition number above which a position is refused as singular."""
RANK_RTOL = 1e-9
"""Singular values below this fraction of the largest count as zero (rank, null space)."""
STEP_MAX_RAD = math.radians(10.0)
"""Largest crank step between branch nodes (a prismatic input: this angle of its Scotch
yoke at mid-stroke, i.e. times the half stroke, m)."""
STEP_MIN_RAD = 1e-7
"""Smallest crank step before the continuation declares the branch lost (prismatic input:
times the half stroke, m)."""
STEP_DONE = 1e-13
"""What is left of a continuation's goal when it counts as reached (rad; a prismatic input:
times the half stroke, m)."""
STEP_TRUST = 0.05
"""Largest scaled Newton correction accepted in a continuation step (else the step halves)."""
EVAL_TRUST = 1e-3
"""Largest scaled correction from the branch predictor before an angle is re-traced."""
CLOSURE_TOL = 1e-7
"""Largest scaled pose mismatch after one traced turn for the branch to count as closed."""
REFINE_STEPS = 1
"""Iterative-refinement steps of a solve with the predictor's inverse (each squares the
relative error, ~1e-8 from a dense node half a degree away, to ~1e-16)."""
DENSE_STEP_RAD = math.radians(1.0)
"""Spacing of the dense branch nodes the batched evaluation predicts from."""
IDLE_INERTIA_RTOL = 1e-9
"""Inertia about an S-S line, relative to m L^2 + trace(I), below which it counts as zero."""
SPIN_ROW_MIN = 1e-3
"""|u x n| below which the spin convention's reference axis n is too close to the S-S line."""
TWO_PI = 2.0 * math.pi


_CONSTANT_ROOT_COLUMNS = ('revolute', 'prismatic', 'spherical', 'universal')
"""Joint types whose twist columns are constant when their parent is the frame."""


class SpatialError(ValueError):
    """The spatial linkage cannot be assembled, is singular, or would leave its branch."""


def component_major(a):
    """Return a batch-first ``(n, nb, k...)`` array as a contiguous ``(k..., nb, n)``."""
    nd = a.ndim
    return np.ascontiguousarray(a.transpose(tuple(range(2, nd)) + (1, 0)))


def cross_c(a, b):
    """Return ``a x b`` of component-major vectors ``(3, ...)`` (broadcast)."""
    out = np.empty(a.shape if np.shape(a) == np.shape(b) else np.broadcast(a, b).shape)
    np.multiply(a[1], b[2], out=out[0])
    out[0] -= a[2] * b[1]
    np.multiply(a[2], b[0], out=out[1])
    out[1] -= a[0] * b[2]
    np.multiply(a[0], b[1], out=out[2])
    out[2] -= a[1] * b[0]
    return out


def _dot_c(a, b):
    """Return the dot products of component-major vectors ``(3, ...)`` (broadcast)."""
    out = a[0] * b[0]
    out += a[1] * b[1]
    out += a[2] * b[2]
    return out


def cross(a, b):
    """Return ``a x b`` over the last axis (broadcast); numpy's cross without its overhead."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    sa = np.shape(a)
    out = np.empty(sa if sa == np.shape(b) else np.broadcast(a, b).shape)
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def mv(mat, vec):
    """Return ``mat @ vec`` over stacks: ``(..., k, k)`` times ``(..., k)`` (broadcast)."""
    vec = np.asarray(vec)
    out = mat[..., 0] * vec[..., None, 0]
    for j in range(1, mat.shape[-1]):
        out += mat[..., j] * vec[..., None, j]
    return out


def dot(a, b):
    """Return the dot products over the last axis (broadcast)."""
    return (a * b).sum(-1)


def skew(v):
    """Return the cross-product matrices ``(..., 3, 3)`` of vectors ``(..., 3)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


EYE3 = np.eye(3)
EYE3.flags.writeable = False


def rot_axis(axis, angle):
    """Return rotations ``(n, 3, 3)`` by ``angle`` ``(n,)`` about the unit ``axis`` (3,)."""
    k = skew(axis)
    k2 = k @ k
    s, c = np.sin(angle), np.cos(angle)
    return EYE3 + s[:, None, None] * k + (1.0 - c)[:, None, None] * k2


def _sin_vers_one(q):
    """Return ``(n, 3)`` rows ``[sin q, 1 - cos q, 1]`` (the weights of a rotation basis)."""
    out = np.empty((q.shape[0], 3))
    np.sin(q, out=out[:, 0])
    np.cos(q, out=out[:, 1])
    np.subtract(1.0, out[:, 1], out=out[:, 1])
    out[:, 2] = 1.0
    return out


def expmap(v):
    """Return the rotations ``exp(v^)`` ``(n, 3, 3)`` of rotation vectors ``(n, 3)``."""
    th = np.sqrt(np.einsum('ni,ni->n', v, v))
    small = th < 1e-8
    safe = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - th ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    k = skew(v)
    return EYE3 + a[:, None, None] * k + b[:, None, None] * (k @ k)


def min_rotation(frm, to):
    """Return the smallest rotation (3, 3) taking the unit vector ``frm`` onto ``to``."""
    frm, to = np.asarray(frm, dtype=float), np.asarray(to, dtype=float)
    c = float(frm @ to)
    axis = cross(frm, to)
    s = float(np.linalg.norm(axis))
    if s < 1e-15:
        if c > 0.0:
            return np.eye(3)
        helper = np.eye(3)[int(np.argmin(np.abs(frm)))]
        axis = cross(frm, helper)
        axis /= np.linalg.norm(axis)
        return rot_axis(axis, np.array([math.pi]))[0]
    return rot_axis(axis / s, np.array([math.atan2(s, c)]))[0]


def _unit(v, where):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def perp_pair(axis):
    """Return two unit vectors normal to ``axis`` and to each other (deterministic)."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e1 = cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, cross(axis, e1)


def _point_gradient(x):
    """Return ``(..., 3, 6)``: row i is ``(x x e_i, e_i)``, the rate of ``x_i`` per twist."""
    g = np.zeros(x.shape + (6,))
    x0, x1, x2 = x[..., 0], x[..., 1], x[..., 2]
    g[..., 0, 1], g[..., 0, 2] = x2, -x1
    g[..., 1, 0], g[..., 1, 2] = -x2, x0
    g[..., 2, 0], g[..., 2, 1] = x1, -x0
    g[..., 3:] = EYE3
    return g


def angle_about(axis, rot):
    """Return the angle ``(n,)`` of rotations ``rot`` ``(n, 3, 3)`` about the unit ``axis``."""
    skw = rot - np.swapaxes(rot, -1, -2)
    vee = 0.5 * np.stack([skw[..., 2, 1], skw[..., 0, 2], skw[..., 1, 0]], -1)
    cos = 0.5 * (np.trace(rot, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(vee @ axis, cos)


def spherical_zeros(linkage, fr):
    """Return ``{joint name: A}``, the relative rotation of each spherical joint at assembly."""
    idx = {n: i for i, n in enumerate(linkage.body_names)}
    out = {}
    for jt in linkage.scene.joints:
        if jt.joint_type == 'spherical':
            ra, rb = fr.rot[0, idx[jt.link_a]], fr.rot[0, idx[jt.link_b]]
            out[jt.name] = ra.T @ rb
    return out


@dataclass
class TreeJoint:
    """A joint of the spanning tree: ``child`` hangs from ``parent`` (body indices)."""

    joint: int            # index in the scene's joints
    name: str
    joint_type: str
    parent: int
    child: int
    s_parent: np.ndarray  # joint point in the parent's axes
    s_child: np.ndarray
    axis: np.ndarray      # in the parent's axes (unit; None for spherical)
    axis_child: np.ndarray
    fixed: np.ndarray     # the constant rotation Z, Rot(a, angle) Z or U (None: spherical)
    dofs: tuple           # indices into the coordinate vector
    flipped: bool         # the scene's end a is the child

    def __post_init__(self):
        """Precompute ``K Z`` and ``K^2 Z`` (K = the axis's cross matrix) for Rot(a, q) Z."""
        if self.axis is not None:
            k = skew(self.axis)
            self.kz, self.k2z = k @ self.fixed, k @ k @ self.fixed
            # [sin, 1 - cos, 1] @ rot_basis = Rot(a, q) Z: one small product per joint
            self.rot_basis = np.stack([self.kz, self.k2z, self.fixed]).reshape(3, 9)
            kc = skew(self.axis_child)   # a universal's second turn Rot(b, q2) likewise
            self.rot_basis_child = np.stack([kc, kc @ kc, EYE3]).reshape(3, 9)


@dataclass
class Rows:
    """The closure rows of one group, as index and local-vector arrays (module docstring)."""

    form: str
    body_b: np.ndarray
    body_a: np.ndarray
    vec_b: np.ndarray     # points: s_b; dots: u_b; lines: s_b; spin: v
    vec_a: np.ndarray     # points: s_a; dots: w_a; lines: s_a; spin: n (world)
    extra: np.ndarray     # lines: w_a; others: unused
    joint: tuple          # the joint name of each row (spin rows: 'spin:<link>')

    @property
    def size(self):
        """Return the number of rows."""
        return self.body_b.size * (3 if self.form == 'point' else 1)

    @property
    def ends(self):
        """Return the b bodies then the a bodies (the stacked passes over both ends)."""
        both = getattr(self, '_ends', None)
        if both is None:
            both = self._ends = np.concatenate([self.body_b, self.body_a])
        return both


@dataclass
class Frames:
    """Body poses, twists and the tree's twist columns over a batch (batch-first)."""

    rot: np.ndarray       # (n, nb, 3, 3)
    origin: np.ndarray    # (n, nb, 3)
    cols: np.ndarray      # (n, ndof, 6) twist columns (omega, v at the frame origin)
    parts: list = None    # the closure rows' world vectors (cached by Linkage._row_parts)
    grads: tuple = None   # the rows' twist gradients (cached by Linkage.gradients)

    @property
    def cols_c(self):
        """Return the twist columns component-major ``(6, ndof, n)`` (cached)."""
        c = getattr(self, '_cols_c', None)
        if c is None:
            c = self._cols_c = np.ascontiguousarray(self.cols.T)
        return c


@dataclass
class SpatialState:
    """The solved kinematics over n crank angles (batch-first; see :class:`Linkage`)."""

    psi: np.ndarray
    psi_d: np.ndarray
    psi_dd: np.ndarray
    q: np.ndarray          # (n, ndof) scalar coordinates (spherical entries unused)
    sph: np.ndarray        # (n, ns, 3, 3) relative rotations of the spherical tree joints
    frames: Frames
    residual: np.ndarray   # (n,) largest scaled closure residual
    cond: np.ndarray       # (n,) scaled Jacobian condition number
    rank: np.ndarray       # (n,) rank of the Jacobian
    jac: np.ndarray = None         # (n, m, ndof) closure Jacobian
    solver: np.ndarray = None      # (n, nu, m) (pseudo-)inverse of the scaled J_u
    refine: np.ndarray = None      # scaled J_u at the solution when solver is the predictor's
    qd: np.ndarray = None          # (n, ndof)
    qdd: np.ndarray = None
    twist: np.ndarray = None       # (n, nb, 6)
    accel: np.ndarray = None       # (n, nb, 6) spatial accelerations

    @property
    def size(self):
        """Return the number of samples."""
        return self.psi.shape[0]

    def component_major(self):
        """
        Return ``(rot (3, 3, nb, n), origin (3, nb, n), twist (6, nb, n))`` (cached).

        The poses and twists component-major (contiguous ``(nb, n)`` blocks), converted once
        per state for the joint values and the inverse dynamics; twist None if not solved.
        """
        cached = getattr(self, '_component_major', None)
        if cached is None:
            fr = self.frames
            cached = (component_major(fr.rot), component_major(fr.origin),
                      None if self.twist is None else component_major(self.twist))
            self._component_major = cached
        return cached


class Rates(NamedTuple):
    """The rates :meth:`Linkage.rates` solves at a batch of positions (batch-first)."""

    qd: np.ndarray        # (n, ndof) coordinate rates
    qdd: np.ndarray       # (n, ndof) coordinate accelerations (None: not asked for)
    twist: np.ndarray     # (n, nb, 6) body twists
    accel: np.ndarray     # (n, nb, 6) spatial accelerations (None: not asked for)
    jac: np.ndarray       # (n, m, ndof) closure Jacobian
    solver: np.ndarray    # (n, nu, m) (pseudo-)inverse of the scaled J_u
    cond: np.ndarray      # (n,) its condition number
    rank: np.ndarray      # (n,) its rank
    sign: np.ndarray      # (n,) sign of its determinant (square systems; else 1)
    refine: np.ndarray    # scaled J_u when ``solver`` is a nearby position's (else None)


class Linkage:
    """
    A spatial scene's compiled spanning tree, closure rows, assembly and traced branch.

    Immutable once built (the branch is traced on first use of :attr:`skeleton`).
    """

    def __init__(self, scene):
        self.scene = scene
        self.warnings = []
        self.body_names = (FRAME,) + tuple(lk.name for lk in scene.links)
        self.nb = len(self.body_names)
        body = {n: i for i, n in enumerate(self.body_names)}
        points = {FRAME: scene.frame_points, **{lk.name: lk.points for lk in scene.links}}
        self._points = {k: {p: np.array(v, dtype=float) for p, v in pts.items()}
                        for k, pts in points.items()}
        self.length_scale = self._length_scale()
        self._compile(body)
        self.stroke_m = getattr(scene, 'crank_stroke_m', None)
        self.periodic = self.stroke_m is None
        # tree coordinate 0 against the input joint's own coordinate: a prismatic tree joint
        # hung from its scene end b slides the other way (coordinates.joint_values)
        self.input_sign = -1.0 if self.tree[0].flipped and not self.periodic else 1.0
        half = 1.0 if self.periodic else 0.5 * (self.stroke_m[1] - self.stroke_m[0])
        # the input coordinate's own scale (rad, or the half stroke in m): every step and
        # tolerance in it is relative to this, so the figures do not depend on the unit
        self.input_scale = half
        self.step_max, self.step_min = STEP_MAX_RAD * half, STEP_MIN_RAD * half
        self._assemble()
        self._skeleton = None

    # ------------------------------------------------------------------ the input

    def input_motion(self, psi, psi_d, psi_dd):
        """
        Return the input joint's ``(x, x', x'')`` at cycle angles ``psi`` (rad, rad/s, rad/s^2).

        A revolute input: ``psi`` and its rates as they are (no copy); a prismatic input: the
        slide of :func:`~mech_balance.schema.spatial.stroke_law` (m) and its rates by the
        chain rule, in the joint's own convention (b's point from a's along a's axis).
        """
        if self.periodic:
            return psi, psi_d, psi_dd
        s, s1, s2 = stroke_law(self.stroke_m, psi)
        return s, s1 * psi_d, s2 * psi_d * psi_d + s1 * psi_dd

    def input_coordinate(self, psi, psi_d, psi_dd):
        """Return :meth:`input_motion` as tree coordinate 0 and its rates (the solver's)."""
        x, xd, xdd = self.input_motion(psi, psi_d, psi_dd)
        if self.input_sign < 0.0:
            return -x, -xd, -xdd
        return x, xd, xdd

    def _where(self, x, digits=4):
        """Return where tree coordinate 0 is ``x``, in words (a crank angle or a slide)."""
        if self.periodic:
            return f'crank angle {crank_angle_text(x, digits)} deg'
        return f'input slide {self.input_sign * x:.{digits + 3}f} m'

    # ------------------------------------------------------------------ compile

    def _length_scale(self):
        ext = []
        for pts in self._points.values():
            vals = list(pts.values())
            for i, a in enumerate(vals):
                for b in vals[i + 1:]:
                    ext.append(float(np.linalg.norm(a - b)))
        ext = [e for e in ext if e > 0.0]
        return max(ext) if ext else 1.0

    def _compile(self, body):
        sc = self.scene
        joints = sc.joints
        crank = next(i for i, j in enumerate(joints) if j.name == sc.crank_joint)
        order = [crank] + [i for i in range(len(joints)) if i != crank]
        seen = {0}
        tree, cuts = [], []
        frontier = [0]
        used = set()
        while frontier:  # breadth first from the frame, crank first
            nxt = []
            for ji in order:
                if ji in used:
                    continue
                jt = joints[ji]
                a, b = body[jt.link_a], body[jt.link_b]
                if a in frontier and b not in seen:
                    tree.append((ji, a, b, False))
                elif b in frontier and a not in seen:
                    tree.append((ji, b, a, True))
                else:
                    continue
                used.add(ji)
                seen.add(tree[-1][2])
                nxt.append(tree[-1][2])
            frontier = nxt
        cuts = [ji for ji in range(len(joints)) if ji not in used]
        self.tree = []
        dof = 0
        self.dof_slide = []
        self.dof_child_fixed = []
        self.sph_index = []
        for ji, parent, child, rev in tree:
            jt = joints[ji]
            pn, cn = self.body_names[parent], self.body_names[child]
            sp = self._points[pn][jt.point_b if rev else jt.point_a]
            scp = self._points[cn][jt.point_a if rev else jt.point_b]
            axis = axis_c = fixed = None
            if jt.axis is not None:
                a_ax = _unit(jt.axis, 'axis')
                b_ax = _unit(jt.axis if jt.axis_b is None else jt.axis_b, 'axis_b')
                axis, axis_c = (b_ax, a_ax) if rev else (a_ax, b_ax)
                if jt.joint_type == 'universal':
                    e = axis_c - (axis_c @ axis) * axis
                    e = perp_pair(axis)[0] if np.linalg.norm(e) < 1e-12 else e / \
                        np.linalg.norm(e)
                    fixed = min_rotation(axis_c, e)
                else:
                    fixed = min_rotation(axis_c, axis)
                    if jt.joint_type == 'prismatic':
                        ang = math.radians(jt.angle_deg or 0.0) * (-1.0 if rev else 1.0)
                        fixed = rot_axis(axis, np.array([ang]))[0] @ fixed
            n = jt.freedoms
            dofs = tuple(range(dof, dof + n))
            dof += n
            kinds = {'revolute': ['r'], 'prismatic': ['s'], 'cylindrical': ['r', 's'],
                     'universal': ['r', 'r'], 'spherical': ['w', 'w', 'w']}[jt.joint_type]
            self.dof_slide += [k == 's' for k in kinds]
            self.dof_child_fixed += [jt.joint_type == 'universal' and i == 1
                                     for i in range(n)]
            if jt.joint_type == 'spherical':
                self.sph_index.append(len(self.tree))
            self.tree.append(TreeJoint(ji, jt.name, jt.joint_type, parent, child, sp, scp,
                                       axis, axis_c, fixed, dofs, rev))
        self.ndof = dof
        self.dof_slide = np.array(self.dof_slide, dtype=bool)
        self.dof_child_fixed = np.array(self.dof_child_fixed, dtype=bool)
        self.is_sph_dof = np.zeros(dof, dtype=bool)
        for t in self.sph_index:
            self.is_sph_dof[list(self.tree[t].dofs)] = True
        self.scalar_dofs = np.flatnonzero(~self.is_sph_dof)
        self.unknown = slice(1, dof)   # every coordinate but the crank (a slice: views)
        self.nu = dof - 1
        # path[d, k]: coordinate d moves body k (k below d's tree joint)
        self.path = np.zeros((dof, self.nb))
        below = {t.child: t for t in self.tree}
        for k in range(1, self.nb):
            node = k
            while node != 0:
                t = below[node]
                self.path[list(t.dofs), k] = 1.0
                node = t.parent
        self.path_t = np.ascontiguousarray(self.path.T)  # (nb, ndof): matmul wants it so
        self.dof_owner = np.zeros(dof, dtype=int)  # the body each column is fixed in
        for t in self.tree:
            for i, d in enumerate(t.dofs):
                self.dof_owner[d] = t.child if self.dof_child_fixed[d] else t.parent
        self._moving_cols = np.flatnonzero(self.dof_owner != 0)   # columns that turn
        self._path_t_moving = np.ascontiguousarray(self.path_t[:, self._moving_cols])
        self.cut_joints = cuts
        self._build_rows(body, cuts)

    def _build_rows(self, body, cuts):
        sc = self.scene
        pts, dots, lines = [], [], []
        for ji in cuts:
            jt = sc.joints[ji]
            a, b = body[jt.link_a], body[jt.link_b]
            sa = self._points[jt.link_a][jt.point_a]
            sb = self._points[jt.link_b][jt.point_b]
            t = jt.joint_type
            if t in ('revolute', 'universal', 'spherical'):
                pts.append((b, a, sb, sa, jt.name))
            if t == 'spherical':
                continue
            ax = _unit(jt.axis, 'axis')
            bx = _unit(jt.axis if jt.axis_b is None else jt.axis_b, 'axis_b')
            if t == 'universal':
                dots.append((b, bx, a, ax, jt.name))
                continue
            e1, e2 = perp_pair(ax)
            dots.append((b, bx, a, e1, jt.name))
            dots.append((b, bx, a, e2, jt.name))
            if t in ('cylindrical', 'prismatic'):
                lines.append((b, a, sb, sa, e1, jt.name))
                lines.append((b, a, sb, sa, e2, jt.name))
            if t == 'prismatic':
                fixed = rot_axis(ax, np.array([math.radians(jt.angle_deg or 0.0)]))[0] @ \
                    min_rotation(bx, ax)
                dots.append((b, fixed.T @ e1, a, e2, jt.name))
        self.rows = []
        if pts:
            self.rows.append(Rows('point', np.array([p[0] for p in pts]),
                                  np.array([p[1] for p in pts]), np.array([p[2] for p in pts]),
                                  np.array([p[3] for p in pts]), None,
                                  tuple(p[4] for p in pts for _ in range(3))))
        if dots:
            self.rows.append(Rows('dot', np.array([p[0] for p in dots]),
                                  np.array([p[2] for p in dots]),
                                  np.array([p[1] for p in dots]),
                                  np.array([p[3] for p in dots]), None,
                                  tuple(p[4] for p in dots)))
        if lines:
            self.rows.append(Rows('line', np.array([p[0] for p in lines]),
                                  np.array([p[1] for p in lines]),
                                  np.array([p[2] for p in lines]),
                                  np.array([p[3] for p in lines]),
                                  np.array([p[4] for p in lines]), tuple(p[5] for p in lines)))
        self._finish_rows()

    def _finish_rows(self):
        self.m = sum(r.size for r in self.rows)
        scale = []
        for r in self.rows:
            scale += [1.0 / self.length_scale if r.form in ('point', 'line') else 1.0] * r.size
        self.row_scale = np.array(scale)
        self.col_scale = np.where(self.dof_slide, self.length_scale, 1.0)
        self.row_joint = tuple(j for r in self.rows for j in r.joint)
        bodies_b, bodies_a = [], []
        for r in self.rows:
            rep = 3 if r.form == 'point' else 1
            bodies_b += list(np.repeat(r.body_b, rep))
            bodies_a += list(np.repeat(r.body_a, rep))
        self.row_b = np.array(bodies_b, dtype=int)
        self.row_a = np.array(bodies_a, dtype=int)
        self.mask_b = self.path[:, self.row_b].T  # (m, ndof)
        self.mask_a = self.path[:, self.row_a].T
        # per group, per joint (k, ndof, 1): which coordinates move its b and its a body
        self._row_masks = [self.path[:, r.body_b].T[:, :, None] for r in self.rows]
        self._row_masks_a = [self.path[:, r.body_a].T[:, :, None] for r in self.rows]
        self.square = self.m == self.nu
        self.js_scale = self.row_scale[:, None] * self.col_scale[self.unknown]

    def scaled(self, jac):
        """Return the scaled Jacobian of the unknowns ``(n, m, nu)`` (rows and columns)."""
        return jac[:, :, self.unknown] * self.js_scale

    # ------------------------------------------------------------------ forward kinematics

    def _col_template(self):
        """
        Return ``(ndof, 6)`` (built once): the constant twist columns of the frame's joints.

        A revolute, prismatic, spherical or universal (first axis) joint on the frame has a
        fixed axis through a fixed point: its columns do not depend on the coordinates.
        """
        tpl = getattr(self, '_cols_tpl', None)
        if tpl is None:
            tpl = np.zeros((self.ndof, 6))
            for t in self.tree:
                if t.parent or t.joint_type not in _CONSTANT_ROOT_COLUMNS:
                    continue
                d = t.dofs
                if t.joint_type == 'spherical':
                    tpl[d[0]:d[0] + 3, :3] = EYE3
                    tpl[d[0]:d[0] + 3, 3:] = cross(t.s_parent[None, :], EYE3)
                elif t.joint_type == 'prismatic':
                    tpl[d[0], 3:] = t.axis
                else:
                    tpl[d[0], :3] = t.axis
                    tpl[d[0], 3:] = cross(t.s_parent, t.axis)
            self._cols_tpl = tpl
        return tpl

    def frames(self, q, sph):
        """Return the :class:`Frames` of coordinates ``q`` (n, ndof) and ``sph`` rotations."""
        n = q.shape[0]
        rot = np.empty((n, self.nb, 3, 3))
        origin = np.empty((n, self.nb, 3))
        rot[:, 0] = EYE3
        origin[:, 0] = 0.0
        cols = np.empty((n, self.ndof, 6))
        cols[:] = self._col_template()  # the frame joints' constant columns, zeros elsewhere
        si = 0
        for t in self.tree:
            root = not t.parent
            rp, pp = rot[:, t.parent], origin[:, t.parent]
            d = t.dofs
            jtype = t.joint_type
            if jtype == 'spherical':
                m = sph[:, si]
                si += 1
                off = t.s_parent
            elif jtype == 'prismatic':
                m = t.fixed
                off = t.s_parent + q[:, d[0], None] * t.axis
            else:
                # Rot(a, theta) Z = Z + sin K Z + (1 - cos) K^2 Z (K, K^2 Z precomputed)
                m = (_sin_vers_one(q[:, d[0]]) @ t.rot_basis).reshape(n, 3, 3)
                off = t.s_parent + q[:, d[1], None] * t.axis if jtype == 'cylindrical' \
                    else t.s_parent
                if jtype == 'universal':
                    m = m @ (_sin_vers_one(q[:, d[1]]) @ t.rot_basis_child).reshape(n, 3, 3)
            # on the frame: m and off as they are ((3, 3) and (3,) when constant: broadcast)
            rc = m if root else rp @ m
            r_joint = off if root else pp + mv(rp, off)
            rot[:, t.child] = rc
            if rc.ndim == 2:
                origin[:, t.child] = r_joint - rc @ t.s_child
            elif rc.flags.c_contiguous:  # one matrix-vector product over the stack
                origin[:, t.child] = r_joint - (rc.reshape(-1, 3) @ t.s_child).reshape(n, 3)
            else:
                origin[:, t.child] = r_joint - mv(rc, t.s_child)
            if root and jtype in _CONSTANT_ROOT_COLUMNS:
                if jtype == 'universal':
                    bw = mv(rc, t.axis_child)
                    cols[:, d[1], :3] = bw
                    cols[:, d[1], 3:] = cross(r_joint, bw)
                continue
            if jtype == 'spherical':
                axes = EYE3 if root else np.swapaxes(rp, 1, 2)
                cols[:, d[0]:d[0] + 3, :3] = axes
                cols[:, d[0]:d[0] + 3, 3:] = cross(r_joint[:, None, :], axes)
                continue
            aw = np.broadcast_to(t.axis, (n, 3)) if root else mv(rp, t.axis)
            if jtype != 'prismatic':
                cols[:, d[0], :3] = aw
                cols[:, d[0], 3:] = cross(r_joint, aw)
            if jtype in ('cylindrical', 'prismatic'):
                cols[:, d[-1], 3:] = aw
            if jtype == 'universal':
                bw = mv(rc, t.axis_child)
                cols[:, d[1], :3] = bw
                cols[:, d[1], 3:] = cross(r_joint, bw)
        return Frames(rot, origin, cols)

    # ------------------------------------------------------------------ closure rows

    def _row_parts(self, fr):
        """Return per group the world quantities the rows need (cached on ``fr``)."""
        if fr.parts is None:
            fr.parts = list(self._row_parts_of(fr))
        return fr.parts

    def _row_parts_of(self, fr):
        """Yield per group the world quantities the rows need."""
        for r in self.rows:
            rb, ra = fr.rot[:, r.body_b], fr.rot[:, r.body_a]
            if r.form == 'spin':
                yield r, rb, ra, mv(rb, r.vec_b), r.vec_a
                continue
            vb = mv(rb, r.vec_b)
            va = mv(ra, r.vec_a)
            if r.form in ('point', 'line'):
                vb = vb + fr.origin[:, r.body_b]
                va = va + fr.origin[:, r.body_a]
            yield r, rb, ra, vb, va

    def residual(self, fr):
        """Return the closure residuals ``(n, m)`` (SI: m for point and line rows)."""
        out = []
        for r, rb, ra, vb, va in self._row_parts(fr):
            if r.form == 'point':
                out.append((vb - va).reshape(vb.shape[0], -1))
            elif r.form == 'dot':
                out.append(dot(vb, va))
            elif r.form == 'line':
                w = mv(ra, r.extra)
                out.append(dot(vb - va, w))
            else:
                out.append(dot(vb, va))
        return np.concatenate(out, axis=1) if out else np.zeros((fr.rot.shape[0], 0))

    def gradients(self, fr):
        """Return ``(G_b, G_a)`` ``(n, m, 6)``: each row's rate per unit twist of b and a."""
        if fr.grads is None:
            fr.grads = self._gradients(fr)
        return fr.grads

    def _gradients(self, fr):
        gb, ga = [], []
        for r, rb, ra, vb, va in self._row_parts(fr):
            n, k = vb.shape[:2]
            if r.form == 'point':
                gb.append(_point_gradient(vb).reshape(n, 3 * k, 6))
                ga.append(np.negative(_point_gradient(va)).reshape(n, 3 * k, 6))
            elif r.form == 'dot':
                c = cross(vb, va)
                z = np.zeros_like(c)
                gb.append(np.concatenate([c, z], -1))
                ga.append(np.concatenate([-c, z], -1))
            elif r.form == 'line':
                w = mv(ra, r.extra)
                d = vb - va
                gb.append(np.concatenate([cross(vb, w), w], -1))
                ga.append(np.concatenate([-cross(va, w) + cross(w, d), -w], -1))
            else:
                c = cross(vb, np.broadcast_to(va, vb.shape))
                gb.append(np.concatenate([c, np.zeros_like(c)], -1))
                ga.append(np.zeros((n, k, 6)))
        if not gb:
            empty = np.zeros((fr.rot.shape[0], 0, 6))
            return empty, empty
        return np.concatenate(gb, axis=1), np.concatenate(ga, axis=1)

    @property
    def wrench_rows(self):
        """
        Return the first row of each row wrench of :meth:`row_wrenches` (built once).

        A coincident-point joint's three rows act as one force at its point (one wrench);
        every other row is a wrench of its own.
        """
        cached = getattr(self, '_wrench_rows', None)
        if cached is None or cached[0] != self.m:
            rows, at = [], 0
            for r in self.rows:
                step = 3 if r.form == 'point' else 1
                rows += list(range(at, at + r.size, step))
                at += r.size
            cached = (self.m, np.array(rows, dtype=int))
            self._wrench_rows = cached
        return cached[1]

    def row_wrenches(self, fr, lam):
        """
        Return ``(W_b, W_a)`` ``(6, q, n)``: the closure rows' wrenches on their b and a bodies.

        Component-major (moment about the frame origin, force) for multipliers ``lam``
        ``(n, m)``: ``lambda_r G(r)`` per row, the three rows of a coincident point merged
        into the force ``F`` at the point (``(x x F, F)``), in :attr:`wrench_rows` order.
        """
        n = lam.shape[0]
        lam_t = lam.T
        wb, wa = [], []
        at = 0
        for r, rb, ra, vb, va in self._row_parts(fr):
            k = r.body_b.size
            xb = vb.transpose(2, 1, 0)                     # (3, k, n)
            lr = lam_t[at:at + r.size]
            at += r.size
            if r.form == 'point':
                f = lr.reshape(k, 3, n).transpose(1, 0, 2)  # (3, k, n): the force on b
                wb.append(np.concatenate([cross_c(xb, f), f]))
                wa.append(-np.concatenate([cross_c(va.transpose(2, 1, 0), f), f]))
                continue
            zero = np.zeros((3, k, n))
            if r.form == 'spin':
                wb.append(np.concatenate([cross_c(xb, r.vec_a.T[:, :, None]) * lr, zero]))
                wa.append(np.zeros((6, k, n)))
                continue
            xa = va.transpose(2, 1, 0)
            if r.form == 'dot':
                c = cross_c(xb, xa) * lr
                wb.append(np.concatenate([c, zero]))
                wa.append(np.concatenate([-c, zero]))
                continue
            w = mv(ra, r.extra).transpose(2, 1, 0) * lr
            wb.append(np.concatenate([cross_c(xb, w), w]))
            wa.append(np.concatenate([cross_c(w, xb - xa) - cross_c(xa, w), -w]))
        if not wb:
            return np.zeros((6, 0, n)), np.zeros((6, 0, n))
        return np.concatenate(wb, axis=1), np.concatenate(wa, axis=1)

    def jacobian(self, fr):
        """
        Return the closure Jacobian ``(n, m, ndof)`` (rows' rates per coordinate rate).

        Computed component-major, ``(m, ndof, n)`` (the batch-last stack the LU takes as
        it is), and returned as a batch-first view of it.  A row's rate per coordinate d is
        its twist gradient (:meth:`gradients`) applied to d's column on the row's bodies
        that d moves: for a point x ``omega_d x x + v_d``, for a dot row ``(u_b x w_a) .
        omega_d``, for a line row ``(x_b x w) . omega_d + w . v_d`` on b and ``(w x d - x_a
        x w) . omega_d - w . v_d`` on a.
        """
        n = fr.rot.shape[0]
        if not self.m:
            return np.zeros((n, 0, self.ndof))
        c = fr.cols_c
        om, vel = c[:3, None], c[3:, None]           # (3, 1, ndof, n)
        out = []
        at = 0
        for r, rb, ra, vb, va in self._row_parts(fr):
            size = r.size
            mb, ma = self._row_masks[at], self._row_masks_a[at]
            at += 1
            xb = vb.transpose(2, 1, 0)[:, :, None]     # (3, k, 1, n)
            if r.form == 'point':
                jb = cross_c(om, xb)
                jb += vel
                ja = cross_c(om, va.transpose(2, 1, 0)[:, :, None])
                ja += vel
                j = jb * mb - ja * ma                    # (3, k, ndof, n)
                out.append(j.transpose(1, 0, 2, 3).reshape(size, self.ndof, n))
                continue
            if r.form == 'spin':
                g = cross_c(xb, r.vec_a.T[:, :, None, None])
                out.append(_dot_c(g, om) * mb)
                continue
            xa = va.transpose(2, 1, 0)[:, :, None]
            if r.form == 'dot':
                out.append(_dot_c(cross_c(xb, xa), om) * (mb - ma))
                continue
            w = mv(ra, r.extra).transpose(2, 1, 0)[:, :, None]
            jb = _dot_c(cross_c(xb, w), om) + _dot_c(w, vel)
            ja = _dot_c(cross_c(w, xb - xa) - cross_c(xa, w), om) - _dot_c(w, vel)
            out.append(jb * mb + ja * ma)
        return np.concatenate(out, axis=0).transpose(2, 0, 1)

    def bias(self, fr, twist, acc0):
        """
        Return the rows' second time derivatives ``(m, n)`` at body accelerations ``acc0``.

        Component-major throughout (``twist`` and ``acc0`` ``(6, nb, n)``).  Body point
        acceleration ``a_O + alpha x x + omega x (v_O + omega x x)``; a vector u fixed in a
        body: ``u' = omega x u``, ``u'' = alpha x u + omega x (omega x u)``.  The b and a
        ends of a group are evaluated together (one stacked pass).
        """
        out = []
        n = twist.shape[-1]
        dot_c = _dot_c
        for r, rb, ra, vb, va in self._row_parts(fr):
            k = r.body_b.size
            vb = vb.transpose(2, 1, 0)                    # (3, k, n) views
            if r.form == 'spin':
                w, al = twist[:3, r.body_b], acc0[:3, r.body_b]
                ddu = cross_c(al, vb)
                ddu += cross_c(w, cross_c(w, vb))
                out.append(dot_c(ddu, r.vec_a.T[:, :, None]))
                continue
            va = va.transpose(2, 1, 0)
            t, a = twist[:, r.ends], acc0[:, r.ends]       # (6, 2k, n): b ends, then a ends
            x = np.concatenate([vb, va], axis=1)
            w = t[:3]
            if r.form == 'point':
                acc = a[3:] + cross_c(a[:3], x)
                acc += cross_c(w, t[3:] + cross_c(w, x))
                out.append((acc[:, :k] - acc[:, k:]).transpose(1, 0, 2).reshape(3 * k, n))
            elif r.form == 'dot':
                du = cross_c(w, x)
                ddu = cross_c(a[:3], x)
                ddu += cross_c(w, du)
                out.append(dot_c(ddu[:, :k], va) + 2.0 * dot_c(du[:, :k], du[:, k:])
                           + dot_c(vb, ddu[:, k:]))
            else:
                wl = mv(ra, r.extra).transpose(2, 1, 0)
                vel = t[3:] + cross_c(w, x)
                acc = a[3:] + cross_c(a[:3], x)
                acc += cross_c(w, vel)
                wa, ala = w[:, k:], a[:3, k:]
                dw = cross_c(wa, wl)
                ddw = cross_c(ala, wl)
                ddw += cross_c(wa, dw)
                out.append(dot_c(acc[:, :k] - acc[:, k:], wl)
                           + 2.0 * dot_c(vel[:, :k] - vel[:, k:], dw)
                           + dot_c(vb - va, ddw))
        return np.concatenate(out, axis=0) if out else np.zeros((0, n))

    def twists(self, fr, qd):
        """Return the body twists ``(6, nb, n)`` (component-major) of rates ``qd`` (n, ndof)."""
        return np.matmul(self.path_t, fr.cols_c * qd.T)

    def accelerations(self, fr, twist, qd):
        """
        Return the body spatial accelerations ``(6, nb, n)`` at zero coordinate accelerations.

        Component-major (``twist`` ``(6, nb, n)``): the sum over the tree of
        ``S' q' = (T_owner x S) q'``, only for the columns fixed in a moving body (a frame
        joint's columns are constant).
        """
        moving = self._moving_cols
        if not moving.size:
            return np.zeros(twist.shape)
        t = twist[:, self.dof_owner[moving]]
        c = fr.cols_c[:, moving]
        w = t[:3]
        dcols = np.empty(c.shape)                 # the motion cross product T x S
        dcols[:3] = cross_c(w, c[:3])
        dcols[3:] = cross_c(w, c[3:])
        dcols[3:] += cross_c(t[3:], c[:3])
        dcols *= qd.T[moving]
        return np.matmul(self._path_t_moving, dcols)

    # ------------------------------------------------------------------ Newton

    def _update(self, q, sph, delta):
        q = q.copy()
        q[:, self.unknown] += delta * (~self.is_sph_dof[self.unknown])
        if self.sph_index:
            sph = sph.copy()
            for i, t in enumerate(self.sph_index):
                d = np.array(self.tree[t].dofs) - 1
                sph[:, i] = expmap(delta[:, d]) @ sph[:, i]
        return q, sph

    def _lu_plan(self, js):
        """
        Return the :class:`~linalg.LUPlan` of the scaled square Jacobian (built once).

        The pattern is structural: row r can depend on coordinate d only if d moves one of
        the row's two bodies (``mask_b``, ``mask_a``); the static order is block lower
        triangular (the loops in dependency order, :func:`linalg.block_triangular_order`,
        so that the factors have no fill between loops and the work grows linearly with
        them), pivots inside the blocks from the first Jacobian met (the assembly's).
        """
        plan = getattr(self, '_plan', None)
        if plan is None or plan[0] != self.m:
            pattern = ((self.mask_b + self.mask_a) > 0)[:, self.unknown]
            sample = np.where(pattern, js[0], 0.0)
            order = linalg.block_triangular_order(pattern, sample)
            if order is None:
                order = (linalg.pivot_order(sample), None)
            plan = (self.m, linalg.LUPlan(pattern, *order))
            self._plan = plan
        return plan[1]

    def _solver(self, js):
        """Return ``(solver, cond, rank, sign)`` of scaled Jacobians ``(n, m, nu)``."""
        n = js.shape[0]
        if self.nu == 0:
            return np.zeros((n, 0, self.m)), np.ones(n), np.zeros(n, dtype=int), np.ones(n)
        if self.square:
            # static-pivot sparse LU over the batch (planar linalg), LAPACK where weak
            batch_last = np.ascontiguousarray(js.transpose(1, 2, 0))  # contiguous: faster
            inv, cond, sign = linalg.inverse(batch_last, self._lu_plan(js), with_sign=True)
            return inv.transpose(2, 0, 1), cond, np.full(n, self.nu, dtype=int), sign
        u, s, vt = np.linalg.svd(js, full_matrices=False)
        keep = s > RANK_RTOL * s[:, :1]
        sinv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
        pinv = np.einsum('nji,nj,nkj->nik', vt, sinv, u)
        smin = np.min(np.where(keep, s, np.inf), axis=1)
        return pinv, s[:, 0] / smin, keep.sum(axis=1), np.ones(n)

    def newton(self, q, sph, max_iter=NEWTON_MAX_ITER, tol=NEWTON_TOL):
        """
        Return ``(q, sph, frames, residual, ok)`` after Newton from ``q``, ``sph`` (batch).

        Stops when every scaled residual is below ``tol``.
        """
        for _ in range(max_iter + 1):
            fr = self.frames(q, sph)
            g = self.residual(fr) * self.row_scale
            res = np.max(np.abs(g), axis=1) if self.m else np.zeros(q.shape[0])
            if np.all(res <= tol) or _ == max_iter or not self.nu:
                break
            js = self.scaled(self.jacobian(fr))
            solver, _, _, _ = self._solver(js)
            delta = -np.einsum('nij,nj->ni', solver, g) * self.col_scale[self.unknown]
            bad = ~np.isfinite(delta).all(axis=1)
            delta[bad] = 0.0
            q, sph = self._update(q, sph, delta)
        ok = (res <= tol) & np.isfinite(res)
        return q, sph, fr, res, ok

    def _chord(self, q, sph, max_iter=NEWTON_MAX_ITER, tol=NEWTON_TOL):
        """
        Return ``(q, sph, frames, residual, ok, factor)``: Newton with the predictor's factor.

        The Jacobian is factorized once, at the predictor; the iteration is then a chord
        method (linear convergence with the factor ~1e-8 of the predictor's error, so one or
        two steps).  ``factor`` is ``(solver, cond, rank, sign)`` (None: not square, the
        full Newton of :meth:`newton` was used), with a fifth entry, the Jacobian at the
        predictor, when every predictor residual is already within ``tol`` (no iteration:
        the predictor is the solution, its factor exact, :meth:`rates` needs no refinement).
        """
        if not self.square or not self.nu:
            q, sph, fr, res, ok = self.newton(q, sph, max_iter, tol)
            return q, sph, fr, res, ok, None
        fr = self.frames(q, sph)
        g = self.residual(fr) * self.row_scale
        jac = self.jacobian(fr)
        factor = self._solver(self.scaled(jac))
        res = np.max(np.abs(g), axis=1)
        if np.all(res <= tol):  # the predictor has converged: its Jacobian and factor are exact
            return q, sph, fr, res, np.isfinite(res), factor + (jac,)
        solver = factor[0]
        cu = self.col_scale[self.unknown]
        for _ in range(max_iter):
            delta = -mv(solver, g) * cu
            delta[~np.isfinite(delta).all(axis=1)] = 0.0
            q, sph = self._update(q, sph, delta)
            fr = self.frames(q, sph)
            g = self.residual(fr) * self.row_scale
            res = np.max(np.abs(g), axis=1)
            if np.all(res <= tol):
                break
        ok = (res <= tol) & np.isfinite(res)
        return q, sph, fr, res, ok, factor

    @property
    def dense(self):
        """Return the branch at nodes every DENSE_STEP_RAD (solved in one batch, cached)."""
        if getattr(self, '_dense', None) is None:
            sk = self.skeleton
            count = max(int(math.ceil(TWO_PI / DENSE_STEP_RAD)), 4)
            if self.periodic:
                psi = sk.psi[0] + TWO_PI * np.arange(count + 1) / count
            else:  # the stroke at the yoke's angles of half a turn, ascending in x
                psi = np.sort(self.input_coordinate(
                    math.pi * np.arange(count // 2 + 1) / (count // 2), 0.0, 0.0)[0])
            k, h = sk.nearest(psi)
            qp, sphp = self._step(sk.q[k], sk.sph[k], sk.qd[k], sk.qdd[k], h)
            q, sph, fr, res, ok = self.newton(qp, sphp)
            bad = ~ok | (self.change(q, sph, qp, sphp) > STEP_TRUST)
            if bad.any():  # keep the traced nodes only: no dense node off the branch
                self._dense = sk
                return sk
            q[:, 0] = psi
            rates = self.unit_rates(fr, q)
            if self.square and np.any(rates.sign != self.branch_sign):
                self._dense = sk
                return sk
            qd, qdd, cond = rates.qd, rates.qdd, rates.cond
            self._dense = Skeleton(psi, q, sph, qd, qdd, cond, self.periodic)
        return self._dense

    # ------------------------------------------------------------------ assembly

    def _initial(self):
        """Return tree coordinates ``(1, ndof)`` and rotations from the scene's poses."""
        return assembly.initial(self)

    def _assemble(self):
        """Assemble the linkage (Levenberg-Marquardt), find idle spins and redundancy."""
        if not self.m and self.nu:
            raise SpatialError(
                f'joints: the linkage is an open chain (no closed loop) with {self.nu} '
                f'degree(s) of freedom besides the crank joint {self.scene.crank_joint!r}; '
                'expected a single-input linkage')
        q, sph = self._initial()
        lam = 1e-3
        fr = self.frames(q, sph)
        g = self.residual(fr) * self.row_scale
        cost = float(np.sum(g * g))
        for _ in range(ASSEMBLY_MAX_ITER):
            if not self.m or np.max(np.abs(g)) <= NEWTON_TOL:
                break
            js = self.scaled(self.jacobian(fr))[0]
            a = js.T @ js
            rhs = js.T @ g[0]
            while True:
                step = -np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-12), rhs)
                q2, sph2 = self._update(q, sph, (step * self.col_scale[self.unknown])[None])
                fr2 = self.frames(q2, sph2)
                g2 = self.residual(fr2) * self.row_scale
                cost2 = float(np.sum(g2 * g2))
                if cost2 < cost:
                    q, sph, fr, g, cost = q2, sph2, fr2, g2, cost2
                    lam = max(lam / 3.0, 1e-12)
                    break
                lam *= 4.0
                if lam > 1e12:
                    break
            if lam > 1e12:
                break
        if self.m and np.max(np.abs(g)) > 1e-10:
            raise SpatialError(
                f'assembly: the linkage cannot be closed at crank angle '
                f'{crank_angle_text(self.scene.assembly_crank_angle_rad, 4)} deg from '
                f'assembly.poses (largest '
                f'scaled closure residual {np.max(np.abs(g)):.3e} after '
                f'{ASSEMBLY_MAX_ITER} iterations); expected poses near an assembled position')
        self._find_idle(q, sph, fr)
        q, sph, fr, res, ok = self.newton(q, sph)
        if not ok[0]:
            raise SpatialError(f'assembly: Newton did not converge (residual {res[0]:.3e})')
        mismatch = assembly.pose_mismatch(self, fr)
        if mismatch:
            raise SpatialError(mismatch)
        self.q0, self.sph0 = q, sph
        self.sph_zero = spherical_zeros(self, fr)
        js = self.scaled(self.jacobian(fr))
        _, cond, rank, sign = self._solver(js)
        self.rank = int(rank[0])
        self.redundant = self.m - self.rank
        self.branch_sign = float(sign[0])
        if self.rank < self.nu:
            raise SpatialError(
                f'joints: the linkage has {self.nu - self.rank} degree(s) of freedom besides '
                f'the crank joint {self.scene.crank_joint!r} (Jacobian rank {self.rank} of '
                f'{self.nu} unknown coordinates) that are not idle spins of S-S links; '
                'expected a single-input linkage')

    def _find_idle(self, q, sph, fr):
        """Detect idle spins from the Jacobian's null space; add the spin rows (or refuse)."""
        if not self.nu:
            return
        js = self.scaled(self.jacobian(fr))[0] if self.m else np.zeros((0, self.nu))
        if js.shape[0]:
            _, s, vt = np.linalg.svd(js)
            s_full = np.zeros(self.nu)
            s_full[:s.size] = s
            null = vt[s_full <= RANK_RTOL * max(s_full[0], 1.0)] if s.size else vt
        else:
            null = np.eye(self.nu)
        if not null.shape[0]:
            return
        # the body twists of each null direction
        qd = np.zeros((null.shape[0], self.ndof))
        qd[:, self.unknown] = null * self.col_scale[self.unknown]
        cols = np.broadcast_to(fr.cols[0], (null.shape[0],) + fr.cols.shape[1:])
        tw = np.einsum('nds,nd,dk->nks', cols, qd, self.path).reshape(null.shape[0], -1)
        spins = []
        sc = self.scene
        for k in range(1, self.nb):
            name = self.body_names[k]
            mine = [j for j in sc.joints if name in (j.link_a, j.link_b)]
            sph_j = [j for j in mine if j.joint_type == 'spherical']
            if len(mine) != 2 or len(sph_j) != 2:
                continue
            x = [fr.origin[0, k] + fr.rot[0, k] @ self._points[name][
                j.point_a if j.link_a == name else j.point_b] for j in sph_j]
            line = x[1] - x[0]
            if np.linalg.norm(line) < 1e-12 * self.length_scale:
                continue
            u = line / np.linalg.norm(line)
            e = np.zeros((self.nb, 6))
            e[k, :3], e[k, 3:] = u, cross(x[0], u)
            e = e.ravel()
            coef, *_ = np.linalg.lstsq(tw.T, e, rcond=None)
            if np.linalg.norm(tw.T @ coef - e) > 1e-6 * np.linalg.norm(e):
                continue
            spins.append((k, sph_j, x, u))
        if len(spins) < null.shape[0]:
            return  # the rank check after assembly names the extra freedoms
        self.idle_lines = []
        for k, sph_j, x, u in spins:
            name = self.body_names[k]
            rl = fr.rot[0, k]
            x0 = self._points[name][sph_j[0].point_a if sph_j[0].link_a == name
                                    else sph_j[0].point_b]
            self.idle_lines.append((name, sph_j[0].name, sph_j[1].name, rl.T @ u, x0))
        self.check_idle_inertia(self.scene)
        for k, sph_j, x, u in spins:
            name = self.body_names[k]
            rl = fr.rot[0, k]
            n_ref = np.eye(3)[int(np.argmin(np.abs(u)))]
            v = cross(u, n_ref)
            v /= np.linalg.norm(v)
            self.rows.append(Rows('spin', np.array([k]), np.array([0]), (rl.T @ v)[None],
                                  n_ref[None], None, (f'spin:{name}',)))
            self.idle_spins = getattr(self, 'idle_spins', ()) + (
                (name, sph_j[0].name, sph_j[1].name),)
        self._finish_rows()

    def check_idle_inertia(self, scene):
        """
        Refuse a design whose S-S link has inertia about its S-S line (the spin convention).

        The inertia about the line through the two spherical joints, ``u.I_c u + m |(c - x0)
        x u|^2``, must be zero to :data:`IDLE_INERTIA_RTOL`; the message names the link,
        the two joints and the way out.
        """
        for name, j1, j2, ul, x0 in getattr(self, 'idle_lines', ()):
            lk = scene.link(name)
            c = np.array(lk.com_m) - x0
            inertia = np.array(lk.inertia_matrix())
            about = float(ul @ inertia @ ul + lk.mass_kg * np.sum(cross(c, ul) ** 2))
            # the magnitudes: a design that is no body (a least-change force balance may
            # give a negative-definite inertia) must not make the scale vanish or go negative
            scale = abs(lk.mass_kg) * self.length_scale ** 2 + float(np.abs(inertia).sum())
            if about > IDLE_INERTIA_RTOL * max(scale, 1e-300):
                raise SpatialError(
                    f'links.{name}: held only by the spherical joints {j1} and {j2}, it '
                    'spins freely about the line through them (an idle freedom of the '
                    f'Jacobian), and its inertia about that line is {about:.6g} kg m^2; '
                    'expected 0 (a slender rod on that line, whose spin is then fixed by '
                    'convention) - or replace one S by a U (universal joint) to hold the spin')

    # ------------------------------------------------------------------ refined solves

    def solve_u(self, solver, js, rhs):
        """
        Return ``x`` with ``js x = rhs`` ``(n, m)`` from an inverse ``solver`` of a nearby Js.

        Square systems: ``solver`` is the inverse at the branch predictor, ``js`` the scaled
        Jacobian at the solution; REFINE_STEPS steps of iterative refinement make the result
        that of ``js`` itself (the two differ by the predictor's error, ~1e-8).
        Redundant systems: ``solver`` is the pseudo-inverse of ``js`` itself.
        """
        x = mv(solver, rhs)
        if self.square and js is not None:
            for _ in range(REFINE_STEPS):
                x += mv(solver, rhs - mv(js, x))
        return x

    def solve_ut(self, solver, js, rhs):
        """Return ``y`` with ``js^T y = rhs`` (as :meth:`solve_u`; minimum norm if redundant)."""
        y = mv(np.swapaxes(solver, 1, 2), rhs)
        if self.square and js is not None:
            for _ in range(REFINE_STEPS):
                y += mv(np.swapaxes(solver, 1, 2), rhs - mv(np.swapaxes(js, 1, 2), y))
        return y

    # ------------------------------------------------------------------ rates

    def rates(self, fr, q, psi_d, psi_dd, need_acc=True, factor=None):
        """
        Return the :class:`Rates` at ``fr``.

        ``factor`` ``(solver, cond, rank, sign)`` from a nearby position (the predictor's)
        is refined against this position's Jacobian instead of factorizing it anew;
        ``(solver, cond, rank, sign, jac)`` is the factor of this very position (exact).
        """
        n = q.shape[0]
        if factor is not None and len(factor) > 4:
            jac = factor[4]  # the factor's own Jacobian, at this very position
        else:
            jac = self.jacobian(fr) if self.m else np.zeros((n, 0, self.ndof))
        if factor is None or not self.square:
            solver, cond, rank, sign = self._solver(self.scaled(jac))
            refine = None
        else:
            solver, cond, rank, sign = factor[:4]
            refine = None if len(factor) > 4 else self.scaled(jac)
        rs = self.row_scale
        cu = self.col_scale[self.unknown]
        qd = np.zeros((n, self.ndof))
        qd[:, 0] = psi_d
        if self.nu:
            rhs = jac[:, :, 0] * psi_d[:, None] * rs
            qd[:, self.unknown] = -self.solve_u(solver, refine, rhs) * cu
        # component-major (6, nb, n) inside; the batch-first results are views of them
        twist_c = self.twists(fr, qd)
        qdd = accel = None
        if need_acc:
            acc0 = self.accelerations(fr, twist_c, qd)
            qdd = np.zeros((n, self.ndof))
            qdd[:, 0] = psi_dd
            if self.nu:
                gam = self.bias(fr, twist_c, acc0).T + jac[:, :, 0] * psi_dd[:, None]
                qdd[:, self.unknown] = -self.solve_u(solver, refine, gam * rs) * cu
            acc0 += self.twists(fr, qdd)
            accel = acc0.transpose(2, 1, 0)
        return Rates(qd, qdd, twist_c.transpose(2, 1, 0), accel, jac, solver, cond, rank, sign,
                     refine)

    # ------------------------------------------------------------------ branch

    @property
    def skeleton(self):
        """Return the traced branch: nodes over one crank turn (computed on first use)."""
        if self._skeleton is None:
            self._skeleton = self._trace()
        return self._skeleton

    def _step(self, q, sph, qd, qdd, h):
        """Return the predictor ``h`` rad along the branch from one node (batch of 1+)."""
        if not np.any(h):  # every angle is a node: the predictor is the node itself
            return q.copy(), sph.copy()
        qp = q + qd * h[:, None] + 0.5 * qdd * (h * h)[:, None]
        qp[:, 0] = q[:, 0] + h
        if self.sph_index:
            sph = sph.copy()
            for i, t in enumerate(self.sph_index):
                d = list(self.tree[t].dofs)
                sph[:, i] = expmap(qd[:, d] * h[:, None] + 0.5 * qdd[:, d] * (h * h)[:, None]) \
                    @ sph[:, i]
        return qp, sph

    def unit_rates(self, fr, q):
        """Return the :class:`Rates` at unit input speed and zero acceleration (branch nodes)."""
        one = np.ones(q.shape[0])
        return self.rates(fr, q, one, 0.0 * one)

    def coordinate_change(self, q, q_ref):
        """Return per sample the largest scaled change of the scalar coordinates but the input."""
        return np.max(np.abs(q - q_ref)[:, self.scalar_dofs[1:]]
                      / self.col_scale[self.scalar_dofs[1:]], axis=1, initial=0.0)

    def rotation_change(self, sph, sph_ref):
        """Return per sample the largest entry of ``sph_ref^T sph - I`` (spherical joints)."""
        if not self.sph_index:
            return np.zeros(sph.shape[0])
        diff = np.matmul(np.swapaxes(sph_ref, -1, -2), sph) - EYE3
        return np.max(np.abs(diff), axis=(1, 2, 3))

    def change(self, q, sph, q_ref, sph_ref):
        """Return per sample the largest scaled change of ``(q, sph)`` from a reference."""
        return np.maximum(self.coordinate_change(q, q_ref), self.rotation_change(sph, sph_ref))

    def _limits(self):
        """Return the :class:`continuation.Limits` of this linkage's input (rad, or m)."""
        return continuation.Limits(
            step_max=self.step_max, step_min=self.step_min,
            step_done=STEP_DONE * self.input_scale, step_trust=STEP_TRUST,
            cond_limit=COND_LIMIT, cond_warn=COND_WARN)

    def _advance(self, start, goal):
        """Yield the nodes from ``start`` to ``goal`` along the input (:mod:`continuation`)."""
        return continuation.advance(_SpatialBranch(self), start, goal, self._limits(),
                                    self.branch_sign if self.square else None)

    def _node(self, q, sph, qd, qdd, cond=1.0):
        """Return a :class:`continuation.Node` of one sample (batch of 1)."""
        return continuation.Node(float(q[0, 0]), (q, sph, qd, qdd), cond, self.branch_sign)

    def _trace(self):
        """Return the :class:`Skeleton` of the branch (one turn, or the stroke)."""
        rates = self.unit_rates(self.frames(self.q0, self.sph0), self.q0)
        start = self._node(self.q0, self.sph0, rates.qd, rates.qdd, float(rates.cond[0]))
        if not self.periodic:
            return self._trace_stroke(start)
        nodes = [start] + list(self._advance(start, TWO_PI))
        end = nodes[-1].state
        start_fr, end_fr = self.frames(self.q0, self.sph0), self.frames(end[0], end[1])
        gap = max(np.max(np.abs(start_fr.rot - end_fr.rot)),
                  np.max(np.abs(start_fr.origin - end_fr.origin)) / self.length_scale)
        if gap > CLOSURE_TOL:
            raise SpatialError(
                'assembly: after one full crank turn the linkage does not return to its '
                f'start (largest pose mismatch {gap:.3e}); the crank cannot turn fully on '
                'this branch')
        return _skeleton_of(nodes, True)

    def _trace_stroke(self, start):
        """Return the branch of a prismatic input over its stroke, from the assembly out."""
        ends = sorted(self.input_coordinate(np.array([0.0, math.pi]), 0.0, 0.0)[0])
        below = list(self._advance(start, ends[0] - start.x))
        above = list(self._advance(start, ends[1] - start.x))
        return _skeleton_of(below[::-1] + [start] + above, False)

    def _warn(self, text):
        if text not in self.warnings:
            self.warnings.append(text)
            warnings.warn(text, RuntimeWarning, stacklevel=3)

    # ------------------------------------------------------------------ evaluation

    def solve(self, psi, psi_d, psi_dd, need_rates=True, need_acc=True):
        """Return the :class:`SpatialState` at crank angles ``psi`` (n,), rad/s, rad/s^2."""
        psi = np.asarray(psi, dtype=float)
        psi_d = np.broadcast_to(np.asarray(psi_d, dtype=float), psi.shape)
        psi_dd = np.broadcast_to(np.asarray(psi_dd, dtype=float), psi.shape)
        x, x_d, x_dd = self.input_coordinate(psi, psi_d, psi_dd)
        sk = self.dense
        k, h = sk.nearest(x)
        if h.any():
            qp, sphp = self._step(sk.q[k], sk.sph[k], sk.qd[k], sk.qdd[k], h)
        else:  # every angle is a node: the predictor is the node itself (gathered copies)
            qp, sphp = sk.q[k], sk.sph[k]
        q, sph, fr, res, ok, factor = self._chord(qp, sphp)
        if q is qp:  # the predictor had converged: no correction
            bad = ~ok
        else:
            bad = ~ok | (self.change(q, sph, qp, sphp) > EVAL_TRUST)
        if bad.any():
            q, sph = q.copy(), sph.copy()
            cs = self.skeleton
            kc, hc = cs.nearest(x[bad])
            for i, kk, hh in zip(np.flatnonzero(bad), kc, hc):
                node = self._node(cs.q[kk:kk + 1], cs.sph[kk:kk + 1], cs.qd[kk:kk + 1],
                                  cs.qdd[kk:kk + 1])
                for node in self._advance(node, float(hh)):
                    pass
                q[i], sph[i] = node.state[0][0], node.state[1][0]
            q, sph, fr, res, ok = self.newton(q, sph)
            factor = None
        rates = self.rates(fr, q, x_d, x_dd, need_acc, factor)
        cond, sign = rates.cond, rates.sign
        if self.square:
            wrong = sign != self.branch_sign
            if wrong.any():
                i = int(np.flatnonzero(wrong)[0])
                raise SpatialError(
                    f'crank angle {crank_angle_text(psi[i], 4)} deg: the solution found is '
                    'on the other assembly branch (the loop Jacobian determinant changed '
                    'sign); the linkage is too close to a singular position here to follow it')
        if np.any(cond > COND_WARN):
            i = int(np.argmax(cond))
            self._warn(f'crank angle {crank_angle_text(psi[i], 3)} deg: near-singular '
                       f'position (Jacobian condition number {cond[i]:.3g} > {COND_WARN:.4g})')
        return SpatialState(psi, psi_d, psi_dd, q, sph, fr, res, cond, rates.rank, rates.jac,
                            rates.solver, rates.refine, rates.qd, rates.qdd, rates.twist,
                            rates.accel)


def _skeleton_of(nodes, periodic):
    """Return the :class:`Skeleton` of traced nodes (states ``(q, sph, qd, qdd)``)."""
    q, sph, qd, qdd = (np.concatenate([n.state[i] for n in nodes]) for i in range(4))
    return Skeleton(np.array([n.x for n in nodes]), q, sph, qd, qdd,
                    np.array([n.cond for n in nodes]), periodic)


class _SpatialBranch(continuation.Branch):
    """The spatial linkage's hooks for :func:`continuation.advance` (q, sph, qd, qdd)."""

    error = SpatialError

    def __init__(self, linkage):
        self.linkage = linkage

    def where(self, x, digits=4):
        """Return where tree coordinate 0 is ``x``, in words."""
        return self.linkage._where(x, digits)

    def predict(self, node, h):
        """Return the predicted ``(q, sph)`` ``h`` along the input from ``node``."""
        q, sph, qd, qdd = node.state
        return self.linkage._step(q, sph, qd, qdd, np.array([h]))

    def correct(self, prediction, x):
        """Return Newton's :class:`continuation.Trial` from the predicted ``(q, sph)``."""
        lk = self.linkage
        qp, sphp = prediction
        q, sph, fr, res, ok = lk.newton(qp, sphp)
        return continuation.Trial((q, sph, fr), bool(ok[0]), float(res[0]),
                                  float(lk.change(q, sph, qp, sphp)[0]))

    def node(self, trial, x):
        """Return the :class:`continuation.Node` with the rates at unit input speed."""
        q, sph, fr = trial.solution
        rates = self.linkage.unit_rates(fr, q)
        return continuation.Node(x, (q, sph, rates.qd, rates.qdd), float(rates.cond[0]),
                                 float(rates.sign[0]))

    def warn(self, text):
        """Record the warning on the linkage."""
        self.linkage._warn(text)


class Skeleton:
    """
    Branch nodes in tree coordinate 0; a second-order predictor from the nearest node.

    ``psi`` are the nodes' input coordinates, ascending: one crank turn (``periodic``: the
    last node is the first turned once) or a prismatic input's stroke (not periodic: a
    coordinate beyond an end is predicted from that end).
    """

    def __init__(self, psi, q, sph, qd, qdd, cond, periodic=True):
        self.psi, self.q, self.sph, self.qd, self.qdd, self.cond = psi, q, sph, qd, qdd, cond
        self.offset = psi - psi[0]
        self.periodic = periodic

    def nearest(self, psi):
        """Return the nearest node's index and the signed step from it, per coordinate."""
        if not self.periodic:
            x = psi - self.psi[0]
            k = np.searchsorted(self.offset, x, side='right') - 1
            k = np.clip(k, 0, self.psi.size - 2)
            k = np.where((self.offset[k + 1] - x) < (x - self.offset[k]), k + 1, k)
            return k, x - self.offset[k]
        x = np.mod(psi - self.psi[0], TWO_PI)
        k = np.searchsorted(self.offset, x, side='right') - 1
        k = np.clip(k, 0, self.psi.size - 2)
        right = (self.offset[k + 1] - x) < (x - self.offset[k])
        k = np.where(right, k + 1, k)
        h = x - self.offset[k]
        k = np.where(k == self.psi.size - 1, 0, k)  # the last node is the first turned once
        return k, h
