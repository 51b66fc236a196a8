"""
The tracker behind ``global_localizer``'s ``track`` mode (ROS-side glue, no node).

:class:`TrackSession` owns one core :class:`~ssm_localization.localization.tracker.Tracker` for
the localizer the node serves (a new map index or laser mount gives a new localizer: the track
starts over, keeping its pose when only the laser mount changed), the odometry source and the
map -> odom broadcaster. ``initialpose`` and the answers of the relocalize services become the
tracker's prior (:meth:`TrackSession.set_prior`); a prior that comes before the map waits for it.
"""
from __future__ import annotations

import threading
from typing import Any, Callable

import numpy as np
from ssm_localization.config import TrackerConfig
from ssm_localization.localization.localizer import GlobalLocalizer
from ssm_localization.localization.tracker import Tracker, TrackResult
from ssm_localization.ros.conversions import covariance3, pose_from_msg, stamp_to_ns
from ssm_localization.ros.odometry import CLOCK_RESET, MapOdomBroadcaster, OdometrySource
from ssm_localization.transforms import Pose2


class TrackSession:
    """One track at a time: scans in, :class:`TrackResult` out; thread-safe."""

    def __init__(self, config: TrackerConfig, odometry: OdometrySource,
                 broadcaster: MapOdomBroadcaster | None, log: Callable[[str], None]) -> None:
        self.config = config
        self.odometry = odometry
        self.broadcaster = broadcaster
        self._log = log
        self._lock = threading.Lock()
        self._tracker: Tracker | None = None
        self._pending: tuple[Pose2, np.ndarray | None] | None = None
        self._last_ns: int | None = None    # stamp of the last scan tracked
        self.count = 0            # scans tracked

    def _tracker_for(self, localizer: GlobalLocalizer) -> Tracker:
        old = self._tracker
        if old is not None and old.localizer is localizer:
            return old
        tracker = Tracker(localizer, self.config)
        if old is not None:
            tracker.noise = old.noise        # the same robot's odometry: what was learnt stays
        if old is not None and old.localizer.index is localizer.index and not old.lost:
            tracker.set_prior(old.pose, old.covariance)      # same map, another laser mount
            self._log('track: the laser mount changed; the track goes on from its last pose')
        elif old is not None:
            self._log('track: a new map index; localizing globally')
        if self._pending is not None:
            tracker.set_prior(*self._pending)
            self._pending = None
        self._tracker = tracker
        return tracker

    def track(self, localizer: GlobalLocalizer, scan: Any, stamp: Any, map_frame: str,
              publish_tf: bool = True) -> TrackResult | None:
        """
        Track one scan (anything with LaserScan fields) taken at ``stamp``.

        The odometry pose at ``stamp`` comes from :attr:`odometry`; with ``publish_tf`` the
        map -> odom transform is sent (again) afterwards. A scan that is not newer than the
        last one tracked (the same scan delivered twice, or one out of order) is skipped:
        None. A stamp more than :data:`CLOCK_RESET` s older than the last one is a clock that
        was reset (a bag played again, a simulation restarted) and is tracked.
        """
        ns = stamp_to_ns(stamp)
        odom = self.odometry.pose_at(stamp)
        with self._lock:
            last = self._last_ns
            if last is not None and last - CLOCK_RESET * 1e9 < ns <= last:
                return None
            tracker = self._tracker_for(localizer)
            result = tracker.track(scan, odom, ns * 1e-9)
            self._last_ns = ns
            self.count += 1
        if publish_tf and self.broadcaster is not None:
            self.broadcaster.update(result.pose if result.ok else None, odom, stamp, map_frame)
        return result

    @property
    def waiting_prior(self) -> bool:
        """Tell whether a prior waits for the first map index."""
        return self._pending is not None

    def set_prior(self, pose: Pose2, covariance: np.ndarray | None = None) -> None:
        """Restart the track from ``pose`` (``ValueError`` for a bad pose or covariance)."""
        with self._lock:
            if self._tracker is None:
                self._pending = Tracker.check_prior(pose, covariance)
            else:
                self._tracker.set_prior(pose, covariance)

    def prior_from_msg(self, msg: Any, map_frame: str) -> str:
        """
        Take a geometry_msgs/PoseWithCovarianceStamped (``initialpose``) as the prior.

        Returns a line for the log; poses in another frame than ``map_frame`` are refused
        (``ValueError``), as are non-finite ones.
        """
        frame = (msg.header.frame_id or '').lstrip('/')
        if frame and frame != map_frame.lstrip('/'):
            raise ValueError(f'initialpose in frame {frame!r}, not the map frame {map_frame!r}')
        pose = pose_from_msg(msg.pose.pose)
        cov = covariance3(msg.pose.covariance)
        try:
            Tracker.check_prior(pose, cov)
        except ValueError:
            cov = None                   # RViz sends a fixed one; a degenerate one: the default
        self.set_prior(pose, cov)
        x, y, yaw = pose
        return (f'track: prior from initialpose x={x:.3f} y={y:.3f} yaw={yaw:.4f}'
                + ('' if cov is not None else ' (default covariance)'))
