"""
Argument types and options shared by the subcommands.

Numbers are checked where they are parsed, so a NaN resolution or a negative count is a one-line
usage error, never a crash later.
"""
from __future__ import annotations

import argparse
import math
from typing import Callable

from ..mapping.map_limits import MAX_MAP_CELLS
from ..matching.scan import MAX_RANGE


def _number(kind: type, test: Callable[[float], bool], want: str) -> Callable[[str], float]:
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'expected {want}, got {text!r}') from None
        if not (math.isfinite(value) and test(value)):
            raise argparse.ArgumentTypeError(f'expected {want}, got {text!r}')
        return value
    parse.__name__ = want       # argparse names the type in some messages
    return parse


finite_float = _number(float, lambda v: True, 'a finite number')
positive_float = _number(float, lambda v: v > 0, 'a number > 0')
nonnegative_float = _number(float, lambda v: v >= 0, 'a number >= 0')
fraction = _number(float, lambda v: 0 <= v <= 1, 'a number in [0, 1]')
positive_int = _number(int, lambda v: v >= 1, 'an integer >= 1')
nonnegative_int = _number(int, lambda v: v >= 0, 'an integer >= 0')
#: a sensor range, metres (readings beyond MAX_RANGE are garbage to the localizer)
sensor_range = _number(float, lambda v: 0 < v <= MAX_RANGE, f'a range in (0, {MAX_RANGE:g}] m')
#: a pose offset's component: metres, or degrees where the option says so
offset_component = _number(float, lambda v: abs(v) <= 1000.0, 'a number within +-1000')
#: a wait, seconds
delay_seconds = _number(float, lambda v: 0 <= v <= 3600.0, 'seconds in [0, 3600]')


def add_max_map_cells(parser: argparse.ArgumentParser) -> None:
    """``--max-map-cells N``: the map-size guard of the nodes' ``max_map_cells``."""
    parser.add_argument('--max-map-cells', type=nonnegative_int, default=MAX_MAP_CELLS,
                        metavar='N', help=f'refuse maps of more than N cells before loading '
                                          f'them (default {MAX_MAP_CELLS}; 0 = no limit)')
