"""
config/: dataclasses from YAML.

Flat files, ROS params files, dotted keys; strict keys; the ``param`` help of every field.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from helpers import REPO
import pytest
from ssm_localization.config import (flatten, from_dict, IndexConfig, LEARNED_WEIGHTS,
                                     load_all_configs, load_configs, LocalizerConfig,
                                     MapBuildConfig, MatcherConfig, SimulationConfig,
                                     TopologyConfig, unflatten)
from ssm_localization.config.fields import help_of
import yaml


def _write(tmp_path: Path, text: str, name: str = 'params.yaml') -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- from_dict

def test_from_dict_defaults_and_values():
    assert from_dict(LocalizerConfig, None) == LocalizerConfig()
    assert from_dict(LocalizerConfig, {}) == LocalizerConfig()
    cfg = from_dict(LocalizerConfig, {'top_n': 7, 'sigma_d': 0.08, 'paper_mode': True})
    assert (cfg.top_n, cfg.sigma_d, cfg.paper_mode) == (7, 0.08, True)


def test_from_dict_rejects_unknown_keys_by_name():
    with pytest.raises(ValueError, match='sigma_dd'):
        from_dict(LocalizerConfig, {'sigma_dd': 0.1})
    with pytest.raises(ValueError, match=r"topology\.'bogus_key'|topology\.bogus_key"):
        from_dict(IndexConfig, {'topology': {'bogus_key': 1}})
    with pytest.raises(ValueError, match='nope'):
        from_dict(IndexConfig, {'matcher': {'nope': 1}})


def test_from_dict_coerces_simple_types():
    cfg = from_dict(LocalizerConfig, {'top_n': 3.0, 'vote_peaks': '12', 'sigma_d': 1,
                                      'beam_tolerance': '0.2', 'laser_pose': [1, '2', 0.5]})
    assert cfg.top_n == 3 and type(cfg.top_n) is int
    assert cfg.vote_peaks == 12 and type(cfg.vote_peaks) is int
    assert cfg.sigma_d == 1.0 and type(cfg.sigma_d) is float
    assert cfg.beam_tolerance == 0.2
    assert cfg.laser_pose == (1.0, 2.0, 0.5) and isinstance(cfg.laser_pose, tuple)
    assert all(type(v) is float for v in cfg.laser_pose)
    idx = from_dict(IndexConfig, {'beams': 180.0, 'sensor_pose': [0, 0, 1],
                                  'matcher': {'weights': [1, 2, 3]}})
    assert idx.beams == 180 and type(idx.beams) is int
    assert idx.sensor_pose == (0.0, 0.0, 1.0)
    assert tuple(idx.matcher.weights) == (1.0, 2.0, 3.0)


@pytest.mark.parametrize('key, value', [
    ('top_n', 2.5), ('top_n', True), ('top_n', 'three'), ('top_n', None), ('sigma_d', 'x'),
    ('sigma_d', False), ('paper_mode', 'yes'), ('paper_mode', 1), ('laser_pose', [1, 2]),
    ('laser_pose', 3.0), ('laser_pose', ['a', 0, 0]),
])
def test_from_dict_rejects_bad_values_by_name(key, value):
    with pytest.raises(ValueError, match=key):
        from_dict(LocalizerConfig, {key: value})


def test_from_dict_nested_section_must_be_a_mapping():
    with pytest.raises(ValueError, match='topology'):
        from_dict(IndexConfig, {'topology': 5})


def test_from_dict_runs_dataclass_validation():
    with pytest.raises(ValueError, match='top_n'):
        from_dict(LocalizerConfig, {'top_n': 0})


@pytest.mark.parametrize('name', ['vote_workers', 'search_workers'])
@pytest.mark.parametrize('workers', [0, -2])
def test_workers_are_every_core_or_a_positive_count(name, workers):
    with pytest.raises(ValueError, match=name):
        from_dict(LocalizerConfig, {name: workers})
    assert getattr(from_dict(LocalizerConfig, {name: -1}), name) == -1


def test_flatten_unflatten_round_trip():
    idx = IndexConfig(beams=90, sensor_pose=(0.1, 0.2, 0.3),
                      matcher=dataclasses.replace(MatcherConfig(), max_points=77))
    flat = flatten(idx)
    assert flat['matcher.max_points'] == 77 and flat['sensor_pose'] == [0.1, 0.2, 0.3]
    assert from_dict(IndexConfig, unflatten(flat)) == idx
    loc = LocalizerConfig(top_n=3, laser_pose=(1.0, 0.0, math.pi))
    assert from_dict(LocalizerConfig, unflatten(flatten(loc))) == loc
    assert unflatten({'a.b.c': 1, 'a.d': 2, 'e': 3}) == {'a': {'b': {'c': 1}, 'd': 2}, 'e': 3}
    # dotted and nested keys of one group merge, in either order
    both = {'index.beams': 180, 'index': {'max_range': 9.0}}
    assert unflatten(both) == unflatten(dict(reversed(both.items()))) == \
        {'index': {'beams': 180, 'max_range': 9.0}}


@pytest.mark.parametrize('flat, why', [
    ({'index.beams': 180, 'index': {'beams': 360}}, "'index.beams' is given twice"),
    ({'index': {'beams': 360}, 'index.beams': 180}, "'index.beams' is given twice"),
    ({'index': {'matcher': {'gap': 1}}, 'index.matcher': 5}, 'is also a group'),
    ({'index.matcher.gap': 1, 'index': {'matcher': 5}}, 'is also a group'),
])
def test_a_parameter_given_twice_is_refused_whatever_the_order(flat, why):
    with pytest.raises(ValueError, match=why):
        unflatten(flat)


# --------------------------------------------------------------------------- load_configs

def test_load_configs_without_file_gives_defaults():
    index_cfg, loc_cfg = load_configs(None)
    assert index_cfg == IndexConfig() and loc_cfg == LocalizerConfig()


def test_load_configs_flat_file(tmp_path):
    p = _write(tmp_path, 'localizer:\n  top_n: 3\n  sigma_d: 0.07\n'
                         'index:\n  beams: 180\n  topology: {arc_spacing: 3.0}\n'
                         '  matcher: {max_points: 90}\n')
    index_cfg, loc_cfg = load_configs(p)
    assert (loc_cfg.top_n, loc_cfg.sigma_d) == (3, 0.07)
    assert index_cfg.beams == 180 and index_cfg.topology.arc_spacing == 3.0
    assert index_cfg.matcher.max_points == 90
    assert loc_cfg.vote_peaks == LocalizerConfig().vote_peaks      # untouched fields keep defaults


def test_load_configs_ros_params_file(tmp_path):
    p = _write(tmp_path, yaml.safe_dump({
        'map_indexer': {'ros__parameters': {'index': {'beams': 90}}},
        'global_localizer': {'ros__parameters': {
            'mode': 'continuous',                     # node parameters are not config fields
            'localizer': {'top_n': 4, 'surface_depth': 0.0},
            'index': {'beams': 240, 'max_range': 15.0}}}}))
    index_cfg, loc_cfg = load_configs(p)
    assert loc_cfg.top_n == 4 and loc_cfg.surface_depth == 0.0
    assert index_cfg.beams == 240 and index_cfg.max_range == 15.0
    index_cfg, _ = load_configs(p, node='map_indexer')
    assert index_cfg.beams == 90


def test_load_configs_dotted_keys_and_laser_pose(tmp_path):
    p = _write(tmp_path, 'global_localizer:\n  ros__parameters:\n'
                         '    localizer.top_n: 2\n'
                         '    index.beams: 120\n    index.topology.merge_radius: 0.7\n'
                         '    laser_x: 0.2\n    laser_yaw: 3.1\n')
    index_cfg, loc_cfg = load_configs(p)
    assert loc_cfg.top_n == 2
    assert index_cfg.beams == 120 and index_cfg.topology.merge_radius == 0.7
    # one laser pose: laser_x/y/yaw feed both configs
    assert loc_cfg.laser_pose == (0.2, 0.0, 3.1)
    assert index_cfg.sensor_pose == (0.2, 0.0, 3.1)


@pytest.mark.parametrize('key', ['localizer.laser_pose', 'index.sensor_pose'])
def test_the_laser_pose_is_set_once_with_the_laser_parameters(tmp_path, key):
    p = _write(tmp_path, f'global_localizer:\n  ros__parameters:\n    {key}: [9.0, 9.0, 9.0]\n')
    with pytest.raises(ValueError, match=f'{key}: the laser pose on the robot base is set '
                                         'once, with laser_x, laser_y and laser_yaw'):
        load_configs(p)


def test_configs_from_params_is_the_path_of_files_and_nodes(tmp_path):
    """A params file and the same values as ROS parameters (dotted) give the same configs."""
    from ssm_localization.config.params import configs_from_params
    values = {'index.beams': 90, 'localizer.top_n': 3, 'tracker.max_misses': 4,
              'laser_x': 0.1, 'mode': 'continuous'}
    p = _write(tmp_path, yaml.safe_dump({'global_localizer': {'ros__parameters': values}}))
    assert configs_from_params(values) == load_all_configs(p)
    assert load_all_configs(p).index.sensor_pose == (0.1, 0.0, 0.0)


def test_load_all_configs_reads_the_file_once(tmp_path, monkeypatch):
    from ssm_localization.config import params
    p = _write(tmp_path, 'localizer: {top_n: 3}\ntracker: {max_misses: 4}\nlaser_x: 0.1\n')
    reads = []
    load = params.load_yaml_file
    monkeypatch.setattr(params, 'load_yaml_file', lambda *a: reads.append(a) or load(*a))
    configs = load_all_configs(p)
    assert len(reads) == 1
    assert configs.localizer.top_n == 3 and configs.tracker.max_misses == 4
    assert configs.index.sensor_pose == configs.localizer.laser_pose == (0.1, 0.0, 0.0)
    assert tuple(load_configs(p)) == configs[:2]
    with pytest.raises(ValueError, match="params.yaml: unknown parameter tracker.'no_such'"):
        load_all_configs(_write(tmp_path, 'tracker: {no_such: 1}\n'))


def test_load_configs_wildcard_node_section(tmp_path):
    p = _write(tmp_path, "'/**':\n  ros__parameters:\n    localizer: {top_n: 6}\n")
    assert load_configs(p)[1].top_n == 6


def test_load_configs_unknown_key_names_file_and_key(tmp_path):
    p = _write(tmp_path, 'global_localizer:\n  ros__parameters:\n'
                         '    localizer: {top_n: 3, sigma_dee: 0.1}\n')
    with pytest.raises(ValueError) as info:
        load_configs(p)
    assert 'sigma_dee' in str(info.value) and str(p) in str(info.value)
    p = _write(tmp_path, 'index.topology.arc_spacingg: 1.0\n', 'dotted.yaml')
    with pytest.raises(ValueError, match='arc_spacingg'):
        load_configs(p)


def test_load_configs_bad_files(tmp_path):
    with pytest.raises(FileNotFoundError, match='missing.yaml'):
        load_configs(tmp_path / 'missing.yaml')
    with pytest.raises(ValueError, match='malformed'):
        load_configs(_write(tmp_path, 'localizer: {top_n: [1, 2\n', 'broken.yaml'))
    with pytest.raises(ValueError, match='mapping'):
        load_configs(_write(tmp_path, '- 1\n- 2\n', 'list.yaml'))
    with pytest.raises(ValueError, match='top_n'):
        load_configs(_write(tmp_path, 'localizer: {top_n: many}\n', 'value.yaml'))
    index_cfg, loc_cfg = load_configs(_write(tmp_path, '', 'empty.yaml'))
    assert loc_cfg == LocalizerConfig()


def test_repository_params_file_loads():
    path = REPO / 'config' / 'ssm_localization.yaml'
    index_cfg, loc_cfg = load_configs(path)
    section = yaml.safe_load(path.read_text())['global_localizer']['ros__parameters']
    for key, value in section['localizer'].items():
        assert getattr(loc_cfg, key) == pytest.approx(value), key
    assert index_cfg.beams == section['index']['beams']
    assert index_cfg.max_range == section['index']['max_range']
    for key, value in section['index']['topology'].items():
        assert getattr(index_cfg.topology, key) == pytest.approx(value), key
    for key, value in section['index']['matcher'].items():
        got = getattr(index_cfg.matcher, key)
        assert (list(got) if isinstance(got, tuple) else got) == pytest.approx(value) \
            if not isinstance(value, str) else got == value, key
    assert loc_cfg.laser_pose == (section['laser_x'], section['laser_y'], section['laser_yaw'])


@pytest.mark.parametrize('cls', [IndexConfig, TopologyConfig, MatcherConfig, LocalizerConfig,
                                 MapBuildConfig, SimulationConfig])
def test_every_config_field_has_help(cls):
    """``param(default, help)``: the one source of the ROS parameter descriptions and the docs."""
    missing = [f.name for f in dataclasses.fields(cls) if not f.metadata.get('help')]
    assert not missing, f'{cls.__name__} fields without help metadata: {missing}'


def test_help_metadata_keeps_the_defaults():
    assert help_of(MatcherConfig)['weights'].startswith('logistic weights')
    assert MatcherConfig().weights == LEARNED_WEIGHTS and IndexConfig().beams == 360
    assert IndexConfig().topology == TopologyConfig() and IndexConfig().matcher == MatcherConfig()
