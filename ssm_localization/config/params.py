"""Config dataclasses from YAML parameter files (``yaml.safe_load`` only).

One file serves the CLI and the ROS nodes: either a plain mapping, or a ROS 2 params file whose
``<node>: ros__parameters:`` section is used. Nested mappings follow the dataclass nesting, e.g.::

    global_localizer:
      ros__parameters:
        localizer: {top_n: 5, sigma_d: 0.05}
        index: {beams: 360, topology: {arc_spacing: 2.5}, matcher: {max_points: 100}}

ROS flattens nested mappings to dotted names (``localizer.top_n``); :func:`unflatten` undoes it.
Unknown keys raise ``ValueError`` naming the key, so typos do not pass silently.
"""
from __future__ import annotations

import dataclasses
import json
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from .localization import LocalizerConfig
from .mapping import IndexConfig, TopologyConfig

T = TypeVar('T')


def load_yaml_mapping(path: str | Path) -> dict:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f'params file not found: {path}')
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f'{path}: malformed YAML: {exc}') from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f'{path}: expected a mapping at the top level')
    return data


def node_section(data: dict, node: str) -> dict:
    """The parameters for ``node`` from a ROS params file, or ``data`` itself if it is flat."""
    for key in (node, '/' + node, '/**', '**'):
        section = data.get(key)
        if isinstance(section, dict) and 'ros__parameters' in section:
            return section['ros__parameters'] or {}
    if any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values()):
        return {}
    return data


def unflatten(flat: dict[str, Any]) -> dict:
    """``{'a.b': 1}`` -> ``{'a': {'b': 1}}``."""
    out: dict = {}
    for key, value in flat.items():
        parts = key.split('.')
        cur = out
        for p in parts[:-1]:
            cur = cur.setdefault(p, {})
        cur[parts[-1]] = value
    return out


def flatten(obj: Any, prefix: str = '') -> dict[str, Any]:
    """A dataclass instance as ``{'dotted.name': value}`` (tuples become lists)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        name = prefix + f.name
        if dataclasses.is_dataclass(value):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = list(value) if isinstance(value, tuple) else value
    return out


def from_dict(cls: type[T], data: dict | None, where: str = '') -> T:
    """Build dataclass ``cls`` from a (nested) mapping, checking keys and coercing simple types."""
    data = dict(data or {})
    hints = typing.get_type_hints(cls)
    kwargs = {}
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f'unknown parameter {where}{unknown[0]!r} for {cls.__name__} '
                         f'(known: {", ".join(sorted(names))})')
    defaults = cls()
    for f in dataclasses.fields(cls):
        if f.name not in data:
            continue
        value = data[f.name]
        current = getattr(defaults, f.name)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, dict):
                raise ValueError(f'parameter {where}{f.name} must be a mapping')
            kwargs[f.name] = from_dict(type(current), value, f'{where}{f.name}.')
            continue
        kwargs[f.name] = _coerce(value, current, hints.get(f.name), f'{where}{f.name}')
    return dataclasses.replace(defaults, **kwargs)


def config_to_json(config: Any) -> str:
    """A config dataclass as JSON of its dotted field names (how an index file stores it)."""
    return json.dumps(flatten(config), sort_keys=True)


def config_from_json(cls: type[T], text: str) -> T:
    """Inverse of :func:`config_to_json`."""
    return from_dict(cls, unflatten(json.loads(text)))


def _coerce(value: Any, default: Any, hint: Any, name: str) -> Any:
    try:
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise TypeError
            return value
        if isinstance(default, int) and not isinstance(default, bool):
            if isinstance(value, bool) or float(value) != int(value):
                raise TypeError
            return int(value)
        if isinstance(default, float):
            if isinstance(value, bool):
                raise TypeError
            return float(value)
        if isinstance(default, tuple):
            seq = list(value)
            if len(seq) != len(default):
                raise TypeError
            return tuple(type(d)(v) if not isinstance(d, (tuple, list)) else v
                         for d, v in zip(default, seq))
        if isinstance(default, str):
            if not isinstance(value, str):
                raise TypeError
            return value
        if default is None:
            return value
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f'parameter {name}: expected {type(default).__name__} like '
                         f'{default!r}, got {value!r}') from None
    return value


def laser_pose_of_section(section: dict) -> tuple[float, float, float] | None:
    """The nodes' ``laser_x/laser_y/laser_yaw`` parameters as a pose, None when none is set."""
    values = [section.get(k) for k in ('laser_x', 'laser_y', 'laser_yaw')]
    if all(v is None for v in values):
        return None
    return tuple(float(v or 0.0) for v in values)


#: keys of a flat params file; a ROS params file may also hold the nodes' own parameters
KNOWN_TOP_LEVEL = ('index', 'localizer', 'laser_x', 'laser_y', 'laser_yaw')


def load_configs(path: str | Path | None, node: str = 'global_localizer'):
    """``(IndexConfig, LocalizerConfig)`` from a params file (defaults where absent)."""
    data = load_yaml_mapping(path) if path else {}
    ros_file = any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values())
    section = node_section(data, node)
    try:
        if any('.' in str(k) for k in section):
            section = unflatten({str(k): v for k, v in section.items()})
        unknown = sorted(str(k) for k in section if k not in KNOWN_TOP_LEVEL)
        if unknown and not ros_file:
            raise ValueError(f'unknown parameter {unknown[0]!r} (known: index, localizer, '
                             'laser_x, laser_y, laser_yaw)')
        index_cfg = from_dict(IndexConfig, section.get('index'), 'index.')
        loc_cfg = from_dict(LocalizerConfig, section.get('localizer'), 'localizer.')
        pose = laser_pose_of_section(section)
        if pose is not None:    # the laser pose on the base feeds both configs
            index_cfg = dataclasses.replace(index_cfg, sensor_pose=pose)
            loc_cfg = dataclasses.replace(loc_cfg, laser_pose=pose)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{path}: {exc}') from None
    return index_cfg, loc_cfg


def load_index_config(path: str | Path) -> IndexConfig:
    """:class:`IndexConfig` from a YAML params file (``yaml.safe_load``).

    Accepts a flat mapping of IndexConfig / TopologyConfig field names (nested ``topology:`` and
    ``matcher:`` mappings allowed), a ROS params file ``map_indexer: ros__parameters: {...}``
    (dotted names allowed; keys that are not index parameters are left to the node), or a
    ``global_localizer`` params file with an ``index:`` section.
    """
    data = load_yaml_mapping(path)
    ros = any(isinstance(v, dict) and 'ros__parameters' in v for v in data.values())
    section = node_section(data, 'map_indexer') if ros else data
    if ros and not section:
        section = node_section(data, 'global_localizer')
    if any('.' in str(key) for key in section):
        section = unflatten(section)
    laser = laser_pose_of_section(section)
    if isinstance(section.get('index'), dict):
        section = section['index']
    idx_names = {f.name for f in dataclasses.fields(IndexConfig)}
    topo_names = {f.name for f in dataclasses.fields(TopologyConfig)}
    topo = dict(section.get('topology') or {})
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
    try:
        return from_dict(IndexConfig, kwargs)
    except ValueError as exc:
        raise ValueError(f'{path}: {exc}') from None
