"""
Scan sequences with odometry for tracking benchmarks and bags (the kidnap protocol).

- the real query sequence of a CARMEN log: its odd-numbered scans in order (1-2 m apart on Intel
  and ACES), the ground truth their corrected poses, the odometry the raw one rebuilt from the
  ODOM lines, expressed in an arbitrary odom frame (a rigid offset from the map frame, as a
  robot's odometry is);
- kidnap sequences spliced from it: ``segments`` pieces of ``n / 5`` consecutive scans taken at
  ``0, 2n/5, 4n/5`` (by default), the odometry continuing across each jump as a small forward
  step, so odometry does not reveal the kidnap while the ground truth jumps;
- single kidnaps (:func:`splice_kidnaps`): five scans before a jump, four after.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .bag_records import ScanRecord
from .carmen import CarmenLog, log_scan_records
from .sensors import SensorLimits
from ..transforms import compose, inverse, Pose2

#: where the odometry frame's origin lies in the map frame (any rigid offset will do)
ODOM_OFFSET: Pose2 = (-13.7, 4.2, 2.1)
#: the odometry increment across a kidnap: a small step forward
KIDNAP_STEP: Pose2 = (0.1, 0.0, 0.0)
#: scans tracked around a single kidnap: up to the scan before it (inclusive), from the one after
KIDNAP_BEFORE = 5
KIDNAP_AFTER = 4


@dataclass(frozen=True)
class ScanSequence:
    """
    Scans in order with their odometry and ground truth.

    ``odom``: the base in the odom frame, ``truth``: the base in the map frame; ``kidnaps``: the
    indices of the scans right after a jump of the ground truth that the odometry does not show.
    """

    name: str
    scans: list[ScanRecord]
    odom: list[Pose2]
    truth: list[Pose2]
    kidnaps: list[int] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.scans)

    def restamped(self, start: float, period: float) -> 'ScanSequence':
        """
        Return the sequence with its scans stamped ``start + k * period``.

        A bag's stamps must increase; spliced segments may go back in time.
        """
        scans = [dataclasses.replace(s, stamp=start + k * period)
                 for k, s in enumerate(self.scans)]
        return dataclasses.replace(self, scans=scans)

    def limited(self, max_range: float) -> 'ScanSequence':
        """
        Return the sequence with every reading beyond ``max_range`` made a no-return (``inf``).

        A shorter laser (``range_max`` says so, as its driver would): in long corridors a scan
        no longer sees the far walls that place it.
        """
        limits = SensorLimits(f'{max_range:g}m', max_range=max_range)
        return dataclasses.replace(self, scans=[limits.apply(s) for s in self.scans],
                                   name=f'{self.name}_{max_range:g}m')

    def by_stamp(self) -> tuple[dict[float, Pose2], dict[float, Pose2]]:
        """Return ``(odom, ground truth)`` keyed by scan stamp, as a bag holds them."""
        stamps = [s.stamp for s in self.scans]
        return dict(zip(stamps, self.odom)), dict(zip(stamps, self.truth))


def log_sequence(log: CarmenLog, indices: Sequence[int] | None = None,
                 odom_offset: Pose2 = ODOM_OFFSET, name: str | None = None) -> ScanSequence:
    """Return the scans ``indices`` of ``log`` (default: the odd ones) with odometry and truth."""
    if log.odometry is None:
        raise ValueError(f'{log.name}: the log has no ODOM lines to rebuild odometry from')
    idx = np.arange(1, len(log), 2) if indices is None else np.asarray(indices, dtype=int)
    if idx.size == 0:
        raise ValueError(f'{log.name}: no scans selected')
    first = tuple(log.odometry[idx[0]])
    odom = [compose(odom_offset, compose(inverse(first), tuple(log.odometry[k]))) for k in idx]
    return ScanSequence(name=name or log.name, scans=log_scan_records(log, idx), odom=odom,
                        truth=[tuple(float(v) for v in log.poses[k]) for k in idx])


def kidnap_sequence(seq: ScanSequence, starts: Sequence[float] = (0.0, 0.4, 0.8),
                    length: float = 0.2, step: Pose2 = KIDNAP_STEP) -> ScanSequence:
    """
    Splice segments of ``seq`` into a kidnap sequence (the benchmark protocol).

    The segments are ``length * n`` consecutive scans starting at ``starts * n``; see
    :func:`splice`.
    """
    n = len(seq)
    size = int(n * length)
    if size < 1:
        raise ValueError(f'{seq.name}: {n} scans are too few for segments of {length:.0%}')
    segments = [(int(n * s), int(n * s) + size) for s in starts]
    if any(b0 > a1 for (_, b0), (a1, _) in zip(segments, segments[1:])):
        raise ValueError(f'{seq.name}: segments at {list(starts)} of {length:.0%} overlap')
    return splice(seq, segments, step, name=f'{seq.name}_kidnap')


def splice(seq: ScanSequence, segments: Sequence[tuple[int, int]],
           step: Pose2 = KIDNAP_STEP, name: str | None = None) -> ScanSequence:
    """
    Join the scan ranges ``[a, b)`` of ``seq``, kidnapping the robot at each join.

    The odometry goes on across each join by ``step`` (and as logged within a segment), the
    ground truth jumps. Segments may come in any order (the scans keep their stamps).
    """
    if not segments or any(not 0 <= a < b <= len(seq) for a, b in segments):
        raise ValueError(f'{seq.name}: segments {list(segments)} are empty or run past the '
                         f'{len(seq)} scans')
    scans, odom, truth, kidnaps = [], [], [], []
    for a, b in segments:
        for k in range(a, b):
            if not odom:
                odom.append(seq.odom[k])
            else:
                if k == a:
                    kidnaps.append(len(scans))
                inc = step if k == a else compose(inverse(seq.odom[k - 1]), seq.odom[k])
                odom.append(compose(odom[-1], inc))
            scans.append(seq.scans[k])
            truth.append(seq.truth[k])
    return ScanSequence(name=name or f'{seq.name}_spliced', scans=scans, odom=odom, truth=truth,
                        kidnaps=kidnaps)


def splice_kidnaps(seq: ScanSequence, kidnaps: Sequence[tuple[int, int]],
                   name: str | None = None) -> ScanSequence:
    """
    Splice single kidnaps of ``seq``: for each ``(before, after)`` pair of scan indices.

    ``KIDNAP_BEFORE`` scans up to ``before`` inclusive, then ``KIDNAP_AFTER`` from ``after``
    (:func:`splice`: the odometry steps by ``KIDNAP_STEP`` across each join).
    """
    segments = []
    for before, after in kidnaps:
        segments += [(before - KIDNAP_BEFORE + 1, before + 1), (after, after + KIDNAP_AFTER)]
    return splice(seq, segments, name=name)
