"""
Misconfigured and damaged recordings: each refused or corrected, with its cause (issue 32).

Every recording is made here from the synthetic rig (test/fault_rigs.py: Hoeken, inertias
perturbed by up to 20%, 4096 counts, 1 kHz, 1% sensor noise, 3 s at 0.75 rev/s) and written
as a real rig writes it, rosbag2 MCAP, rosbag2 sqlite3 and CSV; ``mech-balance identify
--output`` must refuse it (exit status 2, the output untouched, the cause named) or correct
it (exit 0, the correction reported, the calibrated scene's RMS shaking force and moment
within 1% of the true rig's, as for a good recording).
"""

import json
import math
import os
import sys

from mech_balance import schema as scene_mod
from mech_balance.analysis import identify
from mech_balance.cli import identify as cli_identify
from mech_balance.cli import main as cli
import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import fault_rigs as fr  # noqa: E402, I100
import synthetic_rig as sr  # noqa: E402, I100

STORAGES = ('mcap', 'sqlite3', 'csv')
RMS_REL_TOL = 0.01
OFFSET_TOL_S = 1e-3
"""The time offset found within this of the 50 ms injected."""


@pytest.fixture(scope='module')
def rig():
    """Return (clean streams, true RMS force, true RMS moment)."""
    _, true = fr.scenes()
    return (fr.clean(), *sr.true_rms(true))


def _identify(tmp_path, capsys, rec, *extra):
    """Return (exit status, stdout, stderr, the calibrated scene or None)."""
    out = tmp_path / 'cal.yaml'
    out.write_text('previous\n')
    rc = cli.main(['identify', '--scene', 'hoeken', '--bag', str(rec), '--output', str(out),
                   *extra])
    captured = capsys.readouterr()
    if rc != 0:
        assert out.read_text() == 'previous\n'      # untouched
        return rc, captured.out, captured.err, None
    return rc, captured.out, captured.err, scene_mod.load(str(out))


def _error(err):
    """Return the one error line of the verb's stderr (progress lines aside)."""
    lines = [ln for ln in err.splitlines() if ln.startswith('mech-balance identify: error:')]
    assert len(lines) == 1, err
    return lines[0]


def _within(cal, f_true, n_true):
    f_cal, n_cal = sr.true_rms(cal)
    assert f_cal == pytest.approx(f_true, rel=RMS_REL_TOL)
    assert n_cal == pytest.approx(n_true, rel=RMS_REL_TOL)


# ---------------------------------------------------------------------------- corrected


@pytest.mark.parametrize('storage', STORAGES)
@pytest.mark.parametrize('fault, code', [('degrees', 'encoder_unit'),
                                         ('late_50ms', 'time_offset'),
                                         ('stuck', 'encoder_stuck')])
def test_corrected_and_reported(rig, tmp_path, capsys, fault, code, storage):
    streams, f_true, n_true = rig
    rec = fr.write(tmp_path / 'rec', storage, fr.FAULTS[fault](streams))
    rc, out, err, cal = _identify(tmp_path, capsys, rec, '--json')
    assert rc == 0, err
    report = json.loads(out)
    found = {f['code']: f for f in report['findings']}
    assert found[code]['action'] == 'corrected'
    assert not report['refused']
    _within(cal, f_true, n_true)
    if code == 'time_offset':
        assert found[code]['values']['offset_s'] == pytest.approx(fr.LATE_NS * 1e-9,
                                                                  abs=OFFSET_TOL_S)
    if code == 'encoder_stuck':
        t0, t1 = fr.STUCK_S
        assert found[code]['values']['longest_s'] == pytest.approx(t1 - t0, abs=2e-3)
    if code == 'encoder_unit':
        assert found[code]['values']['modulus'] == pytest.approx(360.0, rel=1e-6)


def test_degrees_stated_rad_are_refused_by_the_fit(rig, tmp_path, capsys):
    """``--encoder-unit rad`` takes degrees as rad: the fit is then far above the noise."""
    rec = fr.write(tmp_path / 'rec', 'csv', fr.degrees(rig[0]))
    rc, _, err, _ = _identify(tmp_path, capsys, rec, '--encoder-unit', 'rad')
    assert rc == 2 and '[fit_residual]' in err and 'noise does not explain' in err


# ---------------------------------------------------------------------------- refused


@pytest.mark.parametrize('storage', STORAGES)
@pytest.mark.parametrize('fault, cause', [
    ('negated', ("[sensor_frame] the measured force is the model's negated",
                 '--sensor-convention reaction')),
    ('xy_swapped', ('[sensor_frame]', 'x and y swapped')),
    ('encoder_noise', ('[encoder_noise]', "the encoder's angle noise 0.0",
                       'smooths the motion away')),
    ('two_encoders', ('encoder samples alternate between two tracks 0.69',
                      'record one encoder')),
])
def test_refused_with_the_cause(rig, tmp_path, capsys, fault, cause, storage):
    rec = fr.write(tmp_path / 'rec', storage, fr.FAULTS[fault](rig[0]))
    rc, _, err, _ = _identify(tmp_path, capsys, rec)
    assert rc == 2
    assert all(c in _error(err) for c in cause), err


@pytest.mark.parametrize('storage', STORAGES)
def test_two_sensors_refused_or_selected(rig, tmp_path, capsys, storage):
    """Two sensors on one topic: their frame_ids (a bag) or their alternation (a CSV)."""
    streams, f_true, n_true = rig
    rec = fr.write(tmp_path / 'rec', storage, fr.two_sensors(streams))
    rc, _, err, _ = _identify(tmp_path, capsys, rec)
    assert rc == 2
    if storage == 'csv':
        assert 'wrench samples alternate between two tracks' in err
        return
    half = streams.w_ns.size // 2
    assert f"2 frame_ids: 'ft_a' ({half} messages), 'ft_b' ({half} messages)" in err
    assert '--wrench-frame-id' in err
    rc, _, err, cal = _identify(tmp_path, capsys, rec, '--wrench-frame-id', 'ft_a')
    assert rc == 0, err
    _within(cal, f_true, n_true)
    rc, _, err, _ = _identify(tmp_path, capsys, rec, '--wrench-frame-id', 'ft_c')
    assert rc == 2 and "--wrench-frame-id: got 'ft_c'" in err


@pytest.mark.parametrize('storage', STORAGES)
def test_zeroed_block_refused(tmp_path, capsys, storage):
    """One 4 KiB block of the storage zeroed: never read in silence."""
    rec = fr.write(tmp_path / 'rec', storage, fr.clean(8.0))
    fr.zero_block(rec)
    rc, _, err, _ = _identify(tmp_path, capsys, rec)
    assert rc == 2
    err = _error(err)
    if storage == 'mcap':
        assert "messages read, the bag's metadata counts 8000" in err
        assert 'ros2 bag reindex' in err
    elif storage == 'sqlite3':
        assert 'malformed' in err or "the bag's metadata counts 8000" in err
    else:
        assert 'line ' in err


def test_csv_row_with_a_stray_and_an_empty_field_refused(rig, tmp_path, capsys):
    rec = fr.write(tmp_path / 'rec', 'csv', rig[0])
    fr.stray_field(rec, line=1000)
    rc, _, err, _ = _identify(tmp_path, capsys, rec)
    assert rc == 2
    assert 'line 1001, column crank_position_rad' in err and "3.0', expected a number" in err


def test_csv_empty_field_refused_in_the_fast_path(rig, tmp_path, capsys):
    """An empty field alone (numpy's chunk parse would drop it) is named too."""
    rec = fr.write(tmp_path / 'rec', 'csv', rig[0])
    lines = rec.read_text().splitlines(keepends=True)
    fields = lines[20].split(',')
    fields[3] = ''
    lines[20] = ','.join(fields)
    rec.write_text(''.join(lines))
    rc, _, err, _ = _identify(tmp_path, capsys, rec)
    assert rc == 2 and "line 21, column force_y_N: got ''" in err


# ---------------------------------------------------------------------------- the checks


def test_noise_floor_is_the_white_noise_under_a_signal():
    rng = np.random.default_rng(3)
    t = np.arange(20000) * 1e-3
    signal = np.column_stack([10.0 * np.sin(2 * math.pi * 2.0 * t + k) for k in range(3)])
    noise = rng.normal(size=signal.shape) * [0.1, 0.01, 1.0]
    floor = identify.noise_floor(signal + noise)
    np.testing.assert_allclose(floor, np.std(noise, axis=0), rtol=0.03)
    np.testing.assert_allclose(identify.interleaved(signal + noise), 1.0, atol=0.05)


@pytest.mark.parametrize('angle_deg', [0.0, 30.0, 90.0, 180.0])
def test_frame_check_names_the_rotation(angle_deg):
    rng = np.random.default_rng(4)
    t = np.arange(3000) * 1e-3
    model = np.column_stack([np.cos(5 * t), 0.7 * np.sin(5 * t + 0.3), 0.2 * np.sin(10 * t)])
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    meas = model.copy()
    meas[:, :2] = model[:, :2] @ rot.T
    meas += rng.normal(size=meas.shape) * 0.01
    found = identify.frame_check(meas, model, np.full(3, 0.01), ('fx', 'fy', 'nz'))
    if angle_deg <= identify.FRAME_ANGLE_MAX_DEG:
        assert found is None
        return
    assert found.action == 'refused'
    assert found.values['force_rotation_deg'] == pytest.approx(angle_deg, abs=1.0) or \
        found.values['force_rotation_deg'] == pytest.approx(-angle_deg, abs=1.0)


def test_the_cli_default_ratio_is_the_checks():
    assert cli_identify.RATIO_DEFAULT == identify.FIT_RATIO_MAX


def test_good_recordings_have_no_findings(rig, tmp_path, capsys):
    streams, f_true, n_true = rig
    rec = fr.write(tmp_path / 'rec', 'mcap', streams)
    rc, out, err, cal = _identify(tmp_path, capsys, rec, '--json')
    assert rc == 0, err
    report = json.loads(out)
    assert report['findings'] == [] and not report['refused']
    ratio = np.array([report['residual_rms'][c]['after'] / report['noise_floor'][c]
                      for c in ('force_x', 'force_y', 'moment_z')])
    assert np.all(ratio < identify.FIT_RATIO_WARN)
    _within(cal, f_true, n_true)
