"""
YAML files read with bounds.

A file-size limit and a ``yaml.SafeLoader`` subclass that refuses documents whose aliases expand to
too many nodes ("billion laughs") or refer to themselves.

PyYAML shares an anchored node between its aliases, so loading an alias bomb is cheap; what
explodes is anything that walks the result (``repr`` in an error message, flattening, JSON). The
loader therefore counts the nodes of the document with every alias expanded, in time linear in
the file, and refuses it above :data:`MAX_YAML_NODES`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from .reading import clip, read_bounded

#: largest YAML file read (map YAML, params files, bag metadata)
MAX_YAML_BYTES = 1 << 20
#: most nodes a YAML document may have with its aliases expanded
MAX_YAML_NODES = 100_000


class YamlBombError(yaml.YAMLError):
    """A document whose aliases expand beyond the node limit, or refer to themselves."""


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def expanded_size(root: yaml.Node, limit: int = MAX_YAML_NODES) -> int:
    """
    Nodes under ``root`` (itself included) with every alias expanded, at most ``limit``.

    Iterative and memoized on node identity, so its cost is linear in the composed graph.
    Raises :class:`YamlBombError` beyond ``limit`` or for an alias inside its own anchor.
    """
    sizes: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, finished = stack.pop()
        key = id(node)
        if finished:
            on_path.discard(key)
            total = 1 + sum(sizes[id(c)] for c in _children(node))
            if total > limit:
                raise YamlBombError(f'more than {limit} nodes (aliases expanded)')
            sizes[key] = total
            continue
        if key in sizes:
            continue
        on_path.add(key)
        stack.append((node, True))
        for child in _children(node):
            if id(child) in on_path:
                raise YamlBombError('an alias refers to a node that contains it')
            if id(child) not in sizes:
                stack.append((child, False))
    return sizes[id(root)]


class BoundedSafeLoader(yaml.SafeLoader):
    """
    ``yaml.SafeLoader`` that checks :func:`expanded_size` and refuses duplicate keys.

    PyYAML keeps the last of two equal keys of a mapping without a word (``resolution: 0.05``
    then ``resolution: 5``); YAML 1.2 calls such a document invalid, and so does this loader.
    """

    max_nodes = MAX_YAML_NODES

    def construct_document(self, node: yaml.Node) -> Any:
        expanded_size(node, self.max_nodes)
        return super().construct_document(node)

    def construct_mapping(self, node: yaml.Node, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: set[tuple[str, str]] = set()
            for key, _ in node.value:
                if not isinstance(key, yaml.ScalarNode) or key.tag == 'tag:yaml.org,2002:merge':
                    continue
                if (key.tag, key.value) in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f'duplicate key {clip(key.value)!r}', key.start_mark)
                seen.add((key.tag, key.value))
        return super().construct_mapping(node, deep=deep)


def parse_yaml(data: bytes | str, where: str) -> Any:
    """One YAML document through :class:`BoundedSafeLoader`; ``ValueError`` naming ``where``."""
    try:
        return yaml.load(data, Loader=BoundedSafeLoader)  # noqa: S506 - a SafeLoader subclass
    except YamlBombError as exc:
        raise ValueError(f'{where}: refused: {exc}') from None
    except yaml.YAMLError as exc:
        raise ValueError(f'{where}: malformed YAML: {clip(exc)}') from None
    except RecursionError:
        raise ValueError(f'{where}: malformed YAML: nested too deeply') from None
    except (ValueError, KeyError, AttributeError, TypeError, OverflowError, IndexError) as exc:
        # SafeLoader's constructors of explicit tags and odd scalars (``!!bool maybe``,
        # ``!!timestamp nope``, ``!!int abc``, a date of month 13, a 5000-digit integer)
        raise ValueError(f'{where}: malformed YAML: a value cannot be read '
                         f'({type(exc).__name__}: {clip(exc)})') from None


def load_yaml_file(path: str | Path, what: str, max_bytes: int = MAX_YAML_BYTES) -> Any:
    """Return the YAML document in ``path`` (at most ``max_bytes``; see :func:`parse_yaml`)."""
    data = read_bounded(path, what, max_bytes)
    return parse_yaml(data, f'{what} {path}')
