"""
Plain helpers of the test suite (pytest fixtures and hooks are in ``conftest.py``).

Test modules import them with ``from helpers import ...`` (``test/`` is on ``sys.path``: pytest
puts the directory of the rootmost ``conftest.py`` there).

- paths: :data:`REPO`, :data:`BAGS`, :data:`SHARED_DATA` (``$SSM_LOCALIZATION_DATA``, else
  ``shared/data`` beside the repository); :func:`shared_data` / :func:`find_bag` skip a test
  when they are missing, except under CI (``CI=true``), where that is an error (:func:`missing`);
- ROS: :class:`RosHarness` (an rclpy context with a background executor), :func:`fresh_domain`,
  :func:`ros_params`, :class:`LocalizerRig`;
- geometry: :func:`synthetic_map`, :func:`close_pose`, and synthetic scans of a polygonal room
  (:func:`room_scan`, :func:`raycast`, :func:`pose_error`).
"""
from __future__ import annotations

import math
import os
from pathlib import Path
import random
import sys
import threading
import time
from typing import Any, Callable

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get('SSM_LOCALIZATION_DATA') or REPO.parent / 'shared' / 'data')
BAGS = REPO / 'bags'

_RNG = random.Random(os.getpid() ^ time.time_ns())

try:   # the ROS tests need rclpy; without it their modules cannot even be imported
    import rclpy
    HAVE_RCLPY = True
except ImportError:
    HAVE_RCLPY = False
CI = os.environ.get('CI', '').strip().lower() == 'true'

RCLPY_SKIP_REASON = ('rclpy is not importable: the ROS 2 tests need ROS 2 Jazzy Python packages '
                     '(`make venv` installs them from PyPI, or source /opt/ros/jazzy/setup.bash)')


def venv_bin(name: str) -> Path:
    """Return a console script next to the running interpreter (the venv's bin/)."""
    return Path(sys.executable).parent / name


def missing(reason: str) -> None:
    """Skip the running test for missing data, or fail it under CI (``CI=true``)."""
    if os.environ.get('CI', '').strip().lower() == 'true':
        pytest.fail(f'{reason} (CI=true: the test data must be present)', pytrace=False)
    pytest.skip(reason)


def shared_data(*parts: str) -> Path:
    """Return :data:`SHARED_DATA` / parts; see :func:`missing` when it does not exist."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        missing(f'shared data not found: {path}')
    return path


def find_bag(name: str) -> Path:
    """bags/<name> (directory or .mcap); see :func:`missing` when it does not exist."""
    for cand in (BAGS / name, BAGS / f'{name}.mcap'):
        if cand.exists():
            return cand
    missing(f'bag {BAGS / name} is not in the repository')


class RosHarness:
    """An rclpy context with a background MultiThreadedExecutor and a helper node."""

    def __init__(self, args: list[str] | None = None, num_threads: int = 6) -> None:
        from rclpy.executors import MultiThreadedExecutor
        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(args=args, context=self.context)
        self.executor = MultiThreadedExecutor(num_threads=num_threads, context=self.context)
        self.node = rclpy.create_node(f'ssm_test_{os.getpid()}', context=self.context)
        self.executor.add_node(self.node)
        self._nodes = [self.node]
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException
        try:
            self.executor.spin()
        except (ExternalShutdownException, Exception):  # noqa: BLE001 - shutdown races
            pass

    def add(self, node):
        """Spin ``node`` (created with ``context=harness.context``) too; return it."""
        self.executor.add_node(node)
        self._nodes.append(node)
        return node

    def remove(self, node) -> None:
        self.executor.remove_node(node)
        self._nodes.remove(node)
        node.destroy_node()

    def collect(self, msg_type, topic: str, qos) -> list:
        """Subscribe and append every message to the returned list."""
        got: list = []
        self.node.create_subscription(msg_type, topic, got.append, qos)
        return got

    @staticmethod
    def wait_for(pred: Callable[[], Any], timeout: float, period: float = 0.02) -> Any:
        end = time.monotonic() + timeout
        while True:
            value = pred()
            if value or time.monotonic() > end:
                return value
            time.sleep(period)

    @classmethod
    def wait_for_log(cls, capfd, *texts: str, timeout: float = 5.0) -> str:
        """
        Return stderr read so far and until every one of ``texts`` is in it (or the timeout).

        A node logs from its executor threads, so a line may follow the state change a test
        waited for by a few milliseconds; the test waits for the line, not only the state.
        """
        seen: list[str] = []

        def logged() -> bool:
            seen.append(capfd.readouterr().err)
            return all(t in ''.join(seen) for t in texts)

        cls.wait_for(logged, timeout)
        return ''.join(seen)

    def call(self, client, request, timeout: float = 30.0):
        """Call a service (waits for it first); the response, or None on timeout."""
        if not client.wait_for_service(timeout_sec=min(timeout, 10.0)):
            return None
        future = client.call_async(request)
        end = time.monotonic() + timeout
        while not future.done() and time.monotonic() < end:
            time.sleep(0.02)
        return future.result() if future.done() else None

    def close(self) -> None:
        for node in list(self._nodes):
            try:
                self.executor.remove_node(node)
                node.destroy_node()
            except Exception:  # noqa: BLE001
                pass
        self.executor.shutdown(timeout_sec=2.0)
        self.rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5.0)


def fresh_domain() -> int:
    """
    Move this process (and the processes it starts from now on) to a ROS domain of its own.

    Each ROS test gets one, so a node of an earlier test that is still shutting down (a process
    of the end-to-end tests, a node with the same name) cannot answer for the node under test.
    """
    if 'SSM_TEST_ROS_DOMAIN_ID' in os.environ:
        return int(os.environ['SSM_TEST_ROS_DOMAIN_ID'])
    current = int(os.environ.get('ROS_DOMAIN_ID', '0'))
    domain = current
    while domain == current:
        domain = _RNG.randint(1, 101)
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    return domain


def ros_params(**kw) -> list:
    """Return ``rclpy`` parameter overrides from keyword arguments."""
    from rclpy.parameter import Parameter
    return [Parameter(k, value=v) for k, v in kw.items()]


class LocalizerRig:
    """A GlobalLocalizerNode with ``map`` and ``scan`` publishers, a client, ``global_pose``."""

    def __init__(self, ros, **params) -> None:
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from nav_msgs.msg import OccupancyGrid
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import LaserScan
        from ssm_localization.ros.global_localizer import GlobalLocalizerNode
        from ssm_localization.ros.qos import LATCHED_QOS
        from std_srvs.srv import Trigger
        params.setdefault('scan_timeout', 3.0)
        self.ros = ros
        self.node = ros.add(GlobalLocalizerNode(context=ros.context,
                                                parameter_overrides=ros_params(**params)))
        self.map_pub = ros.node.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
        self.scan_pub = ros.node.create_publisher(LaserScan, 'scan', qos_profile_sensor_data)
        self.client = ros.node.create_client(Trigger, 'relocalize')
        self.poses = ros.collect(PoseWithCovarianceStamped, 'global_pose', LATCHED_QOS)
        self.n_poses_before = 0

    def wait_ready(self, timeout: float = 120.0) -> bool:
        """Wait until the node serves an index of the newest map."""
        return bool(self.ros.wait_for(
            lambda: self.node.map_state().phase.reported == 'ready', timeout, 0.05))

    def call(self, client, request, scan=None, timeout: float = 30.0):
        """Call a service; publish ``scan`` every 50 ms until the answer arrives."""
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(request)
        end = time.monotonic() + timeout
        while not future.done() and time.monotonic() < end:
            if scan is not None:
                self.scan_pub.publish(scan)
            time.sleep(0.05)
        assert future.done(), f'{client.srv_name} did not answer'
        return future.result()

    def call_relocalize(self, scan=None, timeout: float = 30.0):
        """Call relocalize (Trigger); publish ``scan`` every 50 ms until the answer arrives."""
        from std_srvs.srv import Trigger
        self.n_poses_before = len(self.poses)
        return self.call(self.client, Trigger.Request(), scan, timeout)


def close_pose(pose, truth, pos_tol: float = 0.15, yaw_tol: float = 0.05) -> bool:
    """Tell whether ``pose`` is within ``pos_tol`` metres and ``yaw_tol`` rad of ``truth``."""
    from ssm_localization.transforms import wrap_angle
    return (math.hypot(pose[0] - truth[0], pose[1] - truth[1]) < pos_tol
            and abs(float(wrap_angle(pose[2] - truth[2]))) < yaw_tol)


def synthetic_map(variant: int = 0):
    """
    Return a small 3-room map (10 m x 7 m at 0.05 m, frame ``map``).

    ``variant`` adds furniture.
    """
    import numpy as np
    from ssm_localization import OccupancyMap
    res = 0.05
    data = np.zeros((140, 200), np.int8)

    def box(x0: float, y0: float, x1: float, y1: float) -> None:
        r0, r1, c0, c1 = (int(round(v / res)) for v in (y0, y1, x0, x1))
        data[r0:r1, c0:c1] = 100
    box(0, 0, 10, 0.1), box(0, 6.9, 10, 7), box(0, 0, 0.1, 7), box(9.9, 0, 10, 7)
    box(4.0, 0, 4.1, 3.0), box(4.0, 4.0, 4.1, 7)          # wall with a door at y 3..4
    box(7.0, 0, 7.1, 1.0), box(7.0, 2.0, 7.1, 7)          # wall with a door at y 1..2
    box(1.2, 4.6, 1.8, 5.0), box(8.3, 5.0, 8.7, 5.8), box(5.4, 0.8, 5.7, 1.1)
    box(2.5, 1.0, 2.8, 2.2), box(5.0, 5.5, 6.2, 5.8)
    for k in range(variant):
        box(1.0 + 0.8 * k, 3.0, 1.3 + 0.8 * k, 3.3)
    return OccupancyMap(data, res, (-1.0, -0.5, 0.0), 'map')


# --------------------------------------------------------------------------- a polygonal room

# an irregular room (metres) with a pillar and a niche: no symmetry
ROOM = [
    [(-4.0, -3.0), (5.0, -3.0), (5.0, -1.0), (6.5, -1.0), (6.5, 1.5), (5.0, 1.5), (5.0, 4.0),
     (1.0, 4.0), (0.0, 2.5), (-2.5, 4.0), (-4.0, 4.0), (-4.0, -3.0)],
    [(2.0, 0.5), (2.6, 0.5), (2.6, 1.3), (2.0, 1.3), (2.0, 0.5)],
]


def segments(polys=ROOM) -> np.ndarray:
    out = []
    for poly in polys:
        p = np.asarray(poly, float)
        out.append(np.hstack((p[:-1], p[1:])))
    return np.vstack(out)


def raycast(pose, n_beams=360, fov=2 * np.pi, max_range=30.0, polys=ROOM):
    """
    Ranges (n_beams,) of a scanner at ``pose``.

    (x, y, yaw) in the room, counterclockwise from ``-fov/2``; ``inf`` where nothing is hit.
    Returns (ranges, angle_min, angle_increment).
    """
    segs = segments(polys)
    inc = fov / n_beams
    a_min = -fov / 2 if fov < 2 * np.pi else -np.pi
    ang = a_min + inc * np.arange(n_beams) + pose[2]
    d = np.column_stack((np.cos(ang), np.sin(ang)))                    # (B, 2)
    o = np.asarray(pose[:2], float)
    a = segs[:, :2] - o
    e = segs[:, 2:] - segs[:, :2]                                      # (S, 2)
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide='ignore', invalid='ignore'):
        t = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) / den
        u = (a[None, :, 0] * d[:, None, 1] - a[None, :, 1] * d[:, None, 0]) / den
    hit = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0) & (u <= 1)
    r = np.where(hit, t, np.inf).min(axis=1)
    r[r > max_range] = np.inf
    return r, a_min, inc


def room_scan(pose, n_beams=360, fov=2 * np.pi, noise=0.0, rng=None):
    """Points (N, 2) in the scanner frame, counterclockwise scan order."""
    r, a_min, inc = raycast(pose, n_beams, fov)
    if noise:
        r = r + (rng or np.random.default_rng(0)).normal(0.0, noise, r.shape)
    a = a_min + inc * np.arange(n_beams)
    ok = np.isfinite(r)
    return np.column_stack((r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])))


def pose_error(est, truth):
    e = np.asarray(est, float) - np.asarray(truth, float)
    e[2] = (e[2] + np.pi) % (2 * np.pi) - np.pi
    return float(np.hypot(e[0], e[1])), float(abs(e[2]))
