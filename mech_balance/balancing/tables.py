"""The before/after table and the per-link design rows that every planar method reports."""

from dataclasses import dataclass, field
import math

from mech_balance import schema
from mech_balance.analysis import cycle as analysis
from mech_balance.core import equimomental

CHANGE_BASELINE_REL_TOL = 1e-9
"""A before value below this fraction of its kind's largest is round-off (change None)."""


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
    """Return the :class:`LinkDesign` of a link (``counterweights``: point masses >= 0 needed)."""
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
    """Return the before/after rows of RMS bearing forces, torque, shaking force and moment."""
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


__all__ = ['before_after', 'CHANGE_BASELINE_REL_TOL', 'link_design', 'LinkDesign']
