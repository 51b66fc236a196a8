"""
Tracking at sensor rate with odometry, with global localization as the fallback.

Per scan (``Tracker.track``):
1. predict: the last pose moved by the odometry increment since the last scan, its covariance
   grown with the motion (``motion.py``, AMCL's ``diff`` model); without odometry the pose stays
   and its covariance grows by ``no_odom_std``;
2. search: the localizer's correlative branch and bound over a window around the predicted laser
   pose (``window_sigmas`` standard deviations, bounded by ``window_xy`` / ``window_yaw``); the
   prediction itself and the best ``track_hypotheses`` leaves are refined on the wall surface;
3. gate and verify: refined poses further than ``gate_chi2`` (Mahalanobis, prediction and scan
   covariances summed) from the prediction are not the tracked pose; the rest are ray-cast
   (``GlobalLocalizer.verify``) and the best score wins;
4. fuse: the winner is fused with the prediction in information form (``fusion.py``), which
   keeps the scan where its walls pin the pose down and the prediction along what they leave
   free (a corridor's axis, ``weak_std``; the yaw of a few short returns, ``weak_yaw_std``); the
   fused pose is scored and ray-cast again, so every reported pose is one that was verified;
5. decide: ``ok`` when the verified score is at least ``min_score`` with at most the
   localizer's ``max_contradicting`` of the beams through walls, the fused position std is at
   most ``max_position_std`` and no rival in the window, distinct (the localizer's
   ``distinct_xy`` / ``distinct_yaw``, and along a direction the scan determines), scores within
   ``rival_margin`` and fits the prediction about as well (``rival_prior_chi2``; among poses the
   scan cannot tell apart the prediction picks), and the calibrated confidence of the pose's
   evidence (``evidence.py``, ``confidence.py``: judged as a global answer is, with the fused
   covariance and the rivals verified in the window) reaches the localizer's
   ``min_confidence``; ``ambiguous`` for a rival, a weak position or a confidence of at least
   one half below that (the track goes on); ``failed`` for a confidence below one half (step 7);
6. cross-check a doubtful ``ok``: a score under ``check_score`` and ``check_drop`` below the
   median of the last ones (the fit a scan gets in a look-alike corridor after a kidnap), or a
   prediction too uncertain for the window (no odometry): the localizer's correlative search
   over the whole map looks for a better place; only if it finds one does the whole global
   pipeline run, and its ``ok`` answer takes over;
7. fall back: when verification fails (a kidnap, a wrong start, a collapsed fit, a confidence
   below one half) the same scan goes through global localization: an ``ok`` there is a
   relocalization, anything else is reported as such (never ``ok``) and counts as a miss; after
   ``max_misses`` misses in a row the tracker is lost and localizes every scan globally until
   an ``ok``. A scan that fits nowhere but does not contradict the prediction (short returns
   in front of the walls: visitors, exhibits) is no miss: the prediction is held (``ambiguous``)
   while the odometry keeps it likely right (``_hold``).
8. coast: a scan with too few returns to track (an open hall seen by a short-range laser) is
   ray-cast at the prediction; if the map agrees that little is in range there and its few
   returns do not mostly pass through the map's walls, the prediction is the answer, its
   confidence the last verified pose's times the probability that the odometry kept it right
   (the covariance taken with the factor the track's own innovations give it, ``noise.py``;
   ``ok`` while that reaches ``min_confidence``); if not, a miss.
Before the first fix every scan is localized globally; ``set_prior`` (``initialpose``) starts a
track from a given pose, which the next scan verifies like any other prediction.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
import time
from typing import Literal

import numpy as np

from .confidence import confidence, within_right
from .evidence import covariance_stds, Evidence
from .fusion import fuse_weak, lever_arm_covariance, mahalanobis2
from .localizer import (AMBIGUOUS, FAILED, GlobalLocalizer, Hypothesis, Localization,
                        OK, position_std, Query, SparseScan, Status, STATUSES)
from .motion import check_pose, Increment, predict_parts
from .noise import NoiseScale
from .verify import BeamCheck
from ..config.confidence import ConfidenceModel, TRACK_CONFIDENCE_MODEL
from ..config.tracking import TrackerConfig
from ..transforms import apply, Pose2, wrap_angle

#: where a result's pose came from: the track, global localization, or nowhere verified
TRACKED, RELOCALIZED, LOST = 'tracked', 'relocalized', 'lost'
TRACK_MODES = (TRACKED, RELOCALIZED, LOST)
TrackMode = Literal['tracked', 'relocalized', 'lost']
#: covariance of a prior given without one: 0.5 m, 15 deg
DEFAULT_PRIOR_STD = (0.5, math.radians(15.0))


@dataclass
class TrackResult:
    """
    The answer for one scan.

    ``pose`` is the robot base in the map frame (the best guess when not ``ok``; None when there
    is none), ``predicted`` the motion prediction it started from.
    """

    status: Status
    pose: Pose2 | None
    covariance: np.ndarray = field(default_factory=lambda: np.diag([1e3, 1e3, 1e3]))
    mode: TrackMode = LOST
    stamp: float = math.nan
    latency_ms: float = 0.0
    score: float = math.nan
    node: int = -1
    message: str = ''
    predicted: Pose2 | None = None
    localization: Localization | None = None    # the global answer, when global localization ran
    confidence: float = 0.0                     # P(right | evidence), as for a Localization
    evidence: Evidence | None = None            # what the pose rests on

    @property
    def ok(self) -> bool:
        """Tell whether the answer is confident (``status == OK``)."""
        return self.status == OK

    def as_localization(self) -> Localization:
        """Return the answer as a :class:`Localization` (what the nodes publish and report)."""
        glob = self.localization
        return Localization(status=self.status, pose=self.pose, covariance=self.covariance,
                            node=self.node, score=self.score, confidence=self.confidence,
                            evidence=self.evidence,
                            candidates=list(glob.candidates) if glob is not None else [],
                            latency_ms=self.latency_ms, message=f'{self.mode}: {self.message}')


@dataclass
class _Attempt:
    """The outcome of tracking one scan around a prediction."""

    status: Status
    message: str
    pose: Pose2 | None = None
    covariance: np.ndarray | None = None
    score: float = math.nan
    truncated: bool = False      # the prediction's uncertainty reached beyond the window
    confidence: float = 0.0      # P(right | evidence) of the tracked pose
    evidence: Evidence | None = None
    scan_pose: Pose2 | None = None          # the scan's own pose, before the prediction is fused
    scan_covariance: np.ndarray | None = None   # and its covariance


class Tracker:
    """
    Pose tracking on the map of a :class:`GlobalLocalizer`, which it falls back on when lost.

    Not thread-safe: one caller feeds it scans in order.
    """

    def __init__(self, localizer: GlobalLocalizer, config: TrackerConfig | None = None,
                 confidence_model: ConfidenceModel = TRACK_CONFIDENCE_MODEL):
        if not isinstance(localizer, GlobalLocalizer):
            raise ValueError('the tracker needs a GlobalLocalizer built on a map index '
                             f'(got {type(localizer).__name__}: no map?)')
        self.localizer = localizer
        self.config = config or TrackerConfig()
        self.confidence_model = confidence_model
        self._pose: Pose2 | None = None
        self._cov = np.eye(3)
        self._odom: Pose2 | None = None
        self._misses = 0
        self._recent: list[float] = []          # scores of the last ok answers
        self._confidence = 0.0                  # of the last pose a scan verified
        self.relocalizations = 0
        # the odometry's noise scale, learnt from the steps between verified poses (noise.py)
        self.noise = NoiseScale(window=self.config.noise_window,
                                min_samples=self.config.noise_min_samples,
                                bounds=self.config.noise_scale_bounds,
                                covariance_bounds=self.config.carried_covariance_bounds)
        self._fresh = False                     # the belief is a pose the last scan verified
        # (prediction, odometry noise, prediction's covariance) of this scan
        self._step: tuple | None = None

    # -- state ----------------------------------------------------------------------------------
    @property
    def pose(self) -> Pose2 | None:
        """Return the current belief (base in the map frame); None when lost."""
        return self._pose

    @property
    def covariance(self) -> np.ndarray:
        """Return the covariance of the current belief."""
        return self._cov.copy()

    @property
    def lost(self) -> bool:
        """Tell whether there is no track (the next scan is localized globally)."""
        return self._pose is None

    def reset(self) -> None:
        """Forget the track (the next scan is localized globally) and the odometry reference."""
        self._pose, self._odom, self._misses = None, None, 0
        self._cov = np.eye(3)
        self._confidence = 0.0
        self._recent.clear()

    def set_prior(self, pose: Pose2, covariance: np.ndarray | None = None) -> None:
        """
        Start tracking from ``pose`` (base, map frame), e.g. an ``initialpose``.

        The prior is not reported as verified: the next scan is tracked around it (the window
        from its covariance, bounded) and falls back on global localization if it does not fit.
        See :meth:`check_prior` for what is refused.
        """
        self._pose, self._cov = self.check_prior(pose, covariance)
        self._misses, self._confidence = 0, 0.0

    @staticmethod
    def check_prior(pose: Pose2, covariance: np.ndarray | None = None) -> tuple[Pose2, np.ndarray]:
        """
        Return a prior as ``(pose, covariance)``; default covariance: 0.5 m, 15 deg.

        ``ValueError`` for a pose or covariance that is not finite, or a covariance that is not a
        symmetric positive definite 3x3 matrix.
        """
        x, y, yaw = check_pose(pose, 'prior pose')
        if covariance is None:
            xy, a = DEFAULT_PRIOR_STD
            return (x, y, float(wrap_angle(yaw))), np.diag([xy ** 2, xy ** 2, a ** 2])
        cov = np.asarray(covariance, float)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
            raise ValueError(f'prior covariance must be a finite 3x3 matrix, got shape '
                             f'{cov.shape}')
        cov = 0.5 * (cov + cov.T)
        if np.linalg.eigvalsh(cov).min() <= 0.0:
            raise ValueError('prior covariance must be positive definite')
        return (x, y, float(wrap_angle(yaw))), cov

    # -- per scan -------------------------------------------------------------------------------
    def track(self, scan, odom=None, stamp: float = math.nan) -> TrackResult:
        """
        Track one scan.

        ``scan`` is a :class:`Query` or has LaserScan fields (``ranges``, ``angle_min``,
        ``angle_increment``, ``range_min``, ``range_max``: a ``ScanRecord`` or a
        sensor_msgs/LaserScan); ``odom`` is the odometry pose ``(x, y, yaw)`` of the base in the
        odom frame at the scan's time, or None. Bad odometry or a bad scan give a ``failed``
        result with the reason and leave the state as it was (a bad scan still moves the
        prediction by the odometry).
        """
        t0 = time.perf_counter()
        try:
            odom = None if odom is None else check_pose(odom)
        except ValueError as exc:
            return self._result(t0, stamp, FAILED, None, f'bad odometry: {exc}')
        inc, note = None, ''
        if odom is not None and self._odom is not None:
            inc = Increment.between(self._odom, odom)
            if inc.trans > self.config.max_odom_step:
                inc, note = None, (f'odometry jumped {inc.trans:.1f} m: predicted without it; ')
        self._odom = odom
        pred = pred_cov = None
        self._step = None
        if self._pose is not None:
            pred, carried, noise = predict_parts(self._pose, self._cov, inc, self.config)
            pred_cov = carried + (self.noise.apply(noise) if inc is not None else noise)
            if self._fresh and inc is not None:
                self._step = (pred, noise, pred_cov)
            self._pose, self._cov = pred, pred_cov
        self._fresh = False
        try:
            query = scan if isinstance(scan, Query) else self.localizer.prepare_scan(
                scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                scan.range_max)
        except SparseScan as exc:
            if pred is None:
                return self._result(t0, stamp, FAILED, None, f'{note}bad scan: {exc}', mode=LOST)
            return self._coast(t0, stamp, exc, pred, pred_cov, note, inc is not None)
        except (AttributeError, TypeError, ValueError) as exc:
            self._miss()
            return self._result(t0, stamp, FAILED, pred, f'{note}bad scan: {exc}',
                                predicted=pred, mode=LOST if pred is None else TRACKED)
        if pred is None:
            return self._relocalize(t0, stamp, query, note + 'no track: ')
        attempt = self._track(query, pred, pred_cov)
        if attempt.status == FAILED:
            return self._relocalize(t0, stamp, query, f'{note}track lost ({attempt.message}): ',
                                    pred, pred_cov)
        if attempt.truncated or self._doubtful(attempt.score):
            return self._cross_check(t0, stamp, query, attempt, pred, note)
        return self._keep(t0, stamp, attempt, pred, note + attempt.message)

    # -- internals ------------------------------------------------------------------------------
    def _track(self, query: Query, pred: Pose2, pred_cov: np.ndarray) -> _Attempt:
        """Search, refine, gate, verify and fuse around one prediction."""
        cfg, loc = self.config, self.localizer
        laser = loc.laser_pose(pred)
        lcov = _laser_covariance(pred_cov, pred[2], loc.config.laser_pose)
        std = np.sqrt(np.maximum(np.diag(lcov), 0.0))
        reach = cfg.window_sigmas * std
        hx, hy = (float(np.clip(r, *cfg.window_xy)) for r in reach[:2])
        hyaw = float(np.clip(reach[2], *cfg.window_yaw))
        truncated = bool(max(reach[:2]) > cfg.window_xy[1] or reach[2] > cfg.window_yaw[1])
        n = int(math.ceil(hyaw / cfg.yaw_step))
        yaws = laser[2] + cfg.yaw_step * np.arange(-n, n + 1)
        leaves = loc.search_hypotheses(query, yaws, window=(laser[0] - hx, laser[1] - hy,
                                                            laser[0] + hx, laser[1] + hy))
        hyps = [Hypothesis(source='prior', initial_pose=laser)] + leaves[:cfg.track_hypotheses]
        refined = loc.refine(query, hyps, limit=len(hyps))
        gated = [h for h in refined if self._prior_m2(h, pred, pred_cov) <= cfg.gate_chi2]
        if not gated:
            return _Attempt(FAILED, f'no pose within the gate of the prediction '
                                    f'({len(refined)} refined)')
        # the best first, then only the poses that could still win or be a rival (within
        # ``rival_margin``): most scans cast one pose
        checked = loc.verify_contenders(query, gated, first=1, margin=cfg.rival_margin,
                                        plausible=self._plausible)
        verified = sorted((h for h in checked if h.check is not None),
                          key=lambda h: (not self._plausible(h), -h.score))
        top = verified[0]
        if not self._plausible(top):
            return _Attempt(FAILED, f'verification failed: explained {top.explained:.0%}, '
                                    f'through walls {top.contradicting:.0%}, score '
                                    f'{top.score:.2f}')
        # the poses the scan cannot tell apart: the prediction picks among them; each with the
        # squared Mahalanobis distance of its pose from the prediction
        contenders = [(h, self._prior_m2(h, pred, pred_cov)) for h in verified
                      if self._plausible(h) and h.score >= top.score - cfg.rival_margin]
        best, best_m2 = min(contenders, key=lambda c: c[1])
        pose, cov = fuse_weak(best.pose, best.covariance, pred, pred_cov, cfg.weak_std,
                              cfg.weak_yaw_std)
        fused = self._verified(query, best, pose)
        if not self._plausible(fused):
            fused, pose, cov = best, best.pose, best.covariance     # the scan's own pose
        # the evidence of the tracked pose, judged as a global answer is (the prediction's
        # part: the fused covariance; rivals: the distinct poses verified in the window)
        others = [h.score for h in verified if h is not best and loc.apart(h.pose, best.pose)]
        evidence = loc.evidence(query, fused, others)
        stds = covariance_stds(cov)
        evidence = replace(evidence, position_std=stds[0], yaw_std=stds[1],
                           prior_distance=math.sqrt(best_m2))
        conf = confidence(evidence, self.confidence_model)
        refused = min(conf, 0.5)        # the rules refuse: not more likely right than wrong
        common = {'pose': pose, 'covariance': cov, 'score': fused.score, 'truncated': truncated,
                  'confidence': conf, 'evidence': evidence, 'scan_pose': best.pose,
                  'scan_covariance': best.covariance}
        rivals = [h for h, m2 in contenders if h is not best
                  and m2 <= best_m2 + cfg.rival_prior_chi2
                  and loc.apart(h.pose, best.pose)
                  and mahalanobis2(h.pose, best.pose, h.covariance + best.covariance)
                  > cfg.rival_chi2]
        if rivals:
            return _Attempt(AMBIGUOUS, f'{len(rivals) + 1} distinct poses near the prediction '
                                       f'fit about equally well',
                            **dict(common, confidence=refused))
        std_xy = position_std(cov)
        if std_xy > cfg.max_position_std:
            return _Attempt(AMBIGUOUS, f'position std {std_xy:.2f} m along the weakest '
                                       f'direction even with the prediction',
                            **dict(common, confidence=refused))
        facts = (f'explained {best.explained:.0%}, through walls {fused.contradicting:.0%}, '
                 f'position std {std_xy * 1e3:.0f} mm, confidence {conf:.3f}')
        if conf < cfg.lost_confidence:
            return _Attempt(FAILED, f'the tracked pose is more likely wrong than right: {facts}',
                            **common)
        if conf < cfg.min_confidence:
            return _Attempt(AMBIGUOUS, f'tracked with low confidence: {facts}', **common)
        return _Attempt(OK, f'tracked: {facts}', **common)

    def _plausible(self, h: Hypothesis) -> bool:
        """Tell whether a verified pose explains enough of the scan, few beams through walls."""
        return (h.score >= self.config.min_score
                and h.contradicting <= self.localizer.config.max_contradicting)

    @staticmethod
    def _prior_m2(h: Hypothesis, pred: Pose2, pred_cov: np.ndarray) -> float:
        """Return the squared Mahalanobis distance of ``h`` from the prediction."""
        return mahalanobis2(h.pose, pred, pred_cov + h.covariance)

    def _verified(self, query: Query, best: Hypothesis, pose: Pose2) -> Hypothesis:
        """
        Verify ``pose``, ``best`` moved by the fusion: explained fraction and ray casting.

        Returns ``best`` itself when the fusion left it where it was (within 1 cm, 0.2 deg).
        """
        if mahalanobis2(pose, best.pose, np.diag([0.01 ** 2, 0.01 ** 2, 0.003 ** 2])) <= 1.0:
            return best
        return self.localizer.verified_at(query, pose, best)

    def _doubtful(self, score: float) -> bool:
        """
        Tell whether a tracked score is poor and clearly worse than the last ones.

        That is the kind of fit a scan gets in a look-alike corridor after a kidnap (or in a
        crowd).
        """
        cfg = self.config
        if not self._recent:
            return False
        return score < cfg.check_score and score < float(np.median(self._recent)) - cfg.check_drop

    def _cross_check(self, t0: float, stamp: float, query: Query, attempt: _Attempt,
                     pred: Pose2, note: str) -> TrackResult:
        """
        Check a doubtful tracked scan against the rest of the map.

        First cheaply: the localizer's correlative search over the whole map at the tracked yaw,
        its flip and the map-aligned yaws; its leaves distinct from the tracked pose are refined
        and verified. Only if one scores ``switch_margin`` better does the whole global pipeline
        run: its ``ok`` answer takes over (a relocalization), anything else makes the track
        ``ambiguous``.
        """
        cfg, loc = self.config, self.localizer
        yaws = loc.search_yaws(query, [loc.laser_pose(attempt.pose)[2]])
        others = [h for h in loc.search_hypotheses(query, yaws)
                  if loc.apart(loc.base_pose(h.initial_pose), attempt.pose)]
        rival = None
        if others:
            refined = loc.refine(query, others, limit=cfg.check_hypotheses)
            refined = loc.verify(query, [h for h in refined
                                         if loc.apart(h.pose, attempt.pose)][:2])
            rival = max(refined, key=lambda h: h.score, default=None)
        if rival is None or rival.score < attempt.score + cfg.switch_margin:
            found = 'no other place' if rival is None else f'elsewhere {rival.score:.2f}'
            return self._keep(t0, stamp, attempt, pred, f'{note}{attempt.message} (a poor fit, '
                              f'score {attempt.score:.2f}, cross-checked: {found})')
        glob = loc.localize_query(query)
        why = (f'{note}the tracked pose fits poorly (score {attempt.score:.2f}) and another place '
               f'better (score {rival.score:.2f}): ')
        if glob.status == OK and loc.apart(glob.pose, attempt.pose):
            return self._adopt(t0, stamp, glob, why + 'kidnapped? relocalized: ', pred)
        if glob.status == OK:
            return self._keep(t0, stamp, attempt, pred, why + 'global localization confirms '
                              'the track', glob)
        self._miss()
        return self._result(t0, stamp, AMBIGUOUS, attempt.pose, why + f'global localization '
                            f'{glob.status}: {glob.message}', covariance=attempt.covariance,
                            score=attempt.score, predicted=pred, mode=TRACKED,
                            localization=glob, confidence=min(attempt.confidence, 0.5),
                            evidence=attempt.evidence)

    def _coast(self, t0: float, stamp: float, sparse: SparseScan, pred: Pose2,
               pred_cov: np.ndarray, note: str, odometry: bool) -> TrackResult:
        """
        Carry the track over a scan with too few returns to track, if the map agrees.

        The scan's beams are ray-cast at the prediction. Where the map has no wall within the
        sensor's range either (an open hall seen by a short-range laser), at most
        ``coast_disagreement`` of them disagreeing and no more than half of its returns passing
        through walls (a few returns from behind the map's walls say the prediction is off even
        when the many empty beams agree), the prediction is the answer: its confidence is the
        last verified pose's times the probability that the odometry kept it right
        (:meth:`_carried_confidence`), ``ok`` from the tracker's ``min_confidence`` on. Such a
        scan is no evidence against the track, so it is no miss: the next scan that sees enough
        is tracked in a window grown with the covariance (and cross-checked against the whole
        map when the window cannot hold it). Otherwise the scan is evidence against the track:
        a miss. A scan with no measurement at all (every beam NaN or outside its range) is no
        evidence either way: ``failed``, no miss.

        With odometry, the prediction's floor (``min_step_std``: odometry and scan stamps out of
        step) is an error of one scan's stamp, not a random walk: over scans the track coasts
        through it is counted once, for the latest, and the odometry's own noise accumulates.
        """
        cfg = self.config
        why = f'{note}{sparse}'
        check, disagree = self._disagreement(pred, sparse)
        common = {'covariance': pred_cov, 'predicted': pred, 'mode': TRACKED}
        if disagree > cfg.coast_disagreement:
            self._miss()
            return self._result(t0, stamp, FAILED, pred, f'{why}: {disagree:.0%} of its beams '
                                'disagree with the map at the prediction', **common)
        if check.through > check.returns - check.through:
            self._miss()
            return self._result(t0, stamp, FAILED, pred, f'{why}: {check.through} of its '
                                f'{check.returns} returns pass through walls of the map at the '
                                'prediction', **common)
        if odometry:                 # no update: the stamps' floor goes with the next scan
            xy, yaw = cfg.min_step_std
            self._cov = pred_cov - self.noise.apply(np.diag([xy ** 2, xy ** 2, yaw ** 2]))
        if check.beams == 0:         # no measurement at all (NaN, out of range): no evidence
            return self._result(t0, stamp, FAILED, pred, f'bad scan: {why}, and not one beam '
                                'measured anything (NaN or outside [range_min, range_max])',
                                **common)
        conf = self._carried_confidence(pred_cov)
        status = OK if conf >= cfg.min_confidence else AMBIGUOUS
        return self._result(t0, stamp, status, pred, f'{why}: coasting on odometry, the map '
                            f'agrees with {1.0 - disagree:.0%} of its beams, confidence '
                            f'{conf:.3f}', confidence=conf, **common)

    def _disagreement(self, pred: Pose2, scan: SparseScan | Query) -> tuple[BeamCheck, float]:
        """
        Ray-cast a scan at the prediction; return the check and the fraction that disagrees.

        Disagreeing: a return through a wall, or no return where a wall is within range (what
        :meth:`_coast` and :meth:`_hold` ask before carrying the prediction over a scan).
        """
        check = self.localizer.check_at(pred, scan)
        return check, (check.missing + check.through) / max(check.beams, 1)

    def _carried_confidence(self, pred_cov: np.ndarray) -> float:
        """
        Return the last verified pose's confidence times P(the odometry kept it right).

        The covariance is taken with the factor the track's own innovations give it
        (``NoiseScale.covariance``, within ``carried_covariance_bounds``): the reported
        covariances are conservative by a factor that differs by robot and building.
        """
        return self._confidence * within_right(self.noise.covariance * pred_cov)

    def _keep(self, t0: float, stamp: float, attempt: _Attempt, pred: Pose2, message: str,
              glob: Localization | None = None) -> TrackResult:
        """
        Make an ``ok`` tracked pose the belief; any other leaves the prediction as the belief.

        A pose that is not ``ok`` may be the wrong one of look-alikes along a corridor (the
        prediction picked it among poses the scan cannot tell apart): the track does not follow
        it, so that the next scans are judged against the odometry, not against a guess.
        """
        self._misses = 0
        if attempt.status == OK:
            if self._step is not None and attempt.scan_pose is not None:
                pred_step, noise, pred_cov = self._step
                self.noise.add(attempt.scan_pose, pred_step, noise,
                               None if attempt.scan_covariance is None
                               else pred_cov + attempt.scan_covariance)
            self._pose, self._cov = attempt.pose, attempt.covariance
            self._confidence = attempt.confidence
            self._fresh = True
            self._remember(attempt.score)
        return self._result(t0, stamp, attempt.status, attempt.pose, message,
                            covariance=attempt.covariance, score=attempt.score, predicted=pred,
                            mode=TRACKED, localization=glob, confidence=attempt.confidence,
                            evidence=attempt.evidence)

    def _adopt(self, t0: float, stamp: float, glob: Localization, message: str,
               pred: Pose2 | None) -> TrackResult:
        """Make an ``ok`` global answer the belief: a relocalization."""
        self._pose, self._cov, self._misses = glob.pose, glob.covariance, 0
        self._confidence = glob.confidence
        self._fresh = True
        self._recent.clear()
        self._remember(glob.score)
        self.relocalizations += 1
        return self._result(t0, stamp, OK, glob.pose, message + glob.message,
                            covariance=glob.covariance, score=glob.score, node=glob.node,
                            predicted=pred, mode=RELOCALIZED, localization=glob,
                            confidence=glob.confidence, evidence=glob.evidence)

    def _remember(self, score: float) -> None:
        self._recent.append(score)
        del self._recent[:-max(self.config.check_history, 1)]

    def _relocalize(self, t0: float, stamp: float, query: Query, why: str,
                    pred: Pose2 | None = None, pred_cov: np.ndarray | None = None) -> TrackResult:
        """Localize ``query`` globally; an ``ok`` answer becomes the track."""
        glob = self.localizer.localize_query(query)
        if glob.status == OK:
            where = ''
            if pred is not None:
                m2 = mahalanobis2(glob.pose, pred, pred_cov + glob.covariance)
                where = ('far from the prediction (kidnapped?): ' if m2 > self.config.gate_chi2
                         else 'near the prediction: ')
            return self._adopt(t0, stamp, glob, f'{why}relocalized {where}', pred)
        if pred is not None:
            held = self._hold(t0, stamp, query, pred, pred_cov, why, glob)
            if held is not None:
                return held
        self._miss()
        return self._result(t0, stamp, glob.status, glob.pose if glob.pose is not None else pred,
                            f'{why}global localization {glob.status}: {glob.message}',
                            covariance=glob.covariance, score=glob.score, node=glob.node,
                            predicted=pred, mode=LOST, localization=glob,
                            confidence=glob.confidence, evidence=glob.evidence)

    def _hold(self, t0: float, stamp: float, query: Query, pred: Pose2, pred_cov: np.ndarray,
              why: str, glob: Localization) -> TrackResult | None:
        """
        Keep the prediction over a scan that fits nowhere but does not contradict it.

        A scan mostly of things the map does not hold (visitors, exhibits, furniture seen by a
        short-range laser) explains too little anywhere, at the right pose too; when global
        localization finds no ``ok`` either and at the prediction at most
        ``coast_disagreement`` of its beams disagree with the map (a return through a wall, no
        return where a wall is in range: the short returns are clutter in front of the walls),
        the scan is no evidence against the track. The prediction stays the belief and the
        scan is no miss, as for a scan with too few returns (:meth:`_coast`), but it is never
        ``ok``: its confidence is the last verified pose's times the probability that the
        odometry kept it right, capped at one half. Once that falls below ``lost_confidence``
        the track is not held any longer (None: a miss).
        """
        cfg = self.config
        conf = self._carried_confidence(pred_cov)
        if conf < cfg.lost_confidence:
            return None
        _, disagree = self._disagreement(pred, query)
        if disagree > cfg.coast_disagreement:
            return None
        return self._result(t0, stamp, AMBIGUOUS, pred, f'{why}global localization '
                            f'{glob.status}; holding the prediction: the map agrees with '
                            f'{1.0 - disagree:.0%} of its beams there (clutter?), confidence '
                            f'{conf:.3f}', covariance=pred_cov, predicted=pred, mode=TRACKED,
                            localization=glob, confidence=min(conf, 0.5))

    def _miss(self) -> None:
        """Count a scan without a verified pose; too many in a row and the track is dropped."""
        self._misses += 1
        if self._misses > self.config.max_misses:
            self._pose, self._misses = None, 0
            self._recent.clear()

    @staticmethod
    def _result(t0: float, stamp: float, status: Status, pose: Pose2 | None, message: str,
                **kwargs) -> TrackResult:
        return TrackResult(status=status, pose=pose, stamp=stamp, message=message,
                           latency_ms=(time.perf_counter() - t0) * 1e3, **kwargs)


def _laser_covariance(cov: np.ndarray, base_yaw: float, laser_on_base: Pose2) -> np.ndarray:
    """Return the covariance of the laser pose ``base * laser_on_base`` (first order)."""
    off = apply((0.0, 0.0, base_yaw), laser_on_base[:2])[0]      # base -> laser, in the map
    return lever_arm_covariance(cov, off)


__all__ = ['STATUSES', 'TRACK_MODES', 'TrackResult', 'Tracker']
