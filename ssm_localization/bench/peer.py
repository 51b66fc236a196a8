"""
The reference peers of ``bench localize --peer``: exhaustive correlative search.

:class:`ExhaustiveLocalizer` is what Cartographer does to relocalize, written with the same numpy
building blocks as the package (``localization/correlative.py``): every yaw of a full turn at 1
degree, every free cell, by branch and bound; the best leaf is refined on the wall surface (the
same Gauss-Newton as the localizer, so accuracies compare); the answer is ``ambiguous`` when a
distinct leaf scores within ``rival_ratio`` of the best, ``failed`` when no leaf reaches
``min_score``. It shares nothing else with the localizer: no descriptors, no voting, no spectral
matching, and no negative control in its verdict (it says ``ok`` to a fifth of the scans of other
buildings).

:class:`FullSearchLocalizer` is the package's own localizer with that exhaustive search in place of
its restricted one (the hypotheses' yaws and the map-aligned yaws, within a time budget): the same
votes, refinement, ray casting and verdict. Against the package on the same queries it measures
what the restricted search loses in places found, the verdict being the same.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import math
import time

import numpy as np

from ..localization.correlative import CorrelativeGrid
from ..localization.localizer import distinct, GlobalLocalizer, Hypothesis, Localization, Query
from ..localization.refine import refine_poses, SurfaceModel
from ..localization.regions import SearchPlan
from ..mapping.index import MapIndex
from ..matching.scan import downsample_even, ranges_to_points
from ..transforms import Pose2


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


class FullSearchLocalizer(GlobalLocalizer):
    """
    The package's localizer searching every yaw over the whole map, with no time budget.

    Built beside ``ours`` on the same map layers (nothing is built again). Its correlative
    search covers a full turn every ``angular_step`` in every region, its time budget is
    ``budget_s`` (a bound for a runaway search, not a limit any search here reaches), and there
    is no second look (``search_more_alignments`` 0: a search at further yaws would find
    nothing new). Everything else is the package's: the pose votes' hypotheses, which leaves go
    on (``search_keep``, ``search_rivals``), the refinement, the ray casting and the verdict with
    its calibrated confidence.
    """

    def __init__(self, ours: GlobalLocalizer, angular_step: float = math.radians(1.0),
                 budget_s: float = 60.0) -> None:
        # not GlobalLocalizer.__init__: the map layers of `ours` are shared, not built again
        self.__dict__.update(ours.__dict__)
        self.config = dataclasses.replace(ours.config, search_budget=budget_s,
                                          search_more_alignments=0)
        n = max(int(round(2.0 * math.pi / angular_step)), 1)
        self._full_turn = 2.0 * math.pi * np.arange(n) / n

    def search_plan(self, query: Query, seeds: list[Pose2]) -> SearchPlan:
        """Return every yaw of the full turn in every region."""
        allowed = np.ones((len(self._full_turn), self.regions.count), bool)
        return SearchPlan(self._full_turn, allowed, self.regions.labels)
