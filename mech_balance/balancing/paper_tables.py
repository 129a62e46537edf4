"""Seed 001's printed tables that the code compares itself with (data, normalized units)."""

WEIGHT_CASES = ((1.0, 0.0), (0.5, 0.5), (0.0, 1.0))
"""The three weightings of seed 001 Tables 5-10, cases (1)-(3)."""

# seed 001 Table 7 (RMS normalized shaking force, shaking moment) per case and weighting
TABLE7 = {
    ('a', 1): (5.98e-5, 10.2544), ('a', 2): (4.46e-4, 3.4903), ('a', 3): (7.7835, 0.6078),
    ('b', 1): (0.5212, 47.9376), ('b', 2): (4.0489, 4.2403), ('b', 3): (6.6909, 4.1755),
}
# seed 001 Table 5 design vectors [m_i1, m_i2, m_i3, l_i1] per link (normalized); b(2) is
# damaged in the extracted text: reconstructed from Table 6
TABLE5 = {
    ('a', 1): [-3.5246, 2.3285, 2.3718, 0.9134, 4.3784, 1.3282, 1.3968, 1.7398,
               -2.9843, 2.5052, 2.3818, 0.9667],
    ('a', 2): [-4.8784, 0.7227, 5.1566, 0.5886, 5.2843, -1.3781, 3.1938, 1.7240,
               -5.1095, 8.0046, -0.9951, 0.8759],
    ('a', 3): [0.4910, 0.2545, 0.2545, 0.6343, 5.0594, 0.7484, 1.2922, 1.7240,
               -2.9119, 8.3848, -3.5729, 0.8759],
    ('b', 1): [0.0, 2.3350, 2.6650, 0.9514, 5.9063, 0.3106, 0.8831, 2.4240,
               0.0, 4.9305, 4.5695, 2.6276],
    ('b', 2): [0.0, 1.5990, 3.4010, 0.9514, 4.6933, 0.0, 2.4067, 1.7240,
               0.0, 9.5000, 0.0, 0.8759],
    ('b', 3): [0.4910, 0.2545, 0.2545, 0.6343, 4.9665, 0.0, 2.1335, 1.7240,
               0.0, 9.5000, 0.0, 0.9368],
}
# seed 001 Table 10 (driving torque, shaking force, shaking moment), carpet scraper, case a
TABLE10 = {1: (533.63, 1.36, 1337.60), 2: (245.02, 32.74, 5.32), 3: (474.63, 84.70, 3.38)}
TABLE10_ORIGINAL = (1192.30, 182.40, 413.50)
# seed 001 Table 9 design vectors (normalized); case (3)'s "- 5.3880" read as -5.3880
TABLE9 = {
    1: [-9.0271, 3.1794, 6.8477, 0.6480, 3.0299, 3.1281, 1.7513, 1.9080, -0.8209, 13.2130,
        -9.5284, 2.6033, -8.4529, 6.9753, 6.6780, 4.7979, 0.1514, 1.0659, 3.0828, 3.5648,
        2.3972, 6.9384, 6.8620, 8.0674, 17.7147, -5.6340, -5.7872, 5.5376],
    2: [-5.3548, -22.4369, 28.7917, 0.3592, -6.9162, 4.9914, 9.0249, 1.7240, -70.8281,
        37.1001, 43.2280, 1.3079, 22.0392, -6.4234, 33.6626, 2.8325, 1.0194, -10.6993,
        13.9800, 1.9142, 7.8013, 9.6599, -3.2613, 5.9602, 25.2464, -40.4415, 19.4951,
        2.0326],
    3: [0.4910, 0.2545, 0.2545, 0.6343, -8.9417, 21.7354, -5.1980, 1.7240, -37.5079,
        14.1236, 29.2331, 0.8922, 0.2026, -4.1376, 21.8940, 2.7065, 4.9895, 4.6985, -5.3880,
        5.6265, 8.2713, 9.8027, -3.8741, 6.4858, 26.5309, -19.9802, -2.2506, 2.9904],
}
# seed 001 Table 12 (RMS driving torque, shaking force, shaking moment; w1 = w2 = 0.5, eqs.
# B.1-B.5): two- and three-point-mass models
TABLE12 = {
    'hoeken': {'original': (15.32, 11.54, 36.78), 'two': (1.24, 5.67, 4.34),
               'three': (2.15, 0.05, 3.44)},
    'carpet_scraper': {'original': (1192.30, 182.40, 413.50), 'two': (519.37, 55.19, 14.50),
                       'three': (230.47, 51.14, 25.30)},
}
TABLE3_MASS_FACTORS = (1.0, 2.0, 5.0)
"""Seed 001 Table 3 cases (1)-(3): crank and rocker masses 1x, 2x, 5x the original."""


def weight_case(weights):
    """Return the case (1)-(3) of :data:`WEIGHT_CASES` that ``weights`` are, or None."""
    import numpy as np
    for k, w in enumerate(WEIGHT_CASES, 1):
        if np.allclose(weights, w):
            return k
    return None


def compare_optimum(result):
    """Return how a redistribution optimum compares with seed 001's, or None where none applies."""
    k = weight_case(result.weights)
    name = result.scene.name
    if k is None or result.torque_weight or result.reaction_weight or \
            name not in ('hoeken', 'carpet_scraper'):
        return None
    if name == 'hoeken':
        f, n = TABLE7[(result.case, k)]
        x = TABLE5[(result.case, k)]
        label = f'Table 7 case {result.case}({k})'
    elif result.case != 'a':
        return None
    else:
        _, f, n = TABLE10[k]
        x = TABLE9[k]
        label = f'Table 10 case ({k})'
    w1, w2 = result.weights
    z_paper = w1 * f + w2 * n
    z = result.objective['z']
    from mech_balance.balancing import tables
    from mech_balance.core import equimomental
    sc = result.scene
    links = [tables.link_design(lk, result.case == 'b', sc.normalization)
             for lk in equimomental.apply_design(sc, x, normalized=True).links]
    return {'label': label, 'f': f, 'n': n, 'z_paper': z_paper, 'z': z,
            'change_percent': (z - z_paper) / z_paper * 100.0,
            'paper_constraints': result.paper_constraints,
            'unrealizable': {d.name: d.reason for d in links if not d.realizable}}


def analytic_variants(rig, mass_factors=None, keep_centroidal=False, samples=None):
    """Return the Design of each analytic variant (a four-bar: per :data:`TABLE3_MASS_FACTORS`)."""
    from mech_balance import balancing
    from mech_balance.core.rig import as_rig
    rig = as_rig(rig)
    if any(j.joint_type == 'prismatic' for j in rig.scene.joints):
        return [balancing.balance(rig, 'analytic', samples=samples),
                balancing.balance(rig, 'analytic', printed_eq75=True, samples=samples)]
    inertia = 'centroidal' if keep_centroidal else 'distance'
    return [balancing.balance(rig, 'analytic', mass_factor=k, inertia=inertia, samples=samples)
            for k in mass_factors or TABLE3_MASS_FACTORS]


def table12_rows(table12):
    """Return the rows of seed 001 Table 12's comparison: label, torque, force, moment and z."""
    w1, w2 = table12.weights
    rows = []
    paper = TABLE12.get(table12.scene)
    if paper is not None and tuple(table12.weights) == (0.5, 0.5):
        rows += [('paper, two point masses', *paper['two']),
                 ('paper, three point masses', *paper['three'])]
    for label, terms in (('three point masses = relaxation (certified)', table12.lower_terms),
                         ('two point masses, best design found', table12.upper_terms)):
        rows.append((label, terms['driving_torque'], terms['shaking_force'],
                     terms['shaking_moment']))
    return [(label, torque, force, moment, w1 * force + w2 * moment)
            for label, torque, force, moment in rows]
