"""
``param``: a dataclass field with its description.

The one source of every config field's help: the ROS parameter descriptions, the generated params
file and docs/PARAMETERS.md.
"""
from __future__ import annotations

import dataclasses
from typing import Any


def param(default: Any = dataclasses.MISSING, help: str = '', *,  # noqa: A002 - argparse's name
          default_factory: Any = dataclasses.MISSING) -> Any:
    """``dataclasses.field`` with ``metadata={'help': help}``."""
    return dataclasses.field(default=default, default_factory=default_factory,
                             metadata={'help': help})


def help_of(cls: type) -> dict[str, str]:
    """``{field name: help}`` of a config dataclass ('' where a field has none)."""
    return {f.name: f.metadata.get('help', '') for f in dataclasses.fields(cls)}
