"""
Every answer of a ``bench localize`` run, one CSV row each (``--answers CSV``).

The reliability table pools the answers by their reported confidence; this file keeps each of
them with what decided it and the evidence the confidence model weighed, so that the calibration
can be studied again (another binning, a recalibration, one building at a time) without
localizing again. Columns (:data:`COLUMNS`): the set, its split, the sensor, ``own`` or
``foreign``, the map and the place the scan comes from, the status, what decided it
(:func:`decided_by`), how many distinct poses fit about equally well (``look_alikes``, 0 unless
the rule refused the answer for them), the reported confidence, whether the pose is right
(within 0.5 m / 5 deg of the truth, whatever the status; a foreign scan never is), the position
and yaw errors, the latency, then the model's features of the answer's evidence
(``localization/confidence.py``; empty without a pose).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
import math
from pathlib import Path
import re

from ..config.confidence import CONFIDENCE_MODEL
from ..evaluation.replay import ResultRow
from ..files.writing import atomic_files
from ..localization.confidence import feature_values
from ..localization.localizer import Localization, OK
from ..transforms import Pose2

#: the columns before the features
LABELS = ('set', 'split', 'sensor', 'kind', 'map', 'source', 'status', 'decided_by',
          'look_alikes', 'confidence', 'right', 'error_xy', 'error_yaw_deg', 'latency_ms')
COLUMNS = LABELS + tuple(CONFIDENCE_MODEL.features)

_LOOK_ALIKES = re.compile(r'(\d+) distinct poses fit about equally well')


def decided_by(loc: Localization) -> tuple[str, int]:
    """
    Return what decided a global answer's status, and the look-alikes a rival refusal counted.

    ``confidence``: the model (``ok``, or refused below ``min_confidence``); ``rival``: the rule
    for distinct poses that fit about equally well (``localizer.verdict``); ``degenerate``: the
    rule for an undetermined position or a view too small; ``implausible``: the rules for too
    much seen through walls or too little explained; ``no pose``: no hypothesis survived.
    """
    if loc.pose is None:
        return 'no pose', 0
    message = loc.message
    alike = _LOOK_ALIKES.match(message)
    if alike:
        return 'rival', int(alike.group(1))
    if message.startswith('degenerate'):
        return 'degenerate', 0
    if (loc.status == OK or message.startswith('low confidence')
            or message.startswith('the best pose is more likely wrong')):
        return 'confidence', 0
    return 'implausible', 0


@dataclass
class AnswerLog:
    """The rows of a run, written by :meth:`write`."""

    rows: list[dict] = field(default_factory=list)

    def add(self, loc: Localization, truth: Pose2 | None, **labels: str) -> None:
        """
        Add one answer; ``labels``: set, split, sensor, kind, map, source.

        ``truth`` None: a foreign scan (never right) or one without ground truth.
        """
        how, alike = decided_by(loc)
        result = ResultRow.from_localization(math.nan, loc, truth)
        dx, dy, dyaw = result.errors()
        row = dict(labels, status=loc.status, decided_by=how, look_alikes=alike,
                   confidence=f'{loc.confidence:.6f}', right=int(result.correct),
                   error_xy=_num(math.hypot(dx, dy)), error_yaw_deg=_num(math.degrees(dyaw)),
                   latency_ms=f'{loc.latency_ms:.1f}')
        if loc.evidence is not None:
            values = feature_values(loc.evidence)
            row.update({name: _num(values[name]) for name in CONFIDENCE_MODEL.features})
        self.rows.append(row)

    def write(self, path: str | Path) -> Path:
        """Write the rows as CSV to ``path`` (folders made, all or nothing); return it."""
        path = Path(path)
        with atomic_files(path, what='answers file') as (tmp,), \
                open(tmp, 'w', newline='') as f:
            writer = csv.DictWriter(f, fieldnames=COLUMNS, restval='')
            writer.writeheader()
            writer.writerows(self.rows)
        return path


def _num(value: float) -> str:
    """Format a number for the CSV: six significant digits, empty when NaN."""
    return '' if math.isnan(value) else f'{value:.6g}'
