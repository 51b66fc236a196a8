"""
Helpers for the launch files in ``launch/`` (plain Python: no ``launch`` import here).

ROS 2 params files name their nodes (``global_localizer: ros__parameters: ...``). rcl matches
such a key against the node's fully qualified name, so ``global_localizer`` does not reach
``/robot1/global_localizer``. :func:`namespaced_params_file` nests a file's content under the
namespace (``robot1: global_localizer: ros__parameters: ...``), the form rcl matches there, as
nav2's ``RewrittenYaml(root_key=namespace)`` does, without depending on nav2.
"""
from __future__ import annotations

import os
from pathlib import Path
import tempfile
from typing import Any

from ssm_localization.config.params import load_yaml_mapping
import yaml

_TRUE = ('true', '1', 'yes', 'on')
_FALSE = ('false', '0', 'no', 'off')


def launch_bool(text: str, name: str) -> bool:
    """
    Return a launch argument's text (``true``/``false``, ``1``/``0``, ...) as a bool.

    Raises ``ValueError`` naming the argument for anything else.
    """
    value = str(text).strip().lower()
    if value in _TRUE:
        return True
    if value in _FALSE:
        return False
    raise ValueError(f'launch argument {name}:={text!r} is not a boolean (true or false)')


def namespace_tokens(namespace: str) -> list[str]:
    """``'/robot1/arm/'`` -> ``['robot1', 'arm']``; ``''`` or ``'/'`` -> ``[]``."""
    return [token for token in str(namespace).split('/') if token]


def nest_under_namespace(data: dict[str, Any], namespace: str) -> dict[str, Any]:
    """
    Nest every node section of a params mapping under ``namespace`` (unchanged if empty).

    Keys that already are absolute (``/robot1/global_localizer``, ``/**``) are kept at the top
    level: rcl matches them as they are.
    """
    tokens = namespace_tokens(namespace)
    if not tokens:
        return data
    absolute = {k: v for k, v in data.items() if str(k).startswith('/')}
    relative = {k: v for k, v in data.items() if not str(k).startswith('/')}
    nested: dict[str, Any] = relative
    for token in reversed(tokens):
        nested = {token: nested}
    return {**nested, **absolute} if relative else absolute


def namespaced_params_file(path: str | os.PathLike, namespace: str) -> str:
    """
    Return a params file whose node sections reach nodes pushed into ``namespace``.

    Returns ``path`` itself when ``namespace`` is empty, else the path of a new temporary file
    holding :func:`nest_under_namespace` of its content (left for the launched process to read).
    """
    try:
        data = load_yaml_mapping(Path(path).expanduser())
    except FileNotFoundError as exc:        # a launch argument error, like the others here
        raise ValueError(str(exc)) from None
    if not namespace_tokens(namespace):
        return str(Path(path).expanduser())
    fd, out = tempfile.mkstemp(prefix='ssm_localization_params_', suffix='.yaml')
    with os.fdopen(fd, 'w') as fh:
        yaml.safe_dump(nest_under_namespace(data, namespace), fh, default_flow_style=False)
    return out
