"""``map_indexer`` node: builds the topological index of every map it receives.

Subscribes ``map`` (nav_msgs/OccupancyGrid, reliable + transient-local), builds the index
(GVD nodes + virtual scans) in a worker thread, publishes ``topological_map``
(visualization_msgs/MarkerArray, transient-local) and writes ``index_file`` when it is set.
A newer map supersedes the one being indexed; a half-built index is never published.

Also home of the pieces ``global_localizer`` shares: :class:`IndexBuilder` (the worker thread)
and the ROS-parameter <-> config-dataclass mapping (names ``index.*`` / ``localizer.*``, the
same nesting as :mod:`ssm_localization.params`).
"""
from __future__ import annotations

import dataclasses
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable

import rclpy
from nav_msgs.msg import OccupancyGrid
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import MarkerArray

from ssm_localization.config import params as ssm_params
from ssm_localization.ros import markers
from ssm_localization.ros.conversions import occupancy_map_from_msg

# Reliable + transient-local, depth 1: what map_server offers and what latecomers need.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

# Descriptions of config fields (dotted ROS names); others get a generic one.
DESCRIPTIONS: dict[str, str] = {
    'index.beams': 'beams of each virtual scan taken at a topological node (full turn)',
    'index.max_range': 'range of the virtual laser when casting the node scans, metres',
    'localizer.top_n': 'candidate nodes kept by the spectral coarse stage (paper: N = 5)',
    'localizer.sigma_d': 'eq. (10) vicinity score distance scale, metres',
    'localizer.prefilter': 'nodes kept by descriptor voting before spectral ranking; 0 = all',
    'localizer.paper_mode': 'plain paper pipeline: no prefilter, refinement or map check',
    'localizer.min_score': 'map-agreement score below which a hypothesis is rejected',
    'index.matcher.ransac_iterations': 'RANSAC iterations of the fine pose (paper II.C)',
    'index.matcher.ransac_threshold': 'RANSAC inlier distance, metres',
    'index.matcher.ransac_min_span': 'RANSAC: minimum spread of a 2-pair sample, metres',
    'index.matcher.min_inliers': 'fewer RANSAC inliers than this: no match',
    'index.matcher.seed': 'random seed of RANSAC (results are reproducible)',
    'index.matcher.icp': 'refine each match by point-to-line ICP (beyond the paper)',
    'index.matcher.weights': 'logistic weights of the pairwise affinity (eq. 4)',
    'index.matcher.desc_radius': 'radius of the local shape descriptors, metres',
}

GENERIC = 'see '   # prefix of the description of a config field documented nowhere else

# Config fields that the node maps from its own parameters instead (laser_x/laser_y/laser_yaw).
SENSOR_POSE_FIELDS = ('laser_pose', 'sensor_pose')


class Superseded(Exception):
    """Raised inside a build (from its progress callback) when a newer job is waiting."""


# --------------------------------------------------------------------------- parameters

def _ros_value(value: Any) -> Any | None:
    """A config default as a ROS parameter value, or None when ROS cannot type it."""
    if isinstance(value, bool) or isinstance(value, str):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, (list, tuple)) and value:
        if all(isinstance(v, bool) for v in value):
            return [bool(v) for v in value]
        if all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            return [int(v) for v in value]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            return [float(v) for v in value]
        if all(isinstance(v, str) for v in value):
            return list(value)
    return None


def config_parameters(prefix: str, config: Any) -> dict[str, Any]:
    """``{'prefix.dotted.field': default}`` for every ROS-typable field of a config dataclass."""
    out = {}
    for name, value in ssm_params.flatten(config, prefix + '.').items():
        if name.rsplit('.', 1)[-1] in SENSOR_POSE_FIELDS:
            continue
        v = _ros_value(value)
        if v is not None:
            out[name] = v
    return out


def field_descriptions(cls: type) -> dict[str, str]:
    """Field descriptions of a config dataclass, from its source: a trailing ``# comment`` on the
    field line, or a ````name````: text`` entry in the class docstring."""
    import inspect
    import re
    out: dict[str, str] = {}
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return out
    doc = ' '.join((cls.__doc__ or '').split())
    for names, text in re.findall(r'((?:``\w+``(?:,\s*|\s+and\s+)?)+):\s*([^`]+)', doc):
        for name in re.findall(r'``(\w+)``', names):
            out[name] = text.strip().rstrip(';,')
    for name, text in re.findall(r'^\s+(\w+)\s*:[^#\n]*=[^#\n]*#\s*(.+)$', source, re.M):
        out[name] = text.strip()
    return out


def _described(prefix: str, config: Any) -> dict[str, str]:
    """``{dotted name: description}`` for every leaf field of a config tree."""
    out: dict[str, str] = {}
    notes = field_descriptions(type(config))
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        name = f'{prefix}.{f.name}'
        if dataclasses.is_dataclass(value):
            out.update(_described(name, value))
        else:
            out[name] = notes.get(f.name, '')
    return out


def config_parameter_table(prefix: str, config: Any) -> dict[str, tuple[Any, str]]:
    """``{dotted name: (default, description)}`` of a config dataclass (ROS-typable fields)."""
    notes = _described(prefix, config)
    return {name: (default, DESCRIPTIONS.get(name) or notes.get(name) or
                   f'{GENERIC}{type(config).__name__}.{name.split(".", 1)[1]}')
            for name, default in config_parameters(prefix, config).items()}


def declare(node: Node, name: str, default: Any, description: str, read_only: bool = True) -> Any:
    """Declare one parameter with a description; return its value."""
    node.declare_parameter(name, default, ParameterDescriptor(description=description,
                                                              read_only=read_only))
    return node.get_parameter(name).value


def declare_table(node: Node, table: dict[str, tuple[Any, str]],
                  dynamic: tuple[str, ...] = ()) -> dict[str, Any]:
    """Declare every ``name: (default, description)``; read-only unless listed in ``dynamic``."""
    return {name: declare(node, name, default, desc, name not in dynamic)
            for name, (default, desc) in table.items()}


def _with_sensor_pose(config: Any, pose: tuple[float, float, float]) -> Any:
    """Set the laser/sensor pose field(s) of a config tree to ``pose``."""
    changes = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if f.name in SENSOR_POSE_FIELDS:
            changes[f.name] = tuple(float(v) for v in pose)
        elif dataclasses.is_dataclass(value):
            changes[f.name] = _with_sensor_pose(value, pose)
    return dataclasses.replace(config, **changes) if changes else config


def build_config(cls: type, prefix: str, values: dict[str, Any],
                 laser_pose: tuple[float, float, float]) -> Any:
    """Config dataclass ``cls`` from ``{prefix.dotted.name: value}`` plus the laser pose."""
    section = ssm_params.unflatten({k: v for k, v in values.items()
                                    if k.startswith(prefix + '.')}).get(prefix, {})
    return _with_sensor_pose(ssm_params.from_dict(cls, section, prefix + '.'), laser_pose)


def laser_pose_of(values: dict[str, Any]) -> tuple[float, float, float]:
    return (float(values['laser_x']), float(values['laser_y']), float(values['laser_yaw']))


LASER_PARAMS: dict[str, tuple[Any, str]] = {
    'laser_x': (0.0, 'laser x on the robot base frame, metres'),
    'laser_y': (0.0, 'laser y on the robot base frame, metres'),
    'laser_yaw': (0.0, 'laser yaw on the robot base frame, radians (tf2 is not used)'),
}
MAP_PARAMS: dict[str, tuple[Any, str]] = {
    'max_map_cells': (25_000_000, 'ignore larger maps (cells); 0 = no limit'),
    'max_gvd_points': (20000, 'GVD cells drawn in topological_map (subsampled)'),
}


def indexer_parameters() -> dict[str, tuple[Any, str]]:
    """Every map_indexer parameter: ``{name: (default, description)}``."""
    from ssm_localization.config import IndexConfig
    return {'index_file': ('', 'write the index here (npz) after each build; empty = do not '
                               'write'),
            **LASER_PARAMS, **MAP_PARAMS, **config_parameter_table('index', IndexConfig())}


# --------------------------------------------------------------------------- worker

class IndexBuilder:
    """Runs index jobs in one worker thread; the newest submitted job wins.

    ``submit(label, job)`` queues ``job(progress) -> MapIndex``, replacing a queued job that has
    not started; a running job is aborted at its next progress report (``Superseded``) or its
    result is dropped. ``on_done(index, label)`` / ``on_error(exc, label)`` run in the worker.
    """

    def __init__(self, logger, on_done: Callable[[Any, str], None],
                 on_error: Callable[[BaseException, str], None], log_period: float = 5.0):
        self._logger = logger
        self._on_done = on_done
        self._on_error = on_error
        self._log_period = log_period
        self._cv = threading.Condition()
        self._pending: tuple[str, Callable] | None = None
        self._running: str | None = None
        self._stop = False
        self._thread = threading.Thread(target=self._run, name='index_builder', daemon=True)
        self._thread.start()

    @property
    def busy(self) -> bool:
        with self._cv:
            return self._pending is not None or self._running is not None

    def status(self) -> str:
        with self._cv:
            return self._running or (self._pending[0] if self._pending else 'idle')

    def submit(self, label: str, job: Callable) -> None:
        with self._cv:
            if self._pending is not None:
                self._logger.info(f'{label}: replaces the queued {self._pending[0]}')
            elif self._running is not None:
                self._logger.info(f'{label}: supersedes {self._running} (in progress)')
            self._pending = (label, job)
            self._cv.notify_all()

    def wait_idle(self, timeout: float | None = None) -> bool:
        with self._cv:
            return self._cv.wait_for(lambda: self._pending is None and self._running is None,
                                     timeout)

    def stop(self) -> None:
        with self._cv:
            self._stop = True
            self._pending = None
            self._cv.notify_all()
        self._thread.join(timeout=2.0)

    def _superseded(self) -> bool:
        with self._cv:
            return self._pending is not None or self._stop

    def _run(self) -> None:
        while True:
            with self._cv:
                self._cv.wait_for(lambda: self._pending is not None or self._stop)
                if self._stop:
                    return
                label, job = self._pending
                self._pending, self._running = None, label
            t0 = time.monotonic()
            last = [t0, -1]

            def progress(done: int, total: int, what: str = '') -> None:
                if self._superseded():
                    raise Superseded()
                now = time.monotonic()
                decile = int(10 * done / total) if total else 0
                if now - last[0] >= self._log_period or (decile > last[1] and decile % 5 == 0):
                    last[0], last[1] = now, decile
                    self._logger.info(f'{label}: {what or "indexing"} {done}/{total} '
                                      f'({now - t0:.1f} s)')
            try:
                index = job(progress)
                if self._superseded():
                    raise Superseded()
                self._on_done(index, label)
            except Superseded:
                self._logger.info(f'{label}: dropped, a newer map arrived')
            except Exception as exc:  # noqa: BLE001 - any failure of a job is reported, not fatal
                self._on_error(exc, label)
            finally:
                with self._cv:
                    self._running = None
                    self._cv.notify_all()


def map_from_msg(msg: OccupancyGrid, max_cells: int):
    """OccupancyGrid -> OccupancyMap with a size guard; raises ValueError with the reason."""
    cells = int(msg.info.width) * int(msg.info.height)
    if max_cells > 0 and cells > max_cells:
        raise ValueError(f'map of {msg.info.width} x {msg.info.height} cells exceeds '
                         f'max_map_cells = {max_cells}')
    if not msg.info.resolution > 0.0:
        raise ValueError(f'map resolution must be > 0, got {msg.info.resolution}')
    occ = occupancy_map_from_msg(msg)
    if not occ.free_mask().any():
        raise ValueError('map has no free cells: nothing to index')
    return occ


def usable_map(msg: OccupancyGrid, max_cells: int, logger):
    """:func:`map_from_msg`, or None after a logged warning: bad maps never stop a node."""
    try:
        return map_from_msg(msg, max_cells)
    except (ValueError, AttributeError) as exc:
        logger.warning(f'ignoring map: {exc}')
        return None


# --------------------------------------------------------------------------- node

class MapIndexerNode(Node):
    """Indexes each map received on ``map``; publishes ``topological_map``."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('map_indexer', **kwargs)
        from ssm_localization.config import IndexConfig
        values = declare_table(self, indexer_parameters())
        self.laser_pose = laser_pose_of(values)
        self.index_config = build_config(IndexConfig, 'index', values, self.laser_pose)
        self.index_file = str(values['index_file'])
        self.max_map_cells = int(values['max_map_cells'])
        self.max_gvd_points = int(values['max_gvd_points'])
        self.index = None
        self._group = ReentrantCallbackGroup()
        self.marker_pub = self.create_publisher(MarkerArray, 'topological_map', LATCHED_QOS)
        self.create_subscription(OccupancyGrid, 'map', self._on_map, LATCHED_QOS,
                                 callback_group=self._group)
        self.builder = IndexBuilder(self.get_logger(), self._on_index, self._on_error)
        self.get_logger().info(f'waiting for a map on {self.resolve_topic_name("map")}')

    def _on_map(self, msg: OccupancyGrid) -> None:
        occ = usable_map(msg, self.max_map_cells, self.get_logger())
        if occ is None:
            return
        label = f'map {occ.width}x{occ.height} @ {occ.resolution:g} m ({occ.checksum()[:8]})'
        self.get_logger().info(f'{label}: indexing')
        from ssm_localization.mapping.index import build_index
        cfg = self.index_config
        self.builder.submit(label, lambda progress: build_index(occ, cfg, progress=progress))

    def _on_index(self, index, label: str) -> None:
        self.index = index
        n = len(index.node_xy)
        self.get_logger().info(f'{label}: index ready, {n} nodes')
        frame = getattr(index.map, 'frame_id', 'map') or 'map'
        stamp = self.get_clock().now().nanoseconds
        self.marker_pub.publish(markers.marker_array(
            markers.index_markers(index, frame, stamp, self.max_gvd_points), frame, stamp))
        if self.index_file:
            from ssm_localization.mapping.index import save_index
            path = Path(self.index_file).expanduser()
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                save_index(index, path)
                self.get_logger().info(f'index written to {path}')
            except (OSError, ValueError) as exc:
                self.get_logger().error(f'cannot write index file {path}: {exc}')

    def _on_error(self, exc: BaseException, label: str) -> None:
        self.get_logger().warning(f'{label}: indexing failed ({type(exc).__name__}: {exc}); '
                                  'keeping the previous index')

    def destroy_node(self) -> None:
        self.builder.stop()
        super().destroy_node()


def spin(node_factory: Callable[[], Node], args: list[str] | None = None,
         num_threads: int = 4) -> int:
    """init, spin ``node_factory()`` on a MultiThreadedExecutor, shut down cleanly."""
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        executor = MultiThreadedExecutor(num_threads=num_threads)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, ParameterException) as exc:  # bad parameters
        if node is not None:
            raise
        print(f'error: {exc}', file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(args: list[str] | None = None) -> int:
    return spin(MapIndexerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
