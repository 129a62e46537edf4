"""The assembly branch of a spatial linkage: its trace, its dense nodes and the predictor."""

import math

from mech_balance.core import continuation
from mech_balance.core.planar.kinematics import COND_WARN
from mech_balance.rotations import expmap, EYE3, TWO_PI
import numpy as np

COND_LIMIT = 1e10
"""Scaled Jacobian condition number above which a position is refused as singular."""
# a prismatic input's steps are these times its half stroke (m)
STEP_MAX_RAD = math.radians(10.0)
"""Largest crank step between branch nodes."""
STEP_MIN_RAD = 1e-7
"""Smallest crank step before the continuation declares the branch lost."""
STEP_DONE = 1e-13
"""What is left of a continuation's goal when it counts as reached (rad)."""
STEP_TRUST = 0.05
"""Largest scaled Newton correction accepted in a continuation step (else the step halves)."""
EVAL_TRUST = 1e-3
"""Largest scaled correction from the branch predictor before an angle is re-traced."""
CLOSURE_TOL = 1e-7
"""Largest scaled pose mismatch after one traced turn for the branch to count as closed."""
DENSE_STEP_RAD = math.radians(1.0)
"""Spacing of the dense branch nodes the batched evaluation predicts from."""


class SpatialError(ValueError):
    """The spatial linkage cannot be assembled, is singular, or would leave its branch."""


class BranchFollowing:
    """The traced branch of :class:`~mech_balance.core.spatial.kinematics.Linkage` (a mixin)."""

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

    def change(self, q, sph, q_ref, sph_ref):
        """Return per sample the largest scaled change of ``(q, sph)`` but the input's."""
        s = self.scalar_dofs[1:]
        out = np.max(np.abs(q - q_ref)[:, s] / self.col_scale[s], axis=1, initial=0.0)
        if not self.sph_index:
            return out
        diff = np.matmul(np.swapaxes(sph_ref, -1, -2), sph) - EYE3   # spherical joints
        return np.maximum(out, np.max(np.abs(diff), axis=(1, 2, 3)))

    def _advance(self, start, goal):
        """Yield the nodes from ``start`` to ``goal`` along the input (:mod:`continuation`)."""
        limits = continuation.Limits(
            step_max=self.step_max, step_min=self.step_min,
            step_done=STEP_DONE * self.input_scale, step_trust=STEP_TRUST,
            cond_limit=COND_LIMIT, cond_warn=COND_WARN)
        return continuation.advance(_SpatialBranch(self), start, goal, limits,
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
            self._dense = sk           # the traced nodes only if a dense node leaves the branch
            if not bad.any():
                q[:, 0] = psi
                rates = self.unit_rates(fr, q)
                if not (self.square and np.any(rates.sign != self.branch_sign)):
                    self._dense = Skeleton(psi, q, sph, rates.qd, rates.qdd, rates.cond,
                                           self.periodic)
        return self._dense


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
    """Branch nodes (a turn, or the stroke) and a second-order predictor from the nearest."""

    def __init__(self, psi, q, sph, qd, qdd, cond, periodic=True):
        self.psi, self.q, self.sph, self.qd, self.qdd, self.cond = psi, q, sph, qd, qdd, cond
        self.offset = psi - psi[0]
        self.periodic = periodic

    def nearest(self, psi):
        """Return the nearest node's index and the signed step from it, per coordinate."""
        x = np.mod(psi - self.psi[0], TWO_PI) if self.periodic else psi - self.psi[0]
        k = np.searchsorted(self.offset, x, side='right') - 1
        k = np.clip(k, 0, self.psi.size - 2)
        k = np.where((self.offset[k + 1] - x) < (x - self.offset[k]), k + 1, k)
        h = x - self.offset[k]
        if self.periodic:   # the last node is the first turned once
            k = np.where(k == self.psi.size - 1, 0, k)
        return k, h
