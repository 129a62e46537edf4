"""Complete force balance of a spatial rig: the null space of its force map."""

from dataclasses import dataclass, field

from mech_balance import schema
from mech_balance.balancing.spatial.model import body_scales, check_samples, design_columns, \
    free_bodies, maps_of, parameter_model, PSD_ROUNDOFF, RANK_REL_TOL, units_of
from mech_balance.balancing.spatial.result import before_after
from mech_balance.core import regressor
import numpy as np

FORCE_BALANCED_REL = 1e-9
"""A design whose RMS shaking force is at most this fraction of the original's is balanced."""
CONDITION_COEFF_REL = 1e-12
"""Coefficients of a condition below this fraction of its largest are left out of its text."""


@dataclass
class ForceBalance:
    """The complete force balance of a spatial rig: its conditions (SI) and least change."""

    scene: object
    balanced_scene: object
    rank: int
    nullity: int
    conditions: list
    theta: np.ndarray
    attainable: bool
    force_rms_N: tuple
    moment_rms_Nm: tuple
    added_first_moment_kg_m: dict
    added_mass_kg: dict
    free: tuple
    samples: int
    unrealizable: dict = field(default_factory=dict)
    table: list = field(default_factory=list)

    @property
    def realizable(self):
        """Return whether every body of the design is a body (:func:`unrealizable_bodies`)."""
        return not self.unrealizable

    def to_dict(self):
        """Return the result as a plain dict."""
        return schema.plain({
            'scene': self.scene.name, 'method': 'complete force balance (null space)',
            'samples': self.samples, 'free': list(self.free), 'rank': self.rank,
            'nullity': self.nullity, 'conditions': self.conditions,
            'attainable': self.attainable, 'realizable': self.realizable,
            'unrealizable': self.unrealizable,
            'added_first_moment_kg_m': self.added_first_moment_kg_m,
            'added_mass_kg': self.added_mass_kg, 'table': self.table})

    def summary(self):
        """Return the provenance stored with the balanced scene."""
        return schema.plain({'source_scene': self.scene.name,
                             'method': 'complete force balance (null space)',
                             'attainable': self.attainable, 'rank': self.rank})


def force_balance(rig, free=None, samples=None):
    """Return the :class:`ForceBalance` of a rig; ``free``: the bodies that may change (all)."""
    model = parameter_model(rig)
    samples = check_samples(samples, rig)
    maps = maps_of(rig, samples)
    nb = len(model.bodies)
    free_idx = free_bodies(model, free, 'free')
    units = units_of(rig, model)
    # conditions over the parameters the scene can hold, in units of each body's mass, reach
    every = set(range(nb))
    full_basis, _, _ = design_columns(model, every)
    full_scale = body_scales(model, every, units)
    fmat = maps.force @ full_basis * full_scale
    _, sv, vt = np.linalg.svd(fmat)
    rank = int(np.sum(sv > RANK_REL_TOL * sv[0])) if sv.size and sv[0] > 0 else 0
    labels = [f'{b.name}.{lab}' for b in model.bodies for lab in b.labels]
    conditions = _conditions(vt[:rank], full_scale, labels)
    # least change of the free bodies (normalized by their own mass and reach)
    basis, orders, _ = design_columns(model, free_idx)
    body_scale = body_scales(model, free_idx, units)
    g = maps.force @ basis * body_scale                          # N per unit design step
    f0 = maps.force @ model.theta
    step, *_ = np.linalg.lstsq(g, -f0, rcond=None)
    theta = model.theta + basis @ (step * body_scale)
    balanced = model.build(theta)
    force = (float(np.linalg.norm(f0)), float(np.linalg.norm(maps.force @ theta)))
    moment = (float(np.linalg.norm(maps.moment @ model.theta)),
              float(np.linalg.norm(maps.moment @ theta)))
    added = {model.bodies[k].name: theta[10 * k:10 * k + 10] - model.theta[10 * k:10 * k + 10]
             for k in free_idx}
    added_h = {name: [float(x) for x in d[1:4]] for name, d in added.items()}
    added_m = {name: float(d[0]) for name, d in added.items()}
    result = ForceBalance(
        scene=rig.scene, balanced_scene=balanced, rank=rank, nullity=full_basis.shape[1] - rank,
        conditions=conditions, theta=theta,
        attainable=force[1] <= FORCE_BALANCED_REL * max(force[0], 1e-300),
        force_rms_N=force, moment_rms_Nm=moment, added_first_moment_kg_m=added_h,
        added_mass_kg=added_m, free=tuple(model.bodies[k].name for k in free_idx),
        samples=samples, unrealizable=unrealizable_bodies(model, theta, free_idx))
    result.table = before_after(rig, balanced, samples, units)
    return result


def unrealizable_bodies(model, theta, indices):
    """Return ``{body: reason}`` of the bodies among ``indices`` with no positive mass or PSD J."""
    out = {}
    for k in indices:
        t = theta[10 * k:10 * k + 10]
        name = model.bodies[k].name
        if not t[0] > 0.0:
            out[name] = f'mass {t[0]:.6g} kg (not positive)'
            continue
        eig = np.linalg.eigvalsh(regressor.pseudo_inertia(t))
        if eig[0] < -PSD_ROUNDOFF * float(np.abs(eig).max()):
            out[name] = (f'pseudo-inertia eigenvalue {eig[0]:.3g} < 0 (a mass distribution '
                         'no body has)')
    return out


def _conditions(rows, scale, names):
    """Return ``rows @ (y / scale) = 0`` as pivot = sum(coefficient * other) (pivoted QR, SI)."""
    import scipy.linalg
    if rows.shape[0] == 0:
        return []
    _, _, piv = scipy.linalg.qr(rows, pivoting=True)
    r = rows.shape[0]
    pivots, others = piv[:r], piv[r:]
    coeff = -np.linalg.solve(rows[:, pivots], rows[:, others])
    out = []
    for i, p in enumerate(pivots):
        terms = {}
        big = float(np.max(np.abs(coeff[i]))) if coeff.shape[1] else 0.0
        for j, o in enumerate(others):
            c = coeff[i, j]
            if abs(c) > CONDITION_COEFF_REL * max(big, 1.0):
                terms[names[o]] = float(c * scale[p] / scale[o])
        out.append({'parameter': names[p], 'equals': terms})
    return out


def format_conditions(conditions):
    """Return the force-balance conditions as lines of text (SI)."""
    lines = []
    for cond in conditions:
        rhs = ' '.join(f'{"-" if c < 0 else "+"} {abs(c):.6g} {n}'
                       for n, c in cond['equals'].items()) or '0'
        lines.append(f'  {cond["parameter"]} = {rhs.lstrip("+ ")}')
    return lines


__all__ = ['force_balance', 'ForceBalance', 'format_conditions', 'unrealizable_bodies']
