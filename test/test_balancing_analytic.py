"""
Analytic complete force balance: seed 000 eqs. 44-75 (slider-crank), seed 001 eq. 48 (four-bar).

The reference is the physics, not the printed formulas: a force-balanced linkage has a
stationary total mass centre, so its shaking force vanishes to round-off.  Checked here from
link *positions only* (the mass centre over the cycle) and from the core's shaking force.

Correction found: seed 000 eq. 75 prints ``xi_2 = 1/mu_2``.  Eq. 67
(mu_1 xi_1 + mu_2 = mu_2 xi_2) with eq. 71 (1 + mu_1 xi_1 + mu_2 = 0) gives mu_2 xi_2 = -1,
i.e. ``xi_2 = -1/mu_2``: the rod's mass centre lies beyond the crank pin, on the side away
from the slider.  Only the corrected sign balances (test_printed_eq75_does_not_balance).
"""

import math

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.balancing import analytic, redistribution
import numpy as np
from numpy.testing import assert_allclose
import pytest

BALANCED_REL = 1e-12
"""RMS shaking force after / before that counts as complete force balance (round-off)."""
TABLE4_REL = 1e-3
"""Seed 001 Table 4 rows reproduced within 0.1%."""
# seed 001 Table 4: f41, f12, f23, f43, input torque, shaking moment (normalized RMS)
TABLE4 = {1.0: (24.4813, 24.6928, 22.9320, 24.4812, 15.3174, 40.2375),
          2.0: (26.1312, 26.3421, 24.3354, 26.1312, 16.3560, 42.8985),
          5.0: (31.1002, 31.3095, 28.7244, 31.1002, 19.4858, 50.8993)}
TABLE4_ORIGINAL = (24.7783, 24.6928, 22.9319, 23.0385, 15.3173, 36.7785)
TABLE4_COLUMNS = ('bearing O1 |f|', 'bearing A |f|', 'bearing B |f|', 'bearing O3 |f|',
                  'driving torque', 'shaking moment n_sh')
# seed 001 Table 3 point masses (m_i1, m_i2, m_i3) of links 1 and 3, and d_i
TABLE3 = {1.0: ((-0.0619, 0.5309, 0.5309), (-2.3466, 1.4929, 1.4929), 0.3761, 10.6870),
          2.0: ((0.2715, 0.8643, 0.8643), (-6.4616, 5.1308, 5.1308), 0.1880, 5.3438),
          5.0: ((1.2715, 1.8643, 1.8643), (-4.5616, 7.0308, 7.0308), 0.0752, 2.1375)}
TABLE3_POINT_MASS_TOL = 5e-4
"""The paper computed Table 3 with m1 d1 = 0.3760 and m3 d3 = 20.3064 (its optimizer), not
the Berkof-Lowen 0.37616 and 20.306: point masses differ by up to 2e-4."""


def _rows(result):
    return {r['quantity']: r for r in result.table}


def _mass_centre_path(sc, samples=64):
    """Return the total mass centre (complex, m) over the cycle, from link positions only."""
    rig = analysis.Rig(sc)
    state = rig.linkage.solve(np.linspace(0.0, 2.0 * math.pi, samples, endpoint=False),
                              need_rates=False)
    com = np.array([0j] + [complex(*lk.com_m) for lk in sc.links])
    m = np.array([0.0] + [lk.mass_kg for lk in sc.links])
    return np.sum(m[:, None] * (state.pose.origin + state.pose.rot * com[:, None]),
                  axis=0) / np.sum(m)


def _offset_slider_crank():
    data, _ = scene.load_data('slider_crank')
    data['frame']['points']['G'] = [0.0, 0.012]     # guide 12 mm off the crank pivot
    data['links']['rod']['com_m'] = [0.05, 0.004]    # and a rod mass centre off its line
    return scene.from_dict(data, source='offset slider-crank')


def _skewed_four_bar():
    """Return Hoeken with the coupler's mass centre off AB and the rocker frame rotated."""
    data, _ = scene.load_data('hoeken')
    data['links']['coupler']['com_m'] = [0.09, 0.015]
    turn = 0.7
    b = 0.11476 * complex(math.cos(turn), math.sin(turn))
    data['links']['rocker']['points'] = {'O3': [0.0, 0.0], 'B': [b.real, b.imag]}
    data['links']['rocker']['com_m'] = [0.02, 0.03]
    data['assembly']['link_angles_deg']['rocker'] = 103.0 - math.degrees(turn)
    return scene.from_dict(data, source='skewed four-bar')


# ------------------------------------------------------------------------ slider-crank


@pytest.mark.parametrize('make', [lambda: scene.load('slider_crank'), _offset_slider_crank],
                         ids=['in-line', 'offset'])
def test_slider_crank_balance_makes_shaking_force_vanish(make):
    sc = make()
    result = analytic.slider_crank_balance(sc)
    assert result.force_rms_ratio <= BALANCED_REL
    force = _rows(result)['shaking force |f_sh|']
    assert force['after_si'] <= BALANCED_REL * force['before_si']
    # independent of the dynamics code: the total mass centre does not move
    path = _mass_centre_path(result.balanced_scene)
    assert np.ptp(path.real) < 1e-15 and np.ptp(path.imag) < 1e-15


def test_slider_crank_conditions_of_seed000():
    sc = scene.load('slider_crank')
    p = analytic.slider_crank_balance(sc).parameters
    mu1, mu2, xi1, xi2 = p['mu_1'], p['mu_2'], p['xi_1'], p['xi_2']
    assert_allclose([mu1, mu2], [0.8 / 0.6, 0.35 / 0.6], rtol=1e-15)   # eq. 59
    assert p['eta_1'] == 0.0 and p['eta_2'] == 0.0                      # eq. 74
    assert_allclose(mu1 * xi1 + mu2, mu2 * xi2, rtol=1e-14)             # eq. 67
    assert_allclose(1.0 + mu1 * xi1 + mu2, 0.0, atol=1e-14)             # eq. 71
    assert_allclose(xi1, -(1.0 + mu2) / mu1, rtol=1e-15)                # eq. 75, as printed
    assert_allclose(xi2, -1.0 / mu2, rtol=1e-15)                        # eq. 75, corrected
    assert_allclose(p['xi_2_printed_eq75'], 1.0 / mu2, rtol=1e-15)


def test_printed_eq75_does_not_balance():
    """
    Eq. 75 as printed (xi_2 = +1/mu_2) violates eq. 67 and leaves the shaking force.

    With the rod's mass centre on the slider side the slider's and rod's momenta add
    instead of cancelling: the RMS shaking force stays at > 99% of the original.
    """
    sc = scene.load('slider_crank')
    printed = analytic.slider_crank_balance(sc, printed_eq75=True)
    p = printed.parameters
    assert p['xi_2'] == pytest.approx(1.0 / p['mu_2'])
    assert abs(p['mu_1'] * p['xi_1'] + p['mu_2'] - p['mu_2'] * p['xi_2']) > 1.0   # eq. 67
    assert printed.force_rms_ratio > 0.99
    assert np.ptp(_mass_centre_path(printed.balanced_scene).real) > 1e-3


def test_slider_crank_with_given_mass_ratios():
    sc = scene.load('slider_crank')
    result = analytic.slider_crank_balance(sc, mass_ratios=(2.0, 0.4))
    masses = {d.name: d.mass_kg for d in result.links}
    assert_allclose([masses['crank'], masses['rod'], masses['slider']], [1.2, 0.24, 0.6])
    assert result.force_rms_ratio <= BALANCED_REL
    assert all(d.realizable for d in result.links)   # centroidal inertias are kept


def test_force_balance_costs_moment_torque_and_bearings():
    """Seed 001 sec. 1, Lowen et al.: the other dynamic quantities grow."""
    rows = _rows(analytic.slider_crank_balance(scene.load('slider_crank')))
    for name in ('shaking moment n_sh', 'driving torque', 'bearing O |f|', 'bearing A |f|'):
        assert rows[name]['after'] > rows[name]['before'], name


# ------------------------------------------------------------------------ four-bar


def test_berkof_lowen_products_match_table3():
    result = analytic.four_bar_balance(scene.load('hoeken'))
    p = result.parameters
    assert round(p['m1_d1'], 4) == 0.3762 and round(p['m3_d3'], 4) == 20.3060
    assert_allclose([p['theta_1_deg'], p['theta_3_deg']], [180.0, 180.0], atol=1e-9)
    assert result.force_rms_ratio <= BALANCED_REL


@pytest.mark.parametrize('factor', sorted(TABLE4))
def test_table4_rows_of_force_balanced_hoeken(factor):
    result = analytic.four_bar_balance(scene.load('hoeken'), factor)
    rows = _rows(result)
    got = [rows[c]['after'] for c in TABLE4_COLUMNS]
    assert_allclose(got, TABLE4[factor], rtol=TABLE4_REL)
    assert_allclose([rows[c]['before'] for c in TABLE4_COLUMNS], TABLE4_ORIGINAL,
                    rtol=TABLE4_REL)
    assert rows['shaking force |f_sh|']['after'] <= BALANCED_REL * 11.5


@pytest.mark.parametrize('factor', sorted(TABLE3))
def test_table3_point_masses(factor):
    """
    Table 3's point masses follow from eqs. 13-15 with l = l^o, except case (1) link 3.

    Printed (-2.3466, 1.4929, 1.4929) sums to 0.6392, not the 1.900 of its own 'total
    mass' column: a misprint.  Eqs. 13-15 with m = 1.9, l = 1.7517, m d = 20.306 give
    (-7.0949, 4.4974, 4.4974); Table 4's case (1) row is reproduced with those.
    """
    result = analytic.four_bar_balance(scene.load('hoeken'), factor)
    links = {d.name: d.normalized for d in result.links}
    crank_pm, rocker_pm, d1, d3 = TABLE3[factor]
    assert_allclose(links['crank']['point_masses'], crank_pm, atol=TABLE3_POINT_MASS_TOL)
    assert_allclose([links['crank']['com_distance'], links['rocker']['com_distance']],
                    [d1, d3], rtol=1e-3)
    if factor == 1.0:
        assert sum(rocker_pm) == pytest.approx(0.6392)
        assert sum(links['rocker']['point_masses']) == pytest.approx(1.9)
        assert_allclose(links['rocker']['point_masses'], (-7.0949, 4.4974, 4.4974),
                        atol=1e-4)
    else:
        assert_allclose(links['rocker']['point_masses'], rocker_pm,
                        atol=TABLE3_POINT_MASS_TOL)


def test_table3_designs_are_not_realizable_but_centroidal_ones_are():
    """With l kept at l^o (the paper) the rocker's d_3 > l_3: negative centroidal inertia."""
    sc = scene.load('hoeken')
    for factor in sorted(TABLE3):
        paper = {d.name: d for d in analytic.four_bar_balance(sc, factor).links}
        assert paper['crank'].realizable and paper['coupler'].realizable
        assert not paper['rocker'].realizable
        assert paper['rocker'].inertia_com_kg_m2 < 0.0
        kept = analytic.four_bar_balance(sc, factor, inertia='centroidal')
        assert all(d.realizable for d in kept.links)
        assert kept.force_rms_ratio <= BALANCED_REL


def test_general_four_bar_balance():
    """Mass centre off the coupler line, rocker frame not along O3 B: still balanced."""
    result = analytic.four_bar_balance(_skewed_four_bar(), 2.0, inertia='centroidal')
    assert result.force_rms_ratio <= BALANCED_REL
    path = _mass_centre_path(result.balanced_scene)
    assert np.ptp(path.real) < 1e-15 and np.ptp(path.imag) < 1e-15


def test_optimizer_reproduces_berkof_lowen():
    """Seed 001 eq. 49: minimize f with link 2 kept, m and l of links 1 and 3 fixed."""
    sc = scene.load('hoeken')
    l0 = {lk.name: math.sqrt(lk.inertia_origin_kg_m2 / lk.mass_kg) for lk in sc.links}
    fixed = ('crank', 'rocker')
    result = redistribution.optimize(
        sc, (1.0, 0.0), realizable=False, fixed_links=('coupler',),
        mass_bounds={n: (sc.link(n).mass_kg,) * 2 for n in fixed},
        distance_bounds={n: (l0[n],) * 2 for n in fixed})
    closed_form = analytic.four_bar_balance(sc, 1.0)
    for got, ref in zip(result.balanced_scene.links, closed_form.balanced_scene.links):
        assert_allclose(got.first_moment_kg_m, ref.first_moment_kg_m, rtol=1e-7, atol=1e-10)
    assert result.objective['shaking_force_rms'] <= BALANCED_REL * 11.5


# ------------------------------------------------------------------------ bad input


def test_analytic_balance_rejects_the_wrong_linkage():
    with pytest.raises(ValueError, match='slider-crank'):
        analytic.slider_crank_balance(scene.load('hoeken'))
    with pytest.raises(ValueError, match='four-bar'):
        analytic.four_bar_balance(scene.load('slider_crank'))
    with pytest.raises(ValueError, match='four-bar'):
        analytic.four_bar_balance(scene.load('carpet_scraper'))
    with pytest.raises(ValueError, match='mass_factor'):
        analytic.four_bar_balance(scene.load('hoeken'), -1.0)
    with pytest.raises(ValueError, match='inertia'):
        analytic.four_bar_balance(scene.load('hoeken'), 1.0, inertia='mass')
    with pytest.raises(ValueError, match='mass_ratios'):
        analytic.slider_crank_balance(scene.load('slider_crank'), mass_ratios=(0.0, 1.0))
