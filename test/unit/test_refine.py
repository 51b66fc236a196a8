"""
localization/refine.py, verify.py.

Wall-surface signed distance (exact on its half-cell lattice, interpolated between), Gauss-Newton
pose refinement with the wall offset estimated, ray-cast beam check.
"""
from __future__ import annotations

import math

from helpers import BAGS
import numpy as np
import pytest
from scipy import ndimage
from ssm_localization import simulate, SimulationConfig
from ssm_localization.localization import kernels
from ssm_localization.localization.refine import refine_pose, refine_poses, SurfaceModel
from ssm_localization.localization.verify import BeamCheck, check_beams
from ssm_localization.transforms import apply, rotation, wrap_angle

RES = 0.1


def _block_grid() -> np.ndarray:
    """20 x 20 free cells with one 4 x 6 occupied block at rows 8..11, cols 5..10."""
    occ = np.zeros((20, 20), bool)
    occ[8:12, 5:11] = True
    return occ


def _brute_signed_distance(occ: np.ndarray, g: np.ndarray) -> np.ndarray:
    """
    Return Reference: distance.

    (grid units) from grid-frame points to the union of occupied boxes (positive outside) or to the
    union of free boxes (negative inside), by brute force.
    """
    rows, cols = np.nonzero(occ)
    frows, fcols = np.nonzero(~occ)
    out = np.empty(len(g))
    for k, (x, y) in enumerate(g):
        inside = occ[int(math.floor(y)), int(math.floor(x))]
        r, c = (frows, fcols) if inside else (rows, cols)
        dx = x - np.clip(x, c, c + 1.0)
        dy = y - np.clip(y, r, r + 1.0)
        d = np.hypot(dx, dy).min()
        out[k] = -d if inside else d
    return out


@pytest.fixture(scope='module')
def surface() -> SurfaceModel:
    return SurfaceModel.from_occupancy(_block_grid(), RES, (0.0, 0.0, 0.0), 0.0)


def test_signed_distance_zero_on_cell_boundary(surface):
    # left face of the block is x = 5 cells = 0.5 m, bottom face y = 0.8 m, corner (0.5, 0.8)
    pts = np.array([[0.5, 0.95], [0.8, 0.8], [1.1, 1.0], [0.5, 0.8], [0.8, 1.2]])
    s, _, valid = surface.signed_distance(pts)
    assert valid.all()
    assert np.allclose(s, 0.0, atol=1e-6)


def test_signed_distance_sign_and_magnitude(surface):
    # free space left of the block, 0.23 m from its left face; below it 0.17 m from the bottom
    free = np.array([[0.27, 1.0], [0.8, 0.63]])
    s, grad, valid = surface.signed_distance(free)
    assert valid.all()
    assert np.allclose(s, [0.23, 0.17], atol=1e-6)
    assert np.allclose(grad, [[-1.0, 0.0], [0.0, -1.0]], atol=1e-6)   # away from the wall
    # diagonally off the corner (0.5, 0.8), on a lattice point: distance to the corner
    s, _, _ = surface.signed_distance(np.array([[0.4, 0.7]]))
    assert s[0] == pytest.approx(math.hypot(0.1, 0.1), abs=1e-6)
    # inside the block, 0.04 m behind the left face (the nearest free cell)
    s, grad, _ = surface.signed_distance(np.array([[0.54, 1.0]]))
    assert s[0] == pytest.approx(-0.04, abs=1e-6)
    assert np.allclose(grad[0], [-1.0, 0.0], atol=1e-6)   # increases towards free space


def test_signed_distance_depth_shifts_surface():
    occ = _block_grid()
    deep = SurfaceModel.from_occupancy(occ, RES, (0.0, 0.0, 0.0), 0.5)
    s, _, _ = deep.signed_distance(np.array([[0.5, 1.0], [0.55, 1.0], [0.3, 1.0]]))
    # the surface lies half a cell (0.05 m) behind the boundary: at the occupied cell centres
    assert np.allclose(s, [0.05, 0.0, 0.25], atol=1e-6)


def test_signed_distance_matches_brute_force_with_rotated_origin():
    rng = np.random.default_rng(7)
    occ = rng.random((24, 30)) < 0.12
    occ[10:14, 3:20] = True
    origin = (1.3, -0.7, 0.6)
    model = SurfaceModel.from_occupancy(occ, RES, origin, 0.0)
    g = rng.uniform([0.5, 0.5], [29.5, 23.5], (400, 2))        # grid units (col, row)
    world = g * RES @ rotation(origin[2]).T + origin[:2]
    s, grad, valid = model.signed_distance(world)
    assert valid.all()
    err = np.abs(s - _brute_signed_distance(occ, g) * RES)
    # interpolation between lattice points: exact along faces, within a quarter of a cell near
    # corners (this grid is one eighth clutter: mostly corners)
    assert err.max() < 0.25 * RES and err.mean() < 0.03 * RES
    # on the lattice itself it is exact
    lat = rng.integers(1, 47, (200, 2)) / 2.0 + 0.5
    sl, _, _ = model.signed_distance(lat * RES @ rotation(origin[2]).T + origin[:2])
    assert np.allclose(sl, _brute_signed_distance(occ, lat) * RES, atol=1e-6)
    away = np.abs(s) > 1e-3
    norm = np.linalg.norm(grad[away], axis=1)
    assert np.median(np.abs(norm - 1.0)) < 0.05     # unit length but near corners
    # the gradient is the derivative of the signed distance (central differences)
    h = 1e-5
    for axis in (0, 1):
        step = np.zeros(2)
        step[axis] = h
        sp, _, _ = model.signed_distance(world + step)
        sm, _, _ = model.signed_distance(world - step)
        fd = (sp - sm) / (2 * h)
        smooth = away & (np.abs(fd - grad[:, axis]) < 1e-3)
        assert smooth.mean() > 0.9          # only points at medial-axis kinks may differ


def test_signed_distance_off_grid_is_invalid(surface):
    s, grad, valid = surface.signed_distance(np.array([[-0.1, 1.0], [1.0, 2.05], [1.0, 1.9]]))
    assert valid.tolist() == [False, False, True]
    assert s[0] == 0.0 and s[1] == 0.0 and not grad[:2].any()


def test_surface_model_without_occupied_cells_raises():
    with pytest.raises(ValueError, match='no occupied'):
        SurfaceModel.from_occupancy(np.zeros((5, 5), bool), RES, (0.0, 0.0, 0.0))


# --------------------------------------------------------------------------- refine_pose

@pytest.fixture(scope='module')
def depot_clean():
    from ssm_localization import read_bag
    occ_map = read_bag(BAGS / 'depot_sim').map
    sim = simulate(occ_map, SimulationConfig(count=6, noise_sigma=0.0, seed=11))
    model = SurfaceModel.from_occupancy(occ_map.occupied_mask(), occ_map.resolution,
                                        occ_map.origin, 0.0)
    return occ_map, sim, model


def _laser_points(scan) -> np.ndarray:
    a = scan.beam_angles()
    ok = np.isfinite(scan.ranges)
    r = scan.ranges[ok].astype(float)
    return np.column_stack((r * np.cos(a[ok]), r * np.sin(a[ok])))


def _inlier_fraction(model: SurfaceModel, points: np.ndarray, res, distance=0.1) -> float:
    """Return the fraction of ``points`` within ``distance`` of the surface at ``res``'s pose."""
    r, _, valid = model.signed_distance(apply(res.pose, points))
    return float(np.mean(valid & (np.abs(r + (res.depth - model.depth)) < distance)))


def test_refine_pose_recovers_perturbed_pose(depot_clean):
    """3 cm / 2 deg off on clean ray-cast scans: back to < 2 mm with the default settings."""
    _, sim, model = depot_clean
    rng = np.random.default_rng(3)
    errors = []
    for scan, truth in zip(sim.scans, sim.sensor_poses):
        sign = rng.choice([-1.0, 1.0], 3)
        start = (truth[0] + 0.03 * sign[0], truth[1] - 0.03 * sign[1],
                 truth[2] + math.radians(2.0) * sign[2])
        pts = _laser_points(scan)
        res = refine_pose(model, pts, start)
        errors.append((math.hypot(res.pose[0] - truth[0], res.pose[1] - truth[1]) * 1e3,
                       math.degrees(abs(float(wrap_angle(res.pose[2] - truth[2])))),
                       _inlier_fraction(model, pts, res)))
    text = ', '.join(f'{e:.2f} mm / {a:.3f} deg' for e, a, _ in errors)
    assert max(e for e, _, _ in errors) < 2.0, text
    assert max(a for _, a, _ in errors) < 0.1, text
    assert min(f for _, _, f in errors) > 0.95, text


def test_refine_covariance_symmetric_positive_definite(depot_clean):
    _, sim, model = depot_clean
    res = refine_pose(model, _laser_points(sim.scans[0]), tuple(sim.sensor_poses[0]))
    cov = res.covariance
    assert cov.shape == (3, 3)
    assert np.allclose(cov, cov.T, rtol=1e-9, atol=1e-15)
    assert np.linalg.eigvalsh(cov).min() > 0.0


def test_refine_zero_iterations_keeps_pose(depot_clean):
    _, sim, model = depot_clean
    start = tuple(float(v) for v in sim.sensor_poses[1] + (0.02, 0.0, 0.0))
    res = refine_pose(model, _laser_points(sim.scans[1]), start, iterations=0)
    assert res.pose == pytest.approx(start)
    assert res.iterations == 0


def test_explained_is_what_refinement_reports(depot_clean):
    """``SurfaceModel.explained`` at a refined pose, its wall offset added: the result's."""
    _, sim, model = depot_clean
    pts = _laser_points(sim.scans[3])
    res = refine_pose(model, pts, tuple(sim.sensor_poses[3]), estimate_depth=True)
    got = model.explained(apply(res.pose, pts), res.depth - model.depth)
    assert 0.9 < float(got) == pytest.approx(res.explained, abs=1e-9)
    assert model.explained(pts + 1e4) == 0.0 and model.explained(np.zeros((0, 2))) == 0.0


# --------------------------------------------------------------------------- check_beams

def test_check_beams_classification():
    inf = np.inf
    expected = np.array([2.0, 2.0, 2.0, 10.0, inf, inf, 2.0, 4.0])
    measured = np.array([2.1, 2.5, 1.0, 10.3, inf, 3.0, inf, 3.95])
    # beams: ok (0.1 < 0.19), through wall (+0.5), short (-1.0), ok with rel_tol (0.3 < 0.35),
    # no return where none expected (ok), return where the map has nothing (through wall),
    # no return where a wall is (neither), ok
    c = check_beams(measured, expected, tol=0.15, rel_tol=0.02)
    assert c.consistent == pytest.approx(4 / 8)
    assert c.contradicting == pytest.approx(2 / 8)
    assert c.short == pytest.approx(1 / 8)
    assert c.score(2.0) == pytest.approx(4 / 8 - 2 * 2 / 8)
    assert c.score(1.0) == pytest.approx(4 / 8 - 2 / 8)


def test_check_beams_tolerance_edges():
    # rel_tol=0: |diff| must be strictly below tol to agree; >= tol beyond the wall contradicts
    c = check_beams(np.array([1.2, 1.25, 0.75]), np.array([1.0, 1.0, 1.0]), tol=0.25, rel_tol=0.0)
    assert c.consistent == pytest.approx(1 / 3)
    assert c.contradicting == pytest.approx(1 / 3)
    assert c.short == pytest.approx(1 / 3)


def test_check_beams_empty_and_nan_do_not_crash():
    c = check_beams(np.array([]), np.array([]))
    assert (c.consistent, c.contradicting, c.short) == (0.0, 0.0, 0.0)
    c = check_beams(np.array([np.nan, 1.0]), np.array([1.0, 1.0]))
    assert c.consistent == 0.5 and c.contradicting == 0.0 and c.short == 0.0
    assert c.score(1.0) == 0.5       # a NaN beam counts as neither agreeing nor contradicting
    assert BeamCheck(0.5, 0.25, 0.0).score(2.0) == 0.0


def test_batched_refinement_equals_single(depot_clean):
    """refine_poses (several hypotheses at once) gives each pose what refine_pose gives it."""
    _, sim, model = depot_clean
    pts = _laser_points(sim.scans[2])
    truth = sim.sensor_poses[2]
    starts = np.array([truth + (0.02, -0.01, 0.01), truth + (-0.03, 0.02, -0.02),
                       truth + (1.0, 0.5, 0.3)])
    batch = refine_poses(model, pts, starts)
    assert len(batch) == 3
    for start, got in zip(starts, batch):
        one = refine_pose(model, pts, tuple(start))
        assert got.pose == pytest.approx(one.pose, abs=1e-9)
        assert got.explained == pytest.approx(one.explained, rel=1e-9, abs=1e-12)
        assert np.allclose(got.covariance, one.covariance, rtol=1e-6, atol=1e-15)


@pytest.mark.parametrize('estimate_depth', [False, True], ids=['three_unknowns', 'with_depth'])
@pytest.mark.parametrize('origin_yaw', [0.0, 0.4], ids=['map_aligned', 'map_rotated'])
def test_compiled_refinement_is_numpy_s(depot_clean, monkeypatch, estimate_depth, origin_yaw):
    """
    The step's sums compiled (``kernels.normal_equations``) or in numpy: the same refinement.

    Hypotheses near and far from the truth, one partly off the map; the sums differ only in the
    order of their terms (float64 rounding), so the poses agree to 1e-12.
    """
    occ_map, sim, _ = depot_clean
    ox, oy, _ = occ_map.origin
    model = SurfaceModel.from_occupancy(occ_map.occupied_mask(), occ_map.resolution,
                                        (ox, oy, origin_yaw), 0.5)
    pts = _laser_points(sim.scans[4])
    truth = sim.sensor_poses[4] if origin_yaw == 0.0 else np.array([2.0, 3.0, 0.4])
    starts = np.array([truth + (0.02, -0.01, 0.01), truth + (-0.3, 0.2, -0.1),
                       truth + (1.0, 0.5, 0.3), (ox - 1.0, oy - 1.0, 0.0)])
    assert kernels.normal_equations is not None, 'numba is a requirement (requirements.txt)'
    compiled = refine_poses(model, pts, starts, estimate_depth=estimate_depth)
    monkeypatch.setattr(kernels, 'normal_equations', None)
    numpy_way = refine_poses(model, pts, starts, estimate_depth=estimate_depth)
    assert sum(r.iterations for r in compiled) > 8
    for got, want in zip(compiled, numpy_way):
        assert got.pose == pytest.approx(want.pose, abs=1e-12)
        assert got.iterations == want.iterations
        assert got.depth == pytest.approx(want.depth, abs=1e-12)
        assert got.explained == pytest.approx(want.explained, abs=1e-12)
        assert np.allclose(got.covariance, want.covariance, rtol=1e-9, atol=1e-18)


def test_the_compiled_normal_equations_equal_the_python_loop(depot_clean):
    """The loop numba compiles gives the sums of its Python source; NaN and inf points none."""
    _, sim, model = depot_clean
    pts = _laser_points(sim.scans[0])[::7]
    x = np.array([sim.sensor_poses[0] + (0.05, 0.02, 0.03), sim.sensor_poses[0]])
    delta, active = np.array([0.01, -0.02]), np.array([True, True])
    frame = np.array([*model.origin[:2], np.cos(model.origin[2]), np.sin(model.origin[2]),
                      2 / model.resolution, 2.0])
    bad = np.vstack((pts, [[np.nan, 0.0], [np.inf, 1.0], [1e300, -1e300]]))
    sums = []
    for loop, points in ((kernels.normal_equations, pts), (kernels.normal_equations_python, pts),
                         (kernels.normal_equations, bad)):
        out = (np.zeros((2, 4, 4)), np.zeros((2, 4)), np.zeros(2), np.zeros(2, np.int64))
        loop(x, delta, points, active, model.tiles, model.codes, model.values, model.cap, 32,
             frame, model.shape[0], model.shape[1], model.resolution, model.depth, 0.3, 0.1, *out)
        sums.append(out)
    assert (sums[0][3] > 10).all()
    for got, want, with_bad in zip(*sums):
        assert np.allclose(got, want, rtol=1e-12, atol=1e-15)
        assert np.array_equal(with_bad, got)


def _dense_lattice(occ: np.ndarray) -> np.ndarray:
    """Return the dense float32 signed-distance lattice (cells) by two full transforms."""
    fine = np.repeat(np.repeat(occ, 2, axis=0), 2, axis=1)
    pad_o, pad_f = np.pad(fine, 1), np.pad(~fine, 1)
    occ_v = pad_o[:-1, :-1] | pad_o[:-1, 1:] | pad_o[1:, :-1] | pad_o[1:, 1:]
    free_v = pad_f[:-1, :-1] | pad_f[:-1, 1:] | pad_f[1:, :-1] | pad_f[1:, 1:]
    outside = ndimage.distance_transform_edt(~occ_v)
    inside = ndimage.distance_transform_edt(~free_v)
    return (np.where(occ_v & free_v, 0.0, np.where(occ_v, -inside, outside)) / 2).astype(
        np.float32)


@pytest.mark.parametrize('seed', range(4))
def test_tiled_surface_is_the_dense_lattice_within_its_reach(seed):
    """Exact within the reach, clamped beyond; the explained fraction bit for bit the same."""
    rng = np.random.default_rng(seed)
    occ = np.zeros((230, 170), bool)
    occ[rng.random(occ.shape) < 0.0002] = True      # specks, open space between
    occ[40:44, 10:150] = True                       # a wall, and a thick block
    occ[120:170, 60:90] = True
    model = SurfaceModel.from_occupancy(occ, RES, (0.3, -0.2, 0.4), 0.5, reach=0.8)
    dense = _dense_lattice(occ)
    ii, jj = np.meshgrid(np.arange(dense.shape[0] - 1), np.arange(dense.shape[1] - 1),
                         indexing='ij')
    got = model.lattice_values(ii.ravel(), jj.ravel())
    want = dense[:-1, :-1].ravel()
    clamp = np.float32(math.sqrt(model.cap) / 2)
    exact = np.abs(want) < clamp
    assert np.array_equal(got[exact], want[exact])
    assert np.array_equal(np.abs(got[~exact]), np.full((~exact).sum(), clamp))
    assert (np.sign(got[~exact]) == np.sign(want[~exact])).all()
    assert model.codes.size < dense.size            # open tiles are not stored
    # an explained fraction whose sigma puts the clamp beyond exp underflow: identical
    sigma = 0.8 / 38.7
    pts = rng.uniform((-2.0, -2.0), (20.0, 26.0), (40, 500, 2))
    dense_model = SurfaceModel.from_occupancy(occ, RES, (0.3, -0.2, 0.4), 0.5, reach=40.0)
    assert np.array_equal(model.explained(pts, sigma=sigma),
                          dense_model.explained(pts, sigma=sigma))
