"""
Collision-free counterweights (issue 29): every built-in, three weightings, checked in 3-D.

The design's clearance is held against an independent check that shares with the package
only the scene, the drawn sizes (:mod:`mech_balance.core.planar.drawn`) and the rig's body
poses (:meth:`Rig.at` ``.bodies``): every body is a prism along z (a disc, a bar, a pin, a
shaft, a web), its outline a capsule in the plane (a segment and a radius; the distance of
two is that of their segments less both radii), its slab along z rebuilt from the layer
rule, over 3600 crank angles.  The price of clearance is held against the certificate.
"""

import math

from mech_balance import schema as scene
from mech_balance.balancing import clearance_design, counterweights as cw
from mech_balance.cli import main as cli
from mech_balance.core.planar import drawn
from mech_balance.core.rig import rig_for
from mech_balance.schema.planar import planar_from_dict, planar_to_dict
import numpy as np
import pytest
from test_clearance_spatial import segment_distance

ANGLES = 3600
"""Crank angles of the independent check."""
WEIGHTS = ((1.0, 0.0), (0.5, 0.5), (0.0, 1.0))
CASES = (('hoeken', 'crank,rocker'), ('hoeken', 'crank,coupler,rocker'),
         ('slider_crank', 'crank,rod'), ('slider_crank_stiff', 'crank,rod'),
         ('carpet_scraper', 'crank'), ('carpet_scraper', 'crank,rocker'))
"""Every built-in that takes counterweights (kind planar), with the links of its examples."""
MARGIN = clearance_design.DEFAULT_CLEARANCE_MARGIN_M


def segment_gap(a1, b1, a2, b2):
    """
    Return the distances of the segments ``a1``-``b1`` from ``a2``-``b2`` in the plane.

    Zero where they cross; else the least distance of an end from the other segment.
    """
    def side(o, d, p):   # the z component of d x (p - o)
        return d[:, 0] * (p[:, 1] - o[:, 1]) - d[:, 1] * (p[:, 0] - o[:, 0])

    d1, d2 = b1 - a1, b2 - a2
    cross = (side(a2, d2, a1) * side(a2, d2, b1) < 0.0) & \
        (side(a1, d1, a2) * side(a1, d1, b2) < 0.0)
    ends = np.minimum(np.minimum(segment_distance(a1, a2, b2), segment_distance(b1, a2, b2)),
                      np.minimum(segment_distance(a2, a1, b1), segment_distance(b2, a1, b1)))
    return np.where(cross, 0.0, ends)


def _solids(sc):
    """Return the solids as built: ``(name, link, a, b, r, z_lo, z_hi, kind, exempt)``."""
    rig = rig_for(sc)
    scale = rig.linkage.length_scale
    names = ['frame'] + [lk.name for lk in sc.links]
    points = {'frame': sc.frame_points, **{lk.name: lk.points for lk in sc.links}}
    t_bar, w_bar = drawn.BAR_THICKNESS * scale, drawn.BAR_WIDTH * scale
    r_pin, boss = drawn.PIN_RADIUS * scale, drawn.PIN_LENGTH * drawn.BAR_THICKNESS * scale
    z = {n: drawn.LAYER * scale * k for k, n in enumerate(names)}
    half = 0.5 * max(t_bar, boss)
    out = []
    for n in names:
        pts = {k: np.array(v, float) for k, v in points[n].items()}
        edges = drawn.bar_edges({k: complex(*v) for k, v in pts.items()})
        for p, q in edges:
            if not np.allclose(pts[p], pts[q]):
                out.append((f'{n} bar {p}-{q}', n, pts[p], pts[q], 0.5 * w_bar,
                            z[n] - 0.5 * t_bar, z[n] + 0.5 * t_bar, 'bar', ()))
        for k, p in pts.items():
            out.append((f'{n} boss {k}', n, p, p, r_pin, z[n] - 0.5 * boss, z[n] + 0.5 * boss,
                        'boss', ()))
    for jt in sc.joints:
        if jt.joint_type != 'revolute':
            continue
        p = np.array(points[jt.link_a][jt.point_a], float)
        lo = min(z[jt.link_a], z[jt.link_b]) - half
        hi = max(z[jt.link_a], z[jt.link_b]) + half
        out.append((f'pin {jt.name}', jt.link_a, p, p, r_pin, lo, hi, 'pin', ()))
    for lk in sc.links:
        for i, c in enumerate(lk.counterweights):
            zc = z[lk.name] + c.plane_m
            centre = np.array(c.centre_m, float)
            label = f'{lk.name} counterweight {i + 1}'
            out.append((label, lk.name, centre, centre, c.radius_m, zc - 0.5 * c.thickness_m,
                        zc + 0.5 * c.thickness_m, 'disc', ()))
            if c.plane_m == 0.0:
                continue
            mount = c.mount or min(lk.points, key=lambda k: np.hypot(
                *(np.array(lk.points[k]) - centre)))
            m = np.array(lk.points[mount], float)
            s = math.copysign(1.0, c.plane_m)
            ends = sorted([z[lk.name] + s * 0.5 * t_bar, zc - s * 0.5 * c.thickness_m])
            # the shaft runs through the bearing of the link(s) jointed at its mount
            exempt = set()
            for jt in sc.joints:
                for (la, pa), (lb, pb) in (((jt.link_a, jt.point_a), (jt.link_b, jt.point_b)),
                                           ((jt.link_b, jt.point_b), (jt.link_a, jt.point_a))):
                    if (la, pa) == (lk.name, mount) and jt.joint_type == 'revolute':
                        at = np.array(points[lb][pb], float)
                        exempt.add(f'pin {jt.name}')
                        exempt.update(x for x in [f'{lb} boss {k}' for k, v in
                                                  points[lb].items() if np.allclose(v, at)])
                        exempt.update(f'{lb} bar {p}-{q}' for p, q in drawn.bar_edges(
                            {k: complex(*v) for k, v in points[lb].items()})
                            if np.allclose(points[lb][p], at) or np.allclose(points[lb][q], at))
            out.append((f'{label} shaft', lk.name, m, m, r_pin, ends[0], ends[1], 'shaft',
                        tuple(exempt)))
            if not np.allclose(m, centre):
                out.append((f'{label} web', lk.name, m, centre, 0.5 * w_bar,
                            zc - 0.5 * c.thickness_m, zc + 0.5 * c.thickness_m, 'web', ()))
    return out


def least_clearance_3d(sc, margin):
    """
    Return ``(clearance, pair)``: the least 3-D clearance of a counterweight body.

    Over 3600 angles; pairs whose slabs lie ``margin`` or more apart along z are clear by
    that much.
    """
    solids = _solids(sc)
    psi = np.linspace(0.0, 2.0 * np.pi, ANGLES, endpoint=False)
    poses = rig_for(sc).at(psi).bodies
    k_of = {n: i for i, n in enumerate(poses.names)}
    best = (math.inf, None)
    added = ('disc', 'shaft', 'web')

    def world(link, pts):
        k = k_of[link]
        r, o = poses.rotation[:, k, :2, :2], poses.origin_m[:, k, :2]
        x = o[:, 0, None] + r[:, 0, 0, None] * pts[:, 0] + r[:, 0, 1, None] * pts[:, 1]
        y = o[:, 1, None] + r[:, 1, 0, None] * pts[:, 0] + r[:, 1, 1, None] * pts[:, 1]
        return np.stack([x, y], axis=-1)

    cache = {}

    def placed(s):
        if s[0] not in cache:
            cache[s[0]] = (world(s[1], s[2][None])[:, 0], world(s[1], s[3][None])[:, 0])
        return cache[s[0]]

    for i, s1 in enumerate(solids):
        for s2 in solids[i + 1:]:
            if s1[1] == s2[1] or not (s1[7] in added or s2[7] in added) \
                    or s2[0] in s1[8] or s1[0] in s2[8]:
                continue
            gap = max(s1[5], s2[5]) - min(s1[6], s2[6])   # along z (negative: overlap)
            if gap >= margin:
                continue
            # the two capsules' planar clearance, exact (negative: they overlap)
            planar = segment_gap(*placed(s1), *placed(s2)).min() - s1[4] - s2[4]
            value = planar if gap <= 0.0 else math.hypot(max(planar, 0.0), gap)
            if value < best[0]:
                best = (value, (s1[0], s2[0]))
    return best


@pytest.fixture(scope='module', params=CASES, ids=['-'.join(c) for c in CASES])
def case(request):
    name, links = request.param
    sc = scene.load(name)
    out = []
    for w in WEIGHTS:
        out.append((w, cw.balance_with_counterweights(sc, links, w),
                    cw.balance_with_counterweights(sc, links, w, clearance_margin_m=None)))
    return sc, links, out


def test_default_design_is_clear_in_3d_or_says_why(case, capsys):
    sc, links, runs = case
    for w, result, _ in runs:
        report = result.clearance_design
        if report.status == 'none':
            assert not result.designs and report.binding
            assert report.least_clearance_m < report.margin_m
            argv = ['balance', '--scene', sc.name, '--counterweights', links,
                    '--weights', str(w[0]), str(w[1])]
            assert cli.main(argv) == 3
            out, err = capsys.readouterr()
            assert 'NO collision-free design' in out and 'none given' in err
            assert 'counterweights (centre' not in out      # no design printed
            continue
        assert report.status == 'collision-free'
        assert report.least_clearance_m >= MARGIN
        value, pair = least_clearance_3d(result.balanced_scene, MARGIN)
        assert value >= MARGIN - 1e-9, (w, value, pair)


def test_segment_gap_is_the_least_distance_of_two_segments():
    """The check's planar distance against 401 x 401 samples of each of 100 pairs."""
    rng = np.random.default_rng(29)
    a1, b1, a2, b2 = (rng.normal(size=(100, 2)) for _ in range(4))
    b1[0] = a1[0]   # a point (a disc's centre)
    exact = segment_gap(a1, b1, a2, b2)
    t = np.linspace(0.0, 1.0, 401)[:, None]
    for k in range(100):
        p1, p2 = a1[k] + t * (b1[k] - a1[k]), a2[k] + t * (b2[k] - a2[k])
        sampled = np.linalg.norm(p1[:, None] - p2[None], axis=-1).min()
        # the nearest points lie within half a step of a sample each
        h = 0.5 * (np.linalg.norm(b1[k] - a1[k]) + np.linalg.norm(b2[k] - a2[k])) / 400
        assert exact[k] <= sampled + 1e-12 and sampled <= exact[k] + h + 1e-12, k
    assert np.any(exact == 0.0) and np.any(exact > 0.0)   # crossing pairs and apart ones


def test_price_of_clearance_is_certified(case):
    _, _, runs = case
    for w, result, off in runs:
        report = result.clearance_design
        cert = off.certificate
        assert cert.certified
        assert report.lower_bound == pytest.approx(cert.lower_bound, rel=0, abs=0)
        assert report.lower_bound <= report.objective     # the bound holds for any design
        assert report.convex_objective == pytest.approx(off.objective['z'],
                                                        rel=10 * cert.gap_rel + 1e-12)
        if result.answered:
            assert result.objective['z'] == pytest.approx(report.objective, rel=1e-9)


def test_clearance_off_is_the_certified_optimum(case):
    """Off: the convex optimum in its links' planes; on and unmoved: the same discs."""
    _, _, runs = case
    for _, result, off in runs:
        assert off.clearance_design is None
        assert all(d.plane_m == 0.0 and d.mount == '' for d in off.designs)
        report = result.clearance_design
        if report.status == 'collision-free' and not report.moved_in_plane:
            assert [(d.link, d.mass_kg, d.centre_m, d.radius_m, d.thickness_m)
                    for d in result.designs] == \
                [(d.link, d.mass_kg, d.centre_m, d.radius_m, d.thickness_m)
                 for d in off.designs]
            assert report.price == pytest.approx(off.certificate.gap_abs, abs=1e-12)


def test_disc_side_above_pays_a_price_in_the_plane():
    """Both Hoeken discs above: the rocker's shaft crosses the crank's disc layer."""
    sc = scene.load('hoeken')
    result = cw.balance_with_counterweights(sc, 'crank,rocker', (0.5, 0.5), disc_side='above')
    report = result.clearance_design
    assert report.status == 'collision-free' and report.moved_in_plane
    assert report.price > 0.0 and report.lower_bound <= report.objective
    assert all(e['side'] == 'above' for e in report.layers)
    value, _ = least_clearance_3d(result.balanced_scene, MARGIN)
    assert value >= MARGIN - 1e-9


def test_bad_clearance_options_are_refused():
    sc = scene.load('hoeken')
    with pytest.raises(ValueError, match='clearance_margin_m: got -1'):
        cw.balance_with_counterweights(sc, 'crank', clearance_margin_m=-1.0)
    with pytest.raises(ValueError, match="disc_side: got 'left'"):
        cw.balance_with_counterweights(sc, 'crank', disc_side='left')
    with pytest.raises(ValueError, match='max_overhang_m'):
        cw.balance_with_counterweights(sc, 'crank', max_overhang_m=0.0)


def test_overhang_bound_that_prevents_every_layer_is_named(capsys):
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--max-overhang', '0.001']) == 3
    out, _ = capsys.readouterr()
    assert 'max overhang 0.001 m' in out


def test_build_section_is_validated():
    data, _ = scene.load_data('hoeken')
    data['build'] = {'bar_width_m': -1.0}
    with pytest.raises(ValueError, match='build.bar_width_m: got -1'):
        planar_from_dict(data)
    data['build'] = {'layers': {'crank': {'z_m': 0.01, 'depth': 1}}}
    with pytest.raises(ValueError, match='build.layers.crank.depth: unknown field'):
        planar_from_dict(data)
    data['build'] = {'layers': {'nope': {}}}
    with pytest.raises(ValueError, match='build.layers.nope: unknown body'):
        planar_from_dict(data)
    data['build'] = {'layer_pitch_m': 0.01, 'layers': {'crank': {'thickness_m': 0.004}}}
    sc = planar_from_dict(data)
    assert planar_from_dict(planar_to_dict(sc)).build == sc.build


# ------------------------------------------------------------------ the build sheet


def test_build_sheet_numbers_are_the_clis(tmp_path, capsys):
    """The sheet's numbers, read back from the SVG, are the CLI's JSON to the printed digits."""
    import json
    import shutil
    import subprocess
    from mech_balance.viz import build_sheet
    sheet = tmp_path / 'sheet.svg'
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--json', '--build-sheet', str(sheet)]) == 0
    report = json.loads(capsys.readouterr().out)['report']   # Design.to_dict: the method's
    values = build_sheet.read_values(sheet.read_text())
    sc = scene.load('hoeken')
    for d in report['designs']:
        name = d['link']
        link = sc.link(name)
        j, u, _ = build_sheet.link_axis(link, d['mount'])
        rel = (complex(*d['centre_m']) - j) / u
        expected = {'diameter-mm': 2e3 * d['radius_m'], 'thickness-mm': 1e3 * d['thickness_m'],
                    'along-mm': 1e3 * rel.real, 'across-mm': 1e3 * rel.imag,
                    'layer-mm': 1e3 * d['plane_m'], 'mass-kg': d['mass_kg']}
        for key, value in expected.items():
            shown, stored = values[f'{name}-{key}']
            assert stored == pytest.approx(value, rel=1e-12, abs=1e-12)
            # the printed digits: the number in the text, as the CLI's value rounded
            number = float(shown)
            digits = 0.05 if key.endswith('mm') else abs(value) * 5e-4
            assert abs(number - value) <= digits, (key, shown, value)
    assert values['total-added-mass-kg'][1] == pytest.approx(report['added_mass_kg'])
    cost = report['cost']
    assert values['force-before-N'][1] == pytest.approx(cost['shaking_force']['before'])
    assert values['moment-after-Nm'][1] == pytest.approx(cost['shaking_moment']['after'])
    assert values['least-clearance-mm'][1] == pytest.approx(
        1e3 * report['clearance']['least_clearance_m'])
    if shutil.which('rsvg-convert'):   # a real renderer reads it
        png = tmp_path / 'sheet.png'
        subprocess.run(['rsvg-convert', str(sheet), '-o', str(png)], check=True, timeout=60)
        assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_build_sheet_file_types(tmp_path, capsys):
    import shutil
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank',
                     '--build-sheet', str(tmp_path / 'sheet.txt')]) == 2
    assert '--build-sheet' in capsys.readouterr().err and not (tmp_path / 'sheet.txt').exists()
    if shutil.which('rsvg-convert'):
        for name, magic in (('sheet.pdf', b'%PDF'), ('sheet.png', b'\x89PNG')):
            assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank',
                             '--build-sheet', str(tmp_path / name)]) == 0
            assert (tmp_path / name).read_bytes().startswith(magic)


# ------------------------------------------------------------------ the recording


def test_record_draws_the_printed_design_and_marks_collisions(tmp_path, capsys):
    """Record the design balance prints; warn and mark a colliding given design."""
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank,rocker']) == 0
    printed = capsys.readouterr().out
    line = next(x for x in printed.splitlines() if x.startswith('least clearance'))
    assert cli.main(['record', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--samples', '12', '--out', str(tmp_path / 'a.rrd')]) == 0
    out, err = capsys.readouterr()
    # the same design: the same least clearance, pair and angle as balance printed
    assert line in out
    assert 'warning' not in err
    # a user-given colliding design (the convex optimum in the links' planes)
    given = tmp_path / 'colliding.yaml'
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--no-clearance', '--output', str(given)]) == 0
    capsys.readouterr()
    assert cli.main(['record', '--scene', 'hoeken', '--design', str(given), '--samples', '12',
                     '--out', str(tmp_path / 'b.rrd')]) == 0
    out, err = capsys.readouterr()
    assert 'COLLISION: crank counterweight 1 and rocker counterweight 1' in out
    warnings = [x for x in err.splitlines() if x.startswith('warning: collision')]
    assert warnings and len(warnings) == len(set(warnings))   # each once


# The spatial rigs' sphere counterweights: test_clearance_spatial.py.
