"""
How noisy this robot's odometry is, learnt from the scans that verify it (beyond the paper).

The motion model (``motion.py``) has one set of ``odom_alphas`` for every robot; real odometry
differs by an order of magnitude between robots (on the CARMEN logs the squared Mahalanobis
error of one step under the default alphas averages 0.5 on one robot and 4.5 on another; 3 when
they fit). A track that has to coast on the odometry (an open hall seen by a short-range laser)
is only as trustworthy as that noise is right: too large and a right pose is given up after
one scan, too small and a wrong one is kept.

So the tracker scales the odometry's noise, its position part by ``s_xy`` and its heading part by
``s_yaw`` (``S Q S`` with ``S = diag(sqrt s_xy, sqrt s_xy, sqrt s_yaw)``: robots differ in how
much worse they turn than they drive, too), estimated from its own innovations after the
innovation-based adaptive estimation of a Kalman filter's process noise (Mehra, "On the
identification of variances and adaptive Kalman filtering", IEEE TAC 1970; Mohamed & Schwarz,
J. Geodesy 1999). Each step between two verified poses gives an innovation ``d``: the scan's own
pose minus the prediction from the last verified pose. ``s_xy`` is the median of
``d_xy^T Q_xy^-1 d_xy`` over the last ``window`` steps divided by the median of a chi-square
with 2 degrees of freedom, ``s_yaw`` the median of ``d_yaw^2 / Q_yaw`` divided by that of 1
degree (``Q`` being the odometry noise of each step; a median: a step that slipped or a pose
that was not quite right moves it little); each bounded by ``bounds``, and 1 until
``min_samples`` steps are in. The two poses' own errors are left in ``d`` and out of the
covariance: the scales err on the large (safe) side by them. (Their covariances are
conservative, about twice their errors' spread on the Intel log; counting them in would put the
innovations on them and the scales too low.)

The same innovations say how conservative the track's own covariance is: with ``S`` the
prediction's covariance plus the scan pose's, ``d^T S^-1 d`` is chi-square with 3 degrees of
freedom when both are right. Its median over the window divided by that chi-square's median is
``covariance`` (bounded by ``covariance_bounds``, 1 until ``min_samples`` steps are in): the
factor the tracker applies to a pose's covariance when it judges the probability that the
odometry alone kept the pose right (a scan with nothing to verify). The reported covariances are
left as they are.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
import math

import numpy as np
from scipy.special import chdtri

from .fusion import difference, mahalanobis2
from ..transforms import Pose2

#: the medians of chi-square variables with 3, 2 and 1 degrees of freedom
CHI2_3_MEDIAN = float(chdtri(3, 0.5))
CHI2_2_MEDIAN = float(chdtri(2, 0.5))
CHI2_1_MEDIAN = float(chdtri(1, 0.5))


@dataclass
class NoiseScale:
    """The odometry noise scales, the track covariance's factor, and their innovations."""

    window: int = 50
    min_samples: int = 10
    bounds: tuple[float, float] = (0.02, 4.0)
    covariance_bounds: tuple[float, float] = (1.0, 1.0)
    position: float = 1.0
    heading: float = 1.0
    covariance: float = 1.0
    _steps: deque = field(init=False, repr=False)

    def __post_init__(self) -> None:
        lo, hi = self.bounds
        clo, chi = self.covariance_bounds
        if not (0.0 < lo <= 1.0 <= hi and math.isfinite(hi)) or self.window < self.min_samples \
                or self.min_samples < 1 or not (0.0 < clo <= 1.0 <= chi and math.isfinite(chi)):
            raise ValueError(f'NoiseScale: bounds and covariance_bounds (lo, hi) with 0 < lo <= '
                             f'1 <= hi and 1 <= min_samples <= window, got bounds '
                             f'{self.bounds!r}, covariance_bounds {self.covariance_bounds!r}, '
                             f'window {self.window}, min_samples {self.min_samples}')
        self._steps = deque(maxlen=self.window)

    def __len__(self) -> int:
        return len(self._steps)

    def reset(self) -> None:
        """Forget every step (a different robot or odometry source)."""
        self._steps.clear()
        self.position = self.heading = self.covariance = 1.0

    def apply(self, noise: np.ndarray) -> np.ndarray:
        """Return the odometry noise ``noise`` (x, y, yaw covariance) scaled: ``S Q S``."""
        root = np.sqrt([self.position, self.position, self.heading])
        return np.asarray(noise, float) * np.outer(root, root)

    def add(self, measured: Pose2, predicted: Pose2, noise: np.ndarray,
            innovation_cov: np.ndarray | None = None) -> tuple[float, float]:
        """
        Add one step and return the new scales ``(position, heading)``.

        ``measured``: the scan's own pose; ``predicted``: the prediction from the last verified
        pose; ``noise``: the odometry's noise of the step (Q, unscaled); ``innovation_cov``: the
        prediction's covariance plus the scan pose's (None: the step says nothing about the
        covariance's factor). A step that is not finite, or whose noise is singular, is left
        out.
        """
        d = difference(measured, predicted)
        noise = np.asarray(noise, float)
        if noise.shape == (3, 3) and np.all(np.isfinite(noise)) and np.all(np.isfinite(d)) \
                and np.linalg.eigvalsh(0.5 * (noise + noise.T)).min() > 0.0:
            xy = float(d[:2] @ np.linalg.solve(noise[:2, :2], d[:2]))
            # the covariance's factor: a step without a covariance (or a singular one) says
            # nothing of it (NaN, inf: left out of its median)
            nis = (math.nan if innovation_cov is None
                   else mahalanobis2(measured, predicted, innovation_cov))
            self._steps.append((xy, float(d[2] ** 2 / noise[2, 2]), nis))
            self.position, self.heading, self.covariance = self.estimate()
        return self.position, self.heading

    def estimate(self) -> tuple[float, float, float]:
        """
        Return ``(s_xy, s_yaw, covariance)`` of the steps held.

        Each is 1 with fewer than ``min_samples`` steps (for the covariance's factor: steps that
        gave an innovation covariance).
        """
        if len(self._steps) < self.min_samples:
            return 1.0, 1.0, 1.0
        steps = np.array(self._steps)
        xy, yaw = np.median(steps[:, :2], axis=0)
        nis = steps[np.isfinite(steps[:, 2]), 2]
        cov = (_within(float(np.median(nis)) / CHI2_3_MEDIAN, self.covariance_bounds)
               if len(nis) >= self.min_samples else 1.0)
        return (_within(float(xy) / CHI2_2_MEDIAN, self.bounds),
                _within(float(yaw) / CHI2_1_MEDIAN, self.bounds), cov)


def _within(value: float, bounds: tuple[float, float]) -> float:
    """Return ``value`` clamped to ``bounds`` ``(lo, hi)``."""
    return min(max(value, bounds[0]), bounds[1])
