"""
``param``: a dataclass field with its description; ``check_numbers``: the configs' range checks.

The one source of every config field's help: the ROS parameter descriptions, the generated params
file and docs/PARAMETERS.md.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterable


def param(default: Any = dataclasses.MISSING, help: str = '', *,  # noqa: A002 - argparse's name
          default_factory: Any = dataclasses.MISSING) -> Any:
    """``dataclasses.field`` with ``metadata={'help': help}``."""
    return dataclasses.field(default=default, default_factory=default_factory,
                             metadata={'help': help})


def help_of(cls: type) -> dict[str, str]:
    """``{field name: help}`` of a config dataclass ('' where a field has none)."""
    return {f.name: f.metadata.get('help', '') for f in dataclasses.fields(cls)}


def check_numbers(obj: Any, positive: Iterable[str] = (), nonnegative: Iterable[str] = ()) -> None:
    """
    Raise ``ValueError`` unless the named fields of ``obj`` are finite numbers > 0 / >= 0.

    A tuple is checked element by element. The message names ``Class.field`` and the value.
    """
    for names, least in ((positive, '> 0'), (nonnegative, '>= 0')):
        for name in names:
            value = getattr(obj, name)
            values = value if isinstance(value, tuple) else (value,)
            if not all(isinstance(v, (int, float)) and math.isfinite(v)
                       and (v > 0 if least == '> 0' else v >= 0) for v in values):
                what = 'finite numbers' if isinstance(value, tuple) else 'a finite number'
                raise ValueError(f'{type(obj).__name__}.{name} must be {what} {least}, got '
                                 f'{value!r}')
