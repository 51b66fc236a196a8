"""
nav2 localization with start-up global localization.

Starts nav2's ``map_server`` and ``amcl`` (managed, with bonds, by
``lifecycle_manager_localization``, as nav2_bringup's localization launch does) and
``global_localizer`` (managed by ``lifecycle_manager_global_localization`` with
``bond_timeout: 0.0``: global_localizer is an rclpy lifecycle node without bond heartbeats).

Hand-over: ``global_localizer`` localizes the first scans after activation
(``localize_on_start``), publishes the pose on ``initialpose`` (``publish_initialpose``), and
AMCL tracks from there. Later relocalizations: ``global_localization`` (std_srvs/Empty, e.g.
from nav2's ``ReinitializeGlobalLocalization`` behavior-tree node) or ``relocalize``
(std_srvs/Trigger).

Example::

    ros2 launch ssm_localization nav2_localization.launch.py map:=$HOME/maps/office.yaml \
        index_file:=$HOME/.ros/office_index.npz
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node
from ssm_localization.ros.launch_support import launch_bool, namespaced_params_file

PACKAGE = 'ssm_localization'
TF_REMAPS = [('/tf', 'tf'), ('/tf_static', 'tf_static')]


def _arg(context, name):
    return LaunchConfiguration(name).perform(context)


def _nodes(context):
    """Create the nodes once the launch arguments are known (typed parameter values)."""
    namespace = _arg(context, 'namespace')
    use_sim_time = launch_bool(_arg(context, 'use_sim_time'), 'use_sim_time')
    autostart = launch_bool(_arg(context, 'autostart'), 'autostart')
    base_frame = _arg(context, 'base_frame')
    nav2_params = namespaced_params_file(_arg(context, 'nav2_params_file'), namespace)
    ssm_params = namespaced_params_file(_arg(context, 'params_file'), namespace)
    localizer = {
        'use_sim_time': use_sim_time,
        'autostart': False,            # lifecycle_manager_global_localization drives it
        'base_frame': base_frame,
        'publish_initialpose': True,   # hand the pose over to AMCL
        'localize_on_start': launch_bool(_arg(context, 'localize_on_start'),
                                         'localize_on_start'),
    }
    index_file = _arg(context, 'index_file')
    if index_file:
        localizer['index_file'] = os.path.expanduser(index_file)
    return [
        Node(
            package='nav2_map_server',
            executable='map_server',
            name='map_server',
            namespace=namespace,
            output='screen',
            parameters=[nav2_params, {'use_sim_time': use_sim_time,
                                      'yaml_filename': os.path.expanduser(_arg(context, 'map'))}],
        ),
        Node(
            package='nav2_amcl',
            executable='amcl',
            name='amcl',
            namespace=namespace,
            output='screen',
            parameters=[nav2_params, {'use_sim_time': use_sim_time,
                                      'base_frame_id': base_frame,
                                      'set_initial_pose': False}],
            remappings=TF_REMAPS,
        ),
        Node(
            package='nav2_lifecycle_manager',
            executable='lifecycle_manager',
            name='lifecycle_manager_localization',
            namespace=namespace,
            output='screen',
            parameters=[{'use_sim_time': use_sim_time,
                         'autostart': autostart,
                         'node_names': ['map_server', 'amcl']}],
        ),
        LifecycleNode(
            package=PACKAGE,
            executable='global_localizer',
            name='global_localizer',
            namespace=namespace,
            output='screen',
            parameters=[ssm_params, localizer],
            remappings=TF_REMAPS,
        ),
        Node(
            package='nav2_lifecycle_manager',
            executable='lifecycle_manager',
            name='lifecycle_manager_global_localization',
            namespace=namespace,
            output='screen',
            parameters=[{'use_sim_time': use_sim_time,
                         'autostart': autostart,
                         'bond_timeout': 0.0,     # no bond heartbeats from rclpy nodes
                         'node_names': ['global_localizer']}],
        ),
    ]


def generate_launch_description():
    """Declare the arguments; the nodes are created by an OpaqueFunction."""
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        DeclareLaunchArgument(
            'map', description='map_server map file (YAML) to load and localize on'),
        DeclareLaunchArgument(
            'params_file',
            default_value=os.path.join(share, 'config', 'ssm_localization.yaml'),
            description='ROS 2 params file with a global_localizer section'),
        DeclareLaunchArgument(
            'nav2_params_file',
            default_value=os.path.join(share, 'config', 'nav2_localization.yaml'),
            description='ROS 2 params file with map_server and amcl sections'),
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='namespace of every node (params file sections are nested under it)'),
        DeclareLaunchArgument(
            'use_sim_time', default_value='false',
            description='use the /clock topic (simulation or bag playback)'),
        DeclareLaunchArgument(
            'autostart', default_value='true',
            description='the lifecycle managers configure and activate their nodes'),
        DeclareLaunchArgument(
            'base_frame', default_value='base_link',
            description='robot base frame (global_localizer base_frame, amcl base_frame_id)'),
        DeclareLaunchArgument(
            'index_file', default_value='',
            description='index (npz) for global_localizer; empty: the params file value'),
        DeclareLaunchArgument(
            'localize_on_start', default_value='true',
            description='global_localizer localizes the first scans and hands over to AMCL'),
        OpaqueFunction(function=_nodes),
    ])
