"""
Where the laser sits on the robot: from TF when tf2_ros is importable, else the parameters.

``tf2_ros`` comes with every ROS 2 install but not with the PyPI wheels this package's venv uses,
so it is imported here once, guarded. :class:`LaserPoseSource` asks TF for the pose of the
scan's frame on ``base_frame`` (as nav2's AMCL does for each new laser frame) and falls back to
the ``laser_*`` parameters when TF has no answer (yet) or tf2_ros is absent. It logs which source
is in use whenever that changes, and remembers a pose found in TF per frame (lasers are mounted
rigidly).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import threading
from typing import Any, Callable

try:  # optional: any real ROS 2 install has it, the PyPI wheels do not
    import tf2_ros
except ImportError:  # pragma: no cover - depends on the install
    tf2_ros = None

from rclpy.duration import Duration
from rclpy.time import Time
from ssm_localization.ros.conversions import transform_pose, unit_quaternion
from ssm_localization.transforms import Pose2

TF_AVAILABLE = tf2_ros is not None


@dataclass(frozen=True)
class LaserMount:
    """
    The laser's pose on the base, whether it is mounted upside down, and where it came from.

    ``mirrored``: the laser's z axis points down, so its scans turn the other way round in the
    base frame (the scan is mirrored before localization). ``source`` is ``tf``, ``parameters``
    or ``base frame`` (the scan is already in ``base_frame``); ``detail`` says why.
    """

    pose: Pose2
    mirrored: bool
    source: str
    detail: str = ''

    def describe(self) -> str:
        """One line for the log."""
        x, y, yaw = self.pose
        text = f'laser pose ({x:.3f}, {y:.3f}, {yaw:.4f}) from {self.source}'
        if self.mirrored:
            text += ' (upside down: scans are mirrored)'
        return text + (f': {self.detail}' if self.detail else '')


def mount_from_transform(transform: Any) -> tuple[Pose2, bool, float]:
    """
    ``(planar pose, mirrored, tilt in rad)`` of a geometry_msgs/Transform.

    The yaw is that of the laser's x axis projected on the base plane; ``tilt`` is the angle
    between the laser's z axis and the base's z axis (or -z when mirrored).
    """
    pose = transform_pose(transform)
    x, y, _, _ = unit_quaternion(transform.rotation)
    r22 = 1.0 - 2.0 * (x * x + y * y)       # z of the laser's z axis in the base frame
    return pose, r22 < 0.0, math.acos(min(1.0, abs(r22)))


class LaserPoseSource:
    """
    The laser's mounting on ``base_frame`` for a scan frame: TF first, parameters second.

    ``buffer`` is anything with tf2_ros.Buffer's ``lookup_transform(target, source, time,
    timeout)`` (tests pass a stand-in); ``None`` means tf2_ros is unavailable. ``log(text)`` is
    called whenever the source for a frame changes.
    """

    MAX_TILT = math.radians(5.0)    # warn beyond this: the scan is treated as planar

    def __init__(self, base_frame: str, fallback: Pose2, log: Callable[[str], None],
                 buffer: Any = None, unavailable_reason: str = 'tf2_ros is not installed',
                 timeout_sec: float = 0.0) -> None:
        self.base_frame = base_frame.lstrip('/')
        self.fallback = tuple(float(v) for v in fallback)
        self._log = log
        self._buffer = buffer
        self._unavailable = unavailable_reason
        self._timeout = Duration(seconds=timeout_sec)
        self._lock = threading.Lock()
        self._found: dict[str, LaserMount] = {}     # frames TF answered for (rigid mounts)
        self._last: dict[str, tuple[str, str]] = {}   # frame -> (source, detail) last logged
        self._listener = None

    @classmethod
    def for_node(cls, node: Any, base_frame: str, fallback: Pose2,
                 log: Callable[[str], None]) -> 'LaserPoseSource':
        """Return a source listening to ``/tf`` and ``/tf_static`` if tf2_ros exists."""
        if not TF_AVAILABLE:
            return cls(base_frame, fallback, log)
        buffer = tf2_ros.Buffer()
        source = cls(base_frame, fallback, log, buffer=buffer)
        source._listener = tf2_ros.TransformListener(buffer, node, spin_thread=False)
        return source

    @property
    def buffer(self) -> Any:
        """Return the TF buffer, shared with the node's other TF users (None without tf2_ros)."""
        return self._buffer

    @property
    def uses_tf(self) -> bool:
        """Return True when TF is asked at all (tf2_ros importable or a stand-in buffer given)."""
        return self._buffer is not None

    def close(self) -> None:
        """Stop listening to TF."""
        if self._listener is not None:
            unregister = getattr(self._listener, 'unregister', None)
            if unregister is not None:
                unregister()
            self._listener = None

    def mount(self, frame_id: str) -> LaserMount:
        """Return the mounting of the laser whose scans carry ``frame_id``."""
        frame = (frame_id or '').lstrip('/')
        if frame and frame == self.base_frame:
            result = LaserMount((0.0, 0.0, 0.0), False, 'base frame',
                                f'the scan is in {self.base_frame}')
        elif frame in self._found:
            return self._found[frame]
        elif not frame:
            result = self._params('the scan has no frame_id')
        elif self._buffer is None:
            result = self._params(self._unavailable)
        else:
            result = self._lookup(frame)
        self._report(frame, result)
        return result

    def _params(self, why: str) -> LaserMount:
        return LaserMount(self.fallback, False, 'parameters',
                          f'laser_x/laser_y/laser_yaw ({why})')

    def _lookup(self, frame: str) -> LaserMount:
        try:
            stamped = self._buffer.lookup_transform(self.base_frame, frame, Time(),
                                                    self._timeout)
            pose, mirrored, tilt = mount_from_transform(stamped.transform)
        except Exception as exc:  # noqa: BLE001 - tf2 raises several types; all mean "no answer"
            reason = str(exc).strip().splitlines()[0] if str(exc).strip() else \
                type(exc).__name__
            return self._params(f'TF has no {self.base_frame} <- {frame}: {reason}')
        detail = f'TF {self.base_frame} <- {frame}'
        if tilt > self.MAX_TILT:
            detail += f'; tilted by {math.degrees(tilt):.1f} deg, treated as planar'
        result = LaserMount(pose, mirrored, 'tf', detail)
        with self._lock:
            self._found[frame] = result
        return result

    def _report(self, frame: str, result: LaserMount) -> None:
        key = (result.source, result.detail.split(':')[0])
        with self._lock:
            if self._last.get(frame) == key:
                return
            self._last[frame] = key
        self._log(f'scan frame {frame or "(none)"}: {result.describe()}')
