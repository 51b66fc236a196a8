"""
io/bag_reader.py, io/bag_writer.py.

Rosbag2/mcap round trip, bare .mcap files, damaged bags, missing topics.
"""
import math
import shutil
import warnings

from helpers import REPO
import numpy as np
import pytest
from ssm_localization import (BagError, iter_scans, load_map_yaml, OccupancyMap, read_bag,
                              ScanRecord, write_bag)
from ssm_localization.cli.main import main
from ssm_localization.io.bag_reader import bag_topics


def _map():
    data = np.zeros((40, 60), dtype=np.int8)
    data[0, :] = 100
    data[-1, :] = 100
    data[10:15, 20:25] = -1
    return OccupancyMap(data, 0.05, (-1.25, 2.5, 0.3))


def _scans(n=20, beams=90, negative=False):
    rng = np.random.default_rng(3)
    out = []
    for k in range(n):
        r = rng.uniform(0.2, 8.0, beams).astype(np.float32)
        r[::7] = np.inf
        if negative:
            out.append(ScanRecord.from_ranges(1700000000.0 + 0.1 * k, r, math.pi, -math.pi / beams,
                                              range_min=0.1, range_max=10.0))
        else:
            out.append(ScanRecord.from_ranges(1700000000.0 + 0.1 * k, r, -math.pi / 2,
                                              math.pi / beams, range_min=0.1, range_max=10.0,
                                              time_increment=1e-4, scan_time=0.1))
    return out


def _poses(scans, offset=0.0):
    return {s.stamp: (0.5 * i + offset, -0.25 * i, (0.3 * i) % 3 - 1.5) for i, s in
            enumerate(scans)}


@pytest.fixture
def bag(tmp_path):
    scans = _scans()
    path = write_bag(tmp_path / 'bag', map=_map(), scans=scans, ground_truth=_poses(scans),
                     odom=_poses(scans, 3.0))
    return path, scans


def _assert_scans_equal(got, want):
    assert len(got) == len(want)
    for a, b in zip(got, want):
        assert a.stamp == pytest.approx(b.stamp, abs=1e-9)
        np.testing.assert_array_equal(a.ranges, b.ranges)      # float32, inf kept
        assert a.ranges.dtype == np.float32
        for f in ('angle_min', 'angle_max', 'angle_increment', 'time_increment', 'scan_time',
                  'range_min', 'range_max'):
            assert getattr(a, f) == pytest.approx(getattr(b, f), rel=1e-6, abs=1e-7), f
        assert a.frame_id == 'laser'


def test_round_trip_all_topics(bag):
    path, scans = bag
    assert (path / 'metadata.yaml').is_file()
    data = read_bag(path)
    assert data.topic_counts == {'/map': 1, '/scan': 20, '/ground_truth': 20, '/odom': 20}
    _assert_scans_equal(data.scans, scans)
    m = _map()
    np.testing.assert_array_equal(data.map.data, m.data)
    assert data.map.resolution == 0.05 and data.map.checksum() == m.checksum()
    assert data.map.origin == pytest.approx(m.origin)
    assert data.map.frame_id == 'map'
    want_gt, want_od = _poses(scans), _poses(scans, 3.0)
    for got, want in zip(data.scans, scans):
        assert data.ground_truth_of(got) == pytest.approx(want_gt[want.stamp], abs=1e-9)
        assert data.odom[got.stamp] == pytest.approx(want_od[want.stamp], abs=1e-9)


def test_map_is_latched_and_first(bag):
    path, _ = bag
    meta = (path / 'metadata.yaml').read_text()
    assert 'durability: transient_local' in meta
    from rosbags.highlevel import AnyReader
    with AnyReader([path]) as reader:
        topics = [c.topic for c, _, _ in reader.messages()]
    assert topics[0] == '/map' and topics.count('/map') == 1


def test_bare_mcap_and_iter_scans(bag):
    path, scans = bag
    mcap = next(path.glob('*.mcap'))
    data = read_bag(mcap)
    _assert_scans_equal(data.scans, scans)
    assert len(data.ground_truth) == 20
    _assert_scans_equal(list(iter_scans(mcap)), scans)
    assert bag_topics(mcap)['/scan'] == 20


def test_negative_increment_passes_through(tmp_path):
    scans = _scans(3, negative=True)
    write_bag(tmp_path / 'neg', scans=scans)
    got = read_bag(tmp_path / 'neg').scans
    _assert_scans_equal(got, scans)
    assert got[0].angle_increment < 0 and got[0].angle_max < got[0].angle_min


def test_odometry_and_ground_truth_without_a_valid_pose_are_skipped(tmp_path):
    """A NaN odometry pose or a ground truth 1e300 m away: skipped with a warning, not fatal."""
    scans = _scans(4)
    odom, gt = _poses(scans, 3.0), _poses(scans)
    odom[scans[1].stamp] = (math.nan, 0.0, 0.0)
    gt[scans[2].stamp] = (1e300, 0.0, 0.0)
    path = write_bag(tmp_path / 'bad_poses', scans=scans, ground_truth=gt, odom=odom)
    with pytest.warns(RuntimeWarning) as caught:
        got = read_bag(path)
    text = ' '.join(str(w.message) for w in caught)
    assert '/odom: 1 message(s) with no valid pose skipped' in text
    assert '/ground_truth: 1 message(s) with no valid pose skipped' in text
    kept = sorted(s.stamp for i, s in enumerate(scans) if i != 1)
    assert len(got.scans) == 4 and sorted(got.odom) == kept
    assert len(got.ground_truth) == 3 and all(math.isfinite(p[0]) for p in got.odom.values())


def test_missing_bag(tmp_path):
    with pytest.raises(FileNotFoundError, match='nope'):
        read_bag(tmp_path / 'nope')


def test_missing_scan_topic(tmp_path, capsys):
    scans = _scans(2)
    path = write_bag(tmp_path / 'gt_only', map=_map(), ground_truth=_poses(scans))
    with pytest.raises(BagError, match=r'no /scan topic.*/ground_truth'):
        read_bag(path)
    # a BagError is a user error: the command line reports it in one line, exit status 2
    assert main(['replay', str(path), '-o', str(tmp_path / 'r.csv')]) == 2
    assert 'no /scan topic' in capsys.readouterr().err
    with pytest.raises(ValueError, match='no /laser topic'):
        list(iter_scans(path, scan_topic='/laser'))
    assert read_bag(path, require_scans=False).map is not None


def test_overwrite(bag):
    path, scans = bag
    with pytest.raises(FileExistsError):
        write_bag(path, scans=scans)
    write_bag(path, scans=scans[:3], overwrite=True)
    assert len(read_bag(path).scans) == 3


def test_truncated_bag(tmp_path):
    rng = np.random.default_rng(0)
    scans = [ScanRecord.from_ranges(10.0 + 0.1 * k, rng.uniform(1, 5, 720), -math.pi,
                                    math.pi / 360) for k in range(1500)]
    path = write_bag(tmp_path / 'big', scans=scans, compress=False)
    mcap = next(path.glob('*.mcap'))
    size = mcap.stat().st_size
    # cut in the middle: the complete chunks before the cut are read, with a warning
    cut = tmp_path / 'cut'
    shutil.copytree(path, cut)
    with open(cut / mcap.name, 'r+b') as fh:
        fh.truncate(size // 2)
    with pytest.warns(RuntimeWarning, match='truncated or corrupt'):
        data = read_bag(cut)
    assert 0 < len(data.scans) < len(scans)
    _assert_scans_equal(data.scans, scans[:len(data.scans)])
    # cut before the first complete chunk: a clear error naming the bag
    with open(cut / mcap.name, 'r+b') as fh:
        fh.truncate(100)
    with pytest.raises(ValueError, match=r'cut.*truncated or corrupt'):
        read_bag(cut)


def test_garbage_file(tmp_path):
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'not an mcap file at all' * 10)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        with pytest.raises(ValueError, match='bad.mcap'):
            read_bag(bad)
    with pytest.raises(ValueError, match='rosbag2 directory or a .mcap'):
        (tmp_path / 'x.txt').write_text('x')
        read_bag(tmp_path / 'x.txt')


COMMITTED = {
    'intel_queries': {'/map': 1, '/scan': 91, '/ground_truth': 91, '/odom': 91},
    'depot_sim': {'/map': 1, '/scan': 30, '/ground_truth': 30},
    'depot_sim_clutter': {'/map': 1, '/scan': 20, '/ground_truth': 20},
    'depot_sim_fov180': {'/map': 1, '/scan': 20, '/ground_truth': 20},
}


@pytest.mark.parametrize('name', sorted(COMMITTED))
def test_committed_bags(name):
    path = REPO / 'bags' / name
    data = read_bag(path)
    assert data.topic_counts == COMMITTED[name]
    assert data.map is not None and data.map.occupied_mask().any()
    stamps = [s.stamp for s in data.scans]
    assert np.all(np.diff(stamps) > 0)
    assert all(data.ground_truth_of(s) is not None for s in data.scans)
    for s in data.scans:
        assert s.frame_id == 'laser' and s.ranges.dtype == np.float32
        assert not np.isnan(s.ranges).any() and np.all(s.ranges > 0)
    # frames agree: scan endpoints placed at /ground_truth land on the map's occupied cells
    from scipy.ndimage import distance_transform_edt
    from ssm_localization.transforms import apply
    dist = distance_transform_edt(~data.map.occupied_mask()) * data.map.resolution
    d = []
    for s in data.scans:
        r = s.ranges.astype(float)
        a = s.beam_angles()
        ok = np.isfinite(r) & (r < 15.0)
        pts = apply(data.ground_truth_of(s), np.column_stack((r[ok] * np.cos(a[ok]),
                                                              r[ok] * np.sin(a[ok]))))
        rows, cols = data.map.world_to_cell(pts)
        inside = data.map.in_bounds(rows, cols)
        d.append(dist[rows[inside], cols[inside]])
    d = np.concatenate(d)
    assert np.median(d) <= 0.05 and np.mean(d <= 0.1) > (0.5 if 'clutter' in name else 0.9)
    if name == 'intel_queries':
        assert len(data.scans[0].ranges) == 180 and np.isinf(np.concatenate(
            [s.ranges for s in data.scans])).any()
        assert data.map.checksum() == load_map_yaml(REPO / 'maps' / 'intel.yaml').checksum()
    if name.startswith('depot'):
        fov = data.scans[0].angle_max - data.scans[0].angle_min
        assert fov == pytest.approx(math.pi if 'fov180' in name else 2 * math.pi - math.pi / 180,
                                    abs=1e-5)


@pytest.mark.parametrize('name', ['intel', 'aces', 'freiburg-079'])
def test_committed_maps(name):
    occ_map = load_map_yaml(REPO / 'maps' / f'{name}.yaml')
    assert occ_map.resolution == 0.05 and max(occ_map.shape) < 1300
    assert occ_map.occupied_mask().sum() > 5000 and occ_map.free_mask().sum() > 50000
