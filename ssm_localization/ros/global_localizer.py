"""
``global_localizer`` lifecycle node: single-scan global localization for nav2 and scripts.

Lifecycle (rclpy.lifecycle; ``NODE/get_state``, ``NODE/change_state``):

- unconfigured: parameters declared and validated; the services answer that the node is not
  active. With ``autostart`` (default; for ``ros2 run``) the node configures and activates
  itself; under a lifecycle manager ``autostart`` must be false (the launch files set it);
- configure: reads the parameters, loads ``index_file`` or waits for a map on ``map_topic``
  (both are watched: see :mod:`ssm_localization.ros.index_source`), creates the publishers;
- activate: scans are taken, the services localize, ``continuous`` mode runs, ``track`` mode
  tracks, ``localize_on_start`` localizes the first scans until an ``ok`` pose,
  ``/diagnostics`` ticks;
- deactivate / cleanup / shutdown undo those steps; waiting calls get an answer saying why.

A scan's way to a published pose, in this file's order: ``_on_scan`` stores it in the mailbox;
a service call (``RequestQueue`` worker -> ``_serve``) or a mode loop (``_each_scan``) takes
it to ``_localize`` / ``_track``, which ``_prepare`` it (ready index, scan checks, laser mount;
:class:`Refused` says why not), run the core and ``_publish`` the result (``global_pose``,
``candidates``, markers, and the hand-over on ``initialpose``).

Interfaces (docs/ROS_API.md): subscribes ``scan_topic`` (LaserScan, sensor-data QoS) and
``map_topic`` (OccupancyGrid, transient local); publishes ``global_pose``
(PoseWithCovarianceStamped, transient local), ``initialpose`` (with ``publish_initialpose``:
republished until ``handover_confirm_topic`` confirms it, :mod:`ssm_localization.ros.handover`),
``candidates`` (PoseArray, transient local), ``topological_map`` (MarkerArray, transient local)
and ``/diagnostics``; serves ``relocalize`` (std_srvs/Trigger) and ``global_localization``
(std_srvs/Empty), both "localize the next scan and publish", and with
``serve_reinitialize_global_localization`` nav2's ``reinitialize_global_localization``
(std_srvs/Empty): answered at once when a search starts, not answered when it cannot start.

``mode: track`` tracks every scan with odometry (``localization/tracker.py``, glue in
:mod:`ssm_localization.ros.tracking`): it subscribes ``odom`` (nav_msgs/Odometry; TF
``odom_frame`` <- ``base_frame`` when the topic is silent and tf2_ros exists) and takes
``initialpose`` as its prior (also one received before configure or activation), publishes
``global_pose`` for every scan tracked ``ok``, relocalizes globally by itself when the track is
lost, and broadcasts map -> odom with ``publish_tf`` where tf2_ros exists, as AMCL does. The
services' answers become the tracker's prior.
"""
from __future__ import annotations

from concurrent.futures import Future, TimeoutError as FutureTimeout
from dataclasses import dataclass
from functools import partial
import math
from pathlib import Path
import threading
import time
from typing import Any, Callable, TypeVar

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from ssm_localization.localization.localizer import GlobalLocalizer, Localization
from ssm_localization.ros import markers
from ssm_localization.ros.conversions import (pose_array, pose_with_covariance, scan_args_from_msg,
                                              scan_points, scan_problem, ScanArgs)
from ssm_localization.ros.diagnostics import diagnostic_array, localization_status
from ssm_localization.ros.executor import spin
from ssm_localization.ros.handover import HandOver, HandOverConfig
from ssm_localization.ros.index_source import (IndexPhase, IndexSource, IndexWork, MapState,
                                               ServedIndex)
from ssm_localization.ros.laser_pose import LaserMount, LaserPoseSource
from ssm_localization.ros.lifecycle import (answer_invalid_transitions, configured_state,
                                            FAILURE, schedule_autostart, state_label, SUCCESS,
                                            transition)
from ssm_localization.ros.maps import usable_map
from ssm_localization.ros.odometry import MapOdomBroadcaster, OdometryBuffer, OdometrySource
from ssm_localization.ros.parameter_guard import ParameterGuard
from ssm_localization.ros.parameters import (config_problem, DYNAMIC, laser_pose_of,
                                             localizer_parameters, node_configs)
from ssm_localization.ros.qos import LATCHED_QOS, SERVICE_QOS
from ssm_localization.ros.requests import Answer, Refused, RequestQueue, ScanMailbox
from ssm_localization.ros.services import create_withholding_service
from ssm_localization.ros.tracking import TrackSession
from std_srvs.srv import Empty, Trigger
from visualization_msgs.msg import MarkerArray

NODE_MODES = ('on_demand', 'continuous', 'track')   # values of the mode parameter
MARKER_PERIOD = 1.0          # seconds between marker updates in continuous mode
DIAGNOSTICS_PERIOD = 1.0     # seconds between /diagnostics messages while active
MAX_QUEUED_CALLS = 64        # service calls waiting for the next scan at once; more: refused
# executor threads: one per waiting call, plus room for scans, maps, lifecycle and refusals
EXECUTOR_THREADS = MAX_QUEUED_CALLS + 8
ANSWER_SLACK = 120.0         # s beyond scan_timeout a call waits for the localization itself
# odometry: best effort matches every publisher; room for the messages between two scans
ODOM_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT)
# initialpose: reliable and volatile, as RViz and nav2 publish it and AMCL subscribes it
INITIALPOSE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
NAV2_SERVICE = 'reinitialize_global_localization'

T = TypeVar('T')


def format_result(loc: Localization) -> str:
    """One line for the service answer / log: pose, node, status, confidence, score, latency."""
    x, y, yaw = loc.pose
    return (f'x={x:.3f} y={y:.3f} yaw={yaw:.4f} node={loc.node} status={loc.status} '
            f'confidence={float(loc.confidence):.3f} score={float(loc.score):.3f} '
            f'latency_ms={float(loc.latency_ms):.1f}')


@dataclass(frozen=True)
class Prepared:
    """A scan ready for the core: its arguments, the laser mount, the index and localizer."""

    msg: LaserScan
    args: ScanArgs
    mount: LaserMount
    served: ServedIndex
    localizer: GlobalLocalizer


@dataclass(frozen=True)
class Outcome:
    """What became of one localized scan: the result, and whether a pose was published."""

    localization: Localization
    published: bool

    @property
    def reason(self) -> str:
        """Why no pose was published (empty when one was)."""
        loc = self.localization
        return '' if self.published else f'{loc.status}: {loc.message}'


class GlobalLocalizerNode(LifecycleNode):
    """Global localization of single laser scans against the topological index of a map."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('global_localizer', **kwargs)
        answer_invalid_transitions(self)
        self._guard = ParameterGuard(self, localizer_parameters(), DYNAMIC,
                                     {'mode': NODE_MODES}, partial(configured_state, self),
                                     config_problem)
        values = self._guard.declare()
        self._group = ReentrantCallbackGroup()
        self._mailbox = ScanMailbox()
        self._active = False
        self._stop = threading.Event()
        self._localize_lock = threading.Lock()   # one localization at a time
        self._state_lock = threading.Lock()      # guards the fields below
        self._last: Localization | None = None   # the last localization (diagnostics)
        self._last_checksum = ''                  # of the map it was made on
        self._index_marks: list = []
        self._marks_frame = ''
        self._early_prior: PoseWithCovarianceStamped | None = None   # initialpose before track
        self._last_markers = 0.0
        self._configured_parts = False
        # what on_configure creates (None until then, and again after cleanup)
        self._laser = self.handover = self.source = self._queue = None
        self._map_sub = self._scan_sub = None
        self.pose_pub = self.initialpose_pub = self.candidates_pub = None
        self.marker_pub = self.diagnostics_pub = None
        self._pending_prior: PoseWithCovarianceStamped | None = None   # until a map frame
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
        # nav2's behavior tree checks the service exists when it loads the tree: from the start
        self._nav2_service = None
        self._serve_nav2_service(bool(values['serve_reinitialize_global_localization']))
        # a pose on initialpose is kept in every state (track mode takes it as its prior)
        self.create_subscription(PoseWithCovarianceStamped, 'initialpose', self._on_initialpose,
                                 INITIALPOSE_QOS, callback_group=self._group)
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
        try:
            return self._configure_parts(values)
        except Exception:
            self._release_parts()     # what was created before the failure, nothing left behind
            raise

    def _configure_parts(self, values: dict[str, Any]) -> TransitionCallbackReturn:
        configs = node_configs(values)
        self._serve_nav2_service(bool(values['serve_reinitialize_global_localization']))
        self.mode = str(values['mode'])
        self.base_frame = str(values['base_frame']).lstrip('/')
        self.map_frame_param = str(values['map_frame']).lstrip('/')
        self.laser_pose = laser_pose_of(values)
        self.index_config, self.localizer_config = configs.index, configs.localizer
        self.rate = float(values['rate'])
        self.max_map_cells = int(values['max_map_cells'])
        self.max_gvd_points = int(values['max_gvd_points'])
        index_file = str(values['index_file'])
        scan_topic, map_topic = str(values['scan_topic']), str(values['map_topic'])

        self._laser = LaserPoseSource.for_node(self, self.base_frame, self.laser_pose,
                                               self.get_logger().info)
        if not self._laser.uses_tf:
            self.get_logger().info('tf2_ros is not installed: the laser pose comes from the '
                                   'laser_x / laser_y / laser_yaw parameters')
        self.pose_pub = self.create_lifecycle_publisher(PoseWithCovarianceStamped,
                                                        'global_pose', LATCHED_QOS)
        self.initialpose_pub = self.create_lifecycle_publisher(
            PoseWithCovarianceStamped, 'initialpose', INITIALPOSE_QOS)
        self.handover = HandOver(self, self.initialpose_pub, HandOverConfig(
            str(values['handover_confirm_topic']), float(values['handover_period']),
            int(values['handover_tries']), float(values['handover_tolerance'])),
            self._group, self.get_logger())
        self.candidates_pub = self.create_lifecycle_publisher(PoseArray, 'candidates',
                                                              LATCHED_QOS)
        self.marker_pub = self.create_lifecycle_publisher(MarkerArray, 'topological_map',
                                                          LATCHED_QOS)
        self.diagnostics_pub = self.create_lifecycle_publisher(DiagnosticArray, '/diagnostics',
                                                               10)
        self.source = IndexSource(
            IndexWork(configs.index, configs.localizer, self.max_map_cells), self.get_logger(),
            Path(index_file).expanduser() if index_file else None,
            self.resolve_topic_name(map_topic), self._on_served)
        self.source.start()      # before the map subscription: a latched map may come at once
        self._map_sub = self.create_subscription(OccupancyGrid, map_topic, self._on_map,
                                                 LATCHED_QOS, callback_group=self._group)
        self._scan_sub = self.create_subscription(LaserScan, scan_topic, self._on_scan,
                                                  qos_profile_sensor_data,
                                                  callback_group=self._group)
        self._queue = RequestQueue(self._mailbox, MAX_QUEUED_CALLS, self._serve,
                                   self._no_scan_text)
        if self.mode == 'track':
            self._configure_tracking(values, configs.tracker)
        else:
            with self._state_lock:
                self._early_prior = None          # only track mode takes initialpose
        self._configured_parts = True
        self.get_logger().info(f'configured: mode {self.mode}, base frame {self.base_frame}; '
                               f'map: {self.source.map_state().detail}')
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
            self.handover.stop()
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
        self._release_parts(why)

    def _release_parts(self, why: str = 'configure failed') -> None:
        """Stop and destroy every part ``on_configure`` created (those that exist)."""
        if self._queue is not None:
            self._queue.stop(f'not localized: global_localizer {why}')
        if self.source is not None:
            self.source.stop()
        for part in (self._laser, self.handover):
            if part is not None:
                part.close()
        for sub in (self._map_sub, self._scan_sub, *self._track_subs):
            if sub is not None:
                self.destroy_subscription(sub)
        for pub in (self.pose_pub, self.initialpose_pub, self.candidates_pub, self.marker_pub,
                    self.diagnostics_pub):
            if pub is not None:
                self.destroy_lifecycle_publisher(pub)
        self._laser = self.handover = self.source = self._queue = None
        self._map_sub = self._scan_sub = None
        self.pose_pub = self.initialpose_pub = self.candidates_pub = None
        self.marker_pub = self.diagnostics_pub = None
        self._track_subs, self.session = [], None
        with self._state_lock:
            self._last, self._index_marks, self._pending_prior = None, [], None

    def _start_worker(self, target: Callable[[], None], name: str) -> None:
        worker = threading.Thread(target=target, name=name, daemon=True)
        self._workers.append(worker)
        worker.start()

    def destroy_node(self) -> None:
        """Stop the worker threads, then destroy the node."""
        self._destroying = True
        self._deactivate_parts('shutting down')
        self._cleanup_parts('shutting down')
        super().destroy_node()

    def _configure_tracking(self, values: dict[str, Any], config: Any) -> None:
        """Track mode: the tracker session, ``odom``, the TF broadcaster, a kept prior."""
        odom_frame = str(values['odom_frame']).lstrip('/')
        buffer = OdometryBuffer(float(values['odom_max_age']))
        odometry = OdometrySource(buffer, odom_frame, self.base_frame, self._laser.buffer)
        broadcaster = MapOdomBroadcaster.for_node(self, odom_frame,
                                                  float(values['transform_tolerance']))
        if broadcaster is None:
            self.get_logger().info('tf2_ros is not installed: map -> odom is not broadcast')
        self.session = TrackSession(config, odometry, broadcaster, self.get_logger().info)
        self._track_subs = [
            self.create_subscription(Odometry, 'odom', buffer.add, ODOM_QOS,
                                     callback_group=self._group)]
        if values['publish_initialpose']:
            self.get_logger().warning('publish_initialpose is ignored in track mode (the node '
                                      'takes initialpose as its prior)')
        with self._state_lock:
            early, self._early_prior = self._early_prior, None
        if early is not None:
            self._take_prior(early)

    def _on_initialpose(self, msg: PoseWithCovarianceStamped) -> None:
        """Track mode: the prior. Before a track session exists it is kept for it."""
        if self.session is not None:
            self._take_prior(msg)
        elif not self._configured_parts:
            with self._state_lock:
                self._early_prior = msg
            self.get_logger().info('initialpose received before configure: kept as the prior '
                                   'of track mode')

    def _take_prior(self, msg: PoseWithCovarianceStamped) -> None:
        served = self.source.served
        if served is None and not self.map_frame_param:
            # the map's frame is not known before its index is served: judged then
            with self._state_lock:
                self._pending_prior = msg
            self.get_logger().info("initialpose kept: its frame is checked against the map's "
                                   'once the map is indexed')
            return
        try:
            self.get_logger().info(self.session.prior_from_msg(msg, self._frame(served)))
        except ValueError as exc:
            self.get_logger().warning(f'initialpose ignored: {exc}')

    # ------------------------------------------------------------------ map and index
    def _on_map(self, msg: OccupancyGrid) -> None:
        occ = usable_map(msg, self.max_map_cells, self.get_logger())
        if occ is not None:
            self.source.on_map(occ)

    def _on_served(self, served: ServedIndex) -> None:
        """
        IndexSource: a new index (or frame) is served: its markers.

        A different map ends the last answer: it is no longer reported (``/diagnostics``) and
        the candidates are cleared; the latched ``global_pose`` keeps its stamp. A prior that
        waited for the map's frame is taken now.
        """
        frame = self._frame(served)
        stamp = self._now_ns()
        marks = markers.index_markers(served.index, frame, stamp, self.max_gvd_points)
        with self._state_lock:
            new_map = self._last is not None and self._last_checksum != served.checksum
            self._index_marks, self._marks_frame = marks, frame
            if new_map:
                self._last = None
            pending, self._pending_prior = self._pending_prior, None
        if self._active and self.get_parameter('publish_markers').value:
            self.marker_pub.publish(markers.marker_array(marks, frame, stamp))
        if new_map and self._active:
            self.candidates_pub.publish(pose_array([], stamp, frame))
        if pending is not None and self.session is not None:
            self._take_prior(pending)

    def _frame(self, served: ServedIndex | None) -> str:
        return self.map_frame_param or (served.frame.lstrip('/') if served else '') or 'map'

    def map_state(self) -> MapState:
        """Return the index source's state; ``WAITING`` (not configured) before configure."""
        if not self._configured_parts:
            return MapState(IndexPhase.WAITING, 'not configured')
        return self.source.map_state()

    # ------------------------------------------------------------------ one scan
    def _on_scan(self, msg: LaserScan) -> None:
        if self._active:
            self._mailbox.put(msg)

    def _check_ready(self) -> ServedIndex:
        """Return the index served now; raise :class:`Refused` saying why nothing can be."""
        if not self._active:
            label = state_label(self)
            todo = {'unconfigured': 'configure and activate it', 'inactive': 'activate it',
                    'finalized': 'it has shut down'}.get(label, 'try again once it is active')
            raise Refused(f'global_localizer is {label}, not active: {todo} (ros2 lifecycle set '
                          f'{self.get_fully_qualified_name()} configure|activate)')
        phase, detail = self.source.map_state()
        if phase in (IndexPhase.LOADING, IndexPhase.INDEXING):
            raise Refused(f'indexing in progress ({detail}); try again shortly')
        served = self.source.served
        if phase is IndexPhase.WAITING or served is None:
            raise Refused(f'no map/index yet: {detail}')
        return served

    def _prepare(self, msg: LaserScan, min_points: int = 3) -> Prepared:
        """
        Check that ``msg`` can be localized now and prepare it; raise :class:`Refused` if not.

        The scan's arguments are mirrored for an upside-down laser. ``min_points`` 0 lets a
        well-formed scan with (almost) no returns through: the tracker coasts on it where the
        map agrees that nothing is in range.
        """
        served = self._check_ready()
        args = scan_args_from_msg(msg)
        problem = scan_problem(args, min_points)
        if problem:
            self.get_logger().warning(f'skipping scan: {problem}', throttle_duration_sec=2.0)
            raise Refused(f'bad scan: {problem}')
        mount = self._laser.mount(msg.header.frame_id)
        if mount.mirrored:
            args = ScanArgs(args.ranges, -args.angle_min, -args.angle_increment,
                            args.range_min, args.range_max)
        elif args.angle_increment < 0.0:
            self.get_logger().warning('negative angle_increment: mirrored (upside-down) laser? '
                                      'localizing the scan as given', once=True)
        return Prepared(msg, args, mount, served, self._localizer_for(served, mount))

    def _localizer_for(self, served: ServedIndex, mount: LaserMount) -> GlobalLocalizer:
        pose = tuple(mount.pose)
        if all(abs(a - b) < 1e-9 for a, b in zip(pose, served.localizer.config.laser_pose)):
            return served.localizer
        with self._state_lock:
            variant = served.variants.get(pose)
            if variant is None:
                variant = served.variants[pose] = served.localizer.with_laser_pose(pose)
        return variant

    def _run(self, what: str, work: Callable[[], T]) -> T:
        """Run the core under the localization lock; an exception becomes :class:`Refused`."""
        with self._localize_lock:
            try:
                return work()
            except Exception as exc:  # noqa: BLE001 - a bad scan must not kill the node
                self.get_logger().warning(f'{what} error: {type(exc).__name__}: {exc}')
                raise Refused(f'{what} error: {exc}') from exc

    def _localize(self, msg: LaserScan, verbose: bool) -> Outcome:
        """Localize one scan and publish (raises :class:`Refused` when it cannot be)."""
        scan = self._prepare(msg)
        loc = self._run('localization',
                        lambda: scan.localizer.localize_scan(*scan.args.as_tuple()))
        return self._publish(loc, scan, verbose)

    def _track(self, msg: LaserScan) -> None:
        """Track one scan (track mode) and publish."""
        session = self.session
        if session is None:
            return
        scan = self._prepare(msg, min_points=0)
        publish_tf = bool(self.get_parameter('publish_tf').value)
        result = self._run('tracking', lambda: session.track(
            scan.localizer, scan.args, msg.header.stamp, self._frame(scan.served), publish_tf))
        if result is None:
            self.get_logger().info('track: a scan not newer than the last one tracked '
                                   '(delivered twice or out of order): skipped',
                                   throttle_duration_sec=5.0)
            return
        self._publish(result.as_localization(), scan, False)
        if result.mode == 'tracked' and result.status == 'failed':     # a bad or blind scan
            self.get_logger().warning(f'track: {result.message}', throttle_duration_sec=2.0)
        elif result.mode != 'tracked':
            self.get_logger().info(f'track: {result.mode}, {result.status}: {result.message}',
                                   throttle_duration_sec=1.0)

    def _publish(self, loc: Localization, scan: Prepared, verbose: bool) -> Outcome:
        """Publish the candidates, markers and an ``ok`` finite pose (handed over to AMCL)."""
        frame = self._frame(scan.served)
        stamp = scan.msg.header.stamp
        with self._state_lock:
            self._last, self._last_checksum = loc, scan.served.checksum
            index_marks = self._index_marks
        top_n = self.localizer_config.top_n
        self.candidates_pub.publish(pose_array(
            [c.pose for c in list(loc.candidates or [])[:top_n]], stamp, frame))
        now = time.monotonic()
        if self.get_parameter('publish_markers').value and (
                verbose or now - self._last_markers >= MARKER_PERIOD):
            self._last_markers = now
            marks = markers.localization_markers(loc, frame, stamp, top_n, scan_points(scan.args),
                                                 scan.mount.pose, scan.served.index.node_xy)
            self.marker_pub.publish(markers.marker_array([*index_marks, *marks], frame, stamp))
        pose = loc.pose
        published = loc.ok and pose is not None and all(math.isfinite(v) for v in pose)
        if published:
            out = pose_with_covariance(loc, 0, frame)
            out.header.stamp = stamp
            self.pose_pub.publish(out)
            if self.get_parameter('publish_initialpose').value and self.mode != 'track':
                self.handover.start(out)
            log = self.get_logger().info if verbose else self.get_logger().debug
            log(f'{self.base_frame} in {frame}: {format_result(loc)}')
        outcome = Outcome(loc, published)
        if verbose:
            if not published:
                self.get_logger().warning(f'no pose published: {outcome.reason}')
            self._publish_diagnostics()
        return outcome

    # ------------------------------------------------------------------ services
    def _serve(self, msg: LaserScan) -> Answer:
        """RequestQueue: localize the scan the waiting calls asked for; their answer."""
        try:
            outcome = self._localize(msg, verbose=True)
        except Refused as why:
            return Answer(False, str(why))
        if not outcome.published:
            return Answer(False, outcome.reason)
        loc = outcome.localization
        if self.session is not None:
            self.session.set_prior(loc.pose, loc.covariance)    # the track goes on from there
        return Answer(True, format_result(loc))

    def _no_scan_text(self, timeout: float) -> str:
        return f'no scan received on {self._scan_topic()} within {timeout:g} s'

    def _scan_topic(self) -> str:
        return self.resolve_topic_name(str(self.get_parameter('scan_topic').value))

    def _submit(self) -> tuple[Future, float]:
        """Queue a call for the next scan: its Future and timeout; :class:`Refused` if not."""
        self._check_ready()
        timeout = float(self.get_parameter('scan_timeout').value)
        return self._queue.submit(timeout), timeout

    def _localize_next_scan(self, service: str) -> Answer:
        """Wait (in this executor thread) for the answer of the next scan, or refuse."""
        try:
            future, timeout = self._submit()
            answer = future.result(timeout=timeout + ANSWER_SLACK)
        except Refused as why:
            answer = Answer(False, str(why))
        except FutureTimeout:
            answer = Answer(False, f'no answer within {timeout + ANSWER_SLACK:g} s')
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

    def _serve_nav2_service(self, serve: bool) -> None:
        """Create or destroy ``reinitialize_global_localization`` (start-up and configure)."""
        if serve and self._nav2_service is None:
            self._nav2_service = create_withholding_service(
                self, Empty, NAV2_SERVICE, self._on_reinitialize, qos_profile=SERVICE_QOS,
                callback_group=self._group)
        elif not serve and self._nav2_service is not None:
            self.destroy_service(self._nav2_service)
            self._nav2_service = None

    def _on_reinitialize(self, request: Empty.Request,
                         response: Empty.Response) -> Empty.Response | None:
        """
        nav2's ``reinitialize_global_localization``: start a search, answer at once.

        Answered (within the behavior tree's ``server_timeout``) once the next scan is queued
        for localization: the node is active, the index ready and a scan arrived within
        ``scan_timeout``. The outcome is published (``global_pose`` and the hand-over on
        ``initialpose`` when ``ok``; ``/diagnostics``; the log). When no search can start, the
        call is not answered at all: the behavior tree times out and reads FAILURE.
        """
        try:
            age = self._mailbox.age()
            if self._active and (age is None or age > self.get_parameter('scan_timeout').value):
                raise Refused(f'no scan on {self._scan_topic()} in the last '
                              f'{self.get_parameter("scan_timeout").value:g} s')
            future, _ = self._submit()
        except Refused as why:
            self.get_logger().warning(f'{NAV2_SERVICE}: not answered (the caller reads a '
                                      f'failure): {why}')
            return None
        future.add_done_callback(self._log_reinitialized)
        return response

    def _log_reinitialized(self, future: Future) -> None:
        answer = future.result()
        if answer.ok:
            self.get_logger().info(f'{NAV2_SERVICE}: localized, {answer.message}')
        else:
            self.get_logger().warning(f'{NAV2_SERVICE}: not localized: {answer.message}')

    # ------------------------------------------------------------------ loops
    def _continuous_loop(self) -> None:
        """Continuous mode: localize the newest scan, at most ``rate`` times a second."""
        def localize(msg: LaserScan) -> bool:
            outcome = self._localize(msg, verbose=False)
            if not outcome.published:
                self.get_logger().info(f'no pose: {outcome.reason}', throttle_duration_sec=2.0)
            return False
        self._each_scan(localize, 'not localizing: {reason}',
                        1.0 / self.rate if self.rate > 0 else 0.0)

    def _track_loop(self) -> None:
        """Track mode: track the newest scan, again and again."""
        def track(msg: LaserScan) -> bool:
            self._track(msg)
            return False
        self._each_scan(track, 'not tracking: {reason}')

    def _startup_loop(self) -> None:
        """``localize_on_start``: localize incoming scans until the first ``ok`` pose."""
        self.get_logger().info('localize_on_start: localizing incoming scans until the first '
                               'ok pose')

        def localize(msg: LaserScan) -> bool:
            outcome = self._localize(msg, verbose=False)
            if outcome.published:
                self.get_logger().info('localize_on_start: localized, '
                                       f'{format_result(outcome.localization)}; on demand from '
                                       'now on')
                self._publish_diagnostics()
            else:
                self.get_logger().info(f'localize_on_start: {outcome.reason}; trying the next '
                                       'scan', throttle_duration_sec=2.0)
            return outcome.published
        self._each_scan(localize, 'localize_on_start: waiting ({reason})')

    def _each_scan(self, handle: Callable[[LaserScan], bool], waiting: str,
                   period: float = 0.0) -> None:
        """
        Call ``handle(scan)`` with the newest scan, again and again (a mode's worker thread).

        Until the node stops or ``handle`` returns True. A :class:`Refused` scan (not ready, bad
        scan) is logged now and then as ``waiting`` (with ``{reason}``). With a ``period`` (s), a
        scan is taken at most that often (timed from when the last one was taken; the scans in
        between are dropped).
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
            try:
                if handle(msg):
                    return
            except Refused as why:
                self.get_logger().info(waiting.format(reason=why), throttle_duration_sec=5.0)

    # ------------------------------------------------------------------ diagnostics
    def _publish_diagnostics(self) -> None:
        if not self._configured_parts:
            return
        phase, detail = self.source.map_state()
        with self._state_lock:
            last = self._last
        served = self.source.served
        note = served.localizer.calibration_warning if served is not None else ''
        status = localization_status(self.get_name(), self.get_fully_qualified_name(),
                                     phase.reported, last, detail, self._frame(served),
                                     state_label(self), self.mode, note)
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
