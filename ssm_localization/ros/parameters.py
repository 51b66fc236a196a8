"""The nodes' ROS parameters: tables of ``{name: (default, description)}``, declaring them, the
config dataclasses built from them and the generated params file.

Config fields become dotted parameter names (``index.*``, ``localizer.*``: the same nesting as
:mod:`ssm_localization.config.params`), next to the nodes' own parameters.
"""
from __future__ import annotations

import dataclasses
import inspect
import re
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

from ssm_localization.config import IndexConfig, LocalizerConfig
from ssm_localization.config import params as ssm_params

# Descriptions of config fields (dotted ROS names); others get a generic one.
DESCRIPTIONS: dict[str, str] = {
    'index.beams': 'beams of each virtual scan taken at a topological node (full turn)',
    'index.max_range': 'range of the virtual laser when casting the node scans, metres',
    'localizer.top_n': 'candidate nodes kept by the spectral coarse stage (paper: N = 5)',
    'localizer.sigma_d': 'eq. (10) vicinity score distance scale, metres',
    'localizer.prefilter': 'nodes kept by descriptor voting before spectral ranking; 0 = all',
    'localizer.paper_mode': 'plain paper pipeline: no prefilter, refinement or map check',
    'localizer.min_score': 'map-agreement score below which a hypothesis is rejected',
    'index.matcher.ransac_iterations': 'RANSAC iterations of the fine pose (paper II.C)',
    'index.matcher.ransac_threshold': 'RANSAC inlier distance, metres',
    'index.matcher.ransac_min_span': 'RANSAC: minimum spread of a 2-pair sample, metres',
    'index.matcher.min_inliers': 'fewer RANSAC inliers than this: no match',
    'index.matcher.seed': 'random seed of RANSAC (results are reproducible)',
    'index.matcher.icp': 'refine each match by point-to-line ICP (beyond the paper)',
    'index.matcher.weights': 'logistic weights of the pairwise affinity (eq. 4)',
    'index.matcher.desc_radius': 'radius of the local shape descriptors, metres',
}

GENERIC = 'see '   # prefix of the description of a config field documented nowhere else

# Config fields that the node maps from its own parameters instead (laser_x/laser_y/laser_yaw).
SENSOR_POSE_FIELDS = ('laser_pose', 'sensor_pose')


def _ros_value(value: Any) -> Any | None:
    """A config default as a ROS parameter value, or None when ROS cannot type it."""
    if isinstance(value, bool) or isinstance(value, str):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, (list, tuple)) and value:
        if all(isinstance(v, bool) for v in value):
            return [bool(v) for v in value]
        if all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            return [int(v) for v in value]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            return [float(v) for v in value]
        if all(isinstance(v, str) for v in value):
            return list(value)
    return None


def config_parameters(prefix: str, config: Any) -> dict[str, Any]:
    """``{'prefix.dotted.field': default}`` for every ROS-typable field of a config dataclass."""
    out = {}
    for name, value in ssm_params.flatten(config, prefix + '.').items():
        if name.rsplit('.', 1)[-1] in SENSOR_POSE_FIELDS:
            continue
        v = _ros_value(value)
        if v is not None:
            out[name] = v
    return out


def field_descriptions(cls: type) -> dict[str, str]:
    """Field descriptions of a config dataclass, from its source: a trailing ``# comment`` on the
    field line, or a ````name````: text`` entry in the class docstring."""
    out: dict[str, str] = {}
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return out
    doc = ' '.join((cls.__doc__ or '').split())
    for names, text in re.findall(r'((?:``\w+``(?:,\s*|\s+and\s+)?)+):\s*([^`]+)', doc):
        for name in re.findall(r'``(\w+)``', names):
            out[name] = text.strip().rstrip(';,')
    for name, text in re.findall(r'^\s+(\w+)\s*:[^#\n]*=[^#\n]*#\s*(.+)$', source, re.M):
        out[name] = text.strip()
    return out


def _described(prefix: str, config: Any) -> dict[str, str]:
    """``{dotted name: description}`` for every leaf field of a config tree."""
    out: dict[str, str] = {}
    notes = field_descriptions(type(config))
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        name = f'{prefix}.{f.name}'
        if dataclasses.is_dataclass(value):
            out.update(_described(name, value))
        else:
            out[name] = notes.get(f.name, '')
    return out


def config_parameter_table(prefix: str, config: Any) -> dict[str, tuple[Any, str]]:
    """``{dotted name: (default, description)}`` of a config dataclass (ROS-typable fields)."""
    notes = _described(prefix, config)
    return {name: (default, DESCRIPTIONS.get(name) or notes.get(name) or
                   f'{GENERIC}{type(config).__name__}.{name.split(".", 1)[1]}')
            for name, default in config_parameters(prefix, config).items()}


def declare(node: Node, name: str, default: Any, description: str, read_only: bool = True) -> Any:
    """Declare one parameter with a description; return its value."""
    node.declare_parameter(name, default, ParameterDescriptor(description=description,
                                                              read_only=read_only))
    return node.get_parameter(name).value


def declare_table(node: Node, table: dict[str, tuple[Any, str]],
                  dynamic: tuple[str, ...] = ()) -> dict[str, Any]:
    """Declare every ``name: (default, description)``; read-only unless listed in ``dynamic``."""
    return {name: declare(node, name, default, desc, name not in dynamic)
            for name, (default, desc) in table.items()}


def _with_sensor_pose(config: Any, pose: tuple[float, float, float]) -> Any:
    """Set the laser/sensor pose field(s) of a config tree to ``pose``."""
    changes = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if f.name in SENSOR_POSE_FIELDS:
            changes[f.name] = tuple(float(v) for v in pose)
        elif dataclasses.is_dataclass(value):
            changes[f.name] = _with_sensor_pose(value, pose)
    return dataclasses.replace(config, **changes) if changes else config


def build_config(cls: type, prefix: str, values: dict[str, Any],
                 laser_pose: tuple[float, float, float]) -> Any:
    """Config dataclass ``cls`` from ``{prefix.dotted.name: value}`` plus the laser pose."""
    section = ssm_params.unflatten({k: v for k, v in values.items()
                                    if k.startswith(prefix + '.')}).get(prefix, {})
    return _with_sensor_pose(ssm_params.from_dict(cls, section, prefix + '.'), laser_pose)


def laser_pose_of(values: dict[str, Any]) -> tuple[float, float, float]:
    return (float(values['laser_x']), float(values['laser_y']), float(values['laser_yaw']))


LASER_PARAMS: dict[str, tuple[Any, str]] = {
    'laser_x': (0.0, 'laser x on the robot base frame, metres'),
    'laser_y': (0.0, 'laser y on the robot base frame, metres'),
    'laser_yaw': (0.0, 'laser yaw on the robot base frame, radians (tf2 is not used)'),
}
MAP_PARAMS: dict[str, tuple[Any, str]] = {
    'max_map_cells': (25_000_000, 'ignore larger maps (cells); 0 = no limit'),
    'max_gvd_points': (20000, 'GVD cells drawn in topological_map (subsampled)'),
}


def indexer_parameters() -> dict[str, tuple[Any, str]]:
    """Every map_indexer parameter: ``{name: (default, description)}``."""
    return {'index_file': ('', 'write the index here (npz) after each build; empty = do not '
                               'write'),
            **LASER_PARAMS, **MAP_PARAMS, **config_parameter_table('index', IndexConfig())}


NODE_PARAMS: dict[str, tuple[Any, str]] = {
    'mode': ('on_demand', 'on_demand: localize on the relocalize service only; continuous: '
                          'every scan (or at most rate Hz)'),
    'base_frame': ('base_link', 'robot base frame: global_pose is the pose of this frame'),
    'map_frame': ('', "frame_id of global_pose; empty = the map's frame_id"),
    'index_file': ('', 'load this index (npz) instead of indexing the map topic; if the file is '
                       'missing, index the map and save it there'),
    'scan_timeout': (5.0, 'relocalize fails when no scan arrives within this many seconds'),
    'rate': (0.0, 'continuous mode: at most this many localizations per second; 0 = every scan '
                  '(the newest; scans arriving while busy are dropped)'),
    'publish_initialpose': (False, 'also publish each pose on initialpose (AMCL / nav2 take '
                                   'over from there)'),
    'publish_markers': (True, 'publish topological_map (nodes, GVD, candidates, matched scan)'),
}


def localizer_parameters() -> dict[str, tuple[Any, str]]:
    """Every global_localizer parameter: ``{name: (default, description)}``."""
    index_params = {k: v for k, v in indexer_parameters().items() if k.startswith('index.')}
    return {**NODE_PARAMS, **LASER_PARAMS, **MAP_PARAMS, **index_params,
            **config_parameter_table('localizer', LocalizerConfig())}


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return value if value and value.replace('_', '').isalnum() else repr(value)
    if isinstance(value, (list, tuple)):
        return '[' + ', '.join(_yaml_value(v) for v in value) + ']'
    text = repr(value)
    if isinstance(value, float) and 'e' in text and '.' not in text:
        text = text.replace('e', '.0e')      # 1e-05 is a string to YAML 1.1; 1.0e-05 a float
    return text


def params_yaml() -> str:
    """config/ssm_localization.yaml: both nodes' parameters at their defaults.

    Regenerate after changing a default: ``make params-yaml``.
    """
    lines = ['# ssm_localization ROS 2 parameters, every one at its default (generated by',
             '# ssm_localization.ros.parameters.params_yaml; test_ros_params checks it).',
             '#   ros2 run ssm_localization global_localizer --ros-args --params-file '
             'config/ssm_localization.yaml',
             '# Nested keys are dotted parameter names (index.matcher.max_points). Floats need a',
             '# decimal point: ROS parameters are strictly typed.']
    for node, table in (('global_localizer', localizer_parameters()),
                        ('map_indexer', indexer_parameters())):
        lines += [f'{node}:', '  ros__parameters:']
        prev: list[str] = []
        for name in [n for n in table if '.' not in n] + sorted(n for n in table if '.' in n):
            default, desc = table[name]
            parts = name.split('.')
            common = 0
            while common < min(len(prev), len(parts) - 1) and prev[common] == parts[common]:
                common += 1
            for depth in range(common, len(parts) - 1):
                lines.append('    ' + '  ' * depth + parts[depth] + ':')
            if not desc.startswith(GENERIC):
                lines.append('    ' + '  ' * (len(parts) - 1) + f'# {desc}')
            lines.append('    ' + '  ' * (len(parts) - 1) + f'{parts[-1]}: {_yaml_value(default)}')
            prev = parts[:-1]
    return '\n'.join(lines) + '\n'
