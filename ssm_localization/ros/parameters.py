"""
The nodes' ROS parameters.

Tables of ``{name: (default, description)}`` (:mod:`ssm_localization.ros.parameter_guard`
declares them), the config dataclasses built from them and the generated params file.

Config fields become dotted parameter names (``index.*``, ``localizer.*``: the same nesting as
:mod:`ssm_localization.config.params`), next to the nodes' own parameters.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
import sys
from typing import Any

from ssm_localization.config import IndexConfig, LocalizerConfig, TrackerConfig
from ssm_localization.config import params as ssm_params
from ssm_localization.mapping.map_limits import MAX_MAP_CELLS
import yaml


def _ros_value(value: Any) -> Any | None:
    """Return a config default as a ROS parameter value, or None when ROS cannot type it."""
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
        if name in ssm_params.LASER_POSE_FIELDS:      # laser_x / laser_y / laser_yaw instead
            continue
        v = _ros_value(value)
        if v is not None:
            out[name] = v
    return out


def _described(prefix: str, config: Any) -> dict[str, str]:
    """``{dotted name: description}`` for every leaf field of a config tree (``param`` help)."""
    out: dict[str, str] = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        name = f'{prefix}.{f.name}'
        if dataclasses.is_dataclass(value):
            out.update(_described(name, value))
        else:
            out[name] = f.metadata.get('help', '')
    return out


def config_parameter_table(prefix: str, config: Any) -> dict[str, tuple[Any, str]]:
    """``{dotted name: (default, description)}`` of a config dataclass (ROS-typable fields)."""
    notes = _described(prefix, config)
    return {name: (default, notes[name])
            for name, default in config_parameters(prefix, config).items()}


def node_configs(values: dict[str, Any]) -> ssm_params.Configs:
    """
    Return the configs of a node's parameter values (``{name: value}``, dotted names).

    :func:`ssm_localization.config.params.configs_from_params`, the one path from parameters
    to configs (params files take it too); ``ValueError`` for values the core refuses.
    """
    return ssm_params.configs_from_params(
        {k: v for k, v in values.items()
         if k.split('.')[0] in ssm_params.KNOWN_TOP_LEVEL})


def laser_pose_of(values: dict[str, Any]) -> tuple[float, float, float]:
    """Return the ``laser_x/laser_y/laser_yaw`` parameters as a pose."""
    return (float(values['laser_x']), float(values['laser_y']), float(values['laser_yaw']))


#: the parameter group of each config class (a refusal names the group)
CONFIG_GROUPS = {'IndexConfig': 'index', 'TopologyConfig': 'index.topology',
                 'MatcherConfig': 'index.matcher', 'LocalizerConfig': 'localizer',
                 'TrackerConfig': 'tracker'}


def config_problem(values: dict[str, Any]) -> str | None:
    """Why the core refuses the configs of these parameter values, or None."""
    try:
        node_configs(values)
    except (ValueError, TypeError) as exc:
        text = str(exc)
        group = next((g for cls, g in CONFIG_GROUPS.items() if text.startswith(cls)), None)
        return f'invalid {group}.* parameters: {text}' if group else f'invalid parameters: {text}'
    return None


LASER_PARAMS: dict[str, tuple[Any, str]] = {
    'laser_x': (0.0, 'laser x on the robot base frame, metres (global_localizer: used when TF '
                     'has no base_frame <- scan frame transform)'),
    'laser_y': (0.0, 'laser y on the robot base frame, metres (as laser_x)'),
    'laser_yaw': (0.0, 'laser yaw on the robot base frame, radians (as laser_x)'),
}
AUTOSTART: dict[str, tuple[Any, str]] = {
    'autostart': (True, 'configure and activate on start (ros2 run); false under a lifecycle '
                        'manager (nav2 lifecycle_manager with bond_timeout 0.0; the launch '
                        'files set it) or for ros2 lifecycle set'),
}
MAP_PARAMS: dict[str, tuple[Any, str]] = {
    'max_map_cells': (MAX_MAP_CELLS, 'ignore larger maps (cells); 0 = no limit'),
    'max_gvd_points': (20000, 'GVD cells drawn in topological_map (subsampled)'),
}


def indexer_parameters() -> dict[str, tuple[Any, str]]:
    """Every map_indexer parameter: ``{name: (default, description)}``."""
    return {**AUTOSTART,
            'index_file': ('', 'write the index here (npz) after each build; empty = do not '
                               'write'),
            **LASER_PARAMS, **MAP_PARAMS, **config_parameter_table('index', IndexConfig())}


#: global_localizer parameters that may change in any lifecycle state (the others are read at
#: configure and may change only while the node is unconfigured)
DYNAMIC = ('scan_timeout', 'publish_initialpose', 'publish_markers', 'localize_on_start',
           'publish_tf')

NODE_PARAMS: dict[str, tuple[Any, str]] = {
    **AUTOSTART,
    'mode': ('on_demand', 'on_demand: localize on the relocalize service only; continuous: '
                          'every scan (or at most rate Hz) on its own; track: track every scan '
                          'with odometry (odom topic, or TF odom_frame <- base_frame), '
                          'relocalize globally when lost'),
    'base_frame': ('base_link', 'robot base frame: global_pose is the pose of this frame '
                                '(AMCL: base_frame_id)'),
    'map_frame': ('', "frame_id of global_pose; empty = the map's frame_id (AMCL: "
                      'global_frame_id)'),
    'odom_frame': ('odom', 'track mode: the odometry frame (TF odom_frame <- base_frame when the '
                           'odom topic is silent; the child of the map -> odom transform; AMCL: '
                           'odom_frame_id)'),
    'scan_topic': ('scan', 'LaserScan topic (AMCL: scan_topic)'),
    'map_topic': ('map', 'OccupancyGrid topic (AMCL: map_topic)'),
    'index_file': ('', 'load this index (npz) instead of indexing the map topic; if the file is '
                       'missing, index the map and save it there'),
    'localize_on_start': (False, 'once active, localize the incoming scans until the first ok '
                                 'pose, publish it (and hand it over on initialpose when '
                                 'publish_initialpose), then on demand'),
    'publish_initialpose': (False, 'hand each pose over on initialpose (AMCL / nav2 take over '
                                   'from there), republished until handover_confirm_topic '
                                   'confirms it'),
    'serve_reinitialize_global_localization': (
        False, "serve nav2's reinitialize_global_localization (std_srvs/Empty, the "
               "ReinitializeGlobalLocalization behavior-tree node) in place of AMCL's: answered "
               'at once when a search starts, not answered when none can (no scan, no map, not '
               'active). Read at start-up and at configure'),
    'scan_timeout': (5.0, 'relocalize fails when no scan arrives within this many seconds; '
                          'reinitialize_global_localization needs a scan this recent'),
    'publish_tf': (True, 'track mode: broadcast map -> odom (where tf2_ros exists), as AMCL '
                         'does (AMCL: tf_broadcast)'),
    'publish_markers': (True, 'publish topological_map (nodes, GVD, candidates, matched scan)'),
    'rate': (0.0, 'continuous mode: at most this many localizations per second; 0 = every scan '
                  '(the newest; scans arriving while busy are dropped)'),
    'handover_confirm_topic': ('amcl_pose', 'hand-over: the pose topic that confirms a pose '
                                            'handed over on initialpose (AMCL: amcl_pose); '
                                            'empty = publish once, unconfirmed'),
    'handover_period': (1.0, 'hand-over: seconds between publications of an unconfirmed pose'),
    'handover_tries': (30, 'hand-over: publications of a pose before giving up with an error'),
    'handover_tolerance': (0.5, 'hand-over: a confirming pose lies within this many metres '
                                'and radians of the handed one'),
    'odom_max_age': (0.5, "track mode: odometry further than this from a scan's stamp (s) is "
                          'not used; the scan is tracked without odometry'),
    'transform_tolerance': (1.0, 'track mode: map -> odom is stamped this many seconds after '
                                 'its scan (AMCL transform_tolerance)'),
}

#: what a user (a nav2 user) sets; every other parameter is an expert one (tuned defaults)
USER_PARAMETERS = ('autostart', 'mode', 'base_frame', 'map_frame', 'odom_frame', 'scan_topic',
                   'map_topic', 'index_file', 'laser_x', 'laser_y', 'laser_yaw',
                   'localize_on_start', 'publish_initialpose',
                   'serve_reinitialize_global_localization', 'scan_timeout', 'publish_tf',
                   'publish_markers')


def is_user_parameter(name: str) -> bool:
    """Tell whether ``name`` is a user parameter (else an expert one)."""
    return name in USER_PARAMETERS


def localizer_parameters() -> dict[str, tuple[Any, str]]:
    """Every global_localizer parameter: ``{name: (default, description)}``."""
    index_params = {k: v for k, v in indexer_parameters().items() if k.startswith('index.')}
    return {**NODE_PARAMS, **LASER_PARAMS, **MAP_PARAMS, **index_params,
            **config_parameter_table('localizer', LocalizerConfig()),
            **config_parameter_table('tracker', TrackerConfig())}


PARAMS_FILE_HEADER = """\
# ssm_localization ROS 2 parameters, every one at its default. Generated by `make params-yaml`
# (ssm_localization/ros/parameters.py; test_ros_params checks it is current); what each one
# means: docs/PARAMETERS.md. Nested keys are dotted parameter names (index.matcher.max_points).
# Each node lists its user parameters first, then the expert ones (tuned defaults).
#   ros2 run ssm_localization global_localizer --ros-args \\
#       --params-file config/ssm_localization.yaml
"""
EXPERT_COMMENT = ('    # --- expert parameters: tuned defaults; change them only with '
                  'docs/PARAMETERS.md at hand\n')


def node_tables() -> dict[str, dict[str, tuple[Any, str]]]:
    """
    Return ``{node name: its parameter table}``.

    User parameters first (in :data:`USER_PARAMETERS` order), then the node's expert
    parameters, then the dotted (config) ones, sorted.
    """
    out = {}
    for node, table in (('global_localizer', localizer_parameters()),
                        ('map_indexer', indexer_parameters())):
        user = [n for n in USER_PARAMETERS if n in table]
        own = [n for n in table if '.' not in n and n not in user]
        names = user + own + sorted(n for n in table if '.' in n)
        out[node] = {name: table[name] for name in names}
    return out


def _nested(table: dict[str, tuple[Any, str]]) -> dict[str, Any]:
    """Return the default values of a table as nested mappings (dotted names split)."""
    section: dict[str, Any] = {}
    for name, (default, _) in table.items():
        *parents, leaf = name.split('.')
        cur = section
        for part in parents:
            cur = cur.setdefault(part, {})
        cur[leaf] = list(default) if isinstance(default, tuple) else default
    return section


def _indented(data: dict[str, Any], spaces: int) -> str:
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=False)
    return ''.join(' ' * spaces + line for line in text.splitlines(keepends=True))


def params_yaml() -> str:
    """
    config/ssm_localization.yaml.

    Both nodes' parameters at their defaults, user parameters first, then the expert ones under
    a comment (``yaml.safe_dump`` under a short header; the descriptions are in
    :func:`parameters_markdown`).
    """
    out = [PARAMS_FILE_HEADER]
    for node, table in node_tables().items():
        user = {n: v for n, v in table.items() if is_user_parameter(n)}
        expert = {n: v for n, v in table.items() if not is_user_parameter(n)}
        out += [f'{node}:\n', '  ros__parameters:\n', _indented(_nested(user), 4),
                EXPERT_COMMENT, _indented(_nested(expert), 4)]
    return ''.join(out)


def parameters_markdown() -> str:
    """docs/PARAMETERS.md: per node, a table of user parameters and one of expert ones."""
    lines = ['# ROS 2 parameters', '',
             'Generated by `make params-yaml` from the parameter tables in',
             '`ssm_localization/ros/parameters.py` and the `param(default, help)` metadata of the',
             'config dataclasses in `ssm_localization/config/` (test_ros_params checks it is',
             'current). `config/ssm_localization.yaml` lists the same parameters at their',
             'defaults. *User parameters* are what a user (a nav2 user) sets: frames, topics,',
             'the index file, the laser pose, the mode and the nav2 hand-over. *Expert',
             'parameters* are the research knobs of the method, tuned on the benchmarks:',
             'leave them at their defaults unless a measurement says otherwise. Dotted names',
             'are config fields: `index.*` is `IndexConfig`, `index.matcher.*` `MatcherConfig`,',
             '`index.topology.*` `TopologyConfig`, `localizer.*` `LocalizerConfig`, `tracker.*`',
             '`TrackerConfig` (mode `track`). The ones marked *dynamic* may change in any',
             'lifecycle state; the others are read at configure and may change only while the',
             'node is unconfigured (`ros2 lifecycle set NODE cleanup` first).']
    for node, table in node_tables().items():
        lines += ['', f'## {node}']
        for title, user in (('User parameters', True), ('Expert parameters', False)):
            lines += ['', f'### {title}', '', '| parameter | default | description |',
                      '|---|---|---|']
            for name, (default, desc) in table.items():
                if is_user_parameter(name) != user:
                    continue
                value = yaml.safe_dump(list(default) if isinstance(default, tuple) else default,
                                       default_flow_style=True).strip().removesuffix('...')
                text = desc.replace('|', '\\|')
                if node == 'global_localizer' and name in DYNAMIC:
                    text += ' *(dynamic)*'
                lines.append(f'| `{name}` | `{value.strip()}` | {text} |')
    return '\n'.join(lines) + '\n'


def write_params_files(yaml_path: str | Path, markdown_path: str | Path) -> None:
    """Write :func:`params_yaml` and :func:`parameters_markdown` (``make params-yaml``)."""
    Path(yaml_path).write_text(params_yaml())
    Path(markdown_path).write_text(parameters_markdown())


if __name__ == '__main__':
    if len(sys.argv) != 3:
        sys.exit('usage: python -m ssm_localization.ros.parameters PARAMS.yaml PARAMETERS.md')
    write_params_files(sys.argv[1], sys.argv[2])
