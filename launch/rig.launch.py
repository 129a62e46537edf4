"""
Launch the rig node, robot_state_publisher with the rig's URDF and, optionally, RViz.

    ros2 launch mech_balance rig.launch.py scene:=hoeken use_rviz:=true

The URDF is generated here, at launch, by :func:`mech_balance.urdf.urdf_xml` for the
launched scene, with the root link named after the node's ``frame_id`` from the params
file, and handed to robot_state_publisher as its ``robot_description`` parameter;
robot_state_publisher then owns the ``robot_description`` topic, so the rig node is started
with ``publish_robot_description`` false (one publisher per topic).  robot_state_publisher
turns the node's ``joint_states`` (every URDF joint, in the URDF's zero convention) into TF.
The launch arguments are :data:`ARGUMENTS` (documented in README.md, section "RViz,
robot_state_publisher and launch").
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from mech_balance import schema as scene
from mech_balance.cli import urdf as cli_urdf
from mech_balance.ros import urdf

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
    ('use_rviz', 'false', 'true: also start rviz2 with the installed config/rig.rviz.'),
    ('params_file', None,
     'Parameters of the rig node (default: the installed config/rig_params.yaml).'),
)
"""Launch arguments: name, default (None: the installed params file), description."""


def _share(relative):
    """Return the installed path of a file of the package (share/mech_balance/...)."""
    return os.path.join(get_package_share_directory(PACKAGE), relative)


def _nodes(context):
    """Return the nodes for the launch arguments' values (an OpaqueFunction)."""
    scene_name = LaunchConfiguration('scene').perform(context)
    namespace = LaunchConfiguration('namespace').perform(context).strip('/')
    params_file = LaunchConfiguration('params_file').perform(context)
    frame_id = cli_urdf.frame_id_from_params_file(params_file)
    description = urdf.urdf_xml(scene.load(scene_name), frame_id=frame_id)
    prefix = f'/{namespace}' if namespace else ''
    return [
        Node(package=PACKAGE, executable=EXECUTABLE, namespace=namespace, output='screen',
             parameters=[params_file, {'scene': ParameterValue(scene_name, value_type=str),
                                       # robot_state_publisher publishes the URDF
                                       'publish_robot_description': False}]),
        Node(package='robot_state_publisher', executable='robot_state_publisher',
             namespace=namespace, output='screen',
             # a string, not YAML: the XML's comments hold ': ' (launch_ros would parse it)
             parameters=[{'robot_description': ParameterValue(description, value_type=str)}]),
        Node(package='rviz2', executable='rviz2', namespace=namespace, output='screen',
             arguments=['-d', _share(RVIZ_FILE)],
             remappings=[(topic, prefix + topic) for topic in RVIZ_TOPICS] if prefix else [],
             condition=IfCondition(LaunchConfiguration('use_rviz'))),
    ]


def generate_launch_description():
    """Return the launch description: the arguments, then the nodes (module docstring)."""
    declared = [DeclareLaunchArgument(name, default_value=_share(PARAMS_FILE)
                                      if default is None else default, description=text)
                for name, default, text in ARGUMENTS]
    return LaunchDescription(declared + [OpaqueFunction(function=_nodes)])
