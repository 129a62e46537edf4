"""
Optimal mass redistribution of planar linkages (seed 001 eqs. 42-53): :func:`optimize`.

A cone program in the links' inertial parameters (Clarabel), certified by a safe lower bound
(:mod:`mech_balance.balancing.certificate`); docs/balancing.md, "Mass redistribution".
"""

from dataclasses import dataclass, replace
import math
import time

import clarabel
from mech_balance import schema
from mech_balance.analysis.linear_maps import linear_maps, RANK_REL_TOL
from mech_balance.balancing import certificate, conditioning
from mech_balance.balancing.certificate import Certificate, certify, failed_stage, GAP_FLOOR, \
    Stage
from mech_balance.balancing.checks import BalanceError, check_link_names, check_nonneg, \
    check_planar, check_weights, finite_or_none, link_bounds, show
from mech_balance.balancing.defaults import CASES, CENTROIDAL_MARGIN, DEFAULT_WEIGHTS, \
    PAPER_DISTANCE_FACTORS, PAPER_MASS_FACTORS
from mech_balance.balancing.tables import before_after, link_design
from mech_balance.conic import INFEASIBLE, run_solver
from mech_balance.conventions import MAX_WEIGHT
from mech_balance.core import equimomental
from mech_balance.core.planar.rig import objective_units
from mech_balance.schema.scene import Normalization
import numpy as np
import scipy.sparse as sp

FORCE_BALANCE_REL_TOL = 1e-6
"""A stage-1 RMS shaking force below this fraction of the original's counts as complete
force balance attainable; stage 2 then imposes it exactly (force map null space)."""
TIE_BREAK_SLACK = 1e-7
"""Stage 2 keeps the stage-1 objective within this fraction of max(z*, 1)."""


def optimize(scene, weights=DEFAULT_WEIGHTS, case='a', realizable=True,
             paper_constraints=False, mass_bounds=None, distance_bounds=None, samples=None, *,
             torque_weight=0.0, reaction_weight=0.0, max_added_mass_kg=None, fixed_links=(),
             mass_factors=PAPER_MASS_FACTORS, distance_factors=PAPER_DISTANCE_FACTORS,
             centroidal_margin=CENTROIDAL_MARGIN, tie_break=True):
    """
    Return the globally optimal mass distribution of a planar scene (a :class:`BalanceResult`).

    ``mass_bounds`` ``{link: (min_kg, max_kg)}``, ``distance_bounds`` ``{link: (min_m, max_m or
    None)}`` (defaults: the factors x the original).  Raises :class:`~.checks.BalanceError`.
    """
    t_start = time.perf_counter()
    w1, w2 = check_weights(weights)
    torque_weight = check_nonneg(torque_weight, 'torque_weight', MAX_WEIGHT)
    reaction_weight = check_nonneg(reaction_weight, 'reaction_weight', MAX_WEIGHT)
    if w1 + w2 + torque_weight + reaction_weight == 0.0:
        raise BalanceError('weights: got all zero, expected at least one positive weight')
    if case not in CASES:
        raise BalanceError(f'case: got {case!r}, expected one of {", ".join(CASES)}')
    check_planar(scene)
    names = [lk.name for lk in scene.links]
    fixed = check_link_names(fixed_links, names, 'fixed_links')
    if fixed and len(fixed) == len(names):
        raise BalanceError(f'fixed_links: got every link ({", ".join(names)}), expected at '
                           'least one link free to balance')
    if paper_constraints:
        extras = {'mass_bounds': mass_bounds, 'distance_bounds': distance_bounds,
                  'max_added_mass_kg': max_added_mass_kg,
                  'torque_weight': torque_weight or None,
                  'reaction_weight': reaction_weight or None,
                  'fixed_links': fixed or None}
        given = [k for k, v in extras.items() if v is not None and v != {}]
        if given or tuple(mass_factors) != PAPER_MASS_FACTORS or \
                tuple(distance_factors) != PAPER_DISTANCE_FACTORS:
            raise BalanceError(
                f'paper_constraints: got also {", ".join(given) or "other bound factors"}, '
                'expected none: the paper problem (Chaudhary & Saha eqs. 50/53) has only its own '
                'bounds and weights')
        realizable = False
    if max_added_mass_kg is not None:
        max_added_mass_kg = check_nonneg(max_added_mass_kg, 'max_added_mass_kg')
    margin = float(centroidal_margin)
    if not 0.0 <= margin < 1.0:
        raise BalanceError(f'centroidal_margin: got {show(centroidal_margin)}, expected 0 <= '
                           'margin < 1')
    samples = scene.samples if samples is None else int(samples)
    if samples < 4:
        raise BalanceError(f'samples: got {samples}, expected an integer >= 4')
    units = objective_units(scene)
    maps, maps_s = objective_maps(scene, samples, units, torque_weight, reaction_weight)
    theta0 = maps.theta_original
    m0 = theta0[0::4]
    l0 = np.sqrt(theta0[3::4] / m0)
    mlo, mhi = link_bounds(mass_bounds, names, m0 * units.mass_kg, mass_factors,
                           'mass_bounds', 'mass_factors')
    llo, lhi = link_bounds(distance_bounds, names, l0 * units.length_m, distance_factors,
                           'distance_bounds', 'distance_factors')
    spec = _Spec(n=len(names), w=(w1, w2, torque_weight, reaction_weight), case=case,
                 realizable=realizable, margin=margin, mass_lo=mlo / units.mass_kg,
                 mass_hi=mhi / units.mass_kg, dist_lo=llo / units.length_m,
                 dist_hi=lhi / units.length_m, fixed=[nm in fixed for nm in names],
                 theta0=theta0,
                 added_mass=None if max_added_mass_kg is None
                 else max_added_mass_kg / units.mass_kg,
                 blame=conditioning.blame(scene, None if scene.normalization is None else units,
                                          scene.crank_speed_rad_s))
    blame = spec.blame
    stage1 = _solve(maps, spec)
    failed = []
    if not stage1.run.ok:
        failed.append(failed_stage('primary (z)', stage1.run, "the solver's last iterate, "
                                   'made feasible; its lower bound is safe', blame))
    theta, stage2, exact = stage1.point, None, False
    term = tie_break_term(spec.w)
    secondary = None if term is None else ('force', 'moment')[term]
    if tie_break and secondary is not None and stage1.run.ok:
        f_star = float(np.linalg.norm(maps.force @ theta))
        exact = (secondary == 'moment' and
                 f_star <= FORCE_BALANCE_REL_TOL * maps.force_rms_original)
        try:
            stage2 = _solve(maps, spec, secondary=secondary, bound=stage1.objective,
                            exact_force=exact)
        except BalanceError as exc:
            failed.append({'stage': f'tie-break (least RMS shaking {secondary})',
                           'status': 'error', 'reason': str(exc),
                           'design': "the primary stage's optimum"})
            stage2, exact = None, False
        if stage2 is not None and not stage2.run.ok:
            failed.append(failed_stage(f'tie-break (least RMS shaking {secondary})',
                                       stage2.run, "the primary stage's optimum", blame))
            stage2, exact = None, False
        if stage2 is not None:
            theta = stage2.point
            if exact:
                theta = theta - maps.force_null_projector @ theta
    violation = _violation(theta, spec)
    theta, pull = pull_inside(theta, violation, lambda t: _violation(t, spec),
                              lambda t: _repaired(t, spec), lambda: _anchor(spec))
    balanced = _scene_from_theta(scene, theta, units, case)
    terms = maps.terms(theta)
    primal = float(np.dot(spec.w, terms))
    bound, nulls = _certify(stage1, primal, theta)
    cert = certify(stage1, primal, bound, violation, pull, failed, _violation(theta, spec),
                   None if stage2 is None else tie_break_report(
                       stage2, f'RMS shaking {secondary}', _tie_break_bound(stage2, exact),
                       exact), null_directions_assumed=nulls)
    conic_s = stage1.seconds + (0.0 if stage2 is None else stage2.seconds)
    table = before_after(scene, balanced, samples)
    return BalanceResult(
        scene=scene, balanced_scene=balanced, weights=(w1, w2), case=case,
        realizable_constraint=bool(realizable), paper_constraints=bool(paper_constraints),
        torque_weight=torque_weight, reaction_weight=reaction_weight, samples=samples,
        units=units, links=tuple(link_design(lk, case == 'b', units) for lk in
                                 balanced.links),
        objective={'z': primal, 'shaking_force_rms': float(terms[0]),
                   'shaking_moment_rms': float(terms[1]),
                   'driving_torque_rms': None if not torque_weight else float(terms[2]),
                   'bearing_force_rms_sum': None if not reaction_weight else float(terms[3]),
                   'z_original': float(np.dot(spec.w, maps.terms(theta0)))},
        bounds={nm: {'mass_kg': [finite_or_none(mlo[i]), finite_or_none(mhi[i])],
                     'distance_m': [finite_or_none(llo[i]), finite_or_none(lhi[i])],
                     'fixed': bool(spec.fixed[i])} for i, nm in enumerate(names)},
        max_added_mass_kg=max_added_mass_kg, certificate=cert, table=table,
        maps_time_s=maps_s, conic_time_s=conic_s,
        solve_time_s=time.perf_counter() - t_start)


def objective_maps(scene, samples, units, torque_weight, reaction_weight):
    """Return (maps, seconds): the :func:`linear_maps` of the terms the weights use."""
    need = ['shaking_wrench'] + ['driving_torque'] * bool(torque_weight) + \
        ['bearing_reactions'] * bool(reaction_weight)
    t0 = time.perf_counter()
    return linear_maps(scene, samples, need, units), time.perf_counter() - t0


def scene_to_yaml(scene, balance=None):
    """Return a balanced scene as YAML (``balance`` under its key); BalanceError if I_c < 0."""
    for lk in scene.links:
        if lk.inertia_com_kg_m2 < 0.0:
            raise BalanceError(
                f'links.{lk.name}.inertia_com_kg_m2: got {lk.inertia_com_kg_m2:.6g}, expected '
                '>= 0; an unrealizable design cannot be saved as a scene')
    return schema.to_yaml(scene, balance)


@dataclass
class BalanceResult:
    """The optimal design, its certificate, and the before/after table."""

    scene: object
    balanced_scene: object
    weights: tuple
    case: str
    realizable_constraint: bool
    paper_constraints: bool
    torque_weight: float
    reaction_weight: float
    samples: int
    units: Normalization
    links: tuple            # LinkDesign per moving link (balanced)
    objective: dict
    bounds: dict
    max_added_mass_kg: float
    certificate: Certificate
    table: list             # before/after rows (dicts), see before_after
    maps_time_s: float
    conic_time_s: float
    solve_time_s: float

    @property
    def realizable(self):
        """Return True if every link of the design is realizable."""
        return all(d.realizable for d in self.links)

    def summary(self):
        """Return the provenance stored with a balanced scene (``balance`` key)."""
        return schema.plain({
            'source_scene': self.scene.name, 'method': 'Chaudhary & Saha eqs. 42-53, SOCP',
            'weights': list(self.weights), 'case': self.case,
            'torque_weight': self.torque_weight, 'reaction_weight': self.reaction_weight,
            'paper_constraints': self.paper_constraints,
            'realizable_constraint': self.realizable_constraint,
            'objective': self.objective, 'relative_gap': self.certificate.gap_rel,
            'lower_bound': self.certificate.lower_bound,
            'certified': self.certificate.certified,
            'failed_stages': self.certificate.failed_stages or [],
            'realizable': self.realizable})

    def to_dict(self):
        """Return everything as a plain, YAML- and JSON-able dict (SI and normalized)."""
        u = self.units
        return schema.plain({
            'scene': self.scene.name, 'samples': self.samples,
            'weights': list(self.weights), 'case': self.case,
            'torque_weight': self.torque_weight, 'reaction_weight': self.reaction_weight,
            'paper_constraints': self.paper_constraints,
            'realizable_constraint': self.realizable_constraint,
            'units': {'mass_kg': u.mass_kg, 'length_m': u.length_m,
                      'omega_rad_s': u.omega_rad_s,
                      'normalized_from': 'scene' if self.scene.normalization is not None
                      else 'crank link'},
            'links': [d.to_dict() for d in self.links], 'realizable': self.realizable,
            'objective': self.objective, 'bounds': self.bounds,
            'max_added_mass_kg': self.max_added_mass_kg,
            'certificate': self.certificate.to_dict(), 'table': self.table,
            'maps_time_s': self.maps_time_s, 'conic_time_s': self.conic_time_s,
            'solve_time_s': self.solve_time_s})


@dataclass
class _Spec:
    n: int
    w: tuple           # weights of [f~, n~, tau~, sum f~_j]
    case: str
    realizable: bool
    margin: float
    mass_lo: np.ndarray   # normalized; inf/0 for none
    mass_hi: np.ndarray
    dist_lo: np.ndarray
    dist_hi: np.ndarray
    fixed: list
    theta0: np.ndarray
    added_mass: float = None
    blame: str = ''       # the scene values that make the program ill-posed (conditioning)


@dataclass
class _Stage(Stage):
    """A stage (``point``: theta) with what its certificate needs."""

    lo: np.ndarray = None     # explicit box of the program's variables (certificate)
    hi: np.ndarray = None
    norms: list = None        # (G in y units, epigraph index, weight) per objective term
    dscale: np.ndarray = None
    radius_scale: float = None
    free_h: bool = False      # h enters no constraint (case a, no realizability)


def tie_break_report(stage, minimized, lower_bound, exact):
    """Return a tie-break stage's entry of the certificate (``stage2``)."""
    return {'minimized': minimized, 'status': stage.status, 'objective': stage.objective,
            'lower_bound': lower_bound, 'iterations': stage.iterations,
            'attempts': list(stage.run.attempts), 'exact_force_balance': bool(exact)}


def tie_break_term(w):
    """Return what a tie-break stage minimizes (0 force, 1 moment) for weights ``w`` (4,)."""
    w1, w2, wt, wr = w
    if wt or wr or (w1 and w2):
        return None
    return 1 if w2 == 0.0 else 0


class ConeRows:
    """Rows of ``A x + s = b, s in K`` for Clarabel, built block by block."""

    def __init__(self, nx):
        self.nx = nx
        self.blocks = []

    def add(self, kind, a, b):
        """Add a block of rows ``b - a x in K`` of cone ``kind``."""
        a = np.atleast_2d(np.asarray(a, dtype=float))
        self.blocks.append((kind, a, np.asarray(b, dtype=float).ravel()))

    def norm_cone(self, t_index, mat, cols):
        """Add ``x[t_index] >= ||mat @ x[cols]||``."""
        a = np.zeros((1 + mat.shape[0], self.nx))
        a[0, t_index] = -1.0
        a[1:, cols] = -mat
        self.add('soc', a, np.zeros(a.shape[0]))

    def solve(self, q):
        """Return the :class:`mech_balance.conic.Solve` of ``min q'x`` over the blocks."""
        kinds = {'zero': clarabel.ZeroConeT, 'nonneg': clarabel.NonnegativeConeT,
                 'soc': clarabel.SecondOrderConeT}
        merged = []
        for kind, a, b in self.blocks:
            if kind != 'soc' and merged and merged[-1][0] == kind:
                merged[-1] = (kind, np.vstack([merged[-1][1], a]),
                              np.concatenate([merged[-1][2], b]))
            else:
                merged.append((kind, a, b))
        a = sp.csc_matrix(np.vstack([m[1] for m in merged]))
        b = np.concatenate([m[2] for m in merged])
        cones = [kinds[k](blk.shape[0]) for k, blk, _ in merged]
        return run_solver(q, a, b, cones)


def _solve(maps, spec, secondary=None, bound=None, exact_force=False):
    """Build and solve the SOCP (stage 1, or the tie-break stage 2) in link units; a _Stage."""
    n = spec.n
    nv = 4 * n
    t0 = spec.theta0.reshape(-1, 4)
    m0 = t0[:, 0]
    l0 = np.sqrt(t0[:, 3] / m0)
    dscale = np.column_stack([m0, m0 * l0, m0 * l0, m0 * l0 * l0]).ravel()
    y0 = spec.theta0 / dscale
    react = list(maps.reactions.values()) if maps.reactions is not None and spec.w[3] else []
    # variables: y (nv) | t_f, t_n, t_tau | t_react (len(react)) | u (n, case b)
    it_f, it_n, it_t = nv, nv + 1, nv + 2
    ir0 = nv + 3
    iu0 = ir0 + len(react)
    nx = iu0 + (n if spec.case == 'b' else 0)
    prog = ConeRows(nx)
    # (G in y units, epigraph index, weight) per objective term
    norms = [(maps.force * dscale, it_f, spec.w[0]), (maps.moment * dscale, it_n, spec.w[1])]
    if spec.w[2]:
        norms.append((maps.torque * dscale, it_t, spec.w[2]))
    norms += [(mat * dscale, ir0 + j, spec.w[3]) for j, mat in enumerate(react)]
    primary = np.zeros(nx)
    for g, it, w in norms:
        prog.norm_cone(it, g, np.arange(nv))
        primary[it] = w
    for i in range(n):
        im, ix, iy, ii = 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3
        if spec.fixed[i]:
            a = np.zeros((4, nx))
            a[:, im:im + 4] = np.eye(4)
            prog.add('zero', a, y0[im:im + 4])
            continue
        rows = []   # (entries, bound): sum_k entries[k] x_k <= bound
        if np.isfinite(spec.mass_lo[i]):   # seed 001 eq. 46b / 50b
            rows.append(({im: -1.0}, -spec.mass_lo[i] / m0[i]))
        if np.isfinite(spec.mass_hi[i]):
            rows.append(({im: 1.0}, spec.mass_hi[i] / m0[i]))
        # eq. 46c / 50c: l_lo <= l <= l_hi  <=>  m l_lo^2 <= I_O <= m l_hi^2
        rows.append(({im: (spec.dist_lo[i] / l0[i]) ** 2, ii: -1.0}, 0.0))
        if np.isfinite(spec.dist_hi[i]):
            rows.append(({im: -(spec.dist_hi[i] / l0[i]) ** 2, ii: 1.0}, 0.0))
        if spec.case == 'b':
            # eq. 50f: m_j >= 0  <=>  u >= -2 Re(h e^(-i theta_j)), u >= 0, u^2 <= m I_O
            iu = iu0 + i
            rows.append(({iu: -1.0}, 0.0))
            rows += [({ix: -2.0 * unit.real, iy: -2.0 * unit.imag, iu: -1.0}, 0.0)
                     for unit in equimomental.UNIT]
        prog.add('nonneg', [_row(nx, e) for e, _ in rows], [b for _, b in rows])
        if spec.case == 'b':
            prog.add('soc', [_row(nx, {im: -1.0, ii: -1.0}), _row(nx, {iu0 + i: -2.0}),
                             _row(nx, {im: -1.0, ii: 1.0})], np.zeros(3))
        if spec.realizable:
            # |h|^2 <= m (1 - eps) I_O: rotated cone (m + c I, 2h, m - c I) in SOC
            c = 1.0 - spec.margin
            prog.add('soc', [_row(nx, {im: -1.0, ii: -c}), _row(nx, {ix: -2.0}),
                             _row(nx, {iy: -2.0}), _row(nx, {im: -1.0, ii: c})],
                     np.zeros(4))
    if spec.added_mass is not None and not all(spec.fixed):
        cap = spec.added_mass + float(np.sum(m0))
        prog.add('nonneg', _row(nx, {4 * i: m0[i] for i in range(n)}), [cap])
    q = primary
    if secondary is not None:
        if exact_force:
            basis = maps.force_row_basis * dscale
            a = np.zeros((basis.shape[0], nx))
            a[:, :nv] = basis / np.linalg.norm(basis, axis=1, keepdims=True)
            prog.add('zero', a, np.zeros(basis.shape[0]))
        else:
            slack = TIE_BREAK_SLACK * max(abs(bound), GAP_FLOOR)
            prog.add('nonneg', primary, [bound + slack])
        q = np.zeros(nx)
        q[it_n if secondary == 'moment' else it_f] = 1.0
    run = prog.solve(q)
    status = run.status
    if status in INFEASIBLE:
        raise BalanceError(
            'constraints: the balancing problem is infeasible (solver status '
            f'{status}); widen mass_bounds / distance_bounds / max_added_mass_kg')
    if not np.all(np.isfinite(np.asarray(run.sol.x))):
        raise BalanceError(f'solver: {run.why()}; no design{spec.blame}')
    x = np.array(run.sol.x)
    # the box of the certificate (certificate.safe_lower_bound): explicit bounds in y units
    lo = np.full(nx, -np.inf)
    hi = np.full(nx, np.inf)
    for i in range(n):
        im, ii = 4 * i, 4 * i + 3
        if spec.fixed[i]:
            lo[im:im + 4] = hi[im:im + 4] = y0[im:im + 4]
            continue
        lo[im], hi[im] = spec.mass_lo[i] / m0[i], spec.mass_hi[i] / m0[i]
        lo[ii] = lo[im] * (spec.dist_lo[i] / l0[i]) ** 2
        hi[ii] = hi[im] * (spec.dist_hi[i] / l0[i]) ** 2
        if spec.realizable or spec.case == 'b':   # |h|^2 <= m I_O
            reach = math.sqrt(hi[im] * hi[ii]) if np.isfinite(hi[im] * hi[ii]) else np.inf
            lo[im + 1:im + 3], hi[im + 1:im + 3] = -reach, reach
        if spec.case == 'b':
            lo[iu0 + i], hi[iu0 + i] = 0.0, reach
    return _Stage(x[:nv] * dscale, float(q @ x), run, lo=lo, hi=hi, norms=norms,
                  dscale=dscale, free_h=spec.case == 'a' and not spec.realizable,
                  radius_scale=None if secondary is None or exact_force else
                  bound + TIE_BREAK_SLACK * max(abs(bound), GAP_FLOOR))


def _certify(stage, level, centre_theta=None):
    """Return (safe lower bound, null directions assumed) with the objective <= ``level``."""
    lo, hi = stage.lo.copy(), stage.hi.copy()
    nv = stage.point.size
    weighted = [(g, w) for g, _, w in stage.norms if w > 0.0]
    nulls = 0
    if weighted and np.isfinite(level):
        mat = np.vstack([g for g, _ in weighted])
        # h of case a without realizability enters no constraint: a null direction of the
        # objective (the carpet scraper has one) leaves the optimal set unbounded along it
        centre = None if centre_theta is None or not stage.free_h else \
            centre_theta / stage.dscale
        lo[:nv], hi[:nv], nulls = certificate.level_set_bounds(
            mat, level / min(w for _, w in weighted), lo[:nv], hi[:nv], centre,
            RANK_REL_TOL)
    for g, it, w in stage.norms:
        # an optimal point has t = ||G y|| (lower t where it is not tight: nothing else
        # depends on t), and w t <= level for a weighted term
        cap = certificate.norm_bound(g, np.zeros(g.shape[0]), lo[:nv], hi[:nv])
        if w > 0.0 and np.isfinite(level):
            cap = min(cap, level / w * (1.0 + 4.0 * certificate.UNIT_ROUNDOFF))
        lo[it], hi[it] = 0.0, cap
    run = stage.run
    bound = certificate.safe_lower_bound(run.q, run.a, run.b, run.cones, run.sol.z, lo, hi)
    return bound, nulls


def _tie_break_bound(stage, exact):
    """Return the safe lower bound of a tie-break stage, never above its solver objective."""
    level = stage.radius_scale if stage.radius_scale is not None else \
        (0.0 if exact else math.inf)
    bound, _ = _certify(stage, level)
    return min(bound.value, stage.objective)


def _row(nx, entries):
    """Return a row of ``nx`` zeros with ``entries`` {column: value} added."""
    r = np.zeros(nx)
    for k, v in entries.items():
        r[k] += v
    return r


FEASIBLE_ULPS = 8.0
"""A constraint a - b <= 0 counts as met when a - b <= this many ulp of max(|a|, |b|): the
rounding of its own evaluation (equal bounds, m l^2 = I_O, cannot be met more exactly)."""


def _excess(a, b):
    """Return how far a exceeds b beyond the rounding of the comparison (>= 0 if it does)."""
    slack = FEASIBLE_ULPS * np.finfo(float).eps * max(abs(a), abs(b))
    return a - b - slack


def _violation(theta, spec):
    """Return the worst violation of the design constraints (normalized units, >= 0)."""
    t = theta.reshape(-1, 4)
    point_masses, _ = equimomental.point_mass_arrays(t[:, 0], t[:, 1] + 1j * t[:, 2], t[:, 3])
    worst = 0.0
    for i in range(spec.n):
        if spec.fixed[i]:
            continue
        m, hx, hy, i_o = t[i]
        checks = [_excess(spec.mass_lo[i], m) if np.isfinite(spec.mass_lo[i]) else 0.0,
                  _excess(m, spec.mass_hi[i]) if np.isfinite(spec.mass_hi[i]) else 0.0,
                  _excess(m * spec.dist_lo[i] ** 2, i_o),
                  _excess(i_o, m * spec.dist_hi[i] ** 2) if np.isfinite(spec.dist_hi[i])
                  else 0.0]
        if spec.realizable:
            checks.append(_excess(hx * hx + hy * hy, m * (1.0 - spec.margin) * i_o))
        if spec.case == 'b':   # eq. 50f: m_j >= 0
            checks += list(-point_masses[i] - FEASIBLE_ULPS * np.finfo(float).eps * m)
        worst = max(worst, max(checks))
    if spec.added_mass is not None and not all(spec.fixed):
        worst = max(worst, _excess(float(np.sum(t[:, 0])),
                                   float(np.sum(spec.theta0[0::4])) + spec.added_mass))
    return float(max(worst, 0.0))


def _repaired(theta, spec):
    """Return ``theta`` with each link moved onto its bounds by the least local change."""
    t = np.array(theta, dtype=float).reshape(-1, 4)
    free = [i for i in range(spec.n) if not spec.fixed[i]]
    for i in free:
        t[i, 0] = min(max(t[i, 0], spec.mass_lo[i]), spec.mass_hi[i])
    if spec.added_mass is not None and free:
        # the cap on the added mass: take the excess off the masses above their lower bounds
        excess = float(np.sum(t[:, 0]) - np.sum(spec.theta0[0::4]) - spec.added_mass)
        room = np.array([t[i, 0] - spec.mass_lo[i] for i in free])
        if excess > 0.0 and room.sum() > 0.0:
            share = min(1.0, excess * (1.0 + 1e-12) / room.sum())
            for i, r in zip(free, room):
                t[i, 0] = max(t[i, 0] - share * r, spec.mass_lo[i])
    for i in free:
        m = t[i, 0]
        i_o = min(max(t[i, 3], m * spec.dist_lo[i] ** 2), m * spec.dist_hi[i] ** 2)
        t[i, 0], t[i, 3] = m, i_o
        if spec.realizable:
            h2 = t[i, 1] ** 2 + t[i, 2] ** 2
            cap = m * (1.0 - spec.margin) * i_o
            if h2 > cap:
                t[i, 1:3] *= math.sqrt(cap / h2) * (1.0 - 4.0 * np.finfo(float).eps)
    return t.ravel()


PULL_STEPS = (0.0,) + tuple(10.0 ** -k for k in range(12, 0, -1)) + (1.0,)
"""Fractions of the way to the interior anchor tried until a design violates nothing."""


def _anchor(spec):
    """Return a feasible design of the constraints (inside where it can be): the anchor."""
    t0 = spec.theta0.reshape(-1, 4)
    out = t0.copy()
    for i in range(spec.n):
        if spec.fixed[i]:
            continue
        m0, i0 = t0[i, 0], t0[i, 3]
        lo, hi = spec.mass_lo[i], spec.mass_hi[i]
        m = min(max(m0, lo), hi)
        if spec.added_mass is None and hi > lo:
            m = 0.5 * (lo + hi) if np.isfinite(hi) else 1.5 * lo
        l_lo, l_hi = spec.dist_lo[i], spec.dist_hi[i]
        l_2 = min(max(i0 / m0, l_lo ** 2), l_hi ** 2)
        if l_hi > l_lo:
            l_2 = 0.5 * (l_lo ** 2 + l_hi ** 2) if np.isfinite(l_hi) else 1.5 * l_lo ** 2
        out[i] = (m, 0.0, 0.0, m * l_2)
    return out.ravel()


def pull_inside(x, worst, violation, repair, anchor):
    """Return (x, pull): ``x`` if ``worst`` (its violation) is 0, else repaired, else pulled."""
    if worst <= 0.0:
        return x, 0.0
    x = repair(x)
    if violation(x) <= 0.0:
        return x, 0.0
    inside = anchor()
    for lam in PULL_STEPS[1:]:
        cand = (1.0 - lam) * x + lam * inside
        if violation(cand) <= 0.0:
            return cand, lam
    return inside, 1.0


def _scene_from_theta(scene, theta, units, case):
    """Return the scene with link inertias from a normalized parameter vector."""
    t = theta.reshape(-1, 4)
    links = []
    for lk, (m, hx, hy, i_o) in zip(scene.links, t):
        m_kg = m * units.mass_kg
        h = complex(hx, hy) * units.mass_kg * units.length_m
        i_o = i_o * units.mass_kg * units.length_m ** 2
        c = h / m_kg
        links.append(replace(lk, mass_kg=float(m_kg), com_m=(float(c.real), float(c.imag)),
                             inertia_com_kg_m2=float(i_o - abs(h) ** 2 / m_kg)))
    return scene.with_links(links, name=f'{scene.name}_balanced')


__all__ = ['BalanceResult', 'ConeRows', 'FORCE_BALANCE_REL_TOL', 'objective_maps', 'optimize',
           'pull_inside', 'PULL_STEPS', 'scene_to_yaml', 'TIE_BREAK_SLACK', 'tie_break_report',
           'tie_break_term']
