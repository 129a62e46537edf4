"""
Complete force balance of planar linkages in closed form (the total mass centre stationary).

Slider-crank (seed 000 eqs. 44-75) and four-bar (Berkof-Lowen, seed 001 eq. 48); the
derivation: docs/balancing.md, "Closed-form force balances".
"""

from dataclasses import dataclass, replace
import math

from mech_balance import schema
from mech_balance.balancing.checks import BalanceError, check_planar
from mech_balance.balancing.tables import before_after, link_design
from mech_balance.core.planar.rig import objective_units
from mech_balance.schema.scene import FRAME


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

    ``mass_ratios``: (m_1, m_2)/m_3 (eq. 59); ``printed_eq75``: eq. 75 as printed (unbalanced).
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
    method = ('slider-crank, Sinatra & Angeles eqs. 44-75 (xi_2 = -1/mu_2)' if not printed_eq75
              else 'slider-crank, Sinatra & Angeles eq. 75 as printed (xi_2 = +1/mu_2)')
    return _analytic(method,
                     scene, balanced, params, samples, counterweights=False)


def four_bar_balance(scene, mass_factor=1.0, inertia='distance', samples=None):
    """
    Return the Berkof-Lowen complete force balance of a four-bar (seed 001 eq. 48).

    Crank and rocker masses x ``mass_factor``; ``inertia``: 'distance' or 'centroidal' kept.
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
    return _analytic(f'four-bar, Berkof-Lowen (Chaudhary & Saha eq. 48), links 1 and 3 x{k:g}',
                     scene, balanced, params, samples, counterweights=False)


def _analytic(method, scene, balanced, params, samples, counterweights):
    """Return the :class:`AnalyticBalance` of a closed-form design (its table and links)."""
    units = objective_units(scene)
    table = before_after(scene, balanced, samples)
    force = next(r for r in table if r['quantity'].startswith('shaking force'))
    ratio = force['after'] / force['before']
    return AnalyticBalance(method, scene, balanced, params,
                           tuple(link_design(lk, counterweights, units)
                                 for lk in balanced.links), table, ratio)


def _chain(scene, output_type):
    """Return crank, coupler, output of a 3-link loop and their points P1, A1, A2, B2, B3, Q3."""
    check_planar(scene)
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


def _angle_deg(z):
    """Return the angle of a complex number in degrees, in [0, 360)."""
    return math.degrees(math.atan2(z.imag, z.real)) % 360.0


__all__ = ['AnalyticBalance', 'four_bar_balance', 'slider_crank_balance']
