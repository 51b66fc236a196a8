"""
``/diagnostics`` (diagnostic_msgs/DiagnosticArray) of global_localizer.

One status named ``<node name>: localization`` (hardware_id: the node's fully qualified name):
level OK / WARN / ERROR for an ``ok`` / ``ambiguous`` / ``failed`` last localization; before the
first localization OK when the map is indexed, WARN while there is no map or it is being
indexed. Key-values: status, confidence (the calibrated P(right | evidence) of the answer, the
"am I lost" signal: an ``ok`` answer has at least ``min_confidence``), score, latency_ms, node
(topological node id), candidates (count), map (``no map`` / ``indexing`` / ``ready``),
map_note (why the served map lies outside what the confidence was calibrated on: a map of
coarser cells; empty otherwise), frame, x / y / yaw, lifecycle state, mode.
"""
from __future__ import annotations

import math
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from ssm_localization.localization.localizer import AMBIGUOUS, FAILED, OK
from ssm_localization.ros.conversions import time_msg

LEVELS = {OK: DiagnosticStatus.OK, AMBIGUOUS: DiagnosticStatus.WARN,
          FAILED: DiagnosticStatus.ERROR}
MAP_STATES = ('no map', 'indexing', 'ready')


def _number(value: Any, fmt: str) -> str:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return ''
    return format(value, fmt) if math.isfinite(value) else ''


def localization_status(node_name: str, fqn: str, map_state: str, loc: Any = None,
                        map_detail: str = '', frame: str = '', lifecycle: str = '',
                        mode: str = '', map_note: str = '') -> DiagnosticStatus:
    """Return the status of the last localization ``loc`` (a core Localization, or None)."""
    if map_state not in MAP_STATES:
        raise ValueError(f'map state must be one of {MAP_STATES}, got {map_state!r}')
    status = DiagnosticStatus(name=f'{node_name}: localization', hardware_id=fqn)
    if loc is None:
        status.level = DiagnosticStatus.OK if map_state == 'ready' else DiagnosticStatus.WARN
        status.message = ('ready, no localization yet' if map_state == 'ready'
                          else f'{map_state}: {map_detail}' if map_detail else map_state)
        values = {'status': 'none', 'confidence': '', 'score': '', 'latency_ms': '',
                  'node': '-1', 'candidates': '0'}
    else:
        status.level = LEVELS.get(loc.status, DiagnosticStatus.ERROR)
        pose = loc.pose if loc.pose is not None else (math.nan,) * 3
        status.message = (f'{loc.status}: x={pose[0]:.3f} y={pose[1]:.3f} yaw={pose[2]:.4f} '
                          f'confidence={float(loc.confidence):.3f}'
                          if loc.status == OK else f'{loc.status}: {loc.message}')
        values = {'status': loc.status, 'confidence': _number(loc.confidence, '.4f'),
                  'score': _number(loc.score, '.4f'),
                  'latency_ms': _number(loc.latency_ms, '.1f'), 'node': str(int(loc.node)),
                  'candidates': str(len(loc.candidates or ())),
                  'x': _number(pose[0], '.4f'), 'y': _number(pose[1], '.4f'),
                  'yaw': _number(pose[2], '.5f')}
    values.update({'map': map_state, 'map_note': map_note, 'frame': frame,
                   'lifecycle': lifecycle, 'mode': mode})
    status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    return status


def diagnostic_array(statuses: list[DiagnosticStatus], stamp: Any) -> DiagnosticArray:
    """Wrap statuses in a stamped DiagnosticArray."""
    msg = DiagnosticArray()
    msg.header.stamp = time_msg(stamp)
    msg.status = list(statuses)
    return msg
