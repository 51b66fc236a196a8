"""ROS message conversions and markers (no DDS traffic)."""
from __future__ import annotations

import math
from types import SimpleNamespace

from diagnostic_msgs.msg import DiagnosticStatus
from helpers import shared_data
import numpy as np
import pytest
from sensor_msgs.msg import LaserScan
from ssm_localization import occupancy_map_from_msg
from ssm_localization.localization.confidence import resolution_warning
from ssm_localization.ros import conversions as conv
from ssm_localization.ros import markers
from ssm_localization.ros.diagnostics import localization_status
from visualization_msgs.msg import Marker

pytestmark = pytest.mark.ros


def _scan(ranges, angle_min=-1.0, inc=0.01, rmin=0.1, rmax=30.0) -> LaserScan:
    msg = LaserScan()
    msg.angle_min, msg.angle_increment = angle_min, inc
    msg.range_min, msg.range_max = rmin, rmax
    msg.ranges = [float(r) for r in ranges]
    return msg


def test_scan_args_and_problems():
    args = conv.scan_args_from_msg(_scan([1.0, 2.0, 3.0, math.inf]))
    assert args.ranges.dtype == np.float64 and args.ranges.shape == (4,)
    assert conv.scan_problem(args) is None
    assert 'empty' in conv.scan_problem(conv.scan_args_from_msg(_scan([])))
    assert 'finite' in conv.scan_problem(conv.scan_args_from_msg(_scan([math.nan] * 50)))
    assert 'finite' in conv.scan_problem(conv.scan_args_from_msg(_scan([math.inf] * 50)))
    assert 'angle_increment is 0' in conv.scan_problem(
        conv.scan_args_from_msg(_scan([1.0] * 10, inc=0.0)))
    assert 'full turn' in conv.scan_problem(conv.scan_args_from_msg(_scan([1.0] * 10, inc=1.0)))
    # negative increments are legal (mirrored scanners)
    assert conv.scan_problem(conv.scan_args_from_msg(_scan([1.0] * 10, inc=-0.01))) is None
    assert 'degrees for radians' in conv.scan_problem(
        conv.scan_args_from_msg(_scan([1.0] * 10, angle_min=-180.0)))
    # range_max 0 (a driver that leaves it unset): no limit, here and in the core alike
    assert conv.scan_problem(conv.scan_args_from_msg(_scan([1.0] * 10, rmax=0.0))) is None


def test_scan_points_drop_invalid():
    args = conv.scan_args_from_msg(_scan([1.0, math.nan, 0.05, math.inf, 2.0], angle_min=0.0,
                                         inc=math.pi / 2))
    pts = conv.scan_points(args)
    np.testing.assert_allclose(pts, [[1.0, 0.0], [2.0, 0.0]], atol=1e-12)


def test_map_round_trip():
    from ssm_localization.mapping.map_io import load_map_yaml, OccupancyMap
    occ = load_map_yaml(shared_data('maps', 'depot.yaml'))
    grid = conv.occupancy_grid_from_map(occ, 3.5)
    assert (grid.info.width, grid.info.height) == (occ.width, occ.height)
    assert grid.header.frame_id == 'map' and grid.header.stamp.sec == 3
    back = occupancy_map_from_msg(grid)
    np.testing.assert_array_equal(back.data, occ.data)
    assert back.checksum() == occ.checksum()
    rotated = OccupancyMap(np.zeros((4, 6), np.int8), 0.1, (1.0, -2.0, 0.5), 'world')
    back = occupancy_map_from_msg(conv.occupancy_grid_from_map(rotated))
    assert back.frame_id == 'world'
    np.testing.assert_allclose(back.origin, (1.0, -2.0, 0.5), atol=1e-9)


def test_malformed_grid_raises_value_error():
    from nav_msgs.msg import OccupancyGrid
    grid = OccupancyGrid()
    grid.info.width, grid.info.height, grid.info.resolution = 10, 10, 0.05
    grid.data = [0] * 99
    with pytest.raises(ValueError):
        occupancy_map_from_msg(grid)


def test_pose_with_covariance():
    cov = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, 0.003], [0.002, 0.003, 0.01]])
    loc = SimpleNamespace(pose=(1.5, -2.0, 3.0), covariance=cov)
    msg = conv.pose_with_covariance(loc, 7.25, 'map')
    assert msg.header.frame_id == 'map'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (7, 250_000_000)
    np.testing.assert_allclose(conv.pose_from_msg(msg.pose.pose), (1.5, -2.0, 3.0), atol=1e-9)
    c6 = np.array(msg.pose.covariance).reshape(6, 6)
    assert c6[0, 0] == 0.04 and c6[1, 1] == 0.09 and c6[5, 5] == 0.01
    assert c6[0, 5] == c6[5, 0] == 0.002 and c6[1, 5] == 0.003
    np.testing.assert_allclose(conv.covariance3(msg.pose.covariance), cov)
    bad = conv.pose_with_covariance(SimpleNamespace(pose=(0, 0, 0), covariance=np.full((3, 3),
                                                                                       np.nan)),
                                    0, 'map')
    assert np.all(np.isfinite(bad.pose.covariance))


def test_scan_record_to_laser_scan():
    from ssm_localization import ScanRecord
    rec = ScanRecord.from_ranges(1700000000.125, np.r_[1.0, np.inf, 2.5], -0.5, 0.25,
                                 range_min=0.1, range_max=20.0, frame_id='laser')
    msg = conv.laser_scan_from_record(rec)
    assert msg.header.frame_id == 'laser'
    assert msg.header.stamp.sec == 1700000000 and abs(msg.header.stamp.nanosec - 125e6) < 500
    assert msg.angle_max == pytest.approx(0.0)
    assert list(msg.ranges) == [1.0, math.inf, 2.5]
    assert (msg.range_min, msg.range_max) == (pytest.approx(0.1), 20.0)


def _fake_index():
    from ssm_localization.mapping.map_io import OccupancyMap
    occ = OccupancyMap(np.zeros((100, 120), np.int8), 0.05)
    gvd = np.zeros((100, 120), bool)
    gvd[50, :] = True
    return SimpleNamespace(map=occ, gvd_mask=gvd, node_xy=np.array([[1.0, 2.5], [4.0, 2.5]]),
                           node_kind=np.array(['branch', 'dead_end']))


def test_index_markers():
    index = _fake_index()
    arr = markers.marker_array(markers.index_markers(index, 'map', 0, max_gvd_points=50), 'map')
    assert arr.markers[0].action == Marker.DELETEALL
    by_ns = {}
    for m in arr.markers[1:]:
        by_ns.setdefault(m.ns, []).append(m)
    assert len(by_ns['gvd'][0].points) == 50           # subsampled from 120
    nodes = by_ns['nodes'][0]
    assert nodes.type == Marker.SPHERE_LIST and len(nodes.points) == 2
    assert nodes.colors[0] != nodes.colors[1]           # colored by kind
    assert [m.text for m in by_ns['node_ids']] == ['0', '1']
    assert all(m.type == Marker.TEXT_VIEW_FACING for m in by_ns['node_ids'])


def test_localization_markers():
    cands = [SimpleNamespace(node=i, pose=(float(i), 1.0, 0.0), score=1.0 - 0.1 * i)
             for i in range(2)]
    loc = SimpleNamespace(pose=(1.0, 1.0, math.pi / 2), candidates=cands)
    ms = markers.localization_markers(loc, 'map', 0, top_n=5,
                                      scan_xy_laser=np.array([[1.0, 0.0], [2.0, 0.0]]),
                                      laser_pose=(0.5, 0.0, 0.0),
                                      node_xy=np.array([[0.0, 0.0], [1.0, 0.0]]))
    arrows = [m for m in ms if m.ns == 'candidates']
    assert len(arrows) == 2 and arrows[0].color.g > arrows[1].color.g   # best is greenest
    scan = next(m for m in ms if m.ns == 'scan')
    np.testing.assert_allclose([(p.x, p.y) for p in scan.points], [[1.0, 2.5], [1.0, 3.5]],
                               atol=1e-9)
    failed = SimpleNamespace(pose=None, candidates=[])
    assert markers.localization_markers(failed, 'map', scan_xy_laser=np.ones((3, 2))) == []


def test_diagnostics_say_when_the_map_lies_outside_the_calibration():
    loc = SimpleNamespace(status='ok', pose=(1.0, 2.0, 0.5), confidence=0.99, score=0.9,
                          latency_ms=30.0, node=3, candidates=[1, 2], message='')
    for note in ('', resolution_warning(0.1)):
        status = localization_status('gl', '/gl', 'ready', loc, frame='map', map_note=note)
        values = {v.key: v.value for v in status.values}
        assert values['map_note'] == note and values['status'] == 'ok'
        assert status.level == DiagnosticStatus.OK     # the answer's level; the note beside it
    assert 'coarser' in resolution_warning(0.1)
