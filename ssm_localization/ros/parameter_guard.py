"""
Validation of the nodes' parameters at the boundary.

Every parameter is declared with a :class:`ParameterDescriptor` that carries its range (rclpy
refuses out-of-range values, NaN and infinities included, at start-up and at run time) and an
on-set-parameters callback, :class:`ParameterGuard`, that refuses with a reason what a range
cannot express: non-finite floats in lists, a value outside a set of choices, an empty frame
name, a topic name ROS would refuse or a frame id with white space (refused when set, not at
configure), a config the core would reject, and a change of a configure-time parameter while
the node is configured. At start-up a refused value makes the declaration raise (the node exits
with the reason, status 2); at run time ``ros2 param set`` gets the reason and the node keeps its
value.

Two kinds of parameters:

- run-time (``dynamic``): may change in any lifecycle state (``scan_timeout`` ...);
- configure-time (all others): read by ``on_configure``; they may change only while the node is
  unconfigured (``ros2 lifecycle set NODE cleanup`` first), so a running node never holds a
  value it does not use.
"""
from __future__ import annotations

import array
import math
from typing import Any, Callable, Iterable

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import InvalidTopicNameException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.validate_topic_name import validate_topic_name

INTEGER_MAX = 2 ** 62
# (low, high) of the nodes' own numeric parameters; integer parameters without an entry get
# [0, INTEGER_MAX] (counts and sizes), float parameters without one only the finiteness check.
RANGES: dict[str, tuple[float, float]] = {
    'scan_timeout': (0.01, 3600.0),
    'rate': (0.0, 1000.0),
    'laser_x': (-1000.0, 1000.0),
    'laser_y': (-1000.0, 1000.0),
    'laser_yaw': (-2.0 * math.pi, 2.0 * math.pi),
    'max_map_cells': (0, INTEGER_MAX),
    'max_gvd_points': (0, INTEGER_MAX),
    'odom_max_age': (0.0, 60.0),
    'transform_tolerance': (0.0, 60.0),
    'handover_period': (0.01, 60.0),
    'handover_tries': (1, 100000),
    'handover_tolerance': (0.0, 1000.0),
}
NON_EMPTY = ('base_frame', 'odom_frame', 'scan_topic', 'map_topic')
#: names the node subscribes to: a valid ROS topic name (relative, absolute or private), or empty
#: where the parameter allows it (``handover_confirm_topic``: no confirmation)
TOPICS = ('scan_topic', 'map_topic', 'handover_confirm_topic')
#: frame ids: no white space (a leading ``/`` is dropped, as tf2 does not take it)
FRAMES = ('base_frame', 'odom_frame', 'map_frame')


def descriptor(name: str, default: Any, description: str, dynamic: bool,
               choices: Iterable[str] = ()) -> ParameterDescriptor:
    """Return the descriptor of one parameter: description, range, constraints in words."""
    d = ParameterDescriptor(description=description)
    notes = [] if dynamic else ['configure-time: settable while unconfigured']
    if isinstance(default, bool):
        pass
    elif isinstance(default, int) and default >= 0:
        low, high = RANGES.get(name, (0, INTEGER_MAX))
        d.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
    elif isinstance(default, float):
        notes.append('finite')
        if name in RANGES:
            low, high = RANGES[name]
            d.floating_point_range = [FloatingPointRange(from_value=float(low),
                                                         to_value=float(high), step=0.0)]
    elif isinstance(default, list) and default and isinstance(default[0], float):
        notes.append('finite values')
    choices = tuple(choices)
    if choices:
        notes.append('one of ' + ', '.join(choices))
    if name in NON_EMPTY:
        notes.append('not empty')
    if name in TOPICS:
        notes.append('a valid topic name')
    if name in FRAMES:
        notes.append('no white space')
    d.additional_constraints = '; '.join(notes)
    return d


def value_problem(name: str, value: Any, choices: Iterable[str] = ()) -> str | None:
    """Why ``value`` is not acceptable for ``name`` (beyond its descriptor range), or None."""
    # a list set over the set_parameters service arrives as an array.array
    values = list(value) if isinstance(value, (list, tuple, array.array)) else [value]
    for v in values:
        if isinstance(v, float) and not math.isfinite(v):
            return f'{name} must be finite, got {values!r}'
    choices = tuple(choices)
    if choices and value not in choices:
        return f'{name} must be one of {", ".join(choices)}; got {value!r}'
    if name in NON_EMPTY and not str(value).strip():
        return f'{name} must not be empty'
    if name in TOPICS and str(value):
        try:
            validate_topic_name(str(value))
        except InvalidTopicNameException as exc:
            return f'{name}: {str(exc).splitlines()[0]} ({str(value)!r})'
    if name in FRAMES and any(c.isspace() for c in str(value)):
        return f'{name} must not contain white space, got {str(value)!r}'
    return None


class ParameterGuard:
    """
    The on-set-parameters callback of a node (see the module docstring).

    ``table``: ``{name: (default, description)}`` of the node's parameters; ``configured()``:
    True while configure-time parameters are in use (inactive / active); ``check_all(values)``:
    the reason why a full set of values is inconsistent (e.g. the core refuses its config), or
    None.
    """

    def __init__(self, node: Node, table: dict[str, tuple[Any, str]], dynamic: Iterable[str],
                 choices: dict[str, tuple[str, ...]], configured: Callable[[], str | None],
                 check_all: Callable[[dict[str, Any]], str | None]) -> None:
        self._node = node
        self._table = table
        self._dynamic = set(dynamic)
        self._choices = choices
        self._configured = configured
        self._check_all = check_all

    def declare(self) -> dict[str, Any]:
        """Register the callback, then declare every parameter (values checked as they come)."""
        self._node.add_on_set_parameters_callback(self)
        values = {}
        for name, (default, description) in self._table.items():
            dynamic = name in self._dynamic
            self._node.declare_parameter(name, default, descriptor(
                name, default, description, dynamic, self._choices.get(name, ())))
            values[name] = self._node.get_parameter(name).value
        reason = self._check_all(values)
        if reason is not None:
            raise ValueError(reason)
        return values

    def values(self) -> dict[str, Any]:
        """Return the current value of every declared parameter of the table."""
        return {name: self._node.get_parameter(name).value for name in self._table
                if self._node.has_parameter(name)}

    def __call__(self, params: list[Parameter]) -> SetParametersResult:
        """Accept or refuse a set of new values (rclpy calls this before applying them)."""
        changes = {p.name: p.value for p in params if p.name in self._table}
        for name, value in changes.items():
            reason = value_problem(name, value, self._choices.get(name, ()))
            if reason is None and name not in self._dynamic and self._node.has_parameter(name):
                state = self._configured()
                if state is not None:
                    reason = (f'{name} is read when the node is configured; it can change only '
                              f'while unconfigured (now {state}): clean up first')
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        declared = [n for n in changes if self._node.has_parameter(n)]
        if any(name not in self._dynamic for name in declared):   # (declare() checks the rest)
            values = {name: default for name, (default, _) in self._table.items()}
            values.update(self.values())
            values.update(changes)
            reason = self._check_all(values)
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)
