"""io/simulate.py: simulated scans agree with ray casting, clutter, field of view, determinism."""
import math

from helpers import shared_data
import numpy as np
import pytest
from ssm_localization import (load_map_yaml, OccupancyMap, read_bag, simulate, simulate_bag,
                              SimulationConfig)
from ssm_localization.io.simulate import sample_free_poses
from ssm_localization.mapping.raycast import cast_rays


def _room():
    """Return a 10 m x 6 m room with a pillar, 0.05 m cells."""
    data = np.zeros((120, 200), dtype=np.int8)
    data[:2, :] = data[-2:, :] = 100
    data[:, :2] = data[:, -2:] = 100
    data[50:70, 90:110] = 100
    return OccupancyMap(data, 0.05, (-1.0, -2.0, 0.0))


@pytest.fixture(scope='module')
def room():
    return _room()


def test_ranges_match_ray_casting(room):
    cfg = SimulationConfig(count=20, noise_sigma=0.01, seed=4)
    sim = simulate(room, cfg)
    assert len(sim.scans) == 20 and sim.poses.shape == (20, 3)
    np.testing.assert_allclose(sim.sensor_poses, sim.poses)            # no sensor offset
    angles = sim.scans[0].beam_angles()
    truth = cast_rays(room.occupied_mask(), room.resolution, room.origin, sim.poses, angles,
                      cfg.max_range)
    got = np.array([s.ranges for s in sim.scans], dtype=float)
    assert np.all(np.isfinite(truth))                                   # closed room
    err = got - truth
    assert abs(err.mean()) < 0.002 and 0.008 < err.std() < 0.012
    assert np.abs(err).max() < 0.06


def test_poses_have_clearance(room):
    from scipy.ndimage import distance_transform_edt
    poses = sample_free_poses(room, 500, 0.3, np.random.default_rng(0))
    dist = distance_transform_edt(room.free_mask()) * room.resolution
    rows, cols = room.world_to_cell(poses[:, :2])
    assert np.all(dist[rows, cols] >= 0.3)
    assert poses[:, 2].min() < -2.5 and poses[:, 2].max() > 2.5
    with pytest.raises(ValueError, match='clearance'):
        sample_free_poses(room, 5, 5.0, np.random.default_rng(0))


def test_clutter_shortens_beams(room):
    clean = simulate(room, SimulationConfig(count=10, noise_sigma=0.0, seed=1))
    clut = simulate(room, SimulationConfig(count=10, noise_sigma=0.0, seed=1, clutter=8))
    np.testing.assert_array_equal(clean.poses, clut.poses)            # same poses per seed
    a = np.array([s.ranges for s in clean.scans])
    b = np.array([s.ranges for s in clut.scans])
    assert np.all(b <= a + 1e-6)
    shorter = b < a - 1e-3
    assert 0.02 < shorter.mean() < 0.6
    assert np.all(b[shorter] >= 1.0 - 0.3 - 1e-3) and np.all(b[shorter] <= 4.0)
    short = simulate(room, SimulationConfig(count=10, noise_sigma=0.0, seed=1,
                                            short_fraction=0.1))
    c = np.array([s.ranges for s in short.scans])
    assert 0.05 < np.mean(c < a - 1e-3) < 0.15 and np.all(c >= short.config.range_min)


def test_field_of_view(room):
    sim = simulate(room, SimulationConfig(count=2, beams=181, fov_deg=180.0))
    s = sim.scans[0]
    assert s.angle_min == pytest.approx(-math.pi / 2) and s.angle_max == pytest.approx(math.pi / 2)
    assert s.angle_increment == pytest.approx(math.pi / 180) and len(s.ranges) == 181
    full = simulate(room, SimulationConfig(count=2, beams=360)).scans[0]
    assert full.angle_min == pytest.approx(-math.pi)
    assert full.angle_max == pytest.approx(math.pi - 2 * math.pi / 360)
    sim = simulate(room, SimulationConfig(count=3, beams=100, fov_deg=90.0, clutter=5))
    assert sim.scans[0].beam_angles().max() == pytest.approx(math.pi / 4)


def test_seed_determinism(room):
    cfg = SimulationConfig(count=5, clutter=3, short_fraction=0.05, seed=7)
    a, b = simulate(room, cfg), simulate(room, cfg)
    c = simulate(room, SimulationConfig(count=5, clutter=3, short_fraction=0.05, seed=8))
    np.testing.assert_array_equal(a.poses, b.poses)
    for x, y in zip(a.scans, b.scans):
        np.testing.assert_array_equal(x.ranges, y.ranges)
    assert not np.array_equal(a.poses, c.poses)


def test_sensor_offset(room):
    sim = simulate(room, SimulationConfig(count=4, sensor_offset=(0.2, 0.0, math.pi), seed=2))
    p, q = sim.poses[0], sim.sensor_poses[0]
    assert q[0] == pytest.approx(p[0] + 0.2 * math.cos(p[2]))
    assert abs(math.remainder(q[2] - p[2] - math.pi, 2 * math.pi)) < 1e-9


def test_bad_config(room):
    for bad in ({'fov_deg': 0.0}, {'count': 0}, {'short_fraction': 2.0}, {'beams': 1}):
        with pytest.raises(ValueError):
            simulate(room, SimulationConfig(**bad))


def test_bag_on_depot(tmp_path):
    occ_map = load_map_yaml(shared_data('maps', 'depot.yaml'))
    sim = simulate_bag(occ_map, tmp_path / 'sim', SimulationConfig(count=5, seed=3))
    data = read_bag(tmp_path / 'sim')
    assert data.topic_counts == {'/map': 1, '/scan': 5, '/ground_truth': 5}
    assert data.map.checksum() == occ_map.checksum()
    for s, p in zip(data.scans, sim.poses):
        assert data.ground_truth_of(s) == pytest.approx(tuple(p), abs=1e-9)
