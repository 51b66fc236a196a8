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
from typing import NamedTuple, TypeVar

# the conversions without YAML live in convert.py (index files use them); re-exported here
from .convert import (as_mapping as _mapping, config_from_json, config_to_json,  # noqa: F401
                      flatten, from_dict, unflatten)
from .localization import LocalizerConfig
from .mapping import IndexConfig, TopologyConfig
from .tracking import TrackerConfig
from ..files.reading import echo
from ..files.yaml_input import load_yaml_file

T = TypeVar('T')


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


def _node_params(data: dict, node: str) -> dict:
    """
    Return the (unflattened) parameters of ``node`` in a loaded params file.

    Unknown keys of a flat file raise ``ValueError``.
    """
    ros_file = any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values())
    section = node_section(data, node)
    if any('.' in str(k) for k in section):
        section = unflatten({str(k): v for k, v in section.items()})
    unknown = sorted(str(k) for k in section if k not in KNOWN_TOP_LEVEL)
    if unknown and not ros_file:
        raise ValueError(f'unknown parameter {echo(unknown[0])} (known: '
                         f'{", ".join(KNOWN_TOP_LEVEL)})')
    return section


class Configs(NamedTuple):
    """The configs of the ``global_localizer`` node's params: index, localizer, tracker."""

    index: IndexConfig
    localizer: LocalizerConfig
    tracker: TrackerConfig


def load_all_configs(path: str | Path | None, node: str = 'global_localizer') -> Configs:
    """Return the index, localizer and tracker configs of a params file, read once."""
    data = load_yaml_mapping(path) if path else {}
    try:
        section = _node_params(data, node)
        index_cfg = from_dict(IndexConfig, section.get('index'), 'index.')
        loc_cfg = from_dict(LocalizerConfig, section.get('localizer'), 'localizer.')
        pose = laser_pose_of_section(section)
        if pose is not None:    # the laser pose on the base feeds both configs
            index_cfg = dataclasses.replace(index_cfg, sensor_pose=pose)
            loc_cfg = dataclasses.replace(loc_cfg, laser_pose=pose)
        track_cfg = from_dict(TrackerConfig, section.get('tracker'), 'tracker.')
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{path}: {exc}') from None
    return Configs(index_cfg, loc_cfg, track_cfg)


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

    Accepts a flat mapping of IndexConfig / TopologyConfig field names (nested ``topology:`` and
    ``matcher:`` mappings allowed), a ROS params file ``map_indexer: ros__parameters: {...}``
    (dotted names allowed; keys that are not index parameters are left to the node), or a
    ``global_localizer`` params file with an ``index:`` section.
    """
    data = load_yaml_mapping(path)
    try:
        return _index_config_of(data)
    except ValueError as exc:
        raise ValueError(f'{path}: {exc}') from None


def _index_config_of(data: dict) -> IndexConfig:
    """:func:`load_index_config` on the loaded file."""
    ros = any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values())
    section = node_section(data, 'map_indexer') if ros else data
    if ros and not section:
        section = node_section(data, 'global_localizer')
    if any('.' in str(key) for key in section):
        section = unflatten(section)
    laser = laser_pose_of_section(section)
    if 'index' in section:
        section = _mapping(section['index'], 'parameters index')
    idx_names = {f.name for f in dataclasses.fields(IndexConfig)}
    topo_names = {f.name for f in dataclasses.fields(TopologyConfig)}
    topo = dict(_mapping(section.get('topology'), 'parameters topology'))
    kwargs = {}
    for key, value in section.items():
        if key == 'topology':
            continue
        if key in idx_names:
            kwargs[key] = value
        elif key in topo_names:
            topo[key] = value
        elif not ros:
            kwargs[key] = value  # from_dict names the unknown key
    if topo:
        kwargs['topology'] = topo
    if laser is not None:           # the nodes' laser_x/y/yaw: the laser on the base
        kwargs['sensor_pose'] = list(laser)
    return from_dict(IndexConfig, kwargs)
