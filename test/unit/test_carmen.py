"""
io/carmen.py and mapping/grid.py.

Parsing the shared CARMEN logs, map building, conversion to map + bag.
"""

from helpers import shared_data
import numpy as np
import pytest
from ssm_localization import load_map_yaml, MapBuildConfig, read_bag
from ssm_localization.io import carmen
from ssm_localization.mapping.grid import build_occupancy_grid
from ssm_localization.transforms import compose, inverse

LOGS = {'intel': 910, 'aces': 440, 'freiburg-079': 4791}
NO_RETURN = {'intel': 81.83, 'aces': 50.0, 'freiburg-079': 81.91}


def _log_path(name):
    return shared_data('carmen', f'{name}-corrected.log.gz')


@pytest.fixture(scope='module')
def intel():
    return carmen.read_carmen_log(_log_path('intel'))


@pytest.mark.parametrize('name', sorted(LOGS))
def test_parse_counts_and_no_return(name):
    log = carmen.read_carmen_log(_log_path(name))
    beams = 360 if name == 'freiburg-079' else 180
    assert len(log) == LOGS[name] and log.ranges.shape == (LOGS[name], beams)
    assert log.max_range == NO_RETURN[name]
    finite = log.ranges[np.isfinite(log.ranges)]
    assert np.isinf(log.ranges).any() and np.all(finite < log.max_range)
    assert log.angle_min == -np.pi / 2 and log.angle_increment == pytest.approx(np.pi / beams)
    assert log.odometry.shape == (LOGS[name], 3)


def test_odometry_is_raw_and_consistent(intel):
    """Rebuilt odometry drifts away from the corrected poses but its increments track them."""
    odo, gt = intel.odometry, intel.poses
    assert np.linalg.norm(odo[-1, :2] - gt[-1, :2]) > 1.0           # not the corrected pose
    step = [np.hypot(*compose(inverse(odo[k]), odo[k + 1])[:2])
            - np.hypot(*compose(inverse(gt[k]), gt[k + 1])[:2]) for k in range(len(odo) - 1)]
    assert np.median(np.abs(step)) < 0.05


def test_malformed_log(tmp_path):
    bad = tmp_path / 'bad.log'
    bad.write_text('FLASER 3 1.0 2.0\n')
    with pytest.raises(ValueError, match='bad.log:1'):
        carmen.read_carmen_log(bad)
    with pytest.raises(FileNotFoundError):
        carmen.read_carmen_log(tmp_path / 'none.log')


def test_a_log_of_more_readings_than_the_package_reads_is_refused(tmp_path, monkeypatch):
    """A few MB of gzip can expand to a million scans: the readings are counted as they come."""
    line = 'FLASER 4 1.0 2.0 3.0 4.0 0 0 0 0 0 0 1.5 host 1.5\n'
    path = tmp_path / 'long.log'
    path.write_text(line * 40)
    monkeypatch.setattr(carmen, 'MAX_LOG_READINGS', 100)
    with pytest.raises(ValueError, match=r'long.log:26: more than 100 range readings'):
        carmen.read_carmen_log(path)
    path.write_text(line * 25)
    assert len(carmen.read_carmen_log(path)) == 25


def test_select_scans():
    np.testing.assert_array_equal(carmen.select_scans(10, 'even'), [0, 2, 4, 6, 8])
    np.testing.assert_array_equal(carmen.select_scans(10, 'odd', every=2), [1, 5, 9])
    np.testing.assert_array_equal(carmen.select_scans(10, 'all', first=3, last=7, max_scans=2),
                                  [3, 4])
    with pytest.raises(ValueError):
        carmen.select_scans(10, 'third')


def test_monotonic_stamps(intel):
    assert (np.diff(intel.stamps) < 0).sum() == 4                   # the README quirk
    fixed = carmen.monotonic_stamps(intel.stamps)
    assert np.all(np.diff(fixed) > 0)
    assert np.count_nonzero(fixed != intel.stamps) == 4


def test_grid_of_a_synthetic_room():
    """Four walls seen from the centre of a 4 m x 4 m room come out occupied, inside free."""
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    c, s = np.abs(np.cos(angles)), np.abs(np.sin(angles))
    ranges = 2.0 / np.maximum(c, s)
    data, origin = build_occupancy_grid(ranges[None], np.zeros((1, 3)), angles,
                                        MapBuildConfig(resolution=0.1, margin=0.5))
    assert origin[0] == pytest.approx(-2.5) and data.shape == (50, 50)
    assert data[25, 25] == 0 and data[25, 5] == 100 and data[5, 25] == 100
    assert data[0, 0] == -1
    assert (data == 100).sum() == pytest.approx(4 * 40, rel=0.1)


def test_intel_map_fits_odd_scans(intel):
    """
    The map from the even scans is sharp.

    Odd scans' endpoints land on its occupied cells, and better with -pi/2 + i pi/n than with -pi/2
    + i pi/(n-1).
    """
    n = intel.ranges.shape[1]
    even, odd = carmen.select_scans(len(intel), 'even'), carmen.select_scans(len(intel), 'odd')
    fits = {}
    for inc in (np.pi / n, np.pi / (n - 1)):
        angles = -np.pi / 2 + inc * np.arange(n)
        occ_map = carmen.build_map(intel, even, beam_angles=angles)
        d = carmen.endpoint_fit(occ_map, intel, odd, beam_angles=angles)
        fits[inc] = d[np.isfinite(d)]
    good = fits[np.pi / n]
    assert np.median(good) <= 0.05 and np.mean(good <= 0.05) > 0.9
    assert good.mean() < fits[np.pi / (n - 1)].mean()


def test_convert_intel(tmp_path):
    res = carmen.convert_carmen(_log_path('intel'), tmp_path, every=25, first=0, last=400)
    assert res.map_yaml == tmp_path / 'intel.yaml' and (tmp_path / 'intel.pgm').is_file()
    assert res.map_scans == 200 and res.query_scans == 8
    occ_map = load_map_yaml(res.map_yaml)
    data = read_bag(res.bag)
    assert data.topic_counts == {'/map': 1, '/scan': 8, '/ground_truth': 8, '/odom': 8}
    assert data.map.checksum() == occ_map.checksum()
    log = carmen.read_carmen_log(_log_path('intel'))
    s = data.scans[0]
    assert s.angle_min == pytest.approx(-np.pi / 2) and len(s.ranges) == 180
    assert s.angle_increment == pytest.approx(np.pi / 180)
    assert s.angle_max == pytest.approx(-np.pi / 2 + 179 * np.pi / 180)
    assert s.range_max == pytest.approx(81.83) and s.frame_id == 'laser'
    np.testing.assert_array_equal(s.ranges, log.ranges[1].astype(np.float32))   # scan 1: odd
    assert data.ground_truth_of(s) == pytest.approx(tuple(log.poses[1]), abs=1e-9)
    assert data.odom[s.stamp] == pytest.approx(tuple(log.odometry[1]), abs=1e-9)
    with pytest.raises(FileExistsError):
        carmen.convert_carmen(_log_path('intel'), tmp_path, every=25, last=400)


def test_failed_map_write_keeps_the_old_bag(tmp_path, monkeypatch):
    """Bag and map are one transaction: overwriting fails whole when the map cannot be saved."""
    res = carmen.convert_carmen(_log_path('intel'), tmp_path, every=50, first=0, last=200)
    before = sorted((p.relative_to(res.bag), p.read_bytes()) for p in res.bag.rglob('*')
                    if p.is_file())

    def fail(*_args, **_kwargs):
        raise ValueError('map file: cannot write (disk full)')

    monkeypatch.setattr(carmen, 'save_map_yaml', fail)
    with pytest.raises(ValueError, match='disk full'):
        carmen.convert_carmen(_log_path('intel'), tmp_path, every=25, first=0, last=400,
                              overwrite=True)
    after = sorted((p.relative_to(res.bag), p.read_bytes()) for p in res.bag.rglob('*')
                   if p.is_file())
    assert after == before and len(read_bag(res.bag).scans) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ['intel.pgm', 'intel.yaml',
                                                          'intel_queries']


def test_odometry_without_reset_lines(tmp_path):
    """A log whose ODOM lines are plain raw odometry: increments chain from scan to scan."""
    log = tmp_path / 'raw.log'
    log.write_text('ODOM 0 0 0 0 0 0 0.5 h 0.5\n'
                   'FLASER 3 1.0 2.0 9.0 0 0 0 0 0 0 1.0 h 1.0\n'
                   'ODOM 1 0 0 0 0 0 1.5 h 1.5\nODOM 2 0 0.5 0 0 0 1.6 h 1.6\n'
                   'FLASER 3 1.0 2.0 9.0 5 5 0 5 5 0 2.0 h 2.0\n'
                   'ODOM 3 0 0.5 0 0 0 2.5 h 2.5\n'
                   'FLASER 3 1.0 2.0 9.0 5 5 0 5 5 0 3.0 h 3.0\n')
    parsed = carmen.read_carmen_log(log, max_range=9.0)
    np.testing.assert_allclose(parsed.odometry, [[0, 0, 0], [2, 0, 0.5], [3, 0, 0.5]], atol=1e-12)
    assert np.isinf(parsed.ranges[:, 2]).all() and parsed.ranges[0, 0] == 1.0
