"""
nav2 localization with global localization: a drop-in for nav2_bringup's localization_launch.py.

Same arguments as nav2_bringup's (Jazzy) ``localization_launch.py`` (``namespace``, ``map``,
``use_sim_time``, ``autostart``, ``params_file``, ``use_composition``, ``container_name``,
``use_respawn``, ``log_level``) plus ``localizer_params_file``, ``index_file`` and
``localize_on_start``. Starts nav2's ``map_server`` and ``amcl`` managed (with bonds) by
``lifecycle_manager_localization``, as nav2_bringup does, and ``global_localizer`` managed by
``lifecycle_manager_global_localization`` (``bond_timeout: 0.0``: rclpy lifecycle nodes send no
bond heartbeats; ``autostart: false`` on the node, so it never fights its manager).

- Parameters: ``params_file`` is the nav2 params file (map_server and amcl sections; a
  ``global_localizer`` section is read too), rooted at ``namespace`` as RewrittenYaml does.
  global_localizer takes AMCL's ``base_frame_id``, ``global_frame_id``, ``odom_frame_id``,
  ``scan_topic`` and ``map_topic`` unless its own section sets them; ``localizer_params_file``
  (optional) comes last.
- Namespace: nodes are put in ``namespace`` unless a parent ``PushROSNamespace`` did so
  already (nav2_bringup's bringup_launch.py does).
- ``use_sim_time``: as nav2's, set on every node (empty: as a parent set it).
- Hand-over: ``global_localizer`` localizes the first scans after activation
  (``localize_on_start``) and publishes the pose on ``initialpose`` until ``amcl_pose``
  confirms it (AMCL may start later than the node).
- Behavior tree: global_localizer serves ``reinitialize_global_localization``
  (std_srvs/Empty, the ``ReinitializeGlobalLocalization`` BT node); AMCL's service of that name
  is moved to ``amcl/reinitialize_global_localization``.
- ``use_composition``: global_localizer is a Python node and is never composed; map_server and
  amcl run as their own processes as well (a note is logged when it is true).

Example::

    ros2 launch ssm_localization nav2_localization.launch.py map:=$HOME/maps/office.yaml \
        index_file:=$HOME/.ros/office_index.npz
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import (DeclareLaunchArgument, LogInfo, OpaqueFunction,
                            SetEnvironmentVariable)
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node, SetParameter
from ssm_localization.ros.launch_support import (amcl_equivalents, full_namespace, launch_bool,
                                                 namespaced_params_file, node_namespace)

PACKAGE = 'ssm_localization'
TF_REMAPS = [('/tf', 'tf'), ('/tf_static', 'tf_static')]
# global_localizer answers the behavior tree's reinitialize_global_localization: AMCL's moves
AMCL_REMAPS = [('/tf', 'tf'), ('/tf_static', 'tf_static'),
               ('reinitialize_global_localization', 'amcl/reinitialize_global_localization')]


def _arg(context, name):
    return LaunchConfiguration(name).perform(context)


def _nodes(context):
    """Create the nodes once the launch arguments are known (typed parameter values)."""
    pushed = context.launch_configurations.get('ros_namespace')
    namespace = _arg(context, 'namespace')
    ns = node_namespace(pushed, namespace) or ''     # launch_ros LifecycleNode needs a str
    root = full_namespace(pushed, namespace)
    autostart = launch_bool(_arg(context, 'autostart'), 'autostart')
    respawn = launch_bool(_arg(context, 'use_respawn'), 'use_respawn')
    log_args = ['--ros-args', '--log-level', _arg(context, 'log_level')]
    params_file = _arg(context, 'params_file')
    nav2_params = namespaced_params_file(params_file, root)
    from_amcl = amcl_equivalents(params_file, root)
    localizer = {
        'autostart': False,            # lifecycle_manager_global_localization drives it
        'publish_initialpose': True,   # hand the pose over to AMCL
        'serve_reinitialize_global_localization': True,
        'localize_on_start': launch_bool(_arg(context, 'localize_on_start'),
                                         'localize_on_start'),
    }
    index_file = _arg(context, 'index_file')
    if index_file:
        localizer['index_file'] = os.path.expanduser(index_file)
    extra = _arg(context, 'localizer_params_file')
    extra_params = [namespaced_params_file(extra, root)] if extra else []
    map_file = {}
    map_yaml = _arg(context, 'map')
    if map_yaml:            # else map_server's yaml_filename from params_file, as nav2's
        map_file['yaml_filename'] = os.path.expanduser(map_yaml)
    actions = []
    use_sim_time = _arg(context, 'use_sim_time')
    if use_sim_time:        # empty: keep a parent's SetParameter('use_sim_time', ...)
        actions.append(SetParameter('use_sim_time',
                                    launch_bool(use_sim_time, 'use_sim_time')))
    if launch_bool(_arg(context, 'use_composition'), 'use_composition'):
        actions.append(LogInfo(msg=f'ssm_localization: use_composition is not supported (the '
                                   f'container {_arg(context, "container_name")} is not used): '
                                   'map_server, amcl and global_localizer run as processes'))
    actions += [
        Node(
            package='nav2_map_server',
            executable='map_server',
            name='map_server',
            namespace=ns,
            output='screen',
            respawn=respawn,
            respawn_delay=2.0,
            parameters=[nav2_params, map_file],
            arguments=log_args,
            remappings=TF_REMAPS,
        ),
        Node(
            package='nav2_amcl',
            executable='amcl',
            name='amcl',
            namespace=ns,
            output='screen',
            respawn=respawn,
            respawn_delay=2.0,
            parameters=[nav2_params],
            arguments=log_args,
            remappings=AMCL_REMAPS,
        ),
        Node(
            package='nav2_lifecycle_manager',
            executable='lifecycle_manager',
            name='lifecycle_manager_localization',
            namespace=ns,
            output='screen',
            arguments=log_args,
            parameters=[{'autostart': autostart, 'node_names': ['map_server', 'amcl']}],
        ),
        LifecycleNode(
            package=PACKAGE,
            executable='global_localizer',
            name='global_localizer',
            namespace=ns,
            output='screen',
            respawn=respawn,
            respawn_delay=2.0,
            parameters=[from_amcl, nav2_params, *extra_params, localizer],
            arguments=log_args,
            remappings=TF_REMAPS,
        ),
        Node(
            package='nav2_lifecycle_manager',
            executable='lifecycle_manager',
            name='lifecycle_manager_global_localization',
            namespace=ns,
            output='screen',
            arguments=log_args,
            parameters=[{'autostart': autostart,
                         'bond_timeout': 0.0,     # no bond heartbeats from rclpy nodes
                         'node_names': ['global_localizer']}],
        ),
    ]
    return actions


def generate_launch_description():
    """Declare the arguments (nav2_bringup's, then ours); the nodes come from an OpaqueFunction."""
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        SetEnvironmentVariable('RCUTILS_LOGGING_BUFFERED_STREAM', '1'),
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='top-level namespace: roots the params file; nodes are put in it '
                        'unless a parent PushROSNamespace did so'),
        DeclareLaunchArgument(
            'map', default_value='',
            description='map_server map file (YAML); empty: yaml_filename of params_file'),
        DeclareLaunchArgument(
            'use_sim_time', default_value='',
            description='use the /clock topic (true/false); empty: as a parent set it, else '
                        'false'),
        DeclareLaunchArgument(
            'params_file',
            default_value=os.path.join(share, 'config', 'nav2_localization.yaml'),
            description='nav2 params file: map_server, amcl (and global_localizer) sections'),
        DeclareLaunchArgument(
            'autostart', default_value='true',
            description='the lifecycle managers configure and activate their nodes'),
        DeclareLaunchArgument(
            'use_composition', default_value='False',
            description='accepted for nav2_bringup compatibility; nothing is composed'),
        DeclareLaunchArgument(
            'container_name', default_value='nav2_container',
            description='accepted for nav2_bringup compatibility; not used'),
        DeclareLaunchArgument(
            'use_respawn', default_value='False',
            description='restart a node if it crashes'),
        DeclareLaunchArgument(
            'log_level', default_value='info', description='log level'),
        DeclareLaunchArgument(
            'localizer_params_file', default_value='',
            description='optional params file for global_localizer, applied last'),
        DeclareLaunchArgument(
            'index_file', default_value='',
            description='index (npz) for global_localizer; empty: the params file value'),
        DeclareLaunchArgument(
            'localize_on_start', default_value='true',
            description='global_localizer localizes the first scans and hands over to AMCL'),
        OpaqueFunction(function=_nodes),
    ])
