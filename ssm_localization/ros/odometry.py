"""
Odometry for ``global_localizer``'s ``track`` mode, and the map -> odom transform it broadcasts.

- :class:`OdometryBuffer` keeps the recent nav_msgs/Odometry poses (base in the odom frame) and
  gives the pose at a scan's stamp: interpolated between the two messages around it, or the
  nearest one within ``max_age`` seconds;
- :class:`OdometrySource` asks the buffer first and TF (``odom_frame`` <- ``base_frame`` at the
  scan's stamp) second, when tf2_ros is importable and the odom topic is silent;
- :func:`map_to_odom` is the transform AMCL broadcasts: ``T_map_odom = T_map_base *
  T_odom_base^-1``; :class:`MapOdomBroadcaster` sends it (a tf2_ros TransformBroadcaster, or any
  object with ``sendTransform``), stamped ``transform_tolerance`` seconds ahead as AMCL does, and
  re-sends the last one for scans without a new pose so the tree does not go stale.
"""
from __future__ import annotations

from collections import deque
import math
import threading
from typing import Any

from geometry_msgs.msg import TransformStamped
from rclpy.duration import Duration
from rclpy.time import Time
from ssm_localization.ros.conversions import (pose_from_msg, quaternion_msg, stamp_to_ns,
                                              time_msg, transform_pose)
from ssm_localization.ros.laser_pose import tf2_ros, TF_AVAILABLE
from ssm_localization.transforms import compose, inverse, Pose2, pose_at_time

#: odometry messages kept (at 50 Hz: 10 s)
BUFFER_SIZE = 500


CLOCK_RESET = 1.0
"""A stamp this many seconds older than the last one means the clock was reset (a bag played
again, a simulation restarted): what was kept before it is dropped, not what comes after."""


class OdometryBuffer:
    """The recent odometry poses (base in the odom frame) by stamp; thread-safe."""

    def __init__(self, max_age: float, size: int = BUFFER_SIZE) -> None:
        self.max_age_ns = int(max_age * 1e9)
        self._lock = threading.Lock()
        self._poses: deque[tuple[int, Pose2]] = deque(maxlen=size)

    def add(self, msg: Any) -> None:
        """
        Keep one nav_msgs/Odometry message (out-of-order ones are dropped).

        A stamp more than :data:`CLOCK_RESET` s older than the newest one kept is a reset
        clock: the buffer starts again from it.
        """
        stamp = stamp_to_ns(msg.header.stamp)
        try:
            pose = pose_from_msg(msg.pose.pose)
        except ValueError:                  # a zero or non-finite quaternion: no pose at all
            return
        if not all(math.isfinite(v) for v in pose):
            return
        with self._lock:
            if self._poses and stamp < self._poses[-1][0] - CLOCK_RESET * 1e9:
                self._poses.clear()
            if self._poses and stamp <= self._poses[-1][0]:
                if stamp == self._poses[-1][0]:
                    self._poses[-1] = (stamp, pose)
                return
            self._poses.append((stamp, pose))

    def __len__(self) -> int:
        with self._lock:
            return len(self._poses)

    def pose_at(self, stamp: Any) -> Pose2 | None:
        """Return the odometry pose at ``stamp`` (interpolated), or None when none is close."""
        with self._lock:
            poses = list(self._poses)
        return pose_at_time(poses, stamp_to_ns(stamp), self.max_age_ns)


class OdometrySource:
    """
    The odometry pose of the base at a scan's stamp: the odom topic first, TF second.

    ``tf_buffer`` is anything with tf2_ros.Buffer's ``lookup_transform(target, source, time,
    timeout)`` (None: no TF). ``last_source`` says where the last pose came from.
    """

    def __init__(self, buffer: OdometryBuffer, odom_frame: str, base_frame: str,
                 tf_buffer: Any = None) -> None:
        self.buffer = buffer
        self.odom_frame = odom_frame.lstrip('/')
        self.base_frame = base_frame.lstrip('/')
        self.tf_buffer = tf_buffer
        self.last_source = 'none'

    def pose_at(self, stamp: Any) -> Pose2 | None:
        """Return the base's odometry pose at ``stamp``, or None (track without odometry)."""
        pose = self.buffer.pose_at(stamp)
        if pose is not None:
            self.last_source = 'odom topic'
            return pose
        if self.tf_buffer is not None and not len(self.buffer):
            try:
                tf = self.tf_buffer.lookup_transform(self.odom_frame, self.base_frame,
                                                     Time(nanoseconds=stamp_to_ns(stamp)),
                                                     Duration(seconds=0.0))
                pose = transform_pose(tf.transform)
            except Exception:  # noqa: BLE001 - tf2 raises several types; all mean "no answer"
                pose = None
            if pose is not None:
                self.last_source = f'TF {self.odom_frame} <- {self.base_frame}'
                return pose
        self.last_source = 'none'
        return None


def map_to_odom(map_base: Pose2, odom_base: Pose2) -> Pose2:
    """Return ``T_map_odom`` given the base in the map frame and in the odom frame."""
    return compose(map_base, inverse(odom_base))


def transform_stamped(pose: Pose2, stamp_ns: int, parent: str, child: str) -> TransformStamped:
    """Return a geometry_msgs/TransformStamped of a planar pose."""
    msg = TransformStamped()
    msg.header.stamp = time_msg(stamp_ns)
    msg.header.frame_id = parent
    msg.child_frame_id = child
    msg.transform.translation.x, msg.transform.translation.y = float(pose[0]), float(pose[1])
    msg.transform.rotation = quaternion_msg(pose[2])
    return msg


class MapOdomBroadcaster:
    """
    Send map -> odom (AMCL's ``tf_broadcast``): after each pose, and again for later scans.

    ``sender`` has ``sendTransform(TransformStamped)`` (a tf2_ros.TransformBroadcaster).
    """

    def __init__(self, sender: Any, odom_frame: str, tolerance: float) -> None:
        self.sender = sender
        self.odom_frame = odom_frame
        self.tolerance_ns = int(tolerance * 1e9)
        self.last: Pose2 | None = None

    @classmethod
    def for_node(cls, node: Any, odom_frame: str,
                 tolerance: float) -> 'MapOdomBroadcaster | None':
        """Return a broadcaster on ``/tf`` for ``node``; None when tf2_ros is not importable."""
        if not TF_AVAILABLE:
            return None
        return cls(tf2_ros.TransformBroadcaster(node), odom_frame, tolerance)

    def update(self, map_base: Pose2 | None, odom_base: Pose2 | None, stamp: Any,
               map_frame: str) -> bool:
        """
        Send map -> odom for a scan at ``stamp``; return True when one was sent.

        With both poses the transform is new; otherwise the last one is sent again (none
        before the first pose).
        """
        if map_base is not None and odom_base is not None:
            self.last = map_to_odom(map_base, odom_base)
        if self.last is None:
            return False
        self.sender.sendTransform(transform_stamped(
            self.last, stamp_to_ns(stamp) + self.tolerance_ns, map_frame, self.odom_frame))
        return True
