"""
The launch files executed against stand-ins of ``launch`` and ``launch_ros``.

``launch`` and ``launch_ros`` are not on PyPI, so CI runs each launch file's
``generate_launch_description()`` and its ``OpaqueFunction`` with small stand-in modules that
record what the real ones would receive: the nodes' namespaces, parameters, remappings and
arguments, and the ``SetParameter`` actions. The launch context is the one nav2_bringup's
``bringup_launch.py`` builds (a parent ``PushROSNamespace('robot1')`` stored as the
``ros_namespace`` launch configuration, the namespace passed as an argument too), or none. The
same files were run under the real launch 3.4.3 / launch_ros 0.26.6 (docs/ROS_API.md).
"""
from __future__ import annotations

import importlib.util
import sys
import types

from helpers import REPO
import pytest
import yaml

LAUNCH = REPO / 'launch'


class Recorded:
    """An action of a stand-in module: its class name and keyword arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs

    def __repr__(self):
        return f'{type(self).__name__}{self.args}{self.kwargs}'


class DeclareLaunchArgument(Recorded):
    pass


class OpaqueFunction(Recorded):
    pass


class SetEnvironmentVariable(Recorded):
    pass


class LogInfo(Recorded):
    pass


class Node(Recorded):
    pass


class LifecycleNode(Recorded):
    pass


class SetParameter(Recorded):
    pass


class LaunchDescription(Recorded):
    pass


class LaunchConfiguration:
    def __init__(self, name):
        self.name = name

    def perform(self, context):
        return context.launch_configurations[self.name]


class Context:
    def __init__(self, configurations):
        self.launch_configurations = configurations


@pytest.fixture
def standins(monkeypatch, tmp_path):
    """Install the stand-in modules and an ament index with this package's share folder."""
    modules = {
        'launch': {'LaunchDescription': LaunchDescription},
        'launch.actions': {'DeclareLaunchArgument': DeclareLaunchArgument,
                           'OpaqueFunction': OpaqueFunction, 'LogInfo': LogInfo,
                           'SetEnvironmentVariable': SetEnvironmentVariable},
        'launch.substitutions': {'LaunchConfiguration': LaunchConfiguration},
        'launch_ros': {},
        'launch_ros.actions': {'Node': Node, 'LifecycleNode': LifecycleNode,
                               'SetParameter': SetParameter},
        'ament_index_python': {},
        'ament_index_python.packages': {'get_package_share_directory': lambda pkg: str(REPO)},
    }
    for name, attrs in modules.items():
        module = types.ModuleType(name)
        module.__dict__.update(attrs)
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.setattr('tempfile.tempdir', str(tmp_path))


def _run(name: str, **arguments):
    """Run ``launch/NAME``: ``(declared defaults, the OpaqueFunction's actions)``."""
    spec = importlib.util.spec_from_file_location(name.replace('.', '_'), LAUNCH / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    actions = description.args[0]
    config = {a.args[0]: a.kwargs.get('default_value') for a in actions
              if isinstance(a, DeclareLaunchArgument)}
    config.update(arguments)
    opaque, = [a for a in actions if isinstance(a, OpaqueFunction)]
    return config, opaque.kwargs['function'](Context(config))


def _nodes(actions) -> dict:
    return {a.kwargs['name']: a for a in actions if isinstance(a, (Node, LifecycleNode))}


def _params(node) -> list:
    """Each entry of the node's parameters: a dict, or the content of a params file."""
    out = []
    for item in node.kwargs['parameters']:
        out.append(item if isinstance(item, dict) else yaml.safe_load(open(item)))
    return out


def test_global_localizer_under_nav2_bringups_namespace(standins):
    """PushROSNamespace('robot1') + namespace:=robot1: /robot1/global_localizer, not twice."""
    _, actions = _run('global_localizer.launch.py', ros_namespace='/robot1', namespace='robot1')
    node = _nodes(actions)['global_localizer']
    assert node.kwargs['namespace'] == ''          # the parent's push is all there is
    params_file, overrides = _params(node)
    assert 'global_localizer' in params_file['robot1']      # rooted where rcl looks for it
    assert overrides == {'autostart': True, 'localize_on_start': False}
    assert not [a for a in actions if isinstance(a, SetParameter)], \
        'use_sim_time left to the parent'
    assert node.kwargs['arguments'] == ['--ros-args', '--log-level', 'info']
    assert node.kwargs['respawn'] is False


def test_global_localizer_on_its_own_in_a_namespace_with_sim_time(standins):
    _, actions = _run('global_localizer.launch.py', namespace='robot1', use_sim_time='true',
                      autostart='false', use_respawn='true', log_level='debug')
    node = _nodes(actions)['global_localizer']
    assert node.kwargs['namespace'] == 'robot1'
    assert 'global_localizer' in _params(node)[0]['robot1']
    set_param, = [a for a in actions if isinstance(a, SetParameter)]
    assert set_param.args == ('use_sim_time', True)
    assert actions.index(set_param) < actions.index(node), 'scoped before the node'
    assert _params(node)[1]['autostart'] is False and node.kwargs['respawn'] is True
    assert node.kwargs['arguments'][-1] == 'debug'


def test_nav2_entry_as_nav2_bringup_includes_it(standins, tmp_path):
    nav2 = tmp_path / 'nav2_params.yaml'
    nav2.write_text(yaml.safe_dump({
        'amcl': {'ros__parameters': {'base_frame_id': 'base_footprint', 'scan_topic': 'scan'}},
        'map_server': {'ros__parameters': {'yaml_filename': 'office.yaml'}}}))
    _, actions = _run('nav2_localization.launch.py', ros_namespace='/robot1',
                      namespace='robot1', params_file=str(nav2), use_sim_time='True',
                      autostart='true', use_composition='False', use_respawn='False')
    nodes = _nodes(actions)
    assert set(nodes) == {'map_server', 'amcl', 'lifecycle_manager_localization',
                          'global_localizer', 'lifecycle_manager_global_localization'}
    assert all(n.kwargs['namespace'] == '' for n in nodes.values())
    assert [a.args for a in actions if isinstance(a, SetParameter)] == [('use_sim_time', True)]
    # map: empty -> map_server's yaml_filename from the params file, as nav2's
    assert _params(nodes['map_server'])[1] == {}
    assert ('reinitialize_global_localization', 'amcl/reinitialize_global_localization') in \
        nodes['amcl'].kwargs['remappings']
    from_amcl, rooted, fixed = _params(nodes['global_localizer'])
    assert from_amcl == {'base_frame': 'base_footprint', 'scan_topic': 'scan'}
    assert 'amcl' in rooted['robot1']
    assert fixed['autostart'] is False and fixed['publish_initialpose'] is True
    assert fixed['serve_reinitialize_global_localization'] is True
    manager = _params(nodes['lifecycle_manager_global_localization'])[0]
    assert manager == {'autostart': True, 'bond_timeout': 0.0,
                       'node_names': ['global_localizer']}
    assert _params(nodes['lifecycle_manager_localization'])[0]['node_names'] == \
        ['map_server', 'amcl']


def test_nav2_entry_on_its_own_with_a_map_and_composition_noted(standins):
    config, actions = _run('nav2_localization.launch.py', map='~/office.yaml',
                           use_composition='True', index_file='~/office.npz')
    assert config['params_file'].endswith('config/nav2_localization.yaml')
    nodes = _nodes(actions)
    assert nodes['map_server'].kwargs['namespace'] == ''
    assert _params(nodes['map_server'])[1]['yaml_filename'].endswith('/office.yaml')
    assert not _params(nodes['map_server'])[1]['yaml_filename'].startswith('~')
    fixed = _params(nodes['global_localizer'])[-1]
    assert fixed['index_file'].endswith('/office.npz') and fixed['localize_on_start'] is True
    assert not [a for a in actions if isinstance(a, SetParameter)]
    note, = [a for a in actions if isinstance(a, LogInfo)]
    assert 'use_composition is not supported' in note.kwargs['msg']


def test_bad_boolean_arguments_are_named(standins):
    with pytest.raises(ValueError, match='use_respawn'):
        _run('global_localizer.launch.py', use_respawn='maybe')
