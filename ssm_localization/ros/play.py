"""
Publish a bag's topics on live ROS topics (a small ``ros2 bag play`` for our bags).

The bag is read with :mod:`ssm_localization.io.bag_reader`; ``/map`` is published once, first,
reliable + transient-local (latched); ``/scan`` (reliable, so sensor-data and reliable subscribers
both match), ``/ground_truth`` and ``/odom`` follow in timestamp order at ``rate`` times real time
(0 = as fast as possible). Topic names are published relative (``scan``), so a namespace or
``--ros-args -r`` remapping applies.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
import time
from typing import Any, Callable, Iterable

from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from ssm_localization.io.bag_reader import read_bag
from ssm_localization.ros.conversions import (laser_scan_from_record, occupancy_grid_from_map,
                                              pose_msg, pose_stamped, time_msg)
from ssm_localization.ros.executor import shutdown_context
from ssm_localization.ros.qos import LATCHED_QOS

STREAM_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


@dataclass(frozen=True)
class Item:
    stamp: float
    topic: str
    msg: Any


def _norm(topic: str) -> str:
    return '/' + topic.strip('/')


def missing_scan_topic(data, scan_topic: str = '/scan',
                       topics: Iterable[str] | None = None) -> str:
    """
    Return a warning when the scan topic is to be played but the bag holds none of it ('' else).

    A bag of a map alone stays playable with the default ``/scan``; a misspelled ``--scan-topic``
    would otherwise play the other topics without a word.
    """
    scan_topic = _norm(scan_topic)
    if data.scans or (topics and scan_topic not in {_norm(t) for t in topics}):
        return ''
    have = ', '.join(sorted(data.topic_counts)) or 'none'
    return f'no messages on {scan_topic} in the bag (its topics: {have}); playing the others'


def timeline(data, scan_topic: str = '/scan', topics: Iterable[str] | None = None,
             start_offset: float = 0.0, duration: float = 0.0,
             odom_frame: str = 'odom', base_frame: str = 'base_link') -> tuple[Any, list[Item]]:
    """
    ``(map OccupancyGrid or None, [Item] in stamp order)`` of a BagData, for selected topics.

    ``start_offset`` / ``duration`` (seconds, relative to the first scan) select a window of
    the timed topics; the map is always included when selected.
    """
    wanted = {_norm(t) for t in topics} if topics else None
    scan_topic = _norm(scan_topic)

    def keep(topic: str) -> bool:
        return wanted is None or topic in wanted
    items: list[Item] = []
    if keep(scan_topic):
        items += [Item(float(s.stamp), scan_topic, s) for s in data.scans]
    if keep('/ground_truth'):
        items += [Item(float(t), '/ground_truth', p) for t, p in data.ground_truth.items()]
    if keep('/odom'):
        items += [Item(float(t), '/odom', p) for t, p in data.odom.items()]
    items.sort(key=lambda it: (it.stamp, it.topic != scan_topic))
    stamps = [float(s.stamp) for s in data.scans] or [it.stamp for it in items] or [0.0]
    t0 = min(stamps) + max(start_offset, 0.0)
    t1 = t0 + duration if duration > 0 else float('inf')
    items = [it for it in items if t0 - 1e-9 <= it.stamp <= t1 + 1e-9]
    grid = None
    if data.map is not None and keep('/map'):
        first = items[0].stamp if items else 0.0
        grid = occupancy_grid_from_map(data.map, first)
    out = []
    for it in items:
        if it.topic == scan_topic:
            msg = laser_scan_from_record(it.msg)
        elif it.topic == '/ground_truth':
            msg = pose_stamped(it.msg, it.stamp, getattr(data.map, 'frame_id', 'map') or 'map')
        else:
            msg = Odometry()
            msg.header.stamp = time_msg(it.stamp)
            msg.header.frame_id = odom_frame
            msg.child_frame_id = base_frame
            msg.pose.pose = pose_msg(it.msg)
        out.append(Item(it.stamp, it.topic, msg))
    return grid, out


class BagPlayer(Node):
    """Publishers for the bag topics; :meth:`play` does the timing."""

    TYPES = {'/ground_truth': PoseStamped, '/odom': Odometry}

    def __init__(self, grid: OccupancyGrid | None, items: list[Item], scan_topic: str = '/scan',
                 **kwargs: Any) -> None:
        super().__init__('ssm_bag_player', **kwargs)
        self.grid = grid
        self.items = items
        self.pubs = {}
        if grid is not None:
            self.pubs['/map'] = self.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
        for topic in sorted({it.topic for it in items}):
            msg_type = LaserScan if topic == _norm(scan_topic) else self.TYPES[topic]
            self.pubs[topic] = self.create_publisher(msg_type, topic.lstrip('/'), STREAM_QOS)

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait (up to ``timeout`` s) until every stream topic has a subscriber."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if all(p.get_subscription_count() > 0 for t, p in self.pubs.items() if t != '/map'):
                return True
            time.sleep(0.05)
        return False

    def play(self, rate: float = 1.0, loop: bool = False, ok: Callable[[], bool] = lambda: True,
             log: Callable[[str], None] = print) -> int:
        """Publish the map, then the items in time order; return the number of messages sent."""
        sent = 0
        if self.grid is not None:
            self.pubs['/map'].publish(self.grid)
            sent += 1
            log(f'published /map ({self.grid.info.width}x{self.grid.info.height}, latched)')
        if not self.items:
            return sent
        stamps = np.array([it.stamp for it in self.items])
        gaps = np.diff(np.unique(stamps))
        loop_gap = float(np.median(gaps)) if gaps.size else 0.1
        span = float(stamps[-1] - stamps[0])
        passes = 0
        while ok():
            t_bag0, t_wall0 = self.items[0].stamp, time.monotonic()
            for it in self.items:
                if rate > 0:
                    delay = t_wall0 + (it.stamp - t_bag0) / rate - time.monotonic()
                    while delay > 0 and ok():
                        time.sleep(min(delay, 0.1))
                        delay = t_wall0 + (it.stamp - t_bag0) / rate - time.monotonic()
                if not ok():
                    return sent
                self.pubs[it.topic].publish(it.msg)
                sent += 1
            passes += 1
            if passes == 1:
                log(f'played {len(self.items)} messages ({span:.1f} s of bag time)'
                    + ('; looping' if loop else ''))
            if not loop:
                break
            time.sleep(loop_gap / rate if rate > 0 else 0.0)
        return sent

    def flush(self, timeout: float = 2.0) -> None:
        """Wait until reliable subscribers acknowledged everything (before exiting)."""
        for pub in self.pubs.values():
            try:
                pub.wait_for_all_acked(timeout=_duration(timeout))
            except Exception:  # noqa: BLE001 - best effort on shutdown
                pass


def _duration(seconds: float) -> Duration:
    return Duration(nanoseconds=int(seconds * 1e9))


def play_bag(bag: str | Path, rate: float = 1.0, loop: bool = False,
             topics: Iterable[str] | None = None, scan_topic: str = '/scan',
             start_offset: float = 0.0, duration: float = 0.0, delay: float = 0.5,
             wait_subscribers: float = 0.0, hold: float = 0.0,
             ros_args: list[str] | None = None) -> int:
    """Read ``bag`` and publish it (initialises and shuts down rclpy); return an exit code."""
    data = read_bag(bag, scan_topic=_norm(scan_topic), require_scans=False)
    grid, items = timeline(data, scan_topic, topics, start_offset, duration)
    if grid is None and not items:
        raise ValueError(f'{bag}: nothing to play for the selected topics/window')
    try:
        rclpy.init(args=ros_args)
    except Exception as exc:  # noqa: BLE001 - rclpy raises RCLError / UnknownROSArgsError
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f'ROS arguments {" ".join(ros_args or [])}: {first}') from None
    node = None
    try:
        node = BagPlayer(grid, items, scan_topic)
        log = node.get_logger().info
        warning = missing_scan_topic(data, scan_topic, topics)
        if warning:
            node.get_logger().warning(warning)
        if wait_subscribers > 0 and not node.wait_for_subscribers(wait_subscribers):
            log('not every topic has a subscriber yet; playing anyway')
        time.sleep(max(delay, 0.0))
        node.play(rate, loop, ok=rclpy.ok, log=log)
        end = time.monotonic() + max(hold, 0.0)
        while rclpy.ok() and time.monotonic() < end:
            time.sleep(0.1)
        node.flush()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        shutdown_context()
    return 0
