"""
Launch ``global_localizer`` on its own (a lifecycle node, no lifecycle manager).

By default (``autostart:=true``) the node configures and activates itself. With
``autostart:=false`` it stays unconfigured until a lifecycle manager (or
``ros2 lifecycle set``) drives it: set it false whenever a manager manages the node.

As nav2_bringup's launch files: ``namespace`` roots the params file; the node is put in it
unless a parent ``PushROSNamespace`` did so already. ``use_sim_time`` left empty keeps what a
parent set (``SetParameter``), else false.

Examples::

    ros2 launch ssm_localization global_localizer.launch.py
    ros2 launch ssm_localization global_localizer.launch.py namespace:=robot1 \
        index_file:=$HOME/.ros/intel_index.npz localize_on_start:=true
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, SetParameter
from ssm_localization.ros.launch_support import (full_namespace, launch_bool,
                                                 namespaced_params_file, node_namespace)

PACKAGE = 'ssm_localization'
TF_REMAPS = [('/tf', 'tf'), ('/tf_static', 'tf_static')]


def _arg(context, name):
    return LaunchConfiguration(name).perform(context)


def _global_localizer(context):
    """Create the node once the launch arguments are known (typed parameter values)."""
    pushed = context.launch_configurations.get('ros_namespace')
    namespace = _arg(context, 'namespace')
    overrides = {
        'autostart': launch_bool(_arg(context, 'autostart'), 'autostart'),
        'localize_on_start': launch_bool(_arg(context, 'localize_on_start'),
                                         'localize_on_start'),
    }
    index_file = _arg(context, 'index_file')
    if index_file:
        overrides['index_file'] = os.path.expanduser(index_file)
    actions = []
    use_sim_time = _arg(context, 'use_sim_time')
    if use_sim_time:        # empty: keep a parent's SetParameter('use_sim_time', ...)
        actions.append(SetParameter('use_sim_time',
                                    launch_bool(use_sim_time, 'use_sim_time')))
    actions.append(LifecycleNode(
        package=PACKAGE,
        executable='global_localizer',
        name='global_localizer',
        namespace=node_namespace(pushed, namespace) or '',   # LifecycleNode needs a str
        output='screen',
        respawn=launch_bool(_arg(context, 'use_respawn'), 'use_respawn'),
        respawn_delay=2.0,
        parameters=[namespaced_params_file(_arg(context, 'params_file'),
                                           full_namespace(pushed, namespace)),
                    overrides],
        arguments=['--ros-args', '--log-level', _arg(context, 'log_level')],
        # tf listeners subscribe /tf and /tf_static: keep them inside the namespace
        remappings=TF_REMAPS,
    ))
    return actions


def generate_launch_description():
    """Declare the arguments; the node itself is created by an OpaqueFunction."""
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        SetEnvironmentVariable('RCUTILS_LOGGING_BUFFERED_STREAM', '1'),
        DeclareLaunchArgument(
            'params_file',
            default_value=os.path.join(share, 'config', 'ssm_localization.yaml'),
            description='ROS 2 params file with a global_localizer section'),
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='namespace: roots the params file; the node is put in it unless a '
                        'parent PushROSNamespace did so'),
        DeclareLaunchArgument(
            'use_sim_time', default_value='',
            description='use the /clock topic (true/false); empty: as a parent set it, else '
                        'false'),
        DeclareLaunchArgument(
            'autostart', default_value='true',
            description='configure and activate on start; false when a lifecycle manager '
                        'drives the node'),
        DeclareLaunchArgument(
            'index_file', default_value='',
            description='index (npz) to load at configure; empty: the params file value'),
        DeclareLaunchArgument(
            'localize_on_start', default_value='false',
            description='once active, localize incoming scans until the first ok pose'),
        DeclareLaunchArgument(
            'use_respawn', default_value='False',
            description='restart the node if it crashes'),
        DeclareLaunchArgument(
            'log_level', default_value='info', description='log level'),
        OpaqueFunction(function=_global_localizer),
    ])
