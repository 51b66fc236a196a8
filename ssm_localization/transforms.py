"""
Rigid 2-D transforms (SE(2)) as ``(x, y, yaw)`` triples and 3x3 matrices.

Convention everywhere in the package: a pose ``T_a_b = (x, y, yaw)`` maps points from frame b
into frame a: ``p_a = R(yaw) @ p_b + (x, y)``.
"""
from __future__ import annotations

import bisect
import math
from typing import Sequence

import numpy as np

Pose2 = tuple[float, float, float]


def wrap_angle(a):
    """Wrap angle(s) to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def rotation(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def to_matrix(pose) -> np.ndarray:
    x, y, yaw = pose
    m = np.eye(3)
    m[:2, :2] = rotation(yaw)
    m[:2, 2] = (x, y)
    return m


def from_matrix(m: np.ndarray) -> Pose2:
    return (float(m[0, 2]), float(m[1, 2]), float(np.arctan2(m[1, 0], m[0, 0])))


def compose(a, b) -> Pose2:
    """Return ``a * b``: the pose of frame c in frame a, given ``a = T_a_b`` and ``b = T_b_c``."""
    ax, ay, ayaw = a
    bx, by, byaw = b
    c, s = np.cos(ayaw), np.sin(ayaw)
    return (float(ax + c * bx - s * by), float(ay + s * bx + c * by),
            float(wrap_angle(ayaw + byaw)))


def inverse(a) -> Pose2:
    x, y, yaw = a
    c, s = np.cos(yaw), np.sin(yaw)
    return (float(-c * x - s * y), float(s * x - c * y), float(wrap_angle(-yaw)))


def apply(pose, points: np.ndarray) -> np.ndarray:
    """Map (N, 2) points from the child frame into the parent frame of ``pose``."""
    x, y, yaw = pose
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    return pts @ rotation(yaw).T + np.array([x, y])


def yaw_to_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation about z."""
    return (0.0, 0.0, float(np.sin(yaw / 2.0)), float(np.cos(yaw / 2.0)))


def unit_quaternion(x: float, y: float, z: float, w: float) -> tuple[float, float, float, float]:
    """
    Return ``(x, y, z, w)`` scaled to unit length.

    ``ValueError`` for a quaternion with a non-finite component or (almost) zero length, which
    is no rotation at all.
    """
    q = tuple(float(v) for v in (x, y, z, w))
    norm = math.sqrt(sum(v * v for v in q))
    if not math.isfinite(norm) or norm < 1e-9:
        raise ValueError(f'not a rotation: quaternion (x, y, z, w) = {q} is zero or not finite')
    return tuple(v / norm for v in q)


def quaternion_to_yaw(x: float, y: float, z: float, w: float) -> float:
    """
    Return the yaw of a rotation: the heading of its rotated x axis in the plane.

    The quaternion is normalised first (a message's quaternion need not be unit length);
    ``ValueError`` for a zero or non-finite one (:func:`unit_quaternion`).
    """
    x, y, z, w = unit_quaternion(x, y, z, w)
    return float(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def quaternion_tilt(x: float, y: float, z: float, w: float) -> float:
    """Return the angle (rad) between the rotated z axis and z: 0 for a rotation about z only."""
    x, y, z, w = unit_quaternion(x, y, z, w)
    return float(math.acos(min(1.0, max(-1.0, 1.0 - 2.0 * (x * x + y * y)))))


def planar_yaw(x: float, y: float, z: float, w: float, what: str = 'orientation',
               max_tilt: float = math.radians(1.0)) -> float:
    """
    Return the yaw of a rotation that must be about z (a 2-D map's origin, say).

    ``ValueError`` naming ``what`` when it tilts the z axis by more than ``max_tilt``: a map
    rolled by 180 deg is mirrored, and reading only its yaw would place every pose wrong.
    """
    tilt = quaternion_tilt(x, y, z, w)
    if tilt > max_tilt:
        raise ValueError(f'{what} is not a rotation about z: it tilts the z axis by '
                         f'{math.degrees(tilt):.1f} deg (roll / pitch must be 0 in 2-D)')
    return quaternion_to_yaw(x, y, z, w)


def interpolate(a: Pose2, b: Pose2, f: float) -> Pose2:
    """Return the pose a fraction ``f`` of the way from ``a`` to ``b`` (yaw the short way)."""
    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]),
            float(wrap_angle(a[2] + f * float(wrap_angle(b[2] - a[2])))))


def pose_at_time(timed: Sequence[tuple[int, Pose2]], t: int, max_age: int) -> Pose2 | None:
    """
    Return the pose at time ``t`` from ``(time, pose)`` pairs in increasing time order.

    The pose at ``t`` exactly, else interpolated between the poses around ``t`` when they are at
    most ``2 * max_age`` apart, else the nearest one within ``max_age``; None when none is that
    close. Times in any one unit (integer nanoseconds keep stamps exact).
    """
    after = bisect.bisect_left(timed, t, key=lambda tp: tp[0])
    if after < len(timed) and timed[after][0] == t:
        return timed[after][1]
    if 0 < after < len(timed):
        (s0, p0), (s1, p1) = timed[after - 1], timed[after]
        if s1 - s0 <= 2 * max_age:
            return interpolate(p0, p1, (t - s0) / (s1 - s0))
    near = [timed[k] for k in (after - 1, after) if 0 <= k < len(timed)]
    if not near:
        return None
    s, pose = min(near, key=lambda tp: abs(tp[0] - t))
    return pose if abs(s - t) <= max_age else None
