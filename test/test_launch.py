"""
launch/rig.launch.py and config/rig.rviz checked against the package.

The launch file names an executable, a params file and an RViz file: they must be what
setup.py installs, and its arguments must be documented in docs/rviz_launch.md.  launch and
launch_ros are not on PyPI, so the file is read as source here (its constants are plain
literals); where launch_ros is importable the test also builds its LaunchDescription.
"""

import ast
import importlib
import importlib.util
import math
from pathlib import Path
import runpy
import xml.etree.ElementTree as ET

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.cli import urdf as cli_urdf
from mech_balance.ros import params, urdf
import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
LAUNCH_FILE = ROOT / 'launch' / 'rig.launch.py'
README = ROOT / 'docs' / 'rviz_launch.md'
README_SECTION = '# RViz, robot_state_publisher and launch'
RVIZ_ARROW_RANGE_M = (0.03, 0.3)
"""The largest shaking-force and -moment arrows of hoeken must be drawn this long in RViz."""


def _constants():
    """Return the launch file's module-level literal constants."""
    tree = ast.parse(LAUNCH_FILE.read_text())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and \
                isinstance(node.targets[0], ast.Name):
            try:
                out[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                pass
    return out


@pytest.fixture(scope='module')
def setup_kwargs():
    """Return the keyword arguments setup.py passes to setuptools.setup."""
    import os
    import setuptools
    captured = {}
    original, cwd = setuptools.setup, os.getcwd()
    setuptools.setup = lambda **kw: captured.update(kw)
    try:
        os.chdir(ROOT)
        runpy.run_path(str(ROOT / 'setup.py'), run_name='__main__')
    finally:
        setuptools.setup = original
        os.chdir(cwd)
    return captured


def _installed(setup_kwargs):
    """Return the installed files as paths relative to share/<package>/."""
    share = f'share/{setup_kwargs["name"]}'
    out = set()
    for dest, files in setup_kwargs['data_files']:
        dest = dest.replace('\\', '/')
        if dest == share or dest.startswith(share + '/'):
            sub = dest[len(share):].strip('/')
            out |= {f'{sub}/{Path(f).name}'.strip('/') for f in files}
    return out


def test_the_executable_is_an_entry_point_of_the_package(setup_kwargs):
    c = _constants()
    assert c['PACKAGE'] == setup_kwargs['name']
    scripts = dict(s.replace(' ', '').split('=') for s in
                   setup_kwargs['entry_points']['console_scripts'])
    assert c['EXECUTABLE'] in scripts
    module, function = scripts[c['EXECUTABLE']].split(':')
    assert callable(getattr(importlib.import_module(module), function))


def test_the_packages_it_starts_are_exec_depends():
    started = {node.value.value for node in ast.walk(ast.parse(LAUNCH_FILE.read_text()))
               if isinstance(node, ast.keyword) and node.arg == 'package'
               and isinstance(node.value, ast.Constant)}
    assert started == {'robot_state_publisher', 'rviz2'}   # and PACKAGE itself
    depends = {e.text for e in ET.parse(ROOT / 'package.xml').getroot().iter('exec_depend')}
    assert started | {'launch', 'launch_ros'} <= depends


def test_params_rviz_and_launch_files_are_installed(setup_kwargs):
    c = _constants()
    installed = _installed(setup_kwargs)
    for relative in (c['PARAMS_FILE'], c['RVIZ_FILE'], 'launch/rig.launch.py'):
        assert relative in installed, relative
        assert (ROOT / relative).is_file(), relative


def test_launch_arguments_are_documented_in_the_readme():
    c = _constants()
    names = [a[0] for a in c['ARGUMENTS']]
    assert names == ['scene', 'namespace', 'use_rviz', 'params_file']
    text = README.read_text()
    assert README_SECTION in text
    section = text.split(README_SECTION, 1)[1].split('\n## ', 1)[0]
    rows = [line for line in section.splitlines() if line.startswith('| `')]
    documented = {line.split('`')[1]: line for line in rows}
    for name, default, _ in c['ARGUMENTS']:
        assert name in documented, name
        if default not in (None, ''):
            assert f'`{default}`' in documented[name], (name, default)
    assert 'ros2 launch mech_balance rig.launch.py scene:=hoeken use_rviz:=true' in section
    assert 'mech-balance urdf' in section


def test_robot_state_publisher_alone_publishes_robot_description():
    """The launch starts the rig node with publish_robot_description false (one publisher)."""
    assert params.BY_NAME['publish_robot_description'].default is True
    settings = {}
    for node in ast.walk(ast.parse(LAUNCH_FILE.read_text())):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and isinstance(value, ast.Constant):
                    settings.setdefault(key.value, []).append(value.value)
    assert settings.get('publish_robot_description') == [False]


def test_the_default_scene_and_frame_id_are_the_nodes():
    c = _constants()
    spec = {s.name: s for s in params.PARAMETERS}
    assert {a[0]: a[1] for a in c['ARGUMENTS']}['scene'] == spec['scene'].default
    assert cli_urdf.frame_id_from_params_file(ROOT / c['PARAMS_FILE']) == \
        spec['frame_id'].default == urdf.DEFAULT_FRAME_ID


def test_frame_id_from_a_params_file(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    frame_id: a\n'
                    '/cell/rig:\n  ros__parameters:\n    frame_id: b\n'
                    '/other:\n  ros__parameters:\n    frame_id: c\n')
    assert cli_urdf.frame_id_from_params_file(path) == 'b'   # later sections win, as in ROS
    path.write_text('/**:\n  ros__parameters:\n    scene: hoeken\n')
    assert cli_urdf.frame_id_from_params_file(path) == urdf.DEFAULT_FRAME_ID
    with pytest.raises(ValueError, match='params_file: got .*cannot read it'):
        cli_urdf.frame_id_from_params_file(tmp_path / 'missing.yaml')
    path.write_text('/**:\n  ros__parameters:\n    frame_id: ""\n')
    with pytest.raises(ValueError, match='params_file: frame_id: got'):
        cli_urdf.frame_id_from_params_file(path)


def test_rig_node_name_matches():
    node = pytest.importorskip('mech_balance.ros.node')
    assert cli_urdf.RIG_NODE_NAME == node.NODE_NAME


def test_rviz_file_shows_the_rig_and_a_readable_wrench():
    c = _constants()
    config = yaml.safe_load((ROOT / c['RVIZ_FILE']).read_text())
    manager = config['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == urdf.DEFAULT_FRAME_ID
    displays = {d['Class']: d for d in manager['Displays']}
    model = displays['rviz_default_plugins/RobotModel']
    assert model['Description Source'] == 'Topic'
    assert model['Description Topic']['Value'] == '/robot_description'
    assert model['Description Topic']['Durability Policy'] == 'Transient Local'
    assert 'rviz_default_plugins/TF' in displays
    wrench = displays['rviz_default_plugins/Wrench']
    assert wrench['Topic']['Value'] == '/shaking_wrench'
    assert set(c['RVIZ_TOPICS']) == {'/robot_description', '/shaking_wrench'}
    # the scales draw hoeken's largest shaking force and moment at a readable length
    sc = scene.load('hoeken')
    _, w = analysis.Rig(sc).evaluate(np.linspace(0.0, 2.0 * math.pi, 360, endpoint=False))
    force = wrench['Force Arrow Scale'] * np.abs(w.shaking_force).max()
    moment = wrench['Torque Arrow Scale'] * np.abs(w.shaking_moment).max()
    print(f'hoeken in RViz: largest force arrow {force:.3f} m, moment arrow {moment:.3f} m')
    for length in (force, moment):
        assert RVIZ_ARROW_RANGE_M[0] <= length <= RVIZ_ARROW_RANGE_M[1]


def test_launch_description_builds():
    pytest.importorskip('launch_ros', reason='launch_ros is not on PyPI (a ROS 2 install '
                                             'provides it); the source checks above run')
    spec = importlib.util.spec_from_file_location('rig_launch', LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument
    description = module.generate_launch_description()
    assert isinstance(description, LaunchDescription)
    declared = [e.name for e in description.entities if isinstance(e, DeclareLaunchArgument)]
    assert declared == [a[0] for a in module.ARGUMENTS]
