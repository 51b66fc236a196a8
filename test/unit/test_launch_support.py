"""
ssm_localization.ros.launch_support.

Launch argument parsing and namespaced params files (the latter checked against rcl's own
params-file matching).
"""
from __future__ import annotations

from helpers import RCLPY_SKIP_REASON
import pytest
from ssm_localization.ros.launch_support import (amcl_equivalents, full_namespace, launch_bool,
                                                 namespace_tokens, namespaced_params_file,
                                                 nest_under_namespace, node_namespace)
import yaml


@pytest.mark.parametrize('text, value', [('true', True), ('True', True), ('1', True),
                                         ('false', False), ('FALSE', False), ('0', False)])
def test_launch_bool(text, value):
    assert launch_bool(text, 'autostart') is value


@pytest.mark.parametrize('text', ['', 'maybe', 'ture', '2'])
def test_launch_bool_refuses_other_text_naming_the_argument(text):
    with pytest.raises(ValueError, match='autostart'):
        launch_bool(text, 'autostart')


def test_namespace_tokens():
    assert namespace_tokens('') == [] and namespace_tokens('/') == []
    assert namespace_tokens('/robot1/arm/') == ['robot1', 'arm']


def test_nest_under_namespace_keeps_absolute_keys():
    data = {'global_localizer': {'ros__parameters': {'mode': 'continuous'}},
            '/**': {'ros__parameters': {'use_sim_time': True}}}
    assert nest_under_namespace(data, '') is data
    nested = nest_under_namespace(data, '/a/b')
    assert nested['a']['b']['global_localizer'] == data['global_localizer']
    assert nested['/**'] == data['/**']


@pytest.mark.parametrize('pushed, namespace, own, full', [
    (None, '', None, '/'),
    (None, 'robot1', 'robot1', '/robot1'),
    ('/robot1', 'robot1', None, '/robot1'),          # nav2_bringup: pushed and passed
    ('/robot1', '', None, '/robot1'),                # pushed only
    ('/fleet/robot1', '/robot1/', None, '/fleet/robot1'),
    ('/fleet', 'robot1', 'robot1', '/fleet/robot1'),
])
def test_the_namespace_is_pushed_once(pushed, namespace, own, full):
    assert node_namespace(pushed, namespace) == own
    assert full_namespace(pushed, namespace) == full


def test_a_file_nested_under_the_namespace_already_is_kept():
    data = {'robot1': {'global_localizer': {'ros__parameters': {'mode': 'continuous'}}}}
    assert nest_under_namespace(data, '/robot1') is data


def test_amcl_equivalents_follow_amcl_unless_global_localizer_says_otherwise(tmp_path):
    p = tmp_path / 'nav2.yaml'
    p.write_text(yaml.safe_dump({
        'amcl': {'ros__parameters': {'base_frame_id': 'base_footprint', 'global_frame_id': 'map',
                                     'scan_topic': 'front/scan', 'max_particles': 2000}},
        'global_localizer': {'ros__parameters': {'map_frame': 'world'}}}))
    assert amcl_equivalents(p) == {'base_frame': 'base_footprint', 'scan_topic': 'front/scan'}
    nested = tmp_path / 'nested.yaml'
    nested.write_text(yaml.safe_dump({'robot1': {'amcl': {'ros__parameters': {
        'odom_frame_id': 'robot1/odom'}}}}))
    assert amcl_equivalents(nested, '/robot1') == {'odom_frame': 'robot1/odom'}
    assert amcl_equivalents(nested) == {}
    with pytest.raises(ValueError, match='not found'):
        amcl_equivalents(tmp_path / 'missing.yaml')


def test_namespaced_params_file_errors_name_the_file(tmp_path):
    with pytest.raises(ValueError, match='not found'):
        namespaced_params_file(tmp_path / 'missing.yaml', 'robot1')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('- a list\n')
    with pytest.raises(ValueError, match='bad.yaml'):
        namespaced_params_file(bad, 'robot1')
    good = tmp_path / 'ok.yaml'
    good.write_text('global_localizer: {ros__parameters: {mode: on_demand}}\n')
    assert namespaced_params_file(good, '') == str(good)       # no namespace: used as it is


@pytest.mark.ros
def test_rcl_applies_the_namespaced_file_and_not_the_plain_one(ros_domain, tmp_path):
    """
    The reason for the helper.

    Rcl matches ``global_localizer:`` only in the root namespace, the nested form inside
    ``/robot1``.
    """
    rclpy = pytest.importorskip('rclpy', reason=RCLPY_SKIP_REASON)
    plain = tmp_path / 'params.yaml'
    plain.write_text(yaml.safe_dump(
        {'global_localizer': {'ros__parameters': {'scan_timeout': 7.5}}}))
    nested = namespaced_params_file(plain, '/robot1')
    assert nested != str(plain)

    def value(params_file: str, namespace: str):
        ctx = rclpy.Context()
        rclpy.init(args=['--ros-args', '--params-file', params_file], context=ctx)
        try:
            node = rclpy.create_node('global_localizer', namespace=namespace, context=ctx,
                                     automatically_declare_parameters_from_overrides=True)
            try:
                return node.get_parameter_or('scan_timeout').value
            finally:
                node.destroy_node()
        finally:
            rclpy.try_shutdown(context=ctx)

    assert value(str(plain), '') == 7.5
    assert value(str(plain), 'robot1') is None          # what the helper fixes
    assert value(nested, 'robot1') == 7.5
    assert value(nested, 'robot2') is None
