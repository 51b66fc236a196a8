"""localization/localizer.py: vicinity score (eq. 10), candidate ranking, frames, statuses and
bad input."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ssm_localization import (GlobalLocalizer, IndexConfig, Localization, LocalizerConfig,
                              SimulationConfig, build_index, prepare_scan, read_bag, simulate)
from ssm_localization.localization.localizer import STATUSES, vicinity_score
from ssm_localization.mapping.map_io import OccupancyMap
from ssm_localization.matching.matcher import spectral_score
from ssm_localization.mapping.raycast import cast_rays
from ssm_localization.matching.scan import ranges_to_points
from ssm_localization.transforms import wrap_angle

from conftest import BAGS

OFFSET = (0.25, -0.12, 0.6)      # a laser mounted off-centre and turned on the base


def _err(pose, truth) -> tuple[float, float]:
    return (math.hypot(pose[0] - truth[0], pose[1] - truth[1]),
            abs(float(wrap_angle(pose[2] - truth[2]))))


def _assert_close(loc: Localization, truth, xy: float = 0.02, yaw_deg: float = 0.5) -> None:
    assert loc.status == 'ok', loc.message
    e, a = _err(loc.pose, truth)
    assert e < xy and a < math.radians(yaw_deg), (loc.pose, tuple(truth))


@pytest.fixture(scope='module')
def depot():
    bag = read_bag(BAGS / 'depot_sim')
    index = build_index(bag.map)
    return bag, index


@pytest.fixture(scope='module')
def localizer(depot):
    return GlobalLocalizer(depot[1], LocalizerConfig(surface_depth=0.0))


@pytest.fixture(scope='module')
def query(depot, localizer):
    bag, _ = depot
    s = bag.scans[0]
    pts, _ = ranges_to_points(s.ranges, s.angle_min, s.angle_increment, s.range_min, s.range_max)
    return prepare_scan(pts, localizer.matcher_config)


# --------------------------------------------------------------------------- eq. (10)

def _grid_points() -> np.ndarray:
    """Points 1 m apart: nearest neighbours never change for offsets below 0.5 m."""
    x, y = np.meshgrid(np.arange(5.0), np.arange(4.0))
    return np.column_stack((x.ravel(), y.ravel()))


def test_vicinity_identical_scans_score_4_5_per_point():
    pts = _grid_points()
    assert vicinity_score(pts, pts, (0.0, 0.0, 0.0), 0.05) == pytest.approx(4.5 * len(pts))


def test_vicinity_point_beyond_three_sigma_contributes_nothing():
    node = np.array([[0.0, 0.0], [5.0, 0.0]])
    sigma = 0.05
    assert vicinity_score(node, np.array([[0.0, 0.16]]), (0.0, 0.0, 0.0), sigma) == 0.0
    # just inside 3 sigma: the closed form 4.5 - d^2 / (2 sigma^2), small and positive
    d = 0.149
    got = vicinity_score(node, np.array([[0.0, d]]), (0.0, 0.0, 0.0), sigma)
    assert got == pytest.approx(4.5 - d ** 2 / (2 * sigma ** 2))
    assert 0.0 < got < 0.1
    # one far point among matching ones adds nothing
    both = vicinity_score(node, np.array([[5.0, 0.0], [2.5, 0.0]]), (0.0, 0.0, 0.0), sigma)
    assert both == pytest.approx(4.5)


def test_vicinity_pose_moves_query_into_node_frame():
    node = _grid_points()
    pose = (0.3, -0.2, 0.4)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    # query points such that R q + t lands exactly on the node points
    query = (node - pose[:2]) @ np.array([[c, -s], [s, c]])
    assert vicinity_score(node, query, pose, 0.05) == pytest.approx(4.5 * len(node))
    assert vicinity_score(node, query, (0.0, 0.0, 0.0), 0.05) < 4.5 * len(node)


def test_vicinity_decreases_monotonically_with_offset():
    pts = _grid_points()
    offsets = np.linspace(0.0, 0.2, 21)
    scores = [vicinity_score(pts, pts, (dx, 0.0, 0.0), 0.05) for dx in offsets]
    inside = offsets < 0.15
    assert np.all(np.diff(np.array(scores)[inside]) < 0)
    assert all(s == 0.0 for s in np.array(scores)[offsets > 0.1501])
    yaw_scores = [vicinity_score(pts, pts, (0.0, 0.0, a), 0.05) for a in (0.0, 0.005, 0.01, 0.02)]
    assert np.all(np.diff(yaw_scores) < 0)


def test_vicinity_empty_inputs():
    assert vicinity_score(np.zeros((0, 2)), _grid_points(), (0.0, 0.0, 0.0), 0.05) == 0.0
    assert vicinity_score(_grid_points(), np.zeros((0, 2)), (0.0, 0.0, 0.0), 0.05) == 0.0


# --------------------------------------------------------------------------- candidates

def test_prefilter_returns_distinct_valid_nodes(localizer, query):
    nodes = localizer.prefilter(query)
    n = len(localizer.index.features)
    assert len(nodes) == min(localizer.config.prefilter, n)
    assert len(set(int(k) for k in nodes)) == len(nodes)
    assert all(0 <= k < n for k in nodes)


def test_prefilter_disabled_and_paper_mode_keep_all_nodes(depot, query):
    index = depot[1]
    for cfg in (LocalizerConfig(prefilter=0), LocalizerConfig(paper_mode=True)):
        nodes = GlobalLocalizer(index, cfg).prefilter(query)
        assert sorted(nodes.tolist()) == list(range(len(index.features)))


def test_coarse_keeps_top_n_sorted_by_spectral_score(localizer, query):
    nodes = np.arange(0, len(localizer.index.features), 4)       # every 4th node
    hyps = localizer.coarse(query, nodes)
    assert len(hyps) == localizer.config.top_n
    spectral = [h.spectral for h in hyps]
    assert spectral == sorted(spectral, reverse=True)
    assert len({h.node for h in hyps}) == len(hyps)
    # they are the top_n of all scores, and the scores are eq. (5) of spectral_score
    everything = sorted((spectral_score(localizer.index.features[k], query,
                                        localizer.matcher_config)[0] for k in nodes),
                        reverse=True)
    assert spectral == pytest.approx(everything[:len(hyps)])


def test_coarse_with_fewer_nodes_than_top_n(localizer, query):
    hyps = localizer.coarse(query, np.array([3, 1]))
    assert sorted(h.node for h in hyps) == [1, 3]
    assert hyps[0].spectral >= hyps[1].spectral


def test_localization_result_fields(depot, localizer):
    bag, index = depot
    s = bag.scans[0]
    loc = localizer.localize_scan(s.ranges, s.angle_min, s.angle_increment, s.range_min,
                                  s.range_max)
    _assert_close(loc, bag.ground_truth[s.stamp], xy=0.01)
    assert loc.status in STATUSES and loc.ok
    assert 0 <= loc.node < len(index.features)
    assert loc.node in {h.node for h in loc.candidates}
    assert np.isfinite(loc.score) and loc.latency_ms > 0
    cov = np.asarray(loc.covariance)
    assert cov.shape == (3, 3)
    assert np.allclose(cov, cov.T, atol=1e-15)
    assert np.linalg.eigvalsh(cov).min() > 0
    assert math.sqrt(np.linalg.eigvalsh(cov[:2, :2]).max()) < 0.05   # confident: a few cm


def test_paper_mode_picks_largest_vicinity(depot):
    bag, index = depot
    s = bag.scans[1]
    loc = GlobalLocalizer(index, LocalizerConfig(paper_mode=True)).localize_scan(
        s.ranges, s.angle_min, s.angle_increment, s.range_min, s.range_max)
    assert loc.candidates
    assert loc.score == max(h.vicinity for h in loc.candidates)
    assert loc.score > 0


# --------------------------------------------------------------------------- frames

@pytest.fixture(scope='module')
def offset_sim(depot):
    bag, _ = depot
    return simulate(bag.map, SimulationConfig(count=3, sensor_offset=OFFSET, noise_sigma=0.0,
                                              seed=5))


@pytest.mark.parametrize('index_offset', [True, False], ids=['node-offset', 'node-centred'])
def test_laser_pose_offset_gives_base_pose(depot, offset_sim, index_offset):
    bag, plain = depot
    index = build_index(bag.map, IndexConfig(sensor_pose=OFFSET)) if index_offset else plain
    if index_offset:
        # Table 1: the node's virtual laser sits at (x, y, 0) composed with the sensor pose
        x, y = index.node_xy[0]
        assert np.allclose(index.node_sensor_pose[0], (x + OFFSET[0], y + OFFSET[1], OFFSET[2]))
    loc = GlobalLocalizer(index, LocalizerConfig(surface_depth=0.0, laser_pose=OFFSET))
    for scan, base, laser in zip(offset_sim.scans, offset_sim.poses, offset_sim.sensor_poses):
        out = loc.localize_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                scan.range_min, scan.range_max)
        _assert_close(out, base, xy=0.01, yaw_deg=0.2)
        assert _err(out.pose, laser)[0] > 0.2        # it is not the laser's pose
        best = next(h for h in out.candidates if h.node == out.node)
        assert _err(best.laser_pose, laser)[0] < 0.01       # the hypothesis keeps the laser pose


def test_without_laser_pose_the_answer_is_the_laser_frame(depot, offset_sim, localizer):
    scan, laser = offset_sim.scans[0], offset_sim.sensor_poses[0]
    out = localizer.localize_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                  scan.range_min, scan.range_max)
    _assert_close(out, laser, xy=0.01, yaw_deg=0.2)


def test_base_covariance_is_propagated_through_the_lever_arm(depot):
    """cov_base = J cov_laser J^T with J the derivative of base = laser * inverse(laser_pose)."""
    from ssm_localization.transforms import compose, inverse
    lp = (1.5, -0.4, 0.7)
    loc = GlobalLocalizer(depot[1], LocalizerConfig(laser_pose=lp))
    laser = (3.0, 4.0, -2.2)
    cov_laser = np.array([[4e-4, 1e-4, 2e-5], [1e-4, 9e-4, -3e-5], [2e-5, -3e-5, 1e-4]])
    h = 1e-6
    jac = np.zeros((3, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = h
        plus = np.array(compose(tuple(np.add(laser, d)), inverse(lp)))
        minus = np.array(compose(tuple(np.subtract(laser, d)), inverse(lp)))
        diff = plus - minus
        diff[2] = wrap_angle(diff[2])
        jac[:, i] = diff / (2 * h)
    got = loc._base_covariance(cov_laser, laser)
    assert np.allclose(got, jac @ cov_laser @ jac.T, rtol=1e-5, atol=1e-12)
    assert got[0, 0] > cov_laser[0, 0]             # the yaw uncertainty moves the base


# --------------------------------------------------------------------------- statuses

def _corridor() -> OccupancyMap:
    """A 40 m x 2.4 m corridor, closed at both ends, 0.05 m cells."""
    d = np.zeros((52, 804), np.int8)
    d[:2, :] = d[-2:, :] = 100
    d[:, :2] = d[:, -2:] = 100
    return OccupancyMap(d, 0.05)


def test_corridor_scan_is_never_a_confident_answer():
    corridor = _corridor()
    loc = GlobalLocalizer(build_index(corridor))
    n = 360
    angles = -math.pi + 2 * math.pi / n * np.arange(n)
    statuses = []
    for x, y, yaw in [(8.0, 1.3, 0.0), (15.3, 1.0, 0.4), (27.7, 1.6, -2.0)]:
        # 5 m range: only the two long walls are seen, never an end of the corridor
        r = cast_rays(corridor.occupied_mask(), 0.05, corridor.origin,
                      np.array([[x, y, yaw]]), angles, 5.0)[0]
        assert np.isfinite(r).sum() > 200
        out = loc.localize_scan(r, -math.pi, 2 * math.pi / n, 0.05, 5.0)
        statuses.append(out.status)
        assert out.status in ('ambiguous', 'failed'), (x, out.pose, out.message)
    assert statuses


# --------------------------------------------------------------------------- bad input

INC = 2 * math.pi / 360


@pytest.mark.parametrize('ranges, angle_min, inc, why', [
    (np.zeros(0), 0.0, INC, 'too few'),
    (np.full(360, np.inf), -math.pi, INC, 'too few'),
    (np.full(360, np.nan), -math.pi, INC, 'too few'),
    (np.full(360, -1.0), -math.pi, INC, 'too few'),
    (np.full(9, 2.0), -math.pi, INC, 'too few'),
    (np.full(360, 2.0), -math.pi, 0.0, 'angle_increment'),
    (np.full(360, 2.0), float('nan'), INC, 'finite'),
    (np.full(360, 2.0), -math.pi, float('inf'), 'finite'),
], ids=['empty', 'all-inf', 'all-nan', 'negative', 'few', 'zero-increment', 'nan-angle',
        'inf-increment'])
def test_bad_scans_fail_cleanly(localizer, ranges, angle_min, inc, why):
    out = localizer.localize_scan(ranges, angle_min, inc, 0.05, 30.0)
    assert out.status == 'failed' and not out.ok
    assert out.pose is None and out.candidates == [] and math.isnan(out.score)
    assert why in out.message
    assert out.node == -1


def test_min_points_is_configurable(depot):
    bag, index = depot
    s = bag.scans[0]
    loc = GlobalLocalizer(index, LocalizerConfig(min_points=1000))
    out = loc.localize_scan(s.ranges, s.angle_min, s.angle_increment, s.range_min, s.range_max)
    assert out.status == 'failed' and '< 1000' in out.message


def test_out_of_range_beams_are_dropped(depot, localizer):
    bag, _ = depot
    s = bag.scans[2]
    r = np.array(s.ranges, dtype=float)
    r[::3] = 500.0            # beyond range_max: no return
    r[1::7] = 0.01            # below range_min
    out = localizer.localize_scan(r, s.angle_min, s.angle_increment, s.range_min, s.range_max)
    _assert_close(out, bag.ground_truth[s.stamp])


def test_mirrored_scan_localizes_the_same(depot, localizer):
    """A scanner sweeping clockwise: reversed ranges, angle_min at the far end, negative step."""
    bag, _ = depot
    for s in bag.scans[:3]:
        n = len(s.ranges)
        a_last = s.angle_min + (n - 1) * s.angle_increment
        out = localizer.localize_scan(np.asarray(s.ranges)[::-1], a_last, -s.angle_increment,
                                      s.range_min, s.range_max)
        _assert_close(out, bag.ground_truth[s.stamp], xy=0.01)


def test_localize_points_bad_input(localizer):
    for pts in (np.zeros((0, 2)), np.full((50, 2), np.nan), np.ones((5, 2))):
        out = localizer.localize_points(pts)
        assert out.status == 'failed' and 'too few' in out.message


def test_localize_points_matches_localize_scan(depot, localizer):
    bag, _ = depot
    s = bag.scans[4]
    pts, _ = ranges_to_points(s.ranges, s.angle_min, s.angle_increment, s.range_min, s.range_max)
    _assert_close(localizer.localize_points(pts), bag.ground_truth[s.stamp], xy=0.01)


@pytest.mark.parametrize('fill', [100, -1], ids=['all-occupied', 'all-unknown'])
def test_map_without_nodes_is_rejected(fill):
    occ_map = OccupancyMap(np.full((60, 60), fill, np.int8), 0.05)
    index = build_index(occ_map)
    assert len(index.features) == 0
    with pytest.raises(ValueError, match='no nodes'):
        GlobalLocalizer(index)


def test_map_without_walls_is_rejected():
    index = build_index(OccupancyMap(np.zeros((60, 60), np.int8), 0.05))
    with pytest.raises(ValueError, match='no occupied cells'):
        GlobalLocalizer(index)


def test_config_validation():
    with pytest.raises(ValueError, match='top_n'):
        LocalizerConfig(top_n=0)
    with pytest.raises(ValueError, match='sigma_d'):
        LocalizerConfig(sigma_d=0.0)
