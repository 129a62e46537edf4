"""
Rerun recordings, read back with rerun-sdk's own loader (``rerun.chunk.RrdReader``).

Each recording is checked for its entity paths, one row per sample on both timelines, and
values equal to the core's at the recorded crank angles (plots in float64 exactly as
computed; geometry stored by rerun as float32).  Physics: the force-balanced designs keep
the system mass centre still and their shaking-force series near zero.
"""

import argparse
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

from mech_balance import schema as scene_mod
from mech_balance.analysis import cycle as analysis
from mech_balance.balancing import weights
from mech_balance.bench import recording as bench_recording
from mech_balance.cli import main as cli
from mech_balance.conventions import cycle_angles, rms
from mech_balance.core import equimomental
from mech_balance.core.planar import dynamics
from mech_balance.core.rig import rig_for
from mech_balance.viz import recording
import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest
import yaml

A2 = bench_recording.HOEKEN_A2_DESIGN  # seed 001 Table 5, case a(2)
B2 = (0.0, 1.5990, 3.4010, 0.9514, 4.6933, 0.0, 2.4067, 1.7240, 0.0, 9.5000, 0.0, 0.8759)
"""seed 001 Table 5, case b(2) as reconstructed (its print is damaged): counterweights, so
every link is realizable and can be written as a scene file (a(2)'s crank cannot)."""
SAMPLES = 360
EXACT_RTOL = 1e-12
"""Plots are float64 computed by the same core calls: equal to round-off."""
FLOAT32_ATOL_M = 1e-7
"""Geometry is stored as float32: ~6e-8 relative on rigs of ~0.2 m."""
TIME_ATOL_S = 1e-9
"""The time timeline is stored in integer nanoseconds."""
VARIANTS = ('original', 'balanced')
PLOTS = ('shaking_force', 'shaking_moment', 'driving_torque')
PLANAR_PATHS = ({'/info', '/rig/frame', '/rig/pivots', '/rig/links', '/rig/joints'}
                | {f'/{v}/{e}' for v in VARIANTS
                   for e in ('mass_centres', 'point_masses', 'shaking_force', 'shaking_moment')}
                | {f'/plots/{q}/{v}' for q in PLOTS for v in VARIANTS}
                | {f'/by_angle/{q}/{k}' for q in PLOTS for k in VARIANTS + ('cursor', 'values')})
CURVES = {f'/by_angle/{q}/{v}' for q in PLOTS for v in VARIANTS}
"""The plots' curves over the crank angle: static, drawn whole."""


def _series(entities, path):
    return np.array([row[0] for row in entities[path].columns['Scalars:scalars']])


def _points(entities, path, component):
    return np.array(entities[path].columns[component], dtype=float)


def _hoeken_pair():
    sc = scene_mod.load('hoeken')
    return sc, equimomental.apply_design(sc, A2, normalized=True)


@pytest.fixture(scope='module')
def hoeken(tmp_path_factory):
    # point masses are off unless a scene asks for them (issue 16): this one asks
    sc = _scene_with(recording={'streams': {'point_masses': True}})
    bal = equimomental.apply_design(sc, A2, normalized=True)
    path = tmp_path_factory.mktemp('rec') / 'hoeken.rrd'
    summary = recording.record(path, sc, bal, cycles=1, samples=SAMPLES,
                               balanced_source='Chaudhary & Saha Table 5 a(2)')
    return sc, bal, path, summary, recording.read_recording(path)


def _core(sc, samples=SAMPLES):
    rig = analysis.Rig(sc)
    psi = cycle_angles(samples, sc.assembly_crank_angle_rad)
    state, w = rig.evaluate(psi)
    return rig, psi, state, w


# ------------------------------------------------------------------------------ offline


def test_entity_paths_and_one_row_per_sample(hoeken):
    sc, _, path, summary, ent = hoeken
    # a redistribution design also shows where it moved each link's mass centre
    assert set(summary.entity_paths) == PLANAR_PATHS | {'/balanced/mass_changes'}
    assert PLANAR_PATHS <= set(ent)
    assert summary.rows == SAMPLES and summary.variants == VARIANTS
    animated = PLANAR_PATHS - {'/info', '/rig/frame', '/rig/pivots'} - CURVES
    turn_s = 2.0 * math.pi / abs(sc.crank_speed_rad_s)
    for p in animated:
        assert ent[p].rows == SAMPLES, p
        assert_array_equal(ent[p].index['crank_angle'], np.arange(SAMPLES))  # whole degrees
        assert_array_equal(ent[p].index['crank_angle_deg'], np.arange(SAMPLES))
        assert_allclose(ent[p].index['time'], np.arange(SAMPLES) * turn_s / SAMPLES,
                        rtol=0.0, atol=TIME_ATOL_S)
    for p in {'/info', '/rig/frame', '/rig/pivots'} | CURVES:
        assert ent[p].rows == 0 and ent[p].static, p


def test_time_series_equal_the_core(hoeken):
    sc, bal, _, _, ent = hoeken
    for v, s in zip(VARIANTS, (sc, bal)):
        _, _, _, w = _core(s)
        assert_allclose(_series(ent, f'/plots/shaking_force/{v}'), np.abs(w.shaking_force),
                        rtol=EXACT_RTOL, atol=0.0)
        assert_allclose(_series(ent, f'/plots/shaking_moment/{v}'), w.shaking_moment,
                        rtol=EXACT_RTOL, atol=1e-18)
        assert_allclose(_series(ent, f'/plots/driving_torque/{v}'), w.driving_torque,
                        rtol=EXACT_RTOL, atol=1e-18)
    # seed 001 Table 7, case a(2): the shaking force almost vanishes, the moment drops ~90 %
    f_orig = _series(ent, '/plots/shaking_force/original')
    f_bal = _series(ent, '/plots/shaking_force/balanced')
    assert rms(f_bal) < 1e-4 * rms(f_orig)
    assert rms(_series(ent, '/plots/shaking_moment/balanced')) < \
        0.15 * rms(_series(ent, '/plots/shaking_moment/original'))


def test_geometry_equals_the_core(hoeken):
    sc, bal, _, _, ent = hoeken
    rig, _, state, _ = _core(sc)
    lk, pose = rig.linkage, state.pose
    body = {n: i for i, n in enumerate(lk.body_names)}

    def world(name, point):
        b = body[name]
        local = sc.frame_points[point] if name == 'frame' else sc.link(name).points[point]
        z = pose.origin[b] + pose.rot[b] * complex(*local)
        return np.stack([z.real, z.imag], axis=-1)

    joints = _points(ent, '/rig/joints', 'Points2D:positions')
    expected = np.stack([world(j.link_a, j.point_a) for j in sc.joints], axis=1)
    assert_allclose(joints, expected, rtol=0.0, atol=FLOAT32_ATOL_M)
    strips = ent['/rig/links'].columns['LineStrips2D:strips']
    for i, link in enumerate(sc.links):
        got = np.array([row[i] for row in strips])
        want = np.stack([world(link.name, p) for p in link.points], axis=1)
        assert_allclose(got, want, rtol=0.0, atol=FLOAT32_ATOL_M)
    for v, s in zip(VARIANTS, (sc, bal)):
        _, _, _, w = _core(s)
        arrows = _points(ent, f'/{v}/shaking_force', 'Arrows2D:vectors')[:, 0]
        layout_scale = np.linalg.norm(arrows, axis=1) / np.maximum(np.abs(w.shaking_force),
                                                                   1e-300)
        # one scale for both designs, and it is the one the text panel states
        scale_text = f'{0.01 / np.median(layout_scale[np.abs(w.shaking_force) > 0]):.4g}'
        assert f'1 cm of arrow = {scale_text} N' in \
            ent['/info'].static['TextDocument:text'][0]
        masses = np.array([lk_.mass_kg for lk_ in s.links])
        com = sum(m * (pose.origin[body[lk_.name]] + pose.rot[body[lk_.name]]
                       * complex(*lk_.com_m)) for m, lk_ in zip(masses, s.links)) / masses.sum()
        centres = _points(ent, f'/{v}/mass_centres', 'Points2D:positions')
        assert_allclose(centres[:, -1], np.stack([com.real, com.imag], -1), rtol=0.0,
                        atol=FLOAT32_ATOL_M)
        pts = _points(ent, f'/{v}/point_masses', 'Points2D:positions')
        for i, lk_ in enumerate(s.links):
            pm = equimomental.from_link(lk_.mass_kg, lk_.com_m, lk_.inertia_origin_kg_m2)
            b = body[lk_.name]
            z = pose.origin[b][:, None] + pose.rot[b][:, None] * (
                pm.distance_m * equimomental.UNIT)[None, :]
            assert_allclose(pts[:, 3 * i:3 * i + 3], np.stack([z.real, z.imag], -1),
                            rtol=0.0, atol=FLOAT32_ATOL_M)
    # physics: the (almost) force-balanced design keeps its mass centre still
    g_orig = _points(ent, '/original/mass_centres', 'Points2D:positions')[:, -1]
    g_bal = _points(ent, '/balanced/mass_centres', 'Points2D:positions')[:, -1]
    assert np.ptp(g_bal, axis=0).max() < 1e-4 * np.ptp(g_orig, axis=0).max()


def test_point_masses_styled_by_sign_and_size(hoeken):
    _, bal, _, _, ent = hoeken
    static = ent['/balanced/point_masses'].static
    masses = np.concatenate([equimomental.from_link(lk.mass_kg, lk.com_m,
                                                    lk.inertia_origin_kg_m2).masses_kg
                             for lk in bal.links])
    colors = np.array(static['Points2D:colors'])
    assert len(set(colors[masses >= 0])) == 1 and len(set(colors[masses < 0])) == 1
    assert set(colors[masses >= 0]) != set(colors[masses < 0])
    radii = np.array(static['Points2D:radii'])
    assert_allclose(radii ** 2 / np.abs(masses), (radii ** 2 / np.abs(masses))[0], rtol=1e-5)


def test_text_panel_and_blueprint(hoeken):
    sc, bal, path, _, ent = hoeken
    text = ent['/info'].static['TextDocument:text'][0]
    assert text.startswith('# hoeken: original vs balanced')
    assert 'Chaudhary & Saha Table 5 a(2)' in text
    for v, s in zip(VARIANTS, (sc, bal)):
        rig, psi, state, w = _core(s)
        for row in analysis.summarize(analysis.Cycle(rig, psi, state, w, 0.0), True):
            assert f'{row.rms:.4g}' in text, (v, row.quantity)
    views = recording.read_blueprint_views(path)
    kinds = sorted(k for k, _, _ in views)
    assert kinds == ['2D'] * 5 + ['TextDocument']        # the rigs, then the plots
    names = {n for _, n, _ in views}
    assert any(n.startswith('original | force arrow 1 cm = ') for n in names)
    assert any(n.startswith('balanced | force arrow 1 cm = ') for n in names)
    assert {o for k, _, o in views if o.startswith('/by_angle/')} == \
        {f'/by_angle/{q}' for q in PLOTS}


def _scene_with(**top):
    data, path = scene_mod.load_data('hoeken')
    data.update(top)
    return scene_mod.from_dict(data, source=str(path))


def test_switching_a_stream_off_removes_it(tmp_path):
    sc = _scene_with(recording={'streams': {'point_masses': False,
                                            'driving_torque_plot': False}})
    bal = equimomental.apply_design(sc, A2, normalized=True)
    path = tmp_path / 'off.rrd'
    summary = recording.record(path, sc, bal)
    ent = recording.read_recording(path)
    gone = {f'/{v}/point_masses' for v in VARIANTS} | \
        {f'/plots/driving_torque/{v}' for v in VARIANTS} | \
        {f'/by_angle/driving_torque/{k}' for k in VARIANTS + ('cursor', 'values')}
    assert set(summary.entity_paths) == (PLANAR_PATHS - gone) | {'/balanced/mass_changes'}
    assert not gone & set(ent)
    assert (PLANAR_PATHS - gone) <= set(ent)
    assert all('driving torque' not in n for _, n, _ in recording.read_blueprint_views(path))
    assert 'Blue and red discs' not in ent['/info'].static['TextDocument:text'][0]


@pytest.mark.parametrize('name, series, label', [
    ('hoeken', 'driving_torque', 'driving torque'),
    ('pssr_skew', 'driving_force', 'driving force')])
def test_driving_torque_plot_switches_the_input_effort_of_either_kind(tmp_path, name, series,
                                                                      label):
    """
    ``driving_torque_plot`` switches the driving effort's plot: torque or force alike.

    A spatial scene has no ``recording:`` key (yet): pssr_skew's switches are attached to
    the loaded scene, where the recording reads them (``getattr(scene, 'recording')``).
    """
    for on in (True, False):
        if name == 'hoeken':
            sc = _scene_with(recording={'streams': {'driving_torque_plot': on}})
        else:
            sc = scene_mod.load(name)
            streams = scene_mod.Recording().streams
            object.__setattr__(sc, 'recording', scene_mod.Recording(
                streams if on else tuple(s for s in streams if s != 'driving_torque_plot')))
        rrd = tmp_path / f'{name}_{on}.rrd'
        summary = recording.record(rrd, sc, samples=24)
        plotted = {p for p in summary.entity_paths if p.startswith('/plots/')}
        views = [n for _, n, _ in recording.read_blueprint_views(rrd)]
        assert (f'/plots/{series}/original' in plotted) == on
        assert any(label in n for n in views) == on
        if not on:
            assert not {p for p in recording.read_recording(rrd) if series in p}


def test_kinematics_only_scene_computes_no_dynamics(tmp_path, monkeypatch):
    sc = _scene_with(outputs=['kinematics'])

    def refuse(*args, **kwargs):
        raise AssertionError('inverse dynamics computed for a kinematics-only scene')
    monkeypatch.setattr(dynamics, 'inverse_dynamics', refuse)
    path = tmp_path / 'kin.rrd'
    summary = recording.record(path, sc, samples=90)
    ent = recording.read_recording(path)
    assert not [p for p in ent if p.startswith('/plots') or 'shaking' in p]
    assert {'/rig/links', '/rig/joints', '/original/mass_centres'} <= set(summary.entity_paths)
    assert ent['/rig/links'].rows == 90


def test_cycles_repeat_the_turn_on_continuing_timelines(tmp_path):
    sc = scene_mod.load('slider_crank')       # assembled at 90 deg, 300 rpm
    path = tmp_path / 'two.rrd'
    recording.record(path, sc, cycles=2, samples=90)
    ent = recording.read_recording(path)
    series = ent['/plots/shaking_force/original']
    assert series.rows == 180
    # a recorded turn starts at crank angle 0, whatever the assembly angle (issue 16)
    assert_array_equal(series.index['crank_angle'], 4 * np.arange(180))
    assert_allclose(series.index['time'], np.arange(180) * (2 * math.pi / 90) / (10 * math.pi),
                    rtol=0.0, atol=TIME_ATOL_S)
    f = _series(ent, '/plots/shaking_force/original')
    assert_array_equal(f[:90], f[90:])
    _, w = analysis.Rig(sc).evaluate(cycle_angles(90))
    assert_allclose(f[:90], np.abs(w.shaking_force), rtol=EXACT_RTOL, atol=0.0)


def test_user_scale_is_used_and_stated(tmp_path):
    sc = _scene_with(recording={'force_scale_m_per_N': 2.0, 'moment_scale_deg_per_Nm': 900})
    path = tmp_path / 'scale.rrd'
    recording.record(path, sc, samples=36)
    ent = recording.read_recording(path)
    _, _, _, w = _core(sc, 36)
    arrows = _points(ent, '/original/shaking_force', 'Arrows2D:vectors')[:, 0]
    assert_allclose(arrows, 2.0 * np.stack([w.shaking_force.real, w.shaking_force.imag], -1),
                    rtol=1e-6, atol=FLOAT32_ATOL_M)
    names = [n for k, n, o in recording.read_blueprint_views(path)
             if k == '2D' and not o.startswith('/by_angle/') and not n.startswith('zoom')]
    assert names == ['original | force arrow 1 cm = 0.005 N | moment arc 90 deg = 0.1 N*m']


@pytest.mark.parametrize('kwargs, message', [
    ({'samples': 3}, 'samples: got 3, expected an integer >= 4'),
    ({'samples': 2.5}, 'samples: got 2.5'),
    ({'samples': 2}, 'samples: got 2'),
    ({'cycles': 0}, 'cycles: got 0'),
])
def test_bad_arguments(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        recording.record(tmp_path / 'x.rrd', scene_mod.load('hoeken'), **kwargs)


def test_bad_design_and_path(tmp_path):
    sc = scene_mod.load('hoeken')
    with pytest.raises(ValueError, match='design: scene .* has another geometry'):
        recording.record(tmp_path / 'x.rrd', sc, scene_mod.load('carpet_scraper'))
    with pytest.raises(ValueError, match='design: got a spatial scene'):
        recording.record(tmp_path / 'x.rrd', sc, scene_mod.load('rggr'))
    with pytest.raises(ValueError, match='path: got .*expected a file name ending in .rrd'):
        recording.record(tmp_path / 'x.txt', sc)
    with pytest.raises(ValueError, match="--out: got .*its directory '.*no' does not exist"):
        recording.record(tmp_path / 'no' / 'x.rrd', sc, field='--out')
    with pytest.raises(ValueError, match='recording_path: got .*does not exist'):
        recording.LiveRecorder(tmp_path / 'no' / 'x.rrd', sc, field='recording_path')
    assert not (tmp_path / 'no').exists()


def test_output_path_check_names_the_callers_field(tmp_path):
    check = recording.check_output_path
    assert check(tmp_path / 'a.rrd', 'recording_path') == tmp_path / 'a.rrd'
    for path, message in ((tmp_path / 'a.txt', 'expected a file name ending in .rrd'),
                          (tmp_path / 'a', 'expected a file name ending in .rrd'),
                          (tmp_path / 'sub' / 'a.rrd', "its directory '.*sub' does not exist")):
        for field in ('--out', 'recording_path'):
            with pytest.raises(ValueError, match=f'^{field}: got .*{message}'):
                check(path, field)
    (tmp_path / 'dir.rrd').mkdir()
    with pytest.raises(ValueError, match='--out: got .* a directory, expected a file name'):
        check(tmp_path / 'dir.rrd', '--out')
    # create_dir (a command that documents it): missing directories are made, mkdir -p
    deep = tmp_path / 'new' / 'deeper' / 'a.rrd'
    assert check(deep, '--out', create_dir=True) == deep and deep.parent.is_dir()
    (tmp_path / 'file').write_text('')
    with pytest.raises(ValueError, match="--out: got .*'.*file' cannot be created"):
        check(tmp_path / 'file' / 'a.rrd', '--out', create_dir=True)


def test_design_links_are_matched_by_name():
    sc, bal = _hoeken_pair()
    shuffled = bal.with_links(bal.links[::-1])
    aligned = recording.align_design(sc, shuffled)
    assert [lk.name for lk in aligned.links] == [lk.name for lk in sc.links]
    assert aligned.links == bal.links


@pytest.mark.parametrize('value, message', [
    ({'streams': {'nope': True}}, 'recording.streams.nope: unknown field'),
    ({'streams': {'links': 'yes'}}, "recording.streams.links: got 'yes', expected true"),
    ({'force_scale_m_per_N': -1}, r'recording.force_scale_m_per_N: got -1.0, expected .* > 0'),
    ({'colour': 1}, 'recording.colour: unknown field'),
    (3, 'recording: got 3, expected a mapping'),
])
def test_recording_schema_errors_name_the_field(value, message):
    with pytest.raises(scene_mod.SceneError, match=message):
        _scene_with(recording=value)


def test_rggr_recording_is_3d(tmp_path):
    sc = scene_mod.load('rggr')
    bal = weights.balance_weights(rig_for(sc)).balanced_scene
    path = tmp_path / 'rggr.rrd'
    summary = recording.record(path, sc, bal)
    ent = recording.read_recording(path)
    assert not [p for p in ent if 'point_masses' in p]
    assert set(summary.entity_paths) <= set(ent)
    assert ent['/rig/links'].rows == SAMPLES
    assert 'LineStrips3D:strips' in ent['/rig/links'].columns
    assert 'Arrows3D:vectors' in ent['/balanced/shaking_moment'].columns
    psi = cycle_angles(SAMPLES)
    for v, s in zip(VARIANTS, (sc, bal)):
        d = rig_for(s).at(psi)
        assert_allclose(_series(ent, f'/plots/shaking_moment/{v}'),
                        np.linalg.norm(d.moment_Nm, axis=1), rtol=EXACT_RTOL)
        assert_allclose(_series(ent, f'/plots/driving_torque/{v}'), d.joint_effort[:, 0],
                        rtol=EXACT_RTOL, atol=1e-15)
    # the crank's strip ends at the pin B, the coupler's origin
    b = np.array([row[0][1] for row in ent['/rig/links'].columns['LineStrips3D:strips']])
    poses = rig_for(sc).at(psi).bodies
    pin_b = poses.origin_m[:, poses.names.index('coupler')]
    assert_allclose(b, pin_b, rtol=0.0, atol=FLOAT32_ATOL_M)
    # seed 002: complete force balance, and the system mass centre stands still
    assert rms(_series(ent, '/plots/shaking_force/balanced')) < \
        1e-9 * rms(_series(ent, '/plots/shaking_force/original'))
    g = _points(ent, '/balanced/mass_centres', 'Points3D:positions')[:, -1]
    assert np.ptp(g, axis=0).max() < 1e-6
    assert [k for k, _, _ in recording.read_blueprint_views(path)].count('3D') == 2


# ------------------------------------------------------------------------------ live


def test_live_recorder_writes_what_the_core_computes(tmp_path):
    sc, bal = _hoeken_pair()
    path = tmp_path / 'live.rrd'
    rec = recording.LiveRecorder(path, sc, bal)
    singles = [0.0, 0.02, 0.04]
    for k, psi in enumerate(singles):
        assert rec.log_sample(10.0 + 0.02 * k, psi) == 1
    batch = 0.1 + 0.05 * np.arange(4)
    assert rec.log_sample(10.1 + 0.05 * np.arange(4), batch,
                          data=rig_for(sc).at(batch)) == 4
    rec.close()
    rec.close()                                    # idempotent
    assert rec.closed and rec.log_sample(11.0, 0.5) == 0
    ent = recording.read_recording(path)
    psi = np.concatenate([singles, batch])
    series = ent['/plots/shaking_moment/balanced']
    assert series.rows == psi.size
    assert_allclose(series.index['time'][0], 0.0, atol=TIME_ATOL_S)
    assert_array_equal(series.index['crank_angle'], np.round(np.degrees(psi)))
    for v, s in zip(VARIANTS, (sc, bal)):
        _, wv = analysis.Rig(s).evaluate(psi)
        assert_allclose(_series(ent, f'/plots/shaking_moment/{v}'), wv.shaking_moment,
                        rtol=1e-9, atol=1e-15)
        assert_allclose(_series(ent, f'/plots/driving_torque/{v}'), wv.driving_torque,
                        rtol=1e-9, atol=1e-15)
    assert set(recording.entity_paths(rec.layout)) <= set(ent)


def test_live_recorder_rejects_bad_samples(tmp_path):
    with recording.LiveRecorder(tmp_path / 'bad.rrd', scene_mod.load('hoeken')) as rec:
        with pytest.raises(ValueError, match='time_s: got shape'):
            rec.log_sample([0.0, 1.0], [0.0])
        with pytest.raises(ValueError, match='non-finite'):
            rec.log_sample(0.0, float('nan'))
    assert rec.closed


RERUN_CONNECT_WAIT_S = 5.0
"""rerun's ``connect_grpc`` and ``disconnect`` each wait this long for a viewer that is not
there (here only a bound on waits for the view's thread, never a timing assertion)."""
JOIN_WAIT_S = 60.0
"""Wait bound for a caller's thread that must finish while the view's thread is held."""


def _dead_url():
    from mech_balance.bench import node as bench_node
    return f'rerun+http://127.0.0.1:{bench_node.free_port()}/proxy'


def _wait_for(predicate, seconds):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not predicate():
        time.sleep(0.02)
    return predicate()


@pytest.fixture
def held_view(monkeypatch):
    """
    Hold the live view's thread before it knocks at the viewer, until the gate opens.

    A caller that waited for that thread (its connect, flush or disconnect) cannot return
    while the gate is shut: returning proves it did not wait, whatever the machine's load.
    """
    import threading
    from mech_balance.viz import live
    gate = threading.Event()
    real = live.LiveView._knock

    def knock(self):
        gate.wait()
        return real(self)
    monkeypatch.setattr(live.LiveView, '_knock', knock)
    yield gate
    gate.set()


def _in_thread(fn):
    """Run ``fn`` on a thread; return (finished within the wait bound, its result)."""
    import threading
    out = []
    th = threading.Thread(target=lambda: out.append(fn()), daemon=True)
    th.start()
    th.join(JOIN_WAIT_S)
    return not th.is_alive(), (out[0] if out else None)


def test_live_view_to_a_dead_url_never_blocks_and_says_dead(tmp_path, held_view):
    """Issue 23 2b.1: nothing listens at the url; the caller is never held by rerun's waits."""
    sc, url = scene_mod.load('hoeken'), _dead_url()

    def caller():
        rec = recording.LiveRecorder(None, sc, url=url)
        status = rec.status
        taken = [rec.log_sample(0.01 * k, 0.05 * k) for k in range(20)]
        return rec, status, taken
    done, (rec, status, taken) = _in_thread(caller)
    # built and fed while the view's thread is held before it even knocks
    assert done and not held_view.is_set()
    assert status == 'connecting' and taken == [1] * 20
    view = rec._view
    held_view.set()
    assert _wait_for(lambda: rec.status.startswith('dead: '), RERUN_CONNECT_WAIT_S)
    assert '127.0.0.1' in rec.status and 'retried every' in rec.status, rec.status
    # close returns while the view's thread is held at its next knock (the dead viewer is
    # retried): it waits at most its timeout, never for the thread's connect or disconnect
    held_view.clear()
    view._cond.acquire()
    view._cond.notify()         # wake the retry wait: the thread goes to the held knock
    view._cond.release()
    done, _ = _in_thread(lambda: rec.close(timeout_s=0.5))
    assert done and not held_view.is_set()
    assert rec.closed and rec.log_sample(1.0, 1.0) == 0


def test_live_view_with_a_file_and_a_dead_url_still_writes_the_file(tmp_path, held_view):
    path = tmp_path / 'both.rrd'
    sc, url = scene_mod.load('hoeken'), _dead_url()

    def caller():
        rec = recording.LiveRecorder(path, sc, url=url)
        for k in range(5):
            rec.log_sample(0.01 * k, 0.05 * k)
        rec.close(timeout_s=0.5)
        return rec
    done, rec = _in_thread(caller)
    # written and closed while the view's thread is still held before it knocks
    assert done and not held_view.is_set() and rec._view._thread.is_alive()
    held_view.set()
    assert recording.read_recording(path)['/plots/shaking_force/original'].rows == 5


def test_live_view_connects_and_says_so(tmp_path):
    from mech_balance.bench import node as bench_node
    port = bench_node.free_port()
    viewer = bench_node.viewer_endpoint(tmp_path / 'got.rrd', port)
    try:
        rec = recording.LiveRecorder(None, scene_mod.load('hoeken'),
                                     url=f'rerun+http://127.0.0.1:{port}/proxy')
        for k in range(40):
            rec.log_sample(0.05 * k, 0.05 * k)
            time.sleep(0.01)
        assert _wait_for(lambda: rec.status == 'connected', 4 * RERUN_CONNECT_WAIT_S), \
            rec.status
        rec.close(timeout_s=RERUN_CONNECT_WAIT_S)
    finally:
        viewer.send_signal(signal.SIGINT)
        try:
            viewer.wait(timeout=20)
        except subprocess.TimeoutExpired:
            viewer.kill()
    assert recording.read_recording(tmp_path / 'got.rrd')['/rig/links'].rows >= 1


LIVE_SCRIPT = textwrap.dedent("""
    import signal, sys, time
    # Ctrl-C as in a terminal: a parent started in the background without job control (a
    # CI job under `nohup ... &`) passes SIGINT on as ignored, and Python then never raises
    # KeyboardInterrupt (the test waited 60 s for an exit that never came)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    from mech_balance import schema as scene
    from mech_balance.viz import recording
    rec = recording.LiveRecorder(sys.argv[1], scene.load('hoeken'))
    k = 0
    while True:
        rec.log_sample(0.01 * k, 0.01 * k)
        k += 1
        if k == 5:
            print('ready', flush=True)
        time.sleep(0.002)
""")


def test_live_recording_survives_ctrl_c(tmp_path):
    path = tmp_path / 'sigint.rrd'
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root)
    proc = subprocess.Popen([sys.executable, '-c', LIVE_SCRIPT, str(path)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == 'ready'
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert 'KeyboardInterrupt' in err
    from rerun.chunk import RrdReader
    assert len(RrdReader(str(path)).store()) > 0   # needs the footer written on close
    assert recording.read_recording(path)['/plots/shaking_force/original'].rows >= 5


# ------------------------------------------------------------------------------ CLI


def _balanced_yaml(tmp_path, scene_name='hoeken'):
    data, _ = scene_mod.load_data(scene_name)
    bal = equimomental.apply_design(scene_mod.load(scene_name), B2, normalized=True)
    for lk in bal.links:
        spec = data['links'][lk.name]
        spec.pop('inertia_origin_kg_m2', None)
        spec.update(mass_kg=lk.mass_kg, com_m=list(lk.com_m),
                    inertia_com_kg_m2=lk.inertia_com_kg_m2)
    data['name'] = 'hoeken_b2'
    path = tmp_path / 'balanced.yaml'
    path.write_text(yaml.safe_dump(data, sort_keys=True))   # other link and joint order
    return path, bal


def test_cli_record_with_design_file(tmp_path, capsys):
    design, bal = _balanced_yaml(tmp_path)
    out = tmp_path / 'sub' / 'hoeken.rrd'
    assert cli.main(['record', '--scene', 'hoeken', '--design', str(design), '--samples',
                     '120', '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    assert f'wrote {out.resolve()}' in printed
    opener = next(line for line in printed.splitlines() if line.startswith('open it with:'))
    assert 'rerun' in opener and opener.endswith(f' {out.resolve()}')
    ent = recording.read_recording(out)
    _, _, _, w = _core(bal, 120)
    assert_allclose(_series(ent, '/plots/shaking_moment/balanced'), w.shaking_moment,
                    rtol=1e-9, atol=1e-15)


def test_cli_record_balance_runs_the_optimizer(tmp_path, capsys):
    pytest.importorskip('mech_balance.balancing')
    out = tmp_path / 'bal.rrd'
    assert cli.main(['record', '--scene', 'hoeken', '--balance', '--samples', '90',
                     '--out', str(out)]) == 0
    assert 'mech_balance.balancing.redistribution.optimize' in capsys.readouterr().out
    ent = recording.read_recording(out)
    assert rms(_series(ent, '/plots/shaking_moment/balanced')) < \
        rms(_series(ent, '/plots/shaking_moment/original'))


@pytest.mark.parametrize('argv, message', [
    (['--design', 'carpet_scraper'], 'design: scene'),
    (['--out', 'x.txt'], '--out: got'),
])
def test_cli_record_bad_input_exits_2(tmp_path, capsys, argv, message):
    args = ['record', '--scene', 'hoeken', '--out', str(tmp_path / 'x.rrd'), *argv]
    assert cli.main(args) == cli.EXIT_USAGE
    assert message in capsys.readouterr().err


def test_cli_record_samples_must_be_at_least_4(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(['record', '--samples', '3', '--out', 'x.rrd'])
    assert exc.value.code == 2
    assert 'expected an integer >= 4' in capsys.readouterr().err


def test_bench_section_reports_seconds_and_megabytes():
    text = bench_recording.bench_section(argparse.Namespace(repeat=1, scene=['hoeken']),
                                         progress=lambda s: None)
    assert 'hoeken' in text and 'file MB' in text and 'median s' in text
    assert 'hoeken --balance' in text and 'carpet_scraper' not in text   # bench --scene
    assert ' PASS' in text or ' FAIL' in text
    assert 'nothing listens' in text and 'status: dead: nothing accepts' in text


def test_cli_record_with_counterweights(tmp_path, capsys):
    out = tmp_path / 'cw.rrd'
    assert cli.main(['record', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--samples', '36', '--out', str(out)]) == 0
    assert 'add-only counterweights on crank,rocker' in capsys.readouterr().out
    ent = recording.read_recording(out)
    assert ent['/balanced/counterweights'].rows == 36
    assert ent['/balanced/counterweight_planes'].rows == 36
    assert '/original/counterweights' not in ent


def test_cli_record_case_needs_balance_even_with_counterweights(tmp_path, capsys):
    assert cli.main(['record', '--counterweights', 'crank', '--case', 'b',
                     '--out', str(tmp_path / 'x.rrd')]) == 2
    assert '--case applies with --balance only' in capsys.readouterr().err


def test_record_counterweights_with_no_clear_design_records_nothing(tmp_path, capsys):
    """The carpet scraper's crank and rocker discs have no clear design: exit 3, no file."""
    from mech_balance.cli import balance as cli_balance
    out = tmp_path / 'cw.rrd'
    argv = ['--scene', 'carpet_scraper', '--counterweights', 'crank,rocker']
    assert cli.main(['balance', *argv]) == cli_balance.EXIT_NO_CLEAR_DESIGN   # as balance
    capsys.readouterr()
    assert cli.main(['record', *argv, '--out', str(out)]) == \
        cli_balance.EXIT_NO_CLEAR_DESIGN
    err = capsys.readouterr().err
    assert 'NO collision-free design' in err and 'nothing recorded' in err
    assert not out.exists()
