"""
Writing rosbag2 bags (mcap storage, ROS 2 Jazzy definitions) with ``rosbags``.

Layout (topics, frames, stamps): see ``bag_records``; ``/map`` is written first and offered
transient-local, then per scan ``/scan``, ``/ground_truth`` and ``/odom``.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from .bag_records import (GT_TOPIC, GT_TYPE, MAP_TOPIC, MAP_TYPE, ODOM_TOPIC, ODOM_TYPE,
                          SCAN_TOPIC, SCAN_TYPE, ScanRecord, stamp_to_ns, typestore)
from ..files.writing import atomic_dir
from ..mapping.occupancy import OccupancyMap
from ..progress import ProgressCallback
from ..transforms import Pose2, yaw_to_quaternion


def _time_msg(ts, stamp: float):
    sec, nsec = divmod(stamp_to_ns(stamp), 10**9)
    return ts.types['builtin_interfaces/msg/Time'](sec=int(sec), nanosec=int(nsec))


def _header(ts, stamp: float, frame_id: str):
    return ts.types['std_msgs/msg/Header'](stamp=_time_msg(ts, stamp), frame_id=frame_id)


def _pose_msg(ts, pose) -> object:
    x, y, yaw = (float(v) for v in pose)
    qx, qy, qz, qw = yaw_to_quaternion(yaw)
    return ts.types['geometry_msgs/msg/Pose'](
        position=ts.types['geometry_msgs/msg/Point'](x=x, y=y, z=0.0),
        orientation=ts.types['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw))


def _latched_qos():
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                    QosTime)
    zero = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                zero, zero, QosLiveliness.AUTOMATIC, zero, False)]


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
    pwc = ts.types['geometry_msgs/msg/PoseWithCovariance'](pose=_pose_msg(ts, pose),
                                                           covariance=cov)
    vec = ts.types['geometry_msgs/msg/Vector3']
    twist = ts.types['geometry_msgs/msg/Twist'](linear=vec(x=0.0, y=0.0, z=0.0),
                                                angular=vec(x=0.0, y=0.0, z=0.0))
    twc = ts.types['geometry_msgs/msg/TwistWithCovariance'](twist=twist, covariance=cov.copy())
    return ts.types[ODOM_TYPE](header=_header(ts, stamp, frame_id),
                               child_frame_id=child_frame_id, pose=pwc, twist=twc)


def write_bag(path: str | Path, map: OccupancyMap | None = None,  # noqa: A002
              scans: Iterable[ScanRecord] = (),
              ground_truth: Mapping[float, Pose2] | None = None,
              odom: Mapping[float, Pose2] | None = None, overwrite: bool = False,
              map_stamp: float | None = None, odom_frame: str = 'odom',
              base_frame: str = 'base_link', compress: bool = True,
              progress: ProgressCallback | None = None) -> Path:
    """
    Write a rosbag2 directory (mcap storage, Jazzy definitions); return its path.

    ``/map`` is written once, first (log time just before the first message, offered
    transient-local); then per scan in the given order ``/scan``, ``/ground_truth`` and ``/odom``
    for the stamps present in those mappings (matched to the scans' stamps to the nanosecond).
    Message log times are the header stamps, forced strictly increasing so bag order is scan order.
    ``compress`` zstd-compresses the mcap chunks (read natively by the Jazzy mcap plugin).
    The bag is written beside ``path`` and moved into place when complete: a failure leaves
    nothing behind (and an existing bag untouched).
    """
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    path = Path(path)
    if (path.exists() or path.is_symlink()) and not overwrite:
        raise FileExistsError(f'bag exists already (pass overwrite=True): {path}')
    scans = list(scans)
    for s in scans:
        if not math.isfinite(s.stamp) or np.ndim(s.ranges) != 1:
            raise ValueError(f'{path}: scan with a non-finite stamp or non-1-D ranges')
    # poses keyed by integer nanoseconds, so they meet their scans whatever float rounding
    gt = {stamp_to_ns(k): v for k, v in (ground_truth or {}).items()}
    od = {stamp_to_ns(k): v for k, v in (odom or {}).items()}
    ts = typestore()
    first = scans[0].stamp if scans else (min(gt) * 1e-9 if gt else 0.0)
    if map_stamp is None:
        map_stamp = first
    last_ns = -1

    def log_time(stamp: float) -> int:
        nonlocal last_ns
        last_ns = max(stamp_to_ns(stamp), last_ns + 1, 0)
        return last_ns

    with atomic_dir(path, 'bag', overwrite) as stage:   # all or nothing
        writer = Writer(stage, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
        if compress:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            if map is not None:
                conn = writer.add_connection(MAP_TOPIC, MAP_TYPE, typestore=ts,
                                             offered_qos_profiles=_latched_qos())
                last_ns = max(stamp_to_ns(min(map_stamp, first)) - 1_000_000, 0)
                writer.write(conn, last_ns,
                             ts.serialize_cdr(_map_msg(ts, map, map_stamp), MAP_TYPE))
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
                msg = ts.types[GT_TYPE](header=_header(ts, stamp, 'map'),
                                        pose=_pose_msg(ts, gt[key]))
                writer.write(c_gt, log_time(stamp), ts.serialize_cdr(msg, GT_TYPE))
            for key in sorted(od):
                stamp = key * 1e-9
                msg = _odom_msg(ts, stamp, od[key], odom_frame, base_frame)
                writer.write(c_od, log_time(stamp), ts.serialize_cdr(msg, ODOM_TYPE))
    return path
