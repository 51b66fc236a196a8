"""
Gaussian pose estimates: differences, Mahalanobis distances, lever arms and fusion.

The fusion (``fuse_weak``) is that of a scan's pose with a motion prediction, along the directions
the scan leaves undetermined.

A scan pins a pose down along the directions its walls constrain and hardly at all along the
others (a corridor's axis); its covariance says which. Odometry, on the other hand, can be off by
more than its model admits (wheel slip, a bump). So the prediction is fused only along the weak
directions of the scan's position covariance (``fuse_weak``): there it is the better estimate;
elsewhere the scan is, and mixing in a biased prediction would only pull the pose off the walls.
The same holds for the yaw: a few short returns (a short-range laser in a hall) can leave it
undetermined by more than a right pose may be off (5 deg), and there the odometry's yaw, carried
over one scan, is the better estimate.
"""
from __future__ import annotations

import numpy as np

from ..transforms import Pose2, wrap_angle


def difference(a: Pose2, b: Pose2) -> np.ndarray:
    """Return ``a - b`` as (dx, dy, dyaw), the yaw difference wrapped."""
    return np.array([a[0] - b[0], a[1] - b[1], float(wrap_angle(a[2] - b[2]))])


def mahalanobis2(a: Pose2, b: Pose2, cov: np.ndarray) -> float:
    """Return the squared Mahalanobis distance of ``a - b`` under ``cov`` (inf if singular)."""
    d = difference(a, b)
    try:
        return float(d @ np.linalg.solve(np.asarray(cov, float), d))
    except np.linalg.LinAlgError:
        return float('inf')


def lever_arm_covariance(cov: np.ndarray, offset) -> np.ndarray:
    """
    Return the covariance of a frame rigidly ``offset`` (dx, dy, map frame) from a pose.

    First order: a yaw error moves the frame across the lever arm. ``cov`` is the pose's
    (x, y, yaw) covariance.
    """
    jac = np.array([[1.0, 0.0, -offset[1]], [0.0, 1.0, offset[0]], [0.0, 0.0, 1.0]])
    return jac @ np.asarray(cov, float) @ jac.T


def weak_directions(cov: np.ndarray, weak_std: float) -> np.ndarray:
    """Return the (2, k) unit directions along which the position std exceeds ``weak_std``."""
    values, vectors = np.linalg.eigh(np.asarray(cov, float)[:2, :2])
    return vectors[:, values > weak_std ** 2]


def fuse_weak(scan: Pose2, scan_cov: np.ndarray, pred: Pose2, pred_cov: np.ndarray,
              weak_std: float, weak_yaw_std: float = np.inf) -> tuple[Pose2, np.ndarray]:
    """
    Fuse the prediction into the scan's pose along the scan's weak directions.

    Along each position direction ``u`` whose scan std exceeds ``weak_std``, and along the yaw
    when its scan std exceeds ``weak_yaw_std`` (a few short returns that hardly turn the pose),
    the pose and its covariance are the product of the two Gaussians restricted to those
    directions (information form); the other directions stay the scan's. Returns ``(pose,
    covariance)``.
    """
    scan_cov = np.asarray(scan_cov, float)
    dirs = weak_directions(scan_cov, weak_std)
    weak_yaw = bool(scan_cov[2, 2] > weak_yaw_std ** 2)
    if dirs.shape[1] == 0 and not weak_yaw:
        return scan, scan_cov
    basis = np.zeros((3, dirs.shape[1] + weak_yaw))
    basis[:2, :dirs.shape[1]] = dirs
    if weak_yaw:
        basis[2, -1] = 1.0
    s = basis.T @ scan_cov @ basis                 # the weak block of each estimate
    p = basis.T @ np.asarray(pred_cov, float) @ basis
    gain = s @ np.linalg.inv(s + p)                # the Kalman gain within the weak subspace
    step = basis @ gain @ (basis.T @ difference(pred, scan))
    pose = (float(scan[0] + step[0]), float(scan[1] + step[1]),
            float(wrap_angle(scan[2] + step[2])))
    # Joseph form: the gain moves the weak directions only, so it is not the optimal one
    gain3 = basis @ gain
    keep = np.eye(3) - gain3 @ basis.T
    cov = keep @ scan_cov @ keep.T + gain3 @ p @ gain3.T
    return pose, 0.5 * (cov + cov.T)
