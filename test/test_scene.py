"""Scene loading and validation: every bad field is named with its value and expectation."""

import copy
import math

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.core.planar import kinematics
import pytest
import yaml


@pytest.fixture
def hoeken_data():
    data, _ = scene.load_data('hoeken')
    return data


def _load(data):
    return scene.from_dict(copy.deepcopy(data), source='test')


def test_builtin_scenes_load():
    names = scene.builtin_scenes()
    assert {'hoeken', 'slider_crank', 'carpet_scraper', 'rggr'} <= set(names)
    for name in names:
        sc = scene.load(name)
        assert sc.name == name


def test_si_values_and_normalization_recorded():
    sc = scene.load('hoeken')
    assert sc.normalization.length_m == 0.038
    assert sc.normalization.mass_kg == 0.326
    crank = sc.link('crank')
    assert math.isclose(crank.inertia_origin_kg_m2 / (0.326 * 0.038 ** 2), 0.4023,
                        rel_tol=1e-9)


@pytest.mark.parametrize('path, value, match', [
    (('links', 'crank', 'mass_kg'), 'heavy',
     r'links\.crank\.mass_kg: got .heavy., expected a number'),
    (('links', 'crank', 'mass_kg'), -1.0,
     r'links\.crank\.mass_kg: got -1\.0, expected a number > 0'),
    (('links', 'crank', 'mass_kg'), 0.0, r'links\.crank\.mass_kg: got 0\.0'),
    (('links', 'crank', 'mass_kg'), float('nan'),
     r'links\.crank\.mass_kg: got nan, expected a finite'),
    (('links', 'coupler', 'com_m'), [1.0],
     r'links\.coupler\.com_m: got \[1\.0\], expected \[x, y\]'),
    (('links', 'rocker', 'inertia_origin_kg_m2'), 1e-5,
     r'links\.rocker\.inertia_origin_kg_m2: got 1e-05.*centroidal moment of inertia'),
    (('links', 'coupler', 'points', 'B'), [0.0, 0.0],
     r'links\.coupler\.points: A and B .*length 0'),
    (('joints', 'B', 'type'), 'spherical', r'joints\.B\.type: got .spherical., expected one of'),
    (('joints', 'B', 'a'), 'coupler.Z',
     r'joints\.B\.a: got .coupler\.Z., link .coupler. has no point'),
    (('joints', 'B', 'a'), 'ghost.B', r'joints\.B\.a: got .ghost\.B., expected "link\.point"'),
    (('crank', 'joint'), 'A',
     r'crank\.joint: got .A. .* expected a revolute joint between the frame'),
    (('crank', 'joint'), 'Q', r'crank\.joint: got .Q., expected one of the joints'),
    (('crank', 'speed_rad_s'), 0, r'crank\.speed_rad_s: got 0\.0, expected a non-zero'),
    (('crank', 'speed_rad_s'), float('inf'), r'crank\.speed_rad_s: got inf, expected a finite'),
    (('normalization', 'length_m'), -0.038, r'normalization\.length_m: got -0\.038'),
    (('outputs',), ['torque'], r"outputs: got 'torque', expected one of"),
    (('samples',), 2, r'samples: got 2, expected an integer >= 4'),
    (('links', 'crank', 'colour'), 'red', r'links\.crank\.colour: unknown field'),
    (('assembly', 'link_angles_deg', 'ghost'), 10,
     r'assembly\.link_angles_deg\.ghost: no such link'),
])
def test_bad_field_is_named(hoeken_data, path, value, match):
    data = copy.deepcopy(hoeken_data)
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(scene.SceneError, match=match):
        _load(data)


def test_missing_fields_are_named(hoeken_data):
    for key, match in [('links', r'^links: missing'), ('joints', r'^joints: missing'),
                       ('crank', r'^crank: missing'), ('frame', r'^frame: missing')]:
        data = copy.deepcopy(hoeken_data)
        del data[key]
        with pytest.raises(scene.SceneError, match=match):
            _load(data)
    data = copy.deepcopy(hoeken_data)
    del data['links']['crank']['mass_kg']
    with pytest.raises(scene.SceneError, match=r'links\.crank\.mass_kg: missing'):
        _load(data)


def test_both_or_neither_inertia_is_rejected(hoeken_data):
    data = copy.deepcopy(hoeken_data)
    data['links']['crank']['inertia_com_kg_m2'] = 1e-4
    with pytest.raises(scene.SceneError, match=r'exactly one of .*\(got both\)'):
        _load(data)


def test_mobility_and_connectivity(hoeken_data):
    data = copy.deepcopy(hoeken_data)
    del data['joints']['B']
    with pytest.raises(scene.SceneError, match=r'mobility 3\*3 - 2\*3 = 3, expected'):
        _load(data)
    data = copy.deepcopy(hoeken_data)
    data['joints']['B'] = {'type': 'revolute', 'a': 'coupler.B', 'b': 'crank.A'}
    data['links']['rocker']['points']['X'] = [0.2, 0.0]
    data['joints']['O3'] = {'type': 'revolute', 'a': 'rocker.O3', 'b': 'rocker.X'}
    with pytest.raises(scene.SceneError, match='both ends are on link .rocker.'):
        _load(data)


def test_linkage_that_does_not_close(hoeken_data):
    data = copy.deepcopy(hoeken_data)
    # frame link longer than the other three together: B can never be reached
    data['frame']['points']['O3'] = [0.5, 0.0]
    sc = _load(data)
    with pytest.raises(kinematics.BranchError, match='does not close at crank angle 0.000 deg'):
        analysis.Rig(sc)


def test_crank_that_cannot_turn_fully(hoeken_data):
    data = copy.deepcopy(hoeken_data)
    # non-Grashof: a crank longer than the others allow; assembles at 0 deg but not beyond
    # (crank 1, coupler 1.5, rocker 3.02, frame 2.35 in units of a_1: 1 + 3.02 > 1.5 + 2.35)
    data['links']['coupler']['points']['B'] = [0.057, 0.0]
    data['links']['coupler']['com_m'] = [0.02, 0.0]
    data['assembly'] = {'crank_angle_deg': 180.0,
                        'link_angles_deg': {'coupler': 20.0, 'rocker': 170.0}}
    sc = _load(data)
    with pytest.raises(kinematics.BranchError, match=r'crank angle .* deg'), \
            pytest.warns(RuntimeWarning, match='near-singular position'):
        analysis.Rig(sc)


def test_missing_assembly_guess_is_named(hoeken_data):
    data = copy.deepcopy(hoeken_data)
    del data['assembly']['link_angles_deg']['rocker']
    with pytest.raises(kinematics.BranchError, match=r'assembly: missing link_angles_deg\.rocker'):
        analysis.Rig(_load(data))


def test_yaml_file_errors(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('links: [1, 2\n')
    with pytest.raises(scene.SceneError, match='bad.yaml: not valid YAML'):
        scene.load(str(bad))
    bad.write_text(yaml.safe_dump([1, 2]))
    with pytest.raises(scene.SceneError, match='expected a mapping'):
        scene.load(str(bad))
    with pytest.raises(scene.SceneError, match='does not exist'):
        scene.load(str(tmp_path / 'none.yaml'))
    with pytest.raises(scene.SceneError, match="got 'nosuchscene', expected a built-in scene"):
        scene.load('nosuchscene')
    with pytest.raises(scene.SceneError) as error:
        scene.load('nosuchscene')
    assert 'did you mean' not in str(error.value)   # nothing near: no suggestion


@pytest.mark.parametrize('typed, nearest', [('hoekn', 'hoeken'), ('slidercrank', 'slider_crank'),
                                            ('spatial_two_lop', 'spatial_two_loop'),
                                            ('Carpet_Scraper', 'carpet_scraper')])
def test_a_misspelled_scene_name_suggests_the_nearest(typed, nearest):
    with pytest.raises(scene.SceneError, match=f"got '{typed}', expected a built-in scene "
                                               r'.* or a path to a \.yaml file; did you mean '
                                               f"'{nearest}'\\?$"):
        scene.load(typed)


def test_scene_round_trips_through_a_file(tmp_path, hoeken_data):
    path = tmp_path / 'copy.yaml'
    path.write_text(yaml.safe_dump(hoeken_data, sort_keys=False))
    assert scene.load(str(path)).links == scene.load('hoeken').links
