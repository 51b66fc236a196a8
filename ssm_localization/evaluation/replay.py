"""Offline replay: localize every scan of a bag on its own and score it against /ground_truth."""
from __future__ import annotations

from collections import Counter
import csv
from dataclasses import asdict, dataclass, fields
import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from tqdm import tqdm

from ..config.confidence import RIGHT_XY, RIGHT_YAW
from ..files.writing import atomic_files
from ..localization.localizer import GlobalLocalizer, Localization, OK
from ..transforms import Pose2, wrap_angle

#: success: status ok and within these bounds of the ground truth (what the confidence means
#: by "right")
SUCCESS_XY = RIGHT_XY
SUCCESS_YAW = RIGHT_YAW


def within_success(pose: Pose2 | None, truth: Pose2) -> bool:
    """Return whether ``pose`` lies within the success bounds of ``truth`` (False: None, NaN)."""
    return (pose is not None
            and math.hypot(pose[0] - truth[0], pose[1] - truth[1]) <= SUCCESS_XY
            and abs(float(wrap_angle(pose[2] - truth[2]))) <= SUCCESS_YAW)


def status_counts(rows: Sequence) -> tuple[int, int, int]:
    """Return how many ``rows`` (or results) are ``ok``, ``ambiguous`` and ``failed``."""
    counts = Counter(r.status for r in rows)
    return counts['ok'], counts['ambiguous'], counts['failed']


def latency_percentiles(values: Sequence[float]) -> tuple[float, float]:
    """Return the p50 and p95 of ``values`` (NaN for none)."""
    if not len(values):
        return math.nan, math.nan
    return float(np.percentile(values, 50)), float(np.percentile(values, 95))


@dataclass
class ResultRow:
    """One RESULTS.csv row (INTERFACES.md); ground-truth columns are NaN when there is none."""

    stamp: float
    x: float
    y: float
    yaw: float
    status: str
    latency_ms: float
    node: int
    score: float
    confidence: float = math.nan     # P(right | evidence) as the localizer reported it
    gt_x: float = math.nan
    gt_y: float = math.nan
    gt_yaw: float = math.nan

    @classmethod
    def from_localization(cls, stamp: float, loc: Localization, truth: Pose2 | None,
                          **columns) -> 'ResultRow':
        """
        Return the row of ``loc`` and its ground truth (None: unknown).

        ``loc``: a Localization or a result with the same pose, status, latency_ms, node, score
        and confidence; ``columns`` fill a subclass's further columns.
        """
        pose = loc.pose if loc.pose is not None else (math.nan, math.nan, math.nan)
        gt = truth if truth is not None else (math.nan, math.nan, math.nan)
        return cls(stamp=stamp, x=pose[0], y=pose[1], yaw=pose[2], status=loc.status,
                   latency_ms=loc.latency_ms, node=loc.node, score=loc.score,
                   confidence=float(loc.confidence),
                   gt_x=gt[0], gt_y=gt[1], gt_yaw=gt[2], **columns)

    @property
    def has_truth(self) -> bool:
        return not math.isnan(self.gt_x)

    def errors(self) -> tuple[float, float, float]:
        """|dx|, |dy| (m) and |dyaw| (rad) against the ground truth (NaN if unknown)."""
        return (abs(self.x - self.gt_x), abs(self.y - self.gt_y),
                abs(float(wrap_angle(self.yaw - self.gt_yaw))))

    @property
    def correct(self) -> bool:
        """Within the success bounds of the ground truth (whatever the status)."""
        return within_success((self.x, self.y, self.yaw), (self.gt_x, self.gt_y, self.gt_yaw))

    @property
    def right(self) -> bool:
        """Answered ``ok`` and within the success bounds of the ground truth."""
        return self.status == OK and self.has_truth and self.correct

    @property
    def wrong(self) -> bool:
        """Answered ``ok`` but outside the success bounds of the ground truth."""
        return self.status == OK and self.has_truth and not self.correct


@dataclass(frozen=True)
class Summary:
    """Figures for a set of localized scans with ground truth."""

    n: int
    ok: int
    ambiguous: int
    failed: int
    success_rate: float          # status ok and correct, over all scans
    precision: float             # correct over answered ok
    median_xy_mm: float          # Euclidean position error of the ok answers
    median_x_mm: float
    median_y_mm: float
    median_yaw_deg: float
    mean_x_mm: float
    mean_y_mm: float
    mean_yaw_deg: float
    latency_p50_ms: float
    latency_p95_ms: float

    def format(self, title: str = '') -> str:  # noqa: A003 - public name
        head = f'{title}: ' if title else ''
        return (f'{head}n={self.n} ok={self.ok} ambiguous={self.ambiguous} failed={self.failed} | '
                f'success {self.success_rate:.1%} precision {self.precision:.1%} | median error '
                f'{self.median_x_mm:.1f} / {self.median_y_mm:.1f} mm, '
                f'{self.median_yaw_deg:.2f} deg (xy {self.median_xy_mm:.1f} mm) | mean '
                f'{self.mean_x_mm:.1f} / {self.mean_y_mm:.1f} mm, '
                f'{self.mean_yaw_deg:.2f} deg | latency p50 {self.latency_p50_ms:.0f} ms '
                f'p95 {self.latency_p95_ms:.0f} ms')


def summarize(rows: Sequence[ResultRow]) -> Summary:
    """Success rate, precision, error and latency figures (rows without truth are skipped)."""
    rows = [r for r in rows if r.has_truth]
    if not rows:
        raise ValueError('no scan with ground truth to score')
    ok = [r for r in rows if r.status == OK]
    correct = [r for r in ok if r.correct]
    err = np.array([r.errors() for r in ok]) if ok else np.full((1, 3), np.nan)
    _, ambiguous, failed = status_counts(rows)
    p50, p95 = latency_percentiles([r.latency_ms for r in rows])
    nan_med = (lambda a: float(np.median(a))) if ok else (lambda a: math.nan)
    nan_mean = (lambda a: float(np.mean(a))) if ok else (lambda a: math.nan)
    return Summary(
        n=len(rows), ok=len(ok), ambiguous=ambiguous, failed=failed,
        success_rate=len(correct) / len(rows),
        precision=len(correct) / len(ok) if ok else math.nan,
        median_xy_mm=nan_med(np.hypot(err[:, 0], err[:, 1])) * 1e3,
        median_x_mm=nan_med(err[:, 0]) * 1e3, median_y_mm=nan_med(err[:, 1]) * 1e3,
        median_yaw_deg=math.degrees(nan_med(err[:, 2])),
        mean_x_mm=nan_mean(err[:, 0]) * 1e3, mean_y_mm=nan_mean(err[:, 1]) * 1e3,
        mean_yaw_deg=math.degrees(nan_mean(err[:, 2])),
        latency_p50_ms=p50, latency_p95_ms=p95)


def write_results_csv(rows: Iterable[ResultRow], path: str | Path) -> None:
    """
    Write RESULTS.csv: the INTERFACES.md columns first, ground truth after (atomically).

    Rows of a ``ResultRow`` subclass add its further columns.
    """
    rows = list(rows)
    names = [f.name for f in fields(type(rows[0]) if rows else ResultRow)]
    with atomic_files(path, what='results file') as (tmp,), open(tmp, 'w', newline='') as fh:
        w = csv.DictWriter(fh, fieldnames=names)
        w.writeheader()
        for r in rows:
            d = asdict(r)
            w.writerow({k: ('' if isinstance(v, float) and math.isnan(v) and k in ('x', 'y', 'yaw')
                            else v) for k, v in d.items()})


def match_truth(stamps: np.ndarray, truth: dict[float, Pose2],
                tol: float = 1e-3) -> list[Pose2 | None]:
    """Return each scan's ground-truth pose (same stamp within ``tol`` s), else None."""
    if not truth:
        return [None] * len(stamps)
    keys = np.array(sorted(truth))
    out: list[Pose2 | None] = []
    for s in stamps:
        i = int(np.clip(np.searchsorted(keys, s), 1, len(keys) - 1)) if len(keys) > 1 else 0
        j = min((i - 1, i) if len(keys) > 1 else (0,), key=lambda k: abs(keys[k] - s))
        out.append(truth[float(keys[j])] if abs(keys[j] - s) <= tol else None)
    return out


def replay_scans(localizer: GlobalLocalizer, scans: Sequence,
                 truth: dict[float, Pose2] | None = None,
                 progress: bool = True) -> list[ResultRow]:
    """Localize each ScanRecord on its own (no tracking, no odometry)."""
    truths = match_truth(np.array([s.stamp for s in scans]), truth or {})
    rows = []
    for scan, gt in tqdm(zip(scans, truths), desc='replay', total=len(scans),
                         disable=not progress):
        loc = localizer.localize_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                      scan.range_min, scan.range_max)
        rows.append(ResultRow.from_localization(scan.stamp, loc, gt))
    return rows
