"""
What the bag reader and writer share.

Topic names and types, ``ScanRecord`` / ``BagData``, stamps and the rosbags type store.

Topics (docs INTERFACES.md): ``/scan`` sensor_msgs/msg/LaserScan (frame ``laser``, no-return beams
``+inf``), ``/map`` nav_msgs/msg/OccupancyGrid (one message at the start, frame ``map``, offered
transient-local so ``ros2 bag play`` latches it), ``/odom`` nav_msgs/msg/Odometry (optional),
``/ground_truth`` geometry_msgs/msg/PoseStamped (optional, frame ``map``, the scan's stamp).
Stamps are float seconds; poses ``(x, y, yaw)``. ``rosbags`` is imported on first use only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from ..mapping.occupancy import OccupancyMap
from ..transforms import Pose2

SCAN_TOPIC = '/scan'
MAP_TOPIC = '/map'
ODOM_TOPIC = '/odom'
GT_TOPIC = '/ground_truth'
SCAN_TYPE = 'sensor_msgs/msg/LaserScan'
MAP_TYPE = 'nav_msgs/msg/OccupancyGrid'
ODOM_TYPE = 'nav_msgs/msg/Odometry'
GT_TYPE = 'geometry_msgs/msg/PoseStamped'


class BagError(ValueError):
    """A bag that cannot be read (corrupt, truncated, wrong topics)."""


@dataclass(frozen=True, eq=False)
class ScanRecord:
    """One sensor_msgs/LaserScan, ROS-free. ``ranges`` float32, no-return beams ``+inf``."""

    stamp: float
    ranges: np.ndarray
    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float = 0.0
    scan_time: float = 0.0
    range_min: float = 0.0
    range_max: float = math.inf
    frame_id: str = 'laser'

    @classmethod
    def from_ranges(cls, stamp: float, ranges, angle_min: float, angle_increment: float,
                    **kwargs) -> 'ScanRecord':
        """Build a record; ``angle_max = angle_min + (n - 1) * angle_increment``."""
        r = np.asarray(ranges, dtype=np.float32).ravel()
        angle_max = angle_min + max(len(r) - 1, 0) * angle_increment
        return cls(stamp=float(stamp), ranges=r, angle_min=float(angle_min),
                   angle_max=float(angle_max), angle_increment=float(angle_increment), **kwargs)

    def beam_angles(self) -> np.ndarray:
        """(n,) beam angles in the scan frame (float64)."""
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))


@dataclass(frozen=True, eq=False)
class BagData:
    """Everything the package uses from one bag."""

    map: OccupancyMap | None  # noqa: A003 - public field name
    scans: list[ScanRecord]
    ground_truth: dict[float, Pose2] = field(default_factory=dict)   # stamp -> base pose in map
    odom: dict[float, Pose2] = field(default_factory=dict)           # stamp -> pose in odom
    topic_counts: dict[str, int] = field(default_factory=dict)       # every topic in the bag

    def ground_truth_of(self, scan: ScanRecord) -> Pose2 | None:
        """Return the /ground_truth pose carrying the scan's stamp, or None."""
        return self.ground_truth.get(scan.stamp)


def typestore():
    """Return the rosbags type store of ROS 2 Jazzy message definitions."""
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def stamp_to_ns(stamp: float) -> int:
    """Float seconds -> integer nanoseconds (rounded)."""
    return int(round(float(stamp) * 1e9))
