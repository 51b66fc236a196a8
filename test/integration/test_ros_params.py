"""
Check the generated params file and docs against the declared parameters.

config/ssm_localization.yaml and docs/PARAMETERS.md against the parameters the nodes declare, and
--params-file.
"""
from __future__ import annotations

from helpers import REPO
import pytest
import rclpy
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import TransitionCallbackReturn
import yaml

pytestmark = pytest.mark.ros

PARAMS = REPO / 'config' / 'ssm_localization.yaml'
DOCS = REPO / 'docs' / 'PARAMETERS.md'
AUTO = {'use_sim_time', 'start_type_description_service'}   # declared by rclpy itself


def _flat(d: dict, prefix: str = '') -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, f'{prefix}{k}.'))
        else:
            out[prefix + k] = v
    return out


def _make(node_cls, args: list[str] | None = None):
    ctx = rclpy.Context()
    rclpy.init(args=args, context=ctx)
    try:
        return ctx, node_cls(context=ctx)
    except Exception:
        rclpy.try_shutdown(context=ctx)
        raise


def _close(ctx, node) -> None:
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def test_params_file_and_parameter_docs_are_current():
    from ssm_localization.ros.parameters import parameters_markdown, params_yaml
    assert PARAMS.read_text() == params_yaml(), (
        'config/ssm_localization.yaml is stale; regenerate it with: make params-yaml')
    assert DOCS.read_text() == parameters_markdown(), (
        'docs/PARAMETERS.md is stale; regenerate it with: make params-yaml')


def test_parameter_docs_describe_every_parameter_of_both_nodes():
    from ssm_localization.ros.parameters import indexer_parameters, localizer_parameters
    text = DOCS.read_text()
    for table in (localizer_parameters(), indexer_parameters()):
        for name, (_, desc) in table.items():
            assert desc, f'{name} has no description'
            assert f'| `{name}` |' in text, name


def test_a_config_field_without_help_has_no_description(monkeypatch):
    """The parameter tables take descriptions from ``param(..., help)`` only: no generic text."""
    import dataclasses

    from ssm_localization.config import LocalizerConfig
    from ssm_localization.ros import parameters
    plain = dataclasses.make_dataclass('Plain', [('top_n', int, dataclasses.field(default=3))],
                                       frozen=True)
    table = parameters.config_parameter_table('localizer', plain())
    assert table == {'localizer.top_n': (3, '')}
    described = parameters.config_parameter_table('localizer', LocalizerConfig())
    assert all(desc for _, desc in described.values())


@pytest.mark.parametrize('node_name', ['global_localizer', 'map_indexer'])
def test_params_file_lists_every_declared_parameter_at_its_default(ros_domain, node_name):
    from ssm_localization.ros.global_localizer import GlobalLocalizerNode
    from ssm_localization.ros.map_indexer import MapIndexerNode
    cls = {'global_localizer': GlobalLocalizerNode, 'map_indexer': MapIndexerNode}[node_name]
    in_file = _flat(yaml.safe_load(PARAMS.read_text())[node_name]['ros__parameters'])
    ctx, node = _make(cls)           # no params file: the declared defaults
    try:
        declared = {n: node.get_parameter(n).value for n in node._parameters if n not in AUTO}
        for name in declared:
            assert node.describe_parameter(name).description, f'{name} has no description'
    finally:
        _close(ctx, node)
    assert set(in_file) == set(declared)
    for name, value in declared.items():
        expect = list(value) if isinstance(value, (list, tuple)) else value
        assert in_file[name] == pytest.approx(expect) if isinstance(expect, float) \
            else in_file[name] == expect, name


def test_params_file_overrides_reach_the_core_configs(ros_domain, tmp_path):
    from ssm_localization.ros.global_localizer import GlobalLocalizerNode
    doc = yaml.safe_load(PARAMS.read_text())
    p = doc['global_localizer']['ros__parameters']
    p.update(mode='continuous', laser_x=0.25, laser_yaw=3.14159, scan_timeout=2.5)
    p['localizer']['top_n'] = 3
    p['localizer']['sigma_d'] = 0.08
    p['index']['beams'] = 180
    p['index']['matcher']['ransac_iterations'] = 99
    path = tmp_path / 'params.yaml'
    path.write_text(yaml.safe_dump(doc))
    ctx, node = _make(GlobalLocalizerNode, ['--ros-args', '--params-file', str(path),
                                            '-p', 'rate:=4.0', '-p', 'autostart:=false'])
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS   # reads them
        assert node.mode == 'continuous' and node.rate == 4.0
        assert node.get_parameter('scan_timeout').value == 2.5
        assert node.localizer_config.top_n == 3 and node.localizer_config.sigma_d == 0.08
        assert node.index_config.beams == 180
        assert node.index_config.matcher.ransac_iterations == 99
        assert node.localizer_config.laser_pose == (0.25, 0.0, 3.14159)
        assert node.index_config.sensor_pose == (0.25, 0.0, 3.14159)
    finally:
        _close(ctx, node)


def test_ros_node_and_cli_read_the_same_file_alike(ros_domain):
    """``--params-file`` for the node and ``params.load_configs`` for the CLI agree."""
    from ssm_localization.config.params import load_configs
    from ssm_localization.ros.global_localizer import GlobalLocalizerNode
    index_cfg, loc_cfg = load_configs(PARAMS, 'global_localizer')
    ctx, node = _make(GlobalLocalizerNode, ['--ros-args', '--params-file', str(PARAMS),
                                            '-p', 'autostart:=false'])
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.index_config == index_cfg and node.localizer_config == loc_cfg
    finally:
        _close(ctx, node)


def test_bad_parameter_value_is_refused(ros_domain):
    from ssm_localization.ros.global_localizer import GlobalLocalizerNode
    with pytest.raises(ParameterException, match='mode must be one of on_demand, continuous'):
        _make(GlobalLocalizerNode, ['--ros-args', '-p', 'mode:=sideways'])


def test_topic_and_frame_names_are_checked_when_set(ros_domain):
    """A topic ROS would refuse, or a frame with white space: refused at once, with the reason."""
    from rclpy.parameter import Parameter
    from ssm_localization.ros.global_localizer import GlobalLocalizerNode
    with pytest.raises(ParameterException, match='scan_topic: Invalid topic name'):
        _make(GlobalLocalizerNode, ['--ros-args', '-p', 'scan_topic:=bad topic'])
    ctx, node = _make(GlobalLocalizerNode, ['--ros-args', '-p', 'autostart:=false'])
    try:
        for name, value, why in (('map_topic', '1map', 'must not start with a number'),
                                 ('handover_confirm_topic', 'a b', 'Invalid topic name'),
                                 ('base_frame', 'bad frame', 'must not contain white space')):
            result = node.set_parameters([Parameter(name, value=value)])[0]
            assert not result.successful and why in result.reason, (name, result.reason)
        for name, value in (('scan_topic', '~/scan'), ('handover_confirm_topic', ''),
                            ('map_frame', '/map')):
            assert node.set_parameters([Parameter(name, value=value)])[0].successful, name
    finally:
        _close(ctx, node)


def test_a_list_from_the_set_parameters_service_is_checked_for_nan():
    """Over the service a double array arrives as an array.array, not a list: still checked."""
    import array
    from ssm_localization.ros.parameter_guard import value_problem
    assert 'must be finite' in value_problem('index.matcher.weights',
                                             array.array('d', [float('nan'), 1.0, 1.0]))
    assert value_problem('index.matcher.weights', array.array('d', [1.0, 1.0, 1.0])) is None


def test_a_failed_configure_leaves_nothing_behind(ros_domain, monkeypatch):
    """Whatever configure created before it failed is destroyed: publishers, threads, ..."""
    import threading
    from ssm_localization.ros.global_localizer import GlobalLocalizerNode
    ctx, node = _make(GlobalLocalizerNode, ['--ros-args', '-p', 'autostart:=false',
                                            '-p', 'map_frame:=/map'])
    try:
        def counts():
            return (len(list(node.publishers)), len(list(node.subscriptions)),
                    len(list(node.timers)), threading.active_count())
        before = counts()
        real = node.create_subscription

        def failing(msg_type, topic, *args, **kwargs):
            if topic == 'scan':
                raise RuntimeError('no subscription today')
            return real(msg_type, topic, *args, **kwargs)

        monkeypatch.setattr(node, 'create_subscription', failing)
        for _ in range(3):
            assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
            assert counts() == before
        monkeypatch.setattr(node, 'create_subscription', real)
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node._frame(None) == 'map'              # a leading slash is dropped
        assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
        assert counts() == before
    finally:
        _close(ctx, node)
