"""
Position, velocity and acceleration of a single-input spatial linkage (``kind: spatial``).

Tree coordinate 0 is the input: the crank angle, or a prismatic input's slide ``s(psi)``
(:func:`mech_balance.schema.spatial.stroke_law`).  docs/core.md#the-spatial-formulation.
"""

from dataclasses import dataclass
import itertools
from typing import NamedTuple
import warnings

from mech_balance import threads
from mech_balance.conventions import crank_angle_text
from mech_balance.core import linalg
from mech_balance.core.planar.kinematics import COND_WARN, NEWTON_TOL
from mech_balance.core.spatial.assembly import Assembling, RANK_RTOL
from mech_balance.core.spatial.branch import BranchFollowing, EVAL_TRUST, SpatialError, \
    STEP_MAX_RAD, STEP_MIN_RAD
from mech_balance.core.spatial.closure import ClosureRows
from mech_balance.core.spatial.coordinates import joint_frames
from mech_balance.core.spatial.vectors import component_major, cross, cross_c, mv, sin_vers_one
from mech_balance.rotations import expmap, EYE3, skew
from mech_balance.schema.scene import FRAME
from mech_balance.schema.spatial import stroke_law
import numpy as np

NEWTON_MAX_ITER = 10
"""Newton iterations per batched evaluation or continuation step."""
REFINE_STEPS = 1
"""Iterative-refinement steps of a solve with the predictor's inverse (each squares the error)."""


_CONSTANT_ROOT_COLUMNS = ('revolute', 'prismatic', 'spherical', 'universal')
"""Joint types whose twist columns are constant when their parent is the frame."""


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
class Frames:
    """Body poses, twists and the tree's twist columns over a batch (batch-first)."""

    rot: np.ndarray       # (n, nb, 3, 3)
    origin: np.ndarray    # (n, nb, 3)
    cols: np.ndarray      # (n, ndof, 6) twist columns (omega, v at the frame origin)
    parts: list = None    # the closure rows' world vectors (cached by Linkage._row_parts)

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
        """Return ``(rot (3, 3, nb, n), origin (3, nb, n), twist (6, nb, n) or None)`` (cached)."""
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


class Linkage(Assembling, ClosureRows, BranchFollowing):
    """A spatial scene's compiled spanning tree, closure rows, assembly and traced branch."""

    def __init__(self, scene):
        threads.settle_allocator()   # the allocator's policy: mech_balance/threads.py
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
        # a prismatic input hung from its scene end b slides against its own coordinate
        self.input_sign = -1.0 if self.tree[0].flipped and not self.periodic else 1.0
        half = 1.0 if self.periodic else 0.5 * (self.stroke_m[1] - self.stroke_m[0])
        # the input's own scale (rad, or the half stroke in m) for every step and tolerance
        self.input_scale = half
        self.step_max, self.step_min = STEP_MAX_RAD * half, STEP_MIN_RAD * half
        self._assemble()
        self._skeleton = None

    def input_motion(self, psi, psi_d, psi_dd):
        """Return the input joint's ``(x, x', x'')`` at cycle angles ``psi`` (rad or m)."""
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

    def _length_scale(self):
        ext = [float(np.linalg.norm(a - b)) for pts in self._points.values()
               for a, b in itertools.combinations(pts.values(), 2)]
        return max((e for e in ext if e > 0.0), default=1.0)

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
            axis, axis_c, fixed = joint_frames(jt, flipped=rev)
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

    def scaled(self, jac):
        """Return the scaled Jacobian of the unknowns ``(n, m, nu)`` (rows and columns)."""
        return jac[:, :, self.unknown] * self.js_scale

    def _col_template(self):
        """Return ``(ndof, 6)`` (built once): the constant twist columns of the frame's joints."""
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
                m = (sin_vers_one(q[:, d[0]]) @ t.rot_basis).reshape(n, 3, 3)
                off = t.s_parent + q[:, d[1], None] * t.axis if jtype == 'cylindrical' \
                    else t.s_parent
                if jtype == 'universal':
                    m = m @ (sin_vers_one(q[:, d[1]]) @ t.rot_basis_child).reshape(n, 3, 3)
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
            if not (root and jtype in _CONSTANT_ROOT_COLUMNS):   # (else in the template)
                if jtype == 'spherical':
                    axes = np.swapaxes(rp, 1, 2)
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

    def twists(self, fr, qd):
        """Return the body twists ``(6, nb, n)`` (component-major) of rates ``qd`` (n, ndof)."""
        return np.matmul(self.path_t, fr.cols_c * qd.T)

    def accelerations(self, fr, twist, qd):
        """Return the bodies' spatial accelerations ``(6, nb, n)`` at ``q'' = 0``."""
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
        """Return the :class:`~linalg.LUPlan` of the scaled square Jacobian (built once)."""
        plan = getattr(self, '_plan', None)
        if plan is None or plan[0] != self.m:
            pattern = ((self.mask_b + self.mask_a) > 0)[:, self.unknown]
            sample = np.where(pattern, js[0], 0.0)
            plan = (self.m, linalg.static_plan(pattern, sample))
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
        """Return ``(q, sph, frames, residual, ok)`` after Newton from ``q``, ``sph`` (batch)."""
        for _ in range(max_iter + 1):
            fr = self.frames(q, sph)
            g = self.residual(fr) * self.row_scale
            res = np.max(np.abs(g), axis=1) if self.m else np.zeros(q.shape[0])
            if np.all(res <= tol) or _ == max_iter or not self.nu:
                break
            delta = -self._newton_step(self.scaled(self.jacobian(fr)), g) \
                * self.col_scale[self.unknown]
            bad = ~np.isfinite(delta).all(axis=1)
            delta[bad] = 0.0
            q, sph = self._update(q, sph, delta)
        ok = (res <= tol) & np.isfinite(res)
        return q, sph, fr, res, ok

    def _newton_step(self, js, g):
        """Return ``x`` with ``js x = g`` per sample: solved, not inverted (redundant: pinv)."""
        if not self.square:
            return np.einsum('nij,nj->ni', self._solver(js)[0], g)
        batch_last = np.ascontiguousarray(js.transpose(1, 2, 0))
        return linalg.Factored(batch_last, self._lu_plan(js)).solve(g.T).T

    def _chord(self, q, sph, max_iter=NEWTON_MAX_ITER, tol=NEWTON_TOL):
        """Return ``(q, sph, frames, residual, ok, factor)``: Newton with one factor."""
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

    def solve_u(self, solver, js, rhs):
        """Return ``x`` with ``js x = rhs`` from the inverse ``solver`` of a nearby Js."""
        x = mv(solver, rhs)
        if self.square and js is not None:
            for _ in range(REFINE_STEPS):
                x += mv(solver, rhs - mv(js, x))
        return x

    def solve_ut(self, solver, js, rhs):
        """Return ``y`` with ``js^T y = rhs`` (as :meth:`solve_u`; minimum norm if redundant)."""
        return self.solve_u(np.swapaxes(solver, 1, 2),
                            None if js is None else np.swapaxes(js, 1, 2), rhs)

    def rates(self, fr, q, psi_d, psi_dd, need_acc=True, factor=None):
        """Return the :class:`Rates` at ``fr`` (a nearby position's ``factor`` is refined)."""
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

    def _warn(self, text):
        if text not in self.warnings:
            self.warnings.append(text)
            warnings.warn(text, RuntimeWarning, stacklevel=3)

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
