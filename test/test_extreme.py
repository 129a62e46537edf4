"""
Extreme and ill-conditioned rigs: change points, toggles, scale, mass ratios.

* A four-bar at and near the Grashof change point (both ways of folding) and a slider-crank
  whose rod length approaches the crank length: the core must follow the assembly branch
  (checked against the closed-form position of the chosen branch at every angle), report
  the Jacobian condition number (which grows like 1/sqrt(distance to the change point)),
  warn as it grows, and refuse with an error naming the crank angle where the linkage
  cannot be assembled or the branch is lost.
* Scale: lengths 1e-6..1e3 m, masses 1e-8..1e8 kg, crank speeds 1e-3..1e4 rad/s give the
  reference rig's normalized outputs within 1e-9.
* Mass ratios between links up to 1e8: superposition, power balance and the independence of
  the other joints' reactions from the crank's inertia hold to round-off.

Five core bugs were first found here (as strict xfails) and fixed: silent branch jumps
near a change point (now guarded by the sign of det J_u and a midpoint check of the branch
trace), a missing 2 pi in the step-by-step re-trace, a stale crank speed from the linkage
cache, and a NaN driving torque at rest.
"""

import copy
import itertools
import math
import re
import warnings

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.conventions import cycle_angles
from mech_balance.core import forward as simulate
from mech_balance.core.planar import dynamics, kinematics
import numpy as np
from numpy.testing import assert_allclose
import pytest

ANGLES = 1440
R_CRANK = 0.04
NAME_ROUNDOFF = 1e-12
"""Position error allowed per unit of Jacobian condition number (relative to the crank)."""


# ----------------------------------------------------------------------------- builders


def slider_crank(rod_m, assembly_deg=0.0, name=None):
    """Return the slider_crank scene with another rod length (slider on +x at 0 deg)."""
    data, _ = scene.load_data('slider_crank')
    data = copy.deepcopy(data)
    data['name'] = name or f'slider_rod_{rod_m!r}_{assembly_deg!r}'
    data['links']['rod']['points']['B'] = [rod_m, 0.0]
    data['links']['rod']['com_m'] = [rod_m / 3.0, 0.0]
    s0 = R_CRANK * math.cos(math.radians(assembly_deg)) + math.sqrt(
        max(rod_m ** 2 - (R_CRANK * math.sin(math.radians(assembly_deg))) ** 2, 0.0))
    data['assembly'] = {'crank_angle_deg': assembly_deg, 'link_angles_deg': {'rod': -1.0},
                        'joint_displacements_m': {'S': s0}}
    return scene.from_dict(data, 'test')


def slider_position(rod_m, psi):
    """Return the closed-form slide of the in-line slider-crank's +x branch."""
    return R_CRANK * np.cos(psi) + np.sqrt(rod_m ** 2 - (R_CRANK * np.sin(psi)) ** 2)


def four_bar_b(a, b, c, d, psi, sign=1.0):
    """Return the coupler-rocker pin B (complex) of the branch ``sign``, closed form."""
    pa = a * np.exp(1j * psi)
    v = d - pa
    dist = np.abs(v)
    x = (b * b - c * c + dist * dist) / (2.0 * dist)
    h = np.sqrt(np.maximum(b * b - x * x, 0.0))
    return pa + v / dist * (x + sign * 1j * h)


def four_bar(a, b, c, d, psi0_deg=90.0, name=None):
    """Return a four-bar scene: crank a, coupler b, rocker c, frame d (B above O1O3)."""
    psi0 = math.radians(psi0_deg)
    pb = complex(four_bar_b(a, b, c, d, psi0))
    pa = a * complex(math.cos(psi0), math.sin(psi0))
    data = {
        'name': name or f'four_bar_{a!r}_{b!r}_{c!r}_{d!r}', 'kind': 'planar',
        'crank': {'joint': 'O1', 'speed_rad_s': 1.0},
        'frame': {'points': {'O1': [0.0, 0.0], 'O3': [d, 0.0]}},
        'links': {
            'crank': {'points': {'O1': [0.0, 0.0], 'A': [a, 0.0]}, 'mass_kg': 1.0,
                      'com_m': [0.5 * a, 0.0], 'inertia_com_kg_m2': 0.1},
            'coupler': {'points': {'A': [0.0, 0.0], 'B': [b, 0.0]}, 'mass_kg': 2.0,
                        'com_m': [0.5 * b, 0.1], 'inertia_com_kg_m2': 0.5},
            'rocker': {'points': {'O3': [0.0, 0.0], 'B': [c, 0.0]}, 'mass_kg': 1.5,
                       'com_m': [0.4 * c, 0.0], 'inertia_com_kg_m2': 0.3}},
        'joints': {'O1': {'type': 'revolute', 'a': 'frame.O1', 'b': 'crank.O1'},
                   'A': {'type': 'revolute', 'a': 'crank.A', 'b': 'coupler.A'},
                   'B': {'type': 'revolute', 'a': 'coupler.B', 'b': 'rocker.B'},
                   'O3': {'type': 'revolute', 'a': 'frame.O3', 'b': 'rocker.O3'}},
        'assembly': {'crank_angle_deg': psi0_deg,
                     'link_angles_deg': {'coupler': math.degrees(np.angle(pb - pa)),
                                         'rocker': math.degrees(np.angle(pb - d))}},
    }
    return scene.from_dict(data, 'test')


# Change-point families: (a, b, c, d(eps)) with a + l = p + q at eps = 0.
# 'stretched': d longest, coupler and rocker stretched in line at psi = 180 deg;
# 'folded': rocker longest, coupler folded onto the rocker at psi = 0 deg.
FAMILIES = {
    'stretched': (lambda eps: (1.0, 3.0, 2.5, 4.5 - eps), 180.0),
    'folded': (lambda eps: (1.0, 2.5, 4.0, 2.5 + eps), 0.0),
}


def _solve_quietly(rig, psi):
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        return rig.linkage.solve(psi, need_rates=True, need_acc=False)


def _pin_b(state, b):
    return state.pose.origin[2] + state.pose.rot[2] * b


# ----------------------------------------------------------------------------- slider-crank


@pytest.mark.parametrize('eps', [1e-1, 1e-2, 1e-4, 1e-6])
def test_slider_crank_follows_branch_as_rod_approaches_crank(eps):
    rod = R_CRANK * (1.0 + eps)
    rig = analysis.Rig(slider_crank(rod))
    psi = cycle_angles(ANGLES)
    st = _solve_quietly(rig, psi)
    slide = st.pose.origin[3].real
    tol = NAME_ROUNDOFF * R_CRANK * max(float(np.max(st.cond)), 1.0)
    assert_allclose(slide, slider_position(rod, psi), rtol=0, atol=tol)
    # the condition number grows like sqrt(2 / eps) (the rod folds over the crank at 90/270)
    if eps <= 1e-4:
        assert_allclose(np.max(st.cond) * math.sqrt(eps), math.sqrt(2.0), rtol=0.05)


def test_slider_crank_condition_grows_and_warns():
    conds = []
    for eps in (1e-2, 1e-4, 1e-6):
        rig = analysis.Rig(slider_crank(R_CRANK * (1.0 + eps)))
        conds.append(float(np.max(_solve_quietly(rig, cycle_angles(360)).cond)))
    assert conds[0] < conds[1] < conds[2] < kinematics.COND_WARN
    with pytest.warns(RuntimeWarning, match=r'crank angle \d+\.\d+ deg: near-singular'):
        rig = analysis.Rig(slider_crank(R_CRANK * (1.0 + 1e-8)))
        analysis.run_cycle(rig, 360)
    assert any('Jacobian condition number' in w for w in rig.linkage.warnings)


def test_slider_crank_never_jumps_branch_near_change_point():
    rod = R_CRANK * (1.0 + 1e-9)
    rig = analysis.Rig(slider_crank(rod))
    psi = cycle_angles(3600)
    st = _solve_quietly(rig, psi)
    # the two branches are >= 2 r sqrt(2 eps) = 3.6e-6 m apart: 1e-7 m tells them apart
    assert_allclose(st.pose.origin[3].real, slider_position(rod, psi), rtol=0, atol=1e-7)


def test_slider_crank_at_change_point_is_refused_naming_the_angle():
    with pytest.raises(kinematics.BranchError,
                       match=r'crank angle (90|270)\.0+ deg: the linkage passes a singular '
                             r'position'):
        analysis.Rig(slider_crank(R_CRANK))


@pytest.mark.parametrize('eps', [-1e-1, -1e-3])
def test_short_rod_is_refused_where_it_cannot_reach(eps):
    rod = R_CRANK * (1.0 + eps)
    limit = math.degrees(math.asin(rod / R_CRANK))
    with pytest.raises(kinematics.BranchError, match=r'crank angle [\d.]+ deg: cannot '
                                                     r'continue the assembly branch') as exc:
        analysis.Rig(slider_crank(rod))
    angle = float(str(exc.value).split('crank angle ')[1].split(' deg')[0])
    assert abs(angle - limit) < 0.05


def test_assembly_where_the_rod_cannot_reach_names_the_angle():
    with pytest.raises(kinematics.BranchError,
                       match=r'does not close at crank angle 90\.000 deg'):
        analysis.Rig(slider_crank(0.9 * R_CRANK, assembly_deg=90.0))


def _printed_angles(messages):
    """Return the crank angles (deg) named in ``messages``."""
    return [float(a) for m in messages for a in re.findall(r'crank angle (-?[\d.]+) deg', m)]


def test_crank_angles_in_messages_are_wrapped_into_one_turn():
    """A warning or an error names its crank angle in [0, 360) deg, whatever turn it is in."""
    with pytest.raises(kinematics.BranchError,
                       match=r'does not close at crank angle 90\.000 deg'):
        analysis.Rig(slider_crank(0.9 * R_CRANK, assembly_deg=810.0))
    with pytest.raises(kinematics.BranchError,
                       match=r'crank angle (90|270)\.0+ deg: the linkage passes a singular '
                             r'position'):
        analysis.Rig(slider_crank(R_CRANK, assembly_deg=720.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always', RuntimeWarning)
        rig = analysis.Rig(slider_crank(R_CRANK * (1.0 + 1e-8), assembly_deg=720.0))
        traced = _printed_angles(str(w.message) for w in caught)
        rig.linkage.solve(cycle_angles(360) + 6.0 * np.pi, need_rates=True, need_acc=False)
        evaluated = _printed_angles(str(w.message) for w in caught[len(traced):])
    assert traced and all(0.0 <= a < 360.0 for a in traced)
    assert evaluated and all(0.0 <= a < 360.0 for a in evaluated)


# ----------------------------------------------------------------------------- four-bar


@pytest.mark.parametrize('family, eps', [
    (family, eps) for family in FAMILIES for eps in (0.5, 1e-2, 1e-4, 1e-6)])
def test_four_bar_follows_branch_near_grashof_change_point(family, eps):
    dims, singular_deg = FAMILIES[family]
    a, b, c, d = dims(eps)
    assert a + max(b, c, d) < sum((a, b, c, d)) - a - max(b, c, d) + 1e-12  # Grashof
    rig = analysis.Rig(four_bar(a, b, c, d))
    psi = cycle_angles(ANGLES)
    st = _solve_quietly(rig, psi)
    cond = np.max(st.cond)
    assert_allclose(_pin_b(st, b), four_bar_b(a, b, c, d, psi), rtol=0,
                    atol=NAME_ROUNDOFF * max(cond, 1.0))
    worst = math.degrees(psi[int(np.argmax(st.cond))])
    assert abs(((worst - singular_deg) + 180.0) % 360.0 - 180.0) < 1.0 + 40.0 * math.sqrt(eps)
    if eps <= 1e-4:
        assert 0.3 < cond * math.sqrt(eps) < 30.0


@pytest.mark.parametrize('family', FAMILIES)
def test_four_bar_at_change_point_is_refused_naming_the_angle(family):
    dims, singular_deg = FAMILIES[family]
    with pytest.raises(kinematics.BranchError,
                       match=r'crank angle [\d.]+ deg: the linkage passes a singular '
                             'position') as exc:
        analysis.Rig(four_bar(*dims(0.0)))
    angle = float(str(exc.value).split('crank angle ')[1].split(' deg')[0])
    assert abs(((angle - singular_deg) + 180.0) % 360.0 - 180.0) < 1e-3


@pytest.mark.parametrize('family', FAMILIES)
@pytest.mark.parametrize('eps', [-1e-2, -1e-4])
def test_non_grashof_four_bar_is_refused_where_it_stops(family, eps):
    dims, _ = FAMILIES[family]
    a, b, c, d = dims(eps)
    # the crank stops where |A O3| leaves [|b - c|, b + c]
    reach = (b + c) if family == 'stretched' else abs(b - c)
    stop = math.degrees(math.acos((a * a + d * d - reach * reach) / (2.0 * a * d)))
    with pytest.raises(kinematics.BranchError,
                       match=r'crank angle [\d.]+ deg: cannot continue') as exc:
        analysis.Rig(four_bar(a, b, c, d))
    angle = float(str(exc.value).split('crank angle ')[1].split(' deg')[0])
    assert min(abs(angle - stop), abs(angle - (360.0 - stop))) < 0.05


def test_four_bar_never_jumps_branch_near_change_point():
    a, b, c, d = FAMILIES['stretched'][0](1e-9)
    rig = analysis.Rig(four_bar(a, b, c, d))
    psi = cycle_angles(3600)
    st = _solve_quietly(rig, psi)
    assert_allclose(_pin_b(st, b), four_bar_b(a, b, c, d, psi), rtol=0, atol=1e-6)


def test_four_bar_toggle_positions_are_regular_for_crank_input():
    # rocker dead centres: crank and coupler in line (|O1 B| = b +- a); for crank input the
    # loop Jacobian is regular there and the rocker stands still
    a, b, c, d = 1.0, 3.0, 2.5, 3.2
    rig = analysis.Rig(four_bar(a, b, c, d))
    toggles = []
    for reach in (b + a, b - a):
        cos_b = (reach * reach + d * d - c * c) / (2.0 * reach * d)
        beta = math.acos(cos_b)            # angle of B seen from O1 (B above the frame)
        toggles.append(beta if reach == b + a else beta + math.pi)
    psi = np.array(toggles)
    st, _ = rig.evaluate(psi, ('kinematics',))
    assert np.max(st.cond) < 50.0
    rocker_rate = st.omega[3] / st.psi_d
    assert_allclose(rocker_rate, 0.0, atol=1e-12)
    near = rig.evaluate(psi + 1e-3, ('kinematics',))[0].omega[3]
    assert np.all(np.abs(near) > 1e-6)


# ----------------------------------------------------------------------------- scale

SCALES = list(itertools.product((1e-6, 1.0, 1e3), (1e-8, 1.0, 1e8), (1e-3, 1.0, 1e4)))


def scaled_data(data, length, mass, omega):
    """Return a scene mapping with every length, mass and speed scaled (units kept)."""
    d = copy.deepcopy(data)
    d.pop('drive', None)

    def pts(p):
        return {k: [v[0] * length, v[1] * length] for k, v in p.items()}
    d['frame']['points'] = pts(d['frame']['points'])
    for lk in d['links'].values():
        lk['points'] = pts(lk['points'])
        lk['mass_kg'] *= mass
        lk['com_m'] = [x * length for x in lk.get('com_m', [0.0, 0.0])]
        for key in ('inertia_com_kg_m2', 'inertia_origin_kg_m2'):
            if key in lk:
                lk[key] *= mass * length * length
    d['crank']['speed_rad_s'] *= omega
    d['crank']['acceleration_rad_s2'] = d['crank'].get('acceleration_rad_s2', 0.0) * omega ** 2
    asm = d['assembly']
    asm['joint_displacements_m'] = {k: v * length for k, v in
                                    asm.get('joint_displacements_m', {}).items()}
    n = d['normalization']
    d['normalization'] = {'mass_kg': n['mass_kg'] * mass, 'length_m': n['length_m'] * length,
                          'omega_rad_s': n['omega_rad_s'] * omega}
    d['name'] = f'{d["name"]}_L{length:g}_M{mass:g}_W{omega:g}'
    return d


def _normalized(sc, samples=90):
    rig = analysis.Rig(sc)
    cycle = analysis.run_cycle(rig, samples)
    rows = analysis.summarize(cycle, normalized=True)
    st = cycle.state
    length = sc.normalization.length_m
    return (np.array([[r.rms, r.max_abs] for r in rows]), st.pose.phi,
            st.pose.origin / length, st.cond)


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank', 'carpet_scraper'])
def test_normalized_outputs_are_scale_invariant(name):
    data, _ = scene.load_data(name)
    data = copy.deepcopy(data)
    data['crank']['acceleration_rad_s2'] = 0.3 * data['crank']['speed_rad_s'] ** 2
    ref = _normalized(scene.from_dict(scaled_data(data, 1.0, 1.0, 1.0), 'test'))
    for length, mass, omega in SCALES:
        got = _normalized(scene.from_dict(scaled_data(data, length, mass, omega), 'test'))
        assert_allclose(got[0], ref[0], rtol=1e-9, err_msg=f'{length} {mass} {omega}')
        assert_allclose(got[1], ref[1], rtol=0, atol=1e-12)
        assert_allclose(got[2], ref[2], rtol=0, atol=1e-12)
        assert_allclose(got[3], ref[3], rtol=1e-9)


def test_rig_uses_its_own_crank_speed():
    data, _ = scene.load_data('hoeken')
    slow = scene.from_dict(copy.deepcopy(data), 'test')
    fast_data = copy.deepcopy(data)
    fast_data['crank']['speed_rad_s'] = 10.0
    fast = scene.from_dict(fast_data, 'test')
    torque_slow = analysis.run_cycle(analysis.Rig(slow), 36).wrenches.driving_torque
    torque_fast = analysis.run_cycle(analysis.Rig(fast), 36).wrenches.driving_torque
    assert_allclose(torque_fast, 100.0 * torque_slow, rtol=1e-12)


# ----------------------------------------------------------------------------- mass ratios


def _with_link_scaled(sc, link, factor):
    links = [lk if lk.name != link else type(lk)(
        lk.name, lk.points, lk.mass_kg * factor, lk.com_m, lk.inertia_com_kg_m2 * factor)
        for lk in sc.links]
    return sc.with_links(links)


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank'])
@pytest.mark.parametrize('factor', [1e8, 1e-8])
def test_mass_ratio_1e8_superposition_and_power_balance(name, factor):
    sc, _ = simulate.load(name)
    sc = sc.with_outputs(('bearing_reactions',))
    rig = analysis.Rig(sc)
    psi = cycle_angles(72)
    omega, alpha = 2.0, 0.7
    for link in sc.links:
        extreme = rig.with_scene(_with_link_scaled(sc, link.name, factor))
        st, w = extreme.evaluate(psi, speed=omega, accel=alpha)
        ratio = max(lk.mass_kg for lk in extreme.scene.links) / min(
            lk.mass_kg for lk in extreme.scene.links)
        assert ratio >= 1e7
        # superposition: the link alone plus the others alone (parameters are linear)
        theta = dynamics.parameter_vector(extreme.inertia)
        parts = []
        for keep in (True, False):
            mask = np.zeros_like(theta)
            i = [lk.name for lk in sc.links].index(link.name)
            mask[4 * i:4 * i + 4] = 1.0
            part = theta * (mask if keep else 1.0 - mask)
            parts.append(dynamics.inverse_dynamics(
                extreme.linkage, st, dynamics.inertia_from_vector(part), 0j,
                {'bearing_reactions'}))
        for key in ('shaking_force', 'shaking_moment', 'driving_torque'):
            total = getattr(w, key)
            a, b = (getattr(p, key) for p in parts)
            scale = max(np.max(np.abs(a)), np.max(np.abs(b)))
            assert np.max(np.abs(total - a - b)) <= 1e-12 * scale, key
        for joint, force in w.reaction_force.items():
            a, b = (p.reaction_force[joint] for p in parts)
            scale = max(np.max(np.abs(a)), np.max(np.abs(b)))
            assert np.max(np.abs(force - a - b)) <= 1e-12 * scale, joint
        # power balance: tau = I psi'' - c1 psi'^2 (seed 000 eq. 39), both torque paths
        f = simulate.rig_functions(extreme, psi)
        expected = f[0] * alpha - f[1] * omega ** 2
        scale = np.max(np.abs(expected))
        assert_allclose(w.driving_torque, expected, rtol=0, atol=1e-11 * scale)
        _, w2 = extreme.evaluate(psi, ('driving_torque',), speed=omega, accel=alpha)
        assert_allclose(w2.driving_torque, expected, rtol=0, atol=1e-11 * scale)
        assert w.consistency <= 1e-11 * np.max(np.abs(np.concatenate(
            list(w.reaction_force.values()))) * extreme.linkage.length_scale)


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank'])
def test_heavy_crank_leaves_the_other_joints_unchanged(name):
    # the motor carries the crank's own inertia: the other joints must not see a 1e8 crank
    sc, _ = simulate.load(name)
    sc = sc.with_outputs(('bearing_reactions',))
    rig = analysis.Rig(sc)
    crank = next(j for j in sc.joints if j.name == sc.crank_joint)
    crank_link = crank.link_b if crank.link_a == scene.FRAME else crank.link_a
    heavy = rig.with_scene(_with_link_scaled(sc, crank_link, 1e8))
    psi = cycle_angles(72)
    _, ref = rig.evaluate(psi, speed=3.0, accel=1.5)
    _, got = heavy.evaluate(psi, speed=3.0, accel=1.5)
    for joint in ref.reaction_force:
        if joint == sc.crank_joint:
            continue
        scale = np.max(np.abs(ref.reaction_force[joint]))
        assert_allclose(got.reaction_force[joint], ref.reaction_force[joint], rtol=0,
                        atol=1e-9 * scale, err_msg=joint)


# ----------------------------------------------------------------------------- degenerate


def test_single_crank_flywheel_rig():
    # one link, one revolute joint to the frame: mobility 1 and no loop to close
    data = {'name': 'flywheel', 'crank': {'joint': 'O', 'speed_rad_s': 10.0,
                                          'acceleration_rad_s2': 4.0},
            'frame': {'points': {'O': [0.0, 0.0]}},
            'links': {'disc': {'points': {'O': [0.0, 0.0], 'P': [0.1, 0.0]}, 'mass_kg': 2.0,
                               'com_m': [0.02, 0.0], 'inertia_com_kg_m2': 0.01}},
            'joints': {'O': {'type': 'revolute', 'a': 'frame.O', 'b': 'disc.O'}},
            'assembly': {'crank_angle_deg': 0.0}}
    rig = analysis.Rig(scene.from_dict(data, 'test'))
    cycle = analysis.run_cycle(rig, 8)
    i_o = 0.01 + 2.0 * 0.02 ** 2
    assert_allclose(cycle.wrenches.driving_torque, i_o * 4.0, rtol=1e-12)
    # the bearing carries m a_c: centripetal and tangential parts of the mass centre
    c = 0.02 * np.exp(1j * cycle.psi)
    a_c = (1j * 4.0 - 10.0 ** 2) * c
    assert_allclose(cycle.wrenches.reaction_force['O'], 2.0 * a_c, rtol=0, atol=1e-12)
    assert_allclose(simulate.rig_functions(rig, cycle.psi)[0], i_o, rtol=1e-12)


def test_driving_torque_at_rest_is_finite():
    sc, _ = simulate.load('slider_crank')
    rig = analysis.Rig(sc)
    psi = cycle_angles(12)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        _, w = rig.evaluate(psi, ('driving_torque',), speed=0.0, accel=2.0)
    _, ref = rig.evaluate(psi, ('bearing_reactions',), speed=0.0, accel=2.0)
    assert_allclose(w.driving_torque, ref.driving_torque, rtol=1e-12)
