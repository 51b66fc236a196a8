"""rosbag2 bags (mcap storage, ROS 2 Jazzy definitions) read and written with ``rosbags``.

Topics (docs INTERFACES.md): ``/scan`` sensor_msgs/msg/LaserScan (frame ``laser``, no-return beams
``+inf``), ``/map`` nav_msgs/msg/OccupancyGrid (one message at the start, frame ``map``, offered
transient-local so ``ros2 bag play`` latches it), ``/odom`` nav_msgs/msg/Odometry (optional),
``/ground_truth`` geometry_msgs/msg/PoseStamped (optional, frame ``map``, the scan's stamp).

A bag path is a rosbag2 directory (with ``metadata.yaml``), a directory holding one ``.mcap``
file, or a bare ``.mcap`` file. Stamps are float seconds; poses ``(x, y, yaw)``.
"""
from __future__ import annotations

import math
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Iterator, Mapping

import numpy as np

from ..progress import ProgressCallback
from ..transforms import Pose2, quaternion_to_yaw, yaw_to_quaternion

if TYPE_CHECKING:  # map_io is imported lazily (only needed when a bag holds /map)
    from ..mapping.map_io import OccupancyMap

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

    map: 'OccupancyMap | None'
    scans: list[ScanRecord]
    ground_truth: dict[float, Pose2] = field(default_factory=dict)   # stamp -> base pose in map
    odom: dict[float, Pose2] = field(default_factory=dict)           # stamp -> pose in odom
    topic_counts: dict[str, int] = field(default_factory=dict)       # every topic in the bag

    def ground_truth_of(self, scan: ScanRecord) -> Pose2 | None:
        """The /ground_truth pose carrying the scan's stamp, or None."""
        return self.ground_truth.get(scan.stamp)


# ---------------------------------------------------------------- stamps, poses, typestore

def _typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


def stamp_to_ns(stamp: float) -> int:
    """Float seconds -> integer nanoseconds (rounded)."""
    return int(round(float(stamp) * 1e9))


def _time_msg(ts, stamp: float):
    sec, nsec = divmod(stamp_to_ns(stamp), 10**9)
    return ts.types['builtin_interfaces/msg/Time'](sec=int(sec), nanosec=int(nsec))


def _stamp_of(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _header(ts, stamp: float, frame_id: str):
    return ts.types['std_msgs/msg/Header'](stamp=_time_msg(ts, stamp), frame_id=frame_id)


def _pose_msg(ts, pose) -> object:
    x, y, yaw = (float(v) for v in pose)
    qx, qy, qz, qw = yaw_to_quaternion(yaw)
    return ts.types['geometry_msgs/msg/Pose'](
        position=ts.types['geometry_msgs/msg/Point'](x=x, y=y, z=0.0),
        orientation=ts.types['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw))


def _pose_of(pose_msg) -> Pose2:
    q = pose_msg.orientation
    return (float(pose_msg.position.x), float(pose_msg.position.y),
            quaternion_to_yaw(q.x, q.y, q.z, q.w))


def _latched_qos():
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    zero = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                zero, zero, QosLiveliness.AUTOMATIC, zero, False)]


# ---------------------------------------------------------------- writing

def _scan_msg(ts, s: ScanRecord):
    ranges = np.asarray(s.ranges, dtype=np.float32).ravel()
    return ts.types[SCAN_TYPE](
        header=_header(ts, s.stamp, s.frame_id), angle_min=float(s.angle_min),
        angle_max=float(s.angle_max), angle_increment=float(s.angle_increment),
        time_increment=float(s.time_increment), scan_time=float(s.scan_time),
        range_min=float(s.range_min), range_max=float(s.range_max), ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32))


def _map_msg(ts, occ_map, stamp: float):
    data = np.asarray(occ_map.data, dtype=np.int8)
    height, width = data.shape
    info = ts.types['nav_msgs/msg/MapMetaData'](
        map_load_time=_time_msg(ts, stamp), resolution=float(occ_map.resolution),
        width=int(width), height=int(height), origin=_pose_msg(ts, occ_map.origin))
    return ts.types[MAP_TYPE](header=_header(ts, stamp, getattr(occ_map, 'frame_id', 'map')),
                              info=info, data=data.ravel().copy())


def _odom_msg(ts, stamp: float, pose, frame_id: str, child_frame_id: str):
    cov = np.zeros(36, dtype=np.float64)
    pwc = ts.types['geometry_msgs/msg/PoseWithCovariance'](pose=_pose_msg(ts, pose), covariance=cov)
    vec = ts.types['geometry_msgs/msg/Vector3']
    twist = ts.types['geometry_msgs/msg/Twist'](linear=vec(x=0.0, y=0.0, z=0.0),
                                                angular=vec(x=0.0, y=0.0, z=0.0))
    twc = ts.types['geometry_msgs/msg/TwistWithCovariance'](twist=twist, covariance=cov.copy())
    return ts.types[ODOM_TYPE](header=_header(ts, stamp, frame_id),
                               child_frame_id=child_frame_id, pose=pwc, twist=twc)


def write_bag(path: str | Path, map: 'OccupancyMap | None' = None,
              scans: Iterable[ScanRecord] = (),
              ground_truth: Mapping[float, Pose2] | None = None,
              odom: Mapping[float, Pose2] | None = None, overwrite: bool = False,
              map_stamp: float | None = None, odom_frame: str = 'odom',
              base_frame: str = 'base_link', compress: bool = True,
              progress: ProgressCallback | None = None) -> Path:
    """Write a rosbag2 directory (mcap storage, Jazzy definitions); return its path.

    ``/map`` is written once, first (log time just before the first message, offered
    transient-local); then per scan in the given order ``/scan``, ``/ground_truth`` and ``/odom``
    for the stamps present in those mappings (matched to the scans' stamps to the nanosecond).
    Message log times are the header stamps, forced strictly increasing so bag order is scan order.
    ``compress`` zstd-compresses the mcap chunks (read natively by the Jazzy mcap plugin).
    """
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    path = Path(path)
    if path.exists():
        if not overwrite:
            raise FileExistsError(f'bag exists already (pass overwrite=True): {path}')
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    scans = list(scans)
    for s in scans:
        if not math.isfinite(s.stamp) or np.ndim(s.ranges) != 1:
            raise ValueError(f'{path}: scan with a non-finite stamp or non-1-D ranges')
    # poses keyed by integer nanoseconds, so they meet their scans whatever float rounding
    gt = {stamp_to_ns(k): v for k, v in (ground_truth or {}).items()}
    od = {stamp_to_ns(k): v for k, v in (odom or {}).items()}
    ts = _typestore()
    first = scans[0].stamp if scans else (min(gt) * 1e-9 if gt else 0.0)
    if map_stamp is None:
        map_stamp = first
    last_ns = -1

    def log_time(stamp: float) -> int:
        nonlocal last_ns
        last_ns = max(stamp_to_ns(stamp), last_ns + 1, 0)
        return last_ns

    writer = Writer(path, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
    if compress:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        if map is not None:
            conn = writer.add_connection(MAP_TOPIC, MAP_TYPE, typestore=ts,
                                         offered_qos_profiles=_latched_qos())
            last_ns = max(stamp_to_ns(min(map_stamp, first)) - 1_000_000, 0)
            writer.write(conn, last_ns, ts.serialize_cdr(_map_msg(ts, map, map_stamp), MAP_TYPE))
        c_scan = writer.add_connection(SCAN_TOPIC, SCAN_TYPE, typestore=ts) if scans else None
        c_gt = writer.add_connection(GT_TOPIC, GT_TYPE, typestore=ts) if gt else None
        c_od = writer.add_connection(ODOM_TOPIC, ODOM_TYPE, typestore=ts) if od else None
        for i, s in enumerate(scans):
            t = log_time(s.stamp)
            key = stamp_to_ns(s.stamp)
            writer.write(c_scan, t, ts.serialize_cdr(_scan_msg(ts, s), SCAN_TYPE))
            if key in gt:
                msg = ts.types[GT_TYPE](header=_header(ts, s.stamp, 'map'),
                                        pose=_pose_msg(ts, gt.pop(key)))
                writer.write(c_gt, t, ts.serialize_cdr(msg, GT_TYPE))
            if key in od:
                msg = _odom_msg(ts, s.stamp, od.pop(key), odom_frame, base_frame)
                writer.write(c_od, t, ts.serialize_cdr(msg, ODOM_TYPE))
            if progress is not None and (i % 50 == 0 or i + 1 == len(scans)):
                progress(i + 1, len(scans), 'writing bag')
        for key in sorted(gt):   # poses without a scan
            stamp = key * 1e-9
            msg = ts.types[GT_TYPE](header=_header(ts, stamp, 'map'), pose=_pose_msg(ts, gt[key]))
            writer.write(c_gt, log_time(stamp), ts.serialize_cdr(msg, GT_TYPE))
        for key in sorted(od):
            stamp = key * 1e-9
            msg = _odom_msg(ts, stamp, od[key], odom_frame, base_frame)
            writer.write(c_od, log_time(stamp), ts.serialize_cdr(msg, ODOM_TYPE))
    return path


# ---------------------------------------------------------------- reading

def _resolve(path: str | Path) -> Path:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f'bag not found: {path}')
    if path.is_dir() and not (path / 'metadata.yaml').exists():
        mcaps = sorted(path.glob('*.mcap'))
        if len(mcaps) != 1:
            raise BagError(f'{path}: not a rosbag2 directory (no metadata.yaml) and holds '
                           f'{len(mcaps)} .mcap files')
        return mcaps[0]
    if path.is_file() and path.suffix != '.mcap':
        raise BagError(f'{path}: expected a rosbag2 directory or a .mcap file')
    return path


def _mcap_prefix(path: Path) -> tuple[list[tuple[str, str, bytes]], str]:
    """The messages readable from the start of an mcap file cut short (via the ``mcap`` stream
    reader), and why reading stopped."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    out: list[tuple[str, str, bytes]] = []
    reason = 'end of file'
    try:
        with path.open('rb') as fh:
            for rec in StreamReader(fh, record_size_limit=2**30).records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec.name
                elif isinstance(rec, Channel):
                    channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ''))
                elif isinstance(rec, Message) and rec.channel_id in channels:
                    out.append((*channels[rec.channel_id], bytes(rec.data)))
    except Exception as exc:  # the truncation point: any decoding error ends the prefix
        reason = (f'{type(exc).__name__}: {exc}' if str(exc).strip()
                  else f'the file ends inside a record ({type(exc).__name__})')
    return out, reason


class _Reader:
    """Opens a bag with clear errors; iterates (topic, msg) in log-time order.

    An mcap file cut short (no summary, e.g. a recorder that crashed) is read up to the
    truncation point with a ``RuntimeWarning``; one with nothing readable raises ``BagError``.
    """

    def __init__(self, path: str | Path):
        from rosbags.highlevel import AnyReader
        self.path = _resolve(path)
        self.reader = None
        self.prefix: list[tuple[str, str, bytes]] | None = None
        try:
            self.reader = AnyReader([self.path], default_typestore=_typestore())
            self.reader.open()
        except FileNotFoundError:
            raise FileNotFoundError(f'bag not found: {path}') from None
        except Exception as exc:   # rosbags raises several error types for corrupt files
            self.reader = None
            self._open_prefix(path, f'{type(exc).__name__}: {exc}')
        self.counts: dict[str, int] = {}
        if self.reader is not None:
            for c in self.reader.connections:
                self.counts[c.topic] = self.counts.get(c.topic, 0) + c.msgcount
            self.types = {c.topic: c.msgtype for c in self.reader.connections}
        else:
            self.types = {}
            for topic, msgtype, _ in self.prefix:
                self.counts[topic] = self.counts.get(topic, 0) + 1
                self.types[topic] = msgtype

    def _open_prefix(self, path, error: str) -> None:
        mcap = self.path if self.path.is_file() else next(iter(sorted(self.path.glob('*.mcap'))),
                                                         None)
        prefix, reason = _mcap_prefix(mcap) if mcap is not None else ([], 'no .mcap file')
        if not prefix:
            raise BagError(f'{path}: cannot read bag, truncated or corrupt ({error}; {reason})')
        warnings.warn(f'{path}: bag is truncated or corrupt ({error}); using the {len(prefix)} '
                      f'messages readable before the damage ({reason})', RuntimeWarning,
                      stacklevel=4)
        self.prefix = prefix

    def close(self) -> None:
        if self.reader is not None:
            self.reader.close()

    def check_topic(self, topic: str, msgtype: str) -> None:
        if topic not in self.types:
            have = ', '.join(sorted(self.types)) or 'none'
            raise BagError(f'{self.path}: no {topic} topic in the bag (topics: {have})')
        if self.types[topic] != msgtype:
            raise BagError(f'{self.path}: {topic} has type {self.types[topic]}, expected {msgtype}')

    def messages(self, topics: set[str]) -> Iterator[tuple[str, object]]:
        if self.prefix is not None:
            ts = _typestore()
            for topic, msgtype, raw in self.prefix:
                if topic in topics:
                    try:
                        yield topic, ts.deserialize_cdr(raw, msgtype)
                    except Exception as exc:
                        raise BagError(f'{self.path}: cannot decode a {topic} message '
                                       f'({type(exc).__name__}: {exc})') from None
            return
        conns = [c for c in self.reader.connections if c.topic in topics]
        it = self.reader.messages(connections=conns)
        n = 0
        while True:
            try:
                conn, _, raw = next(it)
                msg = self.reader.deserialize(raw, conn.msgtype)
            except StopIteration:
                return
            except Exception as exc:
                warnings.warn(f'{self.path}: bag is truncated or corrupt after {n} messages '
                              f'({type(exc).__name__}: {exc}); using the readable part',
                              RuntimeWarning, stacklevel=3)
                return
            n += 1
            yield conn.topic, msg


def _scan_record(msg) -> ScanRecord:
    return ScanRecord(stamp=_stamp_of(msg.header), ranges=np.asarray(msg.ranges, dtype=np.float32),
                      angle_min=float(msg.angle_min), angle_max=float(msg.angle_max),
                      angle_increment=float(msg.angle_increment),
                      time_increment=float(msg.time_increment), scan_time=float(msg.scan_time),
                      range_min=float(msg.range_min), range_max=float(msg.range_max),
                      frame_id=str(msg.header.frame_id))


def _map_from_msg(msg) -> 'OccupancyMap':
    """OccupancyGrid -> OccupancyMap; the float32 resolution is restored to its shortest decimal
    (0.05, not 0.0500000007) so the map equals (and checksums like) the YAML it was made from."""
    from ..mapping.map_io import OccupancyMap, occupancy_map_from_msg
    m = occupancy_map_from_msg(msg)
    res = float(repr(np.float32(m.resolution)).removeprefix('np.float32(').rstrip(')'))
    return OccupancyMap(m.data, res, m.origin, m.frame_id)


def _progress_step(progress, n: int, total: int) -> None:
    if progress is not None and (n % 50 == 0 or n == total):
        progress(n, total, 'reading bag')


def iter_scans(path: str | Path, scan_topic: str = SCAN_TOPIC,
               progress: ProgressCallback | None = None) -> Iterator[ScanRecord]:
    """Yield the scans of a bag one by one, in bag order (constant memory)."""
    rd = _Reader(path)
    try:
        rd.check_topic(scan_topic, SCAN_TYPE)
        total = rd.counts.get(scan_topic, 0)
        for n, (_, msg) in enumerate(rd.messages({scan_topic}), 1):
            _progress_step(progress, n, total)
            yield _scan_record(msg)
    finally:
        rd.close()


def read_bag(path: str | Path, scan_topic: str = SCAN_TOPIC,
             progress: ProgressCallback | None = None, require_scans: bool = True) -> BagData:
    """Read a whole bag: the first /map, every scan, /ground_truth and /odom poses.

    Raises ``FileNotFoundError`` for a missing path, ``BagError`` (a ``ValueError``) for a bag
    that cannot be opened or lacks ``scan_topic`` (unless ``require_scans=False``). A bag cut
    short mid-file yields its readable prefix with a ``RuntimeWarning``.
    """
    rd = _Reader(path)
    try:
        if require_scans:
            rd.check_topic(scan_topic, SCAN_TYPE)
        topics = {scan_topic, MAP_TOPIC, GT_TOPIC, ODOM_TOPIC}
        total = sum(rd.counts.get(t, 0) for t in topics)
        occ_map, scans, gt, od = None, [], {}, {}
        for n, (topic, msg) in enumerate(rd.messages(topics), 1):
            if topic == scan_topic:
                scans.append(_scan_record(msg))
            elif topic == MAP_TOPIC and occ_map is None:
                occ_map = _map_from_msg(msg)
            elif topic == GT_TOPIC:
                gt[_stamp_of(msg.header)] = _pose_of(msg.pose)
            elif topic == ODOM_TOPIC:
                od[_stamp_of(msg.header)] = _pose_of(msg.pose.pose)
            _progress_step(progress, n, total)
        return BagData(map=occ_map, scans=scans, ground_truth=gt, odom=od,
                       topic_counts=dict(rd.counts))
    finally:
        rd.close()


def bag_topics(path: str | Path) -> dict[str, int]:
    """Message count per topic (from the bag's metadata / summary)."""
    rd = _Reader(path)
    try:
        return dict(rd.counts)
    finally:
        rd.close()
