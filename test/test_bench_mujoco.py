"""
The MuJoCo comparison and the generated chains it scales over.

The chain tests run everywhere; the agreement tests need the optional ``mujoco`` package and
are skipped without it (``make test`` and ``make bench-mujoco`` install it).  No timings here.
"""

import math
import sys

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.bench import chains as chain
from mech_balance.cli import main as cli
from mech_balance.conventions import cycle_angles
from mech_balance.core.planar import dynamics, kinematics
import numpy as np
from numpy.testing import assert_allclose
import pytest

AGREEMENT = 1e-9
"""The comparison's acceptance: relative difference to the cycle's peak."""


def _relative(ours, theirs):
    return float(np.max(np.abs(np.asarray(theirs) - ours)) / np.max(np.abs(ours)))


# ----------------------------------------------------------------------------- the generator


@pytest.mark.parametrize('loops', [1, 3, 4, 9, 19])
def test_chain_counts_assembles_and_turns_fully(loops):
    sc = chain.dyad_chain(loops)
    moving, with_frame, joints = chain.link_counts(loops)
    assert (len(sc.links), len(sc.joints)) == (moving, joints)
    assert with_frame == moving + 1 and 3 * moving - 2 * joints == 1   # Gruebler
    rig = analysis.Rig(sc)                      # assembles and traces the branch, full turn
    lk = rig.linkage
    assert len(lk.cuts) == loops and lk.nu == 2 * loops
    psi = cycle_angles(360) + 0.3
    state, w = rig.evaluate(psi)
    assert np.max(state.residual) < 1e-12
    assert np.max(state.cond) < kinematics.COND_WARN
    # every cut joint closes: its two points coincide (independent of the residual code)
    for c in lk.cuts:
        pa = state.pose.origin[c.a] + state.pose.rot[c.a] * c.p_a
        pb = state.pose.origin[c.b] + state.pose.rot[c.b] * c.p_b
        assert np.max(np.abs(pb - pa)) < 1e-13
    # the crank turns once, every rocker swings within the documented range
    phi = np.degrees(state.pose.phi)
    assert_allclose(np.unwrap(state.pose.phi[1]) - psi, 0.0, atol=1e-12)
    for i, name in enumerate(lk.body_names):
        if name.startswith('rocker'):
            assert 85.0 < phi[i].min() and phi[i].max() < 135.0, name
    assert np.all(np.isfinite(w.driving_torque))


def test_chain_power_balance():
    """Driving power equals the kinetic energy rate, from positions only (finite differences)."""
    rig = analysis.Rig(chain.dyad_chain(4))
    omega, h = rig.scene.crank_speed_rad_s, 1e-3
    psi = cycle_angles(24)
    _, w = rig.evaluate(psi, ('bearing_reactions',), speed=omega, accel=0.0)

    def kinetic(angles):
        st, _ = rig.evaluate(angles, ('kinematics',), speed=omega, accel=0.0)
        return 0.5 * omega ** 2 * dynamics.generalized_inertia(st, rig.inertia)

    # dT/dt = omega dT/dpsi, 4th-order central difference
    rate = omega * (-kinetic(psi + 2 * h) + 8 * kinetic(psi + h) - 8 * kinetic(psi - h)
                    + kinetic(psi - 2 * h)) / (12 * h)
    assert_allclose(w.driving_torque * omega, rate, rtol=0, atol=1e-8 * np.max(np.abs(rate)))


@pytest.mark.parametrize('kwargs, match', [
    ({'loops': 0}, 'loops: got 0, expected an integer from 1'),
    ({'loops': 2.0}, 'loops: got 2.0, expected an integer'),
    ({'loops': True}, 'loops: got True'),
    ({'loops': 2, 'crank_m': -0.1}, 'crank_m: got -0.1, expected a positive'),
    ({'loops': 2, 'density_kg_m': math.nan}, 'density_kg_m: got nan'),
    ({'loops': 2, 'skew': 0.5}, r'skew: got 0.5, expected a number in \[0, 0.2\)'),
])
def test_chain_rejects_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        chain.dyad_chain(**kwargs)


# ----------------------------------------------------------------------------- without MuJoCo


def test_compare_without_mujoco_exits_2(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, 'mujoco', None)        # import mujoco -> ImportError
    assert cli.main(['bench', '--compare', 'mujoco']) == 2
    err = capsys.readouterr().err
    assert '"mujoco" is not installed' in err and 'make bench-mujoco' in err


@pytest.mark.parametrize('worst, status', [(1e-13, 0), (1e-6, 1), (float('nan'), 1)])
def test_compare_exits_1_when_the_models_disagree(worst, status, monkeypatch, capsys):
    from mech_balance.bench import mujoco as bench_mujoco, mujoco_spatial
    monkeypatch.setattr(bench_mujoco, 'import_mujoco', lambda: None)
    result = {'agreement_imposed': {'shaking force': 1e-15},
              'agreement_own': {'shaking force': worst}}
    monkeypatch.setattr(bench_mujoco, 'run', lambda *a, **k: (result, [result], [], 'x'))
    monkeypatch.setattr(bench_mujoco, 'format_report', lambda *a, **k: 'report')
    monkeypatch.setattr(mujoco_spatial, 'run', lambda *a, **k: [])
    monkeypatch.setattr(mujoco_spatial, 'format_report', lambda *a, **k: '')
    assert cli.main(['bench', '--compare', 'mujoco']) == status
    assert ('the models disagree' in capsys.readouterr().err) == bool(status)


@pytest.mark.parametrize('report, status', [('growth -> PASS', 0), ('growth -> FAIL', 3)])
def test_compare_exits_non_zero_on_a_failed_target(report, status, monkeypatch, capsys):
    from mech_balance.bench import mujoco as bench_mujoco, mujoco_spatial
    monkeypatch.setattr(bench_mujoco, 'import_mujoco', lambda: None)
    result = {'agreement_imposed': {'shaking force': 1e-15},
              'agreement_own': {'shaking force': 1e-15}}
    monkeypatch.setattr(bench_mujoco, 'run', lambda *a, **k: (result, [result], [], 'x'))
    monkeypatch.setattr(bench_mujoco, 'format_report', lambda *a, **k: report)
    monkeypatch.setattr(mujoco_spatial, 'run', lambda *a, **k: [])
    monkeypatch.setattr(mujoco_spatial, 'format_report', lambda *a, **k: '')
    assert cli.main(['bench', '--compare', 'mujoco']) == status
    assert ('target(s) FAILED:\n  growth -> FAIL' in capsys.readouterr().err) == bool(status)


def test_interleaved_rounds_time_every_function_in_each_round():
    from mech_balance.bench import mujoco as bench_mujoco
    calls = []
    fns = [(lambda: calls.append('a'), 10), (lambda: calls.append('b'), 5)]
    rounds = bench_mujoco.interleaved_rounds(fns, rounds=5, warmup=1)
    assert [len(r) for r in rounds] == [5, 5]
    # warm-up, then per round: a (1 warm + 2 timed), b (1 warm + 1 timed), alternating
    assert calls[:2] == ['a', 'b']
    assert calls[2:] == (['a'] * 3 + ['b'] * 2) * 5
    assert bench_mujoco.spread([1.0, 2.0, 3.0]) == 1.0


def test_growth_exponent_prints_its_rounds():
    from mech_balance.bench import mujoco as bench_mujoco
    keys = ('ours_full', 'ours_dyn', 'mj_full', 'mj_inverse', 'mj_dyn')
    quantities = ('driving torque', 'shaking force', 'shaking moment')

    def result(links, us):
        rounds = [us * f for f in (0.9, 1.0, 1.0, 1.1, 1.0)]
        return {'scene': f'dyad_chain_{links}', 'links': links, 'joints': links + 1,
                'loops': 1, 'samples': 24, 'repeats': (5, 5),
                'agreement_imposed': dict.fromkeys(quantities, 1e-15),
                'agreement_own': dict.fromkeys(quantities, 1e-15), 'cut_forces': 1e-15,
                'positions': 0.0, 'mujoco_residual': 0.0, 'mujoco_iterations': 1.0,
                'ours_residual': 0.0, 'ours_cond': 1.0, 'ours_iterations': 1.0,
                'us': dict.fromkeys(keys, us),
                'us_rounds': dict.fromkeys(keys, rounds)}
    small, large = result(3, 1.0), result(39, 9.0)
    text = bench_mujoco.format_report(small, [small, large], 'test')
    assert 'growth exponent 4 -> 40 links (cost ~ links^e): mech_balance full 0.95' in text
    assert 'median of 5 round medians' in text and 'its 5 rounds 0.95 to 0.95' in text
    assert 'timings spread up to 20 %' in text


def _spatial_result(name, driving_series):
    """Return a :func:`mujoco_spatial.compare` result of made-up figures (no MuJoCo run)."""
    quantities = ('joint motion', 'driving torque', 'shaking force', 'shaking moment')
    return {'scene': name, 'links': 3, 'joints': 4, 'cuts': ('C',), 'idle': ('coupler',),
            'nv': 7, 'samples': 24, 'repeats': (2, 1), 'driving_series': driving_series,
            'agreement_imposed': dict.fromkeys(quantities, 1e-14),
            'agreement_own': dict.fromkeys(quantities, 2e-14),
            'inertia_error': 0.0, 'spin_residual': 1e-16, 'mujoco_residual': 1e-15,
            'mujoco_iterations': 1.0, 'us': dict.fromkeys(
                ('ours_full', 'ours_dyn', 'mj_full', 'mj_inverse', 'mj_dyn'), 1.0)}


def test_spatial_report_labels_the_effort_by_the_inputs_kind():
    """A prismatic input's effort is printed as the driving force, a revolute's as the torque."""
    from mech_balance.bench import mujoco_spatial
    from mech_balance.core.rig import rig_for
    for name, effort, other in (('pssr_skew', 'driving force', 'driving torque'),
                                ('rssr_skew', 'driving torque', 'driving force')):
        series = rig_for(scene.load(name)).driving_series
        assert mujoco_spatial.effort_label(series) == effort
        text = mujoco_spatial.format_report([_spatial_result(name, series)], 1e-9)
        rows = [x.split()[:2] for x in text.splitlines() if x.startswith('  driving ')]
        assert rows == [effort.split()], text
        assert f'of the peak {effort.split()[1]};' in text and other not in text


# ----------------------------------------------------------------------------- with MuJoCo


@pytest.fixture(scope='module')
def bench_mujoco():
    pytest.importorskip('mujoco', reason='MuJoCo is not installed (optional, pinned in '
                                         'requirements-test.txt, which `make test` installs)')
    from mech_balance.bench import mujoco as bench_mujoco
    return bench_mujoco


def _rigs(name_or_loops, bench_mujoco):
    sc = chain.dyad_chain(name_or_loops) if isinstance(name_or_loops, int) else \
        scene.load(name_or_loops)
    rig = analysis.Rig(sc.with_outputs(scene.OUTPUTS))
    return rig, bench_mujoco.MujocoRig(rig)


@pytest.mark.parametrize('which', ['hoeken', 4, 19])
def test_imposed_motion_agrees_with_mujoco(which, bench_mujoco):
    rig, mjr = _rigs(which, bench_mujoco)
    psi = cycle_angles(72, rig.scene.assembly_crank_angle_rad) + 0.01
    st, w = rig.evaluate(psi, speed=1.7, accel=0.9)
    tau, fsh, nsh, cut = mjr.dynamics(st.q, st.qd, st.qdd)
    assert _relative(w.driving_torque, tau) < AGREEMENT
    assert _relative(w.shaking_force, fsh) < AGREEMENT
    assert _relative(w.shaking_moment, nsh) < AGREEMENT
    ours_cut = np.array([w.reaction_force[c.name] for c in rig.linkage.cuts])
    assert _relative(ours_cut, cut) < AGREEMENT


@pytest.mark.parametrize('which', ['hoeken', 'carpet_scraper', 9])
def test_mujoco_own_kinematics_agrees(which, bench_mujoco):
    rig, mjr = _rigs(which, bench_mujoco)
    sc = rig.scene
    psi = cycle_angles(90, sc.assembly_crank_angle_rad)
    st, w = rig.evaluate(psi)
    tau, fsh, nsh, q, res, iters = mjr.full(psi, sc.crank_speed_rad_s,
                                            sc.crank_acceleration_rad_s2, st.q[:, 0])
    assert np.max(res) <= kinematics.NEWTON_TOL and np.max(iters) <= 3
    assert_allclose(q, st.q, rtol=0, atol=1e-12)
    assert _relative(w.driving_torque, tau) < AGREEMENT
    assert _relative(w.shaking_force, fsh) < AGREEMENT
    assert _relative(w.shaking_moment, nsh) < AGREEMENT


def test_mj_inverse_soft_force_vanishes_for_a_rigid_motion(bench_mujoco):
    """The documented finding: for exact loop kinematics mj_inverse's constraint force is ~0."""
    import mujoco
    rig, mjr = _rigs('hoeken', bench_mujoco)
    st, w = rig.evaluate(cycle_angles(12))
    m, d = mjr.model, mjr.data
    lam = np.array([w.reaction_force[c.name] for c in rig.linkage.cuts])
    for i in range(12):
        d.qpos[mjr.dof], d.qvel[mjr.dof], d.qacc[mjr.dof] = st.q[:, i], st.qd[:, i], st.qdd[:, i]
        mujoco.mj_inverse(m, d)
        assert np.max(np.abs(d.efc_force)) < 1e-6 * np.max(np.abs(lam))
        # so the passive joints appear to need torque: the loop forces are missing there
        assert np.max(np.abs(d.qfrc_inverse[mjr.passive])) > 1e-3 * np.max(np.abs(
            w.driving_torque))


def test_mujoco_model_rejects_prismatic_joints(bench_mujoco):
    rig = analysis.Rig(scene.load('slider_crank'))
    with pytest.raises(ValueError, match='revolute joints only'):
        bench_mujoco.MujocoRig(rig)


def test_compare_report_passes(bench_mujoco):
    """One small run of the whole comparison: agreement PASS printed (timings not checked)."""
    hoeken = bench_mujoco.compare(scene.load('hoeken'), samples=24, repeat=2)
    chains = [bench_mujoco.compare(chain.dyad_chain(n), samples=24, repeat=2) for n in (1, 3)]
    text = bench_mujoco.format_report(hoeken, chains, 'test')
    assert 'PASS (worst' in text and 'FAIL (worst' not in text
    line = next(x for x in text.splitlines() if 'rigs (both motions' in x)
    assert line.endswith('-> PASS'), line
    assert max(hoeken['agreement_own'].values()) < AGREEMENT


# ----------------------------------------------------------------------------- spatial built-ins

SPATIAL = ('rggr', 'rggr_spatial', 'rssr_skew', 'rssp_slider', 'spatial_two_loop', 'pssr_skew')


@pytest.fixture(scope='module')
def mujoco_spatial(bench_mujoco):
    from mech_balance.bench import mujoco_spatial
    return mujoco_spatial


def _spatial(name, mujoco_spatial, scene_=None):
    from mech_balance.core.rig import rig_for
    sc = (scene.load(name) if scene_ is None else scene_).with_outputs(scene.OUTPUTS)
    rig = rig_for(sc)
    return rig, mujoco_spatial.SpatialMujocoRig(rig)


def _spatial_worst(rig, w, state, res, mujoco_spatial):
    """Return the worst relative difference of MuJoCo's results (torque, wrench, reactions)."""
    rel = mujoco_spatial.relative_difference
    forces, moments = mujoco_spatial.reaction_differences(w.reactions, res['reactions'])
    return max(rel(w.driving_torque, res['driving_torque']), rel(w.force_N, res['force']),
               rel(w.moment_Nm, res['moment']), forces, moments)


def test_spatial_builtins_are_compared():
    """Compare every spatial built-in of the registry (none left out)."""
    from mech_balance.schema import registry
    spatial = registry.KINDS['spatial']
    names = {n for n in scene.builtin_scenes() if registry.kind_of(scene.load(n)) is spatial}
    assert names == set(SPATIAL)


@pytest.mark.parametrize('name', SPATIAL)
def test_spatial_imposed_motion_agrees_with_mujoco(name, mujoco_spatial):
    rig, mjr = _spatial(name, mujoco_spatial)
    psi = cycle_angles(72, rig.scene.assembly_crank_angle_rad) + 0.01
    st, w = rig.evaluate(psi, speed=1.7, accel=0.9)
    res = mjr.dynamics(st)
    rel = mujoco_spatial.relative_difference
    # MuJoCo's forward kinematics of the imposed joints reproduces the package's bodies
    length = rig.linkage.length_scale
    assert np.max(np.abs(res['origin'] - st.frames.origin[:, 1:])) < 1e-12 * length
    assert np.max(np.abs(res['rot'] - st.frames.rot[:, 1:])) < 1e-12
    assert rel(st.twist[:, 1:], res['twist']) < 1e-12
    assert rel(st.accel[:, 1:], res['accel']) < 1e-12
    assert rig.reactions_unique
    assert _spatial_worst(rig, w, st, res, mujoco_spatial) < AGREEMENT
    # the spin equations (zero inertia about the S-S line) hold without a multiplier
    assert np.max(res['spin_residual']) < AGREEMENT * np.max(np.abs(w.driving_torque))


@pytest.mark.parametrize('name', SPATIAL)
def test_spatial_mujoco_own_kinematics_agrees(name, mujoco_spatial):
    rig, mjr = _spatial(name, mujoco_spatial)
    sc = rig.scene
    lk = rig.linkage
    speed, accel = sc.crank_speed_rad_s, 25.0
    psi = cycle_angles(90, sc.assembly_crank_angle_rad)
    st, w = rig.evaluate(psi, speed=speed, accel=accel)
    qpos = mjr.to_mujoco(st)[0]
    tau, fsh, nsh, react, q, res, iters = mjr.full(psi, speed, accel, qpos[0])
    assert np.max(res) <= mujoco_spatial.NEWTON_TOL and np.max(iters) <= 3
    q_tree, sph = mjr.tree_coordinates(q)
    assert_allclose(q_tree[:, lk.scalar_dofs], st.q[:, lk.scalar_dofs], rtol=0, atol=1e-12)
    assert_allclose(sph, st.sph, rtol=0, atol=1e-12)     # the same spin convention
    rel = mujoco_spatial.relative_difference
    assert rel(w.driving_torque, tau) < AGREEMENT
    assert rel(w.force_N, fsh) < AGREEMENT
    assert rel(w.moment_Nm, nsh) < AGREEMENT
    assert max(mujoco_spatial.reaction_differences(w.reactions, react)) < AGREEMENT


def test_spatial_idle_rod_has_exactly_zero_moment_in_mujoco(mujoco_spatial):
    """The coupler's placeholder moment is removed after compiling; MuJoCo's warning caught."""
    rig, mjr = _spatial('rssr_skew', mujoco_spatial)
    b = mjr.model.body('coupler').id
    assert np.min(mjr.model.body_inertia[b]) == 0.0
    assert mjr.inertia_error < 1e-13
    assert any('singular' in w for w in mjr.warnings)


@pytest.mark.parametrize('name, link, change', [
    ('rssr_skew', 'rocker', lambda lk: {'mass_kg': lk.mass_kg * (1 + 1e-6)}),
    ('rssr_skew', 'crank', lambda lk: {
        'com_m': (lk.com_m[0], lk.com_m[1] + 1e-7, lk.com_m[2])}),
    ('spatial_two_loop', 'rocker2', lambda lk: {'inertia_com_kg_m2': (
        lk.inertia_com_kg_m2[:4] + (lk.inertia_com_kg_m2[4] + 1e-9,)
        + lk.inertia_com_kg_m2[5:])}),
    ('rssp_slider', 'slider', lambda lk: {'mass_kg': lk.mass_kg * (1 - 1e-6)}),
])
def test_spatial_check_fails_for_a_perturbed_mass_property(name, link, change,
                                                           mujoco_spatial):
    """Build MuJoCo from a slightly different design: it disagrees, so the check can fail."""
    from dataclasses import replace
    rig, _ = _spatial(name, mujoco_spatial)
    sc = rig.scene
    links = tuple(replace(lk, **change(lk)) if lk.name == link else lk for lk in sc.links)
    _, mjr_bad = _spatial(name, mujoco_spatial, replace(sc, links=links))
    st, w = rig.evaluate(cycle_angles(36, sc.assembly_crank_angle_rad))
    res = mjr_bad.dynamics(st)
    assert _spatial_worst(rig, w, st, res, mujoco_spatial) > 10 * AGREEMENT


def test_spatial_model_refuses_a_non_spherical_cut(mujoco_spatial):
    """An RSUR (the tree cuts the universal joint C) is refused with the joint named."""
    from mech_balance.core.rig import rig_for
    from mech_balance.schema.spatial import spatial_from_dict, spatial_to_dict
    d = spatial_to_dict(scene.load('rssr_skew'))
    d['name'] = 'rsur'
    # the cross axis fixed in the rocker, normal to the coupler's y axis and to the rocker's
    # line at the stated poses (the loader refuses an axis_b the poses contradict)
    from scipy.spatial.transform import Rotation
    poses = d['assembly']['poses']
    rot_c, rot_r = (Rotation.from_euler('xyz', poses[k]['rpy_deg'], degrees=True).as_matrix()
                    for k in ('coupler', 'rocker'))
    cross = np.cross(rot_c[:, 1], rot_r[:, 0])
    axis_b = rot_r.T @ (cross / np.linalg.norm(cross))
    d['joints']['C'] = {'type': 'universal', 'a': 'coupler.C', 'b': 'rocker.C',
                        'axis': [0.0, 1.0, 0.0], 'axis_b': [float(x) for x in axis_b]}
    d['links']['coupler']['inertia_com_kg_m2'] = [1e-6, 6.75e-4, 6.75e-4, 0.0, 0.0, 0.0]
    rig = rig_for(spatial_from_dict(d))
    with pytest.raises(ValueError, match=r'spherical cut joints only .* cuts C \(universal\)'):
        mujoco_spatial.SpatialMujocoRig(rig)


def test_spatial_compare_report_passes(mujoco_spatial, bench_mujoco):
    """One small run of the spatial comparison: PASS printed per built-in (timings unchecked)."""
    results = mujoco_spatial.run(bench_mujoco._interleaved_medians, 24, 2, 2, progress=None)
    text = mujoco_spatial.format_report(results, AGREEMENT)
    assert text.count('-> PASS (worst') == len(SPATIAL) and 'FAIL' not in text
    assert text.splitlines()[-1].endswith('-> PASS (limit 1e-09)')
    for r in results:
        assert set(r['agreement_imposed']) == set(mujoco_spatial.QUANTITIES)
        assert mujoco_spatial.worst(r) < AGREEMENT


def _rscr():
    """Return an RSCR: rssr_skew with C cylindrical (normal to BC), listed before B."""
    from mech_balance.core.rig import rig_for
    from mech_balance.schema.spatial import spatial_from_dict, spatial_to_dict
    base = rig_for(scene.load('rssr_skew')).linkage
    fr = base.frames(base.q0, base.sph0)
    ic, ir = base.body_names.index('coupler'), base.body_names.index('rocker')
    y_rocker = fr.rot[0, ir].T @ fr.rot[0, ic] @ np.array([0.0, 1.0, 0.0])
    d = spatial_to_dict(scene.load('rssr_skew'))
    d['name'] = 'rscr'
    j = d['joints']
    d['joints'] = {'A': j['A'], 'C': {'type': 'cylindrical', 'a': 'coupler.C', 'b': 'rocker.C',
                                      'axis': [0.0, 1.0, 0.0],
                                      'axis_b': [float(x) for x in y_rocker]},
                   'B': j['B'], 'D': j['D']}
    d['links']['coupler']['inertia_com_kg_m2'] = [2e-6, 6.75e-4, 6.75e-4, 1e-6, 0.0, 0.0]
    return spatial_from_dict(d)


def test_spatial_cylindrical_flipped_tree_joint_agrees(mujoco_spatial):
    """A cylindrical tree joint whose child is its link a (hinge + slide), no idle spin."""
    rig, mjr = _spatial(None, mujoco_spatial, _rscr())
    lk = rig.linkage
    last = lk.tree[-1]
    assert (last.name, last.joint_type, last.flipped) == ('C', 'cylindrical', True)
    assert [rig.scene.joints[i].name for i in lk.cut_joints] == ['B'] and not mjr.spins
    psi = cycle_angles(72) + 0.01
    st, w = rig.evaluate(psi, speed=1.7, accel=0.9)
    slide = st.q[:, lk.tree[-1].dofs[1]]
    assert np.ptp(slide) > 1e-3                   # the slide moves: the two C points part
    res = mjr.dynamics(st)
    assert rig.reactions_unique
    assert _spatial_worst(rig, w, st, res, mujoco_spatial) < AGREEMENT
    tau, fsh, nsh, react, q, r, iters = mjr.full(psi, 1.7, 0.9, mjr.to_mujoco(st)[0][0])
    assert max(mujoco_spatial.relative_difference(w.driving_torque, tau),
               *mujoco_spatial.reaction_differences(w.reactions, react)) < AGREEMENT
