"""
launch/rig.launch.py and config/rig.rviz checked against the package.

The launch file names an executable, a params file and an RViz file: they must be what
setup.py installs, and its arguments must be documented in docs/rviz_launch.md.  launch and
launch_ros are not on PyPI, so the file is read as source here (its constants are plain
literals) and run against a stand-in of the few launch classes it uses (:func:`stub_launch`:
they record what they are given), which holds its checks before starting anything, its
arguments and which nodes it starts; where launch_ros is importable the test also builds its
real LaunchDescription.
"""

import ast
import importlib
import importlib.util
import math
import os
from pathlib import Path
import re
import runpy
import sys
import types
import xml.etree.ElementTree as ET

from mech_balance import schema as scene
from mech_balance.analysis import cycle as analysis
from mech_balance.ros import names as ros_names, params, urdf
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
    assert names == ['scene', 'namespace', 'use_robot_state_publisher', 'use_rviz',
                     'params_file']
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


def test_the_default_scene_and_frame_id_are_the_nodes():
    c = _constants()
    spec = {s.name: s for s in params.PARAMETERS}
    assert {a[0]: a[1] for a in c['ARGUMENTS']}['scene'] == spec['scene'].default
    assert params.frame_id_from_params_file(ROOT / c['PARAMS_FILE']) == \
        spec['frame_id'].default == urdf.DEFAULT_FRAME_ID


def test_frame_id_from_a_params_file(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    frame_id: a\n'
                    '/cell/rig:\n  ros__parameters:\n    frame_id: b\n'
                    '/other:\n  ros__parameters:\n    frame_id: c\n')
    assert params.frame_id_from_params_file(path) == 'b'   # later sections win, as in ROS
    path.write_text('/**:\n  ros__parameters:\n    scene: hoeken\n')
    assert params.frame_id_from_params_file(path) == urdf.DEFAULT_FRAME_ID
    with pytest.raises(ValueError, match='params_file: got .*cannot read it'):
        params.frame_id_from_params_file(tmp_path / 'missing.yaml')
    path.write_text('/**:\n  ros__parameters:\n    frame_id: ""\n')
    with pytest.raises(ValueError, match='params_file: frame_id: got'):
        params.frame_id_from_params_file(path)


def test_rig_node_name_matches():
    node = pytest.importorskip('mech_balance.ros.node')
    assert ros_names.NODE_NAME == node.NODE_NAME


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


class _Recorded:
    """A stand-in launch class: keeps its arguments; Node instances are counted."""

    created = []

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs
        type(self).created.append(self)


class _Configuration:
    """A stand-in LaunchConfiguration: perform(context) reads the context dict."""

    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context[self.name]


@pytest.fixture()
def stub_launch(monkeypatch, tmp_path):
    """
    Load launch/rig.launch.py against stand-ins of launch and launch_ros.

    Return (module, install): ``install(*packages)`` makes those packages' executables
    exist (in a fake install prefix under tmp_path); any other package is not found.
    """
    node = type('Node', (_Recorded,), {'created': []})
    classes = {'launch': {'LaunchDescription': type('LaunchDescription', (_Recorded,), {})},
               'launch.actions': {n: type(n, (_Recorded,), {}) for n in
                                  ('DeclareLaunchArgument', 'OpaqueFunction', 'Shutdown')},
               'launch.substitutions': {'LaunchConfiguration': _Configuration},
               'launch_ros': {},
               'launch_ros.actions': {'Node': node},
               'launch_ros.parameter_descriptions': {
                   'ParameterValue': lambda value, value_type: value_type(value)}}
    for name, attributes in classes.items():
        monkeypatch.setitem(sys.modules, name, types.SimpleNamespace(**attributes))
    spec = importlib.util.spec_from_file_location('rig_launch_stubbed', LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    present = set()

    def prefix(package):
        if package not in present:
            raise module.PackageNotFoundError(package)
        return str(tmp_path)

    def install(*packages):
        for package in packages:
            present.add(package)
            path = tmp_path / 'lib' / package / module.REQUIRED[package][0]
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text('#!/bin/sh\n')
            path.chmod(0o755)

    monkeypatch.setattr(module, 'get_package_prefix', prefix)
    monkeypatch.setattr(module, 'get_package_share_directory', lambda package: str(ROOT))
    return module, install


def _context(module, **values):
    """Return the launch arguments' values: the defaults, overridden by ``values``."""
    out = {name: module._share(module.PARAMS_FILE) if default is None else default
           for name, default, _ in module.ARGUMENTS}
    out.update(values)
    return out


def _started(nodes):
    """Return the packages of the nodes, in order."""
    return [n.kwargs['package'] for n in nodes]


def test_the_default_launch_starts_the_node_and_robot_state_publisher(stub_launch):
    module, install = stub_launch
    install('mech_balance', 'robot_state_publisher')
    description = module.generate_launch_description()
    declared = [e for e in description.args[0] if type(e).__name__ == 'DeclareLaunchArgument']
    assert [d.args[0] for d in declared] == [a[0] for a in module.ARGUMENTS]
    opaque = description.args[0][-1]
    nodes = opaque.kwargs['function'](_context(module))
    assert _started(nodes) == ['mech_balance', 'robot_state_publisher']
    rig, rsp = nodes
    assert rig.kwargs['parameters'][1] == {'scene': 'hoeken', 'publish_robot_description': False}
    assert rsp.kwargs['parameters'][0]['robot_description'] == \
        urdf.urdf_xml(scene.load('hoeken'), frame_id=urdf.DEFAULT_FRAME_ID)
    for required in nodes:   # either one exiting stops the launch: nothing is left behind
        assert type(required.kwargs['on_exit']).__name__ == 'Shutdown'


def test_arguments_choose_what_is_started(stub_launch, tmp_path):
    module, install = stub_launch
    install('mech_balance', 'rviz2')
    params_file = tmp_path / 'p.yaml'
    params_file.write_text('/**:\n  ros__parameters:\n    frame_id: cell_a\n')
    nodes = module.nodes(module.check(_context(
        module, use_robot_state_publisher='False', use_rviz='1', namespace='/cell/',
        scene='slider_crank', params_file=str(params_file))))
    assert _started(nodes) == ['mech_balance', 'rviz2']
    rig, rviz = nodes
    assert rig.kwargs['namespace'] == rviz.kwargs['namespace'] == 'cell'
    assert rig.kwargs['parameters'] == [
        str(params_file), {'scene': 'slider_crank', 'publish_robot_description': True}]
    assert dict(rviz.kwargs['remappings']) == {t: '/cell' + t for t in module.RVIZ_TOPICS}
    assert rviz.kwargs['arguments'] == ['-d', str(ROOT / module.RVIZ_FILE)]


@pytest.mark.parametrize('values, installed, expected', [
    ({}, ('mech_balance',),
     [r"package 'robot_state_publisher' not found \(sudo apt install "
      r'ros-jazzy-robot-state-publisher, or use_robot_state_publisher:=false\)']),
    ({'use_rviz': 'true'}, ('mech_balance', 'robot_state_publisher'),
     [r"package 'rviz2' not found \(.*use_rviz:=false\)"]),
    ({}, ('robot_state_publisher',), [r"package 'mech_balance' not found \(build and source"]),
    ({'use_rviz': 'yes', 'scene': 'hoekn', 'use_robot_state_publisher': 'false'},
     ('mech_balance',),
     [r"use_rviz:='yes': expected true or false", r'scene:=hoekn: .*hoeken']),
    ({'params_file': '/nonexistent/p.yaml'}, ('mech_balance', 'robot_state_publisher'),
     [r'params_file: got .*nonexistent.*cannot read it']),
])
def test_a_launch_that_cannot_run_starts_nothing(stub_launch, values, installed, expected):
    """Every problem is reported at once, before any process (Node) is created."""
    module, install = stub_launch
    install(*installed)
    node_class = sys.modules['launch_ros.actions'].Node
    with pytest.raises(RuntimeError, match='nothing was started') as error:
        module._nodes(_context(module, **values))
    for pattern in expected:
        assert re.search(pattern, str(error.value)), (pattern, str(error.value))
    assert str(error.value).count('\n  - ') == len(expected)
    assert node_class.created == []


def test_an_executable_missing_from_an_installed_package_is_named(stub_launch, tmp_path):
    module, install = stub_launch
    install('mech_balance', 'robot_state_publisher')
    os.remove(tmp_path / 'lib' / 'robot_state_publisher' / 'robot_state_publisher')
    with pytest.raises(RuntimeError, match="no executable 'robot_state_publisher' in package"):
        module.check(_context(module))
