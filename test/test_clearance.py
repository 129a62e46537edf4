"""
Counterweight planes and the clearance of the bodies over the cycle (issue 19 item 5).

The clearance is held against a brute force that shares nothing with it but the scene: the
bodies are clouds of points sampled over their area, placed by the rig's body poses
(:meth:`Rig.at` ``.bodies``), and their least distance is taken over a fine grid of crank
angles.  The rim bound of the program is held against the designs it returns and against
the certificate.
"""

import json
import math
import xml.etree.ElementTree as ET

from mech_balance import schema as scene
from mech_balance.analysis import clearance
from mech_balance.balancing import counterweights as cw, redistribution
from mech_balance.cli import main as cli
from mech_balance.core.planar import drawn
from mech_balance.core.rig import rig_for
from mech_balance.ros import urdf
import numpy as np
import pytest
from scipy.spatial import cKDTree

GAP_REL = 1e-7
"""Required relative duality gap of every counterweight certificate (as test_counterweights)."""
CLOUD_POINTS = 4000
"""Points sampled on each body of the brute force."""
APART = {'crank': -0.030, 'rocker': -0.0376}
"""Hoeken disc planes with both discs at z = -26.2 mm, below every link: they share a plane
with each other (and their shafts cross the layers above them)."""


@pytest.fixture(scope='module')
def hoeken():
    return scene.load('hoeken')


@pytest.fixture(scope='module')
def default_planes(hoeken):
    """Return the certified convex optimum as is (clearance off): discs in their links' planes."""
    return cw.balance_with_counterweights(hoeken, 'crank,rocker', clearance_margin_m=None)


@pytest.fixture(scope='module')
def rim_bounded(hoeken):
    return cw.balance_with_counterweights(hoeken, 'crank,rocker', planes=APART,
                                          max_rim_radius_factor=0.5, clearance_margin_m=None)


def _cloud(centre, radius, rng, n=CLOUD_POINTS):
    """Return ``(n, 2)`` points spread uniformly over a disc (and its rim)."""
    r = radius * np.sqrt(rng.uniform(0.0, 1.0, n))
    t = rng.uniform(0.0, 2.0 * math.pi, n)
    rim = np.linspace(0.0, 2.0 * math.pi, n // 4, endpoint=False)
    pts = np.concatenate([np.stack([r * np.cos(t), r * np.sin(t)], 1),
                          radius * np.stack([np.cos(rim), np.sin(rim)], 1)])
    return pts + np.asarray(centre, dtype=float)


def _capsule_cloud(a, b, radius, rng, n=48):
    """Return points over a capsule: circles of n points (and filled discs) along a-b."""
    a, b = np.asarray(a), np.asarray(b)
    m = int(np.ceil(np.linalg.norm(b - a) / (0.25 * radius))) + 1   # circles overlap well
    s = np.linspace(0.0, 1.0, m)[:, None]
    centres = (1.0 - s) * a + s * b
    t = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    ring = radius * np.stack([np.cos(t), np.sin(t)], 1)
    inner = radius * np.sqrt(rng.uniform(0.0, 1.0, (n, 1))) * \
        np.stack([np.cos(t), np.sin(t)], 1)
    return np.concatenate([(centres[:, None, :] + ring[None]).reshape(-1, 2),
                           (centres[:, None, :] + inner[None]).reshape(-1, 2)])


def _min_distance(p, q):
    return float(cKDTree(q).query(p)[0].min())


def _disc_centres(sc, psi):
    """Return the world centres ``{link: (n, 2)}`` of the discs, from the rig's body poses."""
    poses = rig_for(sc).at(psi).bodies
    return {lk.name: poses.world(lk.name, lk.counterweights[0].centre_m)[:, :2]
            for lk in sc.links if lk.counterweights}


# ------------------------------------------------------------------ geometry


def test_segment_distance_against_point_clouds():
    rng = np.random.default_rng(19)
    for _ in range(40):
        a1, b1, a2, b2 = rng.uniform(-1.0, 1.0, (4, 2))
        r1, r2 = rng.uniform(0.01, 0.3, 2)
        got = float(clearance.segment_distance(complex(*a1), complex(*b1), complex(*a2),
                                               complex(*b2))) - r1 - r2
        p = _capsule_cloud(a1, b1, r1, rng)
        q = _capsule_cloud(a2, b2, r2, rng)
        brute = _min_distance(p, q)
        spacing = 2.0 * math.pi * max(r1, r2) / 48 + 0.25 * max(r1, r2)
        if got > 0.0:   # apart: the clouds' least distance, to their spacing
            assert got - 1e-12 <= brute <= got + spacing
        else:           # overlapping: some points of the two clouds (nearly) meet
            assert brute <= spacing


def test_segment_distance_exact_cases():
    # crossing segments, parallel ones, a point on a segment, a point off its end
    assert clearance.segment_distance(-1, 1, -1j, 1j) == 0.0
    assert clearance.segment_distance(0, 2, 1j, 2 + 1j) == pytest.approx(1.0)
    assert clearance.segment_distance(1, 1, 0, 2) == 0.0
    assert clearance.segment_distance(3 + 4j, 3 + 4j, -1, 0) == pytest.approx(5.0)


def test_bodies_have_the_drawn_sizes(hoeken):
    rig = rig_for(hoeken)
    scale = rig.linkage.length_scale
    found = {b.name: b for b in clearance.bodies(rig)}
    bar = found['coupler bar A-B']
    assert bar.radius_m == pytest.approx(0.5 * drawn.BAR_WIDTH * scale)
    assert bar.thickness_m == pytest.approx(drawn.BAR_THICKNESS * scale)
    assert bar.z_m == pytest.approx(drawn.LAYER * scale * 2)   # frame 0, crank 1, coupler 2
    boss = found['frame boss O1']
    assert boss.radius_m == pytest.approx(drawn.PIN_RADIUS * scale) and boss.z_m == 0.0
    # link bars and bosses of different links never share a plane
    assert clearance.pairs(list(found.values())) == []


# ------------------------------------------------------------------ Hoeken


def test_hoeken_discs_overlap_at_crank_zero(default_planes):
    """The issue's case: R 57.5 and 44.8 mm, centres 95 mm apart at crank 0 deg: an overlap."""
    sc = default_planes.balanced_scene
    discs = {d.link: d for d in default_planes.designs}
    assert discs['crank'].radius_m == pytest.approx(0.0575, abs=5e-4)
    assert discs['rocker'].radius_m == pytest.approx(0.0448, abs=5e-4)
    c = _disc_centres(sc, [0.0])
    d0 = float(np.linalg.norm(c['crank'][0] - c['rocker'][0]))
    assert d0 == pytest.approx(0.095, abs=1e-3)
    rig = rig_for(sc)
    body = {b.name: b for b in clearance.bodies(rig)}
    pair = clearance.pair_clearance(rig, body['crank counterweight 1'],
                                    body['rocker counterweight 1'], [0.0])[0]
    assert pair == pytest.approx(d0 - discs['crank'].radius_m - discs['rocker'].radius_m,
                                 abs=1e-12)
    assert pair < 0.0


def test_hoeken_least_disc_clearance_at_the_right_angle(default_planes):
    sc = default_planes.balanced_scene
    result = default_planes.clearance
    contact = next(c for c in result.collisions
                   if {c.body_a, c.body_b} == {'crank counterweight 1', 'rocker counterweight 1'})
    # brute force: the discs' centre distance from the body poses on a 0.01 deg grid
    psi = np.radians(np.arange(0.0, 360.0, 0.01))
    c = _disc_centres(sc, psi)
    radii = sum(d.radius_m for d in default_planes.designs)
    gap = np.linalg.norm(c['crank'] - c['rocker'], axis=1) - radii
    k = int(np.argmin(gap))
    assert contact.clearance_m == pytest.approx(gap[k], abs=1e-7)
    assert contact.crank_angle_deg == pytest.approx(math.degrees(psi[k]), abs=0.05)
    assert result.least.clearance_m <= contact.clearance_m
    line = contact.warning()
    assert 'crank counterweight 1' in line and 'rocker counterweight 1' in line
    assert f'{-gap[k] * 1e3:.3g} mm' in line
    assert f'at crank angle {contact.crank_angle_deg:.2f} deg' in line


def test_hoeken_default_planes_collide_with_the_links(default_planes):
    """A 20 mm disc in its link's plane reaches the frame's pivot O1 (it encloses it)."""
    names = {(c.body_a, c.body_b) for c in default_planes.clearance.collisions}
    assert ('frame boss O1', 'crank counterweight 1') in names
    report = default_planes.to_dict()
    assert report['clearance']['least_clearance_m'] < 0.0
    assert len(report['warnings']) == len(default_planes.clearance.collisions)
    json.dumps(report)   # plain


def test_planes_apart_and_rim_bound_give_positive_clearance(hoeken, rim_bounded):
    result = rim_bounded.clearance
    assert not result.collisions and not result.warnings()
    assert {result.least.body_a, result.least.body_b} == {'crank counterweight 1',
                                                          'rocker counterweight 1'}
    assert result.least.clearance_m > 0.0
    # the same from point clouds of the two discs over the cycle
    sc = rim_bounded.balanced_scene
    psi = np.radians(np.arange(0.0, 360.0, 1.0))
    c = _disc_centres(sc, psi)
    discs = {d.link: d for d in rim_bounded.designs}
    radii = discs['crank'].radius_m + discs['rocker'].radius_m
    gap = np.linalg.norm(c['crank'] - c['rocker'], axis=1) - radii
    k = int(np.argmin(gap))
    rng = np.random.default_rng(5)
    brute = _min_distance(_cloud(c['crank'][k], discs['crank'].radius_m, rng),
                          _cloud(c['rocker'][k], discs['rocker'].radius_m, rng))
    assert result.least.clearance_m <= gap[k] + 1e-12
    assert brute == pytest.approx(result.least.clearance_m, abs=2e-3)
    # the planes as asked, in the design, the scene and the drawing
    for d in rim_bounded.designs:
        assert d.plane_m == APART[d.link]
    link = sc.link('crank')
    assert link.counterweights[0].plane_m == APART['crank']
    added = next(b for b in rig_for(sc).drawing.bodies if b.name == 'crank').added[0]
    assert added.centre_m[2] == APART['crank']
    z = result.planes_m
    assert z['crank counterweight 1'] == pytest.approx(z['rocker counterweight 1'])


def test_planes_far_apart_share_no_plane(hoeken):
    """Discs on opposite sides: only their shafts cross layers, well clear of everything."""
    result = cw.balance_with_counterweights(hoeken, 'crank,rocker',
                                            planes='crank=-0.05, rocker=0.05',
                                            clearance_margin_m=None)
    names = {n for c in [result.clearance.least] for n in (c.body_a, c.body_b)}
    assert not result.clearance.collisions and 'crank counterweight 1 shaft' in names
    assert result.to_dict()['clearance']['least_clearance_m'] > 0.05


# ------------------------------------------------------------------ the rim bound


def test_rim_cuts_lie_below_the_exact_rim_set():
    rho = 0.7
    x = np.linspace(0.0, rho, 2001)
    f = x * x + 0.5 * (rho - x) ** 2      # dI / dm on the rim bound
    for c_h, c_m in clearance.rim_cuts(rho):
        assert c_h >= 0.0                  # convex: a cone in |dh|
        assert np.all(c_m - c_h * x <= f + 1e-15)
    assert min(c_m for _, c_m in clearance.rim_cuts(rho)) == pytest.approx(rho * rho / 3.0)


def test_rim_bound_is_enforced_and_certified(hoeken, rim_bounded):
    free = cw.balance_with_counterweights(hoeken, 'crank,rocker', planes=APART,
                                          clearance_margin_m=None)
    cert = rim_bounded.certificate
    assert cert.status == 'Solved' and cert.gap_rel <= GAP_REL
    assert cert.max_violation <= 1e-6
    assert rim_bounded.objective['z'] >= free.objective['z'] - cert.gap_abs
    active = False
    for d in rim_bounded.designs:
        rho = 0.5 * cw.joint_reach_m(hoeken, d.link)
        rim = math.hypot(*d.centre_m) + d.radius_m
        tol = max(cert.max_violation, cert.residual_primal)   # the solver's accuracy
        assert rim <= rho + tol * d.max_centre_radius_m
        # the tightest cut at the design: dI + c_h |dh| <= c_m dm
        dm, dh = d.mass_kg, d.mass_kg * math.hypot(*d.centre_m)
        d_i = d.inertia_com_kg_m2 + dm * (d.centre_m[0] ** 2 + d.centre_m[1] ** 2)
        slack = min(c_m * dm - d_i - c_h * dh for c_h, c_m in clearance.rim_cuts(rho))
        assert slack >= -tol * dm * rho * rho
        active |= slack <= 1e-6 * dm * rho * rho
    free_rims = [math.hypot(*d.centre_m) + d.radius_m for d in free.designs]
    assert max(r / (0.5 * cw.joint_reach_m(hoeken, d.link))
               for r, d in zip(free_rims, free.designs)) > 1.0   # the bound binds
    assert active
    assert rim_bounded.options.to_dict()['max_rim_radius_factor'] == 0.5


# ------------------------------------------------------------------ the scene field


def test_plane_round_trips_bit_for_bit(rim_bounded):
    text = redistribution.scene_to_yaml(rim_bounded.balanced_scene)
    back = scene.from_dict(scene.parse_yaml(text), source='<written>')
    for a, b in zip(rim_bounded.balanced_scene.links, back.links):
        assert [cw_.to_dict() for cw_ in a.counterweights] == \
            [cw_.to_dict() for cw_ in b.counterweights]
        for x, y in zip(a.counterweights, b.counterweights):
            assert x.plane_m.hex() == y.plane_m.hex()
    assert 'plane_m: -0.03' in text
    assert scene.to_yaml(back) == scene.to_yaml(scene.from_dict(
        scene.parse_yaml(scene.to_yaml(back)), source='<again>'))


def test_default_plane_is_not_written(default_planes):
    text = redistribution.scene_to_yaml(default_planes.balanced_scene)
    assert 'plane_m' not in text
    back = scene.from_dict(scene.parse_yaml(text), source='<written>')
    assert all(c.plane_m == 0.0 for lk in back.links for c in lk.counterweights)


def _disc_scene(hoeken, plane):
    data = scene.parse_yaml(scene.to_yaml(hoeken))
    link = next(lk for lk in data['links'] if lk['name'] == 'crank') \
        if isinstance(data['links'], list) else data['links']['crank']
    link['counterweights'] = [{'mass_kg': 7850.0 * math.pi * 0.02 ** 2 * 0.01,
                               'centre_m': [-0.02, 0.0], 'radius_m': 0.02,
                               'thickness_m': 0.01, 'density_kg_m3': 7850.0,
                               'plane_m': plane}]
    return data


@pytest.mark.parametrize('plane, expected', [
    ('x', 'expected a number'), (True, 'expected a number'), (math.nan, 'finite'),
    (11.0, r'within \+-10 m'), (-1e9, r'within \+-10 m')])
def test_bad_plane_is_refused_by_name(hoeken, plane, expected):
    with pytest.raises(scene.SceneError, match=r'links\.crank\.counterweights\[0\]\.plane_m: '
                                               rf'got .*{expected}'):
        scene.from_dict(_disc_scene(hoeken, plane), source='<test>')


def test_good_plane_loads_and_moves_no_mass_property(hoeken):
    near = scene.from_dict(_disc_scene(hoeken, 0.0), source='<test>')
    far = scene.from_dict(_disc_scene(hoeken, -0.25), source='<test>')
    a, b = near.link('crank'), far.link('crank')
    assert (a.mass_kg, a.com_m, a.inertia_com_kg_m2) == (b.mass_kg, b.com_m, b.inertia_com_kg_m2)
    assert b.counterweights[0].plane_m == -0.25


@pytest.mark.parametrize('planes, expected', [
    ('coupler=0.01', "link 'coupler', expected one of the counterweight links"),
    ('crank=0.01,crank=0.02', "'crank' twice"),
    ('crank', 'expected LINK=Z_M'), ('crank=abc', r"planes\.crank: got 'abc'"),
    ('crank=nan', r'planes\.crank: got nan'), ({'crank': 20.0}, r'within \+-10 m')])
def test_bad_planes_option_is_refused_by_name(hoeken, planes, expected):
    with pytest.raises(cw.CounterweightError, match=expected):
        cw.balance_with_counterweights(hoeken, 'crank,rocker', planes=planes)


def test_bad_rim_factor_is_refused(hoeken):
    with pytest.raises(cw.CounterweightError, match='max_rim_radius_factor: got 0'):
        cw.balance_with_counterweights(hoeken, 'crank', max_rim_radius_factor=0.0)


# ------------------------------------------------------------------ command line


def test_cli_reports_clearance_and_warns(capsys):
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--no-clearance']) == 0
    out, err = capsys.readouterr()
    assert 'least clearance' in out
    line = 'warning: collision: crank counterweight 1 and rocker counterweight 1 overlap'
    assert line in err and (out + err).count(line) == 1   # once
    assert 'collision: ' not in out


def test_cli_planes_and_rim_in_json(capsys):
    assert cli.main(['balance', '--scene', 'hoeken', '--counterweights', 'crank,rocker',
                     '--planes', 'crank=-0.030,rocker=-0.0376', '--max-rim-radius-factor',
                     '0.5', '--json']) == 0
    out, err = capsys.readouterr()
    report = json.loads(out)['report']
    assert report['clearance']['least_clearance_m'] > 0.0 and report['warnings'] == []
    assert report['options']['planes'] == {'crank': -0.03, 'rocker': -0.0376}
    assert 'collision' not in err


@pytest.mark.parametrize('argv, expected', [
    (['--planes', 'crank=0.01'], '--planes applies with --counterweights only'),
    (['--max-rim-radius-factor', '0.5'], '--max-rim-radius-factor applies with'),
    (['--counterweights', 'crank', '--planes', 'crank=x'], "planes.crank: got 'x'")])
def test_cli_bad_placement_options_exit_2(argv, expected, capsys):
    assert cli.main(['balance', '--scene', 'hoeken', *argv]) == 2
    assert expected in capsys.readouterr().err


def test_urdf_draws_each_disc_in_its_plane(rim_bounded):
    sc = rim_bounded.balanced_scene
    rig = rig_for(sc)
    root = ET.fromstring(urdf.urdf_xml(sc))
    for d in rim_bounded.designs:
        link = next(el for el in root.iter('link') if el.get('name') == d.link)
        visual = next(v for v in link.iter('visual') if v.get('name') == 'counterweight_0')
        z = float(visual.find('origin').get('xyz').split()[2])
        assert z == pytest.approx(drawn.plane_z_m(rig.linkage, d.link) + APART[d.link],
                                  abs=1e-15)
        assert z == pytest.approx(rim_bounded.clearance.planes_m[f'{d.link} counterweight 1'],
                                  abs=1e-15)
