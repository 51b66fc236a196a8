"""CARMEN laser logs (Radish / Freiburg "corrected" logs): parsing.

``FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta timestamp hostname logger_timestamp``.
The ``x y theta`` of a FLASER line is the SLAM-corrected *laser* pose: used as ground truth.
Scanners sweep right to left over 180 degrees: reading ``i`` is at ``-pi/2 + i * pi / n``.
"""
from __future__ import annotations

import gzip
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: no-return readings of the shared logs (the sensor maximum), by file-name prefix
NO_RETURN = {'intel': 81.83, 'aces': 50.0, 'freiburg-079': 81.91}


@dataclass(frozen=True)
class CarmenLog:
    """The FLASER scans of one log, in file order."""

    ranges: np.ndarray        # (S, n) metres; no-return readings replaced by +inf
    poses: np.ndarray         # (S, 3) corrected laser pose (x, y, theta) in the log's world frame
    stamps: np.ndarray        # (S,) seconds (as logged; may jump backwards)
    angle_min: float
    angle_increment: float
    max_range: float          # the no-return value of this log
    name: str

    def __len__(self) -> int:
        return len(self.ranges)

    def beam_angles(self) -> np.ndarray:
        n = self.ranges.shape[1]
        return self.angle_min + self.angle_increment * np.arange(n)

    def points(self, k: int) -> np.ndarray:
        """Scan ``k`` as (N, 2) points in its laser frame, scan order, no-returns dropped."""
        r = self.ranges[k]
        a = self.beam_angles()
        ok = np.isfinite(r) & (r > 0.0)
        return np.column_stack((r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])))


def _no_return_for(path: Path, ranges: np.ndarray) -> float:
    for prefix, value in NO_RETURN.items():
        if path.name.startswith(prefix):
            return value
    return float(np.max(ranges)) if ranges.size else np.inf


def read_carmen_log(path: str | Path, max_range: float | None = None) -> CarmenLog:
    """Parse the FLASER lines of a (optionally gzipped) CARMEN log.

    Readings ``>= max_range`` (default: the log's known no-return value) become ``+inf``.
    Raises ``ValueError`` naming the file and line for malformed lines.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f'CARMEN log not found: {path}')
    opener = gzip.open if path.suffix == '.gz' else open
    rows, poses, stamps = [], [], []
    n_beams = None
    with opener(path, 'rt') as fh:
        for lineno, line in enumerate(fh, 1):
            if not line.startswith('FLASER'):
                continue
            tok = line.split()
            try:
                n = int(tok[1])
                vals = np.asarray(tok[2:2 + n], dtype=float)
                x, y, th = (float(v) for v in tok[2 + n:5 + n])
                stamp = float(tok[8 + n])
            except (IndexError, ValueError) as exc:
                raise ValueError(f'{path}:{lineno}: malformed FLASER line ({exc})') from None
            if len(vals) != n or (n_beams is not None and n != n_beams):
                raise ValueError(f'{path}:{lineno}: expected {n_beams or n} readings, got {len(vals)}')
            n_beams = n
            rows.append(vals)
            poses.append((x, y, th))
            stamps.append(stamp)
    if not rows:
        raise ValueError(f'{path}: no FLASER lines')
    ranges = np.vstack(rows)
    limit = _no_return_for(path, ranges) if max_range is None else float(max_range)
    ranges = np.where(ranges >= limit - 1e-6, np.inf, ranges)
    n = ranges.shape[1]
    return CarmenLog(ranges=ranges, poses=np.asarray(poses), stamps=np.asarray(stamps),
                     angle_min=-np.pi / 2.0, angle_increment=np.pi / n, max_range=limit,
                     name=path.name.split('-corrected')[0].split('.')[0])
