"""
Bad input that used to end in a confident wrong pose: each gets a clear error or is handled right.

Quaternions that are not unit length (map origin, poses in bags, odometry, ``initialpose``), a
map origin that is not a rotation about z, an index built from another map than the bag's,
absurd finite ranges, map cells outside -1..100 and absurd resolutions.
"""
from __future__ import annotations

import math
from types import SimpleNamespace
import warnings

from helpers import find_bag
import numpy as np
import pytest
from ssm_localization import (build_index, GlobalLocalizer, occupancy_map_from_msg,
                              OccupancyMap, read_bag, save_index, save_map_yaml, write_bag)
from ssm_localization.cli.main import main
from ssm_localization.mapping.map_io import load_map_yaml
from ssm_localization.transforms import (planar_yaw, quaternion_tilt, quaternion_to_yaw,
                                         unit_quaternion)


def _quaternion(yaw: float, scale: float = 1.0, roll: float = 0.0):
    """(x, y, z, w) of yaw then roll, times ``scale``."""
    cy, sy, cr, sr = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
    return tuple(scale * v for v in (sr * cy, sr * sy, cr * sy, cr * cy))


def _grid_msg(data, width, height, quaternion, resolution=0.05):
    x, y, z, w = quaternion
    info = SimpleNamespace(resolution=resolution, width=width, height=height,
                           origin=SimpleNamespace(position=SimpleNamespace(x=1.0, y=2.0, z=0.0),
                                                  orientation=SimpleNamespace(x=x, y=y, z=z,
                                                                              w=w)))
    return SimpleNamespace(header=SimpleNamespace(frame_id='map'), info=info, data=data)


# --------------------------------------------------------------------------- quaternions

@pytest.mark.parametrize('scale', [1.0, 2.0, 0.01, 1e3])
def test_the_yaw_of_a_quaternion_does_not_depend_on_its_length(scale):
    for yaw in (0.0, 0.5, math.pi / 2, 2.5, -3.0):
        assert quaternion_to_yaw(*_quaternion(yaw, scale)) == pytest.approx(yaw)


@pytest.mark.parametrize('q', [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, math.nan, 1.0),
                               (0.0, 0.0, math.inf, 1.0)])
def test_a_zero_or_non_finite_quaternion_is_refused(q):
    with pytest.raises(ValueError, match='not a rotation'):
        quaternion_to_yaw(*q)
    with pytest.raises(ValueError, match='not a rotation'):
        unit_quaternion(*q)


def test_tilt_and_planar_yaw():
    assert quaternion_tilt(*_quaternion(1.0, 3.0)) == pytest.approx(0.0, abs=1e-7)
    assert quaternion_tilt(*_quaternion(0.3, 2.0, roll=math.pi)) == pytest.approx(math.pi)
    assert planar_yaw(*_quaternion(0.7, 2.0)) == pytest.approx(0.7)
    with pytest.raises(ValueError, match='tilts the z axis by 180.0 deg'):
        planar_yaw(*_quaternion(0.0, 1.0, roll=math.pi), what='the origin')


def test_a_map_origin_quaternion_of_length_two_is_the_same_map():
    data = [0] * 6
    unit = occupancy_map_from_msg(_grid_msg(data, 3, 2, _quaternion(math.pi / 2)))
    double = occupancy_map_from_msg(_grid_msg(data, 3, 2, _quaternion(math.pi / 2, 2.0)))
    assert double.origin == pytest.approx((1.0, 2.0, math.pi / 2))
    assert double.checksum() == unit.checksum()


def test_a_rolled_map_origin_is_refused_not_read_as_yaw_zero():
    with pytest.raises(ValueError, match='origin orientation is not a rotation about z'):
        occupancy_map_from_msg(_grid_msg([0] * 6, 3, 2, _quaternion(0.0, 1.0, roll=math.pi)))


def test_bag_poses_with_scaled_quaternions_and_a_zero_one(tmp_path):
    """
    Ground truth in a bag: a scaled quaternion reads right, a zero one is skipped with a warning.

    One bad message of an optional topic does not refuse the bag (its scans are what counts).
    """
    bag = read_bag(find_bag('depot_sim'))
    scans = bag.scans[:3]
    truth = {s.stamp: bag.ground_truth[s.stamp] for s in scans}
    path = write_bag(tmp_path / 'b', bag.map, scans, ground_truth=truth)
    from rosbags.rosbag2 import Reader, Writer
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)

    def rewrite(dest, scale):
        with Reader(path) as rd, Writer(dest, version=8) as wr:
            conns = {c.id: wr.add_connection(c.topic, c.msgtype, typestore=store,
                                             offered_qos_profiles=c.ext.offered_qos_profiles)
                     for c in rd.connections}
            for c, t, raw in rd.messages():
                if c.topic == '/ground_truth':
                    msg = store.deserialize_cdr(raw, c.msgtype)
                    q = msg.pose.orientation
                    q.x, q.y, q.z, q.w = (v * scale for v in (q.x, q.y, q.z, q.w))
                    raw = store.serialize_cdr(msg, c.msgtype)
                wr.write(conns[c.id], t, raw)
        return dest

    scaled = read_bag(rewrite(tmp_path / 'scaled', 2.0))
    for stamp, pose in truth.items():
        assert scaled.ground_truth[stamp] == pytest.approx(pose)
    with pytest.warns(RuntimeWarning, match='/ground_truth: 3 message.s. with no valid pose '
                                            'skipped .the first: not a rotation'):
        zero = read_bag(rewrite(tmp_path / 'zero', 0.0))
    assert zero.ground_truth == {} and len(zero.scans) == 3


# --------------------------------------------------------------------------- maps

def test_map_cells_outside_the_occupancy_range_are_refused():
    with pytest.raises(ValueError, match=r'2 cells hold values outside -1 \(unknown\) .. 100 '
                                         r'\(first: 120 at row 0, column 1\)'):
        occupancy_map_from_msg(_grid_msg([0, 120, -1, 0, -7, 100], 3, 2, _quaternion(0.0)))
    # the uint8 view of an int8 grid: 255 is unknown (-1), nothing else is out of range
    ok = occupancy_map_from_msg(_grid_msg(np.array([0, 255, 100, 0], np.uint8), 2, 2,
                                          _quaternion(0.0)))
    assert ok.data.tolist() == [[0, -1], [100, 0]]
    with pytest.raises(ValueError, match='outside -1'):
        occupancy_map_from_msg(_grid_msg(np.array([0, 200, 100, 0], np.uint8), 2, 2,
                                         _quaternion(0.0)))


@pytest.mark.parametrize('resolution', [1e-9, 1e6, 0.0, -0.05, math.nan, math.inf])
def test_absurd_resolutions_are_refused_where_the_map_comes_in(resolution, tmp_path):
    with pytest.raises(ValueError, match='resolution'):
        occupancy_map_from_msg(_grid_msg([0] * 4, 2, 2, _quaternion(0.0), resolution))
    with pytest.raises(ValueError, match='resolution'):
        OccupancyMap(np.zeros((2, 2), np.int8), resolution)
    save_map_yaml(OccupancyMap(np.zeros((4, 4), np.int8), 0.05), tmp_path / 'm.yaml')
    yaml_path = tmp_path / 'm.yaml'
    text = yaml_path.read_text()
    assert 'resolution: 0.05\n' in text
    yaml_path.write_text(text.replace('resolution: 0.05\n', f'resolution: {resolution}\n'))
    with pytest.raises(ValueError, match='resolution'):
        load_map_yaml(yaml_path)


# --------------------------------------------------------------------------- scans

def test_absurd_finite_ranges_are_dropped_and_the_rest_of_the_scan_localizes():
    bag = read_bag(find_bag('depot_sim'))
    loc = GlobalLocalizer(build_index(bag.map))
    scan = bag.scans[0]
    ranges = np.array(scan.ranges, float)
    ranges[::2] = 1e30
    with warnings.catch_warnings():
        warnings.simplefilter('error', RuntimeWarning)       # no NaN cast to int anywhere
        out = loc.localize_scan(ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                                scan.range_max)
    truth = bag.ground_truth_of(scan)
    assert out.status == 'ok', out.message
    assert math.hypot(out.pose[0] - truth[0], out.pose[1] - truth[1]) < 0.05


# --------------------------------------------------------------------------- replay --index

@pytest.fixture(scope='module')
def other_index(tmp_path_factory):
    """Return an index of another map than the one in the depot bag (its mirror image)."""
    bag = read_bag(find_bag('depot_sim'))
    mirrored = OccupancyMap(bag.map.data[:, ::-1].copy(), bag.map.resolution, bag.map.origin)
    path = tmp_path_factory.mktemp('idx') / 'other.npz'
    save_index(build_index(mirrored), path)
    return path


def test_replay_refuses_an_index_of_another_map_than_the_bags(other_index, tmp_path, capsys):
    out = tmp_path / 'r.csv'
    rc = main(['replay', str(find_bag('depot_sim')), '--index', str(other_index), '-o',
               str(out), '--limit', '2', '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert "built from another map than the bag's /map" in err and '--allow-map-mismatch' in err


def test_replay_with_allow_map_mismatch_warns_and_runs(other_index, tmp_path, capsys):
    out = tmp_path / 'r.csv'
    rc = main(['replay', str(find_bag('depot_sim')), '--index', str(other_index), '-o',
               str(out), '--limit', '2', '--quiet', '--allow-map-mismatch'])
    printed = capsys.readouterr().out
    assert rc == 0 and out.is_file()
    assert 'warning: --index' in printed and "another map than the bag's /map" in printed


def test_replay_accepts_an_index_of_the_bags_own_map(tmp_path, capsys):
    bag = read_bag(find_bag('depot_sim'))
    own = tmp_path / 'own.npz'
    save_index(build_index(bag.map), own)
    rc = main(['replay', str(find_bag('depot_sim')), '--index', str(own), '-o',
               str(tmp_path / 'r.csv'), '--limit', '2', '--quiet'])
    assert rc == 0, capsys.readouterr().err
