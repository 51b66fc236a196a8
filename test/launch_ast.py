"""
What a launch file names, read from its syntax tree (``ast``).

The nodes it starts, their parameters, the files it joins onto the package's share directory.

Shared by test/unit/test_launch_files.py (static checks) and test/integration/test_colcon.py
(the installed files).
"""
from __future__ import annotations

import ast
from dataclasses import dataclass, field
from pathlib import Path


NODE_ACTIONS = ('Node', 'LifecycleNode')


@dataclass
class LaunchedNode:
    """One ``Node(...)`` / ``LifecycleNode(...)`` action of a launch file."""

    action: str
    package: str
    executable: str
    name: str
    parameters: dict = field(default_factory=dict)    # literal keys -> literal value or None
    remappings: list = field(default_factory=list)
    line: int = 0


def const_value(node: ast.AST):
    """Return a literal's value (None when not a literal)."""
    try:
        return ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return None


def _dict_items(node: ast.AST, function: ast.FunctionDef | None) -> dict:
    """Literal keys of a dict display, or of a local variable built as one (plus ``d[k] = v``)."""
    if isinstance(node, ast.Dict):
        return {const_value(k): const_value(v) for k, v in zip(node.keys, node.values)
                if k is not None and isinstance(const_value(k), str)}
    if isinstance(node, ast.Name) and function is not None:
        out: dict = {}
        for stmt in ast.walk(function):
            if isinstance(stmt, ast.Assign):
                for target in stmt.targets:
                    if isinstance(target, ast.Name) and target.id == node.id:
                        out.update(_dict_items(stmt.value, None))
                    elif (isinstance(target, ast.Subscript) and isinstance(target.value, ast.Name)
                          and target.value.id == node.id and isinstance(const_value(target.slice),
                                                                        str)):
                        out[const_value(target.slice)] = const_value(stmt.value)
        return out
    return {}


def _module_constants(tree: ast.Module) -> dict:
    """Module-level ``NAME = literal`` assignments."""
    out = {}
    for stmt in tree.body:
        if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and \
                isinstance(stmt.targets[0], ast.Name):
            value = const_value(stmt.value)
            if value is not None:
                out[stmt.targets[0].id] = value
    return out


def value_of(node: ast.AST, constants: dict):
    """Return a literal or a module constant's value."""
    if isinstance(node, ast.Name) and node.id in constants:
        return constants[node.id]
    return const_value(node)


class LaunchFile:
    """What a launch file names, read from its syntax tree."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.tree = ast.parse(path.read_text(), filename=str(path))
        self.constants = _module_constants(self.tree)
        self.functions = {f.name: f for f in self.tree.body if isinstance(f, ast.FunctionDef)}

    def imports(self) -> list[tuple[str, str, int]]:
        """Return (module, name, line) of every ``from module import name``."""
        return [(n.module, a.name, n.lineno) for n in ast.walk(self.tree)
                if isinstance(n, ast.ImportFrom) for a in n.names]

    def plain_imports(self) -> list[str]:
        return [a.name for n in ast.walk(self.tree) if isinstance(n, ast.Import) for a in n.names]

    def _calls(self, name: str):
        for function in self.functions.values():
            for node in ast.walk(function):
                if isinstance(node, ast.Call) and (
                        (isinstance(node.func, ast.Name) and node.func.id == name) or
                        (isinstance(node.func, ast.Attribute) and node.func.attr == name)):
                    yield function, node

    def declared_arguments(self) -> dict[str, str | None]:
        """``{name: default or None}`` of every DeclareLaunchArgument."""
        out = {}
        for _, call in self._calls('DeclareLaunchArgument'):
            name = value_of(call.args[0], self.constants)
            kw = {k.arg: k.value for k in call.keywords}
            out[name] = 'default' if 'default_value' in kw else None
        return out

    def used_arguments(self) -> set[str]:
        """Launch configurations read (``LaunchConfiguration('x')`` or ``_arg(context, 'x')``)."""
        used = set()
        for name in ('LaunchConfiguration', '_arg'):
            for _, call in self._calls(name):
                if call.args:
                    value = value_of(call.args[-1], self.constants)
                    if isinstance(value, str):
                        used.add(value)
        return used

    def nodes(self) -> list[LaunchedNode]:
        out = []
        for action in NODE_ACTIONS:
            for function, call in self._calls(action):
                kw = {k.arg: k.value for k in call.keywords}
                params: dict = {}
                for item in getattr(kw.get('parameters'), 'elts', []):
                    params.update(_dict_items(item, function))
                out.append(LaunchedNode(
                    action, value_of(kw['package'], self.constants),
                    value_of(kw['executable'], self.constants),
                    value_of(kw['name'], self.constants),
                    params, value_of(kw['remappings'], self.constants) if 'remappings' in kw
                    else [], call.lineno))
        return out

    def share_files(self) -> list[str]:
        """Paths joined onto the package share directory (``os.path.join(share, 'a', 'b')``)."""
        out = []
        for _, call in self._calls('join'):
            if call.args and isinstance(call.args[0], ast.Name) and call.args[0].id == 'share':
                parts = [value_of(a, self.constants) for a in call.args[1:]]
                if all(isinstance(p, str) for p in parts):
                    out.append('/'.join(parts))
        return out
