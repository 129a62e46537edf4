"""
What a person sees in a recording, checked from the file and its blueprint (issue 16).

Every built-in scene is recorded against its balanced design (and Hoeken against a design
with counterweight discs, written by ``mech-balance balance --counterweights``), read back
with rerun's own loader, and checked at the default window (``recording.WINDOW_PX``):

* no two labels of one view closer than their text height, no two label boxes overlapping,
  at any sample of the turn;
* every plot's y range covers its data and shows at least three labelled ticks;
* everything drawn (links, joints, pivots, mass centres, discs, arrows, arcs, labels) lies
  inside its view (2-D: the blueprint's bounds; 3-D: the eye's picture);
* the point masses absent unless asked for; the counterweights present exactly when the
  design has them, at its radius and on its links;
* any sample count, the crank-angle timeline from 0 deg.
"""

import itertools
import math
import os
from pathlib import Path
import signal
import subprocess

from mech_balance import schema as scene_mod
from mech_balance.cli import main as cli
from mech_balance.cli import record as cli_record
from mech_balance.core.rig import rig_for
from mech_balance.viz import drawing, layout as layout_mod, recording
import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

SCENES = ('hoeken', 'slider_crank', 'carpet_scraper', 'rggr')
FLOAT32_ATOL_M = 1e-6
"""Positions are stored as float32 (rigs up to ~1 m)."""
EDGE_TOL_PX = 0.5
"""Something drawn may touch a view's edge by this much (float32 round-off)."""


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    """Record every built-in scene against its balanced design, and a counterweight design."""
    tmp = tmp_path_factory.mktemp('layout')
    out = {}
    for name in SCENES:
        sc = scene_mod.load(name)
        balanced, source = cli_record.balanced_design(sc)
        path = tmp / f'{name}.rrd'
        summary = recording.record(path, sc, balanced, balanced_source=source)
        out[name] = (sc, balanced, path, summary)
    design = tmp / 'hoeken_cw.yaml'
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--output', str(design)]) == 0
    sc, cw = scene_mod.load('hoeken'), scene_mod.load(str(design))
    path = tmp / 'hoeken_cw.rrd'
    out['hoeken_cw'] = (sc, cw, path, recording.record(path, sc, cw))
    return {k: v + (recording.read_recording(v[2]), recording.read_blueprint(v[2]))
            for k, v in out.items()}


ALL = SCENES + ('hoeken_cw',)


def _screen(view, layout, variant):
    """Return the view's :class:`recording.Screen` from the blueprint read back."""
    size = (layout.inset if variant == 'inset' else layout.screens[variant]).size_px
    if view['kind'] == '2D':
        b = view['bounds']
        (y0, y1) = b['y_range']
        return recording.Screen(size, bounds=(tuple(b['x_range']), (-y1, -y0)))
    eye = view['eye']
    return recording.Screen(size, eye_m=eye['position'], target_m=eye['look_target'],
                            up=eye['eye_up'])


NAMES_OTHER, CROSSED, OVERLAPPING = 2, 3, 4
"""The placement tiers (:func:`mech_balance.viz.labels.place_labels`) from which a label
may stand nearer another point, be crossed by a line or cover a point, overlap a label."""


def _tiers(summary, variant):
    """Return per sample the placement tier of each label of a view (reference turn)."""
    t = summary.layout.placed[variant][4]
    return np.tile(t.reshape(summary.samples_per_cycle, -1), (summary.cycles, 1))


def _rig_views(blueprint):
    """Return the rig views by design, and the inset zoomed on a crowded core as 'inset'."""
    views = {v['name'].split(' | ')[0]: v for v in blueprint if v['kind'] in ('2D', '3D')}
    views.update({'inset': v for v in blueprint if v['name'].startswith('zoom x')})
    return views


def _positions(ent, path, dim):
    """Return the per-row positions of an entity as a list of (k, 3) arrays."""
    comp = next(c for c in ent[path].columns if c.endswith(':positions'))
    rows = []
    for row in ent[path].columns[comp]:
        a = np.array(row, dtype=float).reshape(-1, dim)
        rows.append(np.pad(a, ((0, 0), (0, 3 - dim))))
    return rows


@pytest.mark.parametrize('name', ALL)
def test_labels_never_overlap_at_the_default_window(recordings, name):
    _, _, _, summary, ent, blueprint = recordings[name]
    layout = summary.layout
    views = _rig_views(blueprint)
    assert ('inset' in views) == ('inset' in layout.placed) == (name == 'carpet_scraper')
    for variant in layout.placed:
        screen = _screen(views[variant], layout, variant)
        labels = ent[f'/{variant}/labels'].columns
        rows = _positions(ent, f'/{variant}/labels', layout.dim)
        texts = labels[next(c for c in labels if c.endswith(':labels'))]
        assert len(rows) == summary.rows
        closest = math.inf
        for anchors, words, tier in zip(rows, texts, _tiers(summary, variant)):
            px = screen.px(anchors)
            boxes = [recording.label_box_px(p, t) for p, t in zip(px, words)]
            for i, j in itertools.combinations(range(len(px)), 2):
                if max(tier[i], tier[j]) >= OVERLAPPING:
                    continue                # no place inside the view was free of labels
                closest = min(closest, float(np.linalg.norm(px[i] - px[j])))
                a, b = boxes[i], boxes[j]
                overlap = min(a[2], b[2]) - max(a[0], b[0]), min(a[3], b[3]) - max(a[1], b[1])
                assert not (overlap[0] > 0 and overlap[1] > 0), (variant, words[i], words[j])
        assert closest >= recording.LABEL_TEXT_PX, (variant, closest)
        flat = {t for words in texts for t in words}
        assert 'G' not in flat or 'CoM' in flat      # the system mass centre is never 'G'


def _strips(ent, path, kind='LineStrips2D:strips'):
    return [np.array(s, dtype=float) for s in ent[path].static[kind]]


@pytest.mark.parametrize('name', ALL)
def test_plots_read_the_crank_angle_in_degrees(recordings, name):
    """Issue 31 item 7: each plot is a 2-D view whose x axis is the crank angle, 0-360 deg."""
    _, _, _, summary, ent, blueprint = recordings[name]
    layout = summary.layout
    plots = [v for v in blueprint if v['origin'].startswith('/by_angle/')]
    assert len(plots) == len(layout.plots) >= 3
    assert not [v for v in blueprint if v['kind'] == 'TimeSeries']
    n = summary.rows
    for view, plot in zip(sorted(plots, key=lambda v: v['origin']),
                          sorted(layout.plots, key=lambda p: p.entity)):
        root = view['origin']
        assert view['kind'] == '2D' and root == f'/by_angle/{plot.entity}'
        assert view['bounds']['x_range'] == [0.0, plot.axes.size_px[0]]
        pts = np.array(ent[f'{root}/labels'].static['Points2D:positions'])
        texts = ent[f'{root}/labels'].static['Points2D:labels']
        centre = {t: recording.label_box_px(p, t) for p, t in zip(pts, texts)}
        x0, y0, x1, y1 = plot.axes.box_px
        for deg in (0, 90, 180, 270, 360):          # tick labels under their grid line
            box = centre[f'{deg}°']
            assert_allclose(0.5 * (box[0] + box[2]), x0 + (x1 - x0) * deg / 360, atol=1e-3)
            assert box[1] > y1
        assert 'crank angle (deg)' in texts
        unit = plot.unit
        ticks = [t for t in texts if t.endswith(f' {unit}')]
        assert len(ticks) >= 3
        grid = _strips(ent, f'{root}/grid')
        for t in ticks:                             # each y tick at its value, with a line
            value = float(t.split()[0])
            box = centre[t]
            y = plot.axes.y(value)
            assert_allclose(0.5 * (box[1] + box[3]), y, atol=1e-3)
            assert box[2] < x0 and any(abs(g[0, 1] - y) < 1e-3 for g in grid)
        # the curves: x the angle turned, y the value plotted, as the numbers' series
        lo, hi = plot.axes.y_ticks[0], plot.axes.y_ticks[-1]
        for v in layout.variants:
            curve = _strips(ent, f'{root}/{v}')[0]
            values = np.array([r[0] for r in ent[f'/plots/{plot.entity}/{v}'].columns[
                'Scalars:scalars']])
            assert curve.shape == (n + 1, 2)
            deg = (curve[:, 0] - x0) * 360.0 / (x1 - x0)
            assert_allclose(deg, 360.0 * np.arange(n + 1) / n, atol=1e-3)
            back = lo + (y1 - curve[:, 1]) * (hi - lo) / (y1 - y0)
            span = hi - lo
            assert_allclose(back[:-1], values, atol=1e-5 * span)
            assert lo <= values.min() and values.max() <= hi
        # the cursor stands at each sample's angle
        cursor = ent[f'{root}/cursor'].columns['LineStrips2D:strips']
        assert len(cursor) == n
        for k in (0, n // 4, n - 1):
            x = np.array(cursor[k][0])[:, 0]
            assert_allclose(x, x0 + (x1 - x0) * k / n, atol=1e-3)


def _drawn_points(ent, layout, variant):
    """Return ``[(name, points (k, 3), radius m)]`` of everything a view draws, per row."""
    dim = layout.dim
    out = []
    for path in ('/rig/links', ):
        if path in ent:
            comp = next(c for c in ent[path].columns if c.endswith(':strips'))
            for row in ent[path].columns[comp]:
                out.append((path, np.pad(np.concatenate([np.array(s).reshape(-1, dim)
                                                         for s in row]),
                                         ((0, 0), (0, 3 - dim))), 0.0))
    for path in ('/rig/joints', f'/{variant}/mass_centres', f'/{variant}/counterweights',
                 f'/{variant}/point_masses'):
        if path in ent:
            radii = ent[path].static.get(f'Points{dim}D:radii')
            r = max([x for x in radii if x > 0] or [0.0]) if radii else 0.0
            for pts in _positions(ent, path, dim):
                out.append((path, pts, r))
    for path in ('/rig/frame', '/rig/scale', '/rig/gauge'):
        if path in ent:
            comp = next(c for c in ent[path].static if c.endswith(':strips'))
            out.append((path, np.pad(np.concatenate([np.array(s).reshape(-1, dim)
                                                     for s in ent[path].static[comp]]),
                                     ((0, 0), (0, 3 - dim))), 0.0))
    arrows = f'/{variant}/shaking_force'
    if arrows in ent:
        origin = np.array(ent[arrows].static[f'Arrows{dim}D:origins'][0])
        for row in ent[arrows].columns[f'Arrows{dim}D:vectors']:
            tip = origin + np.array(row[0])
            out.append((arrows, np.pad(np.stack([origin, tip]), ((0, 0), (0, 3 - dim))), 0.0))
    moment = f'/{variant}/shaking_moment'
    if moment in ent and dim == 2:
        for row in ent[moment].columns['LineStrips2D:strips']:
            out.append((moment, np.pad(np.concatenate([np.array(s) for s in row]),
                                       ((0, 0), (0, 1))), 0.0))
    return out


@pytest.mark.parametrize('name', ALL)
def test_everything_drawn_lies_inside_its_view(recordings, name):
    _, _, _, summary, ent, blueprint = recordings[name]
    layout = summary.layout
    views = _rig_views(blueprint)
    for variant in layout.variants:
        screen = _screen(views[variant], layout, variant)
        w, h = screen.size_px
        for path, pts, radius in _drawn_points(ent, layout, variant):
            px = screen.px(pts)
            r_px = radius / screen.metres_per_px if screen.bounds is not None else 0.0
            assert px[:, 0].min() - r_px >= -EDGE_TOL_PX and \
                px[:, 0].max() + r_px <= w + EDGE_TOL_PX, (variant, path)
            assert px[:, 1].min() - r_px >= -EDGE_TOL_PX and \
                px[:, 1].max() + r_px <= h + EDGE_TOL_PX, (variant, path)
        labels = ent[f'/{variant}/labels'].columns
        texts = labels[next(c for c in labels if c.endswith(':labels'))]
        for anchors, words in zip(_positions(ent, f'/{variant}/labels', layout.dim), texts):
            for p, t in zip(screen.px(anchors), words):
                x0, y0, x1, y1 = recording.label_box_px(p, t)
                assert x0 >= -EDGE_TOL_PX and y0 >= -EDGE_TOL_PX, (variant, t)
                assert x1 <= w + EDGE_TOL_PX and y1 <= h + EDGE_TOL_PX, (variant, t)


@pytest.mark.parametrize('name', ALL)
def test_point_masses_absent_unless_asked_for(recordings, name):
    _, _, _, summary, ent, _ = recordings[name]
    assert not [p for p in ent if 'point_masses' in p]
    assert 'point_masses' not in summary.layout.streams


def test_counterweights_drawn_at_the_designs_radius_and_place(recordings):
    sc, cw, _, summary, ent, _ = recordings['hoeken_cw']
    discs = [(lk.name, d) for lk in cw.links for d in lk.counterweights]
    assert len(discs) == 2 and {n for n, _ in discs} == {'crank', 'rocker'}
    assert '/original/counterweights' not in ent
    assert '/balanced/counterweights' in summary.entity_paths
    static = ent['/balanced/counterweights'].static
    assert_allclose(static['Points2D:radii'], [d.radius_m for _, d in discs], rtol=1e-6)
    got = np.array(ent['/balanced/counterweights'].columns['Points2D:positions'])
    psi = recording.turn_angles(summary.samples_per_cycle, sc.crank_speed_rad_s)
    poses = rig_for(cw).at(psi, outputs=('kinematics',)).bodies
    for k, (link, d) in enumerate(discs):
        want = poses.world(link, d.centre_m)[:, :2]
        assert_allclose(got[:, k], want, rtol=0.0, atol=FLOAT32_ATOL_M)
    for name in SCENES[:3]:       # the optimized (redistribution) designs add no discs
        assert not [p for p in recordings[name][4] if 'counterweights' in p]


def test_rggr_balanced_design_is_drawn_in_3d(recordings):
    sc, bal, _, summary, ent, blueprint = recordings['rggr']
    eyes = [v['eye'] for v in blueprint if v['kind'] == '3D']
    assert len(eyes) == 2 and eyes[0] == eyes[1]        # one camera for both rigs
    # seed 002's weights are folded into their links (kind spatial): nothing added to draw
    assert not [a for b in rig_for(bal).drawing.bodies for a in b.added]
    assert '/balanced/counterweights' not in ent
    links = ent['/rig/links'].static
    assert all(r > 0.0 for r in links['LineStrips3D:radii'])   # tubes in metres, not lines


@pytest.mark.parametrize('samples', [7, 720, 1000])
def test_any_sample_count_from_zero_degrees(tmp_path, samples):
    sc = scene_mod.load('slider_crank')                 # assembled at 90 deg
    path = tmp_path / f'n{samples}.rrd'
    summary = recording.record(path, sc, samples=samples)
    ent = recording.read_recording(path)
    series = ent['/plots/shaking_force/original']
    assert series.rows == summary.rows == samples
    ticks = series.index['crank_angle']
    assert ticks[0] == 0 and ticks[-1] == round(360 * (samples - 1) / samples)
    assert np.all(np.diff(ticks) >= 0) and np.all(np.diff(series.index['time']) > 0)
    if samples <= 360:
        assert np.all(np.diff(ticks) > 0)                # one tick per sample
    assert_array_equal(ticks, np.round(360.0 * np.arange(samples) / samples))
    readout = [t for row in ent['/original/labels'].columns['Points2D:labels'] for t in row
               if t.startswith('crank ')]
    assert readout[0] == 'crank 0.0 deg' and len(readout) == samples


# ------------------------------------------------------------------------------ live view

LIVE_RATE_HZ = 200.0
LIVE_WINDOW_S = 3.0


def test_node_streams_the_offline_views_to_a_viewer_while_publishing(tmp_path):
    """The node with ``rerun_url`` set: a viewer-side endpoint started here gets the views."""
    from mech_balance.bench import node as bench_node
    domain = int(os.environ.get('ROS_DOMAIN_ID', '53'))
    port = bench_node.free_port()
    saved = tmp_path / 'live.rrd'
    viewer = bench_node.viewer_endpoint(saved, port)
    try:
        base = bench_node.run_node('hoeken', LIVE_RATE_HZ, LIVE_WINDOW_S, domain=domain)
        live = bench_node.run_node(
            'hoeken', LIVE_RATE_HZ, LIVE_WINDOW_S, domain=domain,
            params=(f'rerun_url:=rerun+http://127.0.0.1:{port}/proxy',))
    finally:
        viewer.send_signal(signal.SIGINT)
        try:
            viewer.wait(timeout=20)
        except subprocess.TimeoutExpired:
            viewer.kill()
    assert f'streaming the views to rerun+http://127.0.0.1:{port}/proxy' in live['log']
    got = recording.read_recording(saved)
    offline_path = tmp_path / 'offline.rrd'
    recording.record(offline_path, scene_mod.load('hoeken'))
    offline = recording.read_recording(offline_path)
    # the same views, but the plots over time instead of over the crank angle
    over_angle = {p for p in offline if p.startswith('/by_angle/')}
    assert over_angle and set(offline) - over_angle <= set(got), set(offline) - set(got)
    assert got['/plots/shaking_force/original'].rows >= 10
    assert got['/original/labels'].rows == got['/rig/links'].rows
    # publishing goes on with the live view (the rate itself is measured by `mech-balance
    # bench`, section live_view_section: a test checks behaviour, the bench checks speed)
    assert base['rate_hz'] > 0 and live['rate_hz'] > 0, (base['rate_hz'], live['rate_hz'])


def test_a_new_series_is_plotted_with_no_recording_change(tmp_path):
    """kinetic_energy, asked for in the scene's outputs, gets its plot from RigData.series."""
    data, source = scene_mod.load_data('hoeken')
    data['outputs'] = ['kinematics', 'shaking_wrench', 'driving_torque', 'kinetic_energy']
    sc = scene_mod.from_dict(data, source=str(source))
    path = tmp_path / 'ke.rrd'
    summary = recording.record(path, sc, samples=90)
    ent = recording.read_recording(path)
    got = np.array([r[0] for r in ent['/plots/kinetic_energy/original'].columns[
        'Scalars:scalars']])
    psi = recording.turn_angles(90, sc.crank_speed_rad_s)
    want = rig_for(sc).at(psi, outputs=('kinetic_energy',)).series['kinetic_energy']
    assert_allclose(got, want, rtol=1e-12, atol=0.0)
    assert '/plots/kinetic_energy/original' in summary.entity_paths
    names = [v['name'] for v in recording.read_blueprint(path)
             if v['origin'].startswith('/by_angle/')]
    assert any(n.startswith('kinetic energy') and n.endswith('(J)') for n in names), names
    assert 'kinetic energy' in ent['/info'].static['TextDocument:text'][0]


SAME_PLACE_PX = 1.0
"""Two drawn points closer than this on screen are one place (a joint on a frame pivot)."""


def _label_rows(ent, variant, dim):
    labels = ent[f'/{variant}/labels'].columns
    texts = labels[next(c for c in labels if c.endswith(':labels'))]
    return zip(_positions(ent, f'/{variant}/labels', dim), texts)


def _strip_rows(ent, path, dim):
    comp = next(c for c in ent[path].columns if c.endswith(':strips'))
    return [[np.pad(np.array(s, dtype=float).reshape(-1, dim), ((0, 0), (0, 3 - dim)))
             for s in row] for row in ent[path].columns[comp]]


def _segment_distance(p, strip):
    """Return the distance (px) from point ``p`` (2,) to a polyline ``(k, 2)``."""
    if len(strip) == 1:
        return float(np.linalg.norm(p - strip[0]))
    a, b = strip[:-1], strip[1:]
    ab = b - a
    t = np.clip(np.einsum('ij,ij->i', p - a, ab) / np.maximum(
        np.einsum('ij,ij->i', ab, ab), 1e-300), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))


def _label_centre(anchor_px, text):
    x0, y0, x1, y1 = recording.label_box_px(anchor_px, text)
    return np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])


@pytest.mark.parametrize('name', ALL)
def test_every_label_is_nearer_its_own_point_than_any_other(recordings, name):
    """
    Issue 23 3.1: at every sample, every point label is nearer its own point than any other.

    The points are everything drawn as a dot (frame pivots, joints, mass centres); a link's
    name is nearer its own link than any other link.  Distances from the label box's centre,
    on screen at the default window.
    """
    _, _, _, summary, ent, blueprint = recordings[name]
    layout = summary.layout
    dim = layout.dim
    views = _rig_views(blueprint)
    pivots = np.pad(np.array(ent['/rig/pivots'].static[f'Points{dim}D:positions'],
                             dtype=float).reshape(-1, dim), ((0, 0), (0, 3 - dim)))
    joints = _positions(ent, '/rig/joints', dim)
    links = _strip_rows(ent, '/rig/links', dim)
    point_names = {}
    for i, n in enumerate(layout.frame_names):
        point_names.setdefault(n, []).append(('pivot', i))
    for i, n in enumerate(layout.joint_names):
        point_names.setdefault(n, []).append(('joint', i))
    checked = 0
    for variant in layout.variants:
        screen = _screen(views[variant], layout, variant)
        centres = _positions(ent, f'/{variant}/mass_centres', dim)
        tiers = _tiers(summary, variant)
        for k, (anchors, words) in enumerate(_label_rows(ent, variant, dim)):
            dots = {'pivot': screen.px(pivots), 'joint': screen.px(joints[k]),
                    'centre': screen.px(centres[k])}
            every = np.concatenate(list(dots.values()))
            strips = [screen.px(s) for s in links[k]]
            for anchor, text, tier in zip(screen.px(anchors), words, tiers[k]):
                if tier >= NAMES_OTHER:
                    continue                # no clean place at this sample
                c = _label_centre(anchor, text)
                if text in layout.link_names:
                    i = layout.link_names.index(text)
                    own = _segment_distance(c, strips[i])
                    other = min([_segment_distance(c, s) for j, s in enumerate(strips)
                                 if j != i] or [math.inf])
                    assert own < other, (variant, k, text, own, other)
                    checked += 1
                    continue
                if text == 'CoM':
                    mine = dots['centre'][-1:]
                else:
                    parts = [point_names.get(t, []) for t in text.split('/')]
                    if not all(parts):
                        continue                  # readout, scale, gauge: no point
                    mine = np.array([dots[kind][i] for p in parts for kind, i in p])
                d_own = float(np.min(np.linalg.norm(mine - c, axis=1)))
                same = np.min(np.linalg.norm(every[:, None] - mine[None], axis=-1),
                              axis=1) <= SAME_PLACE_PX
                others = np.linalg.norm(every[~same] - c, axis=1)
                assert others.size == 0 or d_own < others.min(), \
                    (variant, k, text, d_own, float(others.min()))
                checked += 1
    assert checked > 0


def test_counterweights_in_their_links_colour_with_mass_labels_and_planes(recordings):
    """Issue 23 3.2: each disc in its link's colour, its mass in kg on it, its plane drawn."""
    sc, cw, _, summary, ent, _ = recordings['hoeken_cw']
    layout = summary.layout
    discs = [(lk.name, d) for lk in cw.links for d in lk.counterweights]
    colours = ent['/balanced/counterweights'].static['Points2D:colors']
    for (link, _), rgba in zip(discs, colours):
        rgb = layout.link_colors[layout.link_names.index(link)]
        assert tuple((rgba >> s) & 255 for s in (24, 16, 8)) == rgb, link
        assert 0 < (rgba & 255) < 255                               # see-through
    texts = {t for row in ent['/balanced/labels'].columns['Points2D:labels'] for t in row}
    for _, d in discs:
        assert any(t.startswith(f'{d.mass_kg:.3g} kg') for t in texts), (d.mass_kg, texts)
    # the plane ring: around the disc's centre at PLANE_RING_SHARE of its radius, every row
    rings = ent['/balanced/counterweight_planes'].columns['LineStrips2D:strips']
    centres = np.array(ent['/balanced/counterweights'].columns['Points2D:positions'])
    assert len(rings) == summary.rows
    for k in (0, summary.rows // 3):
        for j, (_, d) in enumerate(discs):
            r = np.linalg.norm(np.array(rings[k][j]) - centres[k, j], axis=1)
            assert_allclose(r, drawing.PLANE_RING_SHARE * d.radius_m, rtol=1e-5)
    assert '/original/counterweight_planes' not in ent


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank', 'carpet_scraper'])
def test_a_redistribution_design_shows_what_it_changed(recordings, name):
    """Issue 23 3.2: a line from the link to its moved mass centre, labelled with the kg."""
    sc, bal, _, summary, ent, _ = recordings[name]
    layout = summary.layout
    moved = layout.changes['balanced']
    assert moved and not layout.changes['original']
    stalks = ent['/balanced/mass_changes'].columns['LineStrips2D:strips']
    centres = _positions(ent, '/balanced/mass_centres', 2)
    links = _strip_rows(ent, '/rig/links', 2)
    rows = ent['/balanced/labels'].columns['Points2D:labels']
    original = {b.name: b for b in rig_for(sc).drawing.bodies}
    asked = {s.text for s in layout.labels if s.where == 'change'}
    for j, (i, dm) in enumerate(moved):
        name_i = layout.link_names[i]
        b = next(b for b in rig_for(bal).drawing.bodies if b.name == name_i)
        change = b.mass_kg - original[name_i].mass_kg
        assert dm == change or (dm == 0.0 and abs(change) <= 1e-6 * b.mass_kg)
        shift = np.linalg.norm(np.subtract(b.mass_centre_m, original[name_i].mass_centre_m))
        want = f'{dm:+.3g} kg' if dm else f'moved {shift * 1e3:.0f} mm'   # kept mass: how far
        assert want in asked
        assert all(want in row for row in rows)     # the same label at every sample
        for k in (0, summary.rows // 2):
            a, c = np.array(stalks[k][j], dtype=float)
            assert_allclose(c, centres[k][i, :2], atol=FLOAT32_ATOL_M)   # ends at the centre
            link = links[k][i][:, :2]
            assert _segment_distance(a, link) <= FLOAT32_ATOL_M           # starts on the link


LINE_SAMPLES = 200
"""Points per drawn segment at which the no-line-through-a-label test looks."""
BOX_SHRINK_PX = 0.5
"""A line may touch a label box's edge by this much (float32 positions)."""


@pytest.mark.parametrize('name', ALL)
def test_no_drawn_line_passes_through_a_label(recordings, name):
    """Issue 23 3.6: no link and no frame line crosses a label box, at any sample."""
    _, _, _, summary, ent, blueprint = recordings[name]
    layout = summary.layout
    dim = layout.dim
    views = _rig_views(blueprint)
    links = _strip_rows(ent, '/rig/links', dim)
    frame = []
    if '/rig/frame' in ent:
        comp = next(c for c in ent['/rig/frame'].static if c.endswith(':strips'))
        frame = [np.pad(np.array(s, dtype=float).reshape(-1, dim), ((0, 0), (0, 3 - dim)))
                 for s in ent['/rig/frame'].static[comp]]
    t = np.linspace(0.0, 1.0, LINE_SAMPLES)[:, None]
    for variant in layout.variants:
        screen = _screen(views[variant], layout, variant)
        tiers = _tiers(summary, variant)
        for k, (anchors, words) in enumerate(_label_rows(ent, variant, dim)):
            dense = []
            for strip in links[k] + frame:
                px = screen.px(strip)
                for a, b in zip(px[:-1], px[1:]):
                    dense.append(a + t * (b - a))
            if not dense:
                continue
            dense = np.concatenate(dense)
            for anchor, text, tier in zip(screen.px(anchors), words, tiers[k]):
                if tier >= CROSSED:
                    continue
                x0, y0, x1, y1 = recording.label_box_px(anchor, text)
                s = BOX_SHRINK_PX
                inside = (dense[:, 0] > x0 + s) & (dense[:, 0] < x1 - s) & \
                    (dense[:, 1] > y0 + s) & (dense[:, 1] < y1 - s)
                assert not inside.any(), (variant, k, text)


@pytest.mark.parametrize('chunk', [1, 3, 4, 50])
def test_first_place_finds_the_first_place_of_the_full_test(chunk):
    """The lazy label test picks, per sample, the first place the full test would."""
    from mech_balance.viz import hits
    rng = np.random.default_rng(7)
    for share in (0.05, 0.3, 0.9):
        cheap = rng.random((200, 37)) < 0.6
        costly = rng.random((200, 37)) < share
        calls = []

        def cheap_check(rows, cols):
            return cheap[np.ix_(rows, cols)]

        def costly_check(rows, cols):
            calls.append(len(rows))
            assert cheap[rows, cols].all()   # only places that passed the cheap test
            return costly[rows, cols]

        first = hits.first_place(200, 37, cheap_check, costly_check, chunk=chunk)
        full = cheap & costly
        found = full.any(axis=1)
        assert np.array_equal(first >= 0, found)
        assert np.array_equal(first[found], np.argmax(full, axis=1)[found])
        assert sum(calls) <= cheap.sum()


RIG_VIEW_SHARE = 0.6
"""A 3-D rig's picture spans at least this share of its view's width or height."""
CRANK_PX = 40.0
"""rssr_skew's 30 mm crank is at least this long on screen at every sample."""


def test_a_3d_rig_is_framed_on_its_own_grid(tmp_path):
    """Read back: the grid on z = 0 covers the rig, no more than a line beyond; the eye fills."""
    sc = scene_mod.load('rssr_skew')
    path = tmp_path / 'rssr.rrd'
    summary = recording.record(path, sc, samples=60)
    layout = summary.layout
    ent = recording.read_recording(path)
    assert '/rig/grid' in recording.furniture_paths(layout)
    lines = np.array(ent['/rig/grid'].static['LineStrips3D:strips'], dtype=float)
    assert lines.shape[1:] == (2, 3) and np.all(lines[..., 2] == 0.0)
    spacing = layout.grid_m
    assert_allclose(lines[..., :2] / spacing, np.round(lines[..., :2] / spacing), atol=1e-4)
    x0, y0 = lines[..., :2].reshape(-1, 2).min(axis=0)
    x1, y1 = lines[..., :2].reshape(-1, 2).max(axis=0)
    rows = _strip_rows(ent, '/rig/links', 3)
    drawn = np.concatenate([np.concatenate(row) for row in rows])
    lo, hi = drawn.min(axis=0), drawn.max(axis=0)
    margin = FLOAT32_ATOL_M
    assert x0 <= lo[0] + margin and y0 <= lo[1] + margin     # covers the rig
    assert x1 >= hi[0] - margin and y1 >= hi[1] - margin
    # ... and ends within a margin line and a rounding step of it (not to the horizon, not
    # under the gauge); the rig's extent also holds the frame's axes and the mass centres
    beyond = max(lo[0] - x0, lo[1] - y0, x1 - hi[0], y1 - hi[1])
    assert beyond <= (layout_mod.GRID_MARGIN_LINES + 1) * spacing + 0.25 * layout.size_m
    view = next(v for v in recording.read_blueprint(path) if v['kind'] == '3D')
    target = np.array(view['eye']['look_target'])
    assert x0 <= target[0] <= x1 and y0 <= target[1] <= y1   # the camera looks at the rig
    screen = _screen(view, layout, 'original')
    px = screen.px(drawn)
    w, h = screen.size_px
    assert np.all((px >= -EDGE_TOL_PX) & (px <= np.array([w, h]) + EDGE_TOL_PX))
    # the rig fills its view (it filled about 40 % of it, beside a gauge as large as itself)
    span = np.ptp(px, axis=0) / np.array([w, h])
    assert span.max() >= RIG_VIEW_SHARE, span
    # the 30 mm crank (A-B, the first link) reads at every sample
    crank = [screen.px(np.asarray(row[0], dtype=float)) for row in rows]
    assert min(float(np.linalg.norm(c[-1] - c[0])) for c in crank) >= CRANK_PX
    # the gauge's arrows stand beside the rig's picture, never over it
    tips = np.concatenate([layout.gauge_m + np.array(a, dtype=float).reshape(-1, 3)
                           for a in ent['/original/shaking_force'].columns[
                               'Arrows3D:vectors']])
    g = screen.px(tips)
    assert np.any(g.min(axis=0) > px.max(axis=0)) or np.any(g.max(axis=0) < px.min(axis=0))


def test_a_prismatic_input_reads_its_slide_and_driving_force(tmp_path):
    """pssr_skew's input slides: each view reads the slide (mm) and its design's force."""
    from mech_balance.schema.spatial import stroke_law
    sc = scene_mod.load('pssr_skew')
    bal, source = cli_record.balanced_design(sc)
    path = tmp_path / 'pssr.rrd'
    recording.record(path, sc, bal, samples=36, balanced_source=source)
    ent = recording.read_recording(path)
    psi = recording.turn_angles(36, sc.crank_speed_rad_s)
    for v, design in (('original', sc), ('balanced', bal)):
        force = rig_for(design).at(psi, outputs=('driving_torque',)).series['driving_force']
        labels = ent[f'/{v}/labels'].columns
        rows = labels[next(c for c in labels if c.endswith(':labels'))]
        for k, row in enumerate(rows):
            slide = stroke_law(sc.crank_stroke_m, psi[k])[0]
            want = f'slide {slide * 1e3:.1f} mm, force {force[k]:+.3g} N'
            assert want in row, (v, k, row)
            assert not any(t.startswith('crank ') for t in row)


BUILT_INS = tuple(sorted(p.stem for p in (Path(__file__).resolve().parent.parent / 'config')
                         .glob('*.yaml') if p.stem != 'rig_params'))
CLEAN_SHARE = 0.75
"""At least this share of a view's labels stands at a clean place (tier 1) over the turn."""


@pytest.mark.parametrize('name', BUILT_INS)
def test_every_link_is_labelled_at_every_sample(tmp_path, name):
    """
    Issue 31 item 8: no label drops out from frame to frame, on every built-in.

    Read back: at every sample each rig view (or the inset zoomed on a crowded core) names
    every link and every moving joint, the readout says the crank angle or a prismatic
    input's slide and force, and a design's mass changes read the same at every sample.
    """
    sc = scene_mod.load(name)
    balanced, source = cli_record.balanced_design(sc)
    path = tmp_path / f'{name}.rrd'
    summary = recording.record(path, sc, balanced, samples=60, balanced_source=source)
    layout = summary.layout
    ent = recording.read_recording(path)
    dim = layout.dim
    inset = [set()] * summary.rows
    if '/inset/labels' in ent:
        inset = [set(r) for r in ent['/inset/labels'].columns[f'Points{dim}D:labels']]
    prismatic = getattr(sc, 'crank_stroke_m', None) is not None
    changes = {s.text for s in layout.labels if s.where == 'change'}
    assert not {t for t in changes if t in ('moved 0 mm', '+0 kg', '-0 kg')}
    for v in layout.variants:
        rows = ent[f'/{v}/labels'].columns[f'Points{dim}D:labels']
        assert len(rows) == summary.rows
        for k, row in enumerate(rows):
            names = {n for t in set(row) | inset[k] for n in t.split('/')}
            assert set(layout.link_names) <= names, (v, k, set(layout.link_names) - names)
            joints = np.array(_positions(ent, '/rig/joints', dim))
            moving = [n for n, d in zip(layout.joint_names, np.ptp(joints, axis=0).max(-1))
                      if d > 1e-6]
            assert set(moving) <= names, (v, k, set(moving) - names)
            readout = row[0]
            if prismatic:
                assert readout.startswith('slide ') and ' mm, force ' in readout, readout
            else:
                assert readout.startswith('crank ') and readout.endswith(' deg'), readout
            if v == 'balanced':
                assert changes <= set(row), (k, changes - set(row))
        tiers = summary.layout.placed[v][4]
        assert np.mean(tiers == 1) >= CLEAN_SHARE and not np.any(tiers == 5), \
            (v, np.bincount(tiers))
