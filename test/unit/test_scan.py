"""Scan geometry and features, descriptors and pairwise geometry (paper II.A, eqs. 1-4)."""
from __future__ import annotations

from helpers import room_scan
import numpy as np
import pytest
from ssm_localization import MatcherConfig
from ssm_localization.matching import kernels, scan
from ssm_localization.matching.descriptors import candidates, shape_context
from ssm_localization.matching.features import prepare_scan, ScanFeatures
from ssm_localization.matching.pairwise import (affinity_matrix, angle_table, deformation,
                                                distance_table, potential)
from ssm_localization.matching.scan import (as_points, downsample_even, local_normals,
                                            ranges_to_points, robust_tangents, sweep_direction,
                                            tangents)
from ssm_localization.transforms import apply, rotation


# ---------------------------------------------------------------- ranges_to_points
def test_ranges_to_points_filters_and_keeps_index():
    r = np.array([1.0, np.nan, np.inf, 2.0, -1.0, 0.05, 30.0, 4.0, -np.inf])
    pts, idx = ranges_to_points(r, -np.pi / 2, np.pi / 8, range_min=0.1, range_max=10.0)
    assert idx.tolist() == [0, 3, 7]
    ang = -np.pi / 2 + np.pi / 8 * idx
    np.testing.assert_allclose(pts, np.column_stack((r[idx] * np.cos(ang), r[idx] * np.sin(ang))))


def test_ranges_to_points_negative_increment_is_counterclockwise():
    r = np.array([1.0, 2.0, np.nan, 3.0])
    pts, idx = ranges_to_points(r, np.pi / 2, -np.pi / 4)
    # beams at +90, +45, (0 dropped), -45 deg; returned counterclockwise: -45, +45, +90
    assert idx.tolist() == [3, 1, 0]
    np.testing.assert_allclose(np.arctan2(pts[:, 1], pts[:, 0]), np.deg2rad([-45, 45, 90]),
                               atol=1e-12)
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), [3.0, 2.0, 1.0])
    assert sweep_direction(pts) == 1.0


def test_ranges_to_points_range_limits_inclusive():
    r = np.array([0.1, 0.5, 10.0, 10.5])
    _, idx = ranges_to_points(r, 0.0, 0.1, range_min=0.1, range_max=10.0)
    assert idx.tolist() == [0, 1, 2]


def test_ranges_to_points_all_invalid_and_errors():
    pts, idx = ranges_to_points(np.full(5, np.inf), 0.0, 0.1)
    assert pts.shape == (0, 2) and idx.shape == (0,)
    pts, idx = ranges_to_points([], 0.0, 0.1)
    assert pts.shape == (0, 2)
    with pytest.raises(ValueError, match='1-D'):
        ranges_to_points(np.ones((2, 3)), 0.0, 0.1)
    with pytest.raises(ValueError, match='finite'):
        ranges_to_points(np.ones(3), np.nan, 0.1)
    with pytest.raises(ValueError, match='increment'):
        ranges_to_points(np.ones(3), 0.0, 0.0)


# ---------------------------------------------------------------- downsampling
def test_downsample_even_budget_order_and_spacing():
    pts = room_scan((0.3, 0.1, 0.2), n_beams=720)
    for budget in (50, 120, 300):
        idx = downsample_even(pts, budget)
        assert len(idx) <= budget
        assert len(idx) >= 0.6 * min(budget, len(pts))
        assert np.all(np.diff(idx) > 0)
    idx = downsample_even(pts, 100)
    sel = pts[idx]
    d = np.linalg.norm(sel[:, None] - sel[None], axis=2) + np.eye(len(sel)) * 1e9
    # spatially even: no two kept points much closer than the typical spacing
    nn = d.min(axis=1)
    assert np.percentile(nn, 5) > 0.2 * np.median(nn)


def test_downsample_even_robust_to_interleaved_outliers():
    rng = np.random.default_rng(0)
    pts = room_scan((0.0, 0.0, 0.0), n_beams=360)
    dirty = pts.copy()
    o = rng.choice(len(pts), 100, replace=False)
    dirty[o] = dirty[o][:, ::-1]
    a = pts[downsample_even(pts, 80)]
    b = dirty[downsample_even(dirty, 120)]
    b_in = b[np.linalg.norm(b[:, None] - pts[None], axis=2).min(axis=1) < 1e-9]
    # the clean part keeps a comparable density
    assert len(b_in) > 0.5 * len(a)


def test_downsample_small_inputs():
    assert downsample_even(np.zeros((0, 2)), 10).tolist() == []
    assert downsample_even(np.ones((2, 2)), 10).tolist() == [0, 1]
    assert len(downsample_even(np.ones((50, 2)), 10)) == 1     # all points identical


def test_the_compiled_voxel_selection_equals_its_source_and_numpy(monkeypatch):
    """The same indices three ways: ties (repeated points) to the lower index, any cell size."""
    assert kernels.voxel_select is not None, 'numba is a requirement (requirements.txt)'
    rng = np.random.default_rng(11)
    clouds = [room_scan((0.3, -0.2, 0.4), n_beams=360), rng.normal(0.0, 3.0, (500, 2)),
              np.repeat(rng.uniform(-2.0, 2.0, (40, 2)), 3, axis=0)[rng.permutation(120)],
              np.array([[0.25, -7.5]]), np.ones((9, 2))]
    compiled = []
    for pts in clouds:
        for cell in (0.01, 0.05, 0.137, 0.5, 3.0):
            compiled.append(scan._voxel_select(pts, cell))
            assert np.array_equal(compiled[-1], kernels.voxel_select_python(pts, cell))
    monkeypatch.setattr(kernels, 'voxel_select', None)       # scan.py's numpy form
    plain = [scan._voxel_select(pts, cell) for pts in clouds for cell in (0.01, 0.05, 0.137,
                                                                          0.5, 3.0)]
    assert all(np.array_equal(a, b) for a, b in zip(compiled, plain))
    assert [len(a) for a in plain[10:15]] != [120] * 5 and len(plain[-1]) == 1
    # the cell's point nearest its centroid is kept
    pts = np.array([[0.1, 0.1], [0.5, 0.5], [0.45, 0.52], [0.9, 0.9], [1.5, 0.2]])
    assert scan._voxel_select(pts, 1.0).tolist() == [1, 4]     # centroid (0.49, 0.51)


def test_the_compiled_pairwise_sum_is_numpys_row_sum():
    """Rows of every length to 600 (and two longer), summed as ``np.sum(axis=1)`` sums them."""
    assert kernels.pairwise_sum is not None, 'numba is a requirement (requirements.txt)'
    rng = np.random.default_rng(2)
    tasks, partial = np.empty((128, 2), np.int64), np.empty(64)
    for length in [*range(1, 601), 1000, 4099]:
        rows = rng.normal(size=(3, length)) * np.exp(4.0 * rng.normal(size=(3, length)))
        rows[rng.random(rows.shape) < 0.4] = 0.0
        want = rows.sum(axis=1)
        for r in range(3):
            assert kernels.pairwise_sum(rows[r], length, tasks, partial) == want[r], length
            if length in (1, 7, 8, 129, 600):
                assert kernels.pairwise_sum_python(rows[r], length, tasks, partial) == want[r]


def _compiled_and_numpy(name, call):
    """``call()`` with the compiled kernel ``name``, with its Python source, and with numpy."""
    compiled = getattr(kernels, name)
    assert compiled is not None, 'numba is a requirement (requirements.txt)'
    with pytest.MonkeyPatch.context() as mp:
        first = call()
        mp.setattr(kernels, name, getattr(kernels, f'{name}_python'))
        source = call()
        mp.setattr(kernels, name, None)
        plain = call()
    assert getattr(kernels, name) is compiled
    return first, source, plain


def test_the_compiled_tangents_and_descriptors_equal_numpys():
    """
    robust_tangents and shape_context: the same arrays with the compiled loops as with numpy.

    The neighbourhood sums bit for bit; a descriptor's angle is numba's ``atan2`` where numpy
    has its own, so the float64 histograms may differ in a last bit (not one of these does).
    """
    rng = np.random.default_rng(4)
    cfg = MatcherConfig()
    for k, pose in enumerate([(0.3, 0.1, 0.2), (-1.2, 0.7, 2.0), (2.0, -1.5, -1.0)]):
        pts = room_scan(pose, n_beams=360)
        if k == 2:                                   # clutter and a ragged context
            pts = np.vstack((pts, rng.uniform(-3.0, 3.0, (40, 2))))
        ctx = pts[downsample_even(pts, 4 * cfg.max_points, cfg.context_spacing)]
        sel = pts[downsample_even(pts, cfg.max_points, cfg.min_spacing)]
        three = _compiled_and_numpy('neighbourhood_moments',
                                    lambda: robust_tangents(sel, ctx, 0.3))
        assert np.array_equal(three[0], three[2]) and np.array_equal(three[1], three[2])
        u = three[0]
        w = rng.uniform(0.05, 0.3, len(ctx)) if k == 1 else None
        three = _compiled_and_numpy('shape_context_histograms',
                                    lambda: shape_context(sel, u, 1.5, 4, 12, context=ctx,
                                                          weights=w))
        assert three[0].dtype == three[2].dtype == np.float32
        assert np.array_equal(three[0], three[1]) and np.array_equal(three[0], three[2])
    # one context point only: no neighbours, the sweep direction (both ways alike)
    one = _compiled_and_numpy('neighbourhood_moments',
                              lambda: robust_tangents(sel[:5], ctx[:1], 0.3))
    assert np.array_equal(one[0], one[2]) and np.array_equal(one[1], one[2])


def test_prepare_scan_is_the_same_with_and_without_the_compiled_loops():
    """Odd inputs too (one point, repeats, a line, NaN, 1e5 and 1e-6 m): same arrays, no crash."""
    rng = np.random.default_rng(7)
    kinds = [lambda n: rng.normal(size=(n, 2)) * 5,
             lambda n: np.repeat(rng.normal(size=(max(n // 3, 1), 2)), 3, axis=0)[:n],
             lambda n: np.column_stack((np.linspace(0.0, 5.0, n), np.zeros(n))),
             lambda n: np.full((n, 2), 1.5),
             lambda n: rng.normal(size=(n, 2)) * 1e5,
             lambda n: rng.normal(size=(n, 2)) * 1e-6,
             lambda n: np.where(rng.random((n, 1)) < 0.3, np.nan, rng.normal(size=(n, 2)))]
    configs = [MatcherConfig(), MatcherConfig(max_points=10), MatcherConfig(length_cap=0.0)]
    names = ('points', 'tangents', 'descriptors', 'source_index', 'fine_points', 'fine_normals',
             'fine_weights')
    loops = ('voxel_select', 'neighbourhood_moments', 'shape_context_histograms')
    for case in range(210):
        pts = kinds[case % len(kinds)](int(rng.choice([1, 2, 3, 5, 13, 60, 400])))
        cfg, fine = configs[case % len(configs)], bool(case % 2)
        compiled = prepare_scan(pts, cfg, fine=fine)
        with pytest.MonkeyPatch.context() as mp:
            for name in loops:
                mp.setattr(kernels, name, None)
            plain = prepare_scan(pts, cfg, fine=fine)
        for name in names:
            a, b = getattr(compiled, name), getattr(plain, name)
            assert a.shape == b.shape and np.array_equal(a, b), (case, name)
    assert all(getattr(kernels, name) is not None for name in loops)


# ---------------------------------------------------------------- tangents (eq. 1)
def test_tangents_eq1_line_gap_and_ends():
    x = np.r_[np.linspace(0, 1, 6), np.linspace(3, 4, 6)]
    pts = np.column_stack((x, np.r_[np.zeros(6), np.ones(6)]))
    u = tangents(pts, gap=0.5)
    np.testing.assert_allclose(u, np.tile([1.0, 0.0], (12, 1)), atol=1e-12)
    # without the gap rule the points next to the jump would point diagonally
    u2 = tangents(pts, gap=10.0)
    assert abs(u2[5, 1]) > 0.1 and abs(u2[6, 1]) > 0.1
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0)
    np.testing.assert_allclose(tangents(pts, 0.5, direction=-1.0), -u)


def test_tangents_isolated_point_and_empty():
    pts = np.array([[1.0, 0.0], [5.0, 5.0], [0.0, 2.0]])
    u = tangents(pts, gap=0.5)
    assert np.all(np.isfinite(u))
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0)
    np.testing.assert_allclose(u[0], [0.0, 1.0], atol=1e-12)    # sweep direction (-y, x)
    assert tangents(np.zeros((0, 2)), 0.5).shape == (0, 2)


def test_robust_tangents_follow_counterclockwise_sweep():
    # a wall y = 2 swept counterclockwise: x decreases along the scan
    x = np.linspace(3, -3, 61)
    pts = np.column_stack((x, np.full_like(x, 2.0)))
    noisy = pts + np.random.default_rng(1).normal(0, 0.01, pts.shape)
    u = robust_tangents(noisy, noisy, 0.3)
    assert np.all(u[:, 0] < -0.98)
    u_eq1 = tangents(pts, 0.5)
    assert np.all(u_eq1[:, 0] < -0.99)
    assert sweep_direction(pts) == 1.0 and sweep_direction(pts[::-1]) == -1.0
    np.testing.assert_allclose(robust_tangents(pts, pts, 0.3, direction=-1.0)[:, 0], 1.0,
                               atol=1e-9)


def test_local_normals_weights():
    x = np.linspace(0, 2, 41)
    line = np.column_stack((x, np.zeros_like(x)))
    n, w = local_normals(line, 0.25)
    np.testing.assert_allclose(np.abs(n[:, 1]), 1.0, atol=1e-9)
    assert np.all(w > 0.99)
    corner = np.vstack((line, np.column_stack((np.full(20, 2.0), np.linspace(0.05, 1, 20)))))
    _, wc = local_normals(corner, 0.25)
    assert wc[40] < 0.3            # the corner point has an ill-defined normal


# ---------------------------------------------------------------- features
def test_prepare_scan_drops_nan_and_maps_indices():
    pts = room_scan((0.2, 0.0, 0.0))
    dirty = pts.copy()
    dirty[::7] = np.nan
    cfg = MatcherConfig(max_points=80)
    f = prepare_scan(dirty, cfg)
    assert 3 <= len(f) <= 80
    assert np.all(np.isfinite(dirty[f.source_index]).all(axis=1))
    np.testing.assert_array_equal(f.points, dirty[f.source_index])
    np.testing.assert_allclose(np.linalg.norm(f.tangents, axis=1), 1.0)
    assert f.descriptors.shape == (len(f), cfg.desc_radial_bins * cfg.desc_angular_bins)
    assert not f.is_degenerate
    with pytest.raises(ValueError, match='new_xy'):
        as_points(np.ones((4, 3)), 'new_xy')


def test_scan_features_roundtrip_and_validation(tmp_path):
    f = prepare_scan(room_scan((0.0, 0.5, 1.0)))
    arrays = f.to_arrays('n0_')
    np.savez(tmp_path / 'f.npz', **arrays)
    with np.load(tmp_path / 'f.npz', allow_pickle=False) as z:
        g = ScanFeatures.from_arrays(z, 'n0_')
    for name in arrays:
        np.testing.assert_array_equal(getattr(g, name[3:]), getattr(f, name[3:]))
    np.testing.assert_array_equal(g.dist, f.dist)
    bad = dict(f.to_arrays())
    del bad['descriptors']
    with pytest.raises(ValueError, match='descriptors'):
        ScanFeatures.from_arrays(bad)
    bad = dict(f.to_arrays())
    bad['tangents'] = bad['tangents'][:-1]
    with pytest.raises(ValueError, match='shape'):
        ScanFeatures.from_arrays(bad)


def test_degenerate_features():
    cfg = MatcherConfig()
    assert prepare_scan(np.zeros((0, 2)), cfg).is_degenerate
    assert prepare_scan([[1.0, 2.0], [2.0, 3.0]], cfg).is_degenerate
    x = np.linspace(-2, 2, 50)
    assert prepare_scan(np.column_stack((x, 0.5 * x + 1)), cfg).is_degenerate
    assert prepare_scan(np.full((10, 2), np.nan), cfg).is_degenerate


# ---------------------------------------------------------------- invariance
def _rigid(points, tangents_, pose):
    return apply(pose, points), tangents_ @ rotation(pose[2]).T


def test_descriptors_invariant_to_rigid_motion():
    f = prepare_scan(room_scan((0.4, -0.2, 0.3)))
    pose = (1.3, -0.7, 2.1)
    p2, u2 = _rigid(f.points, f.tangents, pose)
    d1 = shape_context(f.points, f.tangents, 2.0, 4, 8)
    d2 = shape_context(p2, u2, 2.0, 4, 8)
    np.testing.assert_allclose(d1, d2, atol=1e-5)
    assert np.abs(d1).sum() > 0
    np.testing.assert_allclose(np.linalg.norm(d1, axis=1)[np.abs(d1).sum(1) > 0], 1.0, atol=1e-5)


def test_pairwise_tables_invariant_to_rigid_motion():
    f = prepare_scan(room_scan((0.0, 0.0, 0.0)))
    p2, u2 = _rigid(f.points, f.tangents, (-2.0, 3.0, -1.2))
    np.testing.assert_allclose(distance_table(p2), distance_table(f.points), atol=1e-5)
    np.testing.assert_allclose(angle_table(u2), angle_table(f.tangents), atol=1e-3)
    d = distance_table(f.points)
    assert np.all(np.diag(d) == 0) and np.allclose(d, d.T)
    a = angle_table(f.tangents)
    assert a.min() >= 0 and a.max() <= np.pi + 1e-6


def test_deformation_and_potential_eqs_3_4():
    g = deformation(2.0, 0.5, 1.9, 0.3)
    np.testing.assert_allclose(g, [1.0, 0.01, 0.04])
    w = (2.0, -100.0, -10.0)
    np.testing.assert_allclose(potential(g, w), 1 / (1 + np.exp(-(2.0 - 1.0 - 0.4))))
    assert potential(deformation(1.0, 0.2, 1.0, 0.2), w) > potential(g, w)


def test_affinity_zeroing_rules():
    rng = np.random.default_rng(3)
    pr = rng.uniform(-3, 3, (12, 2))
    ur = rng.normal(size=(12, 2))
    ur /= np.linalg.norm(ur, axis=1)[:, None]
    pn, un = _rigid(pr, ur, (0.5, 0.2, 0.7))
    # L: correct pairs, conflicting alternatives and one grossly wrong pair
    L = np.array([[i, i] for i in range(12)] + [[0, 1], [1, 0], [2, 5], [5, 5]])
    G = affinity_matrix(distance_table(pr), angle_table(ur), distance_table(pn), angle_table(un),
                        L, (3.0, -200.0, -12.5), 0.3, 0.6)
    assert G.shape == (len(L), len(L)) and G.dtype == np.float32
    np.testing.assert_allclose(G, G.T)
    assert np.all(np.diag(G) == 0)
    for a in range(len(L)):
        for b in range(len(L)):
            if a != b and (L[a, 0] == L[b, 0] or L[a, 1] == L[b, 1]):
                assert G[a, b] == 0.0
    # consistent pairs get sigmoid(w0): no deformation
    np.testing.assert_allclose(G[0, 1], 1 / (1 + np.exp(-3.0)), rtol=1e-5)
    dd = np.abs(distance_table(pr)[2, 3] - distance_table(pn)[5, 3])
    if dd > 0.3:
        assert G[14, 3] == 0.0


def test_candidates_shape_and_identity_match():
    f = prepare_scan(room_scan((0.2, 0.3, 0.4)))
    L = candidates(f.descriptors, f.descriptors, 3)
    assert L.shape[1] == 2 and len(L) <= 3 * len(f)
    assert len(np.unique(L[:, 0] * 10000 + L[:, 1])) == len(L)
    # every point finds itself among its candidates when matched to itself
    has_self = np.zeros(len(f), bool)
    has_self[L[L[:, 0] == L[:, 1], 1]] = True
    assert has_self.mean() > 0.95
    L2 = candidates(f.descriptors, f.descriptors, 3, both_ways=True)
    assert len(L2) >= len(L)
    assert candidates(f.descriptors[:0], f.descriptors, 3).shape == (0, 2)
