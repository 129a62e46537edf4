"""
Collisions where they happen: the witness points of the clearance and the recording's marks.

The witness points are held against the rig's own body poses (:meth:`Rig.at` ``.bodies``)
and the drawn sizes; the recording is read back with rerun's loader and its collision marks
held against the discs' overlap computed from those poses alone.
"""

import json
import math

from mech_balance import schema as scene
from mech_balance.analysis import clearance
from mech_balance.balancing import counterweights as cw
from mech_balance.cli import main as cli
from mech_balance.core.rig import rig_for
from mech_balance.viz import collisions, recording
import numpy as np
import pytest

SAMPLES = 36
DISCS = ('crank counterweight 1', 'rocker counterweight 1')


@pytest.fixture(scope='module')
def colliding():
    """Hoeken's convex optimum as is (--no-clearance): its discs overlap each other."""
    sc = scene.load('hoeken')
    return sc, cw.balance_with_counterweights(sc, 'crank,rocker', clearance_margin_m=None)


def _pose(sc, design, body, psi):
    """Return (origin, rotation) of a body at crank angles psi (complex; the rig's poses)."""
    poses = rig_for(sc).with_scene(design).at(np.atleast_1d(psi)).bodies
    k = poses.names.index(body)
    rot = poses.rotation[:, k]
    return poses.origin_m[:, k, 0] + 1j * poses.origin_m[:, k, 1], rot[:, 0, 0] + 1j * rot[:, 1, 0]


def _segment_distance(p, a, b):
    t = np.linspace(0.0, 1.0, 20001)
    return float(np.min(np.abs(p - (a + t * (b - a)))))


def test_witness_points_lie_on_both_surfaces_and_span_the_overlap(colliding):
    sc, result = colliding
    bodies = {b.name: b for b in clearance.bodies(rig_for(result.balanced_scene))}
    clear = result.clearance
    assert clear.collisions
    for c in clear.collisions:
        pa, pb = np.array(c.point_a_m), np.array(c.point_b_m)
        # overlapping in the plane: the witness points are the overlap's depth apart
        assert math.hypot(*(pa[:2] - pb[:2])) == pytest.approx(-c.clearance_m, abs=1e-9)
        psi = math.radians(c.crank_angle_deg)
        for point, name in ((pa, c.body_a), (pb, c.body_b)):
            body = bodies[name]
            o, r = _pose(sc, result.balanced_scene, body.link, psi)
            a, b = o[0] + r[0] * body.a, o[0] + r[0] * body.b
            # on the surface of its own body (to the sampled segment's resolution)
            d = _segment_distance(complex(*point[:2]), a, b)
            assert d == pytest.approx(body.radius_m, abs=1e-6 * max(abs(b - a), 1e-3))
            lo, hi = body.z_m - 0.5 * body.thickness_m, body.z_m + 0.5 * body.thickness_m
            assert lo - 1e-12 <= point[2] <= hi + 1e-12
    as_json = clear.to_dict()['collisions'][0]
    assert len(as_json['point_a_m']) == 3 and len(as_json['point_b_m']) == 3


def test_segment_witness_against_sampled_segments():
    rng = np.random.default_rng(29)
    for _ in range(200):
        a1, b1, a2, b2 = rng.normal(size=4) + 1j * rng.normal(size=4)
        q1, q2 = clearance.segment_witness(a1, b1, a2, b2)
        d = clearance.segment_distance(a1, b1, a2, b2)
        assert abs(q1 - q2) == pytest.approx(float(d), abs=1e-12)
        t = np.linspace(0.0, 1.0, 401)   # the sampled minimum bounds the true one from above
        brute = np.min(np.abs((a1 + t[:, None] * (b1 - a1)) - (a2 + t[None, :] * (b2 - a2))))
        assert abs(q1 - q2) <= brute + 1e-12
        assert _segment_distance(q1, a1, b1) <= 1e-4 and _segment_distance(q2, a2, b2) <= 1e-4


def _disc_overlap(sc, design, psi):
    """Return the depth of the two Hoeken discs' overlap at crank angles psi (<= 0: apart)."""
    centres, radii = [], []
    for name in ('crank', 'rocker'):
        (disc,) = design.link(name).counterweights
        o, r = _pose(sc, design, name, psi)
        centres.append(o + r * complex(*disc.centre_m))
        radii.append(disc.radius_m)
    return radii[0] + radii[1] - np.abs(centres[0] - centres[1]), centres, radii


def test_recording_marks_the_collision_at_its_angles(colliding, tmp_path, capsys):
    sc, result = colliding
    out = tmp_path / 'colliding.rrd'
    assert cli.main(['record', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--no-clearance', '--samples', str(SAMPLES), '--out', str(out)]) == 0
    err = capsys.readouterr().err
    warned = [x for x in err.splitlines() if x.startswith('warning: collision')]
    assert warned and len(warned) == len(set(warned)) == len(result.clearance.collisions)
    ent = recording.read_recording(out)
    marks = ent[collisions.POINTS_PATH]
    assert marks.rows == SAMPLES and ent[collisions.BODIES_PATH].rows == SAMPLES
    assert tuple(marks.static['Points2D:colors'][0].to_bytes(4, 'big')[:3]) == \
        collisions.COLLISION_COLOR
    psi = np.radians(marks.index['crank_angle'])
    depth, centres, radii = _disc_overlap(sc, result.balanced_scene, psi)
    pair = f'{DISCS[0]} / {DISCS[1]}'
    for k in range(SAMPLES):
        labels = marks.columns['Points2D:labels'][k] or []
        shown = [i for i, text in enumerate(labels) if text.startswith(pair)]
        # the discs share the links' planes: marked exactly where they overlap
        assert bool(shown) == (depth[k] > 0.0), (k, depth[k])
        if not shown:
            continue
        (i,) = shown
        point = complex(*marks.columns['Points2D:positions'][k][i])
        # midway between the witness points: on the line of centres, half the depth in
        u = (centres[1][k] - centres[0][k]) / abs(centres[1][k] - centres[0][k])
        expected = centres[0][k] + u * (radii[0] - 0.5 * depth[k])
        assert abs(point - expected) == pytest.approx(0.0, abs=1e-6)   # float32 positions
        assert f'overlap {depth[k] * 1e3:.3g} mm' in labels[i]
    # the worst angle of the report (173.19 deg) lies between two marked samples
    least = result.clearance.least
    assert {least.body_a, least.body_b} == set(DISCS)
    k = int(least.crank_angle_deg // (360 / SAMPLES))
    assert depth[k] > 0.0 and depth[(k + 1) % SAMPLES] > 0.0


def test_collision_free_design_has_no_marks(tmp_path, capsys):
    out = tmp_path / 'clear.rrd'
    assert cli.main(['record', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--samples', str(SAMPLES), '--out', str(out)]) == 0
    assert 'warning' not in capsys.readouterr().err
    ent = recording.read_recording(out)
    assert '/balanced/counterweights' in ent
    assert collisions.POINTS_PATH not in ent and collisions.BODIES_PATH not in ent


def test_record_and_balance_agree_on_the_design_and_its_clearance(tmp_path, capsys):
    """The discs recorded are those balance prints, with the least clearance it prints."""
    argv = ['--scene', 'hoeken', '--counterweights', 'crank,rocker', '--weights', '1', '0']
    assert cli.main(['balance', *argv, '--json']) == 0
    report = json.loads(capsys.readouterr().out)['report']
    out = tmp_path / 'a.rrd'
    assert cli.main(['record', *argv, '--samples', str(SAMPLES), '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    least = report['clearance']['least']
    assert f"least clearance {least['clearance_m'] * 1e3:.4g} mm" in printed
    assert f"{least['body_a']} and {least['body_b']} at crank angle " \
        f"{least['crank_angle_deg']:.2f} deg" in printed
    radii = recording.read_recording(out)['/balanced/counterweights'].static['Points2D:radii']
    assert sorted(radii) == pytest.approx(sorted(d['radius_m'] for d in report['designs']),
                                          rel=1e-6)   # float32


def test_record_clearance_options_are_checked(tmp_path, capsys):
    rrd = str(tmp_path / 'x.rrd')
    assert cli.main(['record', '--clearance-margin', '0.01', '--out', rrd]) == 2
    assert '--clearance-margin applies with --counterweights or --design' in \
        capsys.readouterr().err
    assert cli.main(['record', '--counterweights', 'crank', '--no-clearance',
                     '--clearance-margin', '0.01', '--out', rrd]) == 2
    assert '--clearance-margin: no clearance' in capsys.readouterr().err
    assert cli.main(['record', '--counterweights', 'crank', '--clearance-margin', '-1',
                     '--out', rrd]) == 2
    assert '--clearance-margin' in capsys.readouterr().err
