"""Tracker settings (``localization/tracker.py``): motion model, search window, decisions."""
from __future__ import annotations

from dataclasses import dataclass, fields
import math

from .fields import check_numbers, param

#: fields that must be > 0 (the rest must be >= 0); tuples are checked element by element
_POSITIVE = {'min_step_std', 'no_odom_std', 'max_odom_step', 'window_sigmas', 'window_xy',
             'window_yaw', 'yaw_step', 'gate_chi2', 'weak_std', 'weak_yaw_std', 'max_position_std',
             'rival_chi2', 'rival_prior_chi2', 'noise_scale_bounds', 'carried_covariance_bounds',
             'noise_window', 'noise_min_samples'}


@dataclass(frozen=True)
class TrackerConfig:
    """
    Parameters of the tracker (the global localizer it falls back on has its own).

    Lengths in metres, angles in radians. The motion noise follows AMCL's ``diff`` odometry
    model: the odometry increment is split into a rotation, a translation and a rotation; their
    variances grow with the motion (``odom_alphas``: AMCL's ``alpha1..alpha4`` with their
    meaning), plus a floor.
    """

    # -- motion model (prediction)
    odom_alphas: tuple[float, float, float, float] = param(
        (0.01, 0.001, 0.01, 0.005),
        "AMCL's odom_alpha1..4: rotation variance per rad^2 turned and per m^2 travelled, "
        'translation variance per m^2 travelled and per rad^2 turned')
    min_step_std: tuple[float, float] = param(
        (0.05, math.radians(2.0)), 'noise added to every prediction, (metres, rad) std: '
        'odometry and scan stamps are never quite in step')
    no_odom_std: tuple[float, float] = param(
        (1.0, math.radians(45.0)), 'std of the motion between two scans when there is no '
        'odometry (the pose is predicted to stay put), (metres, rad)')
    noise_scale_bounds: tuple[float, float] = param(
        (0.02, 4.0), "bounds of the scales of the odometry's noise (position, heading) that the "
        'tracker learns from the steps between verified poses (localization/noise.py); (1, 1): '
        'the alphas as given')
    carried_covariance_bounds: tuple[float, float] = param(
        (0.25, 4.0), "bounds of the factor the tracker learns for its poses' covariance from the "
        'same steps (the median squared Mahalanobis distance of the scan pose from the '
        'prediction over its chi-square median), applied when it judges how likely the odometry '
        'alone kept a pose right (a scan with nothing to verify); (1, 1): the covariance as '
        'reported')
    noise_window: int = param(50, 'last steps between verified poses the noise scales are '
                                  'learnt from')
    noise_min_samples: int = param(10, 'steps needed before the noise scales move from 1')
    max_odom_step: float = param(
        5.0, 'an odometry increment longer than this between two scans is a jump (reset or '
        'glitch): predicted as no odometry, m')
    # -- search window around the prediction
    window_sigmas: float = param(3.0, 'the window spans the prediction +- this many std')
    window_xy: tuple[float, float] = param(
        (0.3, 1.5), 'half-width of the searched window of positions, (min, max) metres')
    window_yaw: tuple[float, float] = param(
        (math.radians(6.0), math.radians(30.0)), 'half-width of the searched yaws, (min, max) rad')
    yaw_step: float = param(math.radians(1.0), 'yaw step of the windowed search, rad')
    track_hypotheses: int = param(3, 'search leaves refined beside the prediction itself')
    gate_chi2: float = param(
        16.3, 'squared Mahalanobis distance of a refined pose from the prediction beyond which '
        'it is not the tracked pose (chi-square, 3 dof, 99.9 %)')
    weak_std: float = param(
        0.1, "position directions along which the scan's std exceeds this (a corridor's axis) "
        'take the prediction in, metres')
    weak_yaw_std: float = param(
        math.radians(5.0), "a scan's yaw std above this (a few short returns that hardly turn "
        'the pose) takes the prediction in along the yaw too, rad')
    # -- decisions
    min_score: float = param(
        0.4, 'a tracked pose scoring less (explained fraction minus the through-wall penalty) '
        'has lost the track: global localization runs on the same scan')
    max_position_std: float = param(
        0.25, 'a larger position std along the weakest direction after fusing the prediction: '
        'ambiguous, m')
    rival_margin: float = param(
        0.02, "a rival in the window, distinct (the localizer's distinct_xy / distinct_yaw, and "
        'along a direction the scan determines), scoring within this of the best: ambiguous')
    rival_chi2: float = param(
        9.0, "squared Mahalanobis distance (in the two poses' summed scan covariances) beyond "
        'which two poses are distinct')
    rival_prior_chi2: float = param(
        6.0, 'a rival further from the prediction than the chosen pose by more than this '
        '(squared Mahalanobis distance; 6: a likelihood ratio of 5 %) is not a rival')
    check_score: float = param(
        0.75, 'a tracked pose scoring less than this and check_drop less than the median of the '
        'last ok scores is cross-checked by global localization on the same scan (a kidnap into '
        'a look-alike corridor fits like that)')
    check_drop: float = param(0.1, 'see check_score')
    switch_margin: float = param(
        0.05, 'a cross-check answer distinct from the tracked pose and scoring at least this '
        'much better takes over (ok) or makes the track ambiguous')
    check_history: int = param(3, 'last ok scores whose median check_drop is measured from')
    check_hypotheses: int = param(3, 'places elsewhere the cross-check refines')
    max_misses: int = param(
        3, 'scans in a row without a verified pose after which the track is dropped and the '
        'tracker is lost')
    min_confidence: float = param(
        0.93, 'a tracked pose that passes the rules is ok only when its calibrated confidence '
        'P(right | evidence, prediction) reaches this (on the calibration logs: no wrong ok as '
        'recorded or at 120 deg, 0.7 % at 3.5 m)')
    lost_confidence: float = param(
        0.5, 'a tracked pose less likely right than this has lost the track: the same scan '
        'goes through global localization')
    coast_disagreement: float = param(
        0.1, 'a scan with too few returns to track (an open space, a short-range laser) is '
        'ray-cast at the prediction: when at most this fraction of its beams disagrees with the '
        'map (no return where a wall is in range, a return through a wall) the track coasts on '
        'the odometry; otherwise the scan counts as a miss. The same test holds the track '
        '(ambiguous, no miss) through a scan that fits nowhere, its returns short of the walls '
        '(clutter)')

    def __post_init__(self) -> None:
        names = [f.name for f in fields(self)]
        check_numbers(self, [n for n in names if n in _POSITIVE],
                      [n for n in names if n not in _POSITIVE])
        for name in ('min_confidence', 'lost_confidence', 'coast_disagreement'):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f'TrackerConfig.{name} must be in [0, 1], got '
                                 f'{getattr(self, name)!r}')
        for name in ('noise_scale_bounds', 'carried_covariance_bounds'):
            lo, hi = getattr(self, name)
            if not lo <= 1.0 <= hi:
                raise ValueError(f'TrackerConfig.{name} must be (lo, hi) with lo <= 1 <= hi, got '
                                 f'{getattr(self, name)!r}')
        if self.noise_min_samples > self.noise_window:
            raise ValueError(f'TrackerConfig: noise_min_samples must be at most noise_window, got '
                             f'{self.noise_min_samples} and {self.noise_window}')
        for name in ('window_xy', 'window_yaw'):
            if getattr(self, name)[0] > getattr(self, name)[1]:
                raise ValueError(f'TrackerConfig.{name} must be (min, max) with min <= max, got '
                                 f'{getattr(self, name)!r}')
