"""Predictor-corrector branch tracing in the input coordinate: docs/core.md#branch-tracing."""

from dataclasses import dataclass
import math

__all__ = ['Branch', 'Limits', 'Node', 'Trial', 'advance']


@dataclass(frozen=True)
class Limits:
    """The step control of one continuation (input units: rad, or m for a slide)."""

    step_max: float           # largest step
    step_min: float           # a step halved below this loses the branch
    step_done: float          # what may remain of the goal when it counts as reached
    step_trust: float         # largest scaled Newton correction of an accepted step
    cond_limit: float         # largest condition number of an accepted node
    cond_warn: float = math.inf   # a node above this is reported near-singular
    first_step: float = None  # the first step (None: step_max)
    growth: float = 1.5       # step factor after an accepted step
    grow_max_iterations: int = None  # grow only after at most this many Newton iterations


@dataclass
class Trial:
    """A corrected predictor: the branch's solution and how Newton fared."""

    solution: object     # what Branch.node needs (the branch's own arrays)
    ok: bool             # Newton converged
    residual: float      # its scaled residual
    correction: float    # how far it moved the predictor (scaled)
    iterations: int = 0


@dataclass
class Node:
    """A solved point of the branch at input coordinate ``x``, with its rates."""

    x: float
    state: tuple         # the branch's own arrays (coordinates and rates)
    cond: float          # scaled Jacobian condition number
    sign: float          # sign of the Jacobian's determinant


class Branch:
    """What a core supplies to :func:`advance` (the hooks with a default may be kept)."""

    error = ValueError

    def where(self, x, digits=4):
        """Return where the input coordinate is ``x``, in words."""
        raise NotImplementedError

    def predict(self, node, h):
        """Return the predicted position ``h`` along the branch from ``node``."""
        raise NotImplementedError

    def correct(self, prediction, x):
        """Return the :class:`Trial` of Newton from ``prediction`` at input ``x``."""
        raise NotImplementedError

    def node(self, trial, x):
        """Return the :class:`Node` at a converged trial (its rates, condition, sign)."""
        raise NotImplementedError

    def accept(self, start, node, h):
        """Return whether the step from ``start`` to ``node`` holds by the branch's own test."""
        return True

    def sign_changed(self, x, h):
        """Handle a step to ``x`` across a determinant sign change (default: halve it)."""

    def warn(self, text):
        """Report a near-singular node."""


def advance(branch, start, goal, limits, sign=None):
    """
    Follow ``branch`` from the node ``start`` by ``goal`` (signed); yield each new node.

    ``sign`` is the branch's determinant sign (None: not checked, e.g. a redundant
    linkage).  Raises ``branch.error`` naming where the branch was lost.
    """
    node = start
    end = start.x + goal
    first = limits.step_max if limits.first_step is None else limits.first_step
    h = math.copysign(min(first, abs(goal)), goal)
    cond = math.inf
    while abs(end - node.x) > limits.step_done:
        if abs(h) > abs(end - node.x):
            h = end - node.x
        x = node.x + h
        trial = branch.correct(branch.predict(node, h), x)
        good = trial.ok and trial.correction <= limits.step_trust
        if good:
            new = branch.node(trial, x)
            cond = new.cond
            good = math.isfinite(cond) and cond <= limits.cond_limit
        if good and sign is not None and new.sign != sign:
            good = False
            branch.sign_changed(x, h)
        elif good:
            good = branch.accept(node, new, h)
        if not good:
            h *= 0.5
            if abs(h) < limits.step_min:
                raise branch.error(
                    f'{branch.where(node.x)}: cannot continue the assembly branch (Newton '
                    f'residual {trial.residual:.2e}, Jacobian condition {cond:.3g}); the '
                    'linkage cannot be assembled beyond this position, or reaches a singular '
                    'position where its branch is not unique')
            continue
        node = new
        if cond > limits.cond_warn:
            branch.warn(f'{branch.where(x, 3)}: near-singular position (Jacobian condition '
                        f'number {cond:.3g} > {limits.cond_warn:.4g})')
        if limits.grow_max_iterations is None or trial.iterations <= limits.grow_max_iterations:
            h = math.copysign(min(limits.growth * abs(h), limits.step_max), goal)
        yield node
