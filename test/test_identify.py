"""
Identification against a synthetic real rig (test/synthetic_rig.py), bag I/O and the verb.

The rig is made here from the TRUE perturbed scene by the core's forward evaluation; the
code under test sees only the quantized encoder, the noisy biased wrench and the nominal
scene.
"""

from dataclasses import replace
import json
import math
import os
import sys

from mech_balance import atomic
from mech_balance import schema as scene_mod
from mech_balance.analysis import identify, linear_maps
from mech_balance.balancing import defaults, redistribution
from mech_balance.cli import main as cli
from mech_balance.core.planar import rig as planar_rig
from mech_balance.ros import bags
import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import synthetic_rig as sr  # noqa: E402, I100

DURATION_S = 20.0
SE_BOUND = 3.0
"""Every identifiable combination and the bias within this many standard errors."""
RMS_REL_TOL = 0.10
"""Residual RMS after calibration within this fraction of the injected noise RMS."""
Z_REL_TOL = 0.05
"""The calibrated design on the true rig within this fraction of the true optimum z."""
GRAVITY = (0.0, -9.81)
CASES = {
    # name: (scene, mean crank speed rad/s (None: the scene's), gravity, effort, seed)
    'hoeken': ('hoeken', 2.0 * math.pi, None, False, 11),
    'hoeken_gravity': ('hoeken', 2.0 * math.pi, GRAVITY, False, 12),
    'slider_crank_effort': ('slider_crank', None, None, True, 13),
}


def _nominal(name, gravity):
    sc = scene_mod.load(name)
    return sc if gravity is None else replace(sc, gravity_m_s2=gravity)


@pytest.fixture(scope='module')
def rigs():
    """Return {case: (nominal, true, data, result)} for every case (20 s at 1 kHz)."""
    out = {}
    for case, (name, w0, gravity, effort, seed) in CASES.items():
        nominal = _nominal(name, gravity)
        true = sr.perturbed(nominal, seed, gravity=gravity)
        data = sr.record(true, DURATION_S, w0 or nominal.crank_speed_rad_s, seed, effort)
        t = (data.t_ns - data.t_ns[0]) * 1e-9
        result = identify.identify(nominal, t, data.position_rad, t, data.wrench,
                                   effort=data.effort_Nm)
        out[case] = (nominal, true, data, result)
    return out


def _z_on(true, theta, weights=defaults.DEFAULT_WEIGHTS):
    """Return z = w1 f~ + w2 n~ of parameters ``theta`` (SI) on the true rig's geometry."""
    units = planar_rig.objective_units(true)
    maps = linear_maps.linear_maps(true, units=units)
    m, ln = units.mass_kg, units.length_m
    scale = np.tile([m, m * ln, m * ln, m * ln * ln], len(true.links))
    return float(np.dot(weights, maps.terms(np.asarray(theta) / scale)[:2]))


# ---------------------------------------------------------------------------- physics


@pytest.mark.parametrize('case', list(CASES))
def test_regressor_reproduces_the_true_wrench(rigs, case):
    """Y(psi, psid, psidd) theta_true is the rig's wrench on its frame, weight included."""
    _, true, data, _ = rigs[case]
    reg = identify.regressor(true, data.psi, data.speed, data.accel,
                             torque=data.effort_Nm is not None)
    w, tau = reg.predict(data.theta_true)
    scale = np.max(np.abs(data.true_wrench), axis=0)
    np.testing.assert_allclose(w / scale, data.true_wrench / scale, atol=1e-12)
    if tau is not None:
        truth = data.effort_Nm - data.bias[3]
        assert np.sqrt(np.mean((tau - truth) ** 2)) < 1.2 * data.noise_std[3]


def test_crank_motion_accuracy(rigs):
    """The smoothed encoder matches the true crank state to its predicted accuracy."""
    for case in ('hoeken', 'slider_crank_effort'):
        _, _, data, result = rigs[case]
        m = result.motion
        t = (data.t_ns - data.t_ns[0]) * 1e-9
        psi, speed, accel = (np.interp(m.t_s, t, v)
                             for v in (data.psi, data.speed, data.accel))
        psi_err = m.psi_rad - psi
        psi_err -= 2.0 * math.pi * np.round(np.mean(psi_err) / (2.0 * math.pi))
        std = m.predicted_std
        ripple = sr.RIPPLE * m.mean_speed_rad_s ** 2 * sr.RIPPLE_TURNS
        assert np.sqrt(np.mean(psi_err ** 2)) < 2.0 * std['angle_rad']
        assert np.sqrt(np.mean((m.speed_rad_s - speed) ** 2)) < 2.0 * std['speed_rad_s']
        assert np.sqrt(np.mean((m.accel_rad_s2 - accel) ** 2)) < \
            2.0 * std['accel_rad_s2'] + abs(m.gain_error['accel_1x']) * ripple
        assert m.quantization_rad == pytest.approx(2.0 * math.pi / sr.COUNTS_PER_TURN,
                                                   rel=1e-9)


# ---------------------------------------------------------------------------- acceptance


@pytest.mark.parametrize('case', list(CASES))
def test_identifiable_combinations_within_three_standard_errors(rigs, case):
    _, _, data, result = rigs[case]
    assert 0 < result.rank < len(result.names)
    assert len(result.combinations) == result.rank
    for c in result.combinations:
        err = c.estimate - c.value(data.theta_true)
        assert abs(err) <= SE_BOUND * c.std_error, (c.text, err, c.std_error)
        # the data moved the estimate: the scene's value is off by more than the noise
    moved = [abs(c.scene_value - c.value(data.theta_true)) > SE_BOUND * c.std_error
             for c in result.combinations]
    assert sum(moved) >= result.rank // 2


@pytest.mark.parametrize('case', list(CASES))
def test_bias_within_three_standard_errors(rigs, case):
    _, _, data, result = rigs[case]
    target = result.bias_target(data.bias, data.theta_true)
    assert np.all(np.abs(result.bias - target) <= SE_BOUND * result.bias_std_error)
    if CASES[case][2] is None:
        # no gravity: the bias is identifiable on its own and estimates the true bias
        assert result.bias_identifiable.all()
        np.testing.assert_array_equal(target, data.bias)
    else:
        # the weight of the links that do not translate is constant: confounded with the
        # bias in f_y and n_z (gravity along -y), not in f_x
        assert list(result.bias_identifiable) == [True, False, False]


@pytest.mark.parametrize('case', list(CASES))
def test_residual_after_calibration_is_the_noise(rigs, case):
    _, _, data, result = rigs[case]
    ratio = result.rms_after / data.noise_std
    assert np.all(np.abs(ratio - 1.0) <= RMS_REL_TOL), ratio
    # the perturbation is visible: the scene's model is worse everywhere, much worse somewhere
    assert np.all(result.rms_before > result.rms_after)
    assert np.max(result.rms_before / result.rms_after) > 3.0


@pytest.mark.parametrize('case', ['hoeken', 'hoeken_gravity', 'slider_crank_effort'])
def test_calibrated_design_balances_the_true_rig(rigs, case):
    """The optimum of the calibrated scene, built on the true rig, is near its own optimum."""
    nominal, true, data, result = rigs[case]
    z_true = redistribution.optimize(true).objective['z']
    z_applied = {}
    for label, sc in (('calibrated', result.calibrated_scene()), ('nominal', nominal)):
        design = redistribution.optimize(sc).balanced_scene
        change = sr.theta_of(design) - sr.theta_of(sc)     # what is built onto the rig
        z_applied[label] = _z_on(true, data.theta_true + change)
    assert abs(z_applied['calibrated'] - z_true) <= Z_REL_TOL * z_true, (z_applied, z_true)
    # the calibration is what brings the design there: the nominal scene's misses by more
    assert abs(z_applied['nominal'] - z_true) > abs(z_applied['calibrated'] - z_true)


def test_calibrated_scene_is_physical_and_loads(rigs, tmp_path):
    _, _, data, result = rigs['hoeken_gravity']
    assert result.realizable
    path = tmp_path / 'cal.yaml'
    atomic.write_text_atomic(path, identify.calibrated_yaml(result))
    loaded = scene_mod.load(str(path))
    np.testing.assert_allclose(sr.theta_of(loaded), result.theta, rtol=1e-12, atol=1e-15)
    assert loaded.gravity_m_s2 == GRAVITY
    assert [p.name for p in tmp_path.iterdir()] == ['cal.yaml']   # no temporary left


# ---------------------------------------------------------------------------- recordings


@pytest.fixture(scope='module')
def recordings(rigs, tmp_path_factory):
    """Write the slider-crank case (with effort) as MCAP, sqlite3 and CSV."""
    _, _, data, _ = rigs['slider_crank_effort']
    root = tmp_path_factory.mktemp('bags')
    paths = {}
    for storage in bags.STORAGES:
        paths[storage] = bags.write_bag(root / storage, storage, data.t_ns, data.position_rad,
                                        data.wrench, data.effort_Nm, joint='O',
                                        extra_joints=('A', 'B'))
    t_s = (data.t_ns - data.t_ns[0]) * 1e-9
    paths['csv'] = bags.write_csv(root / 'rig.csv', t_s, data.position_rad, data.wrench,
                                  data.effort_Nm)
    return root, paths


def test_storages_and_csv_read_back_identically(rigs, recordings):
    _, _, data, _ = rigs['slider_crank_effort']
    _, paths = recordings
    recs = {k: bags.read(p, default_joint='O') for k, p in paths.items()}
    ref = recs['mcap']
    np.testing.assert_array_equal(ref.position_rad, data.position_rad)
    np.testing.assert_array_equal(ref.planar_wrench, data.wrench)
    np.testing.assert_array_equal(ref.effort_Nm, data.effort_Nm)
    assert ref.t0_ns == data.t_ns[0] and ref.joint == 'O' and ref.frame_id == 'rig'
    for key in ('sqlite3', 'csv'):
        rec = recs[key]
        for field in ('encoder_t_s', 'position_rad', 'effort_Nm', 'wrench_t_s', 'wrench'):
            np.testing.assert_array_equal(getattr(rec, field), getattr(ref, field),
                                          err_msg=f'{key}: {field}')
    results = [identify.identify(scene_mod.load('slider_crank'), r.encoder_t_s,
                                 r.position_rad, r.wrench_t_s, r.planar_wrench,
                                 effort=r.effort_Nm) for r in recs.values()]
    for r in results[1:]:
        np.testing.assert_array_equal(r.theta, results[0].theta)
        np.testing.assert_array_equal(r.bias, results[0].bias)


def test_identify_verb(recordings, tmp_path, capsys):
    _, paths = recordings
    out = tmp_path / 'slider_calibrated.yaml'
    rc = cli.main(['identify', '--scene', 'slider_crank', '--bag', str(paths['sqlite3']),
                   '--output', str(out), '--json'])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    report = json.loads(captured.out)
    assert report['rank'] == len(report['combinations']) == 7
    assert set(report['bias']) == {'force_x', 'force_y', 'moment_z', 'torque'}
    assert report['output'] == str(out)
    assert 'read 20000 of 40000 messages' in captured.err
    loaded = scene_mod.load(str(out))
    np.testing.assert_allclose(sr.theta_of(loaded), report['theta'], rtol=1e-12)
    rc = cli.main(['identify', '--scene', 'slider_crank', '--bag', str(paths['csv'])])
    text = capsys.readouterr().out
    assert rc == 0
    for words in ('rank 7 of 12', 'condition number', 'identifiable combinations',
                  'sensor bias', 'residual RMS', 'before', 'after'):
        assert words in text


# ---------------------------------------------------------------------------- bad input


def _error(capsys, argv):
    rc = cli.main(argv)
    err = capsys.readouterr().err
    assert rc == cli.EXIT_USAGE, err
    return err


def test_bad_recordings_name_the_option(recordings, tmp_path, capsys, rigs):
    _, paths = recordings
    bag = str(paths['mcap'])
    base = ['identify', '--scene', 'slider_crank', '--bag']
    err = _error(capsys, base + [bag, '--wrench-topic', '/nope'])
    assert '--wrench-topic' in err and '/nope' in err and '/measured_wrench' in err
    err = _error(capsys, base + [bag, '--encoder-topic', '/measured_wrench'])
    assert '--encoder-topic' in err and 'sensor_msgs/msg/JointState' in err
    err = _error(capsys, base + [bag, '--joint', 'crank_joint'])
    assert '--joint' in err and "'crank_joint'" in err and 'O, A, B' in err
    err = _error(capsys, base + [str(tmp_path / 'missing')])
    assert '--bag' in err and 'does not exist' in err
    err = _error(capsys, base + [bag, '--output', str(tmp_path / 'no_dir' / 'x.yaml')])
    assert '--output' in err
    # too short: half a second of the slider crank (2.5 turns, less than one usable)
    _, _, data, _ = rigs['slider_crank_effort']
    short = bags.write_bag(tmp_path / 'short', 'mcap', data.t_ns[:200],
                           data.position_rad[:200], data.wrench[:200], joint='O')
    err = _error(capsys, base + [str(short)])
    assert '--bag' in err and 'revolutions' in err and 'expected at least 1' in err
    # a JointState with several joints and no --joint naming the scene's crank
    err = _error(capsys, ['identify', '--scene', 'hoeken', '--bag', bag])
    assert '--joint' in err and 'O, A, B' in err


def test_flipped_sensor_gives_the_constrained_least_squares(rigs, tmp_path, capsys):
    """
    A sensor mounted upside down (wrench negated): no consistent set has its combinations.

    The constrained least squares is found, its residual growth and active constraints
    reported, and it lies far outside the confidence region (the data contradict physics);
    the checks refuse it (the sensor's frame, the fit against the noise): nothing written.
    """
    nominal, _, data, _ = rigs['hoeken']
    t_s = (data.t_ns - data.t_ns[0]) * 1e-9
    path = bags.write_csv(tmp_path / 'flipped.csv', t_s, data.position_rad, -data.wrench)
    result = identify.identify(nominal, t_s, data.position_rad, t_s, -data.wrench)
    cons = result.consistency
    assert result.realizable and cons.stage == 'least squares'
    assert not cons.within_confidence and cons.max_shift_se > identify.CONFIDENCE_SE
    assert cons.residual_growth > 0.1 and cons.active
    # the residual growth reported is the weighted residual's (recomputed from the regressor)
    m = result.motion
    inside = (t_s >= m.t_s[0]) & (t_s <= m.t_s[-1])
    reg = identify.regressor(nominal, *m.at(t_s[inside]))
    meas = -data.wrench[inside]
    chi2 = []
    for theta in (result.theta_ls, result.theta):
        r = meas - reg.wrench @ theta
        r -= r.mean(axis=0)
        chi2.append(float(np.sum(r ** 2 / result.noise_std ** 2)))
    growth = math.sqrt(chi2[1] / chi2[0]) - 1.0
    assert growth == pytest.approx(cons.residual_growth, rel=1e-6)
    # and the constrained least squares is no worse than the scene itself
    r = meas - reg.wrench @ result.theta_scene
    r -= r.mean(axis=0)
    assert chi2[1] <= float(np.sum(r ** 2 / result.noise_std ** 2))
    # the checks name the cause, and no calibrated scene is made of it
    assert [f.code for f in result.refusals] == ['sensor_frame', 'fit_residual']
    with pytest.raises(identify.IdentifyError, match=r"refused, .*model's negated"):
        result.calibrated_scene()
    _assert_consistent(replace(result, findings=[]).calibrated_scene())
    out = tmp_path / 'cal.yaml'
    rc = cli.main(['identify', '--scene', 'hoeken', '--bag', str(path), '--output', str(out)])
    captured = capsys.readouterr()
    assert rc == 2 and not out.exists()
    assert 'constrained least squares, residual grows by' in captured.out
    assert 'OUTSIDE' in captured.out and 'active: links.' in captured.out
    assert '--sensor-convention reaction' in captured.err


def _assert_consistent(scene):
    """Every link: m > 0 and m I_O >= |m c|^2 (planar pseudo-inertia >= 0)."""
    for lk in scene.links:
        assert lk.mass_kg > 0.0
        assert lk.inertia_com_kg_m2 >= 0.0
        h2 = lk.mass_kg ** 2 * (lk.com_m[0] ** 2 + lk.com_m[1] ** 2)
        assert lk.mass_kg * lk.inertia_origin_kg_m2 >= h2


def test_bad_arrays():
    sc = scene_mod.load('hoeken')
    t = np.arange(2000) * 1e-3
    pos = np.mod(2.0 * math.pi * t, 2.0 * math.pi)
    with pytest.raises(identify.IdentifyError, match='wrench: got shape'):
        identify.identify(sc, t, pos, t, np.zeros((2000, 2)))
    with pytest.raises(identify.IdentifyError,
                       match='encoder: sample 1 stamp .* is not after sample 0'):
        identify.identify(sc, t[::-1], pos, t, np.zeros((2000, 3)))
    with pytest.raises(identify.IdentifyError, match='recording: the crank turns'):
        identify.identify(sc, t, np.zeros(2000), t, np.zeros((2000, 3)))
    with pytest.raises(identify.IdentifyError, match='planar'):
        identify.identify(scene_mod.load('rggr'), t, pos, t, np.zeros((2000, 3)))


@pytest.mark.parametrize('case', list(CASES))
def test_consistent_set_is_the_closest_to_the_scene(rigs, case):
    """
    The exact stage against a second formulation (scipy's trust-constr on the nonlinear form).

    Among parameters with the identified combinations and m I_O >= |h|^2 per link, the
    calibrated ones are the closest to the scene in each link's scale.
    """
    from scipy.optimize import minimize
    nominal, _, _, result = rigs[case]
    assert result.consistency.stage == 'exact'
    scale = identify.parameter_scales(nominal)
    theta0 = result.theta_scene
    coeff = np.array([c.coefficients for c in result.combinations])
    est = np.array([c.estimate for c in result.combinations])
    size = np.abs(coeff) @ np.abs(theta0 + scale)
    # the combinations are reproduced to the solver's tolerance
    np.testing.assert_allclose(coeff @ result.theta, est, rtol=0, atol=1e-7 * size.max())
    _assert_consistent(result.calibrated_scene())

    def links(u):
        y = (theta0 + scale * u) / scale
        return y.reshape(-1, 4)

    cons = [{'type': 'eq', 'fun': lambda u: (coeff @ (theta0 + scale * u) - est) / size},
            {'type': 'ineq', 'fun': lambda u: np.array(
                [m * i - hx * hx - hy * hy for m, hx, hy, i in links(u)])},
            {'type': 'ineq', 'fun': lambda u: links(u)[:, 0] - identify.MIN_MASS_REL}]
    u_cal = (result.theta - theta0) / scale
    ref = minimize(lambda u: float(u @ u), u_cal * 0.5, jac=lambda u: 2.0 * u,
                   constraints=cons, method='trust-constr',
                   options={'gtol': 1e-12, 'xtol': 1e-14, 'maxiter': 3000})
    # only a feasible end point proves anything (SLSQP can stop, status 8, outside the cones)
    assert np.all(np.abs(cons[0]['fun'](ref.x)) <= 1e-7), 'the reference misses the combinations'
    assert all(np.all(c['fun'](ref.x) >= -1e-9) for c in cons[1:]), 'the reference is infeasible'
    assert float(u_cal @ u_cal) <= ref.fun * (1.0 + 1e-4) + 1e-12


def test_dropped_encoder_bursts_split_the_data_and_lose_only_the_gaps(rigs):
    """Every stretch between encoder gaps is fitted on its own; only the gaps are lost."""
    nominal, _, data, whole = rigs['hoeken']
    t = (data.t_ns - data.t_ns[0]) * 1e-9
    n = t.size
    keep = np.ones(n, dtype=bool)
    bursts = [(int(f * n), width) for f, width in ((0.2, 40), (0.5, 200), (0.8, 15))]
    for start, width in bursts:
        keep[start:start + width] = False              # dropped encoder messages
    short = int(0.9 * n)
    keep[short - 30:short] = False                     # a stretch of 8 samples between two
    keep[short + 8:short + 38] = False                 # gaps: shorter than any window
    result = identify.identify(nominal, t[keep], data.position_rad[keep], t, data.wrench)
    segs = result.segments
    assert len(segs) == 6 and sum(g.used for g in segs) == 5
    (skipped,) = [g for g in segs if not g.used]
    assert skipped.encoder_samples == 8 and 'shorter than' in skipped.reason
    assert skipped.reason in identify.format_report(result)
    assert [g['encoder_samples'] for g in result.to_dict()['encoder_segments']] == \
        [g.encoder_samples for g in segs]
    # lost: the wrench samples inside the gaps (and the skipped stretch) and, per stretch
    # used, the half window at either end that has no centred fit
    lost = n - result.samples
    gap_samples = int(np.sum(~keep)) + 8
    window = whole.motion.window
    assert gap_samples + 5 * (window - 1) - 5 <= lost <= gap_samples + 5 * window
    assert result.samples == sum(g.wrench_samples for g in segs)
    assert result.rank == whole.rank
    # the newest stretch alone (what ~/identify used before) has a fraction of the samples
    newest = identify.identify(nominal, t[short + 38:], data.position_rad[short + 38:], t,
                               data.wrench)
    assert newest.samples < 0.1 * result.samples
    assert [c.base for c in newest.combinations] == [c.base for c in result.combinations]
    for c, c_new in zip(result.combinations, newest.combinations):
        err = c.estimate - c.value(data.theta_true)
        assert abs(err) <= SE_BOUND * c.std_error, (c.text, err, c.std_error)
        assert c.std_error < 0.5 * c_new.std_error, c.text   # far better determined


def test_a_recording_without_gaps_is_one_stretch(rigs):
    _, _, _, result = rigs['hoeken']
    assert len(result.segments) == 1 and result.segments[0].used
    assert result.segments[0].wrench_samples == result.samples
    assert 'encoder gaps' not in identify.format_report(result)
