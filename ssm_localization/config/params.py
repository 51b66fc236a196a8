"""
Config dataclasses from YAML parameter files (a ``yaml.SafeLoader`` subclass only).

One file serves the CLI and the ROS nodes: either a plain mapping, or a ROS 2 params file whose
``<node>: ros__parameters:`` section is used. Nested mappings follow the dataclass nesting, e.g.::

    global_localizer:
      ros__parameters:
        localizer: {top_n: 5, sigma_d: 0.05}
        index: {beams: 360, topology: {arc_spacing: 2.5}, matcher: {max_points: 100}}

ROS flattens nested mappings to dotted names (``localizer.top_n``); :func:`unflatten` undoes it.
Unknown keys raise ``ValueError`` naming the key, so typos do not pass silently; so does a file
of the wrong shape (a list where a mapping belongs, a string for a number). Files are read with
``files.yaml_input.load_yaml_file``: size and alias limits, no Python objects.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import NamedTuple

# the conversions without YAML live in convert.py (index files use them); re-exported here
from .convert import (as_mapping as _mapping, config_from_json, config_to_json,  # noqa: F401
                      flatten, from_dict, unflatten)
from .localization import LocalizerConfig
from .mapping import IndexConfig, TopologyConfig
from .tracking import TrackerConfig
from ..files.reading import echo
from ..files.yaml_input import load_yaml_file


def load_yaml_mapping(path: str | Path) -> dict:
    """
    Return the top-level mapping of a params file (``{}`` for an empty file).

    ``ValueError`` naming the file for anything else, ``FileNotFoundError`` when it is missing.
    """
    data = load_yaml_file(path, 'params file')
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f'{path}: expected a mapping at the top level, got '
                         f'{type(data).__name__}')
    return data


def node_section(data: dict, node: str) -> dict:
    """
    Return the parameters for ``node`` from a ROS params file.

    A flat mapping (no ``ros__parameters`` section) is returned as it is.
    """
    for key in (node, '/' + node, '/**', '**'):
        section = data.get(key)
        if isinstance(section, dict) and 'ros__parameters' in section:
            return _mapping(section['ros__parameters'], f'{key}: ros__parameters')
    if any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values()):
        return {}
    return data


def laser_pose_of_section(section: dict) -> tuple[float, float, float] | None:
    """
    Return the nodes' ``laser_x/laser_y/laser_yaw`` parameters as a pose.

    Returns None when none of them is set.
    """
    names = ('laser_x', 'laser_y', 'laser_yaw')
    values = [section.get(k) for k in names]
    if all(v is None for v in values):
        return None
    pose = []
    for name, v in zip(names, values):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                              or not math.isfinite(v)):
            raise ValueError(f'parameter {name}: expected a finite number, got {echo(v)}')
        pose.append(float(v or 0.0))
    return tuple(pose)


#: keys of a flat params file; a ROS params file may also hold the nodes' own parameters
KNOWN_TOP_LEVEL = ('index', 'localizer', 'tracker', 'laser_x', 'laser_y', 'laser_yaw')
#: config fields that hold the laser pose on the base: set from laser_x/laser_y/laser_yaw only
LASER_POSE_FIELDS = ('index.sensor_pose', 'localizer.laser_pose')


def _node_params(data: dict, node: str) -> dict:
    """
    Return the parameters of ``node`` in a loaded params file.

    Unknown keys of a flat file raise ``ValueError``; so do, in a ROS params file, a missing
    section for ``node`` (a misspelled node name) and an unknown group of the core's
    parameters (a mapping or a dotted name: ``localiser:``). The node's own scalar parameters
    (``mode``, ``scan_topic``, ...) are left to the node.
    """
    ros_file = any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values())
    if ros_file:
        _require_section(data, (node,))
    section = node_section(data, node)
    unknown = sorted(str(k) for k in section
                     if str(k).split('.')[0] not in KNOWN_TOP_LEVEL)
    if ros_file:
        # the node's own parameters (mode, scan_topic, ...) are scalars; a mapping or a dotted
        # name is a group of the core's, and an unknown one a misspelling (``localiser:``)
        unknown = [k for k in unknown if '.' in k or isinstance(section.get(k), dict)]
    if unknown:
        raise ValueError(f'unknown parameter {"group " if ros_file else ""}'
                         f'{echo(unknown[0])} (known: {", ".join(KNOWN_TOP_LEVEL)})')
    return section


def _require_section(data: dict, nodes: tuple[str, ...]) -> None:
    """``ValueError`` unless a ROS params file has a section for one of ``nodes`` (or ``/**``)."""
    keys = [k for n in nodes for k in (n, '/' + n)] + ['/**', '**']
    if not any(isinstance(data.get(k), dict) and 'ros__parameters' in data[k] for k in keys):
        raise ValueError(f'no {" or ".join(nodes)} section with ros__parameters (the file has '
                         f'{", ".join(echo(k) for k in data)}): a misspelled node name?')


class Configs(NamedTuple):
    """The configs of the ``global_localizer`` node's params: index, localizer, tracker."""

    index: IndexConfig
    localizer: LocalizerConfig
    tracker: TrackerConfig


def configs_from_params(params: dict) -> Configs:
    """
    Return the index, localizer and tracker configs of a node's parameters.

    The one way from parameters to configs: params files (:func:`load_all_configs`,
    :func:`load_index_config`) and the ROS nodes' parameter values come through here.
    ``params`` holds nested mappings or dotted names (``index.beams``); keys other than
    ``index``, ``localizer``, ``tracker`` and ``laser_x/laser_y/laser_yaw`` are left to the
    caller. The laser pose on the base is one value, ``laser_x/laser_y/laser_yaw``: it is set on
    both configs that carry it (:data:`LASER_POSE_FIELDS`, refused as parameters).
    """
    if any('.' in str(k) for k in params):
        params = unflatten({str(k): v for k, v in params.items()})
    for name in LASER_POSE_FIELDS:
        group, leaf = name.split('.')
        section = params.get(group)
        if isinstance(section, dict) and leaf in section:
            raise ValueError(f'parameter {name}: the laser pose on the robot base is set once, '
                             'with laser_x, laser_y and laser_yaw')
    pose = laser_pose_of_section(params) or (0.0, 0.0, 0.0)
    index_cfg = from_dict(IndexConfig, params.get('index'), 'index.')
    loc_cfg = from_dict(LocalizerConfig, params.get('localizer'), 'localizer.')
    track_cfg = from_dict(TrackerConfig, params.get('tracker'), 'tracker.')
    return Configs(dataclasses.replace(index_cfg, sensor_pose=pose),
                   dataclasses.replace(loc_cfg, laser_pose=pose), track_cfg)


def load_all_configs(path: str | Path | None, node: str = 'global_localizer') -> Configs:
    """Return the index, localizer and tracker configs of a params file, read once."""
    data = load_yaml_mapping(path) if path else {}
    try:
        return configs_from_params(_node_params(data, node))
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{path}: {exc}') from None


def load_configs(path: str | Path | None, node: str = 'global_localizer'):
    """``(IndexConfig, LocalizerConfig)`` from a params file (defaults where absent)."""
    return load_all_configs(path, node)[:2]


def load_tracker_config(path: str | Path | None,
                        node: str = 'global_localizer') -> TrackerConfig:
    """Return the :class:`TrackerConfig` of a params file's ``tracker`` section (or defaults)."""
    return load_all_configs(path, node).tracker


def load_index_config(path: str | Path) -> IndexConfig:
    """
    :class:`IndexConfig` from a YAML params file (see :func:`load_yaml_mapping`).

    Accepts a node's parameters (``index:`` section, ``laser_*``) as :func:`load_all_configs`
    does, from a ``map_indexer`` (else ``global_localizer``) section of a ROS params file or a
    flat file; and the short form of ``ssm_localization index --params``: IndexConfig /
    TopologyConfig field names at the top level (nested ``topology:`` and ``matcher:`` mappings
    allowed, ``sensor_pose`` for the laser pose; keys of a ROS file that are no index
    parameters are left to the node).
    """
    data = load_yaml_mapping(path)
    try:
        return configs_from_params(_index_params(data)).index
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{path}: {exc}') from None


def _index_params(data: dict) -> dict:
    """Return a file of :func:`load_index_config` as a node's parameters."""
    ros = any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values())
    if ros:
        _require_section(data, ('map_indexer', 'global_localizer'))
    section = node_section(data, 'map_indexer') if ros else data
    if ros and not section:
        section = node_section(data, 'global_localizer')
    if any('.' in str(key) for key in section):
        section = unflatten({str(k): v for k, v in section.items()})
    if 'index' in section:
        return section
    idx_names = {f.name for f in dataclasses.fields(IndexConfig)}
    topo_names = {f.name for f in dataclasses.fields(TopologyConfig)}
    index = {'topology': dict(_mapping(section.get('topology'), 'parameters topology'))}
    out: dict = {'index': index}
    for key, value in section.items():
        if key == 'topology':
            continue
        if key == 'sensor_pose':
            pose = list(value) if isinstance(value, (list, tuple)) else [value]
            if len(pose) != 3:
                raise ValueError(f'parameter sensor_pose: expected [x, y, yaw], got {echo(value)}')
            out.update(zip(('laser_x', 'laser_y', 'laser_yaw'), pose))
        elif key in ('laser_x', 'laser_y', 'laser_yaw'):
            out[key] = value
        elif key in idx_names:
            index[key] = value
        elif key in topo_names:
            index['topology'][key] = value
        elif not ros:
            index[key] = value  # from_dict names the unknown key
    if not index['topology']:
        del index['topology']
    return out
