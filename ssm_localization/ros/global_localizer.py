"""
``global_localizer`` lifecycle node: single-scan global localization for nav2 and scripts.

Lifecycle (rclpy.lifecycle; ``NODE/get_state``, ``NODE/change_state``):

- unconfigured: parameters declared and validated; the services answer that the node is not
  active. With ``autostart`` (default) the node configures and activates itself;
- configure: reads the parameters, loads ``index_file`` or waits for a map on ``map`` (both are
  watched: see :mod:`ssm_localization.ros.index_source`), creates the publishers;
- activate: scans are taken, the services localize, ``continuous`` mode runs, ``track`` mode
  tracks, ``localize_on_start`` localizes the first scans until an ``ok`` pose,
  ``/diagnostics`` ticks;
- deactivate / cleanup / shutdown undo those steps; waiting calls get an answer saying why.

Interfaces (docs INTERFACES.md): subscribes ``scan`` (LaserScan, sensor-data QoS) and ``map``
(OccupancyGrid, transient local); publishes ``global_pose`` (PoseWithCovarianceStamped,
transient local), ``initialpose`` (with ``publish_initialpose``), ``candidates`` (PoseArray,
transient local), ``topological_map`` (MarkerArray, transient local) and ``/diagnostics``;
serves ``relocalize`` (std_srvs/Trigger) and ``global_localization`` (std_srvs/Empty), both
"localize the next scan and publish".

``mode: track`` (issue 11) tracks every scan with odometry (``localization/tracker.py``, glue in
:mod:`ssm_localization.ros.tracking`): it subscribes ``odom`` (nav_msgs/Odometry; TF
``odom_frame`` <- ``base_frame`` when the topic is silent and tf2_ros exists) and ``initialpose``
(a prior), publishes ``global_pose`` for every scan tracked ``ok``, relocalizes globally by itself
when the track is lost, and broadcasts map -> odom with ``publish_tf`` where tf2_ros exists, as
AMCL does. The services' answers become the tracker's prior.
"""
from __future__ import annotations

from concurrent.futures import TimeoutError as FutureTimeout
from functools import partial
import math
from pathlib import Path
import threading
import time
from typing import Any, Callable, Iterator

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from ssm_localization.config import IndexConfig, LocalizerConfig, TrackerConfig
from ssm_localization.localization.localizer import GlobalLocalizer
from ssm_localization.localization.tracker import TrackResult
from ssm_localization.mapping.index import build_index, load_index, save_index
from ssm_localization.ros import markers
from ssm_localization.ros.conversions import (pose_array, pose_with_covariance, scan_args_from_msg,
                                              scan_points, scan_problem, ScanArgs)
from ssm_localization.ros.diagnostics import diagnostic_array, localization_status
from ssm_localization.ros.executor import spin
from ssm_localization.ros.index_builder import IndexBuilder
from ssm_localization.ros.index_source import IndexSource, ServedIndex
from ssm_localization.ros.laser_pose import LaserMount, LaserPoseSource
from ssm_localization.ros.lifecycle import (answer_invalid_transitions, configured_state,
                                            FAILURE, schedule_autostart, state_label, SUCCESS,
                                            transition)
from ssm_localization.ros.maps import usable_map
from ssm_localization.ros.odometry import MapOdomBroadcaster, OdometryBuffer, OdometrySource
from ssm_localization.ros.parameter_guard import ParameterGuard
from ssm_localization.ros.parameters import (build_config, config_problem, DYNAMIC,
                                             laser_pose_of, LOCALIZER_CONFIGS,
                                             localizer_parameters)
from ssm_localization.ros.qos import LATCHED_QOS, SERVICE_QOS
from ssm_localization.ros.requests import Answer, RequestQueue, ScanMailbox
from ssm_localization.ros.tracking import TrackSession
from std_srvs.srv import Empty, Trigger
from visualization_msgs.msg import MarkerArray

MODES = ('on_demand', 'continuous', 'track')
MARKER_PERIOD = 1.0          # seconds between marker updates in continuous mode
DIAGNOSTICS_PERIOD = 1.0     # seconds between /diagnostics messages while active
MAX_QUEUED_CALLS = 64        # service calls waiting for the next scan at once; more: refused
# executor threads: one per waiting call, plus room for scans, maps, lifecycle and refusals
EXECUTOR_THREADS = MAX_QUEUED_CALLS + 8
ANSWER_SLACK = 120.0         # s beyond scan_timeout a call waits for the localization itself
# odometry: best effort matches every publisher; room for the messages between two scans
ODOM_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)


def format_result(loc: Any) -> str:
    """One line for the service answer / log: pose, node, status, score, latency."""
    x, y, yaw = loc.pose
    return (f'x={x:.3f} y={y:.3f} yaw={yaw:.4f} node={loc.node} status={loc.status} '
            f'score={float(loc.score):.3f} latency_ms={float(loc.latency_ms):.1f}')


class GlobalLocalizerNode(LifecycleNode):
    """Global localization of single laser scans against the topological index of a map."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('global_localizer', **kwargs)
        answer_invalid_transitions(self)
        self._guard = ParameterGuard(self, localizer_parameters(), DYNAMIC, {'mode': MODES},
                                     partial(configured_state, self),
                                     partial(config_problem, LOCALIZER_CONFIGS))
        values = self._guard.declare()
        self._group = ReentrantCallbackGroup()
        self._mailbox = ScanMailbox()
        self._active = False
        self._stop = threading.Event()
        self._localize_lock = threading.Lock()   # one localization at a time
        self._state_lock = threading.Lock()      # guards the fields below
        self._last: Any = None                   # the last Localization (diagnostics)
        self._index_marks: list = []
        self._marks_frame = ''
        self._last_markers = 0.0
        self._configured_parts = False
        self._workers: list[threading.Thread] = []
        self._track_subs: list = []
        self.session: TrackSession | None = None
        self._diag_timer = None
        self._destroying = False
        # always there, so a call in any state gets an answer (not a silent wait for a service)
        self.create_service(Trigger, 'relocalize', self._on_relocalize,
                            qos_profile=SERVICE_QOS, callback_group=self._group)
        self.create_service(Empty, 'global_localization', self._on_global_localization,
                            qos_profile=SERVICE_QOS, callback_group=self._group)
        if values['autostart']:
            schedule_autostart(self)
        else:
            self.get_logger().info('autostart is false: waiting for configure / activate '
                                   '(lifecycle manager or ros2 lifecycle set)')

    # ------------------------------------------------------------------ lifecycle
    @transition('configure')
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self._destroying:
            return FAILURE
        values = self._guard.values()
        self.mode = str(values['mode'])
        self.base_frame = str(values['base_frame']).lstrip('/')
        self.map_frame_param = str(values['map_frame'])
        self.laser_pose = laser_pose_of(values)
        self.index_config = build_config(IndexConfig, 'index', values, self.laser_pose)
        self.localizer_config = build_config(LocalizerConfig, 'localizer', values,
                                             self.laser_pose)
        self.rate = float(values['rate'])
        self.max_map_cells = int(values['max_map_cells'])
        self.max_gvd_points = int(values['max_gvd_points'])
        index_file = str(values['index_file'])
        index_path = Path(index_file).expanduser() if index_file else None

        self._laser = LaserPoseSource.for_node(self, self.base_frame, self.laser_pose,
                                               self.get_logger().info)
        if not self._laser.uses_tf:
            self.get_logger().info('tf2_ros is not installed: the laser pose comes from the '
                                   'laser_x / laser_y / laser_yaw parameters')
        self.pose_pub = self.create_lifecycle_publisher(PoseWithCovarianceStamped,
                                                        'global_pose', LATCHED_QOS)
        self.initialpose_pub = self.create_lifecycle_publisher(
            PoseWithCovarianceStamped, 'initialpose',
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        self.candidates_pub = self.create_lifecycle_publisher(PoseArray, 'candidates',
                                                              LATCHED_QOS)
        self.marker_pub = self.create_lifecycle_publisher(MarkerArray, 'topological_map',
                                                          LATCHED_QOS)
        self.diagnostics_pub = self.create_lifecycle_publisher(DiagnosticArray, '/diagnostics',
                                                               10)
        self.builder = IndexBuilder(self.get_logger(), self._on_index_done,
                                    self._on_index_error)
        self.source = IndexSource(
            self.builder, self.get_logger(), index_path, self.resolve_topic_name('map'),
            partial(load_index, max_cells=self.max_map_cells), self._build, self._make_served,
            save_index, self._on_ready, self._on_frame)
        self.source.start()      # before the map subscription: a latched map may come at once
        self._map_sub = self.create_subscription(OccupancyGrid, 'map', self._on_map,
                                                 LATCHED_QOS, callback_group=self._group)
        self._scan_sub = self.create_subscription(LaserScan, 'scan', self._on_scan,
                                                  qos_profile_sensor_data,
                                                  callback_group=self._group)
        self._queue = RequestQueue(self._mailbox, MAX_QUEUED_CALLS, self._serve,
                                   self._no_scan_text)
        if self.mode == 'track':
            self._configure_tracking(values)
        self._configured_parts = True
        self.get_logger().info(f'configured: mode {self.mode}, base frame {self.base_frame}; '
                               f'map: {self.source.map_state()[1]}')
        return SUCCESS

    @transition('activate')
    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)       # enables the lifecycle publishers
        self._stop.clear()
        self._active = True
        with self._state_lock:
            marks, frame = self._index_marks, self._marks_frame
        if marks and self.get_parameter('publish_markers').value:
            self.marker_pub.publish(markers.marker_array(marks, frame, self._now_ns()))
        self._diag_timer = self.create_timer(DIAGNOSTICS_PERIOD, self._publish_diagnostics,
                                             callback_group=self._group)
        if self.mode in ('continuous', 'track'):
            if self.get_parameter('localize_on_start').value:
                self.get_logger().info(f'localize_on_start: {self.mode} mode localizes every '
                                       'scan anyway')
            if self.mode == 'track':
                self._start_worker(self._track_loop, 'tracker')
            else:
                self._start_worker(self._continuous_loop, 'continuous_localizer')
        elif self.get_parameter('localize_on_start').value:
            self._start_worker(self._startup_loop, 'localize_on_start')
        self._publish_diagnostics()
        return result

    @transition('deactivate')
    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate_parts('deactivated')
        return super().on_deactivate(state)

    @transition('cleanup')
    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._cleanup_parts('cleaned up')
        return SUCCESS

    @transition('shutdown')
    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate_parts('shutting down')
        self._cleanup_parts('shutting down')
        return SUCCESS

    @transition('error processing')
    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate_parts('error')
        self._cleanup_parts('error')
        return SUCCESS

    def _deactivate_parts(self, why: str) -> None:
        self._active = False
        self._stop.set()
        self._mailbox.wake()
        if self._configured_parts:
            n = self._queue.cancel_all(f'not localized: global_localizer {why} while the call '
                                       'waited for a scan')
            if n:
                self.get_logger().warning(f'{n} waiting calls answered: {why}')
        for worker in self._workers:
            worker.join(timeout=10.0)
        self._workers = []
        if self._diag_timer is not None:
            self.destroy_timer(self._diag_timer)
            self._diag_timer = None
        self._mailbox.clear()

    def _cleanup_parts(self, why: str) -> None:
        if not self._configured_parts:
            return
        self._configured_parts = False
        self._queue.stop(f'not localized: global_localizer {why}')
        self.builder.stop()
        self._laser.close()
        self.destroy_subscription(self._map_sub)
        self.destroy_subscription(self._scan_sub)
        for sub in self._track_subs:
            self.destroy_subscription(sub)
        self._track_subs, self.session = [], None
        for pub in (self.pose_pub, self.initialpose_pub, self.candidates_pub, self.marker_pub,
                    self.diagnostics_pub):
            self.destroy_lifecycle_publisher(pub)
        with self._state_lock:
            self._last, self._index_marks = None, []

    def _start_worker(self, target, name: str) -> None:
        worker = threading.Thread(target=target, name=name, daemon=True)
        self._workers.append(worker)
        worker.start()

    def destroy_node(self) -> None:
        """Stop the worker threads, then destroy the node."""
        self._destroying = True
        self._deactivate_parts('shutting down')
        self._cleanup_parts('shutting down')
        super().destroy_node()

    def _configure_tracking(self, values: dict[str, Any]) -> None:
        """Track mode: the tracker session, ``odom`` and ``initialpose``, the TF broadcaster."""
        odom_frame = str(values['odom_frame']).lstrip('/')
        buffer = OdometryBuffer(float(values['odom_max_age']))
        odometry = OdometrySource(buffer, odom_frame, self.base_frame, self._laser.buffer)
        broadcaster = MapOdomBroadcaster.for_node(self, odom_frame,
                                                  float(values['transform_tolerance']))
        if broadcaster is None:
            self.get_logger().info('tf2_ros is not installed: map -> odom is not broadcast')
        self.session = TrackSession(build_config(TrackerConfig, 'tracker', values,
                                                 self.laser_pose),
                                    odometry, broadcaster, self.get_logger().info)
        self._track_subs = [
            self.create_subscription(Odometry, 'odom', buffer.add, ODOM_QOS,
                                     callback_group=self._group),
            self.create_subscription(PoseWithCovarianceStamped, 'initialpose',
                                     self._on_initialpose, 10, callback_group=self._group)]
        if values['publish_initialpose']:
            self.get_logger().warning('publish_initialpose is ignored in track mode (the node '
                                      'takes initialpose as its prior)')

    def _on_initialpose(self, msg: PoseWithCovarianceStamped) -> None:
        if self.session is None:
            return
        try:
            self.get_logger().info(self.session.prior_from_msg(msg,
                                                               self._frame(self.source.served)))
        except ValueError as exc:
            self.get_logger().warning(f'initialpose ignored: {exc}')

    # ------------------------------------------------------------------ map and index
    def _build(self, occ, progress):
        return build_index(occ, self.index_config, progress=progress)

    def _make_served(self, index, source: str) -> ServedIndex:
        sensor = tuple(getattr(index.config, 'sensor_pose', self.laser_pose))
        if source != 'map topic' and any(abs(a - b) > 1e-6
                                         for a, b in zip(sensor, self.laser_pose)):
            self.get_logger().warning(f'{source} was built with the laser at {sensor} on the '
                                      f'base, the laser_* parameters say {self.laser_pose}')
        localizer = GlobalLocalizer(index, self.localizer_config)
        return ServedIndex(index, localizer, index.map_checksum, source,
                           getattr(index.map, 'frame_id', '') or '')

    def _on_index_done(self, result, label: str) -> None:
        self.source.on_done(result, label)

    def _on_index_error(self, exc: BaseException, label: str) -> None:
        self.source.on_error(exc, label)

    def _frame(self, served: ServedIndex | None) -> str:
        return self.map_frame_param or (served.frame if served else '') or 'map'

    def _on_ready(self, served: ServedIndex) -> None:
        frame = self._frame(served)
        how = 'loaded' if served.source != 'map topic' else 'indexed'
        self.get_logger().info(f'{served.source}: {how}, ready, {len(served.index.node_xy)} '
                               f'nodes (frame {frame})')
        self._refresh_index_markers(served, frame)

    def _on_frame(self, frame: str) -> None:
        served = self.source.served
        if served is not None:
            self._refresh_index_markers(served, self._frame(served))

    def _refresh_index_markers(self, served: ServedIndex, frame: str) -> None:
        stamp = self._now_ns()
        marks = markers.index_markers(served.index, frame, stamp, self.max_gvd_points)
        with self._state_lock:
            self._index_marks, self._marks_frame = marks, frame
        if self._active and self.get_parameter('publish_markers').value:
            self.marker_pub.publish(markers.marker_array(marks, frame, stamp))

    def _on_map(self, msg: OccupancyGrid) -> None:
        occ = usable_map(msg, self.max_map_cells, self.get_logger())
        if occ is not None:
            self.source.on_map(occ)

    def map_state(self) -> tuple[str, str]:
        """``('no map' | 'indexing' | 'ready', detail)``; ``'no map'`` before configure."""
        if not self._configured_parts:
            return 'no map', 'not configured'
        return self.source.map_state()

    # ------------------------------------------------------------------ scans
    def _on_scan(self, msg: LaserScan) -> None:
        if self._active:
            self._mailbox.put(msg)

    def _not_ready(self) -> str | None:
        """Why nothing can be localized now, or None."""
        if not self._active:
            label = state_label(self)
            todo = {'unconfigured': 'configure and activate it', 'inactive': 'activate it',
                    'finalized': 'it has shut down'}.get(label, 'try again once it is active')
            return (f'global_localizer is {label}, not active: {todo} (ros2 lifecycle set '
                    f'{self.get_fully_qualified_name()} configure|activate)')
        state, detail = self.source.map_state()
        if state == 'indexing':
            return f'indexing in progress ({detail}); try again shortly'
        if state == 'no map':
            return f'no map/index yet: {detail}'
        return None

    def _localizer_for(self, served: ServedIndex, mount: LaserMount) -> GlobalLocalizer:
        pose = tuple(mount.pose)
        if all(abs(a - b) < 1e-9 for a, b in zip(pose, served.localizer.config.laser_pose)):
            return served.localizer
        with self._state_lock:
            variant = served.variants.get(pose)
            if variant is None:
                variant = served.variants[pose] = served.localizer.with_laser_pose(pose)
        return variant

    def _prepare(self, msg: LaserScan) -> tuple[ScanArgs, LaserMount] | str:
        """
        Return the scan's arguments and the laser mount, or why the scan is skipped.

        The arguments are mirrored for an upside-down laser.
        """
        args = scan_args_from_msg(msg)
        problem = scan_problem(args)
        if problem:
            self.get_logger().warning(f'skipping scan: {problem}', throttle_duration_sec=2.0)
            return f'bad scan: {problem}'
        mount = self._laser.mount(msg.header.frame_id)
        if mount.mirrored:
            args = ScanArgs(args.ranges, -args.angle_min, -args.angle_increment,
                            args.range_min, args.range_max)
        elif args.angle_increment < 0.0:
            self.get_logger().warning('negative angle_increment: mirrored (upside-down) laser? '
                                      'localizing the scan as given', once=True)
        return args, mount

    def _ready(self) -> ServedIndex | str:
        """Return the index served now, or why nothing can be localized."""
        reason = self._not_ready()
        served = self.source.served
        if reason is None and served is None:
            reason = 'no map/index yet'
        return reason or served

    def _process(self, msg: LaserScan, served: ServedIndex, verbose: bool,
                 run: Callable[[GlobalLocalizer, ScanArgs], Any],
                 what: str = 'localization') -> tuple[Any, str | None]:
        """
        Localize (or track) one scan with ``served`` and publish.

        ``run(localizer, args)`` returns the Localization (or TrackResult); it runs under the
        localization lock. Returns ``(result | None, reason | None)``: the reason is None when
        a pose was published.
        """
        prepared = self._prepare(msg)
        if isinstance(prepared, str):
            return None, prepared
        args, mount = prepared
        localizer = self._localizer_for(served, mount)
        with self._localize_lock:
            try:
                result = run(localizer, args)
            except Exception as exc:  # noqa: BLE001 - a bad scan must not kill the node
                self.get_logger().warning(f'{what} error: {type(exc).__name__}: {exc}')
                return None, f'{what} error: {exc}'
        loc = result.as_localization() if isinstance(result, TrackResult) else result
        if self._publish_result(loc, msg, args, mount, served, verbose):
            return result, None
        text = f'{loc.status}: {loc.message}'
        if verbose:
            self.get_logger().warning(f'no pose published: {text}')
        return result, text

    def _localize(self, msg: LaserScan, served: ServedIndex,
                  verbose: bool) -> tuple[Any, str | None]:
        """Localize one scan and publish; ``(Localization | None, reason | None)``."""
        return self._process(msg, served, verbose,
                             lambda localizer, args: localizer.localize_scan(*args.as_tuple()))

    def _track(self, msg: LaserScan, served: ServedIndex) -> None:
        """Track one scan (track mode) and publish."""
        session = self.session
        if session is None:
            return
        publish_tf = bool(self.get_parameter('publish_tf').value)
        result, _ = self._process(
            msg, served, False,
            lambda localizer, args: session.track(localizer, args, msg.header.stamp,
                                                  self._frame(served), publish_tf),
            'tracking')
        if result is not None and result.mode != 'tracked':
            self.get_logger().info(f'track: {result.mode}, {result.status}: {result.message}',
                                   throttle_duration_sec=1.0)

    def _publish_result(self, loc, msg: LaserScan, args: ScanArgs, mount: LaserMount,
                        served: ServedIndex, verbose: bool) -> bool:
        """Publish the candidates, markers and an ``ok`` finite pose; True when a pose was."""
        frame = self._frame(served)
        stamp = msg.header.stamp
        with self._state_lock:
            self._last = loc
            index_marks = self._index_marks
        top_n = self.localizer_config.top_n
        self.candidates_pub.publish(pose_array(
            [c.pose for c in list(loc.candidates or [])[:top_n]], stamp, frame))
        now = time.monotonic()
        if self.get_parameter('publish_markers').value and (
                verbose or now - self._last_markers >= MARKER_PERIOD):
            self._last_markers = now
            marks = markers.localization_markers(loc, frame, stamp, top_n, scan_points(args),
                                                 mount.pose, served.index.node_xy)
            self.marker_pub.publish(markers.marker_array([*index_marks, *marks], frame, stamp))
        pose = loc.pose
        published = loc.ok and pose is not None and all(math.isfinite(v) for v in pose)
        if published:
            out = pose_with_covariance(loc, 0, frame)
            out.header.stamp = stamp
            self.pose_pub.publish(out)
            if self.get_parameter('publish_initialpose').value and self.mode != 'track':
                self.initialpose_pub.publish(out)
            log = self.get_logger().info if verbose else self.get_logger().debug
            log(f'{self.base_frame} in {frame}: {format_result(loc)}')
        if verbose:
            self._publish_diagnostics()
        return published

    # ------------------------------------------------------------------ services
    def _serve(self, msg: LaserScan) -> Answer:
        served = self._ready()
        if isinstance(served, str):
            return Answer(False, served)
        loc, reason = self._localize(msg, served, verbose=True)
        if reason is None and self.session is not None:
            self.session.set_prior(loc.pose, loc.covariance)    # the track goes on from there
        return Answer(reason is None, format_result(loc) if reason is None else reason)

    def _no_scan_text(self, timeout: float) -> str:
        return f'no scan received on {self.resolve_topic_name("scan")} within {timeout:g} s'

    def _localize_next_scan(self, service: str) -> Answer:
        """Wait (in this executor thread) for the answer of the next scan, or refuse."""
        reason = self._not_ready()
        if reason is None:
            timeout = float(self.get_parameter('scan_timeout').value)
            queued = self._queue.submit(timeout)
            if isinstance(queued, str):
                answer = Answer(False, queued)
            else:
                try:
                    answer = queued.result(timeout=timeout + ANSWER_SLACK)
                except FutureTimeout:
                    answer = Answer(False, f'no answer within {timeout + ANSWER_SLACK:g} s')
        else:
            answer = Answer(False, reason)
        if not answer.ok:
            self.get_logger().warning(f'{service} failed: {answer.message}')
        return answer

    def _on_relocalize(self, request: Trigger.Request, response: Trigger.Response):
        answer = self._localize_next_scan('relocalize')
        response.success, response.message = answer.ok, answer.message
        return response

    def _on_global_localization(self, request: Empty.Request, response: Empty.Response):
        self._localize_next_scan('global_localization')
        return response

    # ------------------------------------------------------------------ loops
    def _continuous_loop(self) -> None:
        """Continuous mode: localize the newest scan, at most ``rate`` times a second."""
        period = 1.0 / self.rate if self.rate > 0 else 0.0
        for msg, served in self._ready_scans('not localizing: {reason}', period):
            loc, reason = self._localize(msg, served, verbose=False)
            if reason and loc is not None:
                self.get_logger().info(f'no pose: {reason}', throttle_duration_sec=2.0)

    def _ready_scans(self, waiting: str,
                     period: float = 0.0) -> Iterator[tuple[LaserScan, ServedIndex]]:
        """
        Yield the newest scan and the served index, again and again, when it can be localized.

        Until the node stops; while it cannot localize, ``waiting`` (with ``{reason}``) is
        logged now and then. With a ``period`` (s), a scan is taken at most that often (timed
        from when the last one was taken; the scans in between are dropped).
        """
        done = self._mailbox.seq
        next_t = 0.0
        while not self._stop.is_set():
            if period and self._stop.wait(max(0.0, next_t - time.monotonic())):
                return
            got = self._mailbox.wait_newer(done, None, self._stop)
            if got is None:
                continue
            msg, done = got
            next_t = time.monotonic() + period
            served = self._ready()
            if isinstance(served, str):
                self.get_logger().info(waiting.format(reason=served), throttle_duration_sec=5.0)
                continue
            yield msg, served

    def _track_loop(self) -> None:
        """Track mode: track the newest scan, again and again."""
        for msg, served in self._ready_scans('not tracking: {reason}'):
            self._track(msg, served)

    def _startup_loop(self) -> None:
        """``localize_on_start``: localize incoming scans until the first ``ok`` pose."""
        self.get_logger().info('localize_on_start: localizing incoming scans until the first '
                               'ok pose')
        for msg, served in self._ready_scans('localize_on_start: waiting ({reason})'):
            loc, reason = self._localize(msg, served, verbose=False)
            if reason is None:
                self.get_logger().info(f'localize_on_start: localized, {format_result(loc)}; '
                                       'on demand from now on')
                self._publish_diagnostics()
                return
            self.get_logger().info(f'localize_on_start: {reason}; trying the next scan',
                                   throttle_duration_sec=2.0)

    # ------------------------------------------------------------------ diagnostics
    def _publish_diagnostics(self) -> None:
        if not self._configured_parts:
            return
        state, detail = self.source.map_state()
        with self._state_lock:
            last = self._last
        served = self.source.served
        status = localization_status(self.get_name(), self.get_fully_qualified_name(), state,
                                     last, detail, self._frame(served), state_label(self),
                                     self.mode)
        try:
            self.diagnostics_pub.publish(diagnostic_array([status], self._now_ns()))
        except Exception:  # noqa: BLE001 - a tick racing with cleanup: the publisher is gone
            if self._configured_parts:
                raise

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run ssm_localization global_localizer``."""
    return spin(GlobalLocalizerNode, args, num_threads=EXECUTOR_THREADS)


if __name__ == '__main__':
    raise SystemExit(main())
