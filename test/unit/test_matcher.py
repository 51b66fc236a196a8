"""Spectral scan matching end to end (paper II.B-C) and its building blocks."""
from __future__ import annotations

import math

from helpers import pose_error, room_scan, shared_data
import numpy as np
import pytest
from ssm_localization import (match_features, match_scans, MatcherConfig, MatchResult,
                              prepare_scan, read_carmen_log)
from ssm_localization.matching.matcher import spectral_score
from ssm_localization.matching.ransac import (icp_point_to_line, procrustes, ransac_pose,
                                              two_point_poses)
from ssm_localization.matching.scan import ranges_to_points
from ssm_localization.matching.spectral import binarize, leading_eigenvector, matching_score
from ssm_localization.transforms import apply, compose, inverse


def _perturb(ref, rng, sigma=0.01, n_out=60, max_xy=0.4, max_yaw=np.deg2rad(30)):
    """Paper V.A: noise, swapped-x/y outliers, then a random pose; returns (new, truth)."""
    new = ref + rng.normal(0, sigma, ref.shape)
    idx = rng.choice(len(ref), n_out, replace=False)
    new[idx] = new[idx][:, ::-1]
    truth = (rng.uniform(-max_xy, max_xy), rng.uniform(-max_xy, max_xy),
             rng.uniform(-max_yaw, max_yaw))
    return apply(inverse(truth), new), truth


# ---------------------------------------------------------------- public API
def test_public_exports():
    import ssm_localization
    assert ssm_localization.match_scans is match_scans
    assert ssm_localization.MatcherConfig is MatcherConfig
    assert ssm_localization.MatchResult is MatchResult


def test_config_validation():
    with pytest.raises(ValueError):
        MatcherConfig(max_points=2)
    with pytest.raises(ValueError):
        MatcherConfig(k_candidates=0)
    with pytest.raises(ValueError):
        MatcherConfig(weights=(1.0, 2.0))
    with pytest.raises(ValueError):
        MatcherConfig(tangent_method='spline')
    for field, value, why in (('min_spacing', -1.0, '> 0'), ('icp_max_dist', float('nan'), '> 0'),
                              ('length_cap', -0.1, '>= 0'), ('ransac_iterations', 0, '>= 1'),
                              ('weights', (float('inf'), 1.0, 1.0), 'finite')):
        with pytest.raises(ValueError, match=f'MatcherConfig.{field} must .*{why}'):
            MatcherConfig(**{field: value})
    assert MatcherConfig(length_cap=0.0, retries=0, icp_min_spacing=0.0).retries == 0
    with pytest.raises(Exception):
        MatcherConfig().max_points = 5      # frozen


# ---------------------------------------------------------------- synthetic scans
@pytest.mark.parametrize('truth', [(0.3, -0.25, 0.5), (-0.4, 0.35, -0.52), (0.05, 0.1, 3.0)])
def test_known_transform_same_scan_synthetic(truth):
    ref = room_scan((0.2, 0.1, 0.0))
    new = apply(inverse(truth), ref)
    res = match_scans(ref, new)
    assert res.ok
    dxy, dth = pose_error(res.pose, truth)
    assert dxy < 1e-3 and dth < 1e-4
    # pairs index the caller's arrays; the two voxel downsamplings need not pick the very same
    # points, but inliers pair neighbouring points of the same scan
    assert res.pairs.shape[1] == 2 and res.pairs.dtype.kind == 'i'
    assert np.mean(np.abs(res.inliers[:, 0] - res.inliers[:, 1]) <= 2) > 0.9
    assert res.score > 0


def test_known_transform_different_viewpoints_synthetic():
    rng = np.random.default_rng(5)
    for _ in range(5):
        p_ref = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi))
        p_new = compose(p_ref, (rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4),
                                rng.uniform(-0.5, 0.5)))
        ref = room_scan(p_ref, noise=0.01, rng=rng)
        new = room_scan(p_new, noise=0.01, rng=rng)
        res = match_scans(ref, new)
        dxy, dth = pose_error(res.pose, compose(inverse(p_ref), p_new))
        assert res.ok and dxy < 0.03 and dth < np.deg2rad(0.5), (dxy, dth)


def test_half_fov_scan_against_full_scan():
    ref = room_scan((0.0, 0.0, 0.0))
    p_new = (0.3, -0.2, 0.8)
    new = room_scan(p_new, n_beams=180, fov=np.pi)
    res = match_scans(ref, new)
    dxy, dth = pose_error(res.pose, p_new)
    assert dxy < 0.03 and dth < np.deg2rad(0.5)


def test_clockwise_scan_order_is_handled():
    ref = room_scan((0.0, 0.0, 0.0))
    truth = (0.2, 0.1, 0.3)
    new = apply(inverse(truth), ref)[::-1]          # a clockwise scanner
    res = match_scans(ref, new)
    dxy, dth = pose_error(res.pose, truth)
    assert dxy < 0.01 and dth < 1e-3


def test_nan_rows_are_skipped_and_indices_refer_to_input():
    ref = room_scan((0.0, 0.0, 0.0))
    truth = (0.1, -0.2, 0.4)
    new = apply(inverse(truth), ref)
    new[::5] = np.nan
    res = match_scans(ref, new)
    assert res.ok
    assert np.all(np.isfinite(new[res.pairs[:, 1]]))
    assert res.pairs[:, 0].max() < len(ref) and res.pairs[:, 1].max() < len(new)
    assert pose_error(res.pose, truth)[0] < 0.01


def test_deterministic_with_seed():
    rng = np.random.default_rng(2)
    ref = room_scan((0.0, 0.0, 0.0), noise=0.01, rng=rng)
    new, _ = _perturb(ref, rng, n_out=60)
    a = match_scans(ref, new, MatcherConfig(seed=3))
    b = match_scans(ref, new, MatcherConfig(seed=3))
    assert a.pose == b.pose
    np.testing.assert_array_equal(a.pairs, b.pairs)


def test_spectral_score_prefers_the_same_place():
    cfg = MatcherConfig()
    q = prepare_scan(room_scan((0.5, 0.5, 0.3)), cfg)
    same = prepare_scan(room_scan((0.6, 0.4, -0.2)), cfg)
    other = prepare_scan(room_scan((0.0, 0.0, 0.0))[:60] * [1.0, -1.3] + [5, 1], cfg)
    s_same, pairs = spectral_score(same, q, cfg)
    s_other, _ = spectral_score(other, q, cfg)
    assert s_same > s_other > 0
    assert pairs.shape[1] == 2 and len(pairs) > 10


# ---------------------------------------------------------------- real CARMEN scans
@pytest.mark.parametrize('name,k', [('intel', 300),
                                    pytest.param('freiburg-079', 1000, marks=pytest.mark.slow)])
def test_table2_protocol_on_real_scans(name, k):
    ref = read_carmen_log(shared_data('carmen', f'{name}-corrected.log.gz')).points(k)
    rng = np.random.default_rng(11)
    for _ in range(8):
        new, truth = _perturb(ref, rng)
        res = match_scans(ref, new)
        dxy, dth = pose_error(res.pose, truth)
        assert res.ok and dxy < 0.01 and dth < np.deg2rad(0.2), (dxy, np.rad2deg(dth))


@pytest.mark.slow
def test_real_consecutive_pairs_freiburg():
    log = read_carmen_log(shared_data('carmen', 'freiburg-079-corrected.log.gz'))
    rng = np.random.default_rng(4)
    ok = 0
    ks = rng.choice(len(log) - 3, 10, replace=False)
    for k in ks:
        truth = compose(inverse(tuple(log.poses[k])), tuple(log.poses[k + 3]))
        res = match_scans(log.points(k), log.points(k + 3))
        dxy, dth = pose_error(res.pose, truth)
        ok += dxy < 0.15 and dth < np.deg2rad(3)
    assert ok >= 9


# ---------------------------------------------------------------- spectral step
def test_leading_eigenvector_matches_eigh():
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 1, (40, 40))
    G = ((a + a.T) / 2).astype(np.float32)
    np.fill_diagonal(G, 0)
    x = leading_eigenvector(G, iters=200, tol=1e-7)
    w, v = np.linalg.eigh(G.astype(float))
    np.testing.assert_allclose(x, np.abs(v[:, -1]), atol=1e-4)
    assert np.all(x >= 0)
    assert leading_eigenvector(np.zeros((0, 0), np.float32)).shape == (0,)
    assert np.all(leading_eigenvector(np.zeros((3, 3), np.float32)) == 0)


def test_binarize_never_returns_conflicting_pairs():
    rng = np.random.default_rng(1)
    for _ in range(200):
        n = int(rng.integers(1, 60))
        L = np.unique(rng.integers(0, 8, (n, 2)), axis=0)
        x = rng.uniform(0, 1, len(L))
        x[rng.uniform(size=len(L)) < 0.2] = 0.0
        sel = binarize(x, L)
        q = L[sel]
        assert len(np.unique(q[:, 0])) == len(q)
        assert len(np.unique(q[:, 1])) == len(q)
        assert np.all(x[sel] > 0)
        # greedy: the first pick is the argmax; every unpicked positive pair conflicts
        if np.any(x > 0):
            assert sel[0] == np.argmax(x)
            free = np.ones(len(L), bool)
            free[sel] = False
            for a in np.flatnonzero(free & (x > 0)):
                assert L[a, 0] in q[:, 0] or L[a, 1] in q[:, 1]


def test_binarize_min_ratio_and_score():
    L = np.array([[0, 0], [1, 1], [2, 2]])
    x = np.array([1.0, 0.5, 0.01])
    assert binarize(x, L, 0.1).tolist() == [0, 1]
    G = np.array([[0, 2, 1], [2, 0, 3], [1, 3, 0]], np.float32)
    assert matching_score(G, np.array([0, 1])) == 4.0
    assert matching_score(G, np.array([], int)) == 0.0


# ---------------------------------------------------------------- pose estimation
def test_two_point_poses_and_procrustes_exact():
    rng = np.random.default_rng(2)
    truth = np.array([0.7, -1.1, 2.5])
    new = rng.uniform(-5, 5, (30, 2))
    ref = apply(tuple(truth), new)
    poses = two_point_poses(ref[:10], new[:10], ref[10:20], new[10:20])
    np.testing.assert_allclose(poses, np.tile(truth, (10, 1)), atol=1e-9)
    np.testing.assert_allclose(procrustes(ref, new), truth, atol=1e-9)
    with pytest.raises(ValueError):
        procrustes(ref[:1], new[:1])


def test_ransac_recovers_pose_with_half_outliers():
    rng = np.random.default_rng(3)
    truth = (0.3, -0.2, 0.6)
    new = rng.uniform(-5, 5, (100, 2))
    ref = apply(truth, new) + rng.normal(0, 0.005, (100, 2))
    bad = rng.permutation(100)[:50]
    ref[bad] = rng.uniform(-5, 5, (50, 2))
    pose, mask = ransac_pose(ref, new, 0.05, 200, np.random.default_rng(0))
    dxy, dth = pose_error(pose, truth)
    assert dxy < 0.005 and dth < 1e-3
    truth_mask = np.ones(100, bool)
    truth_mask[bad] = False
    assert np.all(mask[truth_mask])
    assert mask.sum() <= 52
    # degenerate: too few correspondences
    assert ransac_pose(ref[:1], new[:1], 0.05, 10, np.random.default_rng(0))[0] is None


def test_icp_converges_from_offset():
    cfg = MatcherConfig()
    ref = prepare_scan(room_scan((0.0, 0.0, 0.0), noise=0.005), cfg)
    truth = (0.2, 0.1, 0.2)
    new = prepare_scan(room_scan(truth, noise=0.005, rng=np.random.default_rng(7)), cfg)
    start = compose(truth, (0.08, -0.06, np.deg2rad(3)))
    pose, used, rms = icp_point_to_line(ref.fine_points, ref.fine_normals, new.fine_points,
                                        start, 20, 0.3, 0.05, ref.fine_weights)
    dxy, dth = pose_error(pose, truth)
    assert dxy < 0.01 and dth < np.deg2rad(0.2)
    assert used > 50 and rms < 0.02


# ---------------------------------------------------------------- degenerate inputs
def _assert_empty(res):
    assert isinstance(res, MatchResult)
    assert not res.ok
    assert all(math.isnan(v) for v in res.pose)
    assert res.pairs.shape == (0, 2) and res.inliers.shape == (0, 2)
    assert res.message


def test_degenerate_inputs_give_empty_result():
    ref = room_scan((0.0, 0.0, 0.0))
    _assert_empty(match_scans(ref, ref[:2]))
    _assert_empty(match_scans(ref[:2], ref))
    _assert_empty(match_scans(np.zeros((0, 2)), ref))
    _assert_empty(match_scans(ref, []))
    pts, _ = ranges_to_points(np.full(360, np.inf), -np.pi, np.pi / 180)
    _assert_empty(match_scans(ref, pts))
    x = np.linspace(-3, 3, 200)
    line = np.column_stack((x, np.full_like(x, 1.5)))
    _assert_empty(match_scans(line, line + [0.1, 0.0]))
    _assert_empty(match_scans(ref, np.full((50, 2), np.nan)))
    assert spectral_score(prepare_scan(ref), prepare_scan(ref[:2]))[0] == 0.0
    _assert_empty(match_features(prepare_scan(line), prepare_scan(ref)))


def test_malformed_inputs_raise_value_error():
    with pytest.raises(ValueError, match='ref_xy'):
        match_scans(np.ones((5, 3)), np.ones((5, 2)))
    with pytest.raises(ValueError, match='new_xy'):
        match_scans(np.ones((5, 2)), np.ones(7))
