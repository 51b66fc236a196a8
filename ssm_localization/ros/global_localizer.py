"""``global_localizer`` node: single-scan global localization as a ROS 2 service / stream.

Interfaces (docs INTERFACES.md):
- subscribes ``scan`` (sensor_msgs/LaserScan, sensor-data QoS) and, unless ``index_file`` names
  an existing index, ``map`` (nav_msgs/OccupancyGrid, reliable + transient-local);
- publishes ``global_pose`` (geometry_msgs/PoseWithCovarianceStamped, transient-local; stamped
  with the scan's stamp, frame = ``map_frame`` or the map's frame_id), the same on
  ``initialpose`` when ``publish_initialpose`` is true, and ``topological_map`` (MarkerArray);
- serves ``relocalize`` (std_srvs/Trigger): localizes the next scan received after the call.

Modes: ``on_demand`` (service only) and ``continuous`` (every scan, or at most ``rate`` Hz;
always the newest scan, scans arriving while busy are dropped). Indexing and localization run
off the executor threads, so the service answers while a map is being indexed; the localizer is
swapped atomically once a new index is complete. Bad input is logged and skipped.
"""
from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import Any

from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from ssm_localization.config import IndexConfig, LocalizerConfig
from ssm_localization.localization.localizer import GlobalLocalizer
from ssm_localization.mapping.index import build_index, load_index, save_index
from ssm_localization.ros import markers
from ssm_localization.ros.conversions import (pose_with_covariance, scan_args_from_msg,
                                              scan_points, scan_problem)
from ssm_localization.ros.executor import spin
from ssm_localization.ros.index_builder import IndexBuilder
from ssm_localization.ros.maps import usable_map
from ssm_localization.ros.parameters import (DYNAMIC, build_config, declare_table,
                                             laser_pose_of, localizer_parameters)
from ssm_localization.ros.qos import LATCHED_QOS

MODES = ('on_demand', 'continuous')
MARKER_PERIOD = 1.0   # seconds between marker updates in continuous mode
EXECUTOR_THREADS = 8
MAX_WAITING_CALLS = EXECUTOR_THREADS - 3   # relocalize calls blocked on the next scan at once


def format_result(loc) -> str:
    """One line for the service answer / log: pose, node, status, score, latency."""
    x, y, yaw = loc.pose
    return (f'x={x:.3f} y={y:.3f} yaw={yaw:.4f} node={loc.node} status={loc.status} '
            f'score={float(loc.score):.3f} latency_ms={float(loc.latency_ms):.1f}')


class GlobalLocalizerNode(Node):
    """Global localization of single laser scans against the topological index of a map."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('global_localizer', **kwargs)
        values = declare_table(self, localizer_parameters(), dynamic=DYNAMIC)
        self.mode = str(values['mode'])
        if self.mode not in MODES:
            raise ValueError(f'parameter mode must be one of {MODES}, got {self.mode!r}')
        self.base_frame = str(values['base_frame'])
        self.map_frame_param = str(values['map_frame'])
        self.laser_pose = laser_pose_of(values)
        self.index_config = build_config(IndexConfig, 'index', values, self.laser_pose)
        self.localizer_config = build_config(LocalizerConfig, 'localizer', values,
                                             self.laser_pose)
        self.index_file = str(values['index_file'])
        self.rate = float(values['rate'])
        self.max_map_cells = int(values['max_map_cells'])
        self.max_gvd_points = int(values['max_gvd_points'])

        self._state_lock = threading.Lock()     # guards the fields below
        self._localizer = None                  # GlobalLocalizer of the current, complete index
        self._map_frame = self.map_frame_param or 'map'
        self._index_markers: list = []
        self._map_checksum: str | None = None    # of the last map submitted for indexing
        self._index_checksum: str | None = None  # of the map the current localizer serves
        self._localize_lock = threading.Lock()  # one localization at a time
        self._scan_cv = threading.Condition()
        self._scan: LaserScan | None = None
        self._scan_seq = 0
        self._stopping = threading.Event()
        self._last_markers = 0.0
        self._call_slots = threading.BoundedSemaphore(MAX_WAITING_CALLS)

        group = ReentrantCallbackGroup()
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, 'global_pose',
                                              LATCHED_QOS)
        self.initialpose_pub = self.create_publisher(
            PoseWithCovarianceStamped, 'initialpose',
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        self.marker_pub = self.create_publisher(MarkerArray, 'topological_map', LATCHED_QOS)
        self.create_subscription(LaserScan, 'scan', self._on_scan, qos_profile_sensor_data,
                                 callback_group=group)
        self.create_service(Trigger, 'relocalize', self._on_relocalize, callback_group=group)
        self.builder = IndexBuilder(self.get_logger(), self._on_index, self._on_index_error)

        index_path = Path(self.index_file).expanduser() if self.index_file else None
        self._save_to = None
        if index_path is not None and index_path.exists():
            self._waiting_for = f'index file {index_path}'
            self.builder.submit(f'index file {index_path}',
                                lambda progress: self._load_job(index_path))
        else:
            if index_path is not None:
                self.get_logger().warning(f'index file {index_path} not found: indexing the '
                                          'map topic and saving the index there')
                self._save_to = index_path
            self.create_subscription(OccupancyGrid, 'map', self._on_map, LATCHED_QOS,
                                     callback_group=group)
            self._waiting_for = f'a map on {self.resolve_topic_name("map")}'
        self._worker = None
        if self.mode == 'continuous':
            self._worker = threading.Thread(target=self._continuous_loop, daemon=True,
                                            name='continuous_localizer')
            self._worker.start()
        self.get_logger().info(f'mode {self.mode}; waiting for {self._waiting_for}')

    # ------------------------------------------------------------------ index
    def _make_localizer(self, index):
        localizer = GlobalLocalizer(index, self.localizer_config)
        frame = getattr(index.map, 'frame_id', '') or 'map'
        marks = markers.index_markers(index, self.map_frame_param or frame, 0,
                                      self.max_gvd_points)
        return localizer, marks

    def _load_job(self, path: Path):
        index = load_index(path)
        sensor = tuple(getattr(index.config, 'sensor_pose', self.laser_pose))
        if any(abs(a - b) > 1e-6 for a, b in zip(sensor, self.laser_pose)):
            self.get_logger().warning(f'{path} was built with the laser at {sensor} on the base, '
                                      f'the laser_* parameters say {self.laser_pose}')
        self.get_logger().info(f'loaded {path}: its own index parameters apply (index.* ignored)')
        return (index, *self._make_localizer(index))

    def _build_job(self, occ, progress):
        index = build_index(occ, self.index_config, progress=progress)
        return (index, *self._make_localizer(index))

    def _on_map(self, msg: OccupancyGrid) -> None:
        occ = usable_map(msg, self.max_map_cells, self.get_logger())
        if occ is None:
            return
        checksum = occ.checksum()
        with self._state_lock:
            if checksum == self._map_checksum:
                self.get_logger().info('received the same map again: keeping its index')
                return
            self._map_checksum = checksum
        label = f'map {occ.width}x{occ.height} @ {occ.resolution:g} m ({checksum[:8]})'
        self.get_logger().info(f'{label}: indexing')
        self.builder.submit(label, lambda progress: self._build_job(occ, progress))

    def _on_index(self, result, label: str) -> None:
        index, localizer, marks = result
        frame = self.map_frame_param or getattr(index.map, 'frame_id', '') or 'map'
        with self._state_lock:
            self._localizer, self._map_frame, self._index_markers = localizer, frame, marks
            self._index_checksum = index.map.checksum()
        self.get_logger().info(f'{label}: ready, {len(index.node_xy)} nodes (frame {frame})')
        if self.get_parameter('publish_markers').value:
            self.marker_pub.publish(markers.marker_array(marks, frame,
                                                         self.get_clock().now().nanoseconds))
        if self._save_to is not None:
            try:
                self._save_to.parent.mkdir(parents=True, exist_ok=True)
                save_index(index, self._save_to)
                self.get_logger().info(f'index written to {self._save_to}')
            except (OSError, ValueError) as exc:
                self.get_logger().error(f'cannot write index file {self._save_to}: {exc}')

    def _on_index_error(self, exc: BaseException, label: str) -> None:
        with self._state_lock:
            keeping = self._localizer is not None
            self._map_checksum = self._index_checksum
        self.get_logger().warning(f'{label}: indexing failed ({type(exc).__name__}: {exc}); '
                                  + ('keeping the previous index' if keeping else
                                     'still no index'))

    # ------------------------------------------------------------------ scans
    def _on_scan(self, msg: LaserScan) -> None:
        with self._scan_cv:
            self._scan = msg
            self._scan_seq += 1
            self._scan_cv.notify_all()

    def _not_ready(self) -> str | None:
        """Why nothing can be localized now, or None."""
        if self.builder.busy:
            return f'indexing in progress ({self.builder.status()}); try again shortly'
        with self._state_lock:
            if self._localizer is None:
                return f'no map/index yet: waiting for {self._waiting_for}'
        return None

    def localize_msg(self, msg: LaserScan, verbose: bool = True):
        """Localize one scan and publish; return ``(Localization | None, reason | None)``."""
        reason = self._not_ready()
        if reason:
            return None, reason
        with self._state_lock:
            localizer, frame, index_marks = self._localizer, self._map_frame, self._index_markers
        args = scan_args_from_msg(msg)
        problem = scan_problem(args)
        if problem:
            self.get_logger().warning(f'skipping scan: {problem}', throttle_duration_sec=2.0)
            return None, f'bad scan: {problem}'
        if args.angle_increment < 0.0:
            self.get_logger().warning('negative angle_increment: mirrored (upside-down) laser? '
                                      'localizing the scan as given', once=True)
        with self._localize_lock:
            try:
                loc = localizer.localize_scan(*args.as_tuple())
            except Exception as exc:  # noqa: BLE001 - a bad scan must not kill the node
                self.get_logger().warning(f'localization error: {type(exc).__name__}: {exc}')
                return None, f'localization error: {exc}'
        stamp = msg.header.stamp
        now = time.monotonic()
        if self.get_parameter('publish_markers').value and (
                verbose or now - self._last_markers >= MARKER_PERIOD):
            self._last_markers = now
            marks = markers.localization_markers(
                loc, frame, stamp, self.localizer_config.top_n, scan_points(args),
                self.laser_pose, getattr(localizer.index, 'node_xy', None))
            self.marker_pub.publish(markers.marker_array([*index_marks, *marks], frame, stamp))
        pose = loc.pose
        if loc.status != 'ok' or pose is None or not all(math.isfinite(v) for v in pose):
            text = f'{loc.status}: {loc.message}'
            if verbose:
                self.get_logger().warning(f'no pose published: {text}')
            return loc, text
        out = pose_with_covariance(loc, 0, frame)
        out.header.stamp = stamp
        self.pose_pub.publish(out)
        if self.get_parameter('publish_initialpose').value:
            self.initialpose_pub.publish(out)
        log = self.get_logger().info if verbose else self.get_logger().debug
        log(f'{self.base_frame} in {frame}: {format_result(loc)}')
        return loc, None

    def _on_relocalize(self, request: Trigger.Request, response: Trigger.Response):
        reason = self._not_ready()
        timeout = float(self.get_parameter('scan_timeout').value)
        if reason is None and not self._call_slots.acquire(blocking=False):
            reason = f'busy: {MAX_WAITING_CALLS} relocalize calls are already waiting for a scan'
        elif reason is None:
            try:    # blocks this executor thread only; scans arrive on the others
                with self._scan_cv:
                    seq0 = self._scan_seq
                    got = self._scan_cv.wait_for(
                        lambda: self._scan_seq > seq0 or self._stopping.is_set(), timeout)
                    msg = self._scan
            finally:
                self._call_slots.release()
            if not got or msg is None or self._stopping.is_set():
                reason = (f'no scan received on {self.resolve_topic_name("scan")} within '
                          f'{timeout:g} s')
        if reason is None:
            loc, reason = self.localize_msg(msg, verbose=True)
        response.success = reason is None
        response.message = format_result(loc) if reason is None else reason
        if reason is not None:
            self.get_logger().warning(f'relocalize failed: {reason}')
        return response

    def _continuous_loop(self) -> None:
        done = 0
        period = 1.0 / self.rate if self.rate > 0 else 0.0
        next_t = 0.0
        while not self._stopping.is_set():
            if period and self._stopping.wait(max(0.0, next_t - time.monotonic())):
                return
            with self._scan_cv:
                self._scan_cv.wait_for(lambda: self._scan_seq > done or self._stopping.is_set())
                if self._stopping.is_set():
                    return
                msg, done = self._scan, self._scan_seq
            next_t = time.monotonic() + period
            reason = self._not_ready()
            if reason:
                self.get_logger().info(f'not localizing: {reason}', throttle_duration_sec=5.0)
                continue
            try:
                loc, reason = self.localize_msg(msg, verbose=False)
            except Exception:   # publishing fails once Ctrl-C has shut the context down
                if not self.context.ok():
                    return
                raise
            if reason and loc is not None:
                self.get_logger().info(f'no pose: {reason}', throttle_duration_sec=2.0)

    def destroy_node(self) -> None:
        self._stopping.set()
        with self._scan_cv:
            self._scan_cv.notify_all()
        self.builder.stop()
        if self._worker is not None:
            self._worker.join(timeout=5.0)
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return spin(GlobalLocalizerNode, args, num_threads=EXECUTOR_THREADS)


if __name__ == '__main__':
    raise SystemExit(main())
