"""localization/correlative.py: branch-and-bound correlative search against brute force."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage
from ssm_localization.config.localization import LocalizerConfig
from ssm_localization.localization import correlative, kernels
from ssm_localization.localization.correlative import (CorrelativeGrid, likelihood_grid,
                                                       surface_cells)
from ssm_localization.localization.map_layers import search_coarsening
from ssm_localization.mapping.map_io import OccupancyMap
from ssm_localization.mapping.raycast import cast_rays
from ssm_localization.threads import in_parts

RES = 0.1


def _rooms() -> OccupancyMap:
    """Return a 6 m x 4 m walled area with an inner wall and a pillar: no symmetry."""
    d = np.zeros((40, 60), np.int8)
    d[:2, :] = d[-2:, :] = 100
    d[:, :2] = d[:, -2:] = 100
    d[2:25, 30:32] = 100
    d[28:31, 12:15] = 100
    return OccupancyMap(d, RES, (1.0, -2.0, 0.3))


@pytest.fixture(scope='module')
def grid() -> CorrelativeGrid:
    return CorrelativeGrid(_rooms(), depth=3, sigma=0.1, max_range=10.0)


def _scan_from(occ_map: OccupancyMap, pose) -> np.ndarray:
    angles = np.linspace(-math.pi, math.pi, 120, endpoint=False)
    r = cast_rays(occ_map.occupied_mask(), occ_map.resolution, occ_map.origin,
                  np.array([pose]), angles, 10.0)[0]
    # off the cell boundaries ray casting ends on, where a rounding error picks the cell
    r = r + np.random.default_rng(1).normal(0.0, 0.005, len(r))
    ok = np.isfinite(r)
    return np.column_stack((r[ok] * np.cos(angles[ok]), r[ok] * np.sin(angles[ok])))


def _cell_centre_pose(occ_map: OccupancyMap, row: int, col: int, yaw: float):
    x, y = occ_map.cell_to_world([row], [col])[0]
    return (float(x), float(y), yaw)


def _brute_force(grid: CorrelativeGrid, occ_map: OccupancyMap, pts, yaws):
    """Every free cell centre at every yaw, scored exactly as the search scores leaves."""
    rows, cols = np.nonzero(occ_map.free_mask())
    poses = np.array([_cell_centre_pose(occ_map, r, c, y) for y in yaws
                      for r, c in zip(rows, cols)])
    return poses, grid.score_poses(pts, poses)


def test_search_equals_brute_force(grid):
    occ_map = _rooms()
    yaw0 = occ_map.origin[2] + 0.4
    truth = _cell_centre_pose(occ_map, 12, 20, yaw0)
    pts = _scan_from(occ_map, truth)
    yaws = yaw0 + np.radians([-4.0, -2.0, 0.0, 2.0, 4.0])
    found = grid.search(pts, yaws=yaws, min_score=0.3, ratio=1.0)
    poses, scores = _brute_force(grid, occ_map, pts, yaws)
    assert found.complete
    assert found.best_score == pytest.approx(scores.max(), abs=1e-9)
    best = poses[np.argmax(scores)]
    assert np.allclose(found.best_pose, best, atol=1e-9)
    # the likelihood is of the cell a point falls in: ray-cast endpoints lie on cell boundaries,
    # so the best cell may be the next one (the refinement on the wall surface takes it from there)
    assert math.hypot(found.best_pose[0] - truth[0], found.best_pose[1] - truth[1]) < 1.5 * RES
    assert abs(found.best_pose[2] - truth[2]) <= math.radians(2.0) + 1e-9


def test_ratio_returns_every_leaf_within_it(grid):
    occ_map = _rooms()
    yaw0 = occ_map.origin[2]
    pts = _scan_from(occ_map, _cell_centre_pose(occ_map, 30, 45, yaw0))
    yaws = yaw0 + np.radians([0.0, 1.0])
    found = grid.search(pts, yaws=yaws, min_score=0.3, ratio=0.8, max_leaves=10 ** 6)
    _, scores = _brute_force(grid, occ_map, pts, yaws)
    expected = np.sort(scores[scores >= 0.8 * scores.max()])[::-1]
    assert len(found.scores) == len(expected)
    assert np.allclose(found.scores, expected, atol=1e-9)
    assert (np.diff(found.scores) <= 0).all()                     # best first


@pytest.mark.parametrize('depth', [1, 2, 4, 5])
def test_the_leaves_do_not_depend_on_the_depth(grid, depth):
    """The levels only bound: however many there are, the search finds the same leaves."""
    occ_map = _rooms()
    yaw0 = occ_map.origin[2] - 0.3
    pts = _scan_from(occ_map, _cell_centre_pose(occ_map, 25, 10, yaw0))
    yaws = yaw0 + np.radians([-1.0, 0.0, 1.0])
    other = CorrelativeGrid(occ_map, depth=depth, sigma=0.1, max_range=10.0)
    ref = grid.search(pts, yaws=yaws, min_score=0.3, ratio=0.75, max_leaves=10 ** 6)
    found = other.search(pts, yaws=yaws, min_score=0.3, ratio=0.75, max_leaves=10 ** 6)
    assert len(ref.scores) > 10 and ref.complete and found.complete
    assert np.array_equal(found.poses, ref.poses) and np.array_equal(found.scores, ref.scores)


@pytest.mark.parametrize('compiled', [True, False], ids=['compiled', 'numpy'])
@pytest.mark.parametrize('name, value', [
    (None, None),               # the compiled loop against numpy's passes
    ('_SCORE_CHUNK', 7),        # windows scored a chunk at a time: chunk edges change nothing
    ('_FLOAT32_EXACT', 0),      # sums as integers, not as float32 products with ones
], ids=['as_is', 'chunks', 'integer_sums'])
def test_how_windows_are_scored_changes_no_score(grid, monkeypatch, compiled, name, value):
    """
    Compiled or numpy, chunk size, the float32 product (exact below 2^24): the same leaves.

    The reference is numpy's way with its defaults; each variant scores every window again.
    """
    occ_map = _rooms()
    yaw0 = occ_map.origin[2] + 0.1
    pts = _scan_from(occ_map, _cell_centre_pose(occ_map, 15, 45, yaw0))
    yaws = yaw0 + np.radians([-1.0, 0.0, 1.0])
    with monkeypatch.context() as numpy_only:
        numpy_only.setattr(kernels, 'window_sums', None)
        whole = grid.search(pts, yaws=yaws, min_score=0.3, ratio=0.7, max_leaves=10 ** 6)
    if not compiled:
        monkeypatch.setattr(kernels, 'window_sums', None)
    if name is not None:
        monkeypatch.setattr(correlative, name, value)
    other = grid.search(pts, yaws=yaws, min_score=0.3, ratio=0.7, max_leaves=10 ** 6)
    assert len(whole.scores) > 10
    assert np.array_equal(other.poses, whole.poses)
    assert np.array_equal(other.scores, whole.scores)


@pytest.mark.parametrize('workers', [2, 3, -1])
def test_windows_scored_in_threads_give_the_same_leaves(grid, monkeypatch, workers):
    """Every compiled pass split among threads (``workers``): the same leaves, bit for bit."""
    assert kernels.window_sums is not None, 'numba is a requirement (requirements.txt)'
    occ_map = _rooms()
    yaw0 = occ_map.origin[2] + 0.1
    pts = _scan_from(occ_map, _cell_centre_pose(occ_map, 15, 45, yaw0))
    yaws = yaw0 + np.radians([-1.0, 0.0, 1.0])
    whole = grid.search(pts, yaws=yaws, min_score=0.3, ratio=0.7, max_leaves=10 ** 6)
    threaded = CorrelativeGrid(occ_map, depth=3, sigma=0.1, max_range=10.0, workers=workers)
    parts = []
    monkeypatch.setattr(correlative, '_SPLIT_LOOKUPS', 1)
    monkeypatch.setattr(correlative, 'in_parts',
                        lambda task, n, w: parts.append(w) or in_parts(task, n, w))
    other = threaded.search(pts, yaws=yaws, min_score=0.3, ratio=0.7, max_leaves=10 ** 6)
    assert parts and set(parts) == {workers}                  # every pass was split
    assert len(whole.scores) > 10
    assert np.array_equal(other.poses, whole.poses)
    assert np.array_equal(other.scores, whole.scores)


def test_small_passes_are_scored_in_the_calling_thread(grid, monkeypatch):
    """Below ``_SPLIT_LOOKUPS`` look-ups a pass is not worth a thread's start."""
    parts = []
    monkeypatch.setattr(correlative, 'in_parts',
                        lambda task, n, w: parts.append((n, w)) or in_parts(task, n, w))
    threaded = CorrelativeGrid(_rooms(), depth=3, sigma=0.1, max_range=10.0, workers=2)
    pts = _scan_from(_rooms(), _cell_centre_pose(_rooms(), 15, 45, 0.4))
    threaded.search(pts, yaws=[0.4], min_score=0.3)
    assert parts and all(w == 1 for n, w in parts if n * len(pts) < correlative._SPLIT_LOOKUPS)


def test_the_compiled_window_sums_equal_the_python_loop():
    """The loop numba compiles gives the sums of its Python source, clipping included."""
    assert kernels.window_sums is not None, 'numba is a requirement (requirements.txt)'
    rng = np.random.default_rng(5)
    grid = rng.integers(0, 256, 500).astype(np.uint8)
    base = rng.integers(-80, 80, (4, 37)).astype(np.int64)
    yaw = rng.integers(0, 4, 300).astype(np.int64)
    cell = rng.integers(-40, 540, 300).astype(np.int64)   # some indices fall off both ends
    got, want = np.empty(300, np.int32), np.empty(300, np.int32)
    kernels.window_sums(grid, base, yaw, cell, got)
    kernels.window_sums_python(grid, base, yaw, cell, want)
    clipped = np.take(grid, base[yaw] + cell[:, None], mode='clip').sum(axis=1)
    assert np.array_equal(got, want) and np.array_equal(want, clipped)
    assert ((base[yaw] + cell[:, None] < 0).any() and (base[yaw] + cell[:, None] >= 500).any())


def test_allowed_windows_pair_each_yaw_with_the_windows_of_its_regions():
    rng = np.random.default_rng(3)
    lab = rng.integers(-1, 5, 300)
    allowed = rng.random((7, 5)) < 0.3
    allowed[2] = False                                         # a yaw allowed nowhere
    k, at = correlative._allowed_windows(lab, allowed)
    want = {(y, w) for y in range(7) for w in range(300) if lab[w] >= 0 and allowed[y, lab[w]]}
    assert len(k) == len(want) and set(zip(k.tolist(), at.tolist())) == want
    assert (np.diff(k) >= 0).all()                             # yaw-major
    none = correlative._allowed_windows(np.full(4, -1), allowed)
    assert len(none[0]) == len(none[1]) == 0


def test_small_batches_find_the_same_leaves(grid):
    """A pool larger than the few batches the search works on at a time loses no leaf."""
    occ_map = _rooms()
    yaw0 = occ_map.origin[2] + 0.2
    pts = _scan_from(occ_map, _cell_centre_pose(occ_map, 20, 40, yaw0))
    yaws = yaw0 + np.radians([-1.0, 0.0, 1.0])
    whole = grid.search(pts, yaws=yaws, min_score=0.3, ratio=0.7, max_leaves=10 ** 6)
    small = grid.search(pts, yaws=yaws, min_score=0.3, ratio=0.7, max_leaves=10 ** 6, batch=3)
    _, scores = _brute_force(grid, occ_map, pts, yaws)
    assert len(small.scores) == len(whole.scores) == (scores >= 0.7 * scores.max()).sum()
    assert np.array_equal(small.poses, whole.poses) and np.array_equal(small.scores, whole.scores)


def test_window_and_yaws_restrict_the_search(grid):
    occ_map = _rooms()
    yaw0 = occ_map.origin[2] + 1.0
    truth = _cell_centre_pose(occ_map, 12, 20, yaw0)
    pts = _scan_from(occ_map, truth)
    box = (truth[0] - 0.6, truth[1] - 0.6, truth[0] + 0.6, truth[1] + 0.6)
    found = grid.search(pts, yaws=[yaw0], window=box, min_score=0.0, ratio=0.0,
                        max_leaves=10 ** 6)
    assert math.hypot(found.best_pose[0] - truth[0], found.best_pose[1] - truth[1]) < 1.5 * RES
    inside = ((found.poses[:, 0] >= box[0]) & (found.poses[:, 0] <= box[2])
              & (found.poses[:, 1] >= box[1]) & (found.poses[:, 1] <= box[3]))
    assert inside.all() and np.allclose(found.poses[:, 2], yaw0)
    far = (truth[0] + 2.0, truth[1] + 1.0, truth[0] + 2.5, truth[1] + 1.5)
    elsewhere = grid.search(pts, yaws=[yaw0], window=far, min_score=0.0)
    assert elsewhere.best_score < found.best_score


def test_levels_bound_the_leaves(grid):
    """Level k holds the maximum of level 0 over the 2^k x 2^k cells anchored at each cell."""
    t, left = grid._top, grid._left
    base = grid.level_grid(0)
    rng = np.random.default_rng(3)
    for k in range(1, grid.depth + 1):
        level = grid.level_grid(k)
        s = 1 << k
        for r, c in rng.integers(0, 40, (30, 2)):
            window = base[t + r:t + r + s, left + c:left + c + s]
            assert level[t + r, left + c] == window.max()


def test_budget_and_empty_input(grid):
    pts = _scan_from(_rooms(), _cell_centre_pose(_rooms(), 12, 20, 0.0))
    stopped = grid.search(pts, min_score=0.0, budget_s=0.0)
    assert not stopped.complete
    empty = grid.search(np.zeros((0, 2)))
    assert empty.best_pose is None and empty.best_score == 0.0 and len(empty.poses) == 0
    far = grid.search(np.array([[50.0, 0.0]]))       # beyond max_range: dropped
    assert far.best_pose is None


def test_config_validation():
    with pytest.raises(ValueError, match='depth'):
        CorrelativeGrid(_rooms(), depth=0)
    with pytest.raises(ValueError, match='sigma'):
        CorrelativeGrid(_rooms(), sigma=0.0)
    with pytest.raises(ValueError, match='workers'):
        CorrelativeGrid(_rooms(), workers=0)


def test_likelihood_grid_is_the_dense_formula():
    """The clamped, tabled likelihood: the values of the full distance transform."""
    rng = np.random.default_rng(4)
    occ = rng.random((300, 260)) < 0.001
    occ[100:104, :200] = True
    for res, sigma in ((0.05, 0.1), (0.1, 0.1), (0.02, 0.25)):
        dist = ndimage.distance_transform_edt(~occ) * res
        want = np.round(255.0 * np.exp(-0.5 * (dist / sigma) ** 2)).astype(np.uint8)
        assert np.array_equal(likelihood_grid(occ, res, sigma), want)


def test_surface_cells_are_the_occupied_cells_beside_others():
    """An occupied cell is surface when a neighbour (of 8) is not occupied, or is off the map."""
    rng = np.random.default_rng(5)
    for _ in range(50):
        occ = rng.random((int(rng.integers(1, 25)), int(rng.integers(1, 25)))) < rng.random()
        padded = np.pad(occ, 1)
        want = np.zeros_like(occ)
        for r, c in zip(*np.nonzero(occ)):
            want[r, c] = not padded[r:r + 3, c:c + 3].all()
        assert np.array_equal(surface_cells(occ), want)
    block = np.zeros((10, 12), bool)
    block[2:8, 3:10] = True
    ring = surface_cells(block)
    assert ring.sum() == 6 * 7 - 4 * 5 and not ring[3:7, 4:9].any()


def test_the_inside_of_a_solid_fits_no_scan():
    """
    Points inside a filled shape (a parked car drawn solid) score nothing; on its surface, fully.

    Scored against every occupied cell, a scan placed so that its points fall inside the shape
    would fit as well as at the right pose: the search's look-alikes on a campus's car parks.
    """
    d = np.zeros((60, 80), np.int8)
    d[:2, :] = d[-2:, :] = d[:, :2] = d[:, -2:] = 100
    d[20:40, 30:60] = 100                          # a 3 m x 2 m solid
    occ_map = OccupancyMap(d, RES, (0.0, 0.0, 0.0))
    grid = CorrelativeGrid(occ_map, depth=3, sigma=0.1, max_range=10.0)
    inside = np.array([[3.55 + 0.2 * i, 2.55 + 0.09 * j] for i in range(10) for j in range(10)])
    edge = np.array([[3.05 + 0.1 * i, 2.05] for i in range(30)])
    scores = grid.score_poses(np.vstack((inside, edge)), np.array([(0.0, 0.0, 0.0)]))
    assert grid.score_poses(inside, np.array([(0.0, 0.0, 0.0)]))[0] == 0.0
    assert grid.score_poses(edge, np.array([(0.0, 0.0, 0.0)]))[0] > 0.99
    assert 0.2 < scores[0] < 0.3


def test_free_pyramid_at_window_anchors(grid):
    """A level-k window anchored at a multiple of 2^k holds a free cell as the map says."""
    free = _rooms().free_mask()
    for k in range(grid.depth + 1):
        s = 1 << k
        for r in range(0, grid.height, s):
            for c in range(0, grid.width, s):
                assert grid._any_free(k, r, c) == free[r:r + s, c:c + s].any()


def test_points_off_the_map_score_nothing(grid):
    """Poses and points far off the map: the padding (0), never a wrapped-around map cell."""
    pts = np.array([[0.5, 0.0], [0.0, 0.5], [-0.5, 0.3]])
    far = np.array([[-30.0, 2.0, 0.0], [40.0, -1.0, 1.0], [3.0, 30.0, 2.0], [3.0, -30.0, 0.0],
                    [-9.3, -2.0, 0.0]])
    assert (grid.score_poses(pts, far) == 0.0).all()
    found = grid.search(np.array([[9.9, 0.0], [-9.9, 0.0], [0.0, 9.9], [0.0, -9.9]]),
                        yaws=[0.0, 0.7], min_score=0.0, ratio=0.0, max_leaves=10 ** 6)
    # brute force: every leaf's score from the map cells its points fall in, 0 off the map
    for pose, score in zip(found.poses[:200], found.scores[:200]):
        assert grid.score_poses(np.array([[9.9, 0.0], [-9.9, 0.0], [0.0, 9.9], [0.0, -9.9]]),
                                pose[None])[0] == pytest.approx(score)


def _two_regions():
    """Return a grid of a wall-dense region beside the rooms, its region labels and a truth."""
    d = np.zeros((64, 160), np.int8)
    d[::4, :64] = 100                                 # left: walls every 0.4 m
    d[:, ::4][:, :16] = 100
    room = _rooms().data
    d[12:52, 96:156] = room                           # right: the rooms
    occ = OccupancyMap(d, RES, (0.0, 0.0, 0.0))
    grid = CorrelativeGrid(occ, depth=3, sigma=0.1, max_range=10.0)
    truth = _cell_centre_pose(occ, 12 + 12, 96 + 20, 0.4)
    labels = np.where(np.arange(grid.free_windows().shape[1]) < 64 // 8, 0, 1)[None, :] \
        * np.ones((grid.free_windows().shape[0], 1), int)
    labels = np.where(grid.free_windows(), labels, -1)
    return occ, grid, labels, truth


def test_region_ratio_keeps_each_regions_best_place():
    """A wall-dense region scoring every scan well does not hide another region's best place."""
    occ, grid, labels, truth = _two_regions()
    pts = _scan_from(occ, truth)
    allowed = np.ones((1, 2), bool)
    found = grid.search(pts, yaws=[0.4], min_score=0.1, ratio=0.95,
                        regions=(labels, allowed), region_ratio=0.3)
    assert set(found.regions.tolist()) == {0, 1} or found.regions[0] == 1
    right = found.poses[found.regions == 1][0]
    assert math.hypot(right[0] - truth[0], right[1] - truth[1]) < 2 * RES
    # without regions the result is the plain search's, and says no regions
    plain = grid.search(pts, yaws=[0.4], min_score=0.1, ratio=0.95)
    assert plain.regions is None


def test_how_many_windows_a_step_expands_changes_no_leaf():
    """Any batch and any number of hot batches: the same leaves of a regional search."""
    occ, grid, labels, truth = _two_regions()
    pts = _scan_from(occ, truth)
    yaws = 0.4 + np.radians([-1.0, 0.0, 1.0, 90.0])
    kw = {'yaws': yaws, 'min_score': 0.1, 'ratio': 0.9, 'max_leaves': 10 ** 6,
          'regions': (labels, np.ones((4, 2), bool)), 'region_ratio': 0.3}
    first = grid.search(pts, **kw)
    assert len(first.scores) > 10 and set(first.regions.tolist()) == {0, 1}
    for batch, hot in ((3, 1), (5, 2), (64, 1), (16384, 1), (7, 9)):
        found = grid.search(pts, batch=batch, hot_batches=hot, **kw)
        assert np.array_equal(found.poses, first.poses), (batch, hot)
        assert np.array_equal(found.scores, first.scores)
        assert np.array_equal(found.regions, first.regions)
    for batch, hot in ((0, 1), (16, 0)):
        with pytest.raises(ValueError, match='batch and hot_batches'):
            grid.search(pts, batch=batch, hot_batches=hot, **kw)


def test_a_window_key_holds_its_yaw_cell_level_and_region():
    """The pool's int64 keys: each field back as packed; a child's key is its fields' key."""
    keys = correlative._WindowKeys(rows=6000, cols=7000, yaws=360, depth=4, regions=900)
    rng = np.random.default_rng(3)
    n = 1000
    k, r, c = rng.integers(0, 360, n), rng.integers(0, 6000, n), rng.integers(0, 7000, n)
    level, region = 3, rng.integers(0, 900, n)
    key = keys.pack(k, r, c, level, region)
    assert key.dtype == np.int64 and np.all(key >= 0)
    assert np.array_equal(keys.yaw(key), k) and np.array_equal(keys.row(key), r)
    assert np.array_equal(keys.col(key), c) and np.all(keys.level(key) == level)
    assert np.array_equal(keys.region(key), region)
    child = keys.children(key[:5], 4)
    dr, dc = np.tile((0, 0, 4, 4), 5), np.tile((0, 4, 0, 4), 5)
    assert np.array_equal(child, keys.pack(np.repeat(k[:5], 4), np.repeat(r[:5], 4) + dr,
                                           np.repeat(c[:5], 4) + dc, level - 1,
                                           np.repeat(region[:5], 4)))
    with pytest.raises(ValueError, match='do not fit the window keys'):
        correlative._WindowKeys(rows=1 << 30, cols=1 << 30, yaws=360, depth=4, regions=1)


def test_large_maps_are_searched_on_coarser_cells():
    """The search grid is capped: 2, 4, ... map cells a search cell, the fewest that fit."""
    cfg = LocalizerConfig(search_max_cells=8_000_000)
    assert search_coarsening(5_000_000, 0.05, cfg) == 1
    assert search_coarsening(8_000_000, 0.05, cfg) == 1
    assert search_coarsening(8_000_001, 0.05, cfg) == 2
    assert search_coarsening(27_600_000, 0.05, cfg) == 2
    assert search_coarsening(40_000_000, 0.05, cfg) == 4
    # the configured cell first, then doubled; 0 turns the cap off
    assert search_coarsening(5_000_000, 0.025, LocalizerConfig(search_cell=0.1)) == 4
    assert search_coarsening(40_000_000, 0.05, LocalizerConfig(search_max_cells=0)) == 1
    with pytest.raises(ValueError):
        LocalizerConfig(search_max_cells=-1)
