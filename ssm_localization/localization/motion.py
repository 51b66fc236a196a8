"""
Odometry motion model: a pose and its covariance moved by an odometry increment.

AMCL's ``diff`` model (Thrun et al., Probabilistic Robotics, 5.4): the increment between two
odometry poses is a rotation ``rot1`` towards the direction of travel, a translation ``trans`` and
a rotation ``rot2``; their variances are ``alpha1 rot^2 + alpha2 trans^2`` (rotations) and
``alpha3 trans^2 + alpha4 (rot1^2 + rot2^2)`` (translation), the alphas being
``TrackerConfig.odom_alphas``. Here the pose is a Gaussian: the prediction is the increment
composed onto the pose, its covariance the previous one moved along (first order) plus the motion
noise, plus a floor (``min_step_std``). Backward motion is turned around (AMCL does the same), so
a reversing robot does not look like a half turn.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .fusion import lever_arm_covariance
from ..config.tracking import TrackerConfig
from ..files.reading import echo
from ..transforms import compose, inverse, Pose2, wrap_angle


@dataclass(frozen=True)
class Increment:
    """The motion between two odometry poses, in the frame of the first."""

    delta: Pose2                 # (dx, dy, dyaw) in the earlier base frame
    rot1: float
    trans: float
    rot2: float

    @classmethod
    def between(cls, before: Pose2, after: Pose2) -> 'Increment':
        delta = compose(inverse(before), after)
        trans = math.hypot(delta[0], delta[1])
        rot1 = math.atan2(delta[1], delta[0]) if trans > 0.01 else 0.0
        if abs(rot1) > math.pi / 2.0:        # driving backwards
            rot1 = float(wrap_angle(rot1 + math.pi))
        rot2 = float(wrap_angle(delta[2] - rot1))
        return cls(delta=delta, rot1=rot1, trans=trans, rot2=rot2)


def check_pose(pose, what: str = 'odometry pose') -> Pose2:
    """Return ``pose`` as three finite floats; ``ValueError`` naming ``what`` otherwise."""
    try:
        values = tuple(float(v) for v in pose)
    except (TypeError, ValueError):
        raise ValueError(f'{what} must be (x, y, yaw), got {echo(pose)}') from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise ValueError(f'{what} must be three finite numbers (x, y, yaw), got {echo(pose)}')
    return values


def motion_noise(inc: Increment, config: TrackerConfig) -> np.ndarray:
    """Return the (3, 3) covariance of the increment ``(dx, dy, dyaw)`` (earlier base frame)."""
    a1, a2, a3, a4 = config.odom_alphas
    var_rot1 = a1 * inc.rot1 ** 2 + a2 * inc.trans ** 2
    var_trans = a3 * inc.trans ** 2 + a4 * (inc.rot1 ** 2 + inc.rot2 ** 2)
    var_rot2 = a1 * inc.rot2 ** 2 + a2 * inc.trans ** 2
    # (dx, dy, dyaw) = (t cos r1, t sin r1, r1 + r2): first-order propagation
    cr, sr = math.cos(inc.rot1), math.sin(inc.rot1)
    sign = 1.0 if inc.delta[0] * cr + inc.delta[1] * sr >= 0.0 else -1.0
    t = sign * inc.trans
    jac = np.array([[-t * sr, sign * cr, 0.0], [t * cr, sign * sr, 0.0], [1.0, 0.0, 1.0]])
    cov = jac @ np.diag([var_rot1, var_trans, var_rot2]) @ jac.T
    xy, yaw = config.min_step_std
    return cov + np.diag([xy ** 2, xy ** 2, yaw ** 2])


def predict(pose: Pose2, cov: np.ndarray, inc: Increment | None,
            config: TrackerConfig) -> tuple[Pose2, np.ndarray]:
    """
    Move a pose (map frame) and its covariance by an odometry increment.

    ``inc`` None: no odometry; the pose stays and its covariance grows by ``no_odom_std``.
    (The tracker scales the odometry's part by what it learnt: :func:`predict_parts`.)
    """
    new, carried, noise = predict_parts(pose, cov, inc, config)
    return new, carried + noise


def predict_parts(pose: Pose2, cov: np.ndarray, inc: Increment | None,
                  config: TrackerConfig) -> tuple[Pose2, np.ndarray, np.ndarray]:
    """
    Return the prediction of :func:`predict` with its covariance in two parts.

    ``(pose, carried, noise)``: the pose's own covariance carried over the increment (a lever
    arm) and the odometry's noise rotated into the map frame (with no odometry: ``no_odom_std``
    as the noise); the prediction's covariance is their sum.
    """
    cov = np.asarray(cov, float)
    if inc is None:
        xy, yaw = config.no_odom_std
        return pose, cov, np.diag([xy ** 2, xy ** 2, yaw ** 2])
    new = compose(pose, inc.delta)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = inc.delta[0], inc.delta[1]
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    carried = lever_arm_covariance(cov, (c * dx - s * dy, s * dx + c * dy))
    noise = rot @ motion_noise(inc, config) @ rot.T
    return new, 0.5 * (carried + carried.T), 0.5 * (noise + noise.T)
