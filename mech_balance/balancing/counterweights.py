"""
Add-only counterweight balancing: one solid disc per listed link, to a certified optimum.

Disc bounds: t <= t_max, |r| <= r_max, dm <= max_mass_factor x the link's mass; the program:
:mod:`.counterweight_program`, docs/balancing.md, "Counterweights (add-only discs)".
"""

from dataclasses import dataclass
import time

from mech_balance import schema
from mech_balance.analysis import clearance as clearance_mod
from mech_balance.balancing import certificate, clearance_design, redistribution, tables
from mech_balance.balancing.counterweight_options import (
    check_options, CounterweightError, CounterweightOptions, joint_reach_m)
from mech_balance.balancing.counterweight_program import CounterweightDesign, Problem
from mech_balance.balancing.defaults import (
    DEFAULT_DENSITY_KG_M3, DEFAULT_MAX_GYRATION_FACTOR, DEFAULT_MAX_MASS_FACTOR,
    DEFAULT_MAX_RADIUS_FACTOR, DEFAULT_MAX_THICKNESS_M, DEFAULT_WEIGHTS)
from mech_balance.core.planar import dynamics, rig as planar_rig
import numpy as np

__all__ = ['balance_with_counterweights', 'cost_of_balancing', 'CounterweightDesign',
           'CounterweightError', 'CounterweightOptions', 'CounterweightResult',
           'DEFAULT_MAX_GYRATION_FACTOR', 'DEFAULT_MAX_THICKNESS_M', 'format_cost',
           'joint_reach_m', 'METHOD', 'Problem', 'solve']
TIE_BREAK_SLACK = 1e-9
"""A tie-break stage after a weighted sum of norms keeps z within this fraction of max(z*, 1)."""
MASS_STAGE_SLACKS = (TIE_BREAK_SLACK, TIE_BREAK_SLACK, 1e-7)
"""The least-mass stage's slacks on the earlier objectives (x max(z, 1)), tried in turn."""
METHOD = 'counterweights (add-only discs, SOCP)'


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
    """Return the optimal add-only discs on ``links`` ('a,b' or names): a CounterweightResult."""
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
    maps, maps_s = redistribution.objective_maps(scene, opt.samples, units, opt.torque_weight,
                                                 opt.reaction_weight)
    prob = Problem(scene, maps, opt, units)
    blame = prob.blame()
    stage1 = prob.run(prob.weights_vector(), [])
    failed = []
    if not stage1.run.ok:
        failed.append(certificate.failed_stage(
            'primary (z)', stage1.run, "the solver's last iterate, made "
            'feasible; its lower bound is safe', blame))
    y, stage2, stage3, exact = stage1.point, None, None, False
    secondary = prob.secondary()
    pins = []
    if opt.tie_break and secondary is not None and stage1.run.ok:
        name2 = f"tie-break (least RMS shaking {('force', 'moment')[secondary]})"
        primary = 0 if secondary == 1 else 1
        exact = (secondary == 1 and
                 prob.norm(0, y) <= redistribution.FORCE_BALANCE_REL_TOL * maps.force_rms_original)
        pins = [prob.pin(primary, y, exact)]
        stage2 = prob.run(prob.unit(secondary), pins)
        tried = list(stage2.run.attempts)
        if not stage2.run.ok and not exact:
            # the optimal image pinned exactly can be infeasible to round-off: cap it instead
            z_p = prob.norm(primary, y)
            for slack in MASS_STAGE_SLACKS[1:]:
                cap = [(prob.unit(primary), z_p + slack * max(z_p, certificate.GAP_FLOOR))]
                stage2 = prob.run(prob.unit(secondary), [], None, cap)
                tried.extend(stage2.run.attempts)
                if stage2.run.ok:
                    pins = []
                    break
        stage2.run.attempts = tuple(tried)
        if not stage2.run.ok:
            failed.append(certificate.failed_stage(name2, stage2.run,
                                                   "the primary stage's optimum", blame))
            stage2, exact, pins = None, False, []
        else:
            y = stage2.point
            if pins:
                pins = pins + [prob.pin(secondary, y, False)]
    if opt.tie_break and stage1.run.ok:
        # the mass stage keeps every earlier objective optimal: pinned exactly, else capped
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
            tried.extend(stage3.run.attempts)
            if stage3.run.ok:
                break
        stage3.run.attempts = tuple(tried)
        if not stage3.run.ok:
            failed.append(certificate.failed_stage(
                'least added mass', stage3.run, "the previous stage's optimum (its "
                'added mass is not the least)', blame))
            stage3 = None
        else:
            y = stage3.point
    if exact:
        y = prob.project_force_balance(y)
    designs, omitted, worst = prob.discs(y)
    y, pull = prob.feasible(y, worst)
    designs, omitted, final_violation = prob.discs(y)
    balanced = clearance_design.with_discs(scene, designs, f'{scene.name}_counterweights')
    terms = maps.terms(dynamics.parameter_vector(
        dynamics.Inertia.from_links(balanced.links)) / prob.scale)
    w = prob.weights4
    primal = float(np.dot(w, terms))
    s2 = None
    if stage2 is not None:
        # its own safe bound, never above the solver's objective
        s2 = redistribution.tie_break_report(
            stage2, f"RMS shaking {('force', 'moment')[secondary]}",
            min(prob.lower_bound(stage2, None).value, stage2.objective), exact)
    cert = certificate.certify(stage1, primal, prob.lower_bound(stage1, primal), worst, pull,
                               failed, final_violation, s2, null_directions_assumed=0)
    least = None
    if stage3 is not None:
        mass = sum(d.mass_kg for d in designs) / units.mass_kg
        lb3 = min(prob.lower_bound(stage3, None).value, mass)
        least = {'minimized': 'total added mass', 'status': stage3.status,
                 'objective_kg': mass * units.mass_kg, 'lower_bound_kg': lb3 * units.mass_kg,
                 'dual_kg': lb3 * units.mass_kg, 'iterations': stage3.iterations,
                 'attempts': list(stage3.run.attempts)}
    report = None
    if opt.clearance_margin_m is not None:   # the convex optimum made collision-free
        designs, report = clearance_design.design(
            scene, prob, designs, cert.lower_bound, opt.clearance_margin_m, opt.disc_side,
            opt.max_overhang_m, fixed_planes=bool(opt.planes))
        balanced = clearance_design.with_discs(scene, designs, f'{scene.name}_counterweights')
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


def cost_of_balancing(original, balanced, table):
    """Return ``{quantity: {before, after, change_percent}}`` (SI) of a before/after ``table``."""
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
