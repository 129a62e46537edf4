"""The result of a spatial redistribution or counterweights: evaluated, certified, tabled."""

from dataclasses import dataclass
import math
import time

import clarabel
from mech_balance import schema
from mech_balance.balancing import certificate
from mech_balance.balancing.certificate import Certificate, CERTIFIED_GAP_REL, GAP_FLOOR
from mech_balance.balancing.conditioning import blame
from mech_balance.balancing.spatial.model import cycle_of, SpatialBalanceError, Units
from mech_balance.balancing.spatial.program import TIGHT_TOL_SCALE
from mech_balance.conic import INFEASIBLE
from mech_balance.conventions import rms
from mech_balance.core import regressor
from mech_balance.core.rig import rig_for
from mech_balance.schema.scene import SERIES
import numpy as np


@dataclass
class SpatialResult:
    """A spatial design, its certificate and its before/after table (the planar shape)."""

    scene: object
    balanced_scene: object
    method: str
    weights: tuple
    samples: int
    units: Units
    objective: dict
    certificate: object     # certificate.Certificate
    table: list
    bodies: list
    options: dict
    solve_time_s: float
    theta: np.ndarray = None

    def summary(self):
        """Return the provenance stored with the balanced scene (``balance`` key)."""
        return schema.plain({
            'source_scene': self.scene.name, 'method': self.method,
            'weights': list(self.weights), 'objective': self.objective,
            'lower_bound': self.certificate.lower_bound,
            'relative_gap': self.certificate.gap_rel,
            'certified': self.certificate.certified})

    def to_dict(self):
        """Return everything as a plain, JSON-able dict (SI and normalized)."""
        u = self.units
        return schema.plain({
            'scene': self.scene.name, 'method': self.method, 'samples': self.samples,
            'weights': list(self.weights),
            'units': {'mass_kg': u.mass_kg, 'length_m': u.length_m,
                      'omega_rad_s': u.omega_rad_s, 'normalized_from': u.source},
            'bodies': self.bodies, 'objective': self.objective, 'options': self.options,
            'certificate': self.certificate.to_dict(), 'table': self.table,
            'solve_time_s': self.solve_time_s})


def finish(rig, model, units, maps, prog, run, theta, balanced, w, samples, violation, pull,
           t_start, method, options):
    """Evaluate the written design with the core, certify it, and return the result."""
    rig2 = rig.with_scene(balanced) if hasattr(rig, 'with_scene') else rig_for(balanced)
    data = rig2.at(maps.angles)
    f, n = normalized_rms(data, units)
    primal = w[0] * f + w[1] * n
    model_value = w[0] * np.linalg.norm(maps.force @ theta) / units.force_N + \
        w[1] * np.linalg.norm(maps.moment @ theta) / units.moment_Nm
    lo, hi = prog.box(primal)
    lower, bound, fold_err = certificate.folded_lower_bound(run, lo, hi)
    lower = min(lower, primal)
    gap, gap_rel = certificate.relative_gap(primal, lower, GAP_FLOOR)
    cert = Certificate(
        solver=f'clarabel {clarabel.__version__}', status=run.status, primal=primal,
        dual=lower, gap_abs=gap, gap_rel=gap_rel, residual_primal=float(run.sol.r_prim),
        residual_dual=float(run.sol.r_dual), iterations=int(run.sol.iterations),
        max_violation=float(violation), lower_bound=lower, attempts=list(run.attempts),
        bound_detail={'dual_objective': bound.dual_objective,
                      'residual_term': bound.residual_term,
                      'rounding': bound.rounding + fold_err,
                      'dual_residual': bound.dual_residual,
                      'projection_shift': bound.projection_shift,
                      'solver_objective': float(run.sol.obj_val),
                      'model_primal': float(model_value)},
        feasibility_pull=float(pull), failed_stages=[],
        certified=bool(math.isfinite(lower) and gap_rel <= CERTIFIED_GAP_REL))
    base = rig.at(maps.angles)
    f0, n0 = normalized_rms(base, units)
    objective = {'z': primal, 'shaking_force_rms': f, 'shaking_moment_rms': n,
                 'z_original': w[0] * f0 + w[1] * n0}
    return SpatialResult(
        scene=rig.scene, balanced_scene=balanced, method=method, weights=tuple(w),
        samples=samples, units=units, objective=objective, certificate=cert,
        table=before_after(rig, balanced, samples, units, (base, data)),
        bodies=body_rows(model, theta), options=options,
        solve_time_s=time.perf_counter() - t_start, theta=theta)


def normalized_rms(data, units):
    """Return the RMS shaking force and moment of the core's ``data`` in the objective's units."""
    return float(rms(data.force_N)) / units.force_N, float(rms(data.moment_Nm)) / units.moment_Nm


def body_rows(model, theta):
    """Return each body of a design as a row: mass, mass centre, inertia, least eigenvalue of J."""
    out = []
    for k, body in enumerate(model.bodies):
        t = theta[10 * k:10 * k + 10]
        m = float(t[0])
        c = t[1:4] / m if m > 0.0 else np.zeros(3)
        i_o = regressor.inertia_matrix(t[4:10])
        i_c = i_o - m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
        out.append({'name': body.name, 'mass_kg': m, 'mass_centre_m': c.tolist(),
                    'inertia_centre_kg_m2': i_c.tolist(),
                    'pseudo_inertia_min_eigenvalue':
                        float(np.linalg.eigvalsh(regressor.pseudo_inertia(t))[0])})
    return out


def before_after(rig, balanced, samples, units, data=None):
    """Return the before/after rows of RMS shaking force, moment and driving effort."""
    if data is None:
        psi = cycle_of(rig, samples)
        rig2 = rig.with_scene(balanced)
        data = (rig.at(psi), rig2.at(psi))
    normalized = units.source == 'scene'
    rows = []
    # the driving effort under the rig's own series: a torque, or a prismatic input's force
    effort = rig.driving_series
    label, dim = SERIES[effort]
    for name, get, force in (
            ('shaking force', lambda d: d.force_N, True),
            ('shaking moment', lambda d: d.moment_Nm, False),
            (label, lambda d: d.series.get(effort), dim == 'force')):
        values = [get(d) for d in data]
        if any(v is None for v in values):
            continue
        before_si, after_si = (float(rms(v)) for v in values)
        unit_si = 'N' if force else 'N m'
        scale = (units.force_N if force else units.moment_Nm) if normalized else 1.0
        rows.append({'quantity': name,
                     'unit': ('m l omega^2' if force else 'm l^2 omega^2')
                     if normalized else unit_si,
                     'before': before_si / scale, 'after': after_si / scale,
                     'change_percent': (after_si - before_si) / before_si * 100.0
                     if before_si > 0.0 else None,
                     'unit_si': unit_si, 'before_si': before_si, 'after_si': after_si})
    return rows


def best_certified(prog, run, design):
    """Return design(run), or that of a tighter solve when the first is not certified."""
    result = design(run)
    if result.certificate.certified:
        return result
    tight = prog.solve(TIGHT_TOL_SCALE)
    if not tight.ok:
        return result
    other = design(tight)
    if other.certificate.certified or other.certificate.gap_abs < result.certificate.gap_abs:
        return other
    return result


def check_run(run, rig, units):
    """Raise a :class:`SpatialBalanceError` for an infeasible or failed solve (naming why)."""
    if run.status in INFEASIBLE:
        raise SpatialBalanceError(
            f'constraints: the balancing problem is infeasible (solver status {run.status}); '
            'widen mass_bounds / extent_bounds')
    if not run.ok:   # with the scene values that make the program ill-posed
        speed = abs(float(rig.at([0.0], outputs=('kinematics',)).crank_speed_rad_s[0]))
        raise SpatialBalanceError(f'solver: {run.why()}'
                                  + blame(rig.scene, units if units.source == 'scene' else None,
                                          speed))


def write_scene(result, path):
    """Write the balanced scene and its provenance to ``path`` atomically; return it reloaded."""
    from mech_balance import atomic
    import yaml
    provenance = result.summary()
    text = schema.to_yaml(result.balanced_scene, provenance)
    try:
        schema.from_dict(yaml.safe_load(text), source=str(path))
    except ValueError:
        comment = yaml.safe_dump(provenance, sort_keys=False, width=95)
        text = ''.join(f'# {line}\n' for line in comment.splitlines()) + \
            schema.to_yaml(result.balanced_scene)
        # the design itself must load: checked before anything is written
        schema.from_dict(yaml.safe_load(text), source=str(path))
    atomic.write_text_atomic(path, f'# written by mech-balance balance from scene '
                                   f'{result.scene.name}\n' + text)
    return schema.load(str(path))


__all__ = ['before_after', 'best_certified', 'check_run', 'finish', 'SpatialResult', 'write_scene']
