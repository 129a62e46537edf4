"""
Safe lower bounds for the balancing cone programs (Jansson 2004; Neumaier & Shcherbina 2004).

For Clarabel's ``min q'x s.t. A x + s = b, s in K``, any z in K* and a box lo <= x <= hi
holding an optimum: ``L = -b'z + sum_i min(r_i lo_i, r_i hi_i) <= min q'x``, r = q + A'z (1),
with its rounding subtracted.  docs/balancing.md, "Certificates (safe lower bounds)".
"""

from dataclasses import dataclass, field
import math

from mech_balance import schema
import numpy as np
import scipy.sparse as sp

UNIT_ROUNDOFF = np.finfo(float).eps / 2.0
"""u of IEEE double precision (round to nearest)."""
SVD_MARGIN = 1e-6
"""Relative margin on level-set reaches computed from singular vectors (their rounding)."""
CONE_FAMILIES = ('zero', 'nonneg', 'soc')
"""The cones of the balancing programs, by name."""
GAP_FLOOR = 1.0
"""Relative gap = |primal - dual| / max(|primal|, |dual|, GAP_FLOOR) (normalized units)."""
CERTIFIED_GAP_REL = 1e-5
"""A stage is certified when its safe lower bound is finite and primal - L is at most this
fraction of max(|primal|, GAP_FLOOR) (``mech-balance balance`` exits 2 otherwise)."""


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
    terms: np.ndarray = field(default=None, repr=False, compare=False)  # min(r lo, r hi)
    r: np.ndarray = field(default=None, repr=False, compare=False)      # q + A'z


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
    """Return z projected onto the dual cone K* (every entry exactly inside, after rounding)."""
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


REFINE_ROUNDS = 3
"""Rounds of :func:`refine_dual` tried by every bound, the best bound kept."""
REFINE_BELOW = 1e-8
"""No refinement when the residual term is below this fraction of max(1, |L|)."""
REFINE_SHARE = 1e-2
"""A coordinate is refined when its residual term is at least this share of the largest."""


def refine_dual(a, z, r, cols, weight, rot=None):
    """
    Return z + Delta: the least ``sum w_i Delta_i^2`` with ``(A'Delta)_j = -r_j`` on ``cols``.

    ``weight`` (m,): ``inf`` keeps a row; ``rot`` (m, m) orthogonal: the basis of the weights.
    """
    a = _dense(a)
    rows = np.flatnonzero(np.isfinite(weight))
    basis = a if rot is None else rot.T @ a
    root = np.sqrt(np.asarray(weight, dtype=float)[rows])
    sub = basis[rows][:, cols] / root[:, None]
    out = np.array(z, dtype=float)
    if not sub.size:
        return out
    step, *_ = np.linalg.lstsq(sub.T, -np.asarray(r, dtype=float)[cols], rcond=None)
    delta = np.zeros(a.shape[0])
    delta[rows] = step / root
    return out + (delta if rot is None else rot @ delta)


def _movable(cones, frozen=None):
    """Return the weight of :func:`refine_dual` that moves only the rows free within K*."""
    total = sum(dim for _, dim in cones)
    movable = np.zeros(total, dtype=bool)
    k = 0
    for family, dim in cones:
        if family == 'zero':
            movable[k:k + dim] = True
        elif family == 'soc':
            movable[k + 1:k + dim] = True
        k += dim
    if frozen is not None:
        movable &= ~frozen
    return np.where(movable, 1.0, np.inf)


def safe_lower_bound(q, a, b, cones, z, lo, hi):
    """
    Return the :class:`LowerBound` (1) of ``min q'x s.t. a x + s = b, s in K``.

    ``cones``: Clarabel cones or ``(family, dim)`` pairs in row order; ``z``: any dual (it is
    projected and refined); ``lo``/``hi`` (n,): a box (may be infinite) holding an optimum.
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
    weight = _movable(cones, frozen)
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
        z_now = refine_dual(a, project_dual(z_now, cones), best.r, cols, weight)
        cand = _bound(q, a, b, cones, z_now, lo, hi, abs_a)
        if cand.value > best.value:
            best = cand
        else:
            break
    return best


def _idle_epigraphs(a, q, cones, z):
    """Return (z with each unweighted epigraph cone's dual set to 0, their rows) or Nones."""
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


def _dense(a):
    """Return ``a`` as a dense float array (the balancing programs have at most ~1e4 entries)."""
    return a.toarray() if sp.issparse(a) else np.asarray(a, dtype=float)


def _bound(q, a, b, cones, z, lo, hi, abs_a):
    """Return the :class:`LowerBound` (1) at one dual point, with its terms and residual."""
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
        return LowerBound(-math.inf, math.nan, math.nan, 0.0, math.inf, math.inf)
    zp = project_dual(z_raw, cones)
    dual_obj = -float(b @ zp)
    r = q + a.T @ zp
    with np.errstate(invalid='ignore'):
        terms = np.where(r == 0.0, 0.0, np.minimum(r * lo, r * hi))
    bad = tuple(int(i) for i in np.flatnonzero(~np.isfinite(terms)))
    shift = float(np.max(np.abs(zp - z_raw), initial=0.0))
    if bad:
        return LowerBound(-math.inf, dual_obj, -math.inf, 0.0, float(np.max(np.abs(r))),
                          shift, bad, np.where(np.isfinite(terms), terms, 0.0), r)
    resid_term = float(np.sum(terms))
    box = np.maximum(np.abs(lo), np.abs(hi))
    size = np.abs(q) + abs_a.T @ np.abs(zp)       # bounds |r_i| and its rounding error
    blind = (~np.isfinite(box)) & (size > 0.0)
    if blind.any():   # r_i computed 0 on an unbounded coordinate: its error is unbounded
        bad = tuple(int(i) for i in np.flatnonzero(blind))
        return LowerBound(-math.inf, dual_obj, resid_term, math.inf,
                          float(np.max(np.abs(r))), shift, bad, terms, r)
    k = m + n + 4
    err = (float(np.abs(b) @ np.abs(zp))
           + float(np.where(size > 0.0, box, 0.0) @ size)
           + float(np.sum(np.abs(terms))))
    rounding = 2.0 * gamma(k) * err * (1.0 + 4.0 * gamma(k))
    value = dual_obj + resid_term - rounding
    return LowerBound(float(value), dual_obj, resid_term, float(rounding),
                      float(np.max(np.abs(r), initial=0.0)), shift, (), terms, r)


def norm_bound(g, c, lo, hi):
    """Return ``||c|| + sum_j ||g_j|| max(|lo_j|, |hi_j|)`` (rounded up) >= ``||g y + c||``."""
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

    A rank-deficient ``mat`` needs ``centre`` and ``null_rel_tol`` (``nulls``: directions taken).
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
    """Return (lo, hi): each coordinate's range over ``{lo <= y <= hi, ||mat y|| <= radius}``."""
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


SVEC = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2), (0, 3), (1, 3), (2, 3), (3, 3))
"""Clarabel's PSDTriangleConeT order of a 4x4 matrix: the upper triangle by columns."""
POWER_ALPHA = 0.6
"""The power cone x^alpha y^(1 - alpha) >= |z| of the spheres' least spread (5/3 = 1/alpha)."""


def folded_lower_bound(run, lo, hi):
    """Return (value, LowerBound, fold rounding): the safe lower bound with PSD and power cones."""
    z = np.asarray(run.sol.z, dtype=float)
    best = _fold_at(run, z, lo, hi)
    if not (math.isfinite(best[0]) and
            abs(best[1].residual_term) <= REFINE_BELOW * max(1.0, abs(best[0]))):
        for cand in _slack_weighted_duals(run, z):
            out = _fold_at(run, cand, lo, hi)
            if out[0] > best[0]:
                best = out
    return best


REFINE_WEIGHT_FLOOR = 1e-10
"""The least weight of a dual entry in :func:`_slack_weighted_duals` (x the largest slack)."""


def _slack_weighted_duals(run, z):
    """Return the dual points of :data:`REFINE_ROUNDS` slack-weighted rounds of refine_dual."""
    a = sp.csr_matrix(run.a).toarray()
    m = a.shape[0]
    s = np.asarray(run.sol.s, dtype=float)
    if s.size != m or not np.all(np.isfinite(s)) or not np.all(np.isfinite(z)):
        return []
    floor = REFINE_WEIGHT_FLOOR * max(float(np.abs(s).max(initial=0.0)), 1e-300)
    rot = np.eye(m)
    weight = np.full(m, floor)
    start = 0
    for cone, n in run.layout:
        rows = slice(start, start + n)
        blk = s[rows]
        if cone == 'nonneg':
            weight[rows] += np.maximum(blk, 0.0)
        elif cone == 'psd':
            vals, vecs = np.linalg.eigh(_smat(blk))
            vals = np.maximum(vals, 0.0)
            basis = np.zeros((n, n))
            for col, (i, j) in enumerate(SVEC):
                e = np.outer(vecs[:, i], vecs[:, j])
                e = e if i == j else (e + e.T) / math.sqrt(2.0)
                basis[:, col] = _svec(e)
                weight[start + col] += 0.5 * (vals[i] + vals[j])
            rot[rows, rows] = basis
        elif cone != 'zero':
            weight[rows] += float(np.linalg.norm(blk))
        start += n
    cols = np.arange(a.shape[1])
    out = []
    for _ in range(REFINE_ROUNDS):
        zp = _project_all(z, run)
        z = refine_dual(a, zp, run.q + a.T @ zp, cols, weight, rot)
        if not np.all(np.isfinite(z)):
            break
        out.append(z)
    return out


def _project_all(z, run):
    """Return z with every block moved into its dual cone (as the certificate does)."""
    out = _compress(np.array(z, dtype=float), run)
    start = 0
    for cone, n in run.layout:
        rows = slice(start, start + n)
        out[rows] = DUAL_CONES[cone](out[rows]) if cone in DUAL_CONES else \
            project_dual(out[rows], [(cone, n)])
        start += n
    return out


STRUCTURAL_RANK_REL = 1e-12
"""Singular values of a PSD block's matrices below this fraction of the largest are null."""


def _psd_ranges(run):
    """Return ``{first row: P}``: the projector onto a rank-deficient PSD block's range."""
    cached = getattr(run, 'psd_ranges', None)
    if cached is not None:
        return cached
    a = sp.csc_matrix(run.a)
    out, start = {}, 0
    for cone, n in run.layout:
        if cone == 'psd':
            blk = a[start:start + n].toarray()
            mats = [_smat(col) for col in blk.T if np.any(col)]
            if mats:
                u, sv, _ = np.linalg.svd(np.hstack(mats))
                rank = int(np.sum(sv > STRUCTURAL_RANK_REL * sv[0])) if sv[0] > 0 else 0
                if rank < 4:
                    out[start] = u[:, :rank] @ u[:, :rank].T
        start += n
    run.psd_ranges = out
    return out


def _compress(z, run):
    """Return z with each rank-deficient PSD block's dual compressed onto its range."""
    ranges = _psd_ranges(run)
    if not ranges:
        return z
    z = np.array(z, dtype=float)
    for start, proj in ranges.items():
        z[start:start + 10] = _svec(proj @ _smat(z[start:start + 10]) @ proj)
    return z


def _smat(v):
    """Return the symmetric 4x4 matrix of a Clarabel svec (off-diagonals over sqrt(2))."""
    m = np.zeros((4, 4))
    for x, (i, j) in zip(v, SVEC):
        m[i, j] = m[j, i] = x if i == j else x / math.sqrt(2.0)
    return m


def _svec(m):
    """Return Clarabel's svec of a symmetric 4x4 matrix (off-diagonals times sqrt(2))."""
    return np.array([m[i, j] if i == j else m[i, j] * math.sqrt(2.0) for i, j in SVEC])


def _fold_at(run, z, lo, hi):
    """Return (value, LowerBound, fold rounding) of :func:`folded_lower_bound` at a dual point."""
    q, a, b = run.q, sp.csr_matrix(run.a), run.b
    z = _compress(z, run)
    keep, rest_cones, fold_rows, fold_z = [], [], [], []
    start = 0
    for kind, n in run.layout:
        rows = np.arange(start, start + n)
        start += n
        if kind in DUAL_CONES:
            zb = DUAL_CONES[kind](z[rows])
            fold_rows.append(rows)
            fold_z.append(zb)
        else:
            keep.append(rows)
            rest_cones.append((kind, n))
    shift, fold_err = 0.0, 0.0
    qf = q.copy()
    if fold_rows:
        rows = np.concatenate(fold_rows)
        zf = np.concatenate(fold_z)
        ap = a[rows]
        qf = q + ap.T @ zf
        shift = -float(b[rows] @ zf)
        box = np.maximum(np.abs(lo), np.abs(hi))
        k = rows.size + q.size + 4
        term = abs(ap).T @ np.abs(zf)
        fold_err = 2.0 * gamma(k) * (
            float(np.abs(b[rows]) @ np.abs(zf))
            + float(np.where(term > 0.0, box, 0.0) @ term))
    rows = np.concatenate(keep)
    bound = safe_lower_bound(qf, a[rows], b[rows], rest_cones, z[rows], lo, hi)
    value = bound.value + shift - fold_err
    return value, bound, fold_err


def _dual_psd(zb):
    """Return the svec of a PSD matrix nearest the svec ``zb`` (raised by its rounding)."""
    vals, vecs = np.linalg.eigh(_smat(zb))
    vals = np.clip(vals, 0.0, None)
    m = (vecs * vals) @ vecs.T
    m += (64.0 * np.finfo(float).eps * max(float(vals.max(initial=0.0)), 1e-300)) * np.eye(4)
    while np.linalg.eigvalsh(m)[0] < 0.0:     # pragma: no cover - the shift above suffices
        m += np.finfo(float).eps * np.abs(m).max() * 16.0 * np.eye(4)
    return _svec(m)


def _dual_pow(zb, alpha):
    """Return a point of the dual power cone near ``zb`` (u, v raised until it is inside)."""
    u, v, w = (float(x) for x in zb)
    tiny = 1e-300
    u, v = max(u, tiny), max(v, tiny)
    value = (u / alpha) ** alpha * (v / (1.0 - alpha)) ** (1.0 - alpha)
    if value < abs(w):
        grow = abs(w) / value * (1.0 + 1e-12)
        u, v = u * grow, v * grow
    return np.array([u, v, w])


DUAL_CONES = {'psd': lambda z: _dual_psd(z), 'pow': lambda z: _dual_pow(z, POWER_ALPHA)}
"""The cones folded first, and how a dual point is moved into each one's dual cone."""


@dataclass
class Certificate:
    """Global-optimality certificate of a balancing cone program: ``lower_bound`` <= ``primal``."""

    solver: str
    status: str
    primal: float          # z of the returned design (normalized units)
    dual: float            # = lower_bound (backward-compatible key)
    gap_abs: float         # primal - lower_bound (>= 0)
    gap_rel: float         # gap_abs / max(|primal|, GAP_FLOOR)
    residual_primal: float
    residual_dual: float
    iterations: int
    stage2: dict = None    # the tie-break program, if one was solved
    max_violation: float = 0.0  # worst constraint violation of the solver's design
    lower_bound: float = None
    attempts: list = None  # status of every solver attempt of the primary stage
    bound_detail: dict = None
    feasibility_pull: float = 0.0  # fraction pulled towards the interior anchor
    failed_stages: list = None     # stages that did not end Solved/AlmostSolved
    certified: bool = False        # lower bound finite and gap_rel <= CERTIFIED_GAP_REL
    design_violation: float = 0.0  # worst violation of the design reported (0: feasible)

    def to_dict(self):
        """Return the certificate as a plain dict."""
        return schema.plain(self.__dict__)


@dataclass
class Stage:
    """One solved stage of a balancing cone program: its point, objective and solver figures."""

    point: np.ndarray          # the design variables at the solver's point
    objective: float           # q'x
    run: object                # mech_balance.conic.Solve: the data, statuses and solution
    status: str = field(init=False)
    iterations: int = field(init=False)
    r_prim: float = field(init=False)
    r_dual: float = field(init=False)
    seconds: float = field(init=False)

    def __post_init__(self):
        """Read the solver's figures from ``run``."""
        sol = self.run.sol
        self.status, self.seconds = self.run.status, self.run.seconds
        self.iterations, self.r_prim, self.r_dual = \
            int(sol.iterations), float(sol.r_prim), float(sol.r_dual)


def certify(stage, primal, bound, violation, pull, failed, design_violation, stage2=None,
            **detail):
    """
    Return the :class:`Certificate` of a primary :class:`Stage` whose design has z ``primal``.

    ``violation``: before the ``pull``; ``detail``: entries added to :func:`bound_detail`.
    """
    import clarabel
    lower = min(bound.value, primal)
    gap, gap_rel = relative_gap(primal, lower, GAP_FLOOR)
    return Certificate(
        solver=f'clarabel {clarabel.__version__}', status=stage.status, primal=primal,
        dual=lower, gap_abs=gap, gap_rel=gap_rel, residual_primal=stage.r_prim,
        residual_dual=stage.r_dual, iterations=stage.iterations, stage2=stage2,
        max_violation=violation, lower_bound=lower, attempts=list(stage.run.attempts),
        bound_detail=dict(bound_detail(bound), **detail), feasibility_pull=pull,
        failed_stages=failed, design_violation=design_violation,
        certified=bool(np.isfinite(lower) and gap_rel <= CERTIFIED_GAP_REL
                       and design_violation == 0.0))


def failed_stage(stage, run, design, blame=''):
    """Return the report entry of a stage whose solve failed (name, status, why, design)."""
    return {'stage': stage, 'status': run.status, 'reason': run.why() + blame,
            'design': design}


def bound_detail(bound):
    """Return the terms of a :class:`LowerBound` as the certificate's ``bound_detail``."""
    return {'dual_objective': bound.dual_objective, 'residual_term': bound.residual_term,
            'rounding': bound.rounding, 'dual_residual': bound.dual_residual,
            'projection_shift': bound.projection_shift,
            'unbounded_variables': list(bound.unbounded)}


__all__ = ['bound_detail', 'Certificate', 'CERTIFIED_GAP_REL', 'certify', 'cone_list',
           'failed_stage', 'folded_lower_bound', 'gamma', 'GAP_FLOOR', 'level_set_bounds',
           'LowerBound', 'norm_bound', 'polytope_bounds', 'POWER_ALPHA', 'project_dual',
           'relative_gap', 'safe_lower_bound', 'Stage', 'SVEC']
