"""
Seed 001's tables reproduced by the core (Hoeken: Tables 1, 2, 4, 5, 6, 7; carpet: Table 10).

Damaged or inconsistent printed entries are documented where they are used; nothing is
tuned to them.
"""

import math

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.balancing import paper_tables as seed_tables
from mech_balance.core import equimomental
import numpy as np
from numpy.testing import assert_allclose
import pytest

# Table 4, 'Original' row: f41, f12, f23, f43, torque, shaking force, shaking moment
TABLE4_ORIGINAL = [24.7783, 24.6928, 22.9319, 23.0385, 15.3173, 11.5362, 36.7785]
HOEKEN_JOINTS = ['O1', 'A', 'B', 'O3']   # the paper's 41, 12, 23, 43 (4 = frame)

# Table 5 design vectors [m_i1, m_i2, m_i3, l_i1] x 3 links (normalized), the inputs.
# Printed damaged: b(2) '[0.5990 3.4010 0.9514 4.6933 0 2.4067 1.7240 0.95000 0 0.8759]' has
# 10 numbers for 12 slots.  Table 6's b(2) row fixes them: link 1 (m = 5, d = 0.5608 at
# 211.97 deg, I = 4.5258) gives l = sqrt(I/m) = 0.9514 and point masses 0, 1.5990,
# 3.4010 (the leading '0' and the '1' of '1.5990' were lost); link 3 (m = 9.5, d = l =
# 0.8759 at 120 deg) is one point mass 9.5 at 120 deg ('0.95000' is '0 9.5000').
TABLE5 = {f'{case}{k}': x for (case, k), x in seed_tables.TABLE5.items()}
# Table 6: per link (m, d, theta deg, I about origin)
TABLE6 = {
    'a1': [(1.176, 4.5642, 180.36, 0.9809), (7.103, 0.7388, 358.87, 21.5013),
           (1.903, 2.7582, 178.87, 1.7781)],
    'a2': [(1.000, 5.1222, 206.16, 0.3468), (7.100, 1.4330, 317.86, 21.1024),
           (1.900, 5.3554, 137.86, 1.4577)],
    'a3': [(1.000, 0.1500, 0.00, 0.4023), (7.100, 0.9874, 353.35, 21.1024),
           (1.900, 5.3666, 117.18, 1.4577)],
    'b1': [(5.000, 0.4788, 186.52, 4.5258), (7.100, 1.8206, 354.66, 41.7180),
           (9.500, 1.3166, 176.23, 65.5907)],
    'b2': [(5.000, 0.5608, 211.97, 4.5258), (7.100, 0.9870, 329.15, 21.1024),
           (9.500, 0.8759, 120.00, 7.2884)],
    'b3': [(1.000, 0.1500, 0.00, 0.4023), (7.100, 1.0478, 334.65, 21.1024),
           (9.500, 0.9368, 120.00, 8.3371)],
}
TABLE6_DECIMALS = (3, 4, 2, 4)
# (case, link index, column) of Table 6 entries that the printed Table 5 cannot give.
# a(2) link 1: the printed point masses -4.8784 + 0.7227 + 5.1566 sum to 1.0009 (beyond the
# +-0.00015 their rounding allows), yet Table 6 prints 1.000 - the optimizer's active bound
# m_1 >= m_1^o = 1.  Its d = 5.1222 and theta = 206.16 are reproduced from the same masses,
# so the mass entry, not the vector, is the inconsistent one.
TABLE6_INCONSISTENT = {('a2', 0, 0)}
# Table 7 rows: f41, f12, f23, f43, torque, shaking force, shaking moment
TABLE7 = {
    'a1': [6.2614, 10.2671, 5.8774, 6.2615, 3.9129, 5.98e-5, 10.2544],
    'a2': [4.5516, 6.8703, 3.9930, 4.5518, 2.1480, 4.46e-4, 3.4903],
    'a3': [9.5640, 9.4375, 5.3996, 3.4008, 3.7432, 7.7835, 0.6078],
    'b1': [30.1743, 31.5209, 27.7745, 29.9766, 18.8039, 0.5212, 47.9376],
    'b2': [7.7790, 9.5746, 6.1873, 4.5747, 3.4413, 4.0489, 4.2403],
    'b3': [10.1112, 9.9867, 6.5318, 4.8559, 3.9536, 6.6909, 4.1755],
}
# Table 10, 'Original' row of the carpet-scraping machine: torque, shaking force, moment.
TABLE10_ORIGINAL = [1192.30, 182.40, 413.50]


def _rms_row(sc):
    cycle = analysis.run_cycle(analysis.Rig(sc))
    rows = {r.quantity: r.rms for r in analysis.summarize(cycle, normalized=True)}
    return [rows[f'bearing {j} |f|'] for j in HOEKEN_JOINTS] + [
        rows['driving torque'], rows['shaking force |f_sh|'], rows['shaking moment n_sh']]


def test_table4_original_row_within_0p1_percent():
    got = _rms_row(scene.load('hoeken'))
    assert_allclose(got, TABLE4_ORIGINAL, rtol=1e-3)


def test_table2_point_masses_of_the_original_links():
    sc = scene.load('hoeken')
    x = equimomental.design_vector(sc)
    norm = sc.normalization
    x = x.reshape(3, 4) / np.array([norm.mass_kg] * 3 + [norm.length_m])
    table2 = [[0.4910, 0.2545, 0.2545, 0.6343], [6.2930, 0.4035, 0.4035, 3.4479],
              [1.5372, 0.1814, 0.1814, 1.7517]]
    assert_allclose(x, table2, atol=0.6e-4)


def _table6_entries(x):
    out = []
    for pm in equimomental.split_design(x, 3):
        m, c, i_o = equimomental.link_properties(pm)
        out.append((m, math.hypot(*c), math.degrees(math.atan2(c[1], c[0])) % 360.0, i_o))
    return np.array(out)


@pytest.mark.parametrize('case', sorted(TABLE5))
def test_table5_gives_table6_to_the_printed_digits(case):
    """
    Table 6 from Table 5 through eqs. 19-22, to the printed digits.

    Table 5 itself is printed to 4 decimals, so a derived entry is only determined up to the
    propagated rounding of its inputs (+-0.5e-4 each, linearized); the printed Table 6 value
    must lie within that band plus half a unit of its own last digit.  Example: a(2) link 1
    sums to 1.0009 from the printed masses but Table 6 prints 1.000 (the optimizer's mass
    bound m >= 1 was active and Table 5 is rounded).
    """
    x = np.array(TABLE5[case], dtype=float)
    got = _table6_entries(x)
    band = np.zeros_like(got)
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = 0.5e-4
        band += np.abs(_table6_entries(x + dx) - got)
    printed = np.array(TABLE6[case])
    half_unit = 0.5 * 10.0 ** -np.array(TABLE6_DECIMALS, dtype=float)
    diff = np.abs(got - printed)
    diff[:, 2] = np.minimum(diff[:, 2], 360.0 - diff[:, 2])
    ok = diff <= band + half_unit + 1e-12
    for c, i, j in TABLE6_INCONSISTENT:
        if c == case:
            assert not ok[i, j], 'a documented inconsistency became consistent: update it'
            ok[i, j] = True
    assert np.all(ok), (case, got, printed)


@pytest.mark.parametrize('case', sorted(TABLE5))
def test_table7_rows_within_half_percent(case):
    sc = equimomental.apply_design(scene.load('hoeken'), TABLE5[case], normalized=True)
    got = np.array(_rms_row(sc))
    want = np.array(TABLE7[case])
    # The near-zero shaking forces of a(1), a(2) (5.98e-5, 4.46e-4) are residuals of the
    # paper's optimizer; they are reproduced too, relative to the original 11.5362.
    assert_allclose(got, want, rtol=5e-3)


def test_paper_designs_realizability():
    """Which of Table 5's links are buildable (positive centroidal inertia)."""
    verdict = {case: [equimomental.is_realizable(pm)[0]
                      for pm in equimomental.split_design(x, 3)]
               for case, x in TABLE5.items()}
    # negative centroidal inertia (a), or all the mass in one point (b(2), b(3): I_c = 0)
    assert verdict == {
        'a1': [False, True, False], 'a2': [False, True, False], 'a3': [True, True, False],
        'b1': [True, True, True], 'b2': [True, True, False], 'b3': [True, True, False]}


def test_carpet_scraper_original_against_table10(capsys):
    """
    The reconstructed layout (config/carpet_scraper.yaml, assumptions A1-A5) against Table 10.

    Fig. 4 is missing, so the layout is a reconstruction: agreement is expected to within
    the few per cent that the unstated coupler-point and pantograph details leave open, and
    the mirrored pantograph (the other assembly mode) must be clearly worse.
    """
    sc = scene.load('carpet_scraper')
    cycle = analysis.run_cycle(analysis.Rig(sc))
    rows = {r.quantity: r.rms for r in analysis.summarize(cycle, normalized=True)}
    got = [rows['driving torque'], rows['shaking force |f_sh|'], rows['shaking moment n_sh']]
    with capsys.disabled():
        print('\nTable 10 original (paper -> reconstruction): '
              + ', '.join(f'{w:.2f} -> {g:.2f} ({(g - w) / w:+.1%})'
                          for w, g in zip(TABLE10_ORIGINAL, got)))
    assert_allclose(got, TABLE10_ORIGINAL, rtol=0.08)
    assert np.max(cycle.state.residual) <= 1e-10
