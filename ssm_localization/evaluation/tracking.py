"""
Replay with tracking: scans in order through a :class:`Tracker`, scored against ground truth.

Rows are RESULTS.csv rows (``ResultRow``) with one more column, ``mode`` (tracked / relocalized
/ lost). Events:
- first fix: the scans up to and including the first ``ok`` (with ground truth: the first right
  ``ok``), counted from the first scan;
- recoveries: with known kidnaps (``kidnaps``, indices of the scans right after a jump), the scans
  from the kidnap to the first right ``ok`` inclusive, and the wrong ``ok`` answers in between;
  without, every relocalization the tracker detected (a run of scans that were not tracked,
  after a tracked one) and the scans from its start to the next ``ok`` inclusive.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
import math
from typing import Mapping, Sequence

from tqdm import tqdm

from .replay import latency_percentiles, ResultRow, status_counts, summarize, Summary
from ..io.bag_records import stamp_to_ns
from ..localization.localizer import OK
from ..localization.tracker import RELOCALIZED, Tracker, TrackResult
from ..transforms import Pose2, pose_at_time

#: odometry further than this from a scan's stamp (s) is not used (the node's ``odom_max_age``)
ODOM_MAX_AGE = 0.5


@dataclass
class TrackRow(ResultRow):
    """A RESULTS.csv row of a tracked replay: ``mode`` follows the ground-truth columns."""

    mode: str = ''

    @classmethod
    def from_track(cls, stamp: float, res: TrackResult, truth: Pose2 | None) -> 'TrackRow':
        return cls.from_localization(stamp, res, truth, mode=res.mode)


def odometry_at(stamps: Sequence[float], odom: Mapping[float, Pose2],
                max_age: float = ODOM_MAX_AGE) -> list[Pose2 | None]:
    """Return the odometry pose at each stamp (None: none close), as the node interpolates it."""
    timed = sorted({stamp_to_ns(s): p for s, p in odom.items()}.items())
    age = int(max_age * 1e9)
    return [pose_at_time(timed, stamp_to_ns(t), age) for t in stamps]


def track_scans(tracker: Tracker, scans: Sequence, odom: Sequence[Pose2 | None] | None = None,
                truth: Sequence[Pose2 | None] | None = None,
                progress: bool = True) -> list[TrackRow]:
    """Track ``scans`` (ScanRecords) in order with their odometry poses (or None)."""
    n = len(scans)
    odom = list(odom) if odom is not None else [None] * n
    truth = list(truth) if truth is not None else [None] * n
    if len(odom) != n or len(truth) != n:
        raise ValueError(f'{n} scans but {len(odom)} odometry poses and {len(truth)} truths')
    rows = []
    for scan, od, gt in tqdm(zip(scans, odom, truth), desc='track', total=n,
                             disable=not progress):
        res = tracker.track(scan, od, scan.stamp)
        rows.append(TrackRow.from_track(scan.stamp, res, gt))
    return rows


@dataclass(frozen=True)
class Recovery:
    """
    Scans from an event (start, kidnap, detected loss) to the next (right) ``ok``, inclusive.

    ``scans`` is None when none came; ``wrong_ok`` counts the confident wrong answers between.
    """

    start: int
    scans: int | None
    wrong_ok: int = 0


@dataclass(frozen=True)
class TrackSummary:
    """
    Figures of one tracked replay.

    ``summary`` holds the success figures (None without ground truth); latencies are over all
    scans, and over the tracked ones.
    """

    n: int
    ok: int
    ambiguous: int
    failed: int
    summary: Summary | None
    first_fix: Recovery
    recoveries: list[Recovery] = field(default_factory=list)
    tracked: int = 0                 # scans answered from the track
    relocalized: int = 0             # scans answered by global localization (ok)
    latency: tuple[float, float] = (math.nan, math.nan)            # p50, p95, all scans
    tracked_latency: tuple[float, float] = (math.nan, math.nan)    # p50, p95, tracked scans

    @property
    def wrong_before_fix(self) -> int:
        """Count the wrong ``ok`` answers before the first fix and before each recovery."""
        return self.first_fix.wrong_ok + sum(r.wrong_ok for r in self.recoveries)

    def format(self, title: str = '') -> str:  # noqa: A003 - as Summary.format
        head = f'{title}: ' if title else ''
        recov = _recoveries(self.recoveries)
        s = self.summary
        figures = (f'success {s.success_rate:.1%} precision {s.precision:.2%} | '
                   if s is not None else '')
        error = (f' | median xy {s.median_xy_mm:.0f} mm yaw {s.median_yaw_deg:.2f} deg'
                 if s is not None else '')
        return (f'{head}n={self.n} ok={self.ok} amb={self.ambiguous} fail={self.failed} | '
                f'{figures}first fix {_scans(self.first_fix)} | recoveries {recov} | wrong ok '
                f'before a fix {self.wrong_before_fix} | tracked {self.tracked} relocalized '
                f'{self.relocalized}{error} | latency p50 {self.latency[0]:.0f} p95 '
                f'{self.latency[1]:.0f} ms (tracked scans {self.tracked_latency[0]:.0f} / '
                f'{self.tracked_latency[1]:.0f} ms)')


def _scans(r: Recovery) -> str:
    return 'never' if r.scans is None else str(r.scans)


def _recoveries(recoveries: list[Recovery]) -> str:
    """List a few recoveries; count many of them by their number of scans."""
    if not recoveries:
        return '-'
    if len(recoveries) <= 6:
        return ', '.join(_scans(r) for r in recoveries)
    counts = Counter(_scans(r) for r in recoveries)
    return f'{len(recoveries)} (' + ', '.join(f'{k} scans: {v}' for k, v in sorted(
        counts.items())) + ')'


def recovery_after(rows: Sequence[TrackRow], start: int, use_truth: bool = True) -> Recovery:
    """Count the scans from ``start`` to the first (right, with ground truth) ``ok`` inclusive."""
    wrong = 0
    for k in range(start, len(rows)):
        r = rows[k]
        if r.status != OK:
            continue
        if not use_truth or not r.has_truth or r.correct:
            return Recovery(start, k - start + 1, wrong)
        wrong += 1
    return Recovery(start, None, wrong)


def detected_losses(rows: Sequence[TrackRow]) -> list[int]:
    """Return the indices where the tracker stopped tracking (not tracked after tracked)."""
    return [k for k in range(1, len(rows))
            if rows[k].mode != 'tracked' and rows[k - 1].mode == 'tracked']


def summarize_track(rows: Sequence[TrackRow],
                    kidnaps: Sequence[int] | None = None) -> TrackSummary:
    """
    Summarize a tracked replay: per-scan figures, first fix and recoveries (see the module doc).

    Without any ground truth there are no success figures and an ``ok`` counts as a fix.
    """
    use_truth = any(r.has_truth for r in rows)
    starts = list(kidnaps) if kidnaps is not None else detected_losses(rows)
    ok, ambiguous, failed = status_counts(rows)
    return TrackSummary(
        n=len(rows), ok=ok, ambiguous=ambiguous, failed=failed,
        summary=summarize(rows) if use_truth else None,
        first_fix=recovery_after(rows, 0, use_truth),
        recoveries=[recovery_after(rows, k, use_truth) for k in starts],
        tracked=sum(r.mode == 'tracked' for r in rows),
        relocalized=sum(r.mode == RELOCALIZED and r.status == OK for r in rows),
        latency=latency_percentiles([r.latency_ms for r in rows]),
        tracked_latency=latency_percentiles([r.latency_ms for r in rows if r.mode == 'tracked']))
