"""
Safe lower bounds for the balancing cone programs (Jansson 2004; Neumaier & Shcherbina 2004).

Every program is in Clarabel's standard form ``min q'x  s.t.  A x + s = b,  s in K``.  For a
dual point z in the dual cone K* and every feasible x, ``z's >= 0``, so ``z'b >= z'A x`` and

    q'x = (q + A'z)'x - z'A x >= -b'z + r'x,        r = q + A'z   (the dual residual).

If some optimal point lies in the box ``lo <= x <= hi``, then ``r'x >= sum_i min(r_i lo_i,
r_i hi_i)`` there, and

    L = -b'z + sum_i min(r_i lo_i, r_i hi_i)  <=  min q'x                    (1)

holds for *any* z in K*: the solver's dual point need not be optimal or even feasible
(A'z + q = 0 is never met exactly); the remaining residual is paid for with the box.  The
solver's z is first projected onto K* (a zero cone's dual is free, the non-negative orthant
and the second-order cone are self-dual), with the projection's own rounding pushed into
the cone's interior.  Finally (1) is evaluated in floating point; with u the unit round-off
and gamma_k = k u / (1 - k u) (Higham, Accuracy and Stability, Lemma 3.1) every computed
sum of k products is within gamma_k times the sum of the absolute products, so

    L_safe = fl(L) - 2 gamma_N (|b|'|z| + sum_i max(|lo_i|, |hi_i|) (|q_i| + (|A|'|z|)_i)
                                 + sum_i |min(r_i lo_i, r_i hi_i)|)

(N = rows + columns + 4) is a lower bound on the true optimum, assuming round-to-nearest and
no underflow.  An unbounded box side met by a residual of the wrong sign gives ``-inf``
(no bound).

The box must contain one optimal point; :func:`level_set_bounds` derives one from a feasible
design's objective value p (every optimal point has q'x <= p) when the explicit bounds leave
coordinates unbounded.
"""

from dataclasses import dataclass
import math

import numpy as np
import scipy.sparse as sp

UNIT_ROUNDOFF = np.finfo(float).eps / 2.0
"""u of IEEE double precision (round to nearest)."""
SVD_MARGIN = 1e-6
"""Relative margin on level-set reaches computed from singular vectors: it covers their
rounding (orthogonal to ~1e-15) for the directions kept."""
CONE_FAMILIES = ('zero', 'nonneg', 'soc')
"""The cones of the balancing programs, by name (Clarabel's ZeroConeT, NonnegativeConeT,
SecondOrderConeT)."""


def gamma(k):
    """Return gamma_k = k u / (1 - k u), the relative error bound of a k-term dot product."""
    ku = k * UNIT_ROUNDOFF
    if ku >= 1.0:
        return math.inf
    return ku / (1.0 - ku)


@dataclass(frozen=True)
class LowerBound:
    """A safe lower bound ``value`` on a cone program's optimum, and how it was obtained."""

    value: float              # L (safe: rounding error already subtracted); -inf: no bound
    dual_objective: float     # -b'z at the projected dual point
    residual_term: float      # sum_i min(r_i lo_i, r_i hi_i) (<= 0 up to round-off)
    rounding: float           # the subtracted floating-point error bound
    dual_residual: float      # max_i |r_i|
    projection_shift: float   # max |z - proj(z)|: how far the solver's dual was outside K*
    unbounded: tuple = ()     # coordinates with an infinite box side and a residual against it


def cone_list(cones):
    """Return ``[(family, dim)]`` from Clarabel cone objects or ``(family, dim)`` pairs."""
    out = []
    for c in cones:
        if isinstance(c, tuple):
            family, dim = c
        else:
            name = type(c).__name__
            family = {'ZeroConeT': 'zero', 'NonnegativeConeT': 'nonneg',
                      'SecondOrderConeT': 'soc'}.get(name)
            if family is None:
                raise ValueError(f'cones: got {name}, expected one of ZeroConeT, '
                                 'NonnegativeConeT, SecondOrderConeT')
            dim = int(str(c).split('(')[-1].rstrip(')')) if not hasattr(c, 'dim') else c.dim
        if family not in CONE_FAMILIES:
            raise ValueError(f'cones: got {family!r}, expected one of {", ".join(CONE_FAMILIES)}')
        out.append((family, int(dim)))
    return out


def project_dual(z, cones):
    """
    Return z projected onto the dual cone K* (every entry exactly inside, after rounding).

    Zero cone: its dual is the whole space (z unchanged).  Non-negative orthant: max(z, 0).
    Second-order cone {(t, v): ||v|| <= t}: the Euclidean projection, then t raised by the
    relative error bound of the computed norm so that ||v|| <= t holds exactly.
    """
    z = np.array(z, dtype=float)
    out = z.copy()
    k = 0
    for family, dim in cones:
        blk = out[k:k + dim]
        if family == 'nonneg':
            np.maximum(blk, 0.0, out=blk)
        elif family == 'soc':
            t, v = blk[0], blk[1:]
            nv = float(np.linalg.norm(v))
            if nv <= -t:
                blk[:] = 0.0
            elif nv > t:
                a = 0.5 * (t + nv)
                blk[0] = a
                blk[1:] = v * (a / nv)
            nv = float(np.linalg.norm(blk[1:]))
            blk[0] = max(blk[0], nv * (1.0 + 2.0 * gamma(dim + 2)))
        k += dim
    if k != z.size:
        raise ValueError(f'cones: total dimension {k}, expected {z.size} (the rows of A)')
    return out


REFINE_ROUNDS = 2
"""Rounds of :func:`refine_dual` tried by :func:`safe_lower_bound` (the best bound is kept)."""
REFINE_BELOW = 1e-8
"""No refinement when the residual term is below this fraction of max(1, |L|)."""
REFINE_SHARE = 1e-2
"""A coordinate is refined when its residual term is at least this share of the largest."""


def refine_dual(a, cones, z, r, cols, frozen=None):
    """
    Return z corrected so that the dual residual r vanishes on ``cols`` (least squares).

    Only the rows whose dual is free to move without leaving K* change: zero cones and the
    vector part of second-order cones (whose first entry is then raised to the new norm by
    :func:`project_dual`); a non-negative row or a cone's first entry stays.  The residual
    moves to the columns of those first entries (epigraph variables with a finite box).
    """
    a = _dense(a)
    movable = np.zeros(a.shape[0], dtype=bool)
    k = 0
    for family, dim in cones:
        if family == 'zero':
            movable[k:k + dim] = True
        elif family == 'soc':
            movable[k + 1:k + dim] = True
        k += dim
    if frozen is not None:
        movable &= ~frozen
    rows = np.flatnonzero(movable)
    sub = a[np.ix_(rows, cols)]               # (rows, cols)
    if not sub.size:
        return z
    step, *_ = np.linalg.lstsq(sub.T, -r[cols], rcond=None)
    out = np.array(z, dtype=float)
    out[rows] += step
    return out


def safe_lower_bound(q, a, b, cones, z, lo, hi):
    """
    Return the :class:`LowerBound` (1) of ``min q'x s.t. a x + s = b, s in K``.

    ``q`` (n,), ``a`` (m, n) dense or scipy sparse, ``b`` (m,), ``cones`` Clarabel cone
    objects or ``(family, dim)`` pairs in row order, ``z`` the solver's dual (m,) (any
    vector: it is projected), ``lo``/``hi`` (n,) a box (entries may be -inf/inf) that the
    caller guarantees to contain at least one optimal point.  Where a few coordinates with
    wide boxes dominate the residual term, :func:`refine_dual` removes their residual and
    the better of the bounds is returned (each is a bound).
    """
    cones = cone_list(cones)
    a = _dense(a)
    abs_a = np.abs(a)
    q_arr = np.asarray(q, dtype=float).ravel()
    best = _bound(q, a, b, cones, z, lo, hi, abs_a)
    z_now = np.asarray(z, dtype=float)
    idle, frozen = _idle_epigraphs(a, q_arr, cones, z_now)
    if idle is not None:      # a term the objective does not weight: its cone's dual is 0
        cand = _bound(q, a, b, cones, idle, lo, hi, abs_a)
        if cand.value > best.value:
            best, z_now = cand, idle
        else:
            frozen = None
    for _ in range(REFINE_ROUNDS):
        if best.terms is None or not np.isfinite(best.value) and not best.unbounded:
            break
        if np.isfinite(best.value) and \
                abs(best.residual_term) <= REFINE_BELOW * max(1.0, abs(best.value)):
            break   # the residual costs less than the solver's own accuracy: done
        share = np.abs(best.terms)
        cols = np.flatnonzero(share >= REFINE_SHARE * share.max()) if share.max() > 0 \
            else np.array([], dtype=int)
        cols = np.union1d(cols, np.array(best.unbounded, dtype=int))
        if not cols.size:
            break
        z_now = refine_dual(a, cones, project_dual(z_now, cones), best.r, cols, frozen)
        cand = _bound(q, a, b, cones, z_now, lo, hi, abs_a)
        if cand.value > best.value:
            best = cand
        else:
            break
    return LowerBound(best.value, best.dual_objective, best.residual_term, best.rounding,
                      best.dual_residual, best.projection_shift, best.unbounded)


def _idle_epigraphs(a, q, cones, z):
    """
    Return (z with the dual of every idle second-order cone set to 0, their rows) or Nones.

    A cone is idle when its first row is ``-t`` for one variable t that the objective does
    not weight (q_t = 0): ``t >= ||...||`` then only bounds t, whose box is wide (a norm
    the stage does not minimize), and the solver's small dual there costs r_t times it.
    """
    out = np.array(z, dtype=float)
    frozen = np.zeros(out.size, dtype=bool)
    k = 0
    for family, dim in cones:
        if family == 'soc':
            cols = np.flatnonzero(a[k])
            if cols.size == 1 and q[cols[0]] == 0.0:
                out[k:k + dim] = 0.0
                frozen[k:k + dim] = True
        k += dim
    return (out, frozen) if frozen.any() else (None, None)


@dataclass(frozen=True)
class _Work:
    value: float
    dual_objective: float
    residual_term: float
    rounding: float
    dual_residual: float
    projection_shift: float
    unbounded: tuple
    terms: np.ndarray
    r: np.ndarray


def _dense(a):
    """Return ``a`` as a dense float array (the balancing programs have at most ~1e4 entries)."""
    return a.toarray() if sp.issparse(a) else np.asarray(a, dtype=float)


def _bound(q, a, b, cones, z, lo, hi, abs_a):
    """Return the bound (1) at one dual point, with its terms and residual (a _Work)."""
    q = np.asarray(q, dtype=float).ravel()
    b = np.asarray(b, dtype=float).ravel()
    lo = np.asarray(lo, dtype=float).ravel()
    hi = np.asarray(hi, dtype=float).ravel()
    m, n = a.shape
    if q.size != n or b.size != m or lo.size != n or hi.size != n:
        raise ValueError(f'safe_lower_bound: shapes q {q.size}, A {a.shape}, b {b.size}, '
                         f'lo {lo.size}, hi {hi.size} do not match')
    if np.any(lo > hi):
        raise ValueError('safe_lower_bound: lo > hi, expected a box')
    z_raw = np.asarray(z, dtype=float).ravel()
    if not np.all(np.isfinite(z_raw)):
        return _Work(-math.inf, math.nan, math.nan, 0.0, math.inf, math.inf, (), None, None)
    zp = project_dual(z_raw, cones)
    dual_obj = -float(b @ zp)
    r = q + a.T @ zp
    with np.errstate(invalid='ignore'):
        t_lo = r * lo
        t_hi = r * hi
    t_lo = np.where(r == 0.0, 0.0, t_lo)
    t_hi = np.where(r == 0.0, 0.0, t_hi)
    terms = np.minimum(t_lo, t_hi)
    bad = tuple(int(i) for i in np.flatnonzero(~np.isfinite(terms)))
    shift = float(np.max(np.abs(zp - z_raw), initial=0.0))
    if bad:
        return _Work(-math.inf, dual_obj, -math.inf, 0.0, float(np.max(np.abs(r))), shift,
                     bad, np.where(np.isfinite(terms), terms, 0.0), r)
    resid_term = float(np.sum(terms))
    box = np.maximum(np.abs(lo), np.abs(hi))
    size = np.abs(q) + abs_a.T @ np.abs(zp)       # bounds |r_i| and its rounding error
    blind = (~np.isfinite(box)) & (size > 0.0)
    if blind.any():   # r_i computed 0 on an unbounded coordinate: its error is unbounded
        bad = tuple(int(i) for i in np.flatnonzero(blind))
        return _Work(-math.inf, dual_obj, resid_term, math.inf, float(np.max(np.abs(r))),
                     shift, bad, terms, r)
    k = m + n + 4
    err = (float(np.abs(b) @ np.abs(zp))
           + float(np.where(size > 0.0, box, 0.0) @ size)
           + float(np.sum(np.abs(terms))))
    rounding = 2.0 * gamma(k) * err * (1.0 + 4.0 * gamma(k))
    value = dual_obj + resid_term - rounding
    return _Work(float(value), dual_obj, resid_term, float(rounding),
                 float(np.max(np.abs(r), initial=0.0)), shift, (), terms, r)


def norm_bound(g, c, lo, hi):
    """
    Return an upper bound on ``||g y + c||`` over the box ``lo <= y <= hi`` (finite or inf).

    ``||c|| + sum_j ||g_j|| max(|lo_j|, |hi_j|)``, raised by its rounding error: the box of
    an epigraph variable ``t >= ||g y + c||`` that some optimal point attains.
    """
    g = np.atleast_2d(np.asarray(g, dtype=float))
    box = np.maximum(np.abs(np.asarray(lo, float)), np.abs(np.asarray(hi, float)))
    cols = np.linalg.norm(g, axis=0)
    with np.errstate(invalid='ignore'):
        spread = np.where(cols == 0.0, 0.0, cols * box)
    total = float(np.linalg.norm(np.asarray(c, float))) + float(np.sum(spread))
    return total * (1.0 + 4.0 * gamma(g.shape[0] + g.shape[1] + 2))


def level_set_bounds(mat, radius, lo, hi, centre=None, null_rel_tol=None):
    """
    Return (lo, hi, nulls): the infinite entries replaced by what ``||mat y|| <= radius`` implies.

    For the coordinates S whose box is unbounded and B the others,
    ``||mat_S y_S|| <= radius + sum_{j in B} ||mat_j|| max(|lo_j|, |hi_j|)``, so
    ``|y_i| <= that / sigma_min(mat_S)`` for i in S, with sigma_min lowered by its rounding
    error bound (sqrt(k) n u sigma_max).  ``radius`` is p / w_min for an objective
    ``sum w_k ||G_k y|| <= p`` and ``mat`` the stacked G_k (||mat y|| <= sum ||G_k y||).

    If mat_S is rank-deficient the bound needs ``centre`` (a design) and ``null_rel_tol``:
    singular directions below ``null_rel_tol`` sigma_max are taken as exact null directions
    of the objective (moving along them changes no term, so an optimal point shares the
    centre's component there; valid when the coordinates S enter no constraint but the
    objective), and ``|y_i - centre_i| <= (radius + rest + ||mat_S centre_S||) /
    sigma_r`` with sigma_r the least singular value above it.  ``nulls`` counts those
    directions (0 when none was assumed).
    """
    lo = np.array(lo, dtype=float)
    hi = np.array(hi, dtype=float)
    mat = np.atleast_2d(np.asarray(mat, dtype=float))
    free = ~(np.isfinite(lo) & np.isfinite(hi))
    if not free.any() or not math.isfinite(radius):
        return lo, hi, 0
    fixed = ~free
    rest = norm_bound(mat[:, fixed], np.zeros(mat.shape[0]), lo[fixed], hi[fixed]) \
        if fixed.any() else 0.0
    sv = np.linalg.svd(mat[:, free], compute_uv=False)
    k = mat.shape[0] + mat.shape[1]
    slack = math.sqrt(k) * k * UNIT_ROUNDOFF * float(sv[0] if sv.size else 0.0) * 4.0
    full = sv.size == int(free.sum()) and float(sv[-1]) - slack > 0.0 and \
        (null_rel_tol is None or sv[-1] > null_rel_tol * sv[0])
    if full:
        reach = (radius + rest) / (float(sv[-1]) - slack) * (1.0 + 8.0 * gamma(k))
        lo[free] = np.maximum(lo[free], -reach)
        hi[free] = np.minimum(hi[free], reach)
        return lo, hi, 0
    if centre is None or null_rel_tol is None or not sv.size:
        return lo, hi, 0
    keep = sv > null_rel_tol * sv[0]
    if not float(sv[keep][-1]) - slack > 0.0:
        return lo, hi, 0
    c = np.asarray(centre, dtype=float)[free]
    # y_S - c = V_r a (the null component is the centre's): ||S_r a|| <= big, so
    # |y_i - c_i| <= big sqrt(sum_j V_ij^2 / s_j^2), each direction by its own s_j
    _, _, vt = np.linalg.svd(mat[:, free], full_matrices=False)
    big = (radius + rest + float(np.linalg.norm(mat[:, free] @ c))) * (1.0 + 8.0 * gamma(k))
    weights = vt[keep] / (sv[keep] - slack)[:, None]
    reach = big * np.sqrt(np.sum(weights * weights, axis=0)) * (1.0 + SVD_MARGIN)
    lo[free] = np.maximum(lo[free], c - reach)
    hi[free] = np.minimum(hi[free], c + reach)
    return lo, hi, int(free.sum() - keep.sum())


def polytope_bounds(mat, radius, lo, hi, rel_tol):
    """
    Return (lo, hi): every coordinate bounded over ``{lo <= y <= hi, ||mat y|| <= radius}``.

    With ``mat = U S V'``, ``||mat y|| <= radius`` implies ``|v_j' y| <= radius / s_j`` for
    each right singular vector; the directions with ``s_j > rel_tol s_max`` and the box make
    a polytope, and each coordinate's range over it is a linear program (scipy HiGHS).  A
    direction the objective does not see (s_j below rel_tol) is bounded only where the box
    bounds the coordinates it moves, with both signs (the inertias of Table 12's null
    direction, each >= 0.25 I^o).  An unbounded program leaves the side infinite.
    """
    from scipy.optimize import linprog
    lo = np.array(lo, dtype=float)
    hi = np.array(hi, dtype=float)
    mat = np.atleast_2d(np.asarray(mat, dtype=float))
    if np.all(np.isfinite(lo) & np.isfinite(hi)) or not math.isfinite(radius):
        return lo, hi
    _, sv, vt = np.linalg.svd(mat, full_matrices=False)
    keep = sv > rel_tol * sv[0] if sv.size else sv > 0
    rows = vt[keep]
    cap = radius * (1.0 + SVD_MARGIN) / sv[keep]
    a_ub = np.vstack([rows, -rows])
    b_ub = np.concatenate([cap, cap])
    bounds = [(None if not np.isfinite(a) else a, None if not np.isfinite(b) else b)
              for a, b in zip(lo, hi)]
    n = lo.size
    out_lo, out_hi = lo.copy(), hi.copy()
    for i in range(n):
        for sign in (1.0, -1.0):
            if (sign > 0 and np.isfinite(lo[i])) or (sign < 0 and np.isfinite(hi[i])):
                continue
            c = np.zeros(n)
            c[i] = sign
            res = linprog(c, A_ub=a_ub, b_ub=b_ub, bounds=bounds, method='highs')
            if res.status != 0:
                continue
            # HiGHS meets its feasibility tolerance (1e-7): widen by it, relative to the box
            value = sign * res.fun
            slack = 1e-6 * (1.0 + abs(value))
            if sign > 0:
                out_lo[i] = value - slack
            else:
                out_hi[i] = value + slack
    return out_lo, out_hi


def relative_gap(primal, lower, floor=1.0):
    """Return (gap, relative gap): ``primal - lower`` (>= 0) over ``max(|primal|, floor)``."""
    gap = max(float(primal) - float(lower), 0.0)
    return gap, gap / max(abs(float(primal)), floor)


__all__ = ['cone_list', 'gamma', 'level_set_bounds', 'LowerBound', 'norm_bound',
           'polytope_bounds', 'project_dual', 'relative_gap', 'safe_lower_bound']
