"""
The balancing API: linear maps, the cone program's options, YAML export, bad input, CLI.

Seed 001's tables are checked in test_balancing_paper.py, the analytic force balance in
test_balancing_analytic.py.
"""

from dataclasses import replace
import inspect
import json
import math

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis, linear_maps
from mech_balance.balancing import defaults, redistribution, tables
from mech_balance.cli import main as cli
from mech_balance.core import equimomental
from mech_balance.core.planar import rig as planar_rig
import numpy as np
from numpy.testing import assert_allclose
import pytest
import yaml

GAP_REL = 1e-6
ULP = 16.0 * np.finfo(float).eps
"""The design returned meets its bounds exactly (issue 19), up to a few ulp of rounding."""


@pytest.fixture(scope='module')
def hoeken():
    return scene.load('hoeken')


def _with_theta(sc, theta_si):
    links = []
    for lk, (m, hx, hy, i_o) in zip(sc.links, np.reshape(theta_si, (-1, 4))):
        c = (hx / m, hy / m)
        links.append(replace(lk, mass_kg=m, com_m=c,
                             inertia_com_kg_m2=i_o - m * (c[0] ** 2 + c[1] ** 2)))
    return sc.with_links(links)


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank'])
def test_linear_maps_give_the_rms_of_the_core(name):
    """||R theta|| equals the RMS of the full analysis for random inertial parameters."""
    sc = scene.load(name)
    units = planar_rig.objective_units(sc)
    maps = linear_maps.linear_maps(sc, 90, ('bearing_reactions',), units)
    rng = np.random.default_rng(3)
    scale = np.tile([units.mass_kg, units.mass_kg * units.length_m,
                     units.mass_kg * units.length_m, units.mass_kg * units.length_m ** 2],
                    len(sc.links))
    for _ in range(3):
        theta = maps.theta_original * rng.uniform(0.5, 2.0, maps.theta_original.size)
        theta[3::4] += 2.0 * (theta[1::4] ** 2 + theta[2::4] ** 2) / theta[0::4]
        cycle = analysis.run_cycle(analysis.Rig(_with_theta(sc, theta * scale)), 90)
        w = cycle.wrenches
        f_unit = units.mass_kg * units.length_m * units.omega_rad_s ** 2
        n_unit = f_unit * units.length_m
        ref = [np.sqrt(np.mean(np.abs(w.shaking_force) ** 2)) / f_unit,
               np.sqrt(np.mean(w.shaking_moment ** 2)) / n_unit,
               np.sqrt(np.mean(w.driving_torque ** 2)) / n_unit]
        assert_allclose(maps.terms(theta)[:3], ref, rtol=1e-10)
        for joint, mat in maps.reactions.items():
            rms = np.sqrt(np.mean(np.abs(w.reaction_force[joint]) ** 2)) / f_unit
            assert_allclose(np.linalg.norm(mat @ theta), rms, rtol=1e-10)


def test_point_masses_have_one_definition(hoeken):
    """Vectorized eqs. 13-15 equal the per-link model and reproduce m, h, I_O (eqs. 19-22)."""
    links = hoeken.links
    m = np.array([lk.mass_kg for lk in links])
    h = np.array([complex(*lk.first_moment_kg_m) for lk in links])
    i_o = np.array([lk.inertia_origin_kg_m2 for lk in links])
    masses, dist = equimomental.point_mass_arrays(m, h, i_o)
    assert masses.shape == (len(links), 3) and dist.shape == (len(links),)
    for lk, row, d in zip(links, masses, dist):
        pm = equimomental.from_link(lk.mass_kg, lk.com_m, lk.inertia_origin_kg_m2)
        assert pm.masses_kg == tuple(row) and pm.distance_m == d
        design = tables.link_design(lk)
        assert design.point_masses_kg == pm.masses_kg and design.distance_m == d
    assert_allclose(masses.sum(axis=1), m, rtol=1e-14)
    assert_allclose(dist * (masses @ equimomental.UNIT), h, rtol=1e-12)
    assert_allclose(dist ** 2 * masses.sum(axis=1), i_o, rtol=1e-14)


@pytest.mark.parametrize('masses, realizable', [
    ((1.0, 1e-3, 1e-3), True),              # I_c = 6e-3 I_O
    ((1.0, 1e-9, 1e-9), False),             # I_c = 6e-9 I_O <= REALIZABLE_TOL: a point mass
    ((1.0, 1.0, -1e-10), True),             # a counterweight of -5e-11 m counts as zero
    ((1.0, 1.0, -1e-6), False)])            # -5e-7 m is a negative counterweight
def test_balancing_reports_realizability_as_equimomental_defines_it(masses, realizable):
    """link_design's verdict is equimomental.is_realizable's, at its tolerances."""
    pm = equimomental.PointMasses(masses, 0.1)
    m, com, i_o = equimomental.link_properties(pm)
    link = scene.Link('x', {'O': (0.0, 0.0)}, m, com, i_o - m * (com[0] ** 2 + com[1] ** 2))
    design = tables.link_design(link, counterweights=True)
    assert design.realizable is equimomental.is_realizable(pm, counterweights=True)[0]
    assert design.realizable is realizable, design.reason


def test_result_maps_back_to_consistent_links(hoeken):
    result = redistribution.optimize(hoeken, (0.5, 0.5), 'b')
    assert result.certificate.gap_rel <= GAP_REL
    for d, lk in zip(result.links, result.balanced_scene.links):
        # eqs. 19-22: the point masses reproduce mass, first moment and inertia
        units = np.exp(1j * np.radians([0.0, 120.0, 240.0]))
        assert_allclose(sum(d.point_masses_kg), lk.mass_kg, rtol=1e-12)
        assert_allclose(d.distance_m * np.dot(d.point_masses_kg, units),
                        complex(*lk.first_moment_kg_m), rtol=1e-10)
        assert_allclose(d.distance_m ** 2 * lk.mass_kg, lk.inertia_origin_kg_m2, rtol=1e-12)
        assert_allclose(d.inertia_com_kg_m2, lk.inertia_com_kg_m2, rtol=1e-9)
        assert_allclose(d.com_distance_m * np.exp(1j * math.radians(d.com_angle_deg)),
                        complex(*lk.com_m), rtol=1e-10)
        assert min(d.point_masses_kg) >= -1e-8 * d.mass_kg       # case b
    data = result.to_dict()
    assert yaml.safe_load(yaml.safe_dump(data)) == data
    json.dumps(data)
    assert data['certificate']['gap_rel'] <= GAP_REL
    assert {r['quantity'] for r in data['table']} >= {
        'shaking force |f_sh|', 'shaking moment n_sh', 'driving torque', 'bearing O1 |f|'}


def test_extra_terms_and_mass_cap(hoeken):
    base = redistribution.optimize(hoeken, (0.5, 0.5))
    torque = redistribution.optimize(hoeken, (0.5, 0.5), torque_weight=1.0)
    react = redistribution.optimize(hoeken, (0.5, 0.5), reaction_weight=0.25)
    for r in (torque, react):
        assert r.certificate.status == 'Solved' and r.certificate.gap_rel <= GAP_REL
    assert torque.objective['driving_torque_rms'] < \
        {r['quantity']: r['after'] for r in base.table}['driving torque']

    def bearings(r):
        return sum(x['after'] for x in r.table if x['quantity'].startswith('bearing'))
    assert bearings(react) < bearings(base)
    # the objective is the core's evaluation of the design (issue 19: to 1e-9)
    assert_allclose(react.objective['bearing_force_rms_sum'], bearings(react), rtol=1e-9)
    cap = 0.25
    capped = redistribution.optimize(hoeken, (0.5, 0.5), max_added_mass_kg=cap)
    added = sum(d.mass_kg for d in capped.links) - sum(lk.mass_kg for lk in hoeken.links)
    assert added <= cap + ULP * sum(d.mass_kg for d in capped.links)   # exactly feasible
    # the capped optimum is no better than the uncapped one, to their certified gaps
    assert capped.objective['z'] >= base.certificate.lower_bound


def test_fixed_links_and_bounds_are_kept(hoeken):
    crank_m = hoeken.link('crank').mass_kg
    result = redistribution.optimize(hoeken, (0.5, 0.5), fixed_links=('coupler',),
                                     mass_bounds={'crank': (crank_m, 2.0 * crank_m)},
                                     distance_bounds={'rocker': (0.01, None)})
    got = {lk.name: lk for lk in result.balanced_scene.links}
    ref = hoeken.link('coupler')
    # a fixed link is kept, not solved for: its parameters to the rounding of the units
    assert_allclose(got['coupler'].mass_kg, ref.mass_kg, rtol=ULP)
    assert_allclose(got['coupler'].com_m, ref.com_m, rtol=0, atol=ULP * np.hypot(*ref.com_m))
    assert_allclose(got['coupler'].inertia_origin_kg_m2, ref.inertia_origin_kg_m2, rtol=ULP)
    assert crank_m * (1 - ULP) <= got['crank'].mass_kg <= 2.0 * crank_m * (1 + ULP)
    assert result.bounds['rocker']['distance_m'] == [0.01, None]


def test_scene_without_normalization_uses_crank_units():
    sc = scene.load('slider_crank')
    data, _ = scene.load_data('slider_crank')
    del data['normalization']
    bare = scene.from_dict(data, 'bare')
    units = planar_rig.objective_units(bare)
    assert (units.mass_kg, units.length_m) == (0.8, pytest.approx(0.04))
    result = redistribution.optimize(bare, (1.0, 0.0))
    assert result.certificate.gap_rel <= GAP_REL
    assert result.objective['shaking_force_rms'] <= 1e-12 * result.objective['z_original']
    assert result.table[0]['unit'] == 'N'
    assert redistribution.optimize(sc, (1.0, 0.0)).realizable


@pytest.mark.parametrize('name', ['hoeken', 'slider_crank', 'carpet_scraper'])
def test_scene_yaml_round_trip(tmp_path, name):
    sc = scene.load(name)
    result = redistribution.optimize(sc, (0.5, 0.5), samples=72)
    path = tmp_path / 'balanced.yaml'
    path.write_text(redistribution.scene_to_yaml(result.balanced_scene, result.summary()))
    back = scene.load(str(path))
    assert back.links == result.balanced_scene.links
    assert back.joints == sc.joints and back.frame_points == sc.frame_points
    assert back.normalization == sc.normalization
    assert yaml.safe_load(path.read_text())['balance']['realizable'] is True
    rows = analysis.summarize(analysis.run_cycle(analysis.Rig(back), 72))
    ref = analysis.summarize(analysis.run_cycle(analysis.Rig(result.balanced_scene), 72))
    assert_allclose([r.rms for r in rows], [r.rms for r in ref], rtol=1e-12)


def test_scene_yaml_keeps_every_section_the_design_leaves_alone(tmp_path):
    """Drive, recording, notes, gravity... survive ``balance --output``; inertias bit for bit."""
    data, _ = scene.load_data('slider_crank_stiff')
    data['gravity_m_s2'] = [0.0, -9.81]
    data['notes'] = {'source': 'test', 'reference': [1, 2]}
    data['samples'] = 72
    data['outputs'] = ['kinematics', 'shaking_wrench']
    data['recording'] = {'streams': {'info': False, 'point_masses': False},
                         'force_scale_m_per_N': 1e-3}
    sc = scene.from_dict(data, 'source')
    result = redistribution.optimize(sc, samples=72)
    path = tmp_path / 'balanced.yaml'
    path.write_text(redistribution.scene_to_yaml(result.balanced_scene, result.summary()))
    back = scene.load(str(path))
    written = yaml.safe_load(path.read_text())
    assert set(written) == set(data) | {'name', 'schema_version', 'balance'}
    assert back.drive == sc.drive and back.drive['speed_controller']['kp_per_rad_s'] == 5.0
    assert back.recording == sc.recording
    assert not back.recording.enabled('info') and back.recording.enabled('links')
    assert back.recording.force_scale_m_per_N == 1e-3
    assert back.recording.moment_scale_deg_per_Nm is None
    for key in ('description', 'normalization', 'crank_joint', 'crank_speed_rad_s',
                'crank_acceleration_rad_s2', 'gravity_m_s2', 'frame_points', 'joints',
                'assembly_crank_angle_rad', 'assembly_link_angles_rad',
                'assembly_displacements_m', 'outputs', 'samples', 'notes'):
        assert getattr(back, key) == getattr(sc, key), key
    for got, ref in zip(back.links, result.balanced_scene.links):   # bit for bit
        assert (got.mass_kg, got.com_m, got.inertia_com_kg_m2) == \
            (ref.mass_kg, ref.com_m, ref.inertia_com_kg_m2)
    # a default recording stays implicit and loads back as the default
    plain = scene.load('slider_crank')
    assert 'recording' not in yaml.safe_load(redistribution.scene_to_yaml(plain))


def _slider_off_axis(sc, offset_m):
    return sc.with_links([replace(lk, com_m=(lk.com_m[0], offset_m)) if lk.name == 'slider'
                          else lk for lk in sc.links])


@pytest.mark.parametrize('offset_m', [1e-12, 1e-3])
def test_change_of_a_negligible_baseline_is_not_a_percentage(offset_m):
    """A slider mass centre off its guide loads the guide with a moment; on it, none."""
    on_axis = scene.load('slider_crank')
    off_axis = _slider_off_axis(on_axis, offset_m)
    for before, after in ((on_axis, off_axis), (off_axis, on_axis)):
        table = tables.before_after(before, after, 72)
        rows = {r['quantity']: r for r in table}
        # rows are matched by name although the analysis omits a zero moment on one side
        assert list(rows) == ['bearing O |f|', 'bearing A |f|', 'bearing B |f|',
                              'bearing S |f|', 'bearing S moment', 'driving torque',
                              'shaking force |f_sh|', 'shaking moment n_sh']
        assert rows['bearing O |f|']['change_percent'] == pytest.approx(0.0, abs=1e-9)
        moment = rows['bearing S moment']
        scale = max(r[k] for r in table if r['unit'] == moment['unit']
                    for k in ('before', 'after'))
        if moment['before'] <= tables.CHANGE_BASELINE_REL_TOL * scale:
            assert moment['change_percent'] is None       # 0 or ~1e-11 of the scale: n/a
        else:
            assert moment['change_percent'] == pytest.approx(-100.0)
    assert all(r['change_percent'] is not None for r in table
               if r['quantity'] != 'bearing S moment')


def test_unrealizable_design_cannot_be_saved(hoeken):
    result = redistribution.optimize(hoeken, (0.5, 0.5), paper_constraints=True)
    assert not result.realizable
    with pytest.raises(ValueError, match='unrealizable'):
        redistribution.scene_to_yaml(result.balanced_scene)


@pytest.mark.parametrize('kwargs, match', [
    ({'weights': (-1.0, 0.0)}, 'weights'),
    ({'weights': (0.0, 0.0)}, 'at least one positive weight'),
    ({'weights': (1.0,)}, 'weights'),
    ({'case': 'c'}, 'case'),
    ({'paper_constraints': True, 'mass_bounds': {'crank': (0.3, 1.0)}}, 'paper_constraints'),
    ({'paper_constraints': True, 'torque_weight': 1.0}, 'paper_constraints'),
    ({'mass_bounds': {'wheel': (0.3, 1.0)}}, 'mass_bounds.wheel'),
    ({'mass_bounds': {'crank': (0.5, 0.1)}}, 'mass_bounds.crank'),
    ({'mass_bounds': {'crank': (0.0, 1.0)}}, r'mass_bounds.crank: got \(0, 1\), expected 0 <'),
    ({'distance_bounds': {'crank': 0.1}}, 'distance_bounds.crank'),
    ({'distance_bounds': {'crank': (0.0, 0.1)}}, r'distance_bounds.crank: got \(0, 0.1\)'),
    ({'distance_bounds': {'crank': (0.2, 0.1)}}, 'distance_bounds.crank'),
    ({'distance_factors': (0.0, 0.0)}, r'distance_factors: got \(0, 0\), expected .* 0 < low'),
    ({'distance_factors': (1.5, 0.5)}, 'distance_factors: got'),
    ({'mass_factors': (np.float64(0.0), 5.0)}, r'mass_factors: got \(0, 5\)'),
    ({'mass_bounds': {'crank': (np.float64(0.0), 1.0)}}, r'got \(0, 1\)'),
    ({'fixed_links': ('wheel',)}, 'fixed_links'),
    ({'max_added_mass_kg': -1.0}, 'max_added_mass_kg'),
    ({'centroidal_margin': 1.0}, 'centroidal_margin'),
    ({'samples': 2}, 'samples'),
    ({'torque_weight': float('nan')}, 'torque_weight'),
])
def test_bad_input(hoeken, kwargs, match):
    with pytest.raises(ValueError, match=match) as exc:
        redistribution.optimize(hoeken, **kwargs)
    assert 'np.' not in str(exc.value)


def test_equal_bounds_fix_the_value(hoeken):
    """Equal bounds are meaningful (a fixed mass or distance), unlike a zero lower bound."""
    m = hoeken.link('crank').mass_kg
    result = redistribution.optimize(hoeken, mass_bounds={'crank': (m, m)},
                                     distance_factors=(1.0, 1.0), samples=72)
    assert result.realizable
    crank = result.balanced_scene.link('crank')
    # equal bounds are met exactly (issue 19: the design is repaired into its bounds)
    assert_allclose(crank.mass_kg, m, rtol=ULP)
    assert_allclose(crank.inertia_origin_kg_m2, hoeken.link('crank').inertia_origin_kg_m2,
                    rtol=ULP)


def test_infeasible_constraints_are_reported(hoeken):
    m = hoeken.link('crank').mass_kg
    with pytest.raises(ValueError, match='infeasible'):
        redistribution.optimize(hoeken, (1.0, 0.0), mass_bounds={'crank': (3.0 * m, 4.0 * m)},
                                max_added_mass_kg=0.0)


def test_default_weights_are_the_papers_compromise():
    """Seed 001 cases a(2)/b(2): equal weights, the one default of every entry point."""
    assert defaults.DEFAULT_WEIGHTS == (0.5, 0.5)
    default = inspect.signature(redistribution.optimize).parameters['weights'].default
    assert default == defaults.DEFAULT_WEIGHTS


def test_rggr_scene_is_not_planar():
    with pytest.raises(ValueError, match='planar'):
        redistribution.optimize(scene.load('rggr'))


# ------------------------------------------------------------------------ command line


def test_cli_balance_prints_design_table_certificate(capsys):
    assert cli.main(['balance', '--scene', 'hoeken', '--paper-constraints', '--weights',
                     '0.5', '0.5']) == 0
    out = capsys.readouterr().out
    for text in ('certificate (clarabel', 'relative', 'solve time', 'realizable',
                 'shaking moment n_sh', 'bearing O1 |f|', 'Table 7 case a(2)',
                 "paper's design vector: NOT realizable"):
        assert text in out, text


def test_cli_balance_json_and_output(tmp_path, capsys):
    path = tmp_path / 'out.yaml'
    assert cli.main(['balance', '--scene', 'hoeken', '--case', 'b', '--weights', '0', '1',
                     '--samples', '90', '--json', '--output', str(path)]) == 0
    top = json.loads(capsys.readouterr().out)
    data = top['report']   # the method's own report (docs/cli.md, JSON output)
    assert top['certified'] and top['lower_bound'] <= top['objective']
    assert data['case'] == 'b' and data['samples'] == 90 and data['realizable']
    assert data['certificate']['gap_rel'] <= GAP_REL
    back = scene.load(str(path))
    assert [lk.mass_kg for lk in back.links] == pytest.approx(
        [d['mass_kg'] for d in data['links']], rel=1e-15)
    assert cli.main(['analyze', '--scene', str(path)]) == 0


def test_cli_balance_analytic_and_rggr(capsys):
    assert cli.main(['balance', '--scene', 'slider_crank', '--analytic']) == 0
    out = capsys.readouterr().out
    assert 'xi_2 = -1/mu_2' in out and 'as printed (xi_2 = +1/mu_2)' in out
    assert cli.main(['balance', '--scene', 'hoeken', '--analytic', '--mass-factor', '2',
                     '--si']) == 0
    out = capsys.readouterr().out
    assert 'Berkof-Lowen' in out and 'm3_d3 = 20.306' in out and 'kg' in out
    assert cli.main(['balance', '--scene', 'rggr', '--samples', '72']) == 0
    assert 'balancing weights (Hedaya)' in capsys.readouterr().out


@pytest.mark.parametrize('argv, match', [
    (['--case', 'c'], None),
    (['--scene', 'rggr', '--output', 'x.txt'], '--output'),
    (['--weights', '-1', '0'], None),        # argparse: --weights is 0 <= w <= MAX_WEIGHT
    (['--paper-constraints', '--output', 'x.yaml'], 'unrealizable'),
])
def test_cli_balance_bad_input(capsys, tmp_path, argv, match):
    argv = [a if a != 'x.yaml' else str(tmp_path / a) for a in argv]
    if match is None:
        with pytest.raises(SystemExit) as exc:
            cli.main(['balance', *argv])
        assert exc.value.code == 2
        return
    assert cli.main(['balance', *argv]) == 2
    assert match in capsys.readouterr().err


def test_bench_section_lists_every_case():
    from argparse import Namespace
    from mech_balance.bench import balancing as bench_balancing
    text = bench_balancing.bench_section(Namespace(scene=['hoeken'], repeat=3, samples=90),
                                         lambda s: None)
    assert text.count('hoeken') == 12 and 'median ms' in text
