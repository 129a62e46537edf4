"""
Position, velocity and acceleration analysis of a single-input planar linkage.

Loop closure in the spanning tree's relative coordinates (seed 001 sec. 3.2, seed 000 eqs.
17-36), complex vectors, batch-last; solved from the traced branch's predictor, leaving the
branch raises :class:`BranchError`.  docs/core.md#the-planar-core-coreplanar.
"""

from dataclasses import dataclass
import math
import warnings

from mech_balance import threads
from mech_balance.conventions import crank_angle_text
from mech_balance.core import continuation, linalg
from mech_balance.core.planar import dyads
from mech_balance.core.planar.algebra import cross as _cross, max_reduce as _MAX, \
    rmat as _rmat, Tiles
from mech_balance.core.planar.rates import RateAnalysis
from mech_balance.core.planar.skeleton import Skeleton
from mech_balance.core.planar.tree import SpanningTree
from mech_balance.schema.scene import FRAME
import numpy as np

NEWTON_TOL = 1e-13
"""Loop-closure residual (relative to the characteristic length) that ends Newton."""
NEWTON_MAX_ITER = 8
"""Newton iterations per continuation step or per batched evaluation."""
ASSEMBLY_MAX_ITER = 60
"""Damped Newton iterations allowed to assemble the linkage from the scene's guess."""
PRINTED_RTOL = 5e-7
"""Relative resolution of the printed figures (half a unit of ``analyze``'s 6th digit)."""
COND_WARN = math.sqrt(PRINTED_RTOL / (2.0 * NEWTON_TOL))
"""Scaled Jacobian condition number (1-norm, ~1581) above which a position is near-singular
(docs/core.md#the-near-singular-threshold)."""
COND_LIMIT = 1e10
"""Scaled Jacobian condition number above which the position is refused as singular."""
STEP_MAX_RAD = math.radians(5.0)
"""Largest crank step between skeleton nodes (keeps the Hermite predictor within 1e-6)."""
LINE_SEARCH_MIN = 1e-4
"""Smallest step fraction of the damped Newton that assembles the linkage from the guess."""
ANGLE_EPS_RAD = 1e-12
"""Crank angles closer than this are the same angle (ends of the trace and of re-traces)."""
CLOSURE_TOL = 1e-7
"""Largest scaled joint mismatch after one traced turn for the branch to count as closed."""
STEP_MIN_RAD = 1e-7
"""Smallest crank step the continuation may take before it declares the branch lost."""
STEP_TRUST = 0.05
"""Largest scaled Newton correction accepted in a continuation step (else the step halves)."""
EVAL_TRUST = 1e-4
"""Largest scaled correction from the skeleton predictor before an angle is re-traced."""
CHORD_TRUST = 1.0
"""Largest distance (rad) of the skeleton's line or turn table from its predictor for the
dyads' closed form to take the whole turns from it (below pi is what that needs)."""
MIDPOINT_TRUST_FRACTION = 0.1
"""Fraction of ``EVAL_TRUST`` that Newton may move a traced segment's midpoint predictor."""
TWO_PI = 2.0 * math.pi
TRACE_LIMITS = continuation.Limits(
    step_max=STEP_MAX_RAD, step_min=STEP_MIN_RAD, step_done=ANGLE_EPS_RAD,
    step_trust=STEP_TRUST, cond_limit=COND_LIMIT, cond_warn=COND_WARN,
    grow_max_iterations=2)
"""The trace of the skeleton: the step grows after a step that Newton took in two."""
RETRACE_LIMITS = continuation.Limits(
    step_max=STEP_MAX_RAD, step_min=STEP_MIN_RAD, step_done=ANGLE_EPS_RAD,
    step_trust=STEP_TRUST, cond_limit=COND_LIMIT, first_step=STEP_MAX_RAD / 4, growth=1.0)
"""A re-trace from a skeleton node to one angle: quarter steps that do not grow."""


class BranchError(ValueError):
    """The linkage cannot be assembled, is singular, or would leave its branch."""


@dataclass
class Pose:
    """Body poses for a batch of crank angles (batch-last arrays)."""

    phi: np.ndarray       # (nb, p) absolute link angles, rad
    rot: np.ndarray       # (nb, p) exp(i*phi)
    origin: np.ndarray    # (nb, p) complex, link origins, m
    joint_at: np.ndarray  # (nt, p) complex, world location of each tree joint, m
    axis: np.ndarray      # (nt, p) complex, world slide direction (prismatic tree joints)
    cut_points: tuple = None  # cached (pa, pb, arm_a, arm_b, arms, [pa; pb; joint_at])


@dataclass
class KinematicState:
    """Everything the kinematics computes for a batch of crank angles (SI)."""

    psi: np.ndarray        # (p,) crank angle, rad
    psi_d: np.ndarray      # (p,) crank speed, rad/s
    psi_dd: np.ndarray     # (p,) crank acceleration, rad/s^2
    q: np.ndarray          # (nt, p) tree joint coordinates (rad or m)
    pose: Pose
    residual: np.ndarray   # (p,) max |g| / L at the solution
    cond: np.ndarray       # (p,) 1-norm condition number of the scaled Jacobian
    iterations: np.ndarray  # (p,) Newton iterations used
    qd: np.ndarray = None      # (nt, p)
    omega: np.ndarray = None   # (nb, p) rad/s
    vel: np.ndarray = None     # (nb, p) complex velocity of each link origin, m/s
    qdd: np.ndarray = None
    alpha: np.ndarray = None   # (nb, p) rad/s^2
    acc: np.ndarray = None     # (nb, p) complex acceleration of each link origin, m/s^2
    jac: np.ndarray = None      # (m, nt, p) scaled loop Jacobian (None: kept sparse)
    jac_factors: object = None  # linalg.Factored of J_u (solves without the inverse)
    jac_psi: np.ndarray = None  # (m, p) its crank column, d g / d psi (scaled)

    @property
    def jac_inv(self):
        """Return the ``(nu, m, p)`` inverse of the scaled Jacobian J_u (built on demand)."""
        return None if self.jac_factors is None else self.jac_factors.inverse()[0]

    @property
    def size(self):
        """Return the number of crank angles in the batch."""
        return self.psi.shape[0]


class Linkage(SpanningTree, RateAnalysis):
    """The geometry and topology of a planar scene, compiled for batched analysis."""

    def __init__(self, scene):
        threads.settle_allocator()   # the allocator's policy: mech_balance/threads.py
        self.scene = scene
        self.body_names = [FRAME] + [lk.name for lk in scene.links]
        index = {n: i for i, n in enumerate(self.body_names)}
        points = {FRAME: scene.frame_points, **{lk.name: lk.points for lk in scene.links}}
        pts = {n: {k: complex(*v) for k, v in p.items()} for n, p in points.items()}
        self.nb = len(self.body_names)
        joints = list(scene.joints)
        self.joint_names = [j.name for j in joints]
        crank_idx = self.joint_names.index(scene.crank_joint)
        order = [crank_idx] + [i for i in range(len(joints)) if i != crank_idx]

        self.tree, self.cuts = [], []
        visited, used, frontier = {0}, set(), [0]
        parent_joint = {0: None}
        while frontier:
            body = frontier.pop(0)
            for ji in order:
                if ji in used:
                    continue
                jt = joints[ji]
                ia, ib = index[jt.link_a], index[jt.link_b]
                if body not in (ia, ib):
                    continue
                other = ib if ia == body else ia
                used.add(ji)
                if other in visited:
                    self.cuts.append(self._cut(ji, jt, ia, ib, pts))
                    continue
                visited.add(other)
                frontier.append(other)
                parent_joint[other] = len(self.tree)
                self.tree.append(self._tree(ji, jt, body, other, index, pts))
            if body == 0 and not self.tree:
                break
        self.nt = len(self.tree)
        self.parent_joint = [parent_joint[b] for b in range(self.nb)]  # None for the frame
        # body order: tree order (parents before children)
        self.order = [tj.child for tj in self.tree]
        self.unknown = list(range(1, self.nt))          # tree coords solved by Newton
        self.unknown_rows = slice(1, self.nt)           # the same, as a slice (no copies)
        self.nu = len(self.unknown)
        self.m = 2 * len(self.cuts)
        if self.m != self.nu:
            raise BranchError(
                f'joints: {self.nu} unknown joint coordinates but {self.m} loop equations; '
                'the linkage is not a single-degree-of-freedom closed chain')
        # ancestry: anc[b] = tree joints on the path from the frame to body b
        self.anc = [set() for _ in range(self.nb)]
        for t, tj in enumerate(self.tree):
            self.anc[tj.child] = self.anc[tj.parent] | {t}
        self.is_prismatic = np.array([tj.prismatic for tj in self.tree])
        self.length_scale = self._length_scale(scene, pts)
        self._compile()
        crank = next(j for j in scene.joints if j.name == scene.crank_joint)
        self.pivot = complex(*scene.frame_points[crank.point_a if crank.link_a == FRAME
                                                 else crank.point_b])
        self.branch_sign = 1.0  # sign of det J_u on the traced branch (set by the trace)
        self.sparse_jac = False  # J_u as its nonzeros only (all-revolute, nu > 2)
        self.lu = None      # the loop Jacobian's sparse LU plan (linalg.LUPlan), at assembly
        self._skeleton = None
        self.dyads = None   # closed-form dyad plan (dyads.DyadPlan), set with the skeleton
        self.block = None   # its J_u as 2 x 2 diagonal blocks (linalg.BlockPlan), likewise
        self.turn_table_ok = False  # the closed form's whole turns from the skeleton's table
        self.turn_line = None       # or from a line in psi (Skeleton.affine_reference;
        #                             its slope and offset as algebra.Tiles)
        self.warnings = []

    @staticmethod
    def _length_scale(scene, pts):
        if scene.normalization is not None:
            return scene.normalization.length_m
        crank = next(j for j in scene.joints if j.name == scene.crank_joint)
        name = crank.link_b if crank.link_a == FRAME else crank.link_a
        p = list(pts[name].values())
        span = max((abs(x - y) for x in p for y in p), default=0.0)
        if span > 0.0:
            return span
        spans = [abs(x - y) for q in pts.values() for x in q.values() for y in q.values()]
        return max(spans) if max(spans, default=0.0) > 0.0 else 1.0

    def pose(self, q):
        """Return the body poses for tree coordinates ``q`` of shape ``(nt, p)``."""
        phi = np.dot(self.anc_rev, q) if self.dense_tree else self._down_rev(q)
        if self.has_pri:
            phi += self.phi_offset
        rot = np.empty(phi.shape, dtype=complex)
        rot[0] = 1.0
        # cos and sin straight into the real and imaginary parts: cheaper than complex exp
        np.cos(phi[1:], out=rot.real[1:])
        np.sin(phi[1:], out=rot.imag[1:])
        rot_par, rot_ch = rot[self.par], rot[self.ch]
        arm_ch = rot_ch * self.p_ch
        contrib = rot_par * self.p_par - arm_ch
        axis = None
        if self.has_pri:
            axis = np.where(self.axis_on_par, rot_par, -rot_ch) * self.axis_local
            contrib += q * axis
        origin = _rmat(self.anc_all, contrib) if self.dense_tree else self._down(contrib)
        joint_at = origin[self.ch] + arm_ch
        return Pose(phi, rot, origin, joint_at, axis)

    def cut_points(self, pose):
        """Return the world points ``(pa, pb)`` of the cut joints (cached on the pose)."""
        if pose.cut_points is None:
            # both ends of every cut in one go (a ends, b ends), above the tree joints in one
            # buffer that the Jacobian's differences take from
            arms = pose.rot.take(self.cut_ab, axis=0)
            arms *= self.cut_tiles.at(arms.shape[1])['p_ab']
            n = len(self.cuts)
            buf = np.empty((2 * n + self.nt, arms.shape[1]), dtype=complex)
            points = buf[:2 * n]
            np.add(pose.origin.take(self.cut_ab, axis=0), arms, out=points)
            buf[2 * n:] = pose.joint_at
            pose.cut_points = (points[:n], points[n:], arms[:n], arms[n:], arms, buf)
        return pose.cut_points[:2]

    def residual(self, pose):
        """Return the scaled loop-closure residuals ``(m, p)`` (seed 000 eq. 27)."""
        if not self.m:  # an open chain (a lone crank): nothing to close
            return np.zeros((0, pose.phi.shape[1]))
        pa, pb = self.cut_points(pose)
        d = pb - pa
        nr = self.nr
        if not self.npc:
            return self.scaled_rows(d)
        rows = [d.real[:nr], d.imag[:nr]]
        ia, ib = self.cut_a[nr:], self.cut_b[nr:]
        dphi = pose.phi[ib] - pose.phi[ia] - self.cut_angle
        n = pose.rot[ia] * self.cut_axis
        rows += [np.remainder(dphi + math.pi, TWO_PI) - math.pi, _cross(n, d[nr:])]
        return np.concatenate(rows) * self.row_scale[:, None]

    def scaled_rows(self, d):
        """Return the scaled loop rows ``(m, p)`` of revolute cuts' differences ``d`` (x, y)."""
        out = np.empty((self.m, d.shape[1]))
        np.multiply(d.real, self.scale0, out=out[:self.nr])
        np.multiply(d.imag, self.scale0, out=out[self.nr:])
        return out

    def jacobian(self, pose, unknown_only=False):
        """Return the scaled loop Jacobian ``(m, nt, p)`` (``unknown_only``: ``(m, nu, p)``)."""
        if not self.m:
            return np.zeros((0, self.nu if unknown_only else self.nt, pose.phi.shape[1]))
        pa, pb = self.cut_points(pose)
        cols = self.unknown_rows if unknown_only else slice(None)
        if not self.has_pri and not self.npc:
            c, t, i1, i2 = self.jac_nz_u if unknown_only else self.jac_nz
            points = pose.cut_points[5]   # (pa, pb, joint_at)
            d = points[i1]
            d -= points[i2]
            scale = self.row_scale[0] if self.m else 1.0
            out = np.zeros((self.m, self.nu if unknown_only else self.nt, d.shape[1]))
            out[c, t] = d.imag
            out[c, t] *= -scale
            out[self.nr + c, t] = d.real
            out[self.nr + c, t] *= scale
            return out
        sel_a, sel_b, sel = (self.sel_rev_a_u, self.sel_rev_b_u, self.sel_rev_u) if unknown_only \
            else (self.sel_rev_a3, self.sel_rev_b3, self.sel_rev3)
        # revolute tree joint t moves a point P below it by i (P - J_t) per unit rate:
        # d = (P - J_t) summed with the signs of the cut ends; i d = -Im d + i Re d
        d = sel_b * pb[:, None, :]
        d -= sel_a * pa[:, None, :]
        d -= sel * pose.joint_at[cols][None, :, :]
        nr = self.nr
        if not self.has_pri and not self.npc:
            out = np.empty((self.m,) + d.shape[1:])
            np.multiply(d.imag, self.neg_scale0, out=out[:nr])
            np.multiply(d.real, self.scale0, out=out[nr:])
            return out
        d = 1j * d
        if self.has_pri:
            d += self.sel_pri[:, cols, None] * pose.axis[None, cols, :]
            d *= self.col_scale_all[None, cols, None]
        rows = [d.real[:nr], d.imag[:nr]]
        if self.npc:
            ia = self.cut_a[nr:]
            n = pose.rot[ia] * self.cut_axis
            dn = self.sel_rev_a[nr:, cols, None] * (1j * n[:, None, :])
            rows += [np.broadcast_to(self.sel_rev[nr:, cols, None], d[nr:].shape),
                     _cross(dn, (pb - pa)[nr:, None, :]) * self.col_scale_all[None, cols, None]
                     + _cross(n[:, None, :], d[nr:])]
        return np.concatenate(rows) * self.row_scale[:, None, None]

    def jacobian_values(self, pose):
        """Return the nonzeros of J_u (LU entry order) and the crank column ``(m, p)``."""
        self.cut_points(pose)
        _, _, i1, i2, n, crank_rows = self.jac_nz_split
        points = pose.cut_points[5]   # (pa, pb, joint_at)
        d = points.take(i1, axis=0)
        d -= points.take(i2, axis=0)
        scale, neg = self.scale0, self.neg_scale0
        p = d.shape[1]
        values = np.empty((2 * n, p))
        np.multiply(d.imag[:n], neg, out=values[:n])
        np.multiply(d.real[:n], scale, out=values[n:])
        jac_psi = np.empty((self.m, p)) if self.crank_rows_all else np.zeros((self.m, p))
        rows = self.crank_row_slices
        if rows:
            np.multiply(d.imag[n:], neg, out=jac_psi[rows[0]])
            np.multiply(d.real[n:], scale, out=jac_psi[rows[1]])
        else:
            jac_psi[crank_rows] = -scale * d.imag[n:]
            jac_psi[self.nr + crank_rows] = scale * d.real[n:]
        return values, jac_psi

    def factored(self, pose):
        """Return ``(Factored J_u, J_psi or None)`` at ``pose`` (sparse where possible)."""
        if self.block is not None:
            values, jac_psi = self.jacobian_values(pose)
            return linalg.BlockFactored(self.block, values), jac_psi
        if self.sparse_jac:
            values, jac_psi = self.jacobian_values(pose)
            return linalg.Factored(None, self.lu, values=values), jac_psi
        return linalg.Factored(self.jacobian(pose, unknown_only=True), self.lu), None

    def newton(self, psi, q, max_iter=NEWTON_MAX_ITER, tol=NEWTON_TOL):
        """Solve g(q) = 0 from ``q`` ``(nt, p)``: ``(q, pose, residual, iterations, ok)``."""
        q = np.array(q, dtype=float)
        q[0] = psi
        iters = np.zeros(q.shape[1], dtype=int)
        unknown = self.unknown_rows
        for it in range(max_iter + 1):
            pose = self.pose(q)
            g = self.residual(pose)
            res = np.abs(g).max(axis=0) if self.m else np.zeros(q.shape[1])
            if it == max_iter or not res.max(initial=0.0) > tol:  # also stops on nan
                break
            # a Newton step for every angle: at converged ones it is a no-op to round-off
            if self.sparse_jac or self.block is not None:
                step = self.factored(pose)[0].solve(g)
            else:  # closed form for nu <= 2, no inverse or condition number
                step = linalg.solve(self.jacobian(pose, unknown_only=True), g, self.lu)
            if self.has_pri:
                step *= self.col_scale[:, None]
            q[unknown] -= step
            iters += res > tol
        ok = res <= tol
        return q, pose, res, iters, ok

    def closed_form(self, psi, tol=NEWTON_TOL):
        """Return :meth:`newton`'s tuple and ``q_pred`` (None: the dyads closed everywhere)."""
        sk = self.skeleton
        q_pred = None
        if self.turn_line is not None:
            line = self.turn_line.at(psi.shape[0])     # (slope, offset) per batch size
            ref = np.multiply(line['slope'], psi)
            ref += line['offset']
        elif self.turn_table_ok:
            ref = sk.turn_reference(psi)
        else:
            q_pred = sk.predict(psi)
            ref = q_pred[1:]
        q, rot, origin, joint_at = self.dyads.solve(psi, ref)
        phi = np.dot(self.anc_rev, q) if self.dense_tree else self._down_rev(q)
        pose = Pose(phi, rot, origin, joint_at, None)
        res = np.abs(self.residual(pose))
        res = _MAX(res, axis=0)                           # (ufunc reduce: no wrapper)
        ok = res <= tol                                   # False where nan
        if not _all(ok):
            if q_pred is None:
                q_pred = sk.predict(psi)
            return self.newton(psi, np.where(ok, q, q_pred)) + (q_pred,)
        return q, pose, res, np.zeros(psi.shape[0], dtype=int), ok, q_pred

    def assemble(self):
        """Return the tree coordinates at the assembly angle (damped Newton from the guess)."""
        scene = self.scene
        psi0 = scene.assembly_crank_angle_rad
        angles = {0: 0.0, self.tree[0].child: psi0}
        q = np.zeros((self.nt, 1))
        q[0] = psi0
        missing = []
        for t, tj in enumerate(self.tree[1:], start=1):
            name = self.body_names[tj.child]
            if not tj.prismatic:
                if name not in scene.assembly_link_angles_rad:
                    missing.append(f'link_angles_deg.{name}')
                    continue
                angles[tj.child] = scene.assembly_link_angles_rad[name]
                q[t] = angles[tj.child] - angles.get(tj.parent, 0.0)
            else:
                angles[tj.child] = angles.get(tj.parent, 0.0) + (
                    tj.angle if tj.axis_on_parent else -tj.angle)
                if tj.name not in scene.assembly_displacements_m:
                    missing.append(f'joint_displacements_m.{tj.name}')
                    continue
                q[t] = scene.assembly_displacements_m[tj.name]
        if missing:
            raise BranchError(
                f'assembly: missing {", ".join(missing)}; expected an approximate value for '
                'each, which selects the assembly mode (branch)')
        cs = self.col_scale[:, None]
        if self.nu > 2:
            # the static order of the loop Jacobian: block triangular (the Assur groups in
            # dependency order), pivots inside the blocks from the assembly guess
            sample = self.jacobian(self.pose(q))[:, self.unknown, 0]
            self.lu = linalg.static_plan(self._jacobian_pattern(), sample)
            self.sparse_jac = not self.has_pri and not self.npc
            if self.sparse_jac:
                c, t = self.jac_nz_split[0], self.jac_nz_split[1]
                self.lu.set_entries(np.concatenate([c, self.nr + c]), np.concatenate([t, t]))
        for _ in range(ASSEMBLY_MAX_ITER):
            pose = self.pose(q)
            g = self.residual(pose)
            norm = float(np.max(np.abs(g))) if self.m else 0.0
            if norm <= NEWTON_TOL:
                return q
            jinv, cond = linalg.inverse(self.jacobian(pose)[:, self.unknown], self.lu)
            if not np.isfinite(cond[0]):
                break
            step = -linalg.matvec(jinv, g) * cs
            lam = 1.0
            while lam > LINE_SEARCH_MIN:  # backtracking line search on the residual norm
                trial = q.copy()
                trial[self.unknown] += lam * step
                if np.max(np.abs(self.residual(self.pose(trial)))) < norm:
                    break
                lam *= 0.5
            q = trial
        raise BranchError(
            f'assembly: the linkage does not close at crank angle {crank_angle_text(psi0, 3)} '
            f'deg from the given link angles (loop residual {norm * self.length_scale:.3e} m '
            f'after {ASSEMBLY_MAX_ITER} damped Newton steps); check the joint points and '
            'lengths')

    @property
    def skeleton(self):
        """Return the traced branch: nodes over one crank turn (computed on first use)."""
        if self._skeleton is None:
            sk = self._trace()
            self.dyads = dyads.attach_signs(dyads.plan(self), self, sk)
            if self.dyads is not None:
                self.block = self._block_plan()
                slope, offset, err = sk.affine_reference()
                self.turn_line = Tiles(slope=slope, offset=offset) if err <= CHORD_TRUST \
                    else None
                self.turn_table_ok = sk.turn_table_error() <= CHORD_TRUST
            self._skeleton = sk
        return self._skeleton

    def _block_plan(self):
        """Return J_u as the dyads' 2 x 2 diagonal blocks (:class:`linalg.BlockPlan`)."""
        c, t = self.jac_nz_split[0], self.jac_nz_split[1]
        blocks = [((s.cut, self.nr + s.cut), (s.joints[0] - 1, s.joints[1] - 1))
                  for s in self.dyads.steps]
        try:
            return linalg.BlockPlan(self.nu, np.concatenate([c, self.nr + c]),
                                    np.concatenate([t, t]), blocks)
        except ValueError:  # pragma: no cover - a dyad order is block triangular
            return None

    def _trace(self):
        """Return the :class:`Skeleton`: the branch followed once round from the assembly."""
        psi0 = self.scene.assembly_crank_angle_rad
        q = self.assemble()
        branch = _PlanarBranch(self, midpoint_check=True)
        start = branch.node(continuation.Trial((q, self.pose(q)), True, 0.0, 0.0), psi0)
        self.branch_sign = start.sign
        nodes = [start] + list(continuation.advance(branch, start, TWO_PI, TRACE_LIMITS,
                                                    start.sign))
        q_start, q_end = nodes[0].state[0][:, 0], nodes[-1].state[0][:, 0]
        turns = np.zeros(self.nt)
        rev = ~self.is_prismatic
        turns[rev] = np.round((q_end[rev] - q_start[rev]) / TWO_PI)
        gap = np.abs(q_end - q_start - TWO_PI * turns) / np.where(
            self.is_prismatic, self.length_scale, 1.0)
        if np.max(gap[1:], initial=0.0) > CLOSURE_TOL:
            raise BranchError(
                'assembly: after one full crank turn the linkage does not return to its start '
                f'(largest joint mismatch {np.max(gap):.3e}); the crank cannot turn fully on '
                'this branch')
        q, qd, qdd = (np.concatenate([n.state[i] for n in nodes], axis=1) for i in range(3))
        return Skeleton(np.array([n.x for n in nodes]), q, qd, qdd,
                        np.array([n.cond for n in nodes]), turns)

    def scaled_change(self, q, q_ref):
        """Return the largest change ``|q - q_ref|`` of the unknowns (scaled; 0 if none)."""
        if not self.nu:
            return 0.0
        return float(np.max(np.abs((q - q_ref)[self.unknown]) / self.col_scale[:, None]))

    def _det_sign(self, pose):
        if not self.nu:
            return 1.0
        if self.nu <= 2:  # closed form, without the inverse and condition number
            return float(linalg.det_sign(self.jacobian(pose, unknown_only=True))[0])
        return float(self.factored(pose)[0].sign()[0])

    def _warn(self, text):
        if text not in self.warnings:
            self.warnings.append(text)
            warnings.warn(text, RuntimeWarning, stacklevel=3)

    def solve(self, psi, psi_d=None, psi_dd=None, need_rates=True, need_acc=True):
        """Return the :class:`KinematicState` at crank angles ``psi`` (rad; rates: the scene's)."""
        if not (type(psi) is np.ndarray and psi.ndim == 1 and psi.dtype == np.float64):
            psi = np.atleast_1d(np.asarray(psi, dtype=float)).ravel()
        # (a dot product is finite only if every angle is: one cheap pass, exact check after)
        if not math.isfinite(psi.dot(psi)) and not np.isfinite(psi).all():
            raise ValueError('crank_angle_rad: got a non-finite value, expected finite angles')
        sk = self.skeleton
        if self.dyads is not None:
            # where the closed form did not close: Newton from the predictor q_pred
            q, pose, res, iters, ok, q_pred = self.closed_form(psi)
        else:
            q_pred = sk.predict(psi)
            q, pose, res, iters, ok = self.newton(psi, q_pred)
        bad = None
        # q_pred is None: the dyads on the traced branch, closed to tolerance everywhere
        if q_pred is not None and self.nu and (self.dyads is not None or iters.any()):
            # how far the solution lies from the predictor (scaled)
            corr = q[1:] - q_pred[1:]
            np.abs(corr, out=corr)
            if self.has_pri:
                corr /= self.col_scale[:, None]
            if corr.max() > EVAL_TRUST or not ok.all():   # (nan: not ok)
                bad = corr.max(axis=0) > EVAL_TRUST
                bad |= ~ok
        elif not _all(ok):  # no step taken: the predictor is the solution where it converged
            bad = ~ok
        if bad is not None and bad.any():
            q[:, bad] = self._retrace(psi[bad])
            pose = self.pose(q)
            res = np.max(np.abs(self.residual(pose)), axis=0) if self.m else res
        speed = self.scene.crank_speed_rad_s if psi_d is None else psi_d
        accel = self.scene.crank_acceleration_rad_s2 if psi_dd is None else psi_dd
        scalar_speed = isinstance(speed, (int, float)) or np.ndim(speed) == 0
        scalar_accel = isinstance(accel, (int, float)) or np.ndim(accel) == 0
        speed_p = _filled(psi.shape, speed) if scalar_speed else \
            np.broadcast_to(np.asarray(speed, dtype=float), psi.shape)
        accel_p = _filled(psi.shape, accel) if scalar_accel else \
            np.broadcast_to(np.asarray(accel, dtype=float), psi.shape)

        def at(pose):
            if need_rates:
                return self.rates(pose, float(speed) if scalar_speed else speed_p,
                                  float(accel) if scalar_accel else accel_p,
                                  need_acc=need_acc)
            fac = self.factored(pose)[0]
            return {'cond': fac.cond(), 'det_sign': fac.sign()}

        r = at(pose)
        # near a sign change of det J_u the two branches can be closer than EVAL_TRUST: the
        # sign (a by-product of the rates' factorization) tells them apart
        wrong = r['det_sign'] != self.branch_sign
        if np.count_nonzero(wrong):
            q[:, wrong] = self._retrace(psi[wrong])
            pose = self.pose(q)
            res = np.max(np.abs(self.residual(pose)), axis=0) if self.m else res
            r = at(pose)
            wrong = r['det_sign'] != self.branch_sign
            if wrong.any():
                angle = crank_angle_text(psi[np.flatnonzero(wrong)[0]], 4)
                raise BranchError(
                    f'crank angle {angle} deg: the solution found is on the other '
                    'assembly branch (the loop Jacobian determinant changed sign); the '
                    'linkage is too close to a singular position here to follow its branch')
        state = KinematicState(psi, speed_p, accel_p, q, pose, res, r['cond'], iters)
        if need_rates:
            state.jac, state.jac_psi = r['jac'], r['jac_psi']
            state.jac_factors = r['jac_factors']
            state.qd, state.omega, state.vel = r['qd'], r['omega'], r['vel']
            if need_acc:
                state.qdd, state.alpha, state.acc = r['qdd'], r['alpha'], r['acc']
        if np.count_nonzero(state.cond > COND_WARN):
            worst = int(np.argmax(state.cond))
            self._warn(f'crank angle {crank_angle_text(psi[worst], 3)} deg: near-singular '
                       f'position (Jacobian condition number {state.cond[worst]:.3g})')
        return state

    def _retrace(self, psi):
        """Follow the branch from the nearest skeleton node to each angle, step by step."""
        sk = self.skeleton
        branch = _PlanarBranch(self, midpoint_check=False)
        out = np.empty((self.nt, psi.size))
        for i, target in enumerate(psi):
            k, x, _ = sk.locate(np.array([target]))
            base = sk.psi[k[0]] + (target - sk.psi[0] - x[0])
            q = sk.q[:, k[0]:k[0] + 1] + np.where(
                self.is_prismatic, 0.0, TWO_PI * sk.turns * sk.wraps(target))[:, None]
            node = continuation.Node(base, (q, sk.qd[:, k[0]:k[0] + 1],
                                            sk.qdd[:, k[0]:k[0] + 1]), 1.0, self.branch_sign)
            for node in continuation.advance(branch, node, target - base, RETRACE_LIMITS,
                                             self.branch_sign):
                pass
            out[:, i] = node.state[0][:, 0]
        return out


class _PlanarBranch(continuation.Branch):
    """The planar linkage's hooks for :func:`continuation.advance` (state: q, qd, qdd)."""

    error = BranchError

    def __init__(self, linkage, midpoint_check):
        self.linkage, self.midpoint_check = linkage, midpoint_check

    def where(self, x, digits=4):
        """Return the crank angle ``x`` in words."""
        return f'crank angle {crank_angle_text(x, digits)} deg'

    def predict(self, node, h):
        """Return the second-order Taylor predictor of the tree coordinates ``(nt, 1)``."""
        q, qd, qdd = node.state
        return q + qd * h + 0.5 * qdd * h * h

    def correct(self, prediction, x):
        """Return Newton's :class:`continuation.Trial` from ``prediction`` at angle ``x``."""
        lk = self.linkage
        q, pose, res, iters, ok = lk.newton(np.array([x]), prediction)
        return continuation.Trial((q, pose), bool(ok[0]), float(res[0]),
                                  lk.scaled_change(q, prediction), int(iters[0]))

    def node(self, trial, x):
        """Return the :class:`continuation.Node` with the rates at unit crank speed."""
        lk = self.linkage
        q, pose = trial.solution
        rates = lk.rates(pose, 1.0, 0.0)
        return continuation.Node(x, (q, rates['qd'], rates['qdd']), float(rates['cond'][0]),
                                 lk._det_sign(pose))

    def sign_changed(self, x, h):
        """Refuse a sign change that persists down to the smallest steps: a singular crossing."""
        if abs(h) <= 2 * STEP_MIN_RAD:
            raise BranchError(
                f'crank angle {crank_angle_text(x, 4)} deg: the linkage passes '
                'a singular position here (the loop Jacobian changes sign); beyond it '
                'the assembly branch is not unique, so the cycle cannot be followed')

    def accept(self, start, node, h):
        """Return whether Newton keeps a segment's Hermite midpoint within trust, on the branch."""
        lk = self.linkage
        if not self.midpoint_check or not lk.nu:
            return True
        (q0, qd0, qdd0), (q1, qd1, qdd1) = start.state, node.state
        # quintic Hermite basis at t = 1/2: 1/2, 5/32, 1/64 (and mirrored for the end)
        pred = (0.5 * (q0 + q1) + 0.15625 * h * (qd0 - qd1)
                + 0.015625 * h * h * (qdd0 + qdd1))
        q_mid, pose_mid, _, _, ok = lk.newton(np.array([start.x + 0.5 * h]), pred)
        return (bool(ok[0]) and lk.scaled_change(q_mid, pred)
                <= MIDPOINT_TRUST_FRACTION * EVAL_TRUST
                and lk._det_sign(pose_mid) == node.sign)

    def warn(self, text):
        """Record the warning on the linkage."""
        self.linkage._warn(text)


def _all(flags):
    """Return ``flags.all()`` of a boolean array (a quarter of its cost on a cycle's worth)."""
    return np.count_nonzero(flags) == flags.size


def _filled(shape, value):
    """Return ``np.full(shape, value)`` of floats (without np.full's Python wrapper)."""
    out = np.empty(shape)
    out.fill(value)
    return out
