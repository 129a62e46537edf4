"""
Add-only counterweight balancing: one solid disc per listed link, to a certified optimum.

Seed 001's optimum redistributes each link's whole mass; an engineer who owns the rig adds
counterweights to the links it has.  Here each listed link keeps its own mass, mass centre
and inertia and gains one disc (solid cylinder, axis normal to the plane of motion) of
density rho and thickness t <= t_max, its centre r (link frame) at |r| <= r_max and its mass
dm <= max_mass_factor x the link's mass; every other link is untouched.

Convexity (the derivation).  A disc of mass dm, radius R and thickness t has
``dm = rho pi R^2 t`` and centroidal inertia ``I_c = dm R^2 / 2 = dm^2 / (2 pi rho t)``.  With
``dh = dm r`` (its first moment) and ``dI`` (its inertia about the link origin, parallel
axes) ``dI = I_c + dm |r|^2 = I_c + |dh|^2 / dm``.  So t <= t_max is
``I_c >= dm^2 / (2 pi rho t_max)``, and a disc realizes (dm, dh, dI) exactly when

    |dh| <= r_max dm,      dI >= |dh|^2 / dm + dm^2 / (2 pi rho t_max)

(any larger I_c is a thinner, wider disc: ``t = dm^2/(2 pi rho I_c)``, ``R = sqrt(2 I_c/dm)``),
and one bound more, linear: ``dI <= k_max^2 dm`` (:data:`DEFAULT_MAX_GYRATION_FACTOR`).
``|dh|^2/dm`` (quadratic over linear) and ``dm^2/c`` are convex, so the set is convex; with an
auxiliary s it is two rotated second-order cones, ``|dh|^2 <= dm (dI - s)`` and
``dm^2 <= c s`` (c = 2 pi rho t_max), plus the cone ``|dh| <= r_max dm``.  The link
parameters theta = (m, m c, I_O) become theta_0 + (dm, dh, dI), and every RMS quantity of
the objective is the norm of an affine map of them (seed 001 eqs. 25-26, 39;
:func:`mech_balance.analysis.linear_maps.linear_maps`), so the whole problem is a second-order cone
program, solved by Clarabel with its duality gap as the certificate.

Objective and ties as :func:`mech_balance.balancing.redistribution.optimize`: ``z = w1 f~ + w2 n~
[+ torque_weight tau~ + reaction_weight sum f~_j]``.  With exactly one of w1, w2 non-zero the
optimum is generally not unique: stage 2 minimizes the other RMS among the optimal designs
(with complete force balance imposed exactly when w2 = 0 and it is attainable), and stage 3
the total added mass among those.  A single-norm stage's optimal set is pinned exactly (a
Euclidean norm minimized over a convex set has one optimal image, so the optimal designs
are those with the same image: an equality on the map's row space), a weighted sum of norms
by ``z <= z* + TIE_BREAK_SLACK max(z*, 1)``.  A link whose inertia enters no term (a crank
turning at constant speed) gets the thickest, smallest disc, t = t_max.  A counterweight
lighter than :data:`MIN_MASS_REL` of its link is none (omitted).
"""

from dataclasses import dataclass, field
import math
import time

import clarabel
from mech_balance import conic, schema
from mech_balance.analysis import clearance as clearance_mod, linear_maps
from mech_balance.balancing import certificate, checks, clearance_design, conditioning, \
    redistribution, tables
from mech_balance.balancing.defaults import check_counterweight_option, \
    DEFAULT_DENSITY_KG_M3, DEFAULT_MAX_GYRATION_FACTOR, DEFAULT_MAX_MASS_FACTOR, \
    DEFAULT_MAX_RADIUS_FACTOR, DEFAULT_MAX_THICKNESS_M, DEFAULT_WEIGHTS
from mech_balance.core.planar import dynamics, rig as planar_rig
from mech_balance.schema.scene import add_counterweights, Counterweight, MAX_PLANE_OFFSET_M
import numpy as np
import scipy.sparse as sp

MIN_MASS_REL = 1e-7
"""An optimal disc mass below this fraction of its link's mass is no counterweight (omitted:
the cones force its first moment and inertia to zero with it; the solver's accuracy is
~1e-9 of the link, so such a disc's centre is noise)."""
TIE_BREAK_SLACK = 1e-9
"""A tie-break stage after a weighted sum of norms keeps z within this fraction of
max(z*, 1) (a single-norm stage is pinned exactly instead)."""
MASS_STAGE_SLACKS = (TIE_BREAK_SLACK, TIE_BREAK_SLACK, 1e-7)
"""The least-mass stage keeps the earlier objectives within these fractions of max(z, 1), tried
in turn until it solves (first with an exact force balance kept exactly, then capped)."""
FREE_INERTIA_REL = 1e-12
"""A link's inertia column below this fraction of a term's map: the inertia enters no term."""
METHOD = 'counterweights (add-only discs, SOCP)'


class CounterweightError(checks.BalanceError):
    """A counterweight problem has a bad option or cannot be solved."""


# ============================================================================ options


@dataclass(frozen=True)
class CounterweightOptions:
    """The plain options of :func:`balance_with_counterweights` (what a node passes)."""

    links: tuple
    weights: tuple = DEFAULT_WEIGHTS
    density_kg_m3: float = DEFAULT_DENSITY_KG_M3
    max_thickness_m: float = DEFAULT_MAX_THICKNESS_M
    max_radius_factor: float = DEFAULT_MAX_RADIUS_FACTOR
    max_mass_factor: float = DEFAULT_MAX_MASS_FACTOR
    max_gyration_factor: float = DEFAULT_MAX_GYRATION_FACTOR
    torque_weight: float = 0.0
    reaction_weight: float = 0.0
    samples: int = None
    tie_break: bool = True
    planes: tuple = ()                  # ((link, plane_m), ...): a disc's plane (clearance)
    max_rim_radius_factor: float = None  # disc inside F x joint reach of its link's origin
    clearance_margin_m: float = clearance_design.DEFAULT_CLEARANCE_MARGIN_M  # None: off
    disc_side: str = 'auto'             # where the discs' layers go (clearance_design.SIDES)
    max_overhang_m: float = None        # a disc's outer face at most this beyond the linkage

    def to_dict(self):
        """Return the options as a plain dict."""
        out = dict(self.__dict__)
        out['planes'] = {str(k): float(v) for k, v in dict(self.planes).items()}
        return schema.plain(out)


def positive(value, name):
    """Return ``value`` as a finite float > 0, else :class:`CounterweightError` naming it."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CounterweightError(f'{name}: got {value!r}, expected a number > 0') from None
    if not (math.isfinite(v) and v > 0.0):
        raise CounterweightError(f'{name}: got {v:g}, expected a finite number > 0')
    return v


def nonnegative(value, name):
    """Return ``value`` as a finite float >= 0, else :class:`CounterweightError` naming it."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CounterweightError(f'{name}: got {value!r}, expected a number >= 0') from None
    if not (math.isfinite(v) and v >= 0.0):
        raise CounterweightError(f'{name}: got {v:g}, expected a finite number >= 0')
    return v


def link_list(links, scene, name='counterweight_links'):
    """Return the listed link names (text 'a,b' or a sequence), checked against the scene."""
    if isinstance(links, str):
        links = [v.strip() for v in links.split(',')]
    try:
        links = [str(v) for v in links]
    except TypeError:
        raise CounterweightError(f'{name}: got {links!r}, expected link names') from None
    names = [lk.name for lk in scene.links]
    out = []
    for v in links:
        if v not in names:
            raise CounterweightError(f'{name}: got {v!r}, expected link names from '
                                     f'{", ".join(names)}')
        if v not in out:
            out.append(v)
    if not out:
        raise CounterweightError(f'{name}: got none, expected at least one link from '
                                 f'{", ".join(names)}')
    return tuple(out)


def check_options(scene, options):
    """Return validated :class:`CounterweightOptions` (errors name the option)."""
    kind = schema.kind_of(scene)
    if 'counterweights' not in kind.rig_factory().capabilities:
        raise CounterweightError(f'scene {scene.name!r}: kind {kind.name!r}, expected a '
                                 'planar scene')
    try:
        w1, w2 = (float(v) for v in options.weights)
    except (TypeError, ValueError):
        raise CounterweightError(f'weights: got {options.weights!r}, expected two numbers '
                                 '(w1, w2)') from None
    w1, w2 = nonnegative(w1, 'weights (w1)'), nonnegative(w2, 'weights (w2)')
    tw = nonnegative(options.torque_weight, 'torque_weight')
    rw = nonnegative(options.reaction_weight, 'reaction_weight')
    if w1 + w2 + tw + rw == 0.0:
        raise CounterweightError('weights: got all zero, expected at least one positive weight')
    samples = scene.samples if options.samples is None else options.samples
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 4:
        raise CounterweightError(f'samples: got {samples!r}, expected an integer >= 4')
    return CounterweightOptions(
        links=link_list(options.links, scene), weights=(w1, w2),
        density_kg_m3=_ranged(options.density_kg_m3, 'density_kg_m3'),
        max_thickness_m=_ranged(options.max_thickness_m, 'max_thickness_m'),
        max_radius_factor=_ranged(options.max_radius_factor, 'max_radius_factor'),
        max_mass_factor=_ranged(options.max_mass_factor, 'max_mass_factor'),
        max_gyration_factor=_ranged(options.max_gyration_factor, 'max_gyration_factor'),
        torque_weight=tw, reaction_weight=rw, samples=int(samples),
        tie_break=bool(options.tie_break), planes=plane_list(options.planes, options.links,
                                                             scene),
        max_rim_radius_factor=None if options.max_rim_radius_factor is None else
        _ranged(options.max_rim_radius_factor, 'max_rim_radius_factor'),
        **_clearance_options(options))


def _clearance_options(options):
    """Return the checked clearance options (errors name the option)."""
    try:
        over = options.max_overhang_m
        return {'clearance_margin_m': clearance_design.check_margin(options.clearance_margin_m),
                'disc_side': clearance_design.check_side(options.disc_side),
                'max_overhang_m': None if over is None else
                min(positive(over, 'max_overhang_m'), MAX_PLANE_OFFSET_M)}
    except ValueError as exc:
        raise CounterweightError(str(exc)) from None


def plane_list(planes, links, scene, name='planes'):
    """
    Return ``((link, plane_m), ...)`` of a plane per counterweight link, checked.

    ``planes``: a mapping, pairs, or text 'crank=-0.03,rocker=0.03' (m: the disc's mid-plane
    offset along z from its link's plane; a listed link without one: its own plane, 0).
    """
    listed = link_list(links, scene)
    if isinstance(planes, str):
        items = []
        for part in (v.strip() for v in planes.split(',')):
            if not part:
                continue
            link, sep, value = part.partition('=')
            if not sep:
                raise CounterweightError(f'{name}: got {part!r}, expected LINK=Z_M (a link and '
                                         "its disc's plane offset in m)")
            items.append((link.strip(), value.strip()))
    else:
        try:
            items = list(dict(planes or ()).items())
        except (TypeError, ValueError):
            raise CounterweightError(f'{name}: got {planes!r}, expected link: plane_m '
                                     'pairs') from None
    out = {}
    for link, value in items:
        if link not in listed:
            raise CounterweightError(f'{name}: got link {link!r}, expected one of the '
                                     f'counterweight links {", ".join(listed)}')
        if link in out:
            raise CounterweightError(f'{name}: got {link!r} twice, expected one plane per link')
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise CounterweightError(f'{name}.{link}: got {value!r}, expected a number '
                                     '(m)') from None
        if not (math.isfinite(v) and abs(v) <= MAX_PLANE_OFFSET_M):
            raise CounterweightError(f'{name}.{link}: got {v:g}, expected a plane offset '
                                     f'within +-{MAX_PLANE_OFFSET_M:g} m')
        out[link] = v + 0.0
    return tuple(out.items())


def _ranged(value, option):
    """Return an option checked against :data:`.defaults.COUNTERWEIGHT_RANGES`."""
    positive(value, option)
    try:
        return check_counterweight_option(option, value)
    except ValueError as exc:
        raise CounterweightError(str(exc)) from None


def joint_reach_m(scene, link_name):
    """Return the distance from a link's origin to its farthest joint point (m)."""
    lk = scene.link(link_name)
    used = {j.point_a for j in scene.joints if j.link_a == link_name} | \
        {j.point_b for j in scene.joints if j.link_b == link_name}
    return max(math.hypot(*lk.points[p]) for p in used)


# ============================================================================ results


@dataclass
class CounterweightDesign:
    """One counterweight as built: a disc on its link (SI; angle in deg, link frame)."""

    link: str
    mass_kg: float
    centre_m: tuple
    centre_radius_m: float
    centre_angle_deg: float
    radius_m: float
    thickness_m: float
    density_kg_m3: float
    inertia_com_kg_m2: float
    max_centre_radius_m: float
    max_mass_kg: float
    plane_m: float = 0.0        # the disc's plane: offset along z from its link's plane
    mount: str = ''             # the link's point whose shaft carries it ('' nearest)

    def counterweight(self):
        """Return the scene's :class:`~mech_balance.scene.Counterweight` of this disc."""
        return Counterweight(self.mass_kg, tuple(self.centre_m), self.radius_m,
                             self.thickness_m, self.density_kg_m3, self.plane_m, self.mount)

    def to_dict(self):
        """Return the design as a plain dict."""
        return schema.plain(self.__dict__)


@dataclass
class CounterweightResult:
    """The optimal counterweights, the balanced scene, the certificate and the cost."""

    scene: object
    balanced_scene: object
    options: CounterweightOptions
    units: object
    designs: tuple          # CounterweightDesign per link that gets a disc
    omitted: tuple          # listed links whose optimal disc is none (dm -> 0)
    link_totals: dict       # link -> {mass_kg, com_m, inertia_com_kg_m2, inertia_origin_kg_m2}
    objective: dict
    certificate: certificate.Certificate
    least_mass: dict        # the least-added-mass stage (None if not solved)
    table: list             # tables.before_after rows
    cost: dict              # cost_of_balancing
    maps_time_s: float
    conic_time_s: float
    solve_time_s: float
    clearance: object = None  # analysis.clearance.Clearance of the balanced scene
    clearance_design: object = None  # clearance_design.ClearanceReport (None: design off)

    @property
    def answered(self):
        """Return whether there is a design to give (not 'no collision-free design')."""
        return self.clearance_design is None or self.clearance_design.status != 'none'

    @property
    def counterweights(self):
        """Return ``{link: [disc entry]}``, the scene's form (``links.<name>.counterweights``)."""
        return {d.link: [d.counterweight().to_dict()] for d in self.designs}

    @property
    def added_mass_kg(self):
        """Return the total mass of the counterweights."""
        return float(sum(d.mass_kg for d in self.designs))

    def summary(self):
        """Return the provenance stored with the balanced scene (``balance`` key)."""
        return schema.plain({
            'source_scene': self.scene.name, 'method': METHOD,
            'options': self.options.to_dict(), 'objective': self.objective,
            'relative_gap': self.certificate.gap_rel,
            'lower_bound': self.certificate.lower_bound,
            'certified': self.certificate.certified,
            'failed_stages': self.certificate.failed_stages or [],
            'added_mass_kg': self.added_mass_kg,
            **({} if self.clearance_design is None else
               {'clearance_design': self.clearance_design.to_dict()}),
            **({} if self.clearance is None else
               {'least_clearance_m': self.clearance.to_dict()['least_clearance_m'],
                'collisions': len(self.clearance.collisions)})})

    def to_dict(self):
        """Return everything as a plain, YAML- and JSON-able dict (SI, and normalized z)."""
        u = self.units
        return schema.plain({
            'scene': self.scene.name, 'method': METHOD, 'options': self.options.to_dict(),
            'units': {'mass_kg': u.mass_kg, 'length_m': u.length_m,
                      'omega_rad_s': u.omega_rad_s},
            'counterweights': self.counterweights,
            'designs': [d.to_dict() for d in self.designs], 'omitted': list(self.omitted),
            'added_mass_kg': self.added_mass_kg, 'link_totals': self.link_totals,
            'objective': self.objective, 'certificate': self.certificate.to_dict(),
            'least_mass_stage': self.least_mass, 'table': self.table, 'cost': self.cost,
            'maps_time_s': self.maps_time_s, 'conic_time_s': self.conic_time_s,
            'solve_time_s': self.solve_time_s,
            'clearance': None if self.clearance is None else self.clearance.to_dict(),
            'clearance_design': None if self.clearance_design is None else
            self.clearance_design.to_dict(),
            'warnings': [] if self.clearance is None else self.clearance.warnings()})


# ============================================================================ public API


def balance_with_counterweights(scene, links, weights=DEFAULT_WEIGHTS, *,
                                density_kg_m3=DEFAULT_DENSITY_KG_M3,
                                max_thickness_m=DEFAULT_MAX_THICKNESS_M,
                                max_radius_factor=DEFAULT_MAX_RADIUS_FACTOR,
                                max_mass_factor=DEFAULT_MAX_MASS_FACTOR,
                                max_gyration_factor=DEFAULT_MAX_GYRATION_FACTOR,
                                torque_weight=0.0, reaction_weight=0.0, samples=None,
                                tie_break=True, planes=(), max_rim_radius_factor=None,
                                clearance_margin_m=clearance_design.DEFAULT_CLEARANCE_MARGIN_M,
                                disc_side='auto', max_overhang_m=None):
    """
    Return the optimal add-only counterweights of ``links`` (a :class:`CounterweightResult`).

    ``links``: names (a sequence or 'a,b').  The options are those of
    :class:`CounterweightOptions` (SI); see the module docstring for the problem.
    """
    return solve(scene, CounterweightOptions(
        links=links, weights=weights, density_kg_m3=density_kg_m3,
        max_thickness_m=max_thickness_m, max_radius_factor=max_radius_factor,
        max_mass_factor=max_mass_factor, max_gyration_factor=max_gyration_factor,
        torque_weight=torque_weight,
        reaction_weight=reaction_weight, samples=samples, tie_break=tie_break, planes=planes,
        max_rim_radius_factor=max_rim_radius_factor, clearance_margin_m=clearance_margin_m,
        disc_side=disc_side, max_overhang_m=max_overhang_m))


def solve(scene, options):
    """Solve the counterweight problem of :class:`CounterweightOptions` ``options``."""
    t_start = time.perf_counter()
    opt = check_options(scene, options)
    units = planar_rig.objective_units(scene)
    need = ['shaking_wrench']
    if opt.torque_weight:
        need.append('driving_torque')
    if opt.reaction_weight:
        need.append('bearing_reactions')
    t0 = time.perf_counter()
    maps = linear_maps.linear_maps(scene, opt.samples, need, units)
    maps_s = time.perf_counter() - t0
    prob = _Problem(scene, maps, opt, units)
    stage1 = prob.run(prob.weights_vector(), [])
    failed = []
    blame = prob.blame()
    if not stage1.solve.ok:
        failed.append(certificate.failed_stage(
            'primary (z)', stage1.solve, "the solver's last iterate, made "
            'feasible; its lower bound is safe', blame))
    y, stage2, stage3, exact = stage1.y, None, None, False
    secondary = prob.secondary()
    pins = []
    if opt.tie_break and secondary is not None and stage1.solve.ok:
        name2 = f"tie-break (least RMS shaking {('force', 'moment')[secondary]})"
        primary = 0 if secondary == 1 else 1
        exact = (secondary == 1 and
                 prob.norm(0, y) <= redistribution.FORCE_BALANCE_REL_TOL * maps.force_rms_original)
        pins = [prob.pin(primary, y, exact)]
        stage2 = prob.run(prob.unit(secondary), pins)
        tried = list(stage2.solve.attempts)
        if not stage2.solve.ok and not exact:
            # the optimal image pinned exactly can be infeasible to round-off: cap the
            # primary norm instead (z <= z* + slack), as the mass stage does
            z_p = prob.norm(primary, y)
            for slack in MASS_STAGE_SLACKS[1:]:
                cap = [(prob.unit(primary), z_p + slack * max(z_p, certificate.GAP_FLOOR))]
                stage2 = prob.run(prob.unit(secondary), [], None, cap)
                tried.extend(stage2.solve.attempts)
                if stage2.solve.ok:
                    pins = []
                    break
        stage2.solve.attempts = tuple(tried)
        if not stage2.solve.ok:
            failed.append(certificate.failed_stage(name2, stage2.solve,
                                                   "the primary stage's optimum", blame))
            stage2, exact, pins = None, False, []
        else:
            y = stage2.y
            if pins:
                pins = pins + [prob.pin(secondary, y, False)]
    if opt.tie_break and stage1.solve.ok:
        # the mass stage keeps every earlier objective optimal: the optimal images pinned
        # exactly, or, where that is infeasible to round-off at active cones (Clarabel ends
        # AlmostPrimalInfeasible), each objective capped at its optimum plus a slack
        variants = []
        if pins:   # first the optimal images pinned exactly (the tie-break's own argument)
            variants.append((prob.merged(pins, y), None, []))
        for slack in MASS_STAGE_SLACKS:
            bound, caps, keep = None, [], []
            if stage2 is None:
                z1 = prob.z(y)
                bound = z1 + slack * max(z1, certificate.GAP_FLOOR)
            else:
                if exact and pins and slack == MASS_STAGE_SLACKS[0]:
                    keep = pins[:1]
                for k in ([secondary] if keep else [primary, secondary]):
                    zk = prob.norm(k, y)
                    caps.append((prob.unit(k), zk + slack * max(zk, certificate.GAP_FLOOR)))
            variants.append((keep, bound, caps))
        tried = []
        for keep, bound, caps in variants:
            stage3 = prob.run(prob.mass_vector(), keep, bound, caps)
            tried.extend(stage3.solve.attempts)
            if stage3.solve.ok:
                break
        stage3.solve.attempts = tuple(tried)
        if not stage3.solve.ok:
            failed.append(certificate.failed_stage(
                'least added mass', stage3.solve, "the previous stage's optimum (its "
                'added mass is not the least)', blame))
            stage3 = None
        else:
            y = stage3.y
    if exact:
        y = prob.project_force_balance(y)
    designs, omitted, worst = prob.discs(y)
    y, pull = prob.feasible(y, worst)
    designs, omitted, final_violation = prob.discs(y)
    balanced = _balanced(scene, designs)
    theta = dynamics.parameter_vector(dynamics.Inertia.from_links(balanced.links)) / prob.scale
    terms = maps.terms(theta)
    w = prob.weights4
    primal = float(np.dot(w, terms))
    bound1 = prob.lower_bound(stage1, primal)
    lower = min(bound1.value, primal)
    gap, gap_rel = certificate.relative_gap(primal, lower, certificate.GAP_FLOOR)
    s2 = None
    if stage2 is not None:
        # its own safe bound (the box of the disc constraints holds an optimal point: every
        # t at its norm); min with the solver's objective keeps it a bound, never above it
        lb2 = min(prob.lower_bound(stage2, None).value, stage2.objective)
        s2 = {'minimized': f"RMS shaking {('force', 'moment')[secondary]}",
              'status': stage2.status, 'objective': stage2.objective,
              'lower_bound': lb2, 'iterations': stage2.iterations,
              'attempts': list(stage2.solve.attempts), 'exact_force_balance': bool(exact)}
    cert = certificate.Certificate(
        solver=f'clarabel {clarabel.__version__}', status=stage1.status, primal=primal,
        dual=lower, gap_abs=gap, gap_rel=gap_rel,
        residual_primal=stage1.r_prim, residual_dual=stage1.r_dual,
        iterations=stage1.iterations, stage2=s2, max_violation=worst, lower_bound=lower,
        attempts=list(stage1.solve.attempts),
        bound_detail=dict(certificate.bound_detail(bound1), null_directions_assumed=0),
        feasibility_pull=pull, failed_stages=failed,
        certified=bool(np.isfinite(lower) and gap_rel <= certificate.CERTIFIED_GAP_REL
                       and final_violation == 0.0),
        design_violation=final_violation)
    least = None
    if stage3 is not None:
        mass = sum(d.mass_kg for d in designs) / units.mass_kg
        lb3 = min(prob.lower_bound(stage3, None).value, mass)
        least = {'minimized': 'total added mass', 'status': stage3.status,
                 'objective_kg': mass * units.mass_kg, 'lower_bound_kg': lb3 * units.mass_kg,
                 'dual_kg': lb3 * units.mass_kg, 'iterations': stage3.iterations,
                 'attempts': list(stage3.solve.attempts)}
    report = None
    if opt.clearance_margin_m is not None:   # the convex optimum made collision-free
        designs, report = clearance_design.design(
            scene, prob, designs, lower, opt.clearance_margin_m, opt.disc_side,
            opt.max_overhang_m, fixed_planes=bool(opt.planes))
        balanced = _balanced(scene, designs)
        terms = maps.terms(dynamics.parameter_vector(
            dynamics.Inertia.from_links(balanced.links)) / prob.scale)
    clear = clearance_mod.of_design(scene, balanced, opt.samples,
                                    opt.clearance_margin_m or 0.0)
    table = tables.before_after(scene, balanced, opt.samples)
    conic_s = sum(s.seconds for s in (stage1, stage2, stage3) if s is not None)
    totals = {lk.name: {'mass_kg': lk.mass_kg, 'com_m': list(lk.com_m),
                        'inertia_com_kg_m2': lk.inertia_com_kg_m2,
                        'inertia_origin_kg_m2': lk.inertia_origin_kg_m2,
                        'own_mass_kg': lk.own_mass_kg}
              for lk in balanced.links if lk.name in opt.links}
    t_orig = maps.terms(maps.theta_original)
    return CounterweightResult(
        scene=scene, balanced_scene=balanced, options=opt, units=units,
        designs=tuple(designs), omitted=tuple(omitted), link_totals=totals,
        objective={'z': float(np.dot(w, terms)), 'z_convex': primal,
                   'shaking_force_rms': float(terms[0]),
                   'shaking_moment_rms': float(terms[1]),
                   'driving_torque_rms': float(terms[2]) if opt.torque_weight else None,
                   'bearing_force_rms_sum': float(terms[3]) if opt.reaction_weight else None,
                   'z_original': float(np.dot(w, t_orig)),
                   'shaking_force_rms_original': float(t_orig[0]),
                   'shaking_moment_rms_original': float(t_orig[1])},
        certificate=cert, least_mass=least, table=table,
        cost=cost_of_balancing(scene, balanced, table), maps_time_s=maps_s,
        conic_time_s=conic_s, solve_time_s=time.perf_counter() - t_start, clearance=clear,
        clearance_design=report)


def _balanced(scene, designs):
    """Return the scene with the discs of ``designs`` added to their links."""
    by_link = {d.link: d for d in designs}
    return scene.with_links([lk if lk.name not in by_link else
                             add_counterweights(lk, [by_link[lk.name].counterweight()])
                             for lk in scene.links], name=f'{scene.name}_counterweights')


def cost_of_balancing(original, balanced, table):
    """
    Return what a balance did to the shaking moment, torque, bearing loads and total mass.

    From the before/after rows of :func:`mech_balance.balancing.tables.before_after` (SI RMS
    values): ``{quantity: {before, after, change_percent}}`` for the shaking force, shaking
    moment, driving torque, the sum of the RMS bearing forces and the total moving mass
    (kg).  ``change_percent`` is None when the before value is zero.
    """
    rows = {r['quantity']: r for r in table}

    def entry(before, after):
        change = None if before == 0.0 else (after - before) / before * 100.0
        return {'before': float(before), 'after': float(after), 'change_percent': change}

    out = {}
    for key, name in (('shaking_force', 'shaking force |f_sh|'),
                      ('shaking_moment', 'shaking moment n_sh'),
                      ('driving_torque', 'driving torque')):
        if name in rows:
            out[key] = entry(rows[name]['before_si'], rows[name]['after_si'])
    bearings = [r for q, r in rows.items() if q.startswith('bearing ') and q.endswith('|f|')]
    if bearings:
        out['bearing_forces_sum'] = entry(sum(r['before_si'] for r in bearings),
                                          sum(r['after_si'] for r in bearings))
    out['total_mass_kg'] = entry(sum(lk.mass_kg for lk in original.links),
                                 sum(lk.mass_kg for lk in balanced.links))
    return out


def format_cost(cost):
    """Return the cost of balancing as one plain line of percent changes."""
    labels = (('shaking_moment', 'shaking moment'), ('driving_torque', 'driving torque'),
              ('bearing_forces_sum', 'bearing loads (sum of RMS bearing forces)'),
              ('total_mass_kg', 'total mass'), ('shaking_force', 'shaking force'))
    parts = []
    for key, label in labels:
        if key in cost:
            ch = cost[key]['change_percent']
            parts.append(f'{label} ' + ('n/a' if ch is None else f'{ch:+.1f}%'))
    return 'cost of balancing: ' + ', '.join(parts)


# ============================================================================ the program


@dataclass
class _Stage:
    y: np.ndarray
    objective: float
    dual: float
    status: str
    iterations: int
    r_prim: float
    r_dual: float
    seconds: float
    solve: object = None      # conic.Solve: the data and statuses of the program


@dataclass
class _Problem:
    """The counterweight SOCP of one scene: variables, cones, stages."""

    scene: object
    maps: object
    opt: CounterweightOptions
    units: object
    norms: list = field(default_factory=list)   # (G (k, 4L), c (k,)) per objective term
    _static: tuple = None                       # the shared cones, built once

    def __post_init__(self):
        maps, opt, u = self.maps, self.opt, self.units
        names = [lk.name for lk in self.scene.links]
        n = len(names)
        ms, ls = u.mass_kg, u.length_m
        self.scale = np.tile([ms, ms * ls, ms * ls, ms * ls * ls], n)
        self.idx = [names.index(nm) for nm in opt.links]
        t0 = maps.theta_original.reshape(-1, 4)
        m0 = t0[self.idx, 0]
        l0 = np.sqrt(t0[self.idx, 3] / m0)
        # variables y per listed link, in units of the link: dm = m0 y_m, dh = m0 l0 y_h, ...
        self.m0, self.l0 = m0, l0
        self.cols = np.concatenate([np.arange(4 * i, 4 * i + 4) for i in self.idx])
        self.r_max = np.array([opt.max_radius_factor * joint_reach_m(self.scene, nm) / ls
                               for nm in opt.links])
        self.k_max = np.array([opt.max_gyration_factor * joint_reach_m(self.scene, nm) / ls
                               for nm in opt.links])
        self.dsc = np.column_stack([m0, m0 * l0, m0 * l0, m0 * l0 * l0]).ravel()
        self.m_max = np.array([opt.max_mass_factor * self.scene.link(nm).own_mass_kg / ms
                               for nm in opt.links])
        # the rim bound rho (normalized), None without max_rim_radius_factor
        self.rho = None if opt.max_rim_radius_factor is None else np.array(
            [opt.max_rim_radius_factor * joint_reach_m(self.scene, nm) / ls for nm in opt.links])
        self.plane = dict(opt.planes)
        # c = 2 pi rho t_max (kg/m^2), normalized: kg/m^2 * ls^2 / ms
        self.c_disc = 2.0 * math.pi * opt.density_kg_m3 * opt.max_thickness_m * ls * ls / ms
        w1, w2 = opt.weights
        self.weights4 = np.array([w1, w2, opt.torque_weight, opt.reaction_weight])
        theta0 = maps.theta_original
        mats = [maps.force, maps.moment]
        self.term_of = [0, 1]
        if opt.torque_weight:
            mats.append(maps.torque)
            self.term_of.append(2)
        if opt.reaction_weight:
            for r in maps.reactions.values():
                mats.append(r)
                self.term_of.append(3)
        self.norms = [(mat[:, self.cols] * self.dsc, mat @ theta0) for mat in mats]
        # a link whose inertia enters no term (a crank at constant speed: alpha = 0) gets
        # the thickest disc, t = t_max: the objective and the added mass do not decide it
        col = [max(np.linalg.norm(g[:, 4 * i + 3]) / max(np.linalg.norm(g), 1e-300)
                   for g, _ in self.norms) for i in range(len(opt.links))]
        self.inertia_free = [v <= FREE_INERTIA_REL for v in col]
        self.nl = len(opt.links)
        self.ny = 4 * self.nl
        self.nx = self.ny + self.nl + len(self.norms)   # y | s (aux) | t (epigraphs)

    # ----------------------------------------------------------------- objective pieces

    def blame(self):
        """Return the scene values that make the program ill-posed (:mod:`.conditioning`)."""
        sc = self.scene
        return conditioning.blame(sc, None if sc.normalization is None else self.units,
                                  sc.crank_speed_rad_s)

    def weights_vector(self):
        q = np.zeros(self.nx)
        for k, term in enumerate(self.term_of):
            q[self.ny + self.nl + k] = self.weights4[term]
        return q

    def unit(self, k):
        q = np.zeros(self.nx)
        q[self.ny + self.nl + k] = 1.0
        return q

    def mass_vector(self):
        q = np.zeros(self.nx)
        q[0:self.ny:4] = self.m0
        return q

    def norm(self, k, y):
        g, c = self.norms[k]
        return float(np.linalg.norm(g @ y + c))

    def z(self, y):
        return float(sum(self.weights4[t] * self.norm(k, y) for k, t in enumerate(self.term_of)))

    def secondary(self):
        """Return the index of the tie-break norm (0 force, 1 moment) or None."""
        w1, w2, wt, wr = self.weights4
        if wt or wr or (w1 and w2):
            return None
        return 1 if w2 == 0.0 else 0

    # ----------------------------------------------------------------------- pins

    def _row_space(self, g):
        u, sv, vt = np.linalg.svd(g, full_matrices=False)
        if not sv.size or sv[0] == 0.0:
            return u[:, :0], sv[:0], vt[:0]
        r = int(np.sum(sv > linear_maps.RANK_REL_TOL * sv[0]))
        return u[:, :r], sv[:r], vt[:r]

    def pin(self, k, y, exact):
        """
        Return (rows, target): the optimal set of a single-norm stage, ``rows y = target``.

        ``exact``: the norm's map is zero (complete force balance): the minimum-norm
        solution's row-space part; else the image of the stage's optimum ``y``.
        """
        g, c = self.norms[k]
        u, sv, vt = self._row_space(g)
        if not sv.size:        # the term does not depend on the counterweights at all
            return vt, np.zeros(0)
        if exact:
            return vt, -(u.T @ c) / sv
        # rows weighted by their singular values: the solver's equality residual is then
        # measured in units of the norm (orthonormal rows let a 1e-9 residual along a large
        # singular direction move the optimum's norm by 1e-5 on the carpet scraper)
        rows = vt * (sv / sv[0])[:, None]
        return rows, rows @ y

    def merged(self, pins, y):
        """Return the pins as one orthonormal row set at the latest optimum ``y``."""
        if not pins:
            return []
        rows = np.vstack([p[0] for p in pins])
        _, sv, vt = self._row_space(rows)
        if not sv.size:
            return []
        rows = vt * (sv / sv[0])[:, None]
        return [(rows, rows @ y)]

    def project_force_balance(self, y):
        """Return ``y`` moved onto the exact force balance (orthogonal projection)."""
        rows, target = self.pin(0, y, True)
        return y - rows.T @ (rows @ y - target)

    # ----------------------------------------------------------------------- solve

    def run(self, q, pins, bound=None, caps=()):
        nx, ny, nl = self.nx, self.ny, self.nl
        a_blocks, b_blocks, cones = [], [], []

        def add(cone, a, b):
            a_blocks.append(np.atleast_2d(a))
            b_blocks.append(np.asarray(b, dtype=float).ravel())
            cones.append(cone(a_blocks[-1].shape[0]))

        # 0 <= dm <= max_mass_factor m_link (in link units: 0 <= y_m <= m_max / m0), and
        # dI <= k_max^2 dm (radius of gyration about the link origin <= k_max)
        a = np.zeros((3 * nl, nx))
        b = np.zeros(3 * nl)
        for i in range(nl):
            a[3 * i, 4 * i] = -1.0
            a[3 * i + 1, 4 * i] = 1.0
            b[3 * i + 1] = self.m_max[i] / self.m0[i]
            a[3 * i + 2, 4 * i] = -(self.k_max[i] / self.l0[i]) ** 2
            a[3 * i + 2, 4 * i + 3] = 1.0
        if bound is not None:
            a = np.vstack([a, self.weights_vector()])
            b = np.append(b, bound)
        for row, value in caps:
            a = np.vstack([a, row])
            b = np.append(b, value)
        add(clarabel.NonnegativeConeT, a, b)
        for rows, target in pins:
            if not rows.shape[0]:
                continue
            a = np.zeros((rows.shape[0], nx))
            a[:, :ny] = rows
            add(clarabel.ZeroConeT, a, target)
        dynamic = len(a_blocks)
        if self._static is None:
            self._add_cones(add)
            self._static = (sp.csc_matrix(np.vstack(a_blocks[dynamic:])),
                            np.concatenate(b_blocks[dynamic:]),
                            [blk.shape[0] for blk in a_blocks[dynamic:]])
        a_static, b_static, sizes = self._static
        a_all = sp.vstack([sp.csc_matrix(np.vstack(a_blocks[:dynamic])), a_static],
                          format='csc')
        b_all = np.concatenate(b_blocks[:dynamic] + [b_static])
        cones = cones[:dynamic] + [clarabel.SecondOrderConeT(k) for k in sizes]
        run = conic.run_solver(q, a_all, b_all, cones)
        status = run.status
        if not np.all(np.isfinite(np.asarray(run.sol.x))):
            raise CounterweightError(f'solver: {run.why()} (counterweight problem); no '
                                     f'design{self.blame()}')
        x = np.array(run.sol.x)
        return _Stage(y=x[:ny], objective=float(q @ x), dual=float(run.sol.obj_val_dual),
                      status=status, iterations=int(run.sol.iterations),
                      r_prim=float(run.sol.r_prim), r_dual=float(run.sol.r_dual),
                      seconds=run.seconds, solve=run)

    def box(self, level=None, q=None):
        """
        Return (lo, hi): bounds on every variable that the constraints imply (link units).

        ``0 <= y_m <= m_max/m0``, ``|y_h| <= (r_max/l0) y_m``, ``0 <= y_s <= y_I <=
        (k_max/l0)^2 y_m`` (and, with the rim bound, ``y_I <= b y_m`` and ``|y_h| <= (b/a)
        y_m`` from each cut ``y_I + a |y_h| <= b y_m``); an epigraph t at most its norm's
        bound over that box, and at most ``level / w`` when the stage's weighted objective
        is at most ``level``.  When
        a link's inertia enters none of the norms that the objective ``q`` weights (exactly
        zero columns: the RMS force alone), an optimal point with the least inertia the
        disc allows exists, ``y_I = |y_h|^2/y_m + kappa y_m^2``, which bounds y_I instead.
        """
        nx, ny, nl = self.nx, self.ny, self.nl
        lo, hi = np.zeros(nx), np.zeros(nx)
        used = None if q is None else \
            [k for k in range(len(self.norms)) if q[ny + nl + k] != 0.0]
        for i in range(nl):
            m_hi = self.m_max[i] / self.m0[i]
            h_hi = self.r_max[i] / self.l0[i] * m_hi
            i_hi = (self.k_max[i] / self.l0[i]) ** 2 * m_hi
            # the rim cuts y_I + a |y_h| <= b y_m (a >= 0, y_I >= 0) bound both
            margin = 1.0 + 8.0 * certificate.UNIT_ROUNDOFF
            for a, b in self._rim_cuts(i):
                i_hi = min(i_hi, b * m_hi * margin)
                if a > 0.0:
                    h_hi = min(h_hi, b / a * m_hi * margin)
            if used is not None and all(not np.any(self.norms[k][0][:, 4 * i + 3])
                                        for k in used):
                kappa = self.m0[i] / (self.c_disc * self.l0[i] ** 2)
                i_hi = min(i_hi, ((self.r_max[i] / self.l0[i]) ** 2 * m_hi
                                  + kappa * m_hi * m_hi) * (1.0 + 8.0 * certificate.UNIT_ROUNDOFF))
            lo[4 * i:4 * i + 4] = (0.0, -h_hi, -h_hi, 0.0)
            hi[4 * i:4 * i + 4] = (m_hi, h_hi, h_hi, i_hi)
            hi[ny + i] = i_hi
        weights = self.weights_vector()
        for k, (g, c) in enumerate(self.norms):
            it = ny + nl + k
            cap = certificate.norm_bound(g, c, lo[:ny], hi[:ny])
            if level is not None and weights[it] > 0.0:
                cap = min(cap, level / weights[it] * (1.0 + 4.0 * certificate.UNIT_ROUNDOFF))
            hi[it] = cap
        return lo, hi

    def lower_bound(self, stage, level):
        """Return the safe lower bound (:mod:`.certificate`) of a solved stage."""
        run = stage.solve
        lo, hi = self.box(level, run.q if level is not None else None)
        return certificate.safe_lower_bound(run.q, run.a, run.b, run.cones, run.sol.z, lo, hi)

    def _rim_cuts(self, i):
        """Return the rim cuts of listed link i in link units, ``y_I + a |y_h| <= b y_m``."""
        if self.rho is None:
            return []
        l0 = self.l0[i]
        return [(c_h / l0, c_m / (l0 * l0)) for c_h, c_m in clearance_mod.rim_cuts(self.rho[i])]

    def anchor(self):
        """
        Return a strictly feasible point of the disc constraints (centred small discs).

        Centred (y_h = 0), a disc's y_I lies between ``kappa y_m^2`` (the thickest disc) and
        ``g2 y_m``, g2 the least of the gyration bound and the rim cuts' ``b`` (the rim bound
        leaves a centred disc a radius of gyration up to rho / sqrt(3)).
        """
        y = np.zeros(self.ny)
        for i in range(self.nl):
            g2 = min([(self.k_max[i] / self.l0[i]) ** 2] + [b for _, b in self._rim_cuts(i)])
            kappa = self.m0[i] / (self.c_disc * self.l0[i] ** 2)
            a = min(0.5 * self.m_max[i] / self.m0[i], 0.5 * g2 / kappa)
            y[4 * i] = a
            y[4 * i + 3] = 0.5 * (kappa * a * a + g2 * a)
        return y

    def repair(self, y):
        """
        Return ``y`` with each disc moved onto its constraints by the least local change.

        The mass is capped at m_max, the first moment shrunk to the radius bound and to what
        the gyration bound and the rim cuts leave, and the inertia clipped into
        [|dh|^2/dm + dm^2/c, min(k_max^2 dm, c_m dm - c_h |dh|)] (the violations an
        interior-point solution has at active constraints; with a small rim bound the
        solver's absolute accuracy moves a light disc's centre by more than the rim), each
        with a margin of a few ulp.
        """
        y = np.array(y, dtype=float)
        shrink = 1.0 - 16.0 * certificate.UNIT_ROUNDOFF
        for i in range(self.nl):
            im = 4 * i
            ym = min(y[im], self.m_max[i] / self.m0[i] * shrink)
            if ym <= 0.0:
                continue
            y[im] = ym
            h = math.hypot(y[im + 1], y[im + 2])
            h_max = self.r_max[i] / self.l0[i] * ym * shrink
            if h > h_max:
                y[im + 1:im + 3] *= h_max / h
                h = math.hypot(y[im + 1], y[im + 2])
            kappa = self.m0[i] / (self.c_disc * self.l0[i] ** 2)
            g2 = (self.k_max[i] / self.l0[i]) ** 2
            room = ym * ym * (g2 - kappa * ym)   # the largest |h|^2 the gyration bound leaves
            if room > 0.0 and h * h > room * shrink:
                y[im + 1:im + 3] *= math.sqrt(room * shrink) / h * shrink
                h = math.hypot(y[im + 1], y[im + 2])
            cuts = self._rim_cuts(i)
            for a, b in cuts:   # the rim: h^2/ym + a h + kappa ym^2 - b ym <= 0 leaves h <= root
                c0 = kappa * ym * ym - b * ym
                disc = a * a - 4.0 * c0 / ym
                root = 0.5 * ym * (math.sqrt(disc) - a) if disc >= 0.0 else -1.0
                if 0.0 <= root < h:
                    y[im + 1:im + 3] *= root * shrink / h
                    h = math.hypot(y[im + 1], y[im + 2])
            i_lo = (h * h / ym + kappa * ym * ym) / shrink
            i_hi = min([g2 * ym] + [b * ym - a * h for a, b in cuts]) * shrink
            if i_lo <= i_hi:
                y[im + 3] = min(max(y[im + 3], i_lo), i_hi)
        return y

    def feasible(self, y, worst):
        """
        Return (y, pull): ``y`` repaired (:meth:`repair`), else moved towards :meth:`anchor`.

        The constraints are convex and the anchor inside them, so a convex combination
        with a large enough fraction ``pull`` is feasible; ``pull`` 0 when ``y`` already is.
        """
        if worst <= 0.0:
            return y, 0.0
        y = self.repair(y)
        if self.discs(y)[2] <= 0.0:
            return y, 0.0
        anchor = self.anchor()
        for lam in redistribution.PULL_STEPS[1:]:
            cand = (1.0 - lam) * y + lam * anchor
            if self.discs(cand)[2] <= 0.0:
                return cand, lam
        return anchor, 1.0

    def _add_cones(self, add):
        """Add the cones every stage shares: the discs' and the objective terms' epigraphs."""
        nx, ny, nl = self.nx, self.ny, self.nl
        for i in range(nl):
            im, ix, iy, ii, i_s = 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3, ny + i
            # |dh| <= r_max dm  ->  |y_h| <= (r_max / l0) y_m
            a = np.zeros((3, nx))
            a[0, im] = -self.r_max[i] / self.l0[i]
            a[1, ix] = a[2, iy] = -1.0
            add(clarabel.SecondOrderConeT, a, np.zeros(3))
            # |dh|^2 <= dm (dI - s): ||(2 y_h, y_m - y_I + y_s)|| <= y_m + y_I - y_s
            a = np.zeros((4, nx))
            a[0, [im, ii, i_s]] = (-1.0, -1.0, 1.0)
            a[1, ix] = a[2, iy] = -2.0
            a[3, [im, ii, i_s]] = (-1.0, 1.0, -1.0)
            add(clarabel.SecondOrderConeT, a, np.zeros(4))
            # s >= dm^2 / c  ->  y_m^2 <= y_s / kappa, kappa = m0 / (c l0^2):
            # ||(2 y_m, y_s - 1/kappa)|| <= y_s + 1/kappa
            inv_kappa = self.c_disc * self.l0[i] ** 2 / self.m0[i]
            a = np.zeros((3, nx))
            a[0, i_s] = a[2, i_s] = -1.0
            a[1, im] = -2.0
            add(clarabel.SecondOrderConeT, a, [inv_kappa, 0.0, -inv_kappa])
            if self.rho is not None:   # the disc inside rho: dI + c_h |dh| <= c_m dm
                l0 = self.l0[i]
                for c_h, c_m in clearance_mod.rim_cuts(self.rho[i]):
                    a = np.zeros((3, nx))
                    a[0, [im, ii]] = (-c_m / (l0 * l0), 1.0)
                    a[1, ix] = a[2, iy] = -c_h / l0
                    add(clarabel.SecondOrderConeT, a, np.zeros(3))
        for k, (g, c) in enumerate(self.norms):
            a = np.zeros((1 + g.shape[0], nx))
            a[0, ny + nl + k] = -1.0
            a[1:, :ny] = -g
            add(clarabel.SecondOrderConeT, a, np.concatenate([[0.0], c]))

    # ----------------------------------------------------------------------- discs

    def discs(self, y):
        """
        Return (designs, omitted links, worst constraint violation) of ``y``.

        Violations are in units of the link: mass by its own mass, first moment by own mass x
        reach, inertia by own mass x reach^2.
        """
        u, opt = self.units, self.opt
        ms, ls = u.mass_kg, u.length_m
        d = (y * self.dsc).reshape(-1, 4)
        designs, omitted, worst = [], [], 0.0
        rho = opt.density_kg_m3
        for i, name in enumerate(opt.links):
            own = self.scene.link(name).own_mass_kg
            dm = d[i, 0] * ms
            dh = complex(d[i, 1], d[i, 2]) * ms * ls
            d_i = d[i, 3] * ms * ls * ls
            r_max = self.r_max[i] * ls
            if dm <= MIN_MASS_REL * own:   # built as no disc: feasible
                omitted.append(name)
                continue
            r = dh / dm
            i_min = dm * dm / (2.0 * math.pi * rho * opt.max_thickness_m)
            i_c = d_i - abs(dh) ** 2 / dm
            k_max = self.k_max[i] * ls
            i_c = i_min if self.inertia_free[i] else max(i_c, i_min)   # t <= t_max
            # violations of the disc as built, in units of the link (own mass, reach)
            i_ref = own * r_max ** 2
            worst = max(worst, (abs(r) - r_max) * dm / (own * r_max),
                        (i_c + dm * abs(r) ** 2 - k_max ** 2 * dm) / i_ref,
                        (dm - self.m_max[i] * ms) / own)
            radius = math.sqrt(2.0 * i_c / dm)
            if self.rho is not None:   # the rim bound, in units of the largest centre radius
                worst = max(worst, (abs(r) + radius - self.rho[i] * ls) / r_max)
            thickness = dm * dm / (2.0 * math.pi * rho * i_c)
            designs.append(CounterweightDesign(
                link=name, mass_kg=float(dm), centre_m=(float(r.real), float(r.imag)),
                centre_radius_m=float(abs(r)),
                centre_angle_deg=math.degrees(math.atan2(r.imag, r.real)) % 360.0,
                radius_m=float(radius), thickness_m=float(thickness), density_kg_m3=rho,
                inertia_com_kg_m2=float(0.5 * dm * radius ** 2),
                max_centre_radius_m=float(r_max), max_mass_kg=float(self.m_max[i] * ms),
                plane_m=float(self.plane.get(name, 0.0))))
        return designs, omitted, float(max(worst, 0.0))
