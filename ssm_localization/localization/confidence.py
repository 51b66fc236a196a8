"""
``P(right | evidence)``: the calibrated confidence reported with every answer (beyond the paper).

The model (``config/confidence.py``) is a score of the features below -- a logistic regression
plus boosted regression trees for global answers, a logistic regression for tracked ones --
mapped to a probability by an isotonic map, fitted by ``scripts/learn_confidence.py`` on
labelled answers of the calibration buildings and checked on buildings it never saw (``bench
localize`` prints the reliability of its probabilities and draws the diagram). A status of
``ok`` needs at least ``LocalizerConfig.min_confidence``. The
tracker's poses have a model of their own (``TRACK_CONFIDENCE_MODEL``): the same evidence plus
how far the scan's own pose lies from the motion prediction, fitted on tracked answers.
"""
from __future__ import annotations

import math

import numpy as np

from .evidence import Evidence
from ..config.confidence import CALIBRATION_RESOLUTION, ConfidenceModel, RIGHT_XY, RIGHT_YAW

#: the margin to the best distinct rival is clipped to this (a larger lead adds nothing)
MAX_MARGIN = 1.0


def feature_values(ev: Evidence) -> dict[str, float]:
    """
    Return the model's inputs made from the evidence of one answer.

    Fractions as they are; the margin clipped to +-:data:`MAX_MARGIN`; standard deviations and
    the count of returns on a log scale (their effect is one of ratios).
    """
    return {
        'hit': ev.hit,
        'through': ev.through,
        'short': ev.short,
        'missing': ev.missing,
        'on_wall': ev.on_wall,
        'unknown': ev.unknown,
        'unexplained_runs': ev.unexplained_runs,
        'explained': ev.explained,
        'margin': max(-MAX_MARGIN, min(MAX_MARGIN, ev.margin)),
        'log_position_std': math.log(max(ev.position_std, 1e-3)),
        'log_yaw_std': math.log(max(ev.yaw_std, 1e-4)),
        'log_returns': math.log(max(ev.returns, 1)),
        'log_scan_length': math.log(max(ev.scan_length, 0.5)),
        'log_extent': math.log(max(ev.extent, 0.1)),
        'close_rivals': float(ev.close_rivals),
        'near_rivals': float(ev.near_rivals),
        'return_fraction': ev.return_fraction,
        'log_prior_distance': math.log1p(ev.prior_distance),      # NaN for a global answer
        'log_scan_position_std': math.log(max(ev.scan_position_std, 1e-3)),
    }


def confidence(ev: Evidence | None, model: ConfidenceModel) -> float:
    """Return ``P(right | evidence)`` of one answer (0 when there is no evidence: no pose)."""
    if ev is None:
        return 0.0
    values = feature_values(ev)
    if not all(math.isfinite(values[f]) for f in model.features):
        return 0.0
    return model.probability(values)


def resolution_warning(resolution: float) -> str:
    """
    Return a warning for a map of coarser cells than the calibration buildings' ('' otherwise).

    The confidence was fitted on real buildings mapped at :data:`CALIBRATION_RESOLUTION`. On the
    six real buildings' maps built at 0.1 m both success and precision are lower (``bench
    localize --map-resolution 0.1``; docs/DESIGN.md, "Map resolution"), and widening the
    evidence's tolerances by the coarser cells moved wrong ``ok`` answers rather than removing
    them, so the verdict is left as calibrated and the user is told.
    """
    if not resolution > CALIBRATION_RESOLUTION * (1.0 + 1e-6):
        return ''
    return (f"the map's cells are {resolution:g} m, coarser than the {CALIBRATION_RESOLUTION:g} "
            f"m cells of the buildings' maps the confidence was calibrated on: on such maps "
            f'fewer scans are ok and an ok pose is less certain to be right (docs/DESIGN.md, '
            f'"Map resolution"); a map of {CALIBRATION_RESOLUTION:g} m cells localizes best')


def within_right(cov) -> float:
    """
    Return the probability that a pose with Gaussian error ``cov`` (x, y, yaw) is still right.

    Right as the confidence means it: within ``RIGHT_XY`` and ``RIGHT_YAW`` of the truth. The
    position error's probability of lying within the circle is exact for its 2-D Gaussian
    (:func:`within_circle`); the yaw error is taken as independent of it. The tracker's
    confidence in a pose carried over a scan with nothing to verify is that of the last
    verified pose times this.
    """
    cov = np.asarray(cov, float)
    std_yaw = math.sqrt(max(float(cov[2, 2]), 1e-12))
    return within_circle(cov[:2, :2], RIGHT_XY) * math.erf(RIGHT_YAW / (math.sqrt(2.0) * std_yaw))


def within_circle(cov, radius: float, n: int = 64) -> float:
    """
    Return ``P(|e| <= radius)`` for a 2-D Gaussian error ``e ~ N(0, cov)``.

    With ``e = L w`` (``w`` standard normal, ``L`` the covariance's square root) and ``w`` in
    polar coordinates, the radial integral is closed: along the direction ``phi`` the error
    stays within the circle up to ``|w| = radius / |L u(phi)|``, with probability
    ``1 - exp(-radius^2 / (2 |L u(phi)|^2))``. The directions are averaged by the midpoint rule
    over a half turn (``w`` and ``-w`` are alike): exact to 1e-6 with ``n`` 64, whatever the
    axis ratio (the integrand changes with ``radius`` against the larger std, not the smaller).
    """
    cov = np.asarray(cov, float)
    values = np.maximum(np.linalg.eigvalsh(0.5 * (cov + cov.T)), 1e-12)
    phi = (np.arange(n) + 0.5) * math.pi / n
    spread = values[0] * np.cos(phi) ** 2 + values[1] * np.sin(phi) ** 2
    return float(np.mean(-np.expm1(-0.5 * radius ** 2 / spread)))
