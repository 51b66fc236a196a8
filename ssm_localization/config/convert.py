"""
Config dataclasses to and from plain data: nested mappings, dotted names, JSON.

No YAML here (``params.py`` reads the files): index files store their config as JSON through
:func:`config_to_json` / :func:`config_from_json`, so loading an index needs nothing beyond the
standard library.
"""
from __future__ import annotations

import dataclasses
import json
from typing import Any, TypeVar

from ..files.reading import echo

T = TypeVar('T')


def as_mapping(value: Any, name: str) -> dict:
    """``value`` if it is a mapping (``{}`` for None), else ``ValueError`` naming ``name``."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ValueError(f'{name} must be a mapping, got {echo(value)}')
    return value


def unflatten(flat: dict[str, Any]) -> dict:
    """
    ``{'a.b': 1}`` -> ``{'a': {'b': 1}}``.

    A parameter given twice, once dotted and once in its group (``index.beams: 180`` beside
    ``index: {beams: 360}``), is refused: which one wins would depend on the order of the keys.
    """
    out: dict = {}
    for key, value in flat.items():
        parts = str(key).split('.')
        cur = out
        for p in parts[:-1]:
            cur = cur.setdefault(p, {})
            if not isinstance(cur, dict):
                raise ValueError(f'parameter {echo(key)}: {p!r} is also given a value')
        _put(cur, parts[-1], value, str(key))
    return out


def _put(group: dict, name: str, value: Any, where: str) -> None:
    """Set ``group[name] = value``, merging groups and refusing a parameter given twice."""
    if name not in group:
        group[name] = value
    elif isinstance(group[name], dict) and isinstance(value, dict):
        for key, item in value.items():
            _put(group[name], str(key), item, f'{where}.{key}')
    elif isinstance(group[name], dict):
        raise ValueError(f'parameter {echo(where)} is also a group of parameters')
    else:
        raise ValueError(f'parameter {echo(where)} is given twice (dotted and in its group)')


def flatten(obj: Any, prefix: str = '') -> dict[str, Any]:
    """Return a dataclass instance as ``{'dotted.name': value}`` (tuples become lists)."""
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
    data = dict(as_mapping(data, f'parameters {where.rstrip(".") or cls.__name__}'))
    kwargs = {}
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(str(k) for k in set(data) - names)
    if unknown:
        raise ValueError(f'unknown parameter {where}{echo(unknown[0])} for {cls.__name__} '
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
        kwargs[f.name] = _coerce(value, current, f'{where}{f.name}')
    return dataclasses.replace(defaults, **kwargs)


def config_to_json(config: Any) -> str:
    """
    Return a config dataclass as JSON of its dotted field names.

    This is how an index file stores the config it was built with.
    """
    return json.dumps(flatten(config), sort_keys=True)


def config_from_json(cls: type[T], text: str) -> T:
    """Inverse of :func:`config_to_json`."""
    return from_dict(cls, unflatten(json.loads(text)))


def _coerce(value: Any, default: Any, name: str) -> Any:
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
                         f'{default!r}, got {echo(value)}') from None
    return value
