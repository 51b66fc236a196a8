"""
Pose estimation (paper II.C): 2-point RANSAC (eqs. 7-8), least squares, point-to-line ICP.

All poses are ``(x, y, yaw)`` with ``p_ref = R(yaw) @ p_new + (x, y)``.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from ..transforms import apply, compose, inverse


def two_point_poses(ref_a, new_a, ref_b, new_b) -> np.ndarray:
    """
    Poses (H, 3) from correspondence pairs a = (i, i') and b = (j, j'), vectorized.

    eq. 8: ``A = x_i' - x_j'``, ``B = y_i' - y_j'``, ``C = x_i - x_j``, ``D = y_i - y_j``,
    ``theta = atan2(AD - BC, AC + BD)``; eq. 7 then gives ``t = p_i - R(theta) p_i'``.
    """
    A = new_a[:, 0] - new_b[:, 0]
    B = new_a[:, 1] - new_b[:, 1]
    C = ref_a[:, 0] - ref_b[:, 0]
    D = ref_a[:, 1] - ref_b[:, 1]
    th = np.arctan2(A * D - B * C, A * C + B * D)
    c, s = np.cos(th), np.sin(th)
    tx = ref_a[:, 0] - c * new_a[:, 0] + s * new_a[:, 1]
    ty = ref_a[:, 1] - s * new_a[:, 0] - c * new_a[:, 1]
    return np.column_stack((tx, ty, th))


def procrustes(ref: np.ndarray, new: np.ndarray, weights: np.ndarray | None = None):
    """Closed-form 2-D least squares ``min sum w ||ref - R new - t||^2``; returns (x, y, yaw)."""
    w = np.ones(len(ref)) if weights is None else np.asarray(weights, float)
    sw = w.sum()
    if len(ref) < 2 or sw <= 0.0:
        raise ValueError('procrustes: need at least 2 weighted correspondences')
    cr = (w[:, None] * ref).sum(axis=0) / sw
    cn = (w[:, None] * new).sum(axis=0) / sw
    r = ref - cr
    q = new - cn
    sxx = (w * (q[:, 0] * r[:, 0] + q[:, 1] * r[:, 1])).sum()
    sxy = (w * (q[:, 0] * r[:, 1] - q[:, 1] * r[:, 0])).sum()
    th = math.atan2(sxy, sxx)
    c, s = math.cos(th), math.sin(th)
    return (float(cr[0] - c * cn[0] + s * cn[1]), float(cr[1] - s * cn[0] - c * cn[1]), th)


def ransac_hypotheses(ref: np.ndarray, new: np.ndarray, threshold: float, iterations: int,
                      rng: np.random.Generator, min_span: float = 0.2,
                      weights: np.ndarray | None = None, n_best: int = 1,
                      distinct: tuple[float, float] = (0.3, 0.1)) -> list:
    """
    2-point RANSAC over correspondences ``ref[k] <-> new[k]`` (II.C steps 1-4).

    All ``iterations`` hypotheses are drawn and scored at once (eqs. 7-8); pairs closer than
    ``min_span`` or whose lengths differ by more than ``2 * threshold`` are skipped. Hypotheses
    are ranked by support (then least residual); the ``n_best`` best mutually distinct ones
    (farther apart than ``distinct`` = (metres, radians)) are each refined by least squares on
    their inliers, twice (re-collecting inliers). With ``weights`` (e.g. the eigenvector x* of
    eq. 6, beyond the paper) pairs are drawn with probability proportional to their weight and
    the support is the summed weight of the inliers instead of their count.
    Returns a list of ``(pose, inlier_mask)``, best first (empty if nothing fits).
    """
    k = len(ref)
    if k < 2:
        return []
    if weights is None:
        a = rng.integers(0, k, iterations)
        b = rng.integers(0, k - 1, iterations)
        b += b >= a
        wv = np.ones(k)
    else:
        wv = np.maximum(np.asarray(weights, float), 0.0)
        if wv.sum() <= 0.0:
            wv = np.ones(k)
        p = wv / wv.sum()
        a = rng.choice(k, iterations, p=p)
        b = rng.choice(k, iterations, p=p)
        same = a == b
        b[same] = (b[same] + 1 + rng.integers(0, k - 1, same.sum())) % k
    lr = np.linalg.norm(ref[a] - ref[b], axis=1)
    ln = np.linalg.norm(new[a] - new[b], axis=1)
    good = (lr > min_span) & (np.abs(lr - ln) < 2.0 * threshold)
    if not good.any():
        return []
    a, b = a[good], b[good]
    poses = two_point_poses(ref[a], new[a], ref[b], new[b])
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    px = c[:, None] * new[None, :, 0] - s[:, None] * new[None, :, 1] + poses[:, 0:1]
    py = s[:, None] * new[None, :, 0] + c[:, None] * new[None, :, 1] + poses[:, 1:2]
    r2 = (px - ref[None, :, 0]) ** 2 + (py - ref[None, :, 1]) ** 2
    inl = r2 < threshold * threshold
    support = inl @ wv
    cost = np.where(inl, r2, threshold * threshold).sum(axis=1)
    out: list = []
    chosen: list = []
    for h in np.lexsort((cost, -support)).tolist():
        if len(out) >= n_best:
            break
        mask = inl[h]
        if mask.sum() < 2:
            break
        raw = poses[h]
        if any(math.hypot(raw[0] - o[0], raw[1] - o[1]) < distinct[0] and
               abs(math.remainder(raw[2] - o[2], 2 * math.pi)) < distinct[1] for o in chosen):
            continue
        chosen.append(raw)
        pose = tuple(float(v) for v in raw)
        for _ in range(2):
            pose = procrustes(ref[mask], new[mask])
            res = np.linalg.norm(ref - apply(pose, new), axis=1)
            m2 = res < threshold
            if m2.sum() < 2:
                break
            mask = m2
        out.append((pose, mask))
    return out


def ransac_pose(ref: np.ndarray, new: np.ndarray, threshold: float, iterations: int,
                rng: np.random.Generator, min_span: float = 0.2,
                weights: np.ndarray | None = None):
    """
    Return the best hypothesis of :func:`ransac_hypotheses`.

    ``(pose, inlier_mask)`` or ``(None, empty mask)``.
    """
    hyps = ransac_hypotheses(ref, new, threshold, iterations, rng, min_span, weights, 1)
    return hyps[0] if hyps else (None, np.zeros(len(ref), dtype=bool))


def icp_point_to_line(ref: np.ndarray, ref_normals: np.ndarray, new: np.ndarray, pose,
                      iterations: int = 15, max_dist: float = 0.3, min_dist: float = 0.05,
                      ref_weights: np.ndarray | None = None, tree=None, damping: float = 1e-4,
                      tol: float = 1e-5, max_step: tuple[float, float] = (0.05, 0.03)):
    """
    Refine ``pose`` by point-to-line ICP (beyond the paper: real scans do not share points).

    Each iteration pairs every transformed new point with its nearest reference point (k-d tree),
    keeps pairs closer than a gate (``max_dist`` first, then 3x the median pair distance clipped
    to [min_dist, max_dist]) and solves the damped, weighted Gauss-Newton step of
    ``sum w_i (n_i . (R p' + t - p_i))^2`` for a left increment. ``ref_weights`` (e.g. normal
    quality, 0 at corners) scale each reference point. Each step is clamped to ``max_step``
    (metres, radians): a trust region against ill-conditioned (corridor) steps. Stops after
    ``iterations`` or when the step is below ``tol`` (metres / radians).
    Returns ``(pose, n_pairs, rms)``.
    """
    pose = tuple(float(v) for v in pose)
    if len(ref) < 3 or len(new) < 3:
        return pose, 0, math.inf
    if tree is None:
        tree = cKDTree(ref)
    w_ref = np.ones(len(ref)) if ref_weights is None else np.asarray(ref_weights, float)
    gate = max_dist
    used, rms = 0, math.inf
    eye = np.eye(3)
    for _ in range(iterations):
        q = apply(pose, new)
        dist, nn = tree.query(q, distance_upper_bound=gate)
        keep = dist < gate
        if keep.sum() < 3:
            break
        gate = min(max(3.0 * float(np.median(dist[keep])), min_dist), max_dist)
        nk_i = nn[keep]
        w = w_ref[nk_i]
        sw = float(w.sum())
        used = int(np.count_nonzero(w))
        if used < 3:
            break
        qk = q[keep]
        nk = ref_normals[nk_i]
        e = ((qk - ref[nk_i]) * nk).sum(axis=1)
        J = np.column_stack((nk, nk[:, 1] * qk[:, 0] - nk[:, 0] * qk[:, 1]))
        Jw = J * w[:, None]
        delta = -np.linalg.solve(Jw.T @ J + (damping * sw) * eye, Jw.T @ e)
        st = math.hypot(delta[0], delta[1])
        if st > max_step[0]:
            delta[:2] *= max_step[0] / st
        delta[2] = min(max(delta[2], -max_step[1]), max_step[1])
        rms = float(np.sqrt((w * e * e).sum() / sw))
        pose = compose((float(delta[0]), float(delta[1]), float(delta[2])), pose)
        if abs(delta[0]) + abs(delta[1]) < tol and abs(delta[2]) < tol:
            break
    return pose, used, rms


def mutual_nn_procrustes(ref: np.ndarray, new: np.ndarray, pose, gate: float,
                         iterations: int = 2, ref_tree=None, new_tree=None):
    """
    Polish ``pose`` by point-to-point least squares on mutual nearest neighbours.

    Pairs closer than ``gate``; closed-form Procrustes, ``iterations`` times. Where both scans
    sample the same points this removes the along-wall freedom point-to-line ICP leaves.
    Returns ``(pose, n_pairs)``; the input pose if fewer than 3 pairs are found.
    """
    pose = tuple(float(v) for v in pose)
    if len(ref) < 3 or len(new) < 3:
        return pose, 0
    ref_tree = ref_tree if ref_tree is not None else cKDTree(ref)
    new_tree = new_tree if new_tree is not None else cKDTree(new)
    used = 0
    idx = np.arange(len(new))
    for _ in range(iterations):
        q = apply(pose, new)
        d, nn = ref_tree.query(q, distance_upper_bound=gate)
        found = d < gate
        if found.sum() < 3:
            break
        back_pts = apply(inverse(pose), ref[nn[found]])
        _, back = new_tree.query(back_pts)
        keep = idx[found][back == idx[found]]
        if len(keep) < 3:
            break
        used = len(keep)
        pose = procrustes(ref[nn[keep]], new[keep])
    return pose, used
