"""Global localization of one laser scan on an indexed map (paper section IV, and beyond).

Pipeline for one query scan (laser frame points ``q``):
1. prefilter (beyond the paper): every query descriptor votes for the ``vote_neighbours`` nodes
   holding its nearest descriptors (one distance matrix against all node descriptors, stacked at
   start-up); the ``prefilter`` most voted nodes go on;
2. coarse (IV.A): rank those nodes by the spectral matching score (eq. 5 at the binarized
   solution of eq. 6); keep the top ``top_n``;
3. fine (IV.B): RANSAC pose of the query against each candidate's virtual scan, vicinity score
   (eq. 10, ``sigma_d``); the node frame turns the local pose into a map-frame laser pose;
4. beyond the paper: each hypothesis is refined on the map's wall surface (``refine.py``) and
   verified by ray casting (``verify.py``); the status is ``ok`` / ``ambiguous`` / ``failed``.
With ``paper_mode=True`` steps 1 and 4 and the matcher's ICP are skipped and the largest
vicinity score wins: the plain method of the paper (``bench localize --paper`` compares both).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..config.localization import LocalizerConfig
from ..mapping.index import MapIndex
from ..mapping.raycast import RayCaster
from ..matching.descriptors import descriptor_distances
from ..matching.features import prepare_scan
from ..matching.matcher import match_features, spectral_score, spectral_solution
from ..matching.scan import ranges_to_points
from ..transforms import Pose2, apply, compose, inverse, wrap_angle
from .refine import SurfaceModel, refine_poses
from .verify import BeamCheck, check_beams

STATUSES = ('ok', 'ambiguous', 'failed')


@dataclass
class Hypothesis:
    """One candidate pose: a node, its scores and the resulting laser pose in the map frame."""

    node: int
    spectral: float
    solution: tuple | None = field(default=None, repr=False)   # eqs. (2)-(6), reused by fine
    vicinity: float = 0.0
    laser_pose: Pose2 = (0.0, 0.0, 0.0)
    pose: Pose2 = (0.0, 0.0, 0.0)           # base pose in the map frame
    covariance: np.ndarray | None = None
    check: BeamCheck | None = None
    cost: float = float('inf')              # mean truncated squared surface residual (m^2)
    fit: float = float('inf')               # cost normalized, plus the through-wall penalty

    @property
    def score(self) -> float:
        """Beam agreement with the map once verified, else the vicinity score of eq. (10)."""
        return self.check.score if self.check is not None else self.vicinity

    def plausible(self, cfg: LocalizerConfig) -> bool:
        return (self.check is not None and self.check.consistent >= cfg.min_consistent
                and self.check.contradicting <= cfg.max_contradicting)


@dataclass
class Localization:
    """The answer for one scan. ``pose`` is the robot base in the map frame."""

    status: str
    pose: Pose2 | None
    covariance: np.ndarray = field(default_factory=lambda: np.diag([1e3, 1e3, 1e3]))
    node: int = -1
    score: float = float('nan')
    candidates: list[Hypothesis] = field(default_factory=list)
    latency_ms: float = 0.0
    message: str = ''

    @property
    def ok(self) -> bool:
        return self.status == 'ok'


def vicinity_score(node_points: np.ndarray, query_points: np.ndarray, pose: Pose2,
                   sigma_d: float, tree: cKDTree | None = None) -> float:
    """Eq. (10): ``sum_i 4.5 - d_i^2 / (2 sigma_d^2)`` over pairs closer than ``3 sigma_d``.

    Pairs are each query point (moved into the node frame by ``pose``) and its nearest node point.
    """
    if len(node_points) == 0 or len(query_points) == 0:
        return 0.0
    tree = tree if tree is not None else cKDTree(node_points)
    d, _ = tree.query(apply(pose, query_points), distance_upper_bound=3.0 * sigma_d)
    d = d[np.isfinite(d)]
    return float(np.sum(4.5 - d ** 2 / (2.0 * sigma_d ** 2)))


def _same(a: Pose2, b: Pose2, xy: float = 0.05, yaw: float = np.deg2rad(2.0)) -> bool:
    return np.hypot(a[0] - b[0], a[1] - b[1]) < xy and abs(wrap_angle(a[2] - b[2])) < yaw


def _distinct(a: Pose2, b: Pose2, cfg: LocalizerConfig) -> bool:
    return (np.hypot(a[0] - b[0], a[1] - b[1]) > cfg.distinct_xy
            or abs(wrap_angle(a[2] - b[2])) > cfg.distinct_yaw)


class GlobalLocalizer:
    """Single-scan global localization against a :class:`MapIndex`.

    Everything that depends on the map only (node KD-trees, the stacked node descriptors, the
    ray caster, the wall surface model) is built here once; ``localize_*`` does per-scan work.
    """

    def __init__(self, index: MapIndex, config: LocalizerConfig | None = None):
        self.index = index
        self.config = config or LocalizerConfig()
        self.matcher_config = index.config.matcher
        cfg = self.config
        if cfg.paper_mode:   # section II.C as written: RANSAC + least squares, nothing more
            self.fine_config = dataclasses.replace(self.matcher_config, icp=False, polish=False,
                                                   retries=0, ransac_hypotheses=1)
        else:
            self.fine_config = dataclasses.replace(
                self.matcher_config, icp=cfg.fine_icp, icp_iterations=cfg.fine_icp_iterations,
                polish=cfg.fine_icp and cfg.fine_polish, retries=cfg.fine_retries,
                ransac_hypotheses=cfg.fine_ransac_hypotheses)
        if len(index.features) == 0:
            raise ValueError('the map index has no nodes: nothing to localize against')
        self._node_trees = [cKDTree(f.points) if len(f.points) else None for f in index.features]
        desc = [f.descriptors for f in index.features]
        self._desc_count = np.array([len(d) for d in desc])
        self._desc_stack = (np.concatenate(desc) if self._desc_count.sum()
                            else np.zeros((0, 1), np.float32))
        self._desc_starts = np.minimum(np.concatenate(([0], np.cumsum(self._desc_count)[:-1])),
                                       max(len(self._desc_stack) - 1, 0))
        m = index.map
        self._occupied = m.occupied_mask(index.config.occupied_thresh)
        self._caster = RayCaster(self._occupied, m.resolution, m.origin)
        self._surface = SurfaceModel.from_occupancy(self._occupied, m.resolution, m.origin,
                                                    self.config.surface_depth)

    # -- entry points -----------------------------------------------------------------------
    def localize_scan(self, ranges, angle_min: float, angle_increment: float,
                      range_min: float = 0.0, range_max: float = float('inf')) -> Localization:
        """Localize a LaserScan given by its ranges and beam geometry."""
        t0 = time.perf_counter()
        try:
            ranges = np.asarray(ranges, dtype=float).ravel()
            points, idx = ranges_to_points(ranges, angle_min, angle_increment, range_min, range_max)
        except ValueError as exc:
            return self._failed(t0, f'bad scan: {exc}')
        angles = angle_min + angle_increment * np.arange(len(ranges))
        beams = np.where((ranges >= range_min) & (ranges <= range_max), ranges, np.inf)
        beams[np.isnan(ranges)] = np.nan
        keep = ~np.isnan(beams)
        return self._localize(points, angles[keep], beams[keep], t0)

    def localize_points(self, points_xy: np.ndarray) -> Localization:
        """Localize laser-frame points given in scan order (no no-return information)."""
        t0 = time.perf_counter()
        try:
            pts = np.asarray(points_xy, dtype=float)
            if pts.ndim != 2 or pts.shape[1] != 2:
                raise ValueError(f'expected (N, 2) points, got shape {pts.shape}')
        except (TypeError, ValueError) as exc:
            return self._failed(t0, f'bad points: {exc}')
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        return self._localize(pts, np.arctan2(pts[:, 1], pts[:, 0]), np.hypot(pts[:, 0], pts[:, 1]), t0)

    # -- stages -----------------------------------------------------------------------------
    def _failed(self, t0: float, message: str, candidates=None) -> Localization:
        return Localization(status='failed', pose=None, candidates=candidates or [],
                            latency_ms=(time.perf_counter() - t0) * 1e3, message=message)

    def prefilter(self, query) -> np.ndarray:
        """Nodes ordered by descriptor votes (each query point votes once per node)."""
        n_nodes = len(self.index.features)
        cfg = self.config
        if (cfg.paper_mode or cfg.prefilter <= 0 or cfg.prefilter >= n_nodes
                or len(self._desc_stack) == 0 or len(query.descriptors) == 0):
            return np.arange(n_nodes)
        # squared distance of every query descriptor to its nearest descriptor of every node
        d2 = descriptor_distances(self._desc_stack, query.descriptors)          # (Q, total)
        per_node = np.minimum.reduceat(d2, self._desc_starts, axis=1)           # (Q, nodes)
        per_node[:, self._desc_count == 0] = np.inf
        # each query point votes for its ``vote_neighbours`` best nodes
        k = min(cfg.vote_neighbours, n_nodes)
        best = np.argpartition(per_node, k - 1, axis=1)[:, :k]
        votes = np.bincount(best.ravel(), minlength=n_nodes)
        return np.argsort(-votes, kind='stable')[:cfg.prefilter]

    def coarse(self, query, nodes: np.ndarray) -> list[Hypothesis]:
        """Eq. (5)-(6) score of every node in ``nodes``; the ``top_n`` best (section IV.A)."""
        scored = []
        for k in nodes:
            sol = spectral_solution(self.index.features[k], query, self.matcher_config)
            s, _ = spectral_score(self.index.features[k], query, self.matcher_config, sol)
            scored.append(Hypothesis(node=int(k), spectral=float(s), solution=sol))
        scored.sort(key=lambda h: -h.spectral)
        return scored[:self.config.top_n]

    def fine(self, query, hyps: list[Hypothesis]) -> list[Hypothesis]:
        """RANSAC pose per candidate and the vicinity score of eq. (10) (section IV.B)."""
        base_from_laser = inverse(self.config.laser_pose)
        out = []
        for h in hyps:
            feats = self.index.features[h.node]
            m = match_features(feats, query, self.fine_config, h.solution)
            h.solution = None
            if not m.ok:
                continue
            h.vicinity = vicinity_score(feats.points, query.points, m.pose, self.config.sigma_d,
                                        self._node_trees[h.node])
            h.laser_pose = compose(tuple(self.index.node_sensor_pose[h.node]), m.pose)
            h.pose = compose(h.laser_pose, base_from_laser)
            out.append(h)
        return out

    def _refine_unique(self, hyps: list[Hypothesis], points: np.ndarray) -> list[Hypothesis]:
        """Refine each distinct pose once on the wall surface (batched); drop duplicates."""
        cfg = self.config
        todo: list[Hypothesis] = []
        for h in sorted(hyps, key=lambda h: -h.spectral):
            if not any(_same(h.laser_pose, o.laser_pose) for o in todo):
                todo.append(h)
        if not todo:
            return []
        results = refine_poses(self._surface, points, np.array([h.laser_pose for h in todo]),
                               iterations=cfg.refine_iterations if cfg.refine else 0,
                               truncate=cfg.refine_radius, inlier_distance=cfg.inlier_distance)
        base_from_laser = inverse(cfg.laser_pose)
        out: list[Hypothesis] = []
        for h, r in zip(todo, results):
            h.laser_pose, h.cost = r.pose, r.cost
            h.covariance = self._base_covariance(r.covariance, h.laser_pose)
            h.pose = compose(h.laser_pose, base_from_laser)
            if not any(_same(h.laser_pose, o.laser_pose) for o in out):
                out.append(h)
        return out

    def beam_check(self, hyps: list[Hypothesis], angles: np.ndarray, beams: np.ndarray) -> None:
        """Ray-cast the query's beams from every hypothesis at once; compare with the scan."""
        if not hyps:
            return
        cfg = self.config
        expected = self._caster.cast(np.array([h.laser_pose for h in hyps]), angles,
                                     cfg.max_cast_range)
        measured = np.where(beams > cfg.max_cast_range, np.inf, beams)
        for h, e in zip(hyps, expected):
            h.check = check_beams(measured, e, tol=cfg.beam_tolerance)
            h.fit = (h.cost / cfg.inlier_distance ** 2
                     + cfg.contradiction_weight * h.check.contradicting)

    @staticmethod
    def _position_std(h: Hypothesis) -> float:
        """Standard deviation (m) of the position along its least constrained direction."""
        if h.covariance is None:
            return float('inf')
        return float(np.sqrt(max(np.linalg.eigvalsh(h.covariance[:2, :2]).max(), 0.0)))

    def _base_covariance(self, cov_laser: np.ndarray, laser_pose: Pose2) -> np.ndarray:
        """Propagate the laser-pose covariance to the base pose (first order)."""
        lx, ly, _ = inverse(self.config.laser_pose)
        off = apply((0.0, 0.0, laser_pose[2]), (lx, ly))[0]      # laser -> base, in the map
        jac = np.array([[1.0, 0.0, -off[1]], [0.0, 1.0, off[0]], [0.0, 0.0, 1.0]])
        return jac @ cov_laser @ jac.T

    def _localize(self, points: np.ndarray, angles: np.ndarray, beams: np.ndarray,
                  t0: float) -> Localization:
        cfg = self.config
        if len(points) < cfg.min_points:
            return self._failed(t0, f'too few valid points ({len(points)} < {cfg.min_points})')
        try:
            query = prepare_scan(points, self.matcher_config)
        except ValueError as exc:
            return self._failed(t0, f'bad scan: {exc}')
        hyps = self.fine(query, self.coarse(query, self.prefilter(query)))
        if not hyps:
            return self._failed(t0, 'no candidate node gave a consistent match')
        if cfg.paper_mode:
            best = max(hyps, key=lambda h: h.vicinity)
            return Localization(status='ok', pose=best.pose, node=best.node, score=best.vicinity,
                                candidates=hyps, latency_ms=(time.perf_counter() - t0) * 1e3,
                                message='paper mode: largest vicinity score')
        hyps = self._refine_unique(hyps, points)
        self.beam_check(hyps, angles, beams)
        hyps.sort(key=lambda h: (not h.plausible(cfg), h.fit))
        best = hyps[0]
        ms = (time.perf_counter() - t0) * 1e3
        if not best.plausible(cfg):      # the best-fitting pose is kept only for diagnosis
            return Localization(status='failed', pose=best.pose, node=best.node,
                                score=best.score, candidates=hyps, latency_ms=ms,
                                message=(f'no hypothesis agrees with the map (best fit: agree '
                                         f'{best.check.consistent:.0%}, through walls '
                                         f'{best.check.contradicting:.0%})'))
        if best.fit > cfg.max_fit:
            return Localization(status='failed', pose=best.pose, node=best.node,
                                score=best.score, candidates=hyps, latency_ms=ms,
                                message=(f'the best pose explains too little of the scan (fit '
                                         f'{best.fit:.2f} > {cfg.max_fit})'))
        rivals = [h for h in hyps[1:] if h.plausible(cfg) and _distinct(h.pose, best.pose, cfg)
                  and h.fit <= best.fit * cfg.ambiguity_ratio]
        cov = best.covariance
        if rivals:
            status = 'ambiguous'
            msg = f'{len(rivals) + 1} distinct poses fit about equally well'
            spread = np.array([h.pose for h in rivals + [best]])
            cov = cov + np.diag([*np.var(spread[:, :2], axis=0), np.pi ** 2 / 3.0])
        elif self._position_std(best) > cfg.max_position_std:
            status = 'ambiguous'
            msg = (f'degenerate geometry (e.g. a corridor): position std '
                   f'{self._position_std(best):.2f} m along the weakest direction')
        else:
            status = 'ok'
            msg = (f'agree {best.check.consistent:.0%}, through walls '
                   f'{best.check.contradicting:.0%}, fit {best.fit:.3f}')
        return Localization(status=status, pose=best.pose, covariance=cov, node=best.node,
                            score=best.score, candidates=hyps, latency_ms=ms, message=msg)
