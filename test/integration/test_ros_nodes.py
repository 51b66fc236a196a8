"""map_indexer / global_localizer nodes in-process (DDS on localhost, unique domain)."""
from __future__ import annotations

import math
import time

from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from helpers import close_pose, find_bag, LocalizerRig, ros_params, synthetic_map
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from sensor_msgs.msg import LaserScan
from ssm_localization.ros.conversions import (laser_scan_from_record, occupancy_grid_from_map,
                                              pose_from_msg, stamp_to_sec)
from ssm_localization.ros.lifecycle import state_label
from ssm_localization.ros.qos import LATCHED_QOS
from visualization_msgs.msg import Marker, MarkerArray

pytestmark = pytest.mark.ros

POS_TOL = 0.15      # m
YAW_TOL = 0.05      # rad


def _has_nodes(arr: MarkerArray) -> bool:
    return any(m.ns == 'nodes' and len(m.points) > 0 for m in arr.markers)


def _simulated(occ, count: int = 6, seed: int = 3):
    from ssm_localization import simulate, SimulationConfig
    return simulate(occ, SimulationConfig(count=count, seed=seed, clearance=0.4,
                                          noise_sigma=0.005, stamp0=100.0))


def _close(pose, truth) -> bool:
    return close_pose(pose, truth, POS_TOL, YAW_TOL)


class Localizer(LocalizerRig):
    """The localizer rig with the topological_map stream, autostarted."""

    def __init__(self, ros, **params) -> None:
        super().__init__(ros, **params)
        self.markers = ros.collect(MarkerArray, 'topological_map', LATCHED_QOS)
        assert ros.wait_for(lambda: state_label(self.node) == 'active', 10), 'not autostarted'

    def served(self):
        """Return the localizer the node serves now (None before the first index)."""
        served = self.node.source.served
        return served.localizer if served is not None else None

    def busy(self) -> bool:
        return self.node.map_state().phase.reported == 'indexing'

    def publish_map(self, occ_or_grid) -> None:
        grid = occ_or_grid if isinstance(occ_or_grid, OccupancyGrid) \
            else occupancy_grid_from_map(occ_or_grid)
        self.map_pub.publish(grid)

    def relocalize(self, scan: LaserScan | None, timeout: float = 30.0):
        """Call relocalize; publish ``scan`` every 50 ms until the answer arrives."""
        return self.call_relocalize(scan, timeout)

    def new_pose(self, timeout: float = 5.0):
        """
        Return the pose published by the last successful relocalize.

        The service answer and the topic message travel separately, so wait (bounded) for the
        message to arrive.
        """
        assert self.ros.wait_for(lambda: len(self.poses) > self.n_poses_before, timeout), \
            'no global_pose after relocalize'
        return self.poses[-1]


# ---------------------------------------------------------------------------- map_indexer

def test_map_indexer_markers_index_file_and_newest_map_wins(ros, tmp_path):
    from ssm_localization.mapping.index import load_index
    from ssm_localization.ros.map_indexer import MapIndexerNode
    index_file = tmp_path / 'sub' / 'index.npz'
    node = ros.add(MapIndexerNode(context=ros.context,
                                  parameter_overrides=ros_params(index_file=str(index_file))))
    got = ros.collect(MarkerArray, 'topological_map', LATCHED_QOS)
    pub = ros.node.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
    first = synthetic_map(0)
    pub.publish(occupancy_grid_from_map(first))
    assert ros.wait_for(lambda: any(_has_nodes(a) for a in got), 120), 'no topological_map'
    arr = next(a for a in got if _has_nodes(a))
    assert arr.markers[0].action == Marker.DELETEALL
    nodes = next(m for m in arr.markers if m.ns == 'nodes')
    assert arr.markers[0].header.frame_id == 'map'
    assert any(m.ns == 'gvd' and len(m.points) > 0 for m in arr.markers)
    labels = [m for m in arr.markers if m.type == Marker.TEXT_VIEW_FACING]
    assert len(labels) == len(nodes.points)
    assert ros.wait_for(index_file.exists, 10)
    index = load_index(index_file)
    assert len(index.node_xy) == len(nodes.points)
    np.testing.assert_array_equal(index.map.data, first.data)

    # Three maps in a row: the last one wins, nothing half-built is published.
    n_before = len(got)
    maps = [synthetic_map(k) for k in (1, 2, 3)]
    for occ in maps:
        pub.publish(occupancy_grid_from_map(occ))
        time.sleep(0.05)
    assert ros.wait_for(lambda: node.index is not None and node.builder is not None
                        and not node.builder.busy
                        and np.array_equal(node.index.map.data, maps[-1].data), 120)
    assert ros.wait_for(lambda: np.array_equal(load_index(index_file).map.data, maps[-1].data),
                        10)
    assert all(_has_nodes(a) for a in got[n_before:])


def test_map_indexer_newer_map_aborts_running_build(ros, monkeypatch, capfd):
    from ssm_localization.ros import map_indexer
    from ssm_localization.ros.map_indexer import MapIndexerNode
    real_build = map_indexer.build_index
    started = []

    def slow_build(occ, config=None, progress=None, **kwargs):
        started.append(occ)
        for i in range(10):
            time.sleep(0.1)
            progress(i, 100, 'slow test build')
        return real_build(occ, config, progress, **kwargs)
    monkeypatch.setattr(map_indexer, 'build_index', slow_build)
    node = ros.add(MapIndexerNode(context=ros.context))
    got = ros.collect(MarkerArray, 'topological_map', LATCHED_QOS)
    pub = ros.node.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
    first, second = synthetic_map(0), synthetic_map(3)
    pub.publish(occupancy_grid_from_map(first))
    assert ros.wait_for(lambda: started, 10)
    pub.publish(occupancy_grid_from_map(second))
    assert ros.wait_for(lambda: node.index is not None and node.builder is not None
                        and not node.builder.busy, 60)
    assert np.array_equal(node.index.map.data, second.data)
    assert len(started) == 2
    assert 'dropped, a newer map arrived' in ros.wait_for_log(capfd, 'dropped, a newer map')
    time.sleep(0.3)
    assert len([a for a in got if _has_nodes(a)]) == 1     # only the complete, newest index


def test_map_indexer_ignores_bad_maps(ros):
    from ssm_localization.mapping.map_io import OccupancyMap
    from ssm_localization.ros.map_indexer import MapIndexerNode
    node = ros.add(MapIndexerNode(context=ros.context))
    pub = ros.node.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
    pub.publish(occupancy_grid_from_map(OccupancyMap(np.full((50, 50), 100, np.int8), 0.05)))
    time.sleep(0.5)
    assert node.index is None and node.builder is not None and not node.builder.busy


# ---------------------------------------------------------------------------- global_localizer

def test_relocalize_before_map_fails_with_reason(ros):
    loc = Localizer(ros, scan_timeout=0.5)
    res = loc.relocalize(None)
    assert not res.success
    assert 'no map' in res.message and 'map' in res.message


def test_localizer_service_bad_input_and_kidnapping(ros, capfd):
    """Indexing-in-progress answer, bad scans rejected, then good relocalizations (kidnapped)."""
    occ = synthetic_map(0)
    sim = _simulated(occ, count=8)
    loc = Localizer(ros, scan_timeout=1.0)
    loc.publish_map(occ)
    assert ros.wait_for(lambda: loc.busy() or loc.served() is not None, 10)
    if loc.busy():   # answered while indexing, not blocked behind it
        t0 = time.monotonic()
        res = loc.relocalize(None)
        assert not res.success and 'indexing in progress' in res.message
        assert time.monotonic() - t0 < 5.0
    assert loc.wait_ready()
    assert any(_has_nodes(a) for a in loc.markers) or ros.wait_for(
        lambda: any(_has_nodes(a) for a in loc.markers), 5)

    # no scan at all -> timeout
    res = loc.relocalize(None)
    assert not res.success and 'no scan' in res.message

    # bad scans over the wire: each is refused with a reason, the node keeps serving
    good = laser_scan_from_record(sim.scans[0])
    bad = []
    empty = LaserScan()
    empty.header = good.header
    bad.append(empty)
    nan = laser_scan_from_record(sim.scans[0])
    nan.ranges = [math.nan] * len(good.ranges)
    bad.append(nan)
    inf = laser_scan_from_record(sim.scans[0])
    inf.ranges = [math.inf] * len(good.ranges)
    bad.append(inf)
    zero = laser_scan_from_record(sim.scans[0])
    zero.angle_increment = 0.0
    bad.append(zero)
    capfd.readouterr()
    for scan in bad:
        res = loc.relocalize(scan)
        assert not res.success and res.message.startswith('bad scan'), res.message
    assert not loc.poses, 'nothing may be published for bad scans'
    assert 'skipping scan' in capfd.readouterr().err        # logged as a warning

    # a mirrored scan (negative increment, reversed ranges) is the same scan: still localizes
    k0 = 0
    mirrored = laser_scan_from_record(sim.scans[k0])
    n = len(mirrored.ranges)
    mirrored.angle_min = mirrored.angle_min + mirrored.angle_increment * (n - 1)
    mirrored.angle_increment = -mirrored.angle_increment
    mirrored.ranges = list(reversed(mirrored.ranges))
    res = loc.relocalize(mirrored)
    assert res.success, res.message

    # good relocalizations at two distant poses (kidnapping)
    dist = np.hypot(*(sim.poses[:, :2] - sim.poses[k0, :2]).T)
    k1 = int(np.argmax(dist))
    for k in (k0, k1):
        scan = laser_scan_from_record(sim.scans[k])
        before = len(loc.poses)
        res = loc.relocalize(scan)
        assert res.success, res.message
        for key in ('x=', 'y=', 'yaw=', 'node=', 'status=ok'):
            assert key in res.message, res.message
        assert ros.wait_for(lambda: len(loc.poses) > before, 5)
        msg = loc.poses[-1]
        assert msg.header.frame_id == 'map'
        assert stamp_to_sec(msg.header.stamp) == pytest.approx(sim.scans[k].stamp, abs=1e-6)
        pose = pose_from_msg(msg.pose.pose)
        assert _close(pose, sim.poses[k]), (k, pose, sim.poses[k])
        cov = np.array(msg.pose.covariance).reshape(6, 6)
        assert np.all(np.isfinite(cov)) and cov[0, 0] > 0 and cov[5, 5] > 0
    assert dist[k1] > 3.0
    cands = [m for m in loc.markers[-1].markers if m.ns == 'candidates']
    scan_pts = [m for m in loc.markers[-1].markers if m.ns == 'scan']
    assert cands and scan_pts and len(scan_pts[0].points) > 10


def test_service_answers_while_indexing(ros, monkeypatch):
    """A relocalize call during indexing fails at once with 'indexing in progress'."""
    from ssm_localization.ros import index_source
    real_build = index_source.build_index

    def slow_build(occ, config=None, progress=None):     # a big map, deterministically
        for i in range(20):
            time.sleep(0.1)
            if progress is not None:
                progress(i, 100, 'slow test build')
        return real_build(occ, config, progress)
    monkeypatch.setattr(index_source, 'build_index', slow_build)
    loc = Localizer(ros)
    loc.publish_map(synthetic_map(0))
    assert ros.wait_for(loc.busy, 10)
    t0 = time.monotonic()
    res = loc.relocalize(None, timeout=10)
    assert not res.success and 'indexing in progress' in res.message, res.message
    assert time.monotonic() - t0 < 1.5
    assert loc.wait_ready(60)


def test_localizer_survives_bad_maps_and_reindexes_new_map(ros, capfd):
    from ssm_localization.mapping.map_io import OccupancyMap
    occ = synthetic_map(0)
    sim = _simulated(occ, count=2, seed=11)
    loc = Localizer(ros, publish_initialpose=True, map_frame='world')
    initial = ros.collect(PoseWithCovarianceStamped, 'initialpose', 10)
    loc.publish_map(occ)
    assert loc.wait_ready()
    first_localizer = loc.served()

    # no free space, malformed, absurdly large: warnings, the current index stays
    loc.publish_map(OccupancyMap(np.full((60, 60), 100, np.int8), 0.05))
    malformed = occupancy_grid_from_map(occ)
    malformed.data = malformed.data[:-7]
    loc.publish_map(malformed)
    huge = OccupancyGrid()
    huge.info.width = huge.info.height = 100_000
    huge.info.resolution = 0.05
    loc.publish_map(huge)
    walled = np.full((12, 12), 100, np.int8)
    walled[4:8, 4:8] = 0                       # free cells, but no room for a single node
    loc.publish_map(OccupancyMap(walled, 0.05))
    assert ros.wait_for(lambda: 'indexing failed' in capfd.readouterr().err, 10)
    assert loc.served() is first_localizer and not loc.busy()
    res = loc.relocalize(laser_scan_from_record(sim.scans[0]))
    assert res.success, res.message
    assert loc.new_pose().header.frame_id == 'world'
    # handed over on initialpose (again every handover_period until AMCL confirms it: with
    # no AMCL here a slow poll may first see two copies)
    assert ros.wait_for(lambda: len(initial) >= 1, 5)
    assert all(_close(pose_from_msg(m.pose.pose), sim.poses[0]) for m in list(initial))

    # the same map again: no re-indexing; a changed map: a new localizer swapped in
    loc.publish_map(occ)
    time.sleep(0.3)
    assert loc.served() is first_localizer and not loc.busy()
    changed = synthetic_map(2)
    candidates = ros.collect(PoseArray, 'candidates', LATCHED_QOS)
    assert loc.node._last is not None
    loc.publish_map(changed)
    assert ros.wait_for(lambda: loc.served() is not first_localizer, 120)
    assert loc.wait_ready()
    # the answer on the old map is not reported on the new one; its candidates are cleared
    assert loc.node._last is None
    assert ros.wait_for(lambda: any(len(m.poses) == 0 for m in list(candidates)), 5)
    sim2 = _simulated(changed, count=1, seed=5)
    res = loc.relocalize(laser_scan_from_record(sim2.scans[0]))
    assert res.success, res.message
    assert _close(pose_from_msg(loc.new_pose().pose.pose), sim2.poses[0])


def test_index_file_is_saved_then_loaded_without_a_map(ros, tmp_path):
    occ = synthetic_map(1)
    sim = _simulated(occ, count=1, seed=21)
    index_file = tmp_path / 'cache' / 'index.npz'
    first = Localizer(ros, index_file=str(index_file))     # missing: index the map, save it
    first.publish_map(occ)
    assert first.wait_ready() and ros.wait_for(index_file.exists, 10)
    ros.remove(first.node)
    second = Localizer(ros, index_file=str(index_file))    # present: loaded, not rebuilt
    assert second.wait_ready()
    assert second.node.source.served.source == f'index file {index_file}'
    time.sleep(0.3)      # the same map is still latched on /map: compared, kept
    assert second.node.source.served.source == f'index file {index_file}' and not second.busy()
    res = second.relocalize(laser_scan_from_record(sim.scans[0]))
    assert res.success, res.message
    assert _close(pose_from_msg(second.new_pose().pose.pose), sim.poses[0])


def test_continuous_mode_takes_newest_scan(ros):
    occ = synthetic_map(0)
    sim = _simulated(occ, count=12, seed=7)
    loc = Localizer(ros, mode='continuous')
    loc.publish_map(occ)
    assert loc.wait_ready()
    by_stamp = {round(s.stamp, 6): p for s, p in zip(sim.scans, sim.poses)}
    for scan in sim.scans:          # 100 Hz: faster than the localizer, so some are dropped
        loc.scan_pub.publish(laser_scan_from_record(scan))
        time.sleep(0.01)
    last = round(sim.scans[-1].stamp, 6)
    assert ros.wait_for(lambda: any(round(stamp_to_sec(m.header.stamp), 6) == last
                                    for m in loc.poses), 30), 'newest scan never localized'
    assert 1 <= len(loc.poses) <= len(sim.scans)
    ok = 0
    for msg in loc.poses:
        truth = by_stamp[round(stamp_to_sec(msg.header.stamp), 6)]
        ok += _close(pose_from_msg(msg.pose.pose), truth)
    assert ok == len(loc.poses)


def test_continuous_mode_rate_limit(ros):
    occ = synthetic_map(0)
    sim = _simulated(occ, count=1, seed=9)
    loc = Localizer(ros, mode='continuous', rate=2.0)
    loc.publish_map(occ)
    assert loc.wait_ready()
    scan = laser_scan_from_record(sim.scans[0])
    t0 = time.monotonic()
    while time.monotonic() - t0 < 2.0:          # 40 scans in 2 s at 20 Hz
        loc.scan_pub.publish(scan)
        time.sleep(0.05)
    time.sleep(0.3)
    assert 2 <= len(loc.poses) <= 6, len(loc.poses)


@pytest.mark.parametrize('bag_name', ['depot_sim', 'intel_queries'])
def test_localize_bag_scans_against_ground_truth(ros, bag_name):
    """Scans of a committed bag fed over ROS; published poses checked against /ground_truth."""
    from ssm_localization import read_bag
    data = read_bag(find_bag(bag_name))
    assert data.map is not None and data.ground_truth
    loc = Localizer(ros, scan_timeout=5.0)
    loc.publish_map(data.map)
    assert loc.wait_ready(300)
    with_truth = [s for s in data.scans if s.stamp in data.ground_truth]
    picks = [with_truth[i] for i in np.linspace(0, len(with_truth) - 1, 5).astype(int)]
    good = 0
    for scan in picks:
        res = loc.relocalize(laser_scan_from_record(scan))
        if not res.success:
            continue
        msg = loc.new_pose()
        assert stamp_to_sec(msg.header.stamp) == pytest.approx(scan.stamp, abs=1e-6)
        truth = data.ground_truth[scan.stamp]
        pose = pose_from_msg(msg.pose.pose)
        assert _close(pose, truth), (scan.stamp, pose, truth)   # published poses are right
        good += 1
    assert good >= 3, f'only {good}/5 scans localized'
