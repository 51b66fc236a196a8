"""
Launch ``global_localizer`` on its own (a lifecycle node).

By default (``autostart:=true``) the node configures and activates itself. With
``autostart:=false`` it stays unconfigured until a lifecycle manager (or
``ros2 lifecycle set``) drives it.

Examples::

    ros2 launch ssm_localization global_localizer.launch.py
    ros2 launch ssm_localization global_localizer.launch.py namespace:=robot1 \
        index_file:=$HOME/.ros/intel_index.npz localize_on_start:=true
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode
from ssm_localization.ros.launch_support import launch_bool, namespaced_params_file

PACKAGE = 'ssm_localization'


def _arg(context, name):
    return LaunchConfiguration(name).perform(context)


def _global_localizer(context):
    """Create the node once the launch arguments are known (typed parameter values)."""
    namespace = _arg(context, 'namespace')
    overrides = {
        'use_sim_time': launch_bool(_arg(context, 'use_sim_time'), 'use_sim_time'),
        'autostart': launch_bool(_arg(context, 'autostart'), 'autostart'),
        'localize_on_start': launch_bool(_arg(context, 'localize_on_start'),
                                         'localize_on_start'),
    }
    index_file = _arg(context, 'index_file')
    if index_file:
        overrides['index_file'] = os.path.expanduser(index_file)
    return [
        LifecycleNode(
            package=PACKAGE,
            executable='global_localizer',
            name='global_localizer',
            namespace=namespace,
            output='screen',
            parameters=[namespaced_params_file(_arg(context, 'params_file'), namespace),
                        overrides],
            # tf listeners subscribe /tf and /tf_static: keep them inside the namespace
            remappings=[('/tf', 'tf'), ('/tf_static', 'tf_static')],
        ),
    ]


def generate_launch_description():
    """Declare the arguments; the node itself is created by an OpaqueFunction."""
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file',
            default_value=os.path.join(share, 'config', 'ssm_localization.yaml'),
            description='ROS 2 params file with a global_localizer section'),
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='namespace of the node (its params file sections are nested under it)'),
        DeclareLaunchArgument(
            'use_sim_time', default_value='false',
            description='use the /clock topic (simulation or bag playback)'),
        DeclareLaunchArgument(
            'autostart', default_value='true',
            description='configure and activate on start; false: wait for a lifecycle manager'),
        DeclareLaunchArgument(
            'index_file', default_value='',
            description='index (npz) to load at configure; empty: the params file value'),
        DeclareLaunchArgument(
            'localize_on_start', default_value='false',
            description='once active, localize incoming scans until the first ok pose'),
        OpaqueFunction(function=_global_localizer),
    ])
