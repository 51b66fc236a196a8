"""
Spectral scan matching (paper section II): public API ``match_scans``.

Pipeline: ``prepare_scan`` (downsample, tangents eq. 1, descriptors) -> tentative correspondences
L (descriptor top-k) -> affinity G (eqs. 2-4) -> leading eigenvector + greedy binarization
(eqs. 5-6) -> 2-point RANSAC + least squares (eqs. 7-8). Beyond the paper (config flags): a
point-to-line ICP + mutual-nearest-neighbour least-squares polish on the denser point sets, and,
when the pose explains too little of the new scan, further RANSAC hypotheses / spectral clusters
ranked by overlap.

Config fields read by ``prepare_scan`` (so stored ScanFeatures, e.g. in a map index, must be
rebuilt when they change): max_points, min_spacing, context_spacing, tangent_method,
tangent_radius, gap, desc_radius, length_cap, desc_radial_bins, desc_angular_bins,
icp_max_points, icp_min_spacing, normal_radius. See ``config.matcher.PREPARE_FIELDS``.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .descriptors import candidates
from .features import prepare_scan, ScanFeatures
from .pairwise import affinity_matrix
from .ransac import icp_point_to_line, mutual_nn_procrustes, ransac_hypotheses
from .scan import as_points
from .spectral import binarize, leading_eigenvector, matching_score
from ..config.matcher import MatcherConfig
from ..transforms import apply

__all__ = ['MatchResult', 'match_scans', 'match_features', 'spectral_score', 'spectral_solution']


@dataclass(frozen=True)
class MatchResult:
    """
    ``pose`` (x, y, yaw).

    ``p_ref ~= R(yaw) @ p_new + (x, y)``; ``pairs`` (K, 2) consistent correspondences (binarized
    eq. 6) as indices into the caller's ref / new arrays; ``score`` eq. 5 at that solution;
    ``inliers`` (K_in, 2) the pairs supporting the pose; ``ok`` whether the estimate is trustworthy
    (enough inliers); ``overlap`` the fraction of the new scan's points within ``overlap_dist`` of
    the reference at ``pose``. ``pose`` is NaN when nothing could be estimated.
    """

    pose: tuple[float, float, float]
    pairs: np.ndarray
    score: float
    inliers: np.ndarray
    ok: bool
    n_candidates: int = 0
    message: str = ''
    rms: float = math.nan
    overlap: float = math.nan


def _empty(message: str, n_candidates: int = 0, score: float = 0.0,
           pairs: np.ndarray | None = None) -> MatchResult:
    z = np.zeros((0, 2), dtype=np.int64)
    return MatchResult(pose=(math.nan, math.nan, math.nan), pairs=z if pairs is None else pairs,
                       score=score, inliers=z, ok=False, n_candidates=n_candidates,
                       message=message)


def _spectral(ref: ScanFeatures, new: ScanFeatures, config: MatcherConfig):
    """L, G, x*, the binarized selection (indices into L) and the score E."""
    L = candidates(ref.descriptors, new.descriptors, config.k_candidates, config.both_ways)
    if len(L) < 2:
        return L, None, None, np.zeros(0, dtype=np.int64), 0.0
    G = affinity_matrix(ref.dist, ref.angle, new.dist, new.angle, L, config.weights,
                        config.max_dist_deform, config.max_angle_deform)
    x = leading_eigenvector(G, config.power_iterations, config.power_tol)
    sel = binarize(x, L, config.binarize_min_ratio)
    return L, G, x, sel, matching_score(G, sel)


def spectral_solution(ref: ScanFeatures, new: ScanFeatures, config: MatcherConfig | None = None):
    """
    Eqs. (2)-(6) for two prepared scans: ``(L, G, x*, selection, E)``, or None if degenerate.

    Pass it to :func:`match_features` as ``solution`` to reuse the coarse stage's work.
    """
    config = config or MatcherConfig()
    if ref.is_degenerate or new.is_degenerate:
        return None
    return _spectral(ref, new, config)


def spectral_score(ref: ScanFeatures, new: ScanFeatures, config: MatcherConfig | None = None,
                   solution=None) -> tuple[float, np.ndarray]:
    """
    Coarse stage: return the spectral score and the consistent pairs.

    ``(E, pairs)`` with E = eq. 5 at the binarized eq. 6 solution and ``pairs`` (K, 2) indices into
    the callers' arrays (``source_index``). ``(0.0, empty)`` if degenerate.
    """
    solution = solution or spectral_solution(ref, new, config)
    if solution is None:
        return 0.0, np.zeros((0, 2), dtype=np.int64)
    L, _, _, sel, score = solution
    q = L[sel]
    return score, np.column_stack((ref.source_index[q[:, 0]], new.source_index[q[:, 1]]))


def overlap(ref: ScanFeatures, new: ScanFeatures, pose, dist: float) -> float:
    """Return the fraction of new ICP points within ``dist`` of a reference one at ``pose``."""
    if len(new.fine_points) == 0 or len(ref.fine_points) == 0:
        return 0.0
    d, _ = ref.fine_tree.query(apply(pose, new.fine_points), distance_upper_bound=dist)
    return float(np.mean(d < dist))


def _refine(ref: ScanFeatures, new: ScanFeatures, pose, config: MatcherConfig):
    """ICP + polish from ``pose``; returns ``(pose, rms, overlap)``, never losing overlap."""
    ov0 = overlap(ref, new, pose, config.overlap_dist)
    if not config.icp:
        return pose, math.nan, ov0
    p, _, rms = icp_point_to_line(ref.fine_points, ref.fine_normals, new.fine_points, pose,
                                  config.icp_iterations, config.icp_max_dist,
                                  config.icp_min_dist, ref_weights=ref.fine_weights,
                                  tree=ref.fine_tree)
    if config.polish:
        p, _ = mutual_nn_procrustes(ref.fine_points, new.fine_points, p, config.polish_gate,
                                    config.polish_iterations, ref.fine_tree, new.fine_tree)
    ov = overlap(ref, new, p, config.overlap_dist)
    if ov < ov0 - 0.05:          # safety net: the refinement slid away (corridors)
        return pose, math.nan, ov0
    return p, rms, ov


def _estimate(ref: ScanFeatures, new: ScanFeatures, q: np.ndarray, xq: np.ndarray,
              config: MatcherConfig):
    """
    RANSAC (II.C) on the consistent pairs ``q`` (eigenvector values ``xq``), then ICP.

    If the best hypothesis explains less than ``retry_overlap`` of the new scan, the next
    distinct hypotheses (up to ``ransac_hypotheses``) are refined too and the one with the
    largest overlap wins. Returns ``(pose, inlier mask, rms, overlap)`` or None.
    """
    rp = ref.points[q[:, 0]]
    npts = new.points[q[:, 1]]
    rng = np.random.default_rng(config.seed)
    hyps = ransac_hypotheses(rp, npts, config.ransac_threshold, config.ransac_iterations, rng,
                             config.ransac_min_span, xq if config.ransac_weighted else None,
                             max(config.ransac_hypotheses, 1))
    best = None
    for pose0, mask in hyps:
        pose, rms, ov = _refine(ref, new, pose0, config)
        if best is None or ov > best[3]:
            best = (pose, mask, rms, ov)
        if ov >= config.retry_overlap:
            break
    if best is None:
        return None
    pose, mask, rms, ov = best
    mask2 = np.linalg.norm(rp - apply(pose, npts), axis=1) < config.ransac_threshold
    if mask2.sum() >= mask.sum() // 2:
        mask = mask2
    return pose, mask, rms, ov


def match_features(ref: ScanFeatures, new: ScanFeatures, config: MatcherConfig | None = None,
                   solution=None) -> MatchResult:
    """
    Match two prepared scans; never raises on degenerate input (returns ``ok=False``).

    Beyond the paper: when the pose explains less than ``retry_overlap`` of the new scan, the
    next distinct RANSAC hypotheses are refined (``ransac_hypotheses``), then the inliers of that
    cluster are removed from G and the next spectral cluster is tried (``retries`` times); the
    pose with the largest overlap wins. ``score`` is always eq. 5 of the first (paper) solution.
    ``solution``: the :func:`spectral_solution` of these scans with these settings, if known.
    """
    config = config or MatcherConfig()
    if ref.is_degenerate or new.is_degenerate:
        return _empty('degenerate scan (fewer than 3 points or collinear)')
    L, G, x, sel, score = solution or _spectral(ref, new, config)
    best = None
    last = None
    for attempt in range(1 + max(config.retries, 0)):
        if attempt > 0:
            if last is None:
                break
            prev = last  # the inlier pairs of the previous attempt
            drop = np.isin(L[:, 0], prev[:, 0]) | np.isin(L[:, 1], prev[:, 1])
            if attempt == 1:
                G = G.copy()
            G[drop, :] = 0.0
            G[:, drop] = 0.0
            x = leading_eigenvector(G, config.power_iterations, config.power_tol)
            sel = binarize(x, L, config.binarize_min_ratio)
        q = L[sel]
        last = None
        if len(q) < 2:
            break
        est = _estimate(ref, new, q, x[sel], config)
        if est is None:
            break
        pose, mask, rms, ov = est
        last = q[mask]
        if best is None or ov > best[4]:
            best = (pose, q, mask, rms, ov)
        if ov >= config.retry_overlap:
            break
    if best is None:
        q = L[sel] if len(L) else np.zeros((0, 2), dtype=np.int64)
        pairs = np.column_stack((ref.source_index[q[:, 0]], new.source_index[q[:, 1]]))
        return _empty('no pose (too few consistent correspondences)', len(L), score, pairs)
    pose, q, mask, rms, ov = best
    pairs = np.column_stack((ref.source_index[q[:, 0]], new.source_index[q[:, 1]]))
    inliers = pairs[mask]
    ok = bool(len(inliers) >= config.min_inliers)
    return MatchResult(pose=(float(pose[0]), float(pose[1]), float(pose[2])), pairs=pairs,
                       score=score, inliers=inliers, ok=ok, n_candidates=len(L),
                       message='' if ok else f'only {len(inliers)} inliers', rms=rms, overlap=ov)


def match_scans(ref_xy, new_xy, config: MatcherConfig | None = None) -> MatchResult:
    """
    Pose of the new scan in the reference scan's frame: ``p_ref ~= R(yaw) @ p_new + (x, y)``.

    ``ref_xy`` (N, 2) and ``new_xy`` (M, 2): points in scan order, metres. Raises ``ValueError``
    for arrays that are not (N, 2); fewer than 3 finite points, all-invalid or collinear scans
    give a ``MatchResult`` with ``ok=False`` and a NaN pose.
    """
    config = config or MatcherConfig()
    ref = prepare_scan(as_points(ref_xy, 'ref_xy'), config)
    new = prepare_scan(as_points(new_xy, 'new_xy'), config)
    return match_features(ref, new, config)
