"""
Global localization of one laser scan on an indexed map (paper section IV, and beyond).

Pipeline for one query scan (``LocalizerConfig`` names the knobs):
1. query features (II.A): spatially even points, tangents (eq. 1), shape descriptors;
2. pose voting (beyond the paper, ``voting.py``): the virtual-scan features of every GVD node
   are pooled in the map frame; each query point's nearest descriptors vote for the pose they
   imply; the ``vote_peaks`` strongest peaks of the vote histogram are candidate places;
3. coarse (IV.A): the correspondences of each peak are matched spectrally -- affinity G (eqs.
   2-4), leading eigenvector and binarization (eq. 6) -- and the peaks are ranked by their
   spectral score (eq. 5); the ``top_n`` best go on;
4. fine (IV.B): 2-point RANSAC and least squares (eqs. 7-8) on each peak's consistent
   correspondences give a pose hypothesis;
5. correlative search (beyond the paper, ``correlative.py``): branch and bound over the whole
   map at the yaws of the best hypotheses and their flips, which finds the places the voting
   missed (typically a corridor whose position along it only far walls tell); an answer that
   is not ``ok`` in the end gets a second look, the search at further yaws (``second_look``;
   on a map of several regions a ``failed`` one gets a weak look instead, the search at the
   yaws of the vote peaks too weak to be hypotheses, ``weak_look``);
   an ``ok`` one is checked for its look-alikes, the search at its yaw and its half turn over
   the whole map (``twin_check``: on a map of one region ``search_flips``; on a map of several,
   ``search_twins``, its places ranked by a quick ray check, ``twin_places``);
6. refinement (``refine.py``): Gauss-Newton on the map's wall surface, the surface offset
   estimated from the scan, on the even points, and once more from the optimum of every
   endpoint (the few even points alone can settle half a degree off); the explained fraction
   ``mean exp(-r^2 / 2 score_sigma^2)`` over the even points measures how much of the scan a
   pose explains;
7. verification (``verify.py``): ray casting; beams seeing through walls count against a pose;
8. the answer: ``failed`` when the best pose explains too little of the scan, ``ambiguous`` when a
   distinct pose scores within ``ambiguity_margin``, the geometry leaves the position
   undetermined beyond ``max_position_std`` or the scan sees nothing beyond
   ``min_scan_extent``; otherwise the evidence of the pose (``evidence.py``,
   the margin measured against the best distinct rival, ray-cast for it) gives the calibrated
   confidence ``P(right | evidence)`` (``confidence.py``): ``ok`` from ``min_confidence``, else
   ``ambiguous`` or (below one half) ``failed``; the covariance is the Gauss-Newton one, scaled
   and floored (``covariance_scale``, ``min_position_std``, ``min_yaw_std``).
``paper_mode`` runs the paper's own pipeline instead: every node ranked by the spectral score of
the query against its virtual scan, RANSAC + least squares on the ``top_n`` best, the largest
vicinity score (eq. 10) wins, always ``ok``.
"""
from __future__ import annotations

from collections.abc import Callable
import copy
import dataclasses
from dataclasses import dataclass, field, replace
import math
import time
from typing import Literal

import numpy as np
from scipy.spatial import cKDTree

from .confidence import confidence, resolution_warning
from .evidence import (beam_fractions, covariance_stds, endpoint_evidence, Evidence,
                       rival_counts)
from .fusion import lever_arm_covariance
from .map_layers import build_map_layers
from .refine import refine_poses, RefineResult
from .regions import (is_new_yaw, pick_leaves, place_leaves, REGION_BATCH, REGION_HOT_BATCHES,
                      REGION_RATIO, SearchPlan, spread_yaws, with_region_bests)
from .verify import BeamCheck, check_beams
from .voting import alignment_yaws, Votes
from ..config.confidence import CONFIDENCE_MODEL, ConfidenceModel
from ..config.localization import LocalizerConfig
from ..mapping.index import MapIndex
from ..matching.features import prepare_scan, ScanFeatures
from ..matching.matcher import match_features, spectral_score, spectral_solution
from ..matching.pairwise import affinity_matrix, angle_table, distance_table
from ..matching.ransac import ransac_hypotheses
from ..matching.scan import (MAX_RANGE, ranges_to_points, scan_geometry_problem, sensor_range,
                             thinned)
from ..matching.spectral import binarize, leading_eigenvector, matching_score
from ..progress import LayerHook, no_layers
from ..transforms import apply, compose, inverse, Pose2, wrap_angle

#: the statuses of an answer: confident, several places fit (or too little evidence), no estimate
OK, AMBIGUOUS, FAILED = 'ok', 'ambiguous', 'failed'
STATUSES = (OK, AMBIGUOUS, FAILED)
Status = Literal['ok', 'ambiguous', 'failed']
#: the twin check's search returns at most this many leaves (places of a metre: ``twin_places``)
TWIN_LEAVES = 4096


class SparseScan(ValueError):
    """
    A well-formed scan with too few returns to match: an open space, a short-range laser.

    It carries the scan's beams for the ray check (``angles``, ``beams``, ``range_max``: as a
    :class:`Query` holds them), so that a caller can still compare it with the map.
    """

    def __init__(self, message: str, angles: np.ndarray, beams: np.ndarray,
                 range_max: float) -> None:
        super().__init__(message)
        self.angles, self.beams, self.range_max = angles, beams, range_max


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """
    One candidate pose, a value: each stage returns new hypotheses (``dataclasses.replace``).

    ``laser_pose`` is the laser in the map frame, ``pose`` the base; ``refined`` once refined on
    the wall surface, ``check`` once verified by ray casting.
    """

    source: str
    initial_pose: Pose2                     # laser pose before refinement
    node: int = -1                          # GVD node whose features voted most for it
    spectral: float = 0.0                   # eq. (5) score of its correspondences
    correlative: float = 0.0                # mean point likelihood before refinement
    laser_pose: Pose2 = (0.0, 0.0, 0.0)
    pose: Pose2 = (0.0, 0.0, 0.0)
    covariance: np.ndarray | None = None    # (3, 3) x, y, yaw of the base, as reported
    explained: float = 0.0                  # mean exp(-r^2 / 2 score_sigma^2) after refinement
    depth: float = 0.0                      # estimated wall-surface offset, metres
    check: BeamCheck | None = None
    vicinity: float = 0.0                   # eq. (10), paper mode
    refined: bool = False
    score: float = 0.0                      # explained - weight x through-wall fraction
    found_by: frozenset[str] = frozenset()  # sources of the duplicates merged into it

    def __post_init__(self) -> None:
        object.__setattr__(self, 'found_by', frozenset(self.found_by) | {self.source})

    @property
    def contradicting(self) -> float:
        return self.check.contradicting if self.check is not None else 0.0


@dataclass
class Query:
    """
    One scan, prepared once.

    ``features`` (spatially even points, tangents, descriptors), ``points`` every valid endpoint
    (laser frame, sweep order), ``angles`` / ``beams`` the beams for the ray check (``inf`` = no
    return), ``range_max`` the sensor's range.
    """

    features: ScanFeatures
    points: np.ndarray
    angles: np.ndarray
    beams: np.ndarray
    range_max: float = math.inf     # the sensor's range: a wall nearer should give a return
    _picked: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def wall_angles(self) -> np.ndarray:
        """Return the directions of the scan's walls: its features' tangents, laser frame."""
        tangents = self.features.tangents
        return np.arctan2(tangents[:, 1], tangents[:, 0])

    def picked_beams(self, count: int, max_range: float) -> tuple[np.ndarray, np.ndarray]:
        """
        Return ``count`` evenly spaced beams: angles and ranges (``inf`` beyond ``max_range``).

        Computed once per query and arguments (the ray check of every hypothesis uses them).
        """
        key = (count, max_range)
        if key not in self._picked:
            self._picked[key] = pick_beams(self.angles, self.beams, count, max_range)
        return self._picked[key]


@dataclass
class Localization:
    """The answer for one scan. ``pose`` is the robot base in the map frame."""

    status: Status
    pose: Pose2 | None
    covariance: np.ndarray = field(default_factory=lambda: np.diag([1e3, 1e3, 1e3]))
    node: int = -1
    score: float = float('nan')
    candidates: list[Hypothesis] = field(default_factory=list)
    latency_ms: float = 0.0
    message: str = ''
    stages: dict[str, float] = field(default_factory=dict)   # milliseconds per stage
    confidence: float = 0.0                 # P(right | evidence), calibrated (confidence.py)
    evidence: Evidence | None = None        # what the pose rests on (None: no pose)

    @property
    def ok(self) -> bool:
        return self.status == OK


def vicinity_score(node_points: np.ndarray, query_points: np.ndarray, pose: Pose2,
                   sigma_d: float, tree: cKDTree | None = None) -> float:
    """
    Eq. (10): ``sum_i 4.5 - d_i^2 / (2 sigma_d^2)`` over pairs closer than ``3 sigma_d``.

    Pairs are each query point (moved into the node frame by ``pose``) and its nearest node point.
    """
    if len(node_points) == 0 or len(query_points) == 0:
        return 0.0
    tree = tree if tree is not None else cKDTree(node_points)
    d, _ = tree.query(apply(pose, query_points), distance_upper_bound=3.0 * sigma_d)
    d = d[np.isfinite(d)]
    return float(np.sum(4.5 - d ** 2 / (2.0 * sigma_d ** 2)))


def scan_beams(ranges, angle_min: float, angle_increment: float, range_min: float = 0.0,
               range_max: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the beams of a LaserScan for the ray check: ``(angles, ranges)``, laser frame.

    The readings within ``[range_min, range_max]`` and the ``+inf`` ones (no return, REP 117);
    NaN, ``-inf`` and finite readings outside the range are no measurement at all.
    """
    ranges = np.asarray(ranges, dtype=float).ravel()
    angles = angle_min + angle_increment * np.arange(len(ranges))
    with np.errstate(invalid='ignore'):
        keep = (((ranges >= range_min) & (ranges <= min(sensor_range(range_max), MAX_RANGE)))
                | (ranges == np.inf))
    return angles[keep], ranges[keep]


def pick_beams(angles: np.ndarray, beams: np.ndarray, count: int,
               max_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Return ``count`` evenly spaced beams: angles and ranges (``inf`` beyond ``max_range``)."""
    if len(angles) == 0:
        return angles, beams
    pick = np.unique(np.linspace(0, len(angles) - 1, count).astype(int))
    return angles[pick], np.where(beams[pick] > max_range, np.inf, beams[pick])


def distinct(a: Pose2, b: Pose2, xy: float, yaw: float) -> bool:
    """Poses further apart than ``xy`` metres or ``yaw`` radians."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) > xy or abs(wrap_angle(a[2] - b[2])) > yaw


def _by_correlation(hyps: list[Hypothesis]) -> list[Hypothesis]:
    """Return scored hypotheses by their correlative score, best first, duplicates dropped."""
    return _merged(sorted(hyps, key=lambda h: -h.correlative), lambda h: h.initial_pose)


def _merged(ranked: list[Hypothesis], pose_of) -> list[Hypothesis]:
    """
    ``ranked`` without duplicates (the same pose within 5 cm and 0.02 rad).

    The first of each stays, with the sources of the others added to its ``found_by``.
    """
    out: list[Hypothesis] = []
    for h in ranked:
        k = next((k for k, o in enumerate(out)
                  if not distinct(pose_of(h), pose_of(o), 0.05, 0.02)), None)
        if k is None:
            out.append(h)
        elif not h.found_by <= out[k].found_by:
            out[k] = replace(out[k], found_by=out[k].found_by | h.found_by)
    return out


class StageClock:
    """Milliseconds per stage of one localization (``Localization.stages``)."""

    def __init__(self) -> None:
        self.t0 = self.last = time.perf_counter()
        self.stages: dict[str, float] = {}

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.stages[name] = self.stages.get(name, 0.0) + (now - self.last) * 1e3
        self.last = now

    @property
    def total_ms(self) -> float:
        return (time.perf_counter() - self.t0) * 1e3


class GlobalLocalizer:
    """
    Single-scan global localization against a :class:`MapIndex`.

    Everything that depends on the map only (the pooled node features, the correlative grids,
    the wall surface model, the ray caster) is built here once; ``localize_*`` does per-scan work.
    The stages are public so the tracker can reuse them on its own hypotheses.
    """

    def __init__(self, index: MapIndex, config: LocalizerConfig | None = None,
                 confidence_model: ConfidenceModel = CONFIDENCE_MODEL,
                 layer: LayerHook = no_layers):
        self.index = index
        self.config = cfg = config or LocalizerConfig()
        self.confidence_model = confidence_model
        self.matcher_config = index.config.matcher
        if len(index.features) == 0:
            raise ValueError('the map index has no nodes: nothing to localize against')
        layers = build_map_layers(index, cfg, layer)
        self.grid, self.surface = layers.grid, layers.surface
        self.caster, self.voting = layers.caster, layers.voting
        self.regions = layers.regions
        self._map_spectrum = np.fft.fft(self.voting.orientation_histogram())
        self._base_from_laser = inverse(cfg.laser_pose)
        self._paper_config = dataclasses.replace(self.matcher_config, icp=False, polish=False,
                                                 retries=0, ransac_hypotheses=1)
        self._node_trees = ([cKDTree(f.points) if len(f.points) else None
                             for f in index.features] if cfg.paper_mode else [])

    @property
    def calibration_warning(self) -> str:
        """
        Return why this map lies outside what the confidence was calibrated on ('' if not).

        A map of coarser cells than the calibration maps' (``confidence.resolution_warning``).
        """
        return resolution_warning(self.index.map.resolution)

    # -- frames -------------------------------------------------------------------------------
    def base_pose(self, laser_pose: Pose2) -> Pose2:
        """Return the base pose in the map frame given the laser's."""
        return compose(laser_pose, self._base_from_laser)

    def with_laser_pose(self, laser_pose: Pose2) -> GlobalLocalizer:
        """
        Return this localizer for a laser mounted at ``laser_pose`` on the base.

        The map-only structures (features, grids, wall model) are shared; only the base <-> laser
        conversions change, so a laser pose from TF costs nothing to apply.
        """
        variant = copy.copy(self)
        variant.config = dataclasses.replace(self.config, laser_pose=tuple(laser_pose))
        variant._base_from_laser = inverse(variant.config.laser_pose)
        return variant

    def laser_pose(self, base_pose: Pose2) -> Pose2:
        """Return the laser pose in the map frame given the base's."""
        return compose(base_pose, self.config.laser_pose)

    def apart(self, a: Pose2, b: Pose2) -> bool:
        """Tell whether two base poses are distinct places (``distinct_xy``, ``distinct_yaw``)."""
        return distinct(a, b, self.config.distinct_xy, self.config.distinct_yaw)

    # -- entry points -----------------------------------------------------------------------
    def localize_scan(self, ranges, angle_min: float, angle_increment: float,
                      range_min: float = 0.0, range_max: float = float('inf')) -> Localization:
        """Localize a LaserScan given by its ranges and beam geometry."""
        clock = StageClock()
        try:
            query = self.prepare_scan(ranges, angle_min, angle_increment, range_min, range_max)
        except ValueError as exc:
            return self._failed(clock, f'bad scan: {exc}')
        return self.localize_query(query, clock)

    def localize_points(self, points_xy: np.ndarray) -> Localization:
        """Localize laser-frame points given in scan order (no no-return information)."""
        clock = StageClock()
        try:
            pts = np.asarray(points_xy, dtype=float)
            if pts.ndim != 2 or pts.shape[1] != 2:
                raise ValueError(f'expected (N, 2) points, got shape {pts.shape}')
            pts = pts[np.all(np.isfinite(pts), axis=1)]
            query = self.prepare_points(pts, np.arctan2(pts[:, 1], pts[:, 0]),
                                        np.hypot(pts[:, 0], pts[:, 1]))
        except (TypeError, ValueError) as exc:
            return self._failed(clock, f'bad points: {exc}')
        return self.localize_query(query, clock)

    def prepare_scan(self, ranges, angle_min: float, angle_increment: float,
                     range_min: float = 0.0, range_max: float = float('inf')) -> Query:
        """
        Return a :class:`Query` from LaserScan fields; ``ValueError`` for a malformed scan.

        The beams of the ray check are the readings within ``[range_min, range_max]`` and the
        ``+inf`` ones (no return, REP 117); NaN, ``-inf`` and finite readings outside the range
        are no measurement at all and are left out. Fields that make no scan
        (``scan_geometry_problem``: the node refuses the same) raise ``ValueError``; a scan of
        more than ``MAX_BEAMS`` beams is thinned to every k-th beam.
        """
        ranges = np.asarray(ranges, dtype=float).ravel()
        problem = scan_geometry_problem(len(ranges), float(angle_min), float(angle_increment),
                                        float(range_min), float(range_max))
        if problem is not None:
            raise ValueError(problem)
        ranges, angle_increment = thinned(ranges, angle_increment)
        points, _ = ranges_to_points(ranges, angle_min, angle_increment, range_min, range_max)
        angles, beams = scan_beams(ranges, angle_min, angle_increment, range_min, range_max)
        return self.prepare_points(points, angles, beams, range_max)

    def prepare_points(self, points: np.ndarray, angles: np.ndarray, beams: np.ndarray,
                       range_max: float = math.inf) -> Query:
        """Return a :class:`Query` of laser-frame ``points`` (sweep order) and its beams."""
        if len(points) < self.config.min_points:
            raise SparseScan(f'too few valid points ({len(points)} < {self.config.min_points})',
                             angles, beams, sensor_range(range_max))
        # no ICP set: the localizer votes with the features and refines on the wall surface
        return Query(features=prepare_scan(points, self.matcher_config, fine=False),
                     points=points, angles=angles, beams=beams,
                     range_max=sensor_range(range_max))

    def localize_query(self, query: Query, clock: StageClock | None = None) -> Localization:
        """Return the whole pipeline on a prepared query."""
        clock = clock or StageClock()
        clock.lap('prepare')
        if self.config.paper_mode:
            return self._paper(query, clock)
        spectral, weak = self.spectral_peaks(query, clock)
        hyps = self.correlate(query, spectral)
        seeds = [h.initial_pose for h in _by_correlation(hyps)]
        if self.config.search:
            found = self.search_hypotheses(query, self.search_plan(query, seeds))
            hyps += self.correlate(query, found)        # scored as the spectral ones are
            clock.lap('search')
        verified, others = [], []
        if hyps:
            verified, others = self.examine(query, hyps, clock)
            answer = self.decide(query, verified, clock, others=others)
            if answer.status == OK:
                return self.twin_check(query, answer, verified, others, clock)
        else:
            answer = self._failed(clock, 'no pose hypothesis: neither the pose votes nor the '
                                         'correlative search found a place that fits')
        if answer.status == FAILED and weak:
            again = self.weak_look(query, seeds, weak, verified, others, clock)
            if again is not None:
                return again
        return (self.second_look(query, seeds, verified, others, clock)
                or replace(answer, latency_ms=clock.total_ms))

    def examine(self, query: Query, hyps: list[Hypothesis], clock: StageClock,
                before: list[Hypothesis] = ()) -> tuple[list[Hypothesis], list[Hypothesis]]:
        """
        Return ``(verified, others)``: the hypotheses worth it refined and verified, the rest.

        :meth:`to_refine` picks from ``hyps`` by correlation, they are refined (from two
        starts), joined with the places examined ``before`` (a place met twice counts once)
        and every contender is verified (:meth:`verify_contenders`; a place verified before is
        not cast again). ``others``: the hypotheses of ``hyps`` not refined.
        """
        ranked = _by_correlation(hyps)
        todo = self.to_refine(ranked)
        refined = self.refine(query, todo, len(todo), basin=True)
        clock.lap('refine')
        merged = _merged(sorted([*before, *refined], key=lambda h: -h.explained),
                         lambda h: h.laser_pose)
        verified = self.verify_contenders(query, merged)
        clock.lap('verify')
        return verified, [h for h in ranked if h not in todo]

    def second_look(self, query: Query, seeds: list[Pose2], verified: list[Hypothesis],
                    others: list[Hypothesis], clock: StageClock) -> Localization | None:
        """
        Return the answer decided again with the places of a search at further yaws (or None).

        For an answer that is not ``ok``: the search once more at the next
        ``search_more_alignments`` yaws aligning the scan's walls with the map's
        (``SearchRegions.plan``). A building whose walls run in more than two directions (a
        museum's 45 degree halls) can put the right yaw beyond the first two alignments. Then
        the first look's yaws once more out to ``search_more_spread``: the walls a single scan
        sees can run a few degrees off the map's, and a yaw 1.5 degrees off the truth may score
        too little for a place (an Edmonton scan the search at every yaw finds). Its
        places join the first ones, refined and verified places included, and the answer is
        decided on all of them: a rival found before stays a rival. None when the second
        search finds no place, or is not to be run.

        Only on a map of one region (a building). On a campus of several regions the second
        search costs more than the first, every region at further yaws: measured on the campus
        benchmark it found 1.6 points more places but took the p95 latency from 127 to 214 ms
        (docs/EXPERIMENTS.md).
        """
        cfg = self.config
        if not (cfg.search and cfg.search_more_alignments) or self.regions.count > 1:
            return None
        plan = self.regions.plan(query.wall_angles, seeds, cfg, more=True)
        found = self.correlate(query, self.search_hypotheses(query, plan))
        clock.lap('search')
        if not found:
            return None
        return self.decide_again(query, found, verified, others, clock)

    def weak_look(self, query: Query, seeds: list[Pose2], weak: list[Pose2],
                  verified: list[Hypothesis], others: list[Hypothesis],
                  clock: StageClock) -> Localization | None:
        """
        Return a ``failed`` answer decided again with the places at the weak peaks' yaws.

        ``weak``: the RANSAC poses of the vote peaks with ``weak_min_inliers`` inliers or more
        but fewer than ``fine_min_inliers`` (:meth:`spectral_peaks`). Only on a map of several
        regions, where each region is searched at its own alignment yaws and at the yaws of the
        hypotheses that lie in it (``SearchRegions.plan``): a building of a campus whose walls
        the scan sees askew, with no hypothesis in it, is never searched at its right yaw. Here
        each weak pose's region is searched at its yaw (and flip), those the first plan did not
        search there; the places found join the first ones (a rival found before stays a
        rival). An answer this turns ``ok`` is twin-checked whatever its confidence and stays
        ``ok`` only from ``weak_min_confidence`` (0.9985; before the recalibration of
        2026-12-08 such an answer said 0.9899 there, and the bar was 0.99), else it is
        ``ambiguous``. Measured without the bar (docs/EXPERIMENTS.md, 2026-12-03, confidences
        as then reported): on the campus benchmark 28 ``failed`` answers turned right
        (0.963-0.9996) and none wrong over two query draws (900 and 1770 scans, sharing some);
        on the 30 M-cell office over 16 query seeds one turned wrong, at 0.957, and none right;
        the bar keeps 25 of the campus's 28. None when there is nothing to search or the map
        has one region (its ``second_look`` searches further alignments
        everywhere).
        """
        cfg = self.config
        if self.regions.count <= 1 or not cfg.search:
            return None
        plan = self.regions.plan(query.wall_angles, seeds, cfg, weak=weak)
        found = self.correlate(query, self.search_hypotheses(query, plan))
        clock.lap('search')
        if not found:
            return None
        verified, more = self.examine(query, found, clock, before=verified)
        answer = self.decide(query, verified, clock, others=more + others)
        if answer.status != OK:
            return replace(answer, latency_ms=clock.total_ms)
        answer = self.twin_check(query, answer, verified, more + others, clock, always=True)
        if answer.status == OK and answer.confidence < cfg.weak_min_confidence:
            return replace(answer, status=AMBIGUOUS, latency_ms=clock.total_ms,
                           message=f'a place only weak vote peaks led to, at a confidence of '
                                   f'{answer.confidence:.3f}, below weak_min_confidence '
                                   f'{cfg.weak_min_confidence:g}')
        return replace(answer, latency_ms=clock.total_ms)

    def twin_check(self, query: Query, answer: Localization, verified: list[Hypothesis],
                   others: list[Hypothesis], clock: StageClock,
                   always: bool = False) -> Localization:
        """
        Return an ``ok`` answer decided again with its twins: the search at its yaw everywhere.

        On a map of several regions each region is searched at its own alignment yaws and at
        the yaws of the hypotheses that lie in it (``SearchRegions.plan``), so a look-alike
        room in another region is searched only at that region's alignment yaws, up to half a
        bin off, and which of two twins the search keeps is luck. Here every region is searched
        at the answer's laser yaw and its flip (a room turned by a half turn); the places found
        join the first ones and the answer is decided on all of them, so a twin becomes the
        rival it is. On a map of several regions (``search_twins``) every ``ok`` answer is
        checked (an answer above ``search_twins_below``, 1.0 by default, is not), for places
        scoring at least ``search_twins_ratio`` of the answer's own correlative score, and the
        places go on ranked by a quick ray check (:meth:`twin_places`). On the 30 M-cell office
        over twelve query seeds it took the wrong ``ok`` answers from 11 to none, the right ones
        from 1910 to 1901, where checking only answers below 0.99 and taking the places their
        correlative score ranked best had left them (docs/EXPERIMENTS.md, 2026-12-03).
        A map of one region searches the seeds' yaws everywhere already, but a seed's yaw is
        the hypothesis's, up to a bin off the refined answer, and a room that fits turned round
        is kept or lost by the search's leaf cap: the check (``search_flips``, on by default)
        searches the answer's own yaw and half turn. On the benchmark's 17 370 single scans it
        made two wrong ``ok`` answers ``ambiguous`` (90° lasers, 177-180° off), and 39 right
        ones through short and narrow lasers (0.1-1.0 points of pooled success), for about 3 ms
        a query (docs/EXPERIMENTS.md).
        """
        cfg = self.config
        several = self.regions.count > 1
        wanted = cfg.search_twins if several else cfg.search_flips
        if not (cfg.search and wanted) or answer.pose is None:
            return answer
        if several and not always and answer.confidence > cfg.search_twins_below:
            return answer
        laser = self.laser_pose(answer.pose)
        yaws = np.array([laser[2], laser[2] + math.pi])
        plan = SearchPlan(yaws, np.ones((len(yaws), self.regions.count), bool),
                          self.regions.labels)
        if several:
            found = self.twin_places(query, answer, plan)
        else:
            found = [h for h in self.correlate(query, self.search_hypotheses(query, plan))
                     if self.apart(self.base_pose(h.initial_pose), answer.pose)]
        clock.lap('twins')
        if not found:
            return replace(answer, latency_ms=clock.total_ms)
        return self.decide_again(query, found, verified, others, clock)

    def twin_places(self, query: Query, answer: Localization,
                    plan: SearchPlan) -> list[Hypothesis]:
        """
        Return the places of a twin search worth deciding with, best by a quick ray check first.

        The search (``plan``: the answer's yaw and flip in every region) looks for places scoring
        at least ``search_twins_ratio`` of the answer's own correlative score on the search's
        points. On a campus it finds tens of them (office_30m's wrong answers: 39-151 places of
        a metre, 15-22 a query on average at 0.95), most of them places where the scan's few
        points lie on walls but its beams see through others; the twin that matters ranked
        15th to 101st by that score, beyond the leaves :func:`pick_leaves` would keep. So the
        best leaf of each place (:func:`place_leaves`) distinct from the answer is ray-cast
        with ``search_twins_beams`` beams (:meth:`quick_checks`), and the
        ``search_twins_keep`` best that score within ``search_twins_margin`` of the answer's
        own check go on.
        """
        cfg = self.config
        pts = _evenly(query.features.points, cfg.search_points)
        laser = self.laser_pose(answer.pose)
        own = self.grid.score_poses(pts, np.array([laser]))[0]
        floor = max(cfg.search_min_score, cfg.search_twins_ratio * float(own))
        found = self.grid.search(pts, yaws=plan.yaws, min_score=floor, ratio=cfg.search_ratio,
                                 budget_s=cfg.search_budget, max_leaves=TWIN_LEAVES,
                                 regions=plan.regions, region_ratio=REGION_RATIO,
                                 batch=REGION_BATCH, hot_batches=REGION_HOT_BATCHES)
        leaves = [int(i) for i in place_leaves(found.poses)
                  if self.apart(self.base_pose(tuple(found.poses[i])), answer.pose)]
        if not leaves:
            return []
        own_check, quick, poses = self.quick_checks(query, laser, found.poses[leaves])
        order = np.lexsort((-found.scores[leaves], -quick))[:cfg.search_twins_keep]
        keep = [k for k in order if quick[k] >= own_check - cfg.search_twins_margin]
        return self.correlate(query, [   # scored on every point of the scan, as the first look
            Hypothesis(source='search', initial_pose=tuple(float(v) for v in poses[k]))
            for k in keep])

    def quick_checks(self, query: Query, laser: Pose2, leaves: np.ndarray
                     ) -> tuple[float, np.ndarray, np.ndarray]:
        """
        Return the quick ray check of the answer at ``laser`` and of each place, and its pose.

        ``search_twins_beams`` beams, scored ``consistent - contradiction_weight x
        contradicting`` (``BeamCheck.score``). A place (laser poses ``leaves``, ``(n, 3)``)
        is cast at its leaf and at the leaf refined once on the spatially even points, and keeps
        the better of the two with its pose: a leaf lies up to half a search cell and half a
        yaw step off, and a narrow laser's long beams then miss their walls (office_30m, a 90°
        scan whose truth's leaf the check dropped for a twin), while a refinement from the
        leaf alone can settle in another basin (another 90° scan, whose rival only its leaf
        kept). Measured in docs/EXPERIMENTS.md (2026-12-03, session 58).
        """
        cfg = self.config
        angles, measured = query.picked_beams(cfg.search_twins_beams, cfg.max_cast_range)
        refined = np.array([r.pose for r in self._gauss_newton(query.features.points, leaves)])
        checks = self._checks([laser, *map(tuple, leaves), *map(tuple, refined)], angles,
                              measured, query.range_max)
        quick = np.array([c.score(cfg.contradiction_weight) for c in checks])
        at_leaf, once = quick[1:1 + len(leaves)], quick[1 + len(leaves):]
        poses = np.where((once > at_leaf)[:, None], refined, leaves)
        return float(quick[0]), np.maximum(at_leaf, once), poses

    def decide_again(self, query: Query, found: list[Hypothesis], verified: list[Hypothesis],
                     others: list[Hypothesis], clock: StageClock) -> Localization:
        """
        Return the answer decided on a further search's places ``found`` and the first ones.

        ``found`` are examined (:meth:`examine`) joined with the places ``verified`` before (a
        place met twice counts once, a rival found before stays a rival); ``others``, the first
        look's hypotheses not refined, stay among the candidates.
        """
        verified, more = self.examine(query, found, clock, before=verified)
        return self.decide(query, verified, clock, others=more + others)

    # -- stages -----------------------------------------------------------------------------
    def spectral_hypotheses(self, query: Query,
                            clock: StageClock | None = None) -> list[Hypothesis]:
        """Pose voting, spectral coarse ranking of the peaks (eq. 5), RANSAC fine pose."""
        return self.spectral_peaks(query, clock)[0]

    def spectral_peaks(self, query: Query, clock: StageClock | None = None
                       ) -> tuple[list[Hypothesis], list[Pose2]]:
        """
        Return the spectral hypotheses and the weak peaks' RANSAC poses (laser, map frame).

        A peak of the ``top_n`` whose RANSAC pose (eqs. 7-8) has ``fine_min_inliers`` inliers
        becomes a hypothesis; one with ``weak_min_inliers`` or more but fewer is a weak peak
        (``weak_look``; none when ``weak_min_inliers`` is 0).
        """
        cfg = self.config
        feats = query.features
        votes = self.voting.vote(feats)
        peaks = self.voting.peaks(votes, cfg.vote_peaks)
        if clock:
            clock.lap('vote')
        scored = []
        for peak in peaks:
            sel, energy = self._peak_spectral(feats, votes, peak.members)
            if len(sel) >= 2:
                scored.append((energy, peak.members[sel]))
        scored.sort(key=lambda t: -t[0])
        if clock:
            clock.lap('coarse')
        rng = np.random.default_rng(self.matcher_config.seed)
        mc = self.matcher_config
        out, weak = [], []
        for energy, members in scored[:cfg.top_n]:
            qi, mj = votes.qi[members], votes.mj[members]
            found = ransac_hypotheses(self.voting.points[mj], feats.points[qi],
                                      mc.ransac_threshold, cfg.fine_ransac_iterations, rng,
                                      mc.ransac_min_span)
            if not found or found[0][1].sum() < cfg.fine_min_inliers:
                if found and 0 < cfg.weak_min_inliers <= found[0][1].sum():
                    weak.append(tuple(float(v) for v in found[0][0]))
                continue
            pose, inliers = found[0]
            node = int(np.bincount(self.voting.nodes[mj[inliers]]).argmax())
            out.append(Hypothesis(source='spectral', initial_pose=pose, node=node,
                                  spectral=float(energy)))
        if clock:
            clock.lap('fine')
        return out, weak

    def _peak_spectral(self, feats: ScanFeatures, votes: Votes, members: np.ndarray):
        """
        Spectral matching (eqs. 2-6) of a peak's correspondences: (selection, eq. 5 score).

        The query's pairwise tables are its cached ``dist`` / ``angle``; the map's are built for
        the peak's features only.
        """
        mc = self.matcher_config
        uj, lj = np.unique(votes.mj[members], return_inverse=True)
        pairs = np.column_stack((lj.ravel(), votes.qi[members]))
        g = affinity_matrix(distance_table(self.voting.points[uj]),
                            angle_table(self.voting.tangents[uj]), feats.dist, feats.angle,
                            pairs, mc.weights, mc.max_dist_deform, mc.max_angle_deform)
        x = leading_eigenvector(g, mc.power_iterations, mc.power_tol)
        sel = binarize(x, pairs, mc.binarize_min_ratio)
        return sel, matching_score(g, sel)

    def search_hypotheses(self, query: Query, yaws: np.ndarray | SearchPlan,
                          window: tuple[float, float, float, float] | None = None,
                          min_score: float | None = None) -> list[Hypothesis]:
        """
        Correlative branch and bound over the whole map (or ``window``) at the given ``yaws``.

        ``yaws`` may be a :class:`~.regions.SearchPlan` (each yaw in its regions, see
        :meth:`search_plan`). At most ``search_keep`` distinct leaves, best first (see
        :meth:`search_yaws`). ``min_score``: no leaf scoring less (default
        ``search_min_score``).
        """
        cfg = self.config
        plan = yaws if isinstance(yaws, SearchPlan) and yaws.allowed.shape[1] > 1 else None
        yaws = yaws.yaws if isinstance(yaws, SearchPlan) else yaws
        if len(yaws) == 0:
            return []
        pts = _evenly(query.features.points, cfg.search_points)
        regional = {} if plan is None else {
            'regions': plan.regions, 'region_ratio': REGION_RATIO, 'batch': REGION_BATCH,
            'hot_batches': REGION_HOT_BATCHES}
        floor = cfg.search_min_score if min_score is None else min_score
        found = self.grid.search(pts, yaws=yaws, window=window, min_score=floor,
                                 ratio=cfg.search_ratio, budget_s=cfg.search_budget, **regional)
        return [Hypothesis(source='search', initial_pose=tuple(float(v) for v in found.poses[i]),
                           correlative=float(found.scores[i]))
                for i in pick_leaves(found, cfg.search_keep, lambda a, b: not distinct(
                    a, b, cfg.vote_bin_xy, cfg.search_step * 3), cfg.search_rivals)]

    def search_plan(self, query: Query, seeds: list[Pose2]) -> SearchPlan:
        """
        Return where to search at which yaws: :meth:`search_yaws`, region by region.

        ``seeds``: laser poses of the best hypotheses, best first (``regions.py``).
        """
        return self.regions.plan(query.wall_angles, seeds, self.config)

    def search_yaws(self, query: Query, yaws) -> np.ndarray:
        """
        Return the yaws to search around the orientations ``yaws``, best first.

        Up to ``search_seeds`` of them distinct modulo a half turn, then the
        ``search_alignments`` yaws that align the scan's wall directions with the map's; each
        with its flip, each +- ``search_spread``.
        """
        cfg = self.config
        centres: list[float] = []
        for yaw in yaws:
            if is_new_yaw(yaw, centres, cfg.search_step):
                centres.append(yaw)
            if len(centres) >= cfg.search_seeds:
                break
        for yaw in alignment_yaws(self._map_spectrum, query.wall_angles, cfg.search_alignments):
            if is_new_yaw(yaw, centres, cfg.search_step):
                centres.append(float(yaw))
        return spread_yaws(centres, cfg) if centres else np.zeros(0)

    def correlate(self, query: Query, hyps: list[Hypothesis]) -> list[Hypothesis]:
        """Return ``hyps`` with the correlative score (mean point likelihood) of their poses."""
        if not hyps:
            return []
        scores = self.grid.score_poses(query.features.points,
                                       np.array([h.initial_pose for h in hyps]))
        return [replace(h, correlative=float(s)) for h, s in zip(hyps, scores)]

    def to_refine(self, ranked: list[Hypothesis]) -> list[Hypothesis]:
        """
        Return the hypotheses worth refining: the first ``refine_hypotheses`` of ``ranked``.

        On a map of several regions also the first hypothesis of each region those leave out
        and every one the search found (its rivals; ``regions.py``).
        """
        return with_region_bests(self.regions, ranked, self.config.refine_hypotheses,
                                 lambda h: h.initial_pose, lambda h: 'search' in h.found_by)

    def refine(self, query: Query, hyps: list[Hypothesis], limit: int | None = None,
               basin: bool = False) -> list[Hypothesis]:
        """
        Return the first ``limit`` hypotheses refined on the wall surface (batched).

        Gauss-Newton on the spatially even points, the truncation radius shrinking as
        configured. ``basin`` (the global search's hypotheses): also a second start, first on
        every endpoint of the scan, then on the even points at the last radius, and each
        hypothesis keeps whichever optimum explains more of the scan. From a search leaf 5 cm and
        0.35 degrees off, the even points alone settled 0.5 degrees off (explaining 0.87 of the
        scan where the truth explains 0.99) and lost to a look-alike room of the 30 M-cell
        office; every endpoint finds the right basin. The tracker, which starts at its
        prediction, refines once. ``limit`` defaults to :meth:`to_refine`'s choice; those that
        meet are merged; best explained first.
        """
        cfg = self.config
        todo = hyps[:limit] if limit is not None else self.to_refine(hyps)
        if not todo:
            return []
        starts = [h.initial_pose for h in todo]
        results = self._gauss_newton(query.features.points, starts)
        if basin:
            wide = self._gauss_newton(query.points, starts)
            again = self._gauss_newton(query.features.points, [r.pose for r in wide],
                                       (cfg.refine_radius[1], cfg.refine_radius[1]))
            results = [b if b.explained > a.explained else a for a, b in zip(results, again)]
        done = [replace(h, laser_pose=r.pose, explained=r.explained, depth=r.depth, refined=True,
                        score=r.explained, pose=self.base_pose(r.pose),
                        covariance=self.report_covariance(r.covariance, r.pose))
                for h, r in zip(todo, results)]
        return _merged(sorted(done, key=lambda h: -h.explained), lambda h: h.laser_pose)

    def _gauss_newton(self, points: np.ndarray, starts,
                      truncate: tuple[float, float] | None = None) -> list[RefineResult]:
        """Return the laser poses ``starts`` refined on the wall surface with ``points``."""
        cfg = self.config
        return refine_poses(self.surface, points, np.asarray(starts),
                            iterations=cfg.refine_iterations,
                            truncate=cfg.refine_radius if truncate is None else truncate,
                            estimate_depth=cfg.estimate_depth, depth_prior=cfg.surface_depth_std,
                            score_sigma=cfg.score_sigma)

    def verify_contenders(self, query: Query, refined: list[Hypothesis],
                          first: int | None = None, margin: float | None = None,
                          plausible: Callable[[Hypothesis], bool] | None = None
                          ) -> list[Hypothesis]:
        """
        Return ``refined`` with every hypothesis that could win or be a rival verified.

        ``refined`` comes best explained first. First the ``first`` best (default: the
        ``verify_hypotheses`` best and every one within ``verify_margin`` of the best explained
        fraction), then, until none is left, every one that could still win or be a rival: a score
        never exceeds the explained fraction, so an unverified hypothesis explaining less than
        the best ``plausible`` verified score minus ``margin`` (default ``ambiguity_margin``) can
        be neither. ``plausible(h)`` defaults to at most ``max_contradicting`` through walls.
        """
        cfg = self.config
        out = list(refined)
        if not out:
            return out
        margin = cfg.ambiguity_margin if margin is None else margin
        limit = cfg.max_contradicting
        plausible = plausible or (lambda h: h.contradicting <= limit)
        if first is None:
            top = out[0].explained
            batch = [k for k, h in enumerate(out)
                     if k < cfg.verify_hypotheses or h.explained >= top - cfg.verify_margin]
        else:
            batch = list(range(min(first, len(out))))
        batch = [k for k in batch if out[k].check is None]     # verified before: as it was
        while batch:
            for k, h in zip(batch, self.verify(query, [out[k] for k in batch])):
                out[k] = h
            best = max((h.score for h in out if h.check is not None and plausible(h)),
                       default=-np.inf)
            batch = [k for k, h in enumerate(out)
                     if h.check is None and h.explained >= best - margin]
        return out

    def check_at(self, pose: Pose2, sparse: SparseScan | Query) -> BeamCheck:
        """
        Return the ray check of a scan (too sparse to be a :class:`Query`, or one) at a base pose.

        What :meth:`verify` does for a hypothesis: do its few returns and its no-returns agree
        with the map there?
        """
        cfg = self.config
        angles, measured = pick_beams(sparse.angles, sparse.beams, cfg.verify_beams,
                                      cfg.max_cast_range)
        return self._checks([self.laser_pose(pose)], angles, measured, sparse.range_max)[0]

    def verify(self, query: Query, hyps: list[Hypothesis]) -> list[Hypothesis]:
        """Return ``hyps`` verified: the query's beams ray-cast from each (all at once)."""
        if not hyps:
            return []
        cfg = self.config
        angles, measured = query.picked_beams(cfg.verify_beams, cfg.max_cast_range)
        checks = self._checks([h.laser_pose for h in hyps], angles, measured, query.range_max)
        return [replace(h, check=check,
                        score=h.explained - cfg.contradiction_weight * check.contradicting)
                for h, check in zip(hyps, checks)]

    def _checks(self, laser_poses: list[Pose2], angles: np.ndarray, measured: np.ndarray,
                range_max: float) -> list[BeamCheck]:
        """Ray-cast ``angles`` from each laser pose and compare with the ``measured`` ranges."""
        cfg = self.config
        expected = self.caster.cast(np.array(laser_poses), angles, cfg.max_cast_range)
        return [check_beams(measured, e, tol=cfg.beam_tolerance, range_limit=range_max)
                for e in expected]

    def polish(self, query: Query, h: Hypothesis) -> Hypothesis:
        """Return ``h`` after a last Gauss-Newton run on every endpoint of the scan."""
        cfg = self.config
        if cfg.polish_iterations <= 0:
            return h
        r = refine_poses(self.surface, query.points, np.array([h.laser_pose]),
                         iterations=cfg.polish_iterations,
                         truncate=(cfg.refine_radius[1], cfg.refine_radius[1]),
                         estimate_depth=cfg.estimate_depth, depth_prior=cfg.surface_depth_std,
                         score_sigma=cfg.score_sigma)[0]
        return replace(h, laser_pose=r.pose, depth=r.depth, pose=self.base_pose(r.pose),
                       covariance=self.report_covariance(r.covariance, r.pose))

    def verified_at(self, query: Query, pose: Pose2, like: Hypothesis) -> Hypothesis:
        """
        Return a hypothesis at the base pose ``pose``, scored and verified as ``like`` was.

        Its explained fraction is measured as :meth:`refine` measures it, with the wall offset
        ``like`` estimated, then it is ray-cast (the tracker's fused poses).
        """
        laser = self.laser_pose(pose)
        explained = self.surface.explained(apply(laser, query.features.points),
                                           like.depth - self.surface.depth,
                                           self.config.score_sigma)
        h = Hypothesis(source=like.source, initial_pose=laser, laser_pose=laser, pose=pose,
                       covariance=like.covariance, explained=float(explained), depth=like.depth,
                       refined=True)
        return self.verify(query, [h])[0]

    def decide(self, query: Query, hyps: list[Hypothesis], clock: StageClock | None = None,
               others: list[Hypothesis] = ()) -> Localization:
        """
        Return the answer from refined and verified hypotheses.

        The best scoring one, polished on every endpoint, with the status of :func:`verdict`.

        ``candidates`` of the answer: the verified hypotheses by score, then the refined ones,
        then ``others`` (not refined), for diagnosis (``bench localize`` reads them).
        """
        clock = clock or StageClock()
        cfg = self.config
        limit = cfg.max_contradicting
        checked = sorted((h for h in hyps if h.check is not None),
                         key=lambda h: (h.contradicting > limit, -h.score))
        if not checked:
            return self._failed(clock, 'no verified hypothesis')
        rivals, hyps = self.rivals(query, checked[0], hyps)
        best = self.polish(query, checked[0])
        ranked = [best] + checked[1:]
        evidence = self.evidence(query, best, rivals)
        status, message, cov, conf = verdict(ranked, cfg, evidence, self.confidence_model)
        clock.lap('decide')
        return Localization(status=status, pose=best.pose, covariance=cov, node=best.node,
                            score=best.score, message=message, latency_ms=clock.total_ms,
                            stages=clock.stages, confidence=conf, evidence=evidence,
                            candidates=ranked + [h for h in hyps if h.check is not None
                                                 and all(h is not c for c in checked)]
                            + [h for h in hyps if h.check is None] + list(others))

    def rivals(self, query: Query, best: Hypothesis,
               hyps: list[Hypothesis]) -> tuple[list[float], list[Hypothesis]]:
        """
        Return the scores of the verified places distinct from ``best`` and ``hyps``.

        The refined hypothesis distinct from ``best`` that explains most of the scan is verified
        if it was not yet (and so returned in ``hyps``), so the margin of the answer
        (``evidence.py``) is always measured against a ray-cast rival.
        """
        others = [k for k, h in enumerate(hyps)
                  if h is not best and h.refined and self.apart(h.pose, best.pose)]
        if not others:
            return [], hyps
        top = max(others, key=lambda k: hyps[k].explained)
        if hyps[top].check is None:
            hyps = hyps[:top] + self.verify(query, [hyps[top]]) + hyps[top + 1:]
        return [hyps[k].score for k in others if hyps[k].check is not None], hyps

    def evidence(self, query: Query, h: Hypothesis, rivals=()) -> Evidence:
        """Return the evidence for the verified ``h``; ``rivals``: its distinct rivals' scores."""
        check = h.check
        if check is None:
            raise ValueError('evidence needs a verified hypothesis (ray-cast beam check)')
        hit, through, short = beam_fractions(check)
        on_wall, unknown, runs, length = endpoint_evidence(
            self.surface, self.index.map, h.laser_pose, query.points, h.depth)
        position_std, yaw_std = covariance_stds(h.covariance)
        even = query.features.points
        extent = float(np.percentile(np.hypot(even[:, 0], even[:, 1]), 90)) if len(even) else 0.0
        margin, close, near = rival_counts(h.score, rivals)
        return Evidence(hit=hit, through=through, short=short,
                        missing=check.missing / max(check.beams, 1), on_wall=on_wall,
                        unknown=unknown, unexplained_runs=runs, explained=h.explained,
                        margin=margin, position_std=position_std, yaw_std=yaw_std,
                        returns=check.returns, scan_length=length, extent=extent,
                        close_rivals=close, near_rivals=near,
                        return_fraction=float(np.mean(np.isfinite(query.beams)))
                        if len(query.beams) else 0.0,
                        scan_position_std=position_std)

    def report_covariance(self, cov_laser: np.ndarray, laser_pose: Pose2) -> np.ndarray:
        """Return the Gauss-Newton laser covariance, scaled and floored, propagated to the base."""
        cfg = self.config
        cov = cfg.covariance_scale * np.asarray(cov_laser, float) + np.diag(
            [cfg.min_position_std ** 2, cfg.min_position_std ** 2, cfg.min_yaw_std ** 2])
        lx, ly, _ = self._base_from_laser
        off = apply((0.0, 0.0, laser_pose[2]), (lx, ly))[0]      # laser -> base, in the map
        return lever_arm_covariance(cov, off)

    # -- the paper's pipeline -----------------------------------------------------------------
    def _paper(self, query: Query, clock: StageClock) -> Localization:
        """
        Section IV as written.

        All nodes ranked by spectral score, RANSAC + LS on the top_n, the largest vicinity score
        (eq. 10) wins.
        """
        cfg = self.config
        feats = query.features
        scored = []
        for k, node in enumerate(self.index.features):
            sol = spectral_solution(node, feats, self.matcher_config)
            s, _ = spectral_score(node, feats, self.matcher_config, sol)
            scored.append((float(s), k, sol))
        scored.sort(key=lambda t: -t[0])
        clock.lap('coarse')
        hyps = []
        for s, k, sol in scored[:cfg.top_n]:
            node = self.index.features[k]
            m = match_features(node, feats, self._paper_config, sol)
            if not m.ok:
                continue
            laser = compose(tuple(self.index.node_sensor_pose[k]), m.pose)
            hyps.append(Hypothesis(
                source='paper', initial_pose=laser, node=k, spectral=s, laser_pose=laser,
                pose=compose(laser, self._base_from_laser),
                vicinity=vicinity_score(node.points, feats.points, m.pose, cfg.sigma_d,
                                        self._node_trees[k])))
        clock.lap('fine')
        if not hyps:
            return self._failed(clock, 'no candidate node gave a consistent match')
        hyps.sort(key=lambda h: -h.vicinity)
        best = hyps[0]
        return Localization(status=OK, pose=best.pose, node=best.node, score=best.vicinity,
                            candidates=hyps, latency_ms=clock.total_ms, stages=clock.stages,
                            message='paper mode: largest vicinity score')

    @staticmethod
    def _failed(clock: StageClock, message: str) -> Localization:
        return Localization(status=FAILED, pose=None, latency_ms=clock.total_ms,
                            message=message, stages=clock.stages)


def _evenly(points: np.ndarray, count: int) -> np.ndarray:
    """At most ``count`` of ``points``, evenly spaced in their order."""
    if len(points) <= count:
        return points
    return points[np.linspace(0, len(points) - 1, count).astype(int)]


def verdict(ranked: list[Hypothesis], cfg: LocalizerConfig, evidence: Evidence | None = None,
            model: ConfidenceModel = CONFIDENCE_MODEL) -> tuple[Status, str, np.ndarray, float]:
    """
    ``(status, message, covariance, confidence)`` for verified hypotheses, plausible ones first.

    First the rules a pose must pass whatever the evidence says:
    ``failed`` when even the best has more than ``max_contradicting`` of its beams seeing through
    walls, or explains too little of the scan (score below ``min_score``);
    ``ambiguous`` when a distinct pose scores within ``ambiguity_margin`` of it, or explains at
    least as much of the scan and sees through at most ``rival_contradiction`` more of its
    beams (the covariance then spans them), or when its position is undetermined beyond
    ``max_position_std`` along some direction (2 sigma beyond the 0.5 m success tolerance: a
    bare corridor), or when the scan
    sees too little to tell places apart (its evidence's ``extent`` below ``min_scan_extent``:
    a wall or a thing right in front of the sensor, whose shape repeats all over a building).
    Then the calibrated ``confidence`` = ``P(right | evidence)`` (``confidence.py``): ``ok`` when
    it reaches ``min_confidence``, else ``ambiguous`` (at least 0.5: more likely right than not)
    or ``failed``. An answer the rules refuse reports the rate at which such answers were right
    on the calibration split (``ConfidenceModel.refused``), except one refused for its rivals:
    ``min(P(right | evidence), 2 / (k + 1))`` for ``k`` > 2 distinct poses that fit about
    equally well, as if the best of them were twice as likely as each of the others (its lead,
    however small, is evidence: on the tuning split such answers were right 22 % of the time;
    this rule says 22 %, and 58 % where 60 % were right for those it puts at 0.4 or more;
    ``min(P, 1 / k)`` said 18 %, and 50 % where 72 % were right; docs/BENCHMARKS.md), and
    ``min(P, ConfidenceModel.pair)`` for a pair: the rate at which the best of a pair was right
    on the tuning split where the model said more than 2/3 (0.854 on 2026-12-08, where 2/3
    had been 19-20 points cautious on both splits).
    """
    best = ranked[0]
    cov = best.covariance if best.covariance is not None else np.diag([1e3, 1e3, 1e3])
    if best.contradicting > cfg.max_contradicting:
        return FAILED, (f'no pose agrees with the map: at the best, {best.contradicting:.0%} of '
                        f'the beams see through walls (> {cfg.max_contradicting:.0%})'), \
            _inflated(cov), model.refused['implausible']
    if best.score < cfg.min_score:
        return FAILED, (f'the best pose explains too little of the scan (explained '
                        f'{best.explained:.0%}, through walls {best.contradicting:.0%}: '
                        f'score {best.score:.2f} < {cfg.min_score})'), _inflated(cov), \
            model.refused['implausible']
    rivals = [h for h in ranked[1:]
              if distinct(h.pose, best.pose, cfg.distinct_xy, cfg.distinct_yaw)
              and (h.score >= best.score - cfg.ambiguity_margin or _explains_more(h, best, cfg))]
    if rivals:
        spread = np.array([h.pose for h in rivals + [best]])
        cov = cov + np.diag([*np.var(spread[:, :2], axis=0), np.pi ** 2 / 3.0])
        cleaner = [h for h in rivals if h.score < best.score - cfg.ambiguity_margin]
        why = (f'; another explains more of the scan, '
               f'{max(h.explained for h in cleaner):.0%} against {best.explained:.0%}, and sees '
               f'through at most {cfg.rival_contradiction:.0%} more of its beams'
               if cleaner else '')
        return AMBIGUOUS, (f'{len(rivals) + 1} distinct poses fit about equally well '
                           f'(scores {best.score:.2f} and '
                           f'{max(h.score for h in rivals):.2f}{why})'), cov, \
            min(confidence(evidence, model), model.rival_cap(len(rivals) + 1))
    std = position_std(cov)
    if std > cfg.max_position_std:
        return AMBIGUOUS, (f'degenerate geometry (e.g. a corridor): position std {std:.2f} m '
                           f'along the weakest direction'), cov, model.refused['degenerate']
    if evidence is not None and evidence.extent < cfg.min_scan_extent:
        return AMBIGUOUS, (f'degenerate view: 90 % of the scan lies within '
                           f'{evidence.extent:.2f} m of the sensor (< {cfg.min_scan_extent} m), '
                           f'too little to tell places apart'), cov, model.refused['degenerate']
    conf = confidence(evidence, model)
    facts = (f'explained {best.explained:.0%}, through walls {best.contradicting:.0%}, '
             f'position std {std * 1e3:.0f} mm, confidence {conf:.3f}')
    if conf >= cfg.min_confidence:
        return OK, facts, cov, conf
    if conf >= 0.5:
        return AMBIGUOUS, f'low confidence (< {cfg.min_confidence}): {facts}', cov, conf
    return (FAILED, f'the best pose is more likely wrong than right: {facts}', _inflated(cov),
            conf)


def _explains_more(h: Hypothesis, best: Hypothesis, cfg: LocalizerConfig) -> bool:
    """
    Tell whether ``h`` explains at least as much of the scan as ``best``, nearly as cleanly.

    The score is the explained fraction minus the share of beams that see through walls, and
    such beams are often the map's specks (people and chairs that stood still while it was
    made): a place that explains more of the scan but sees through a few more specks can be
    the right one. On the ACES map with 0.2 % of its free cells made specks (``bench localize
    --map-specks``) the right place lost so in 3 of its 4 wrong ``ok`` answers as recorded;
    through the five sensors this rule makes 7 of its 18 wrong ``ok`` answers ``ambiguous`` and
    costs 5 of 11 500 right answers of ``bench localize --sets all`` on the maps as built
    (docs/EXPERIMENTS.md).
    """
    return (h.check is not None and h.explained >= best.explained
            and h.contradicting <= best.contradicting + cfg.rival_contradiction
            and h.score >= cfg.min_score)


def position_std(cov: np.ndarray | None) -> float:
    """Return standard deviation (m) of the position along its least constrained direction."""
    if cov is None:
        return float('inf')
    return float(np.sqrt(max(np.linalg.eigvalsh(np.asarray(cov)[:2, :2]).max(), 0.0)))


def _inflated(cov: np.ndarray) -> np.ndarray:
    """Return the covariance of a rejected pose: it says nothing about where the robot is."""
    return cov + np.diag([1e2, 1e2, np.pi ** 2])
