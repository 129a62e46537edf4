"""
Balancing of planar linkages: analytic complete force balance and optimal mass distribution.

Two tools, one physics (the core's shaking wrench, :mod:`mech_balance.conventions`):

Analytic complete force balance (the total mass centre is stationary)
    * slider-crank, seed 000 eqs. 44-75: :func:`slider_crank_balance`;
    * four-bar, Berkof-Lowen, seed 001 eq. 48: :func:`four_bar_balance`.
    Both are derived here in complex numbers for arbitrary link frames (docstrings) and
    checked against the physics: the shaking force of the result vanishes to round-off.
    Seed 000 eq. 75 prints ``xi_2 = 1/mu_2``; eqs. 67 and 71 give ``mu_2 xi_2 = -1``, and
    only ``xi_2 = -1/mu_2`` makes the shaking force vanish (``printed_eq75=True`` shows it).

Optimal mass redistribution, seed 001 eqs. 42-53: :func:`optimize`
    Per moving link the inertial parameters theta_i = (m_i, h_i = m_i c_i, I_Oi) enter the
    shaking force, the shaking moment, the driving torque and every bearing reaction
    *linearly* (seed 001 eqs. 25-26, 39).  The RMS of a linear map over p crank angles is a
    Euclidean norm, ``||A theta|| / sqrt(p)``, and the paper's constraints are convex in
    theta (the three point masses at 0, 120, 240 deg and common distance l of eq. 27 are
    ``m = sum m_j``, ``h = l sum m_j e^(i theta_j)``, ``I_O = m l^2``):

    ==========================================  ==============================================
    seed 001 constraint (design x = m_ij, l_i1)  in theta (convex)
    ==========================================  ==============================================
    m_min <= sum_j m_ij <= m_max (46b, 50b)      linear in m
    l_min <= l_i1 <= l_max (46c, 50c)            m l_min^2 <= I_O <= m l_max^2 (linear)
    m_ij >= 0 (50f, case b)                      sqrt(m I_O) >= -2 Re(h e^(-i theta_j)),
                                                 a rotated second-order cone
    realizable: I_O - |h|^2/m >= eps I_O          |h|^2 <= m (1 - eps) I_O, rotated cone
    ==========================================  ==============================================

    so the problem is a second-order cone program (SOCP), solved to global optimality by the
    interior-point solver Clarabel, whose primal and dual objectives give the certificate
    (duality gap).  The maps are built from the core by evaluating the wrenches at unit
    parameter vectors on one kinematic solution, then compressed by a QR factorization
    (``||A theta|| = ||R theta||``, R is 4n x 4n) so the cones stay small.  The optimum is
    mapped back to link mass, mass centre, inertia and the three point masses (eqs. 11-15).

Units: scenes are SI.  The objective ``z = w1 f~ + w2 n~`` is dimensionless, in the units of
seed 001 sec. 3.4 (force by m_1 a_1 omega^2, moment by m_1 a_1^2 omega^2) taken from the
scene's ``normalization`` or, if it records none, from its crank link mass, crank length
and crank speed (:func:`objective_units`).
"""

from dataclasses import dataclass, field, replace
import math
import time

import clarabel
from mech_balance import schema
from mech_balance.analysis import cycle as analysis
from mech_balance.analysis.linear_maps import linear_maps, LinearMaps, RANK_REL_TOL  # noqa: F401
from mech_balance.balancing import certificate
from mech_balance.balancing.defaults import BOUND_RATIO_RANGE, CASES, CENTROIDAL_MARGIN, \
    DEFAULT_WEIGHTS, DISTANCE_RATIO_RANGE, PAPER_DISTANCE_FACTORS, PAPER_MASS_FACTORS
from mech_balance.conic import SOLVER_MAX_ITER, solver_settings, SOLVER_TOL  # noqa: F401
from mech_balance.conventions import MAX_WEIGHT
from mech_balance.core import equimomental
from mech_balance.core.planar.rig import objective_units
from mech_balance.schema.scene import FRAME, Normalization
import numpy as np
import scipy.sparse as sp

FORCE_BALANCE_REL_TOL = 1e-6
"""A stage-1 RMS shaking force below this fraction of the original's counts as complete
force balance attainable; stage 2 then imposes it exactly (force map null space)."""
TIE_BREAK_SLACK = 1e-7
"""Stage 2 keeps the stage-1 objective within this fraction of max(z*, 1)."""
GAP_FLOOR = 1.0
"""Relative gap = |primal - dual| / max(|primal|, |dual|, GAP_FLOOR) (normalized units)."""
CERTIFIED_GAP_REL = 1e-5
"""A stage is certified when its safe lower bound is finite and primal - L is at most this
fraction of max(|primal|, GAP_FLOOR) (``mech-balance balance`` exits 2 otherwise)."""
RETRY_SETTINGS = (
    {},
    {'equilibrate_max_iter': 50, 'static_regularization_constant': 1e-7, 'max_iter': 400},
    {'presolve_enable': False, 'iterative_refinement_max_iter': 50,
     'static_regularization_constant': 1e-10, 'max_iter': 400},
    {'equilibrate_enable': False, 'max_iter': 400, 'tol_scale': 10.0},
)
"""Clarabel settings tried in turn until a solve ends Solved (more equilibration, another
static regularization without presolve, no equilibration with tolerances 10x looser)."""
SOLVED = ('Solved', 'AlmostSolved')
"""Statuses whose point is used; anything else after every retry is a failed stage."""
INFEASIBLE = ('PrimalInfeasible', 'AlmostPrimalInfeasible')
"""Statuses that prove (or nearly) the constraints have no common point."""
CHANGE_BASELINE_REL_TOL = 1e-9
"""A before/after row whose before value is below this fraction of the table's largest value
of the same kind (force or moment) is round-off (e.g. the moment of a prismatic bearing that
is zero but for the last bits): its change is reported as None ('n/a'), not a percentage."""


class BalanceError(ValueError):
    """A balancing problem is ill-posed, infeasible or cannot be solved."""


# ============================================================================ public API


def optimize(scene, weights=DEFAULT_WEIGHTS, case='a', realizable=True,
             paper_constraints=False, mass_bounds=None, distance_bounds=None, samples=None, *,
             torque_weight=0.0, reaction_weight=0.0, max_added_mass_kg=None, fixed_links=(),
             mass_factors=PAPER_MASS_FACTORS, distance_factors=PAPER_DISTANCE_FACTORS,
             centroidal_margin=CENTROIDAL_MARGIN, tie_break=True):
    """
    Return the globally optimal mass distribution of a planar scene (seed 001 eqs. 42-53).

    Minimizes ``z = w1 f~ + w2 n~ [+ torque_weight tau~ + reaction_weight sum_j f~_j]``
    (RMS over one revolution of the normalized shaking force, shaking moment, driving
    torque and bearing forces) over every moving link's mass, mass centre and inertia;
    ``weights`` = (w1, w2) defaults to :data:`DEFAULT_WEIGHTS`.

    Constraints per link (not for ``fixed_links``, whose inertia stays the original):
    ``mass_bounds`` ``{link: (min_kg, max_kg)}`` (default ``mass_factors`` times the
    original mass), ``distance_bounds`` ``{link: (min_m, max_m)}`` on the point-mass
    distance l = sqrt(I_O/m) (default ``distance_factors`` times the original l; ``None``
    for no upper bound), ``case`` 'a' (point masses of any sign) or 'b' (non-negative,
    counterweights), ``realizable`` (centroidal inertia >= ``centroidal_margin`` I_O, on
    by default), ``max_added_mass_kg`` (cap on total mass minus the original's).  Bounds
    and factors need 0 < min <= max (equal bounds fix the value; a zero mass or distance
    is no body), else ``ValueError`` naming the option.

    ``paper_constraints=True`` reproduces seed 001 eqs. 50/53 exactly: the paper's bounds,
    the chosen case, no realizability constraint; it rejects the options the paper lacks.

    If exactly one of w1, w2 is zero (and no other term is weighted) the optimum is
    generally not unique; with ``tie_break`` a second cone program returns, among the
    optimal designs, the one with the least RMS of the unweighted quantity; when complete
    force balance is attainable with w2 = 0 it is imposed exactly (shaking force zero to
    round-off) and the least RMS shaking moment is found among force-balanced designs.
    """
    t_start = time.perf_counter()
    w1, w2 = _weights(weights)
    torque_weight = _nonneg(torque_weight, 'torque_weight', MAX_WEIGHT)
    reaction_weight = _nonneg(reaction_weight, 'reaction_weight', MAX_WEIGHT)
    if w1 + w2 + torque_weight + reaction_weight == 0.0:
        raise BalanceError('weights: got all zero, expected at least one positive weight')
    if case not in CASES:
        raise BalanceError(f'case: got {case!r}, expected one of {", ".join(CASES)}')
    _check_planar(scene)
    names = [lk.name for lk in scene.links]
    fixed = _link_names(fixed_links, names, 'fixed_links')
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
                'expected none: the paper problem (seed 001 eqs. 50/53) has only its own '
                'bounds and weights')
        realizable = False
    if max_added_mass_kg is not None:
        max_added_mass_kg = _nonneg(max_added_mass_kg, 'max_added_mass_kg')
    margin = float(centroidal_margin)
    if not 0.0 <= margin < 1.0:
        raise BalanceError(f'centroidal_margin: got {_show(centroidal_margin)}, expected 0 <= '
                           'margin < 1')
    samples = scene.samples if samples is None else int(samples)
    if samples < 4:
        raise BalanceError(f'samples: got {samples}, expected an integer >= 4')
    units = objective_units(scene)
    need = ['shaking_wrench']
    if torque_weight:
        need.append('driving_torque')
    if reaction_weight:
        need.append('bearing_reactions')
    t0 = time.perf_counter()
    maps = linear_maps(scene, samples, need, units)
    maps_s = time.perf_counter() - t0
    theta0 = maps.theta_original
    m0 = theta0[0::4]
    l0 = np.sqrt(theta0[3::4] / m0)
    mlo, mhi = _bounds(mass_bounds, names, m0 * units.mass_kg, mass_factors, 'mass_bounds',
                       'mass_factors')
    llo, lhi = _bounds(distance_bounds, names, l0 * units.length_m, distance_factors,
                       'distance_bounds', 'distance_factors')
    spec = _Spec(n=len(names), w=(w1, w2, torque_weight, reaction_weight), case=case,
                 realizable=realizable, margin=margin, mass_lo=mlo / units.mass_kg,
                 mass_hi=mhi / units.mass_kg, dist_lo=llo / units.length_m,
                 dist_hi=lhi / units.length_m, fixed=[nm in fixed for nm in names],
                 theta0=theta0,
                 added_mass=None if max_added_mass_kg is None
                 else max_added_mass_kg / units.mass_kg)
    stage1 = _solve(maps, spec)
    failed = []
    blame = '' if scene.normalization is None else \
        speed_blame(abs(scene.crank_speed_rad_s), abs(units.omega_rad_s))
    if not stage1.run.ok:
        failed.append(failed_stage('primary (z)', stage1.run, "the solver's last iterate, "
                                   'made feasible; its lower bound is safe', blame))
    theta, stage2, exact = stage1.theta, None, False
    secondary = _secondary(spec)
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
            theta = stage2.theta
            if exact:
                theta = theta - maps.force_null_projector @ theta
    theta, violation, pull = _feasible(theta, spec)
    balanced = _scene_from_theta(scene, theta, units, case)
    terms = maps.terms(theta)
    primal = float(np.dot(spec.w, terms))
    bound, nulls = _certify(stage1, primal, theta)
    lower = min(bound.value, primal)
    gap, gap_rel = certificate.relative_gap(primal, lower, GAP_FLOOR)
    cert = Certificate(
        solver=f'clarabel {clarabel.__version__}', status=stage1.status,
        primal=primal, dual=lower, gap_abs=gap, gap_rel=gap_rel,
        residual_primal=stage1.r_prim, residual_dual=stage1.r_dual,
        iterations=stage1.iterations,
        stage2=None if stage2 is None else {
            'minimized': f'RMS shaking {secondary}', 'status': stage2.status,
            'objective': stage2.objective, 'lower_bound': _tie_break_bound(stage2, exact),
            'iterations': stage2.iterations,
            'attempts': list(stage2.run.attempts),
            'exact_force_balance': bool(exact)},
        max_violation=violation, lower_bound=lower, attempts=list(stage1.run.attempts),
        bound_detail=dict(_bound_detail(bound), null_directions_assumed=nulls),
        feasibility_pull=pull, failed_stages=failed,
        certified=bool(np.isfinite(lower) and gap_rel <= CERTIFIED_GAP_REL
                       and _violation(theta, spec) == 0.0),
        design_violation=_violation(theta, spec))
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
        bounds={nm: {'mass_kg': [_num(mlo[i]), _num(mhi[i])],
                     'distance_m': [_num(llo[i]), _num(lhi[i])],
                     'fixed': bool(spec.fixed[i])} for i, nm in enumerate(names)},
        max_added_mass_kg=max_added_mass_kg, certificate=cert, table=table,
        maps_time_s=maps_s, conic_time_s=conic_s,
        solve_time_s=time.perf_counter() - t_start)


def scene_to_yaml(scene, balance=None):
    """
    Return a balanced planar scene as YAML text that :func:`mech_balance.schema.load` reads.

    The scene writer (:func:`mech_balance.schema.to_yaml`) with ``balance`` (a plain dict,
    e.g. the summary of a :class:`BalanceResult`) stored under the scene's ``balance`` key.
    A link with a negative centroidal inertia cannot be written (no body has one):
    :class:`BalanceError`.
    """
    for lk in scene.links:
        if lk.inertia_com_kg_m2 < 0.0:
            raise BalanceError(
                f'links.{lk.name}.inertia_com_kg_m2: got {lk.inertia_com_kg_m2:.6g}, expected '
                '>= 0; an unrealizable design cannot be saved as a scene')
    return schema.to_yaml(scene, balance)


# ============================================================================ results


@dataclass
class Certificate:
    """
    Global-optimality certificate of a balancing cone program (the primary stage).

    ``lower_bound`` (also under the old key ``dual``) is a safe lower bound on every
    feasible z (:func:`mech_balance.balancing.certificate.safe_lower_bound`), never above
    ``primal``, the core's z of the returned design (which satisfies every constraint:
    ``max_violation`` is its worst violation before ``feasibility_pull`` moved it).
    """

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


def failed_stage(stage, run, design, blame=''):
    """
    Return the report entry of a stage whose solve failed (name, status, why, design).

    ``blame``: the scene values that make the program ill-scaled (:func:`speed_blame`).
    """
    return {'stage': stage, 'status': run.status, 'reason': run.why() + blame,
            'design': design}


SPEED_UNIT_RATIO_MAX = 10.0
"""A crank speed above this many times ``normalization.omega_rad_s`` is named when a cone
program fails (:func:`speed_blame`)."""


def speed_blame(speed, omega):
    """
    Return the text naming a crank speed far above the objective's unit ('' when it is not).

    The balancing's objective is in units of the scene's ``normalization`` (force
    m l omega^2, moment m l^2 omega^2); a crank speed far above ``normalization.omega_rad_s``
    makes the cone program's data (~ (speed / omega)^2) span more decades than the solver
    resolves.  Measured on rssr_skew (spatial): certified up to 16 x, not at 48 x,
    NumericalError from about 5e3 x; hoeken (planar): certified up to 1e6 x, not from
    1e7 x.  Slower than the unit certifies (1e-13 x, 1e-9 x).  The limit stated is the
    spatial one, where both certify.
    """
    ratio = speed / omega
    if not ratio > SPEED_UNIT_RATIO_MAX:
        return ''
    return (f'; the scene makes it ill-scaled: crank.speed_rad_s = {speed:g} is {ratio:.3g} x '
            f'normalization.omega_rad_s = {omega:g}, the unit of the objective (its data goes '
            f'as the square, {ratio ** 2:.3g}), expected a crank speed at most '
            f'{SPEED_UNIT_RATIO_MAX:g} x normalization.omega_rad_s (set it near the crank '
            'speed, or drop the normalization block)')


def _bound_detail(bound):
    return {'dual_objective': bound.dual_objective, 'residual_term': bound.residual_term,
            'rounding': bound.rounding, 'dual_residual': bound.dual_residual,
            'projection_shift': bound.projection_shift,
            'unbounded_variables': list(bound.unbounded)}


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
            'source_scene': self.scene.name, 'method': 'seed 001 eqs. 42-53, SOCP',
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
class LinkDesign:
    """One link of a design: point masses (eqs. 11-15), mass, mass centre, inertia."""

    name: str
    point_masses_kg: tuple
    distance_m: float
    mass_kg: float
    com_distance_m: float
    com_angle_deg: float
    inertia_origin_kg_m2: float
    inertia_com_kg_m2: float
    realizable: bool
    reason: str
    normalized: dict = field(default_factory=dict)

    def to_dict(self):
        """Return the link design as a plain dict."""
        return schema.plain(self.__dict__)


def link_design(link, counterweights=False, units=None):
    """
    Return the :class:`LinkDesign` of a scene link (three point masses, l = sqrt(I_O/m)).

    ``counterweights`` also requires non-negative point masses for realizability (case b).
    """
    m = float(link.mass_kg)
    h = complex(*link.first_moment_kg_m)
    i_o = float(link.inertia_origin_kg_m2)
    i_c = equimomental.centroidal_inertia(m, h, i_o)
    if i_o > 0.0:
        pm = equimomental.from_link(m, link.com_m, i_o)   # seed 001 eqs. 8-15
        masses, dist = pm.masses_kg, pm.distance_m
        ok, reason = equimomental.is_realizable(pm, counterweights)
    else:
        masses, dist = (m / 3.0,) * 3, 0.0
        ok, reason = False, 'zero moment of inertia about the origin (a point mass)'
    c = h / m
    out = LinkDesign(link.name, tuple(float(v) for v in masses), dist, m, abs(c),
                     math.degrees(math.atan2(c.imag, c.real)) % 360.0, i_o, i_c, bool(ok),
                     reason)
    if units is not None:
        ms, ls = units.mass_kg, units.length_m
        out.normalized = {'point_masses': [v / ms for v in masses], 'distance': dist / ls,
                          'mass': m / ms, 'com_distance': abs(c) / ls,
                          'inertia_origin': i_o / (ms * ls * ls),
                          'inertia_com': i_c / (ms * ls * ls)}
    return out


def before_after(original, balanced, samples=None):
    """
    Return the before/after rows of RMS bearing forces, torque, shaking force and moment.

    Each row: quantity, ``unit``/``before``/``after`` in the papers' normalized units when
    the scene records a normalization (SI otherwise), the same in SI (``unit_si``,
    ``before_si``, ``after_si``) and ``change_percent``: ``None`` (print 'n/a') when the
    before value is round-off, below :data:`CHANGE_BASELINE_REL_TOL` times the largest
    value of its kind (force or moment) in the table.  Rows are matched by quantity: one
    that the analysis leaves out on one side as round-off (a bearing moment) counts 0 there.
    """
    rig = analysis.Rig(original.with_outputs(('bearing_reactions',)))
    cycles = [analysis.run_cycle(r, samples) for r in
              (rig, rig.with_scene(balanced.with_outputs(('bearing_reactions',))))]
    si = [analysis.summarize(c, False) for c in cycles]
    view = si if original.normalization is None else \
        [analysis.summarize(c, True) for c in cycles]
    quantities = _merged([r.quantity for r in view[0]], [r.quantity for r in view[1]])
    by_name = [[{r.quantity: r for r in rows} for rows in pair] for pair in (view, si)]
    scale = {}
    for row in (*view[0], *view[1]):
        scale[row.kind] = max(scale.get(row.kind, 0.0), row.rms)
    rows = []
    for q in quantities:
        (b, a), (b_si, a_si) = ([side.get(q) for side in pair] for pair in by_name)
        ref, ref_si = b or a, b_si or a_si
        before, after = (0.0 if r is None else r.rms for r in (b, a))
        change = None
        if before > CHANGE_BASELINE_REL_TOL * scale[ref.kind]:
            change = (after - before) / before * 100.0
        rows.append({'quantity': q, 'unit': ref.unit, 'before': before, 'after': after,
                     'change_percent': change, 'unit_si': ref_si.unit,
                     'before_si': 0.0 if b_si is None else b_si.rms,
                     'after_si': 0.0 if a_si is None else a_si.rms})
    return rows


def _merged(first, second):
    """Return the union of two sub-sequences of one order, in that order."""
    out, i, j = [], 0, 0
    while i < len(first) and j < len(second):
        if first[i] == second[j]:
            out.append(first[i])
            i, j = i + 1, j + 1
        elif first[i] not in second:
            out.append(first[i])
            i += 1
        else:
            out.append(second[j])
            j += 1
    return out + first[i:] + second[j:]


# ============================================================================ cone program


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


@dataclass
class _Stage:
    theta: np.ndarray
    objective: float
    dual: float
    status: str
    iterations: int
    r_prim: float
    r_dual: float
    seconds: float
    run: object = None         # Solve
    lo: np.ndarray = None     # explicit box of the program's variables (certificate)
    hi: np.ndarray = None
    norms: list = None        # (G in y units, epigraph index, weight) per objective term
    dscale: np.ndarray = None
    nv: int = 0
    radius_scale: float = None
    free_h: bool = False      # h enters no constraint (case a, no realizability)


def _secondary(spec):
    w1, w2, wt, wr = spec.w
    if wt or wr:
        return None
    if w2 == 0.0:
        return 'moment'
    if w1 == 0.0:
        return 'force'
    return None


@dataclass
class Solve:
    """One cone program as solved: the solution, the data (for the certificate), attempts."""

    sol: object
    status: str
    attempts: tuple        # the status of every attempt, in order
    q: np.ndarray
    a: object              # scipy csc (m, n)
    b: np.ndarray
    cones: list
    seconds: float

    @property
    def ok(self):
        """Return True if the solver's point is usable (Solved or AlmostSolved)."""
        return self.status in SOLVED and np.all(np.isfinite(np.asarray(self.sol.x)))

    def why(self):
        """Return a plain reason for a failed solve (every attempt's status)."""
        return (f'Clarabel status {self.status} after {len(self.attempts)} attempts '
                f'({", ".join(self.attempts)}; retries: more equilibration, other '
                'regularization without presolve, looser tolerances)')


def run_solver(q, a, b, cones):
    """
    Solve ``min q'x s.t. a x + s = b, s in K`` with Clarabel, retrying until Solved.

    Each entry of :data:`RETRY_SETTINGS` is tried in turn until one ends Solved (or proves
    infeasibility); otherwise the best attempt (AlmostSolved before any other) is returned
    with every status in :attr:`Solve.attempts`.
    """
    q = np.asarray(q, dtype=float)
    a = sp.csc_matrix(a)
    b = np.asarray(b, dtype=float)
    p = sp.csc_matrix((q.size, q.size))
    attempts, best, best_rank, t0 = [], None, None, time.perf_counter()
    for extra in RETRY_SETTINGS:
        sol = clarabel.DefaultSolver(p, q, a, b, cones, solver_settings(**extra)).solve()
        status = str(sol.status)
        attempts.append(status)
        finite = bool(np.all(np.isfinite(np.asarray(sol.x))))
        if status == 'Solved' and finite or status in INFEASIBLE:
            best = sol
            break
        rank = (status == 'AlmostSolved' and finite, finite)
        if best is None or rank > best_rank:
            best, best_rank = sol, rank
    return Solve(best, str(best.status), tuple(attempts), q, a, b, cones,
                 time.perf_counter() - t0)


class _Program:
    """Rows of ``A x + s = b, s in K`` for Clarabel, built block by block."""

    def __init__(self, nx):
        self.nx = nx
        self.blocks = []

    def add(self, kind, a, b):
        a = np.atleast_2d(np.asarray(a, dtype=float))
        self.blocks.append((kind, a, np.asarray(b, dtype=float).ravel()))

    def norm_cone(self, t_index, mat, cols):
        """Add ``x[t_index] >= ||mat @ x[cols]||``."""
        a = np.zeros((1 + mat.shape[0], self.nx))
        a[0, t_index] = -1.0
        a[1:, cols] = -mat
        self.add('soc', a, np.zeros(a.shape[0]))

    def solve(self, q):
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
    """
    Build and solve the SOCP (stage 1, or the tie-break stage 2); return a _Stage.

    The variables are each link's parameters in units of its original link,
    y = theta / (m^o, m^o l^o, m^o l^o, m^o l^o^2): the cone forms below are invariant under
    that scaling (h^2 and m I_O scale alike) and it equilibrates links of very different
    size (the carpet scraper's inertias span four decades).
    """
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
    prog = _Program(nx)
    cols = np.arange(nv)
    prog.norm_cone(it_f, maps.force * dscale, cols)
    prog.norm_cone(it_n, maps.moment * dscale, cols)
    primary = np.zeros(nx)
    primary[[it_f, it_n, it_t]] = spec.w[:3]
    if spec.w[2]:
        prog.norm_cone(it_t, maps.torque * dscale, cols)
    for j, mat in enumerate(react):
        prog.norm_cone(ir0 + j, mat * dscale, cols)
        primary[ir0 + j] = spec.w[3]
    for i in range(n):
        im, ix, iy, ii = 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3
        if spec.fixed[i]:
            a = np.zeros((4, nx))
            a[:, im:im + 4] = np.eye(4)
            prog.add('zero', a, y0[im:im + 4])
            continue
        rows, rhs = [], []
        if np.isfinite(spec.mass_lo[i]):   # seed 001 eq. 46b / 50b
            rows.append(_row(nx, {im: -1.0}))
            rhs.append(-spec.mass_lo[i] / m0[i])
        if np.isfinite(spec.mass_hi[i]):
            rows.append(_row(nx, {im: 1.0}))
            rhs.append(spec.mass_hi[i] / m0[i])
        # eq. 46c / 50c: l_lo <= l <= l_hi  <=>  m l_lo^2 <= I_O <= m l_hi^2
        rows.append(_row(nx, {im: (spec.dist_lo[i] / l0[i]) ** 2, ii: -1.0}))
        rhs.append(0.0)
        if np.isfinite(spec.dist_hi[i]):
            rows.append(_row(nx, {im: -(spec.dist_hi[i] / l0[i]) ** 2, ii: 1.0}))
            rhs.append(0.0)
        if spec.case == 'b':
            # eq. 50f: m_j >= 0  <=>  u >= -2 Re(h e^(-i theta_j)), u >= 0, u^2 <= m I_O
            iu = iu0 + i
            rows.append(_row(nx, {iu: -1.0}))
            rhs.append(0.0)
            for unit in equimomental.UNIT:
                rows.append(_row(nx, {ix: -2.0 * unit.real, iy: -2.0 * unit.imag,
                                      iu: -1.0}))
                rhs.append(0.0)
        prog.add('nonneg', rows, rhs)
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
        raise BalanceError(f'solver: {run.why()}; no design')
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
    norms = [(maps.force * dscale, it_f, spec.w[0]), (maps.moment * dscale, it_n, spec.w[1])]
    if spec.w[2]:
        norms.append((maps.torque * dscale, it_t, spec.w[2]))
    norms += [(mat * dscale, ir0 + j, spec.w[3]) for j, mat in enumerate(react)]
    return _Stage(theta=x[:nv] * dscale, objective=float(q @ x),
                  dual=float(run.sol.obj_val_dual), status=status,
                  iterations=int(run.sol.iterations), r_prim=float(run.sol.r_prim),
                  r_dual=float(run.sol.r_dual), seconds=run.seconds, run=run, lo=lo, hi=hi,
                  norms=norms, dscale=dscale, nv=nv,
                  free_h=spec.case == 'a' and not spec.realizable,
                  radius_scale=None if secondary is None or exact_force else
                  bound + TIE_BREAK_SLACK * max(abs(bound), GAP_FLOOR))


def _certify(stage, level, centre_theta=None):
    """
    Return the safe lower bound (:mod:`.certificate`) of a stage's program.

    ``level``: an upper bound on the weighted objective sum w_k ||G_k y|| at some optimal
    point (a feasible design's z, or a tie-break's cap), which bounds the coordinates that
    the constraints leave free (:func:`.certificate.level_set_bounds`).
    """
    lo, hi = stage.lo.copy(), stage.hi.copy()
    nv = stage.nv
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
    """
    Return the safe lower bound of a tie-break stage, never above its solver objective.

    Every feasible point of the stage keeps the primary objective at most its cap
    (``radius_scale``), or, with the exact force balance, the force zero: that level bounds
    the coordinates as in :func:`_certify` (no null direction is assumed: the force rows or
    the cap constrain the first moments).  The min with the solver's objective keeps a bound.
    """
    level = stage.radius_scale if stage.radius_scale is not None else \
        (0.0 if exact else math.inf)
    bound, _ = _certify(stage, level)
    return min(bound.value, stage.objective)


def _row(nx, entries):
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
    """
    Return ``theta`` with each link moved onto its bounds by the least local change.

    The mass clipped into its bounds (and the cap on the added mass taken off the masses
    above their lower bounds), I_O into [m l_lo^2, m l_hi^2], the first moment
    shrunk to the realizability cone (|h|^2 <= m (1 - margin) I_O): the round-off
    violations of an interior-point solution at active constraints.
    """
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


def _feasible(theta, spec):
    """
    Return (design, its violation before, pull): ``theta`` pulled towards the anchor.

    The first fraction of :data:`PULL_STEPS` whose convex combination violates nothing
    (the constraints are convex and the anchor satisfies them).
    """
    before = _violation(theta, spec)
    if before == 0.0:
        return theta, 0.0, 0.0
    fixed = _repaired(theta, spec)
    if _violation(fixed, spec) == 0.0:
        return fixed, before, 0.0
    theta = fixed
    anchor = _anchor(spec)
    for lam in PULL_STEPS[1:]:
        cand = (1.0 - lam) * theta + lam * anchor
        if _violation(cand, spec) == 0.0:
            return cand, before, lam
    return anchor, before, 1.0


# ============================================================================ analytic balance


@dataclass
class AnalyticBalance:
    """An analytic complete force balance: the design, its parameters and its cost."""

    method: str
    scene: object
    balanced_scene: object
    parameters: dict
    links: tuple
    table: list
    force_rms_ratio: float   # RMS shaking force after / before

    def to_dict(self):
        """Return the analytic balance as a plain dict."""
        return schema.plain({'method': self.method, 'scene': self.scene.name,
                             'parameters': self.parameters,
                             'links': [d.to_dict() for d in self.links], 'table': self.table,
                             'force_rms_ratio': self.force_rms_ratio})


def slider_crank_balance(scene, mass_ratios=None, printed_eq75=False, samples=None):
    """
    Return the complete force balance of a slider-crank (seed 000 eqs. 44-75).

    The link masses are kept (or set by ``mass_ratios`` = (mu_1, mu_2) = (m_1, m_2)/m_3,
    eq. 59, with the slider mass kept); the crank's and rod's mass centres are moved to
    the balancing positions and their centroidal inertias kept.

    Derivation in complex numbers (link frames arbitrary): a point P of link k is at
    ``o_k + R_k P`` and the link's first moment about the world origin is
    ``m_k o_k + R_k h_k``.  With crank pivot P_1 and pin A_1 (crank frame), rod points
    A_2, B_2 (rod frame) and the slider at B, the rod's rotation is
    ``R_2 = (B - A) / (B_2 - A_2)`` and the total first moment is, up to a constant,
    ``R_1 [h_1 - m_1 P_1 + (m_2 - g)(A_1 - P_1)] + (g + m_3) B``, with
    ``g = (h_2 - m_2 A_2)/(B_2 - A_2)``.  R_1 and the slider position B(psi) are
    independent functions of the crank angle, so both brackets vanish:

        h_2 = m_2 A_2 - m_3 (B_2 - A_2),   h_1 = m_1 P_1 - (m_2 + m_3)(A_1 - P_1).

    In seed 000's notation (eqs. 63-64, 73: r_1 = (xi_1 + i eta_1) r_12,
    r_2 = (xi_2 + i eta_2) r_23) this is eta_1 = eta_2 = 0 (eq. 74),
    xi_1 = -(1 + mu_2)/mu_1 (eq. 75, as printed) and **xi_2 = -1/mu_2**: eqs. 67 and 71
    give mu_2 xi_2 = -1, while eq. 75 prints xi_2 = 1/mu_2 (a lost sign).  The rod's mass
    centre lies beyond the crank pin, away from the slider.  ``printed_eq75=True`` builds
    the printed design instead, to show that its shaking force does not vanish.
    """
    crank, rod, slider, pts = _chain(scene, 'prismatic')
    m1, m2, m3 = crank.mass_kg, rod.mass_kg, slider.mass_kg
    if mass_ratios is not None:
        mu1, mu2 = (float(v) for v in mass_ratios)
        if not (mu1 > 0.0 and mu2 > 0.0 and math.isfinite(mu1 + mu2)):
            raise BalanceError(f'mass_ratios: got {mass_ratios!r}, expected (mu_1, mu_2) > 0')
        m1, m2 = mu1 * m3, mu2 * m3
    mu1, mu2 = m1 / m3, m2 / m3                                     # seed 000 eq. 59
    p1, a1, a2, b2 = pts['P1'], pts['A1'], pts['A2'], pts['B2']
    xi1 = -(1.0 + mu2) / mu1                                        # eq. 75
    xi2 = (1.0 if printed_eq75 else -1.0) / mu2                     # eq. 75, sign corrected
    c1 = p1 + xi1 * (a1 - p1)                                       # eqs. 63-64, 73-74
    c2 = a2 + xi2 * (b2 - a2)
    links = []
    for lk in scene.links:
        if lk.name == crank.name:
            lk = replace(lk, mass_kg=m1, com_m=(c1.real, c1.imag))
        elif lk.name == rod.name:
            lk = replace(lk, mass_kg=m2, com_m=(c2.real, c2.imag))
        links.append(lk)
    suffix = '_eq75_printed' if printed_eq75 else '_force_balanced'
    balanced = scene.with_links(links, name=scene.name + suffix)
    params = {'mu_1': mu1, 'mu_2': mu2, 'xi_1': xi1, 'eta_1': 0.0, 'xi_2': xi2,
              'eta_2': 0.0, 'xi_2_printed_eq75': 1.0 / mu2, 'printed_eq75': bool(printed_eq75),
              'rho_1': abs(xi1), 'alpha_1_deg': 180.0 if xi1 < 0 else 0.0,
              'rho_2': abs(xi2), 'alpha_2_deg': 180.0 if xi2 < 0 else 0.0}
    return _analytic('slider-crank, seed 000 eqs. 44-75 (xi_2 = -1/mu_2)' if not printed_eq75
                     else 'slider-crank, seed 000 eq. 75 as printed (xi_2 = +1/mu_2)',
                     scene, balanced, params, samples, counterweights=False)


def four_bar_balance(scene, mass_factor=1.0, inertia='distance', samples=None):
    """
    Return the Berkof-Lowen complete force balance of a four-bar (seed 001 eq. 48).

    The coupler (link 2) is kept; the crank's and rocker's masses become ``mass_factor``
    times the original (Table 3 cases 1, 2, 5) and their first moments are set to

        h_1 = m_1 P_1 - (m_2 - g)(A_1 - P_1),   h_3 = m_3 Q_3 - g (B_3 - Q_3),
        g = (h_2 - m_2 A_2) / (B_2 - A_2)

    (crank pivot P_1 and pin A_1, coupler points A_2, B_2, rocker pivot Q_3 and pin B_3, in
    the link frames): the coefficients of the crank and rocker rotations in the total first
    moment after eliminating the coupler's rotation through the loop ``B - A``.  With the
    link x-axes along O_i O_(i+1) this is eq. 48: ``m_1 d_1 = m_2 r_2 a_12/a_2B`` with
    r_2 = |c_2 - B|, ``m_3 d_3 = m_2 d_2 a_3B / a_2B``, theta_1 = theta'_2 and
    theta_3 = theta_2 + pi.

    ``inertia``: 'distance' keeps the point-mass distance l = sqrt(I_O/m) of the original
    (the paper's Table 3, ``l_i1 = l_i1^o``: I_O = m l^2, realizable only if d <= l);
    'centroidal' keeps the centroidal moment of inertia (always realizable).
    """
    crank, coupler, rocker, pts = _chain(scene, 'revolute')
    if inertia not in ('distance', 'centroidal'):
        raise BalanceError(f'inertia: got {inertia!r}, expected "distance" or "centroidal"')
    k = float(mass_factor)
    if not (k > 0.0 and math.isfinite(k)):
        raise BalanceError(f'mass_factor: got {mass_factor!r}, expected a number > 0')
    m2, h2 = coupler.mass_kg, complex(*coupler.first_moment_kg_m)
    g = (h2 - m2 * pts['A2']) / (pts['B2'] - pts['A2'])
    m1, m3 = k * crank.mass_kg, k * rocker.mass_kg
    h1 = m1 * pts['P1'] - (m2 - g) * (pts['A1'] - pts['P1'])       # seed 001 eq. 48
    h3 = m3 * pts['Q3'] - g * (pts['B3'] - pts['Q3'])
    new = {}
    for lk, m, h in ((crank, m1, h1), (rocker, m3, h3)):
        c = h / m
        if inertia == 'distance':
            i_o = m * lk.inertia_origin_kg_m2 / lk.mass_kg          # I_O = m (l^o)^2
            i_c = i_o - abs(h) ** 2 / m
        else:
            i_c = lk.inertia_com_kg_m2
        new[lk.name] = replace(lk, mass_kg=m, com_m=(c.real, c.imag), inertia_com_kg_m2=i_c)
    balanced = scene.with_links([new.get(lk.name, lk) for lk in scene.links],
                                name=f'{scene.name}_force_balanced')
    units = objective_units(scene)
    link1 = pts['A1'] - pts['P1']
    link3 = pts['B3'] - pts['Q3']
    params = {
        'mass_factor': k, 'inertia': inertia,
        'm1_d1_kg_m': abs(h1 - m1 * pts['P1']), 'm3_d3_kg_m': abs(h3 - m3 * pts['Q3']),
        'theta_1_deg': _angle_deg((h1 - m1 * pts['P1']) / link1),
        'theta_3_deg': _angle_deg((h3 - m3 * pts['Q3']) / link3),
        'm1_d1': abs(h1 - m1 * pts['P1']) / (units.mass_kg * units.length_m),
        'm3_d3': abs(h3 - m3 * pts['Q3']) / (units.mass_kg * units.length_m)}
    return _analytic(f'four-bar, Berkof-Lowen (seed 001 eq. 48), links 1 and 3 x{k:g}',
                     scene, balanced, params, samples, counterweights=False)


# ============================================================================ helpers


def _analytic(method, scene, balanced, params, samples, counterweights):
    units = objective_units(scene)
    table = before_after(scene, balanced, samples)
    force = next(r for r in table if r['quantity'].startswith('shaking force'))
    ratio = force['after'] / force['before']
    return AnalyticBalance(method, scene, balanced, params,
                           tuple(link_design(lk, counterweights, units)
                                 for lk in balanced.links), table, ratio)


def _chain(scene, output_type):
    """
    Identify crank, coupler and output of a 3-link single loop; return them and points.

    Points (complex, link frames): P1 crank pivot, A1 crank pin, A2/B2 coupler ends, and
    Q3/B3 rocker pivot and pin (``output_type`` 'revolute') or B3 the slider's joint point.
    """
    _check_planar(scene)
    kind = 'slider-crank' if output_type == 'prismatic' else 'four-bar'
    if len(scene.links) != 3 or len(scene.joints) != 4:
        raise BalanceError(
            f'scene {scene.name!r}: {len(scene.links)} links and {len(scene.joints)} joints, '
            f'expected a {kind} (3 moving links, 4 joints)')
    cj = next(j for j in scene.joints if j.name == scene.crank_joint)
    crank_name = cj.link_b if cj.link_a == FRAME else cj.link_a

    def ends(jt, name):
        return jt.point_a if jt.link_a == name else jt.point_b

    def other(jt, name):
        return jt.link_b if jt.link_a == name else jt.link_a

    joints = [j for j in scene.joints if j is not cj]
    try:
        ja = next(j for j in joints if crank_name in (j.link_a, j.link_b)
                  and FRAME not in (j.link_a, j.link_b))
        coupler_name = other(ja, crank_name)
        jb = next(j for j in joints if j is not ja and coupler_name in (j.link_a, j.link_b))
        out_name = other(jb, coupler_name)
        jg = next(j for j in joints if j not in (ja, jb))
    except StopIteration:
        raise BalanceError(f'scene {scene.name!r}: expected a {kind} chain '
                           'frame-crank-coupler-output-frame') from None
    if out_name in (FRAME, crank_name) or FRAME not in (jg.link_a, jg.link_b) or \
            out_name not in (jg.link_a, jg.link_b) or ja.prismatic or \
            jb.prismatic or jg.joint_type != output_type:
        raise BalanceError(
            f'scene {scene.name!r}: expected a {kind} (revolute crank, coupler joints '
            f'revolute, output joined to the frame by a {output_type} joint)')
    crank, coupler, out = (scene.link(n) for n in (crank_name, coupler_name, out_name))

    def pt(link, name):
        return complex(*link.points[name])

    pts = {'P1': pt(crank, ends(cj, crank_name)), 'A1': pt(crank, ends(ja, crank_name)),
           'A2': pt(coupler, ends(ja, coupler_name)), 'B2': pt(coupler, ends(jb, coupler_name)),
           'B3': pt(out, ends(jb, out_name)), 'Q3': pt(out, ends(jg, out_name))}
    return crank, coupler, out, pts


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


def _angle_deg(z):
    return math.degrees(math.atan2(z.imag, z.real)) % 360.0


def _check_planar(scene):
    kind = schema.kind_of(scene)
    if 'mass_redistribution' not in kind.rig_factory().capabilities:
        raise BalanceError(f'scene {scene.name!r}: kind {kind.name!r}, expected a planar '
                           'scene (the rig cannot be balanced by mass redistribution; '
                           'mech_balance.balancing.balance picks its method)')


def _weights(weights):
    try:
        w1, w2 = (float(v) for v in weights)
    except (TypeError, ValueError):
        raise BalanceError(f'weights: got {_show(weights)}, expected two numbers (w1, w2)') \
            from None
    for name, v in (('w1', w1), ('w2', w2)):
        if not (math.isfinite(v) and v >= 0.0):
            raise BalanceError(f'weights: {name} = {v:g}, expected a finite number >= 0')
        if v > MAX_WEIGHT:
            raise BalanceError(f'weights: {name} = {v:g}, expected at most {MAX_WEIGHT:g} '
                               '(the fixed range of the weights)')
    return w1, w2


def _nonneg(value, name, highest=None):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise BalanceError(f'{name}: got {value!r}, expected a number >= 0') from None
    if not (math.isfinite(v) and v >= 0.0):
        raise BalanceError(f'{name}: got {v:g}, expected a finite number >= 0')
    if highest is not None and v > highest:
        raise BalanceError(f'{name}: got {v:g}, expected at most {highest:g} '
                           '(the fixed range of the weights)')
    return v


def _link_names(values, names, field_name):
    if isinstance(values, str):
        values = [values]
    out = set()
    for v in values or ():
        if v not in names:
            raise BalanceError(f'{field_name}: got {v!r}, expected link names from '
                               f'{", ".join(names)}')
        if v in out:
            raise BalanceError(f'{field_name}: got {v!r} twice, expected each link once')
        out.add(v)
    return out


def _bounds(given, names, original, factors, field_name, factors_name):
    """
    Return SI (lo, hi) arrays: defaults are factors x original, overridden per link.

    Every link needs 0 < lo <= hi (hi may be inf, for no bound; lo == hi fixes the value):
    a link without mass, or with point masses at distance 0 (I_O = 0, no body, the
    equimomental model of seed 001 eq. 27 degenerates), makes the problem meaningless.
    """
    try:
        f_lo, f_hi = (float(v) for v in factors)
    except (TypeError, ValueError):
        raise BalanceError(f'{factors_name}: got {_show(factors)}, expected (low, high)') \
            from None
    if not (0.0 < f_lo <= f_hi) or math.isinf(f_lo):
        raise BalanceError(f'{factors_name}: got {_show(factors)}, expected factors of the '
                           'original with 0 < low <= high')
    lo = np.array(original, dtype=float) * f_lo
    hi = np.array(original, dtype=float) * f_hi
    from_factors = set(names)
    if given is not None:
        if not isinstance(given, dict):
            raise BalanceError(f'{field_name}: got {_show(given)}, expected a mapping link -> '
                               '(min, max)')
        for key, pair in given.items():
            if key not in names:
                raise BalanceError(f'{field_name}.{key}: no such link, expected one of '
                                   f'{", ".join(names)}')
            i = names.index(key)
            try:
                a, b = pair
                a = float(a)
                b = math.inf if b is None else float(b)
            except (TypeError, ValueError):
                raise BalanceError(f'{field_name}.{key}: got {_show(pair)}, expected '
                                   '(min, max), max may be None') from None
            if not (0.0 < a <= b) or math.isinf(a):
                raise BalanceError(f'{field_name}.{key}: got {_show(pair)}, expected '
                                   '0 < min <= max')
            lo[i], hi[i] = a, b
            from_factors.discard(key)
    low_ratio, high_ratio = DISTANCE_RATIO_RANGE if field_name == 'distance_bounds' else \
        BOUND_RATIO_RANGE
    for i, name in enumerate(names):
        if not lo[i] > 0.0:   # a factor times an original of 0
            raise BalanceError(f'{field_name}.{name}: lower bound {lo[i]:g}, expected > 0 '
                               f'(the original is 0; give {field_name} for this link)')
        ref = float(original[i])
        if ref > 0.0 and not (low_ratio * ref <= lo[i] and
                              (math.isinf(hi[i]) or hi[i] <= high_ratio * ref)):
            where = f'{factors_name} {_show(factors)} for link {name}' \
                if name in from_factors else f'{field_name}.{name}'
            raise BalanceError(
                f'{where}: got ({lo[i]:g}, {hi[i]:g}), expected bounds within '
                f'[{low_ratio:g}, {high_ratio:g}] x the original {ref:g} (defaults.'
                'BOUND_RATIO_RANGE, DISTANCE_RATIO_RANGE: tighter or wider bounds no '
                'solver resolves)')
    return lo, hi


def _show(value):
    """Return a value for an error message: numbers as :g, never a numpy repr."""
    if isinstance(value, (list, tuple, np.ndarray)):
        return '(' + ', '.join(_show(v) for v in value) + ')'
    if isinstance(value, (float, np.floating, np.integer)) and not isinstance(value, bool):
        return f'{value:g}'
    return repr(value)


def _num(x):
    return None if not math.isfinite(x) else float(x)
