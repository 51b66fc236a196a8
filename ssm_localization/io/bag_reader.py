"""
Reading rosbag2 bags (mcap storage, ROS 2 Jazzy definitions) with ``rosbags``.

A bag path is a rosbag2 directory (with ``metadata.yaml``), a directory holding one ``.mcap``
file, or a bare ``.mcap`` file. Topics and records: see ``bag_records``. A bag cut short mid-file
yields its readable prefix (read with the ``mcap`` stream reader, when the optional ``mcap``
package is installed) and a ``RuntimeWarning``.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator
import warnings

import numpy as np

from .bag_limits import check_bag_files, MAX_CHUNK_BYTES
from .bag_records import (BagData, BagError, GT_TOPIC, MAP_TOPIC, ODOM_TOPIC, SCAN_TOPIC,
                          SCAN_TYPE, ScanRecord, typestore)
from ..files.yaml_input import load_yaml_file
from ..mapping.map_limits import MAX_MAP_CELLS, MAX_ORIGIN
from ..mapping.occupancy import occupancy_map_from_msg
from ..progress import ProgressCallback
from ..transforms import Pose2, quaternion_to_yaw


def _stamp_of(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def _pose_of(pose_msg) -> Pose2 | str:
    """
    Return ``(x, y, yaw)`` of a geometry_msgs/Pose, or why it is no pose.

    A zero or non-finite quaternion and non-finite or implausibly far coordinates (beyond
    ``map_limits.MAX_ORIGIN``) make no pose, as the node's odometry buffer drops them.
    """
    q = pose_msg.orientation
    try:
        yaw = quaternion_to_yaw(q.x, q.y, q.z, q.w)
    except ValueError as exc:
        return str(exc)
    x, y = float(pose_msg.position.x), float(pose_msg.position.y)
    if not (math.isfinite(x) and math.isfinite(y)) or max(abs(x), abs(y)) > MAX_ORIGIN:
        return f'position ({x:g}, {y:g}) is not finite or beyond {MAX_ORIGIN:g} m'
    return (x, y, yaw)


def _resolve(path: str | Path) -> Path:
    """
    Return what ``rosbags`` opens for ``path`` after checking the files it would read.

    :func:`bag_limits.check_bag_files`: regular files only, and no mcap chunk or file
    compressed whole that expands beyond its limits.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f'bag not found: {path}')
    if not (path.is_dir() or path.is_file()):
        raise BagError(f'{path}: not a rosbag2 directory or a regular .mcap file')
    metadata = path / 'metadata.yaml'
    if path.is_dir() and metadata.exists():
        # rosbags parses it too: refuse oversized files and alias bombs before it does
        doc = load_yaml_file(metadata, 'bag metadata')
        if not isinstance(doc, dict):
            raise BagError(f'{metadata}: bag metadata is not a mapping')
        info = doc.get('rosbag2_bagfile_information')
        info = info if isinstance(info, dict) else {}
        listed = info.get('relative_file_paths')
        names = [n for n in listed if isinstance(n, str)] if isinstance(listed, list) else []
        mode = str(info.get('compression_mode') or '').upper()
        check_bag_files([path / n for n in names] or sorted(path.glob('*.mcap*')),
                        file_compressed=mode == 'FILE')
        return path
    if path.is_dir():
        mcaps = sorted(path.glob('*.mcap'))
        if len(mcaps) != 1:
            raise BagError(f'{path}: not a rosbag2 directory (no metadata.yaml) and holds '
                           f'{len(mcaps)} .mcap files')
        path = mcaps[0]
    if path.suffix != '.mcap':
        raise BagError(f'{path}: expected a rosbag2 directory or a .mcap file')
    check_bag_files([path], file_compressed=False)
    return path


MCAP_MISSING = ('reading what is left of a damaged bag needs the optional Python package mcap '
                '(pip install mcap)')


def _mcap_prefix(path: Path) -> tuple[list[tuple[str, str, bytes]], str]:
    """
    Return the messages readable from the start of an mcap file cut short.

    Read with the ``mcap`` stream reader (an optional dependency); also returns why reading
    stopped.
    """
    try:
        from mcap import records, stream_reader
    except ImportError:
        return [], MCAP_MISSING
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    out: list[tuple[str, str, bytes]] = []
    reason = 'end of file'
    try:
        with path.open('rb') as fh:
            for rec in stream_reader.StreamReader(fh, record_size_limit=MAX_CHUNK_BYTES).records:
                if isinstance(rec, records.Schema):
                    schemas[rec.id] = rec.name
                elif isinstance(rec, records.Channel):
                    channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ''))
                elif isinstance(rec, records.Message) and rec.channel_id in channels:
                    out.append((*channels[rec.channel_id], bytes(rec.data)))
    except Exception as exc:  # the truncation point: any decoding error ends the prefix
        reason = (f'{type(exc).__name__}: {exc}' if str(exc).strip()
                  else f'the file ends inside a record ({type(exc).__name__})')
    return out, reason


class _Reader:
    """
    Opens a bag with clear errors; iterates (topic, msg) in log-time order.

    An mcap file cut short (no summary, e.g. a recorder that crashed) is read up to the
    truncation point with a ``RuntimeWarning``; one with nothing readable raises ``BagError``.
    """

    def __init__(self, path: str | Path):
        from rosbags.highlevel import AnyReader
        self.path = _resolve(path)
        self.reader = None
        self.prefix: list[tuple[str, str, bytes]] | None = None
        try:
            self.reader = AnyReader([self.path], default_typestore=typestore())
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
        mcap = (self.path if self.path.is_file()
                else next(iter(sorted(self.path.glob('*.mcap'))), None))
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
            raise BagError(f'{self.path}: {topic} has type {self.types[topic]}, '
                           f'expected {msgtype}')

    def messages(self, topics: set[str]) -> Iterator[tuple[str, object]]:
        if self.prefix is not None:
            ts = typestore()
            for topic, msgtype, raw in self.prefix:
                if topic in topics:
                    try:
                        yield topic, ts.deserialize_cdr(raw, msgtype)
                    except Exception as exc:
                        raise BagError(f'{self.path}: cannot decode a {topic} message '
                                       f'({type(exc).__name__}: {exc})') from None
            return
        conns = [c for c in self.reader.connections if c.topic in topics]
        if not conns:       # rosbags reads every connection when given none
            return
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
             progress: ProgressCallback | None = None, require_scans: bool = True,
             max_map_cells: int = MAX_MAP_CELLS, read_map: bool = True) -> BagData:
    """
    Read a whole bag: the first /map, every scan, the /ground_truth and /odom poses.

    ``read_map=False`` skips /map (for a caller with a map of its own). The map's resolution and
    origin yaw are the shortest decimals of their float32 values (``occupancy.canonical``), so
    it checksums like the YAML it was made from.

    Raises ``FileNotFoundError`` for a missing path, ``BagError`` (a ``ValueError``) for a bag
    that cannot be opened or lacks ``scan_topic`` (unless ``require_scans=False``),
    :class:`~ssm_localization.mapping.map_limits.MapTooLargeError` for a /map of more than
    ``max_map_cells`` cells (0: no limit). A bag cut short mid-file yields its readable prefix
    with a ``RuntimeWarning``; so do /odom and /ground_truth messages with no valid pose (a zero
    or non-finite quaternion, non-finite coordinates), which are skipped, as the node does.
    """
    rd = _Reader(path)
    try:
        if require_scans or scan_topic in rd.types:     # a scan topic present is LaserScan
            rd.check_topic(scan_topic, SCAN_TYPE)
        topics = {scan_topic, GT_TOPIC, ODOM_TOPIC} | ({MAP_TOPIC} if read_map else set())
        total = sum(rd.counts.get(t, 0) for t in topics)
        occ_map, scans, gt, od = None, [], {}, {}
        skipped: dict[str, tuple[int, str]] = {}     # topic: (count, the first reason)
        for n, (topic, msg) in enumerate(rd.messages(topics), 1):
            if topic == scan_topic:
                scans.append(_scan_record(msg))
            elif topic == MAP_TOPIC and occ_map is None:
                try:
                    occ_map = occupancy_map_from_msg(msg, max_map_cells)
                except ValueError as exc:
                    raise type(exc)(f'{rd.path}: {MAP_TOPIC}: {exc}') from None
            elif topic in (GT_TOPIC, ODOM_TOPIC):
                pose = _pose_of(msg.pose if topic == GT_TOPIC else msg.pose.pose)
                if isinstance(pose, str):
                    count, first = skipped.get(topic, (0, pose))
                    skipped[topic] = (count + 1, first)
                else:
                    (gt if topic == GT_TOPIC else od)[_stamp_of(msg.header)] = pose
            _progress_step(progress, n, total)
        for topic, (count, first) in skipped.items():
            warnings.warn(f'{rd.path}: {topic}: {count} message(s) with no valid pose skipped '
                          f'(the first: {first})', RuntimeWarning, stacklevel=2)
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
