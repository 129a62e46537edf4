"""
Launch the rig node, robot_state_publisher with the rig's URDF and, optionally, RViz.

    ros2 launch mech_balance rig.launch.py scene:=hoeken use_rviz:=true

The arguments are :data:`ARGUMENTS`; everything is checked before anything starts
(:func:`check`), and a failed launch leaves no process behind. docs/rviz_launch.md says
who publishes ``robot_description`` and TF, and what each argument does.
"""

import os

from ament_index_python.packages import get_package_prefix, get_package_share_directory
from ament_index_python.packages import PackageNotFoundError
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from mech_balance import schema as scene
from mech_balance.ros import params, urdf

PACKAGE = 'mech_balance'
EXECUTABLE = 'rig_node'
"""The rig node's console script (setup.py entry point)."""
PARAMS_FILE = 'config/rig_params.yaml'
"""The default params file, relative to the package's share directory."""
RVIZ_FILE = 'config/rig.rviz'
"""The RViz configuration, relative to the package's share directory."""
RVIZ_TOPICS = ('/robot_description', '/shaking_wrench')
"""Topics named in the RViz file; remapped into the namespace when one is given."""
ARGUMENTS = (
    ('scene', 'hoeken',
     "Built-in scene name or scene YAML path: the rig node's scene parameter and the URDF."),
    ('namespace', '', 'Namespace of the rig node, robot_state_publisher and RViz.'),
    ('use_robot_state_publisher', 'true',
     'true: start robot_state_publisher with the URDF of the scene (TF for RViz); '
     'false: the rig node publishes robot_description itself.'),
    ('use_rviz', 'false', 'true: also start rviz2 with the installed config/rig.rviz.'),
    ('params_file', None,
     'Parameters of the rig node (default: the installed config/rig_params.yaml).'),
)
"""Launch arguments: name, default (None: the installed params file), description."""
BOOLEANS = {'true': True, '1': True, 'false': False, '0': False}
"""The values a boolean launch argument takes (case-insensitive), as launch's IfCondition."""
REQUIRED = {
    PACKAGE: (EXECUTABLE, 'build and source this workspace (colcon build; '
                          'source install/setup.bash)'),
    'robot_state_publisher': ('robot_state_publisher',
                              'sudo apt install ros-jazzy-robot-state-publisher, '
                              'or use_robot_state_publisher:=false'),
    'rviz2': ('rviz2', 'sudo apt install ros-jazzy-rviz2, or use_rviz:=false'),
}
"""Package -> (executable it must install, how to get it or do without it)."""


def _share(relative):
    """Return the installed path of a file of the package (share/mech_balance/...)."""
    return os.path.join(get_package_share_directory(PACKAGE), relative)


def _missing_executable(package):
    """Return why ``package``'s executable cannot be started, or None when it can."""
    executable, remedy = REQUIRED[package]
    try:
        prefix = get_package_prefix(package)
    except PackageNotFoundError:
        return f"package '{package}' not found ({remedy})"
    path = os.path.join(prefix, 'lib', package, executable)
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        return f'{path}: no executable {executable!r} in package {package!r} ({remedy})'
    return None


def _boolean(name, value, problems):
    """Return the boolean of launch argument ``name``; a bad value is added to problems."""
    try:
        return BOOLEANS[value.strip().lower()]
    except KeyError:
        problems.append(f'{name}:={value!r}: expected true or false')
        return False


def check(values):
    """
    Return what to start for the launch arguments' ``values`` (a dict of name -> string).

    Every problem is collected first (bad booleans, a scene that does not load, an
    unreadable params file, a package or executable that is not installed); if there is
    any, raise RuntimeError listing them all, before any process is started.  Otherwise
    return a dict: scene, namespace, params_file, description (the URDF, or None without
    robot_state_publisher), use_robot_state_publisher, use_rviz.
    """
    problems = []
    use_rsp = _boolean('use_robot_state_publisher', values['use_robot_state_publisher'],
                       problems)
    use_rviz = _boolean('use_rviz', values['use_rviz'], problems)
    packages = [PACKAGE] + ['robot_state_publisher'] * use_rsp + ['rviz2'] * use_rviz
    problems += [p for p in map(_missing_executable, packages) if p]
    frame_id = sc = None
    try:
        frame_id = params.frame_id_from_params_file(values['params_file'])
    except ValueError as exc:
        problems.append(str(exc))
    try:
        sc = scene.load(values['scene'])
    except (OSError, ValueError) as exc:
        problems.append(f'scene:={values["scene"]}: {exc}')
    if problems:
        raise RuntimeError('rig.launch.py: nothing was started:\n  - '
                           + '\n  - '.join(problems))
    return {'scene': values['scene'], 'namespace': values['namespace'].strip('/'),
            'params_file': values['params_file'],
            'description': urdf.urdf_xml(sc, frame_id=frame_id) if use_rsp else None,
            'use_robot_state_publisher': use_rsp, 'use_rviz': use_rviz}


def nodes(plan):
    """Return the Node actions of a :func:`check` plan (required nodes shut the launch down)."""
    namespace = plan['namespace']
    prefix = f'/{namespace}' if namespace else ''
    use_rsp = plan['use_robot_state_publisher']
    out = [Node(package=PACKAGE, executable=EXECUTABLE, namespace=namespace, output='screen',
                parameters=[plan['params_file'],
                            {'scene': ParameterValue(plan['scene'], value_type=str),
                             # robot_state_publisher publishes the URDF when it runs
                             'publish_robot_description': not use_rsp}],
                on_exit=Shutdown(reason=f'{EXECUTABLE} exited'))]
    if use_rsp:
        out.append(Node(
            package='robot_state_publisher', executable='robot_state_publisher',
            namespace=namespace, output='screen',
            # a string, not YAML: the XML's comments hold ': ' (launch_ros would parse it)
            parameters=[{'robot_description': ParameterValue(plan['description'],
                                                             value_type=str)}],
            on_exit=Shutdown(reason='robot_state_publisher exited')))
    if plan['use_rviz']:
        out.append(Node(
            package='rviz2', executable='rviz2', namespace=namespace, output='screen',
            arguments=['-d', _share(RVIZ_FILE)],
            remappings=[(topic, prefix + topic) for topic in RVIZ_TOPICS] if prefix else []))
    return out


def _nodes(context):
    """Check the launch arguments, then return the nodes to start (an OpaqueFunction)."""
    values = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGUMENTS}
    return nodes(check(values))


def generate_launch_description():
    """Return the launch description: the arguments, then the nodes (module docstring)."""
    declared = [DeclareLaunchArgument(name, default_value=_share(PARAMS_FILE)
                                      if default is None else default, description=text)
                for name, default, text in ARGUMENTS]
    return LaunchDescription(declared + [OpaqueFunction(function=_nodes)])
