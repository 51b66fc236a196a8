"""
``bench soak``.

A ``global_localizer`` process in continuous mode, fed a looping bag for minutes, its resident
memory and pose rate sampled.

The node runs as its own process (the installed console script, or ``python -m`` of its module),
so its RSS is honest; this driver publishes the bag's map once (latched) and its scans in a loop
at a fixed rate, counts the poses the node publishes on ``global_pose``, and reads the node's
``VmRSS`` from /proc every ``sample_s`` seconds. After ``warmup_s`` the RSS must stay within
``flat_tolerance`` of its value at the end of the warm-up (10 % by default).
"""
from __future__ import annotations

from dataclasses import dataclass
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import threading
import time

from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from ssm_localization.evaluation.plotting import plot_soak
from ssm_localization.io.bag_reader import read_bag
from ssm_localization.ros.conversions import laser_scan_from_record, occupancy_grid_from_map
from ssm_localization.ros.executor import shutdown_context
from ssm_localization.ros.qos import LATCHED_QOS


@dataclass(frozen=True)
class Sample:
    """One sample: seconds since start, the node's RSS (MB), poses per second since the last."""

    t: float
    rss_mb: float
    pose_rate: float


class SoakDriver(Node):
    """Publishes the map once and the scans in a loop; counts the poses that come back."""

    def __init__(self, bag: Path, rate: float) -> None:
        super().__init__('ssm_soak_driver')
        data = read_bag(bag)
        if data.map is None or not data.scans:
            raise ValueError(f'{bag}: a soak needs a bag with /map and /scan')
        self._scans = [laser_scan_from_record(s) for s in data.scans]
        self._map = occupancy_grid_from_map(data.map)
        self._k = 0
        self.poses = 0
        self._lock = threading.Lock()
        self._map_pub = self.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
        self._scan_pub = self.create_publisher(LaserScan, 'scan', qos_profile_sensor_data)
        self.create_subscription(PoseWithCovarianceStamped, 'global_pose', self._on_pose,
                                 LATCHED_QOS)
        self._map_pub.publish(self._map)
        self.create_timer(1.0 / rate, self._tick)

    def _tick(self) -> None:
        msg = self._scans[self._k % len(self._scans)]
        msg.header.stamp = self.get_clock().now().to_msg()
        self._scan_pub.publish(msg)
        self._k += 1

    def _on_pose(self, _msg: PoseWithCovarianceStamped) -> None:
        with self._lock:
            self.poses += 1

    def take_poses(self) -> int:
        with self._lock:
            n, self.poses = self.poses, 0
        return n


def rss_mb(pid: int) -> float:
    """Resident set size of process ``pid`` in MB (``VmRSS`` of /proc)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return float(line.split()[1]) / 1024.0
    raise ValueError(f'no VmRSS for process {pid}')


def node_command(params: list[str]) -> list[str]:
    """Return the installed ``global_localizer`` beside this interpreter, else its module."""
    script = Path(sys.executable).parent / 'global_localizer'
    base = [str(script)] if script.exists() else [sys.executable, '-m',
                                                  'ssm_localization.ros.global_localizer']
    return base + ['--ros-args', '-p', 'mode:=continuous', *params]


def soak(bag: Path, minutes: float, rate: float = 10.0, sample_s: float = 5.0,
         warmup_s: float = 60.0, flat_tolerance: float = 0.10, params: tuple[str, ...] = (),
         plot: Path | None = None) -> int:
    """Run the soak; print one line per sample and a verdict. Returns 0 when RSS stayed flat."""
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(random.Random(os.getpid()).randint(1, 101)))
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    proc = subprocess.Popen(node_command([a for p in params for a in ('-p', p)]), env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    rclpy.init()
    driver = SoakDriver(bag, rate)
    executor = SingleThreadedExecutor()
    executor.add_node(driver)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    samples: list[Sample] = []
    t0 = time.monotonic()
    print(f'soak: node pid {proc.pid}, scans at {rate:g} Hz from {bag}, {minutes:g} min, '
          f'ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]}', flush=True)
    try:
        while time.monotonic() - t0 < minutes * 60.0:
            time.sleep(sample_s)
            if proc.poll() is not None:
                print(f'soak: the node exited with status {proc.returncode}: '
                      f'{proc.stderr.read()[-2000:]}', flush=True)
                return 1
            s = Sample(t=time.monotonic() - t0, rss_mb=rss_mb(proc.pid),
                       pose_rate=driver.take_poses() / sample_s)
            samples.append(s)
            print(f'  t={s.t:7.1f} s  rss={s.rss_mb:7.1f} MB  poses/s={s.pose_rate:5.2f}',
                  flush=True)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            proc.kill()
        executor.shutdown()
        driver.destroy_node()
        shutdown_context()
    return report(samples, warmup_s, flat_tolerance, plot)


def report(samples: list[Sample], warmup_s: float, flat_tolerance: float,
           plot: Path | None = None) -> int:
    """Print the summary; 0 when the RSS after warm-up stays within the tolerance."""
    after = [s for s in samples if s.t >= warmup_s]
    if not after:
        print('soak: too short for a verdict (no sample after the warm-up)')
        return 1
    ref = after[0].rss_mb
    lo, hi = min(s.rss_mb for s in after), max(s.rss_mb for s in after)
    growth = (after[-1].rss_mb - ref) / ref
    spread = (hi - lo) / ref
    rate = sum(s.pose_rate for s in after) / len(after)
    flat = spread <= flat_tolerance
    print(f'soak summary: after {warmup_s:g} s of warm-up RSS {ref:.1f} -> {after[-1].rss_mb:.1f} '
          f'MB (growth {growth:+.1%}, min {lo:.1f}, max {hi:.1f}, spread {spread:.1%}); '
          f'{rate:.2f} poses/s; RSS flat within {flat_tolerance:.0%}: '
          f'{"yes" if flat else "NO"}', flush=True)
    if plot is not None:
        plot_soak([(s.t, s.rss_mb, s.pose_rate) for s in samples], warmup_s, plot)
        print(f'wrote {plot}')
    return 0 if flat else 1
