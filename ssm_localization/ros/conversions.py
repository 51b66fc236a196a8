"""
Conversions between ROS 2 messages and the ROS-free core types.

LaserScan -> ``localize_scan`` arguments, :class:`OccupancyMap` -> OccupancyGrid (the other way is
the core's duck-typed ``mapping.occupancy.occupancy_map_from_msg``),
``Localization`` -> PoseWithCovarianceStamped, ``ScanRecord`` -> LaserScan, poses -> PoseStamped.
Everything here is a plain function of its inputs (no node, no I/O).
"""
from __future__ import annotations

import array
from dataclasses import dataclass
import math
from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, PoseWithCovarianceStamped, Quaternion
from nav_msgs.msg import OccupancyGrid
import numpy as np
from sensor_msgs.msg import LaserScan
from ssm_localization.matching.scan import ranges_to_points, scan_geometry_problem, sensor_range
from ssm_localization.transforms import quaternion_to_yaw, yaw_to_quaternion

# Index of x, y, yaw in the row-major 6x6 covariance of geometry_msgs (x, y, z, roll, pitch, yaw).
_COV6_INDEX = (0, 1, 5)


@dataclass(frozen=True)
class ScanArgs:
    """The arguments of ``GlobalLocalizer.localize_scan`` taken from a LaserScan."""

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float

    def as_tuple(self) -> tuple[np.ndarray, float, float, float, float]:
        return (self.ranges, self.angle_min, self.angle_increment, self.range_min,
                self.range_max)


def scan_args_from_msg(msg: LaserScan) -> ScanArgs:
    """Convert LaserScan -> :class:`ScanArgs` (float64, unvalidated: :func:`scan_problem`)."""
    return ScanArgs(np.asarray(msg.ranges, dtype=np.float64), float(msg.angle_min),
                    float(msg.angle_increment), float(msg.range_min), float(msg.range_max))


def scan_problem(args: ScanArgs, min_points: int = 3) -> str | None:
    """
    Return why a scan cannot be localized (a short reason), or None when it is usable.

    The fields' checks are the core's (``matching.scan.scan_geometry_problem``), so the node,
    ``replay`` and the Python API refuse the same scans; then at least ``min_points`` readings.
    """
    n = args.ranges.size
    if n == 0:
        return 'empty scan (no ranges)'
    problem = scan_geometry_problem(n, args.angle_min, args.angle_increment, args.range_min,
                                    args.range_max)
    if problem is not None:
        return problem
    lo = args.range_min if math.isfinite(args.range_min) else 0.0
    hi = sensor_range(args.range_max)
    with np.errstate(invalid='ignore'):
        valid = np.isfinite(args.ranges) & (args.ranges >= lo) & (args.ranges <= hi)
    count = int(valid.sum())
    if count < min_points:
        return (f'only {count} of {n} ranges are finite and within '
                f'[{args.range_min:g}, {args.range_max:g}] m')
    return None


def scan_points(args: ScanArgs) -> np.ndarray:
    """(N, 2) points of the valid beams, in the laser frame (for markers; the core's rules)."""
    return ranges_to_points(args.ranges, args.angle_min, args.angle_increment, args.range_min,
                            args.range_max)[0]


# --- time --------------------------------------------------------------------------------------

def stamp_to_ns(stamp: Any) -> int:
    """Return a builtin_interfaces/Time, int nanoseconds or float seconds -> int nanoseconds."""
    if hasattr(stamp, 'sec') and hasattr(stamp, 'nanosec'):
        return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    if isinstance(stamp, (int, np.integer)):
        return int(stamp)
    return int(round(float(stamp) * 1e9))


def time_msg(stamp: Any) -> Time:
    """Convert int nanoseconds / float seconds / Time -> builtin_interfaces/Time."""
    ns = stamp_to_ns(stamp)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_to_sec(stamp: Any) -> float:
    return stamp_to_ns(stamp) * 1e-9


# --- maps --------------------------------------------------------------------------------------

def occupancy_grid_from_map(occ_map, stamp: Any = 0, frame_id: str | None = None) -> OccupancyGrid:
    """Convert OccupancyMap -> OccupancyGrid (row 0 = bottom row, as both use)."""
    data = np.asarray(occ_map.data, dtype=np.int8)
    height, width = data.shape
    msg = OccupancyGrid()
    msg.header.stamp = time_msg(stamp)
    msg.header.frame_id = frame_id or getattr(occ_map, 'frame_id', None) or 'map'
    msg.info.map_load_time = msg.header.stamp
    msg.info.resolution = float(occ_map.resolution)
    msg.info.width = int(width)
    msg.info.height = int(height)
    msg.info.origin = pose_msg(tuple(float(v) for v in occ_map.origin))
    msg.data = array.array('b', data.tobytes())
    return msg


# --- poses -------------------------------------------------------------------------------------

def quaternion_msg(yaw: float) -> Quaternion:
    x, y, z, w = yaw_to_quaternion(float(yaw))
    return Quaternion(x=x, y=y, z=z, w=w)


def pose_msg(pose) -> Pose:
    """(x, y, yaw) -> geometry_msgs/Pose."""
    x, y, yaw = (float(v) for v in pose)
    msg = Pose()
    msg.position.x, msg.position.y = x, y
    msg.orientation = quaternion_msg(yaw)
    return msg


def pose_from_msg(msg: Pose) -> tuple[float, float, float]:
    """geometry_msgs/Pose -> (x, y, yaw)."""
    q = msg.orientation
    return (float(msg.position.x), float(msg.position.y), quaternion_to_yaw(q.x, q.y, q.z, q.w))


def unit_quaternion(q: Any) -> tuple[float, float, float, float]:
    """
    Return ``(x, y, z, w)`` of a geometry_msgs/Quaternion scaled to unit length.

    ``ValueError`` for a non-finite or zero quaternion.
    """
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not math.isfinite(norm) or norm < 1e-9:
        raise ValueError('transform with a non-finite or zero rotation / translation')
    return x / norm, y / norm, z / norm, w / norm


def transform_pose(transform: Any) -> tuple[float, float, float]:
    """
    Return the planar pose (x, y, yaw) of a geometry_msgs/Transform.

    The yaw is that of the rotated x axis projected on the plane (the rotation normalised
    first). ``ValueError`` for a non-finite translation or a non-finite / zero rotation.
    """
    t = transform.translation
    if not all(math.isfinite(v) for v in (t.x, t.y, t.z)):
        raise ValueError('transform with a non-finite or zero rotation / translation')
    return (float(t.x), float(t.y), quaternion_to_yaw(*unit_quaternion(transform.rotation)))


def pose_stamped(pose, stamp: Any, frame_id: str) -> PoseStamped:
    msg = PoseStamped()
    msg.header.stamp = time_msg(stamp)
    msg.header.frame_id = frame_id
    msg.pose = pose_msg(pose)
    return msg


def pose_array(poses, stamp: Any, frame_id: str) -> PoseArray:
    """(x, y, yaw) poses -> geometry_msgs/PoseArray (non-finite poses are left out)."""
    msg = PoseArray()
    msg.header.stamp = time_msg(stamp)
    msg.header.frame_id = frame_id
    msg.poses = [pose_msg(p) for p in poses
                 if p is not None and all(math.isfinite(float(v)) for v in p)]
    return msg


def covariance6(cov3) -> list[float]:
    """
    3x3 (x, y, yaw) covariance -> row-major 6x6 list; z/roll/pitch get a tiny variance.

    Non-finite entries (no estimate) become a large variance so consumers never see NaN.
    """
    cov = np.full((6, 6), 0.0)
    cov[2, 2] = cov[3, 3] = cov[4, 4] = 1e-9
    c3 = np.asarray(cov3 if cov3 is not None else np.eye(3) * 1e3, dtype=np.float64).reshape(3, 3)
    if not np.all(np.isfinite(c3)):
        c3 = np.eye(3) * 1e3
    c3 = 0.5 * (c3 + c3.T)
    for i, a in enumerate(_COV6_INDEX):
        for j, b in enumerate(_COV6_INDEX):
            cov[a, b] = c3[i, j]
    return [float(v) for v in cov.ravel()]


def covariance3(cov6) -> np.ndarray:
    """Row-major 6x6 -> 3x3 (x, y, yaw)."""
    c6 = np.asarray(cov6, dtype=np.float64).reshape(6, 6)
    return c6[np.ix_(_COV6_INDEX, _COV6_INDEX)].copy()


def pose_with_covariance(localization, stamp: Any, frame_id: str) -> PoseWithCovarianceStamped:
    """Localization (``.pose`` of the base in the map frame, ``.covariance`` 3x3) -> message."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = time_msg(stamp)
    msg.header.frame_id = frame_id
    msg.pose.pose = pose_msg(localization.pose)
    msg.pose.covariance = covariance6(getattr(localization, 'covariance', None))
    return msg


# --- bag records -------------------------------------------------------------------------------

def laser_scan_from_record(record, frame_id: str | None = None) -> LaserScan:
    """bags.ScanRecord -> LaserScan (``angle_max`` from the beam count; float32 ranges)."""
    ranges = np.asarray(record.ranges, dtype=np.float32).ravel()
    msg = LaserScan()
    msg.header.stamp = time_msg(record.stamp)
    msg.header.frame_id = frame_id or getattr(record, 'frame_id', None) or 'laser'
    msg.angle_min = float(record.angle_min)
    msg.angle_increment = float(record.angle_increment)
    msg.angle_max = float(record.angle_min + record.angle_increment * max(ranges.size - 1, 0))
    msg.range_min = float(record.range_min)
    msg.range_max = float(record.range_max)
    msg.ranges = array.array('f', ranges.tobytes())
    return msg
