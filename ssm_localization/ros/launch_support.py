"""
Helpers for the launch files in ``launch/`` (plain Python: no ``launch`` import here).

Namespaces, as nav2_bringup uses them: a parent launch file wraps its includes in
``PushROSNamespace(namespace)`` and passes ``namespace`` as an argument too, only to root the
params file. :func:`node_namespace` gives a node the ``namespace`` argument only when the launch
context has not pushed it already (no ``/robot1/robot1``), so the launch files work both
included that way and on their own (``namespace:=robot1``).

ROS 2 params files name their nodes (``global_localizer: ros__parameters: ...``). rcl matches
such a key against the node's fully qualified name, so ``global_localizer`` does not reach
``/robot1/global_localizer``. :func:`namespaced_params_file` nests a file's node sections under
the namespace (``robot1: global_localizer: ros__parameters: ...``), the form rcl matches there,
as nav2's ``RewrittenYaml(root_key=namespace)`` does, without depending on nav2.

:func:`amcl_equivalents` reads AMCL's frame and topic parameters from a nav2 params file, so
``global_localizer`` follows the same robot as AMCL without a second setting.
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


def node_namespace(pushed: str | None, namespace: str) -> str | None:
    """
    Return the ``namespace=`` to give a node, or None when ``pushed`` already holds it.

    ``pushed`` is the launch context's ``ros_namespace`` (what ``PushROSNamespace`` set);
    ``namespace`` the launch argument. nav2_bringup pushes the namespace and passes it as an
    argument as well: pushing it again would give ``/robot1/robot1/NODE``.
    """
    wanted = namespace_tokens(namespace)
    if not wanted:
        return None
    have = namespace_tokens(pushed or '')
    if have[-len(wanted):] == wanted:
        return None
    return '/'.join(wanted)


def full_namespace(pushed: str | None, namespace: str) -> str:
    """Return the namespace a node ends up in: ``pushed`` plus :func:`node_namespace`."""
    own = node_namespace(pushed, namespace)
    return '/' + '/'.join(namespace_tokens(pushed or '') + namespace_tokens(own or ''))


def _is_namespace_section(value: Any) -> bool:
    """Tell whether a params-file value is a namespace (node sections inside), not a node."""
    return isinstance(value, dict) and 'ros__parameters' not in value and any(
        isinstance(v, dict) for v in value.values())


def nest_under_namespace(data: dict[str, Any], namespace: str) -> dict[str, Any]:
    """
    Nest every node section of a params mapping under ``namespace`` (unchanged if empty).

    Keys that already are absolute (``/robot1/global_localizer``, ``/**``) are kept at the top
    level, as is a file already nested under the namespace's first name: rcl matches them as
    they are.
    """
    tokens = namespace_tokens(namespace)
    if not tokens:
        return data
    if _is_namespace_section(data.get(tokens[0])):
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


#: AMCL parameter -> the global_localizer parameter of the same meaning
AMCL_EQUIVALENTS = {'base_frame_id': 'base_frame', 'global_frame_id': 'map_frame',
                    'odom_frame_id': 'odom_frame', 'scan_topic': 'scan_topic',
                    'map_topic': 'map_topic'}


def _section(data: dict[str, Any], node: str, namespace: str) -> dict[str, Any]:
    """Return ``node``'s ``ros__parameters`` in a params mapping (plain or namespaced keys)."""
    tokens = namespace_tokens(namespace)
    for path in ([node], [*tokens, node], ['/' + '/'.join([*tokens, node])]):
        cur: Any = data
        for key in path:
            cur = cur.get(key) if isinstance(cur, dict) else None
        if isinstance(cur, dict) and isinstance(cur.get('ros__parameters'), dict):
            return cur['ros__parameters']
    return {}


def amcl_equivalents(path: str | os.PathLike, namespace: str = '') -> dict[str, Any]:
    """
    Return global_localizer parameters taken from the ``amcl`` section of a nav2 params file.

    Only what AMCL sets there (:data:`AMCL_EQUIVALENTS`: frames and topics) and the
    ``global_localizer`` section does not; an empty dict when the file has neither.
    """
    try:
        data = load_yaml_mapping(Path(path).expanduser())
    except FileNotFoundError as exc:
        raise ValueError(str(exc)) from None
    amcl = _section(data, 'amcl', namespace)
    ours = _section(data, 'global_localizer', namespace)
    return {mine: amcl[theirs] for theirs, mine in AMCL_EQUIVALENTS.items()
            if theirs in amcl and mine not in ours and isinstance(amcl[theirs], str)}
