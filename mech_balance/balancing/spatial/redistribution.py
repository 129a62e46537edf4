"""Certified redistribution of a spatial rig into realizable bodies (docs/balancing.md)."""

import math
import time

from mech_balance.balancing.defaults import DEFAULT_WEIGHTS, EXTENT_FACTOR_RANGE, \
    PAPER_MASS_FACTORS, SPATIAL_MASS_FACTOR_RANGE
from mech_balance.balancing.spatial.model import check_samples, check_weights, checked_range, \
    design_columns, maps_of, parameter_model, program_units, SpatialBalanceError, units_of
from mech_balance.balancing.spatial.program import ConeProgram
from mech_balance.balancing.spatial.repair import RealizableChecks
from mech_balance.balancing.spatial.result import best_certified, check_run, finish
from mech_balance.conic import INFEASIBLE
import numpy as np

EXTENT_FACTOR = 1.5
"""Default extent bound: RMS distance of a body's mass from its origin <= this x its reach."""


def redistribute(rig, weights=DEFAULT_WEIGHTS, samples=None, *, mass_factors=PAPER_MASS_FACTORS,
                 mass_bounds=None, extent_factor=EXTENT_FACTOR, extent_bounds=None,
                 fixed=(), force_balanced=False):
    """Return the certified optimal redistribution (:class:`SpatialResult`) of a spatial rig."""
    t_start = time.perf_counter()
    w = check_weights(weights)
    model = parameter_model(rig)
    samples = check_samples(samples, rig)
    nb = len(model.bodies)
    fixed_idx = {model.index(n, 'fixed') for n in (fixed or ())}
    free_idx = [k for k in range(nb) if k not in fixed_idx]
    if not free_idx:
        raise SpatialBalanceError('fixed: got every body, expected at least one free body')
    units = units_of(rig, model)
    maps = maps_of(rig, samples)
    mlo, mhi = _mass_bounds(model, free_idx, mass_bounds, mass_factors)
    extent = _extent_bounds(model, free_idx, extent_bounds, extent_factor)
    prog = _redistribution_program(model, maps, units, free_idx, w, mlo, mhi, extent,
                                   force_balanced)
    note = None
    run = prog.solve() if prog.balanceable is not False else None
    if force_balanced and (run is None or run.status in INFEASIBLE):
        note = ('complete force balance is not attainable with realizable bodies within the '
                'bounds; minimized the RMS shaking force instead')
        w = (1.0, 0.0)
        prog = _redistribution_program(model, maps, units, free_idx, w, mlo, mhi, extent,
                                       False)
        run = prog.solve()
    check_run(run, rig, units)
    checks = RealizableChecks(model, free_idx, mlo, mhi, extent)
    options = {'mass_bounds_kg': {model.bodies[k].name: [mlo[k], mhi[k]] for k in free_idx},
               'extent_bounds_m': {model.bodies[k].name: extent[k] for k in free_idx},
               'fixed': sorted(model.bodies[k].name for k in fixed_idx),
               'force_balanced': bool(force_balanced), 'note': note}

    def design(run):
        theta = prog.theta(run.sol.x)
        if prog.balanceable:
            theta = prog.project_null(theta)
        violation = checks.violation(theta)
        theta, pull = checks.repair(
            theta, keep_force=bool(prog.balanceable),
            objective=lambda t: w[0] * np.linalg.norm(maps.force @ t) / units.force_N
            + w[1] * np.linalg.norm(maps.moment @ t) / units.moment_Nm)
        options['violation_after_pull'] = checks.violation(theta)
        return finish(rig, model, units, maps, prog, run, theta, model.build(theta), w,
                      samples, violation, pull, t_start,
                      'redistribution (PSD pseudo-inertia, SOCP+SDP)', dict(options))
    return best_certified(prog, run, design)


def _redistribution_program(model, maps, units, free_idx, w, mlo, mhi, extent, force_balanced):
    """Return the :class:`ConeProgram` of a redistribution (variables per body: its basis)."""
    basis, orders, where = design_columns(model, free_idx)
    units_k = {k: program_units(model, k, mlo[k], mhi[k], extent[k]) for k in free_idx}
    body_scale = np.concatenate([[units_k[k][0] * units_k[k][1] ** o
                                  for o in model.bodies[k].orders] for k in sorted(free_idx)])
    offset = model.theta.copy()
    for k in free_idx:
        offset[10 * k:10 * k + 10] = 0.0
    prog = ConeProgram(basis * body_scale, offset, units)
    prog.epigraphs(maps, w)
    for k in sorted(free_idx):
        body = model.bodies[k]
        cols = where[k]
        b_k = body.basis * body_scale[cols]
        m_k, r_k = units_k[k]
        prog.mass_rows(cols, b_k, mlo[k], mhi[k], m_k)
        prog.psd(cols, b_k, m_k, r_k)
        prog.extent(cols, b_k, extent[k], m_k, r_k)
        # the box of every feasible point: lo <= m <= hi, |h_i| <= m r, |I_ij| <= m r^2 (on a
        # line from the point a: s <= |p| + |a|, so int s^2 dm <= m (r + |a|)^2 and
        # |int s dm| <= m (r + |a|), Cauchy-Schwarz with int |p|^2 dm <= m r^2)
        reach = extent[k] + body.line_offset_m
        for j, order in zip(range(cols.start, cols.stop), body.orders):
            size = mhi[k] * reach ** order / body_scale[j] * (1.0 + 1e-12)
            prog.box_lo[j] = mlo[k] / body_scale[j] * (1.0 - 1e-12) if order == 0 else -size
            prog.box_hi[j] = size
    prog.balanceable = prog.force_null(maps) if force_balanced else None
    return prog


def _mass_bounds(model, free_idx, given, factors):
    """Return ({k: lo_kg}, {k: hi_kg}) of the free bodies (``mass_bounds``, ``mass_factors``)."""
    lo_f, hi_f = (float(x) for x in factors)
    if not (0.0 < lo_f <= hi_f and math.isfinite(hi_f)):
        raise SpatialBalanceError(f'mass_factors: got {factors!r}, expected 0 < lo <= hi, '
                                  'finite')
    for value in (lo_f, hi_f):
        checked_range('mass_factors', value, *SPATIAL_MASS_FACTOR_RANGE)
    given = dict(given or {})
    mlo, mhi = {}, {}
    for k in free_idx:
        name = model.bodies[k].name
        m0 = float(model.theta[10 * k])
        if m0 <= 0.0:
            raise SpatialBalanceError(
                f'links.{name}.mass_kg: got {m0:g}, a massless link, which the redistribution '
                'cannot scale (its mass bounds are mass_factors x the original mass), expected '
                f'a mass > 0 kg for it or the link fixed (--fix {name}, or '
                f'balance.fixed_links: [{name}])')
        lo, hi = given.pop(name, (lo_f * m0, hi_f * m0))
        lo, hi = float(lo), float(hi)
        if not (0.0 < lo <= hi and math.isfinite(hi)):
            raise SpatialBalanceError(f'mass_bounds.{name}: got ({lo:g}, {hi:g}), expected '
                                      '0 < lo <= hi, finite (kg)')
        low, high = SPATIAL_MASS_FACTOR_RANGE
        for value in (lo, hi):
            if not low * m0 * (1 - 1e-12) <= value <= high * m0 * (1 + 1e-12):
                raise SpatialBalanceError(
                    f'mass_bounds.{name}: got {value:g} kg, expected a mass in [{low:g}, '
                    f'{high:g}] x its original {m0:g} kg (defaults.SPATIAL_MASS_FACTOR_RANGE:'
                    ' the range in which the program certifies)')
        mlo[k], mhi[k] = lo, hi
    if given:
        raise SpatialBalanceError(f'mass_bounds: got {sorted(given)[0]!r}, expected a free '
                                  'body')
    return mlo, mhi


def _extent_bounds(model, free_idx, given, factor):
    """Return {k: radius_m} of the free bodies (``extent_bounds`` over ``extent_factor``)."""
    factor = checked_range('extent_factor', factor, *EXTENT_FACTOR_RANGE)
    given = dict(given or {})
    out = {}
    low, high = EXTENT_FACTOR_RANGE
    for k in free_idx:
        name = model.bodies[k].name
        reach = model.bodies[k].reach_m
        r = float(given.pop(name, factor * reach))
        if not (math.isfinite(r) and r > 0.0):
            raise SpatialBalanceError(f'extent_bounds.{name}: got {r!r}, expected a finite '
                                      'radius > 0 (m)')
        if not low * reach * (1 - 1e-12) <= r <= high * reach * (1 + 1e-12):
            raise SpatialBalanceError(
                f'extent_bounds.{name}: got {r:g} m, expected a radius in [{low:g}, {high:g}] '
                f'x its reach {reach:g} m (defaults.EXTENT_FACTOR_RANGE: the range in which '
                'the program certifies)')
        out[k] = r
    if given:
        raise SpatialBalanceError(f'extent_bounds: got {sorted(given)[0]!r}, expected a free '
                                  'body')
    return out


__all__ = ['EXTENT_FACTOR', 'redistribute']
