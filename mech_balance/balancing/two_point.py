"""
Seed 001 Appendix B: the two-point-mass model of a link, and Table 12's comparison.

:func:`table12`: the certified three-point relaxation (a LOWER bound), a verified two-point
design (an UPPER bound); docs/balancing.md, "Chaudhary & Saha Table 12: two point masses".
"""

from dataclasses import dataclass
import itertools
import math
import time

from mech_balance import conic, schema
from mech_balance.analysis import linear_maps
from mech_balance.balancing import certificate, checks, conditioning
from mech_balance.balancing.redistribution import ConeRows
import numpy as np

PAPER_MASS_FACTORS = (1.0, 5.0)
"""seed 001 eqs. B.2 / B.4: m^o <= m <= 5 m^o."""
PAPER_INERTIA_FACTOR = 0.25
"""seed 001 eqs. B.3 / B.5: I_O >= 0.25 I^o (no upper bound)."""
SCP_ITERATIONS = 30
"""Sequential convex programs per choice of pieces, at most."""
SCP_TOL = 1e-10
"""Stop when z changes by less than this fraction between two programs."""
BAND_REL_TOL = 1e-9
"""A link is representable by two point masses if m I_O is outside the band by -this x
(|hx| + |hy|)^2 (round-off of an optimum on its edge)."""
MAX_BAND_LINKS = 4
"""Links in the band at R's optimum beyond which the choices are not all tried (2^k)."""


@dataclass
class TwoPointResult:
    """Table 12 for one scene and weighting: both bounds, designs and RMS values."""

    scene: str
    weights: tuple
    lower_bound_z: float          # safe lower bound of the relaxation (three-point model)
    lower_bound_dual: float       # = lower_bound_z (backward-compatible key)
    lower_bound_gap_rel: float    # (relaxation_z - lower_bound_z) / max(relaxation_z, 1)
    lower_terms: dict             # f~, n~, tau~ of the relaxation's optimum
    upper_bound_z: float          # best two-point design found (feasible, verified)
    upper_terms: dict
    gap_rel: float                # (upper - lower) / max(upper, 1)
    point_masses: dict            # link -> {m_1, m_2, l_1, l_2} (normalized) of the upper
    band_links: tuple             # links R's optimum leaves unrepresentable
    programs: int
    seconds: float
    relaxation_z: float = None    # z of the relaxation's design (feasible, clipped)
    failed_programs: list = None  # sequential programs that ended without a point, and why
    upper_feasibility_tol: float = 0.0  # the solver's feasibility tolerance at the upper design

    def to_dict(self):
        """Return the result as a plain dict."""
        return schema.plain(self.__dict__)


def representable(theta, rel_tol=BAND_REL_TOL):
    """Return per link whether (m, hx, hy, I_O) rows of ``theta`` lie in P or N."""
    t = np.asarray(theta, dtype=float).reshape(-1, 4)
    m, hx, hy, i_o = t.T
    hi = (np.abs(hx) + np.abs(hy)) ** 2
    lo = (np.abs(hx) - np.abs(hy)) ** 2
    slack = rel_tol * np.maximum(hi, 1e-300)
    return (m * i_o >= hi - slack) | (m * i_o <= lo + slack)


def point_masses(m, hx, hy, i_o):
    """Return (m_1, m_2, l_1, l_2) of a link in P or N (seed 001 Table 11, theta = 0, pi/2)."""
    b = hy * hy - hx * hx - i_o * m
    disc = max(b * b - 4.0 * i_o * hx * hx * m, 0.0)
    roots = [(-b + s * math.sqrt(disc)) / (2.0 * i_o) for s in (1.0, -1.0)]
    inside = [r for r in roots if 0.0 < r < m]
    m1 = inside[0] if inside else roots[0]
    m2 = m - m1
    return m1, m2, hx / m1 if m1 else 0.0, hy / m2 if m2 else 0.0


def table12(scene, weights=(0.5, 0.5), samples=None):
    """Return the :class:`TwoPointResult` of seed 001 eqs. B.1-B.5 for a planar scene."""
    t_start = time.perf_counter()
    w = np.array([float(weights[0]), float(weights[1])])
    maps = linear_maps.linear_maps(scene, samples, ('shaking_wrench', 'driving_torque'))
    theta0 = maps.theta_original.reshape(-1, 4)
    n = theta0.shape[0]
    m0, i0 = theta0[:, 0], theta0[:, 3]
    dsc = np.column_stack([m0, np.sqrt(m0 * i0), np.sqrt(m0 * i0), i0]).ravel()
    blame = conditioning.blame(scene, scene.normalization, scene.crank_speed_rad_s)
    try:
        lower = _program(maps, dsc, w, n, ['free'] * n, None)
    except checks.BalanceError as exc:
        raise checks.BalanceError(f'{exc}{blame}') from None
    programs, failed = 1, []
    y_r = lower['theta']
    band = [i for i, ok in enumerate(representable(y_r)) if not ok]
    best = None
    if not band:
        best = lower
    else:
        tried = band[:MAX_BAND_LINKS]
        for choice in itertools.product(('P', 'N'), repeat=len(tried)):
            pieces = _initial_pieces(y_r)
            for i, c in zip(tried, choice):
                pieces[i] = 'P' if c == 'P' else _n_piece(y_r[4 * i:4 * i + 4])
            theta, z_prev = y_r, math.inf
            for _ in range(SCP_ITERATIONS):
                try:
                    sol = _program(maps, dsc, w, n, pieces, theta)
                except checks.BalanceError as exc:
                    failed.append(f'pieces {choice}: {exc}')
                    break
                programs += 1
                theta = sol['theta']
                if all(representable(theta)) and (best is None or sol['z'] < best['z']):
                    best = sol
                if abs(z_prev - sol['z']) <= SCP_TOL * max(abs(sol['z']), 1.0):
                    break
                z_prev = sol['z']
    if best is None:
        raise checks.BalanceError('two-point model: no sequential cone program found a '
                                  'two-point design (every piece failed or left the set)'
                                  f'{blame}')
    t, feas_tol = _clipped(best['theta'].reshape(-1, 4), m0, i0, best['feasibility_tol'])
    pm = {lk.name: dict(zip(('m_1', 'm_2', 'l_1', 'l_2'), point_masses(*row)))
          for lk, row in zip(scene.links, t)}
    # verify: the point masses give back the parameters, and the core evaluates the design
    rebuilt = [v for p in pm.values() for v in _rebuild(p)]
    if feas_tol < conic.SOLVER_TOL:   # clipped: repair the rebuild's round-off
        pm, rebuilt = _repaired(pm, m0, i0)
    upper_terms = _terms(maps, np.array(rebuilt))
    lower_terms = _terms(maps, lower['theta'])
    z_up = float(w @ [upper_terms['shaking_force'], upper_terms['shaking_moment']])
    z_lo = min(lower['lower'].value, lower['z'], z_up)   # safe: below both designs
    return TwoPointResult(
        scene=scene.name, weights=tuple(w), lower_bound_z=z_lo,
        lower_bound_dual=z_lo,
        lower_bound_gap_rel=certificate.relative_gap(lower['z'], z_lo)[1],
        lower_terms=lower_terms, upper_bound_z=z_up, upper_terms=upper_terms,
        gap_rel=(z_up - z_lo) / max(abs(z_up), 1.0), point_masses=pm,
        band_links=tuple(scene.links[i].name for i in band), programs=programs,
        seconds=time.perf_counter() - t_start, relaxation_z=lower['z'],
        failed_programs=failed, upper_feasibility_tol=feas_tol)


def _clipped(t, m0, i0, solver_tol):
    """Return the upper design moved into the bounds B.2-B.3 where it stays representable, tol."""
    c = t.copy()
    c[:, 0] = np.clip(c[:, 0], PAPER_MASS_FACTORS[0] * m0, PAPER_MASS_FACTORS[1] * m0)
    c[:, 3] = np.maximum(c[:, 3], PAPER_INERTIA_FACTOR * i0)
    if np.all(representable(c)):
        return c, 4.0 * np.finfo(float).eps   # the test's conversion to SI: a few ulp
    return t, solver_tol


def _rebuild(p):
    """Return a link's (m, hx, hy, I_O) from its point masses."""
    return [p['m_1'] + p['m_2'], p['m_1'] * p['l_1'], p['m_2'] * p['l_2'],
            p['m_1'] * p['l_1'] ** 2 + p['m_2'] * p['l_2'] ** 2]


def _repaired(pm, m0, i0):
    """Return point masses whose rebuilt parameters meet B.2-B.3 exactly, and those parameters."""
    margin = 1.0 + 8.0 * np.finfo(float).eps
    out, rebuilt = {}, []
    for (name, p), mo, io in zip(pm.items(), m0, i0):
        p = dict(p)
        for _ in range(4):
            m, _, _, i_o = _rebuild(p)
            lo, hi = PAPER_MASS_FACTORS[0] * mo, PAPER_MASS_FACTORS[1] * mo
            if m < lo or m > hi:
                k = (lo * margin if m < lo else hi / margin) / m
                p['m_1'], p['m_2'] = p['m_1'] * k, p['m_2'] * k
                continue
            if i_o < PAPER_INERTIA_FACTOR * io:
                k = math.sqrt(PAPER_INERTIA_FACTOR * io / i_o) * margin
                p['l_1'], p['l_2'] = p['l_1'] * k, p['l_2'] * k
                continue
            break
        out[name] = p
        rebuilt += _rebuild(p)
    return out, rebuilt


def _terms(maps, theta):
    return {'shaking_force': float(np.linalg.norm(maps.force @ theta)),
            'shaking_moment': float(np.linalg.norm(maps.moment @ theta)),
            'driving_torque': float(np.linalg.norm(maps.torque @ theta))}


def _initial_pieces(theta):
    """Return the piece of each link at ``theta``: 'P', an N piece, or 'P' when in the band."""
    out = []
    for row in np.asarray(theta).reshape(-1, 4):
        m, hx, hy, i_o = row
        out.append('P' if m * i_o >= (abs(hx) + abs(hy)) ** 2 * (1 - BAND_REL_TOL)
                   else _n_piece(row) if m * i_o <= (abs(hx) - abs(hy)) ** 2 * (1 + 1e-9)
                   else 'P')
    return out


def _n_piece(row):
    """Return the N piece (dominant axis, signs) nearest to a link's parameters."""
    _, hx, hy, _ = row
    axis = 0 if abs(hx) >= abs(hy) else 1
    return ('N', axis, 1.0 if hx >= 0 else -1.0, 1.0 if hy >= 0 else -1.0)


def _program(maps, dsc, w, n, pieces, theta_at):
    """Solve B.1-B.3 with each link in its piece ('free': the relaxation); return a dict."""
    nv = 4 * n
    nx = nv + 2 + n
    prog = ConeRows(nx)
    rows, rhs = [], []

    def at_most(entries, value):
        """Add the row ``sum_k entries[k] x_k <= value``."""
        r = np.zeros(nx)
        r[list(entries)] = list(entries.values())
        rows.append(r)
        rhs.append(value)

    for i in range(n):
        at_most({4 * i: -1.0}, -PAPER_MASS_FACTORS[0])           # seed 001 eq. B.2
        at_most({4 * i: 1.0}, PAPER_MASS_FACTORS[1])
        at_most({4 * i + 3: -1.0}, -PAPER_INERTIA_FACTOR)        # eq. B.3
        piece = pieces[i]
        if piece == 'P':
            # |hx| + |hy| <= u (4 rows) and u^2 <= m I_O (rotated cone below)
            for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                at_most({4 * i + 1: sx, 4 * i + 2: sy, nv + 2 + i: -1.0}, 0.0)
        elif piece != 'free':
            _, axis, sx, sy = piece
            m, hx, hy, i_o = theta_at[4 * i:4 * i + 4]
            a_ = math.sqrt((m / i_o) * (dsc[4 * i + 3] / dsc[4 * i]))   # scaled variables
            sb, sd = (sx, sy) if axis == 0 else (sy, sx)
            ib, id_ = (4 * i + 1, 4 * i + 2) if axis == 0 else (4 * i + 2, 4 * i + 1)
            # sb h_b - sd h_d >= m/(2a) + a I/2 (in units: h by sqrt(m0 I0)), and signs fixed
            at_most({ib: -sb, id_: sd, 4 * i: 0.5 / a_, 4 * i + 3: 0.5 * a_}, 0.0)
            for idx, s in ((ib, sb), (id_, sd)):
                at_most({idx: -s}, 0.0)
    prog.add('nonneg', rows, rhs)
    for i in range(n):
        if pieces[i] == 'P':
            a = np.zeros((3, nx))
            a[0, [4 * i, 4 * i + 3]] = -1.0
            a[1, nv + 2 + i] = -2.0
            a[2, [4 * i, 4 * i + 3]] = (-1.0, 1.0)
            prog.add('soc', a, np.zeros(3))
    for k, mat in enumerate((maps.force, maps.moment)):
        prog.norm_cone(nv + k, mat * dsc, np.arange(nv))
    q = np.zeros(nx)
    q[nv:nv + 2] = w
    run = prog.solve(q)
    status = run.status
    if not run.ok:
        raise checks.BalanceError(f'two-point model: {run.why()}')
    x = np.array(run.sol.x)
    y = x[:nv]
    out = {'status': status, 'attempts': list(run.attempts),
           'feasibility_tol': conic.SOLVER_TOL * max(1.0, float(np.max(np.abs(x))))}
    if all(p == 'free' for p in pieces):
        # the relaxation's constraints are bounds only: clip the design into them exactly
        # (a feasible design), then the safe lower bound (certificate.safe_lower_bound)
        y = y.copy()
        y[0::4] = np.clip(y[0::4], PAPER_MASS_FACTORS[0], PAPER_MASS_FACTORS[1])
        y[3::4] = np.maximum(y[3::4], PAPER_INERTIA_FACTOR)
        out['feasibility_tol'] = 0.0
    theta = y * dsc
    z = float(w @ [np.linalg.norm(maps.force @ theta), np.linalg.norm(maps.moment @ theta)])
    out.update(theta=theta, z=z)
    if all(p == 'free' for p in pieces):
        out['lower'] = _relaxation_bound(run, maps, dsc, w, n, y, z)
    return out


def _relaxation_bound(run, maps, dsc, w, n, y, level):
    """Return the safe lower bound (:mod:`.certificate`) of the relaxation B.1-B.3."""
    nv = 4 * n
    nx = run.q.size
    lo, hi = np.full(nx, -np.inf), np.full(nx, np.inf)
    lo[0:nv:4], hi[0:nv:4] = PAPER_MASS_FACTORS
    lo[3:nv:4] = PAPER_INERTIA_FACTOR
    mats = [maps.force * dsc, maps.moment * dsc]
    used = [m for m, wk in zip(mats, w) if wk > 0.0]
    zero = ~np.any(np.vstack(used) != 0.0, axis=0)
    lo[:nv][zero] = hi[:nv][zero] = y[zero]
    lo[nv + 2:], hi[nv + 2:] = 0.0, 0.0     # the P pieces' auxiliaries: unused here
    radius = level / min(w[w > 0])
    lo[:nv], hi[:nv] = certificate.polytope_bounds(np.vstack(used), radius, lo[:nv], hi[:nv],
                                                   linear_maps.RANK_REL_TOL)
    # first moments along null directions of the objective: the design's (level_set_bounds)
    lo[:nv], hi[:nv], _ = certificate.level_set_bounds(np.vstack(used), radius, lo[:nv],
                                                       hi[:nv], y, linear_maps.RANK_REL_TOL)
    for k, wk in enumerate(w):
        lo[nv + k] = 0.0
        hi[nv + k] = certificate.norm_bound(mats[k], np.zeros(mats[k].shape[0]), lo[:nv],
                                            hi[:nv])
        if wk > 0.0:
            hi[nv + k] = min(hi[nv + k], level / wk * (1.0 + 4.0 * certificate.UNIT_ROUNDOFF))
    return certificate.safe_lower_bound(run.q, run.a, run.b, run.cones, run.sol.z, lo, hi)
