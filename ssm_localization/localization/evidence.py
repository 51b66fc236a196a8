"""
The evidence an answer rests on, in terms that mean the same in every building (beyond the paper).

A pose is trusted for what the scan and the map say about it, not for how it was found:
- how the beams agree with the map there (``verify.BeamCheck``: returns that end on the map's
  walls, in front of them -- clutter the map does not hold -- or behind them, beams with no
  return where the map has a wall within the sensor's range);
- how the endpoints lie on the wall surface: on it, in unknown cells, and how much of the scan's
  length lies in unexplained stretches longer than a metre (an unmapped *wall*, which clutter --
  people, chairs -- seldom makes);
- how well the pose is determined (its covariance), how far ahead of the best distinct rival
  place it is (the margin of their scores) and how many distinct places score nearly as well
  (a scan that fits many places tells little about any one of them);
- how much there is of it (returns among the checked beams, and the share of the scan's beams
  that returned at all: a short laser in a large hall returns few);
- for a tracked pose, how far the scan's own pose lies from the motion prediction.
``confidence.py`` turns these into a calibrated probability that the pose is right.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .refine import SurfaceModel
from .verify import BeamCheck
from ..mapping.occupancy import OccupancyMap
from ..transforms import apply, Pose2

#: an endpoint within this of the wall surface lies on it, metres
ON_WALL = 0.1
#: an endpoint further than this from the wall surface is unexplained, metres
UNEXPLAINED = 0.15
#: consecutive endpoints further apart than this do not belong to one surface, metres
LINK = 0.5
#: unexplained stretches longer than this count as unmapped structure, metres
LONG_RUN = 1.0
#: distinct rivals scoring within these of the answer's score are counted (close, near)
CLOSE_RIVAL = 0.05
NEAR_RIVAL = 0.1


@dataclass(frozen=True)
class Evidence:
    """What one pose of one scan rests on (fractions in [0, 1] unless said otherwise)."""

    hit: float               # of the returns: end on the map's wall (within the beam tolerance)
    through: float           # of the returns: end behind a wall, or where the map has none
    short: float             # of the returns: end in front of the map's wall (unmapped things)
    missing: float           # of the beams: no return where the map has a wall within range
    on_wall: float           # of the endpoints: within ON_WALL of the wall surface
    unknown: float           # of the endpoints: in unknown cells or off the map
    unexplained_runs: float  # of the scan's length: unexplained stretches over LONG_RUN
    explained: float         # mean exp(-r^2 / 2 sigma^2) over the spatially even points
    margin: float            # score minus the best distinct rival's score (no rival: 0)
    position_std: float      # metres, along the least determined direction
    yaw_std: float           # radians
    returns: int             # beams with a finite reading among those checked
    scan_length: float       # metres of surface the scan sees (gaps between linked endpoints)
    extent: float            # metres: 90th percentile of the range of its spatially even points
    close_rivals: int = 0    # distinct verified poses scoring within CLOSE_RIVAL of this one
    near_rivals: int = 0     # ... within NEAR_RIVAL
    return_fraction: float = 1.0   # of the scan's beams: a return (finite, within range)
    prior_distance: float = math.nan   # tracked poses: the scan's own pose from the motion
    #                                    prediction, in standard deviations (Mahalanobis)
    scan_position_std: float = math.nan  # the scan's own pose, before a tracker fuses in the
    #                                      prediction: metres along its least determined direction


def endpoint_evidence(surface: SurfaceModel, occ_map: OccupancyMap, laser_pose: Pose2,
                      points: np.ndarray, depth: float) -> tuple[float, float, float, float]:
    """
    Return ``(on_wall, unknown, unexplained_runs, scan_length)`` of a scan's endpoints.

    ``points`` (N, 2) every valid endpoint in the laser frame, in sweep order, placed at
    ``laser_pose``; ``depth`` the wall surface offset estimated for this pose (metres behind the
    occupied-cell boundary).
    """
    if len(points) == 0:
        return 0.0, 1.0, 0.0, 0.0
    world = apply(laser_pose, points)
    d, _, valid = surface.signed_distance(world)
    d = d - surface.depth + depth
    rows, cols = occ_map.world_to_cell(world)
    inside = occ_map.in_bounds(rows, cols)
    unknown = ~inside
    unknown[inside] = occ_map.data[rows[inside], cols[inside]] < 0
    off = ~valid | (np.abs(d) > UNEXPLAINED)
    runs, length = unexplained_runs(world, off)
    return float(np.mean(valid & (np.abs(d) < ON_WALL))), float(np.mean(unknown)), runs, length


def unexplained_runs(points: np.ndarray, off: np.ndarray, link: float = LINK,
                     long_run: float = LONG_RUN) -> tuple[float, float]:
    """
    Return ``(fraction, length)``: the scan's length and its fraction in long unexplained runs.

    ``points`` (N, 2) in sweep order, ``off`` (N,) the unexplained ones. The scan's length is the
    sum of the gaps between consecutive endpoints closer than ``link`` (one surface); a stretch
    is a chain of consecutive unexplained endpoints so linked; ``fraction`` is the length of the
    stretches longer than ``long_run`` over the scan's length.
    """
    if len(points) < 2:
        return 0.0, 0.0
    gaps = np.hypot(*np.diff(points, axis=0).T)
    linked = gaps < link
    total = float(gaps[linked].sum())
    if total <= 0.0:
        return 0.0, 0.0
    step = linked & off[1:] & off[:-1]            # a gap inside an unexplained stretch
    # stretches: maximal runs of such gaps; their lengths by cumulative sums at run boundaries
    edges = np.diff(np.concatenate(([0], step.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    cum = np.concatenate(([0.0], np.cumsum(np.where(step, gaps, 0.0))))
    lengths = cum[ends] - cum[starts]
    return float(lengths[lengths > long_run].sum() / total), total


def rival_counts(score: float, rivals) -> tuple[float, int, int]:
    """
    Return ``(margin, close, near)`` of a pose scoring ``score`` against its distinct rivals.

    ``rivals`` the scores of the distinct places verified for the same scan; ``margin`` is the
    lead over the best of them (``score`` itself when there is none), ``close`` / ``near`` how
    many score within :data:`CLOSE_RIVAL` / :data:`NEAR_RIVAL` of it.
    """
    rivals = [float(r) for r in rivals]
    margin = score - max(rivals, default=0.0)
    return (margin, sum(r >= score - CLOSE_RIVAL for r in rivals),
            sum(r >= score - NEAR_RIVAL for r in rivals))


def beam_fractions(check: BeamCheck) -> tuple[float, float, float]:
    """Return ``(hit, through, short)`` of a beam check as fractions of its returns."""
    if check.returns <= 0:
        return 0.0, 0.0, 0.0
    return (check.hits / check.returns, check.through / check.returns,
            check.shorts / check.returns)


def covariance_stds(cov: np.ndarray | None) -> tuple[float, float]:
    """Return the position std along the least determined direction and the yaw std."""
    if cov is None:
        return math.inf, math.inf
    cov = np.asarray(cov, float)
    return (float(math.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 0.0))),
            float(math.sqrt(max(cov[2, 2], 0.0))))
