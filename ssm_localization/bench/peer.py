"""
The reference peer of ``bench localize --peer``: exhaustive correlative search.

What Cartographer does to relocalize, written with the same numpy building blocks as the package
(``localization/correlative.py``): every yaw of a full turn at 1 degree, every free cell, by branch
and bound; the best leaf is refined on the wall surface (the same Gauss-Newton as the localizer, so
accuracies compare); the answer is ``ambiguous`` when a distinct leaf scores within
``rival_ratio`` of the best, ``failed`` when no leaf reaches ``min_score``. It shares nothing else
with the localizer: no descriptors, no voting, no spectral matching.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import time

import numpy as np

from ..localization.correlative import CorrelativeGrid
from ..localization.localizer import distinct, GlobalLocalizer, Hypothesis, Localization
from ..localization.refine import refine_poses, SurfaceModel
from ..mapping.index import MapIndex
from ..matching.scan import downsample_even, ranges_to_points


@dataclass(frozen=True)
class PeerConfig:
    """Settings of the exhaustive search (chosen on ACES like the localizer's)."""

    points: int = 100                       # spatially even scan points scored
    angular_step: float = math.radians(1.0)
    depth: int = 5
    sigma: float = 0.1
    max_range: float = 30.0
    min_score: float = 0.5
    rival_ratio: float = 0.98               # a distinct leaf within this ratio: ambiguous
    distinct_xy: float = 0.5
    distinct_yaw: float = math.radians(10.0)
    surface_depth: float = 0.5              # of the refinement's wall surface (cells)


class ExhaustiveLocalizer:
    """
    ``localize_scan`` with the localizer's signature, by exhaustive search.

    ``ours``: a GlobalLocalizer on the same index whose correlative grid and wall surface are
    reused where their parameters are the peer's (they are the same precomputed tables).
    """

    def __init__(self, index: MapIndex, config: PeerConfig | None = None,
                 ours: GlobalLocalizer | None = None) -> None:
        self.config = cfg = config or PeerConfig()
        m = index.map
        lc = ours.config if ours is not None and ours.index is index else None
        if lc is not None and (lc.search_sigma, lc.search_depth, lc.max_cast_range,
                               ours.grid.resolution) == (cfg.sigma, cfg.depth, cfg.max_range,
                                                         m.resolution):
            self.grid = ours.grid
        else:
            self.grid = CorrelativeGrid(m, occupied_thresh=index.config.occupied_thresh,
                                        sigma=cfg.sigma, depth=cfg.depth,
                                        max_range=cfg.max_range)
        if lc is not None and lc.surface_depth == cfg.surface_depth:
            self.surface = ours.surface
        else:
            occupied = m.occupied_mask(index.config.occupied_thresh)
            self.surface = SurfaceModel.from_occupancy(occupied, m.resolution, m.origin,
                                                       cfg.surface_depth)

    def localize_scan(self, ranges, angle_min: float, angle_increment: float,
                      range_min: float = 0.0, range_max: float = float('inf')) -> Localization:
        cfg = self.config
        t0 = time.perf_counter()
        try:
            pts, _ = ranges_to_points(np.asarray(ranges, float), angle_min, angle_increment,
                                      range_min, range_max)
        except ValueError as exc:
            return Localization(status='failed', pose=None, message=f'bad scan: {exc}')
        even = pts[downsample_even(pts, cfg.points, 0.05)]
        found = self.grid.search(even, angular_step=cfg.angular_step, min_score=cfg.min_score,
                                 ratio=cfg.rival_ratio)
        if not len(found.poses):
            return Localization(status='failed', pose=None,
                                latency_ms=(time.perf_counter() - t0) * 1e3,
                                message=f'no pose scores {cfg.min_score} or more')
        best = tuple(float(v) for v in found.poses[0])
        rivals = [p for p in found.poses[1:]
                  if distinct(tuple(p), best, cfg.distinct_xy, cfg.distinct_yaw)]
        r = refine_poses(self.surface, pts, np.array([best]), estimate_depth=True,
                         depth_prior=0.1)[0]
        hyp = Hypothesis(source='search', initial_pose=best, laser_pose=r.pose, pose=r.pose,
                         correlative=found.best_score, explained=r.explained, refined=True,
                         score=found.best_score)
        status = 'ambiguous' if rivals else 'ok'
        return Localization(status=status, pose=r.pose, covariance=r.covariance,
                            score=found.best_score, candidates=[hyp],
                            latency_ms=(time.perf_counter() - t0) * 1e3,
                            message=f'{len(rivals)} distinct rivals within {cfg.rival_ratio}')
