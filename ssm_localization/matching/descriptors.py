"""
Rotation-invariant local descriptors and tentative correspondences L (paper II.B).

The paper does not say how L is built; all n x m pairs would make G far too big. Each point gets a
small log-polar histogram (a shape context) of its neighbours within a radius, expressed in the
frame of its own tangent (eq. 1), so it is invariant to rigid motion. L holds, for every new point,
the ``k`` reference points with the nearest descriptors (optionally also the reverse direction).
``ssm_localization bench scanmatch`` prints the fraction of true correspondences kept in L vs k.
"""
from __future__ import annotations

import numpy as np

from . import kernels
from .scan import pair_offsets


def shape_context(points: np.ndarray, tangents: np.ndarray, radius: float, radial_bins: int,
                  angular_bins: int, context: np.ndarray | None = None,
                  offsets=None, weights: np.ndarray | None = None) -> np.ndarray:
    """
    Return (N, radial_bins * angular_bins) float32 descriptors, Hellinger-normalised.

    Each row has unit L2 norm.

    Neighbour ``j`` of point ``i`` (``0 < d_ij < radius``) is binned by ``log2(d_ij)`` (radial
    edges ``radius / 2**k``) and by its bearing in the frame (u_i, n_i); the bearing vote is split
    linearly between the two nearest angular bins so small tangent errors do not flip bins.
    Neighbours are taken from ``context`` (default: ``points``), ideally a spatially even set;
    ``offsets`` may pass precomputed ``(dx, dy)`` = context - points, each (N, C). ``weights``
    (C,) weight each context point's vote (e.g. the scan length it stands for, so the histogram
    measures surface length and does not depend on the sampling density).
    """
    ctx = points if context is None else context
    n = len(points)
    nb = radial_bins * angular_bins
    if n == 0:
        return np.zeros((0, nb), dtype=np.float32)
    if kernels.shape_context_histograms is not None and len(ctx) > 0:
        # one compiled pass, the offsets taken pair by pair (kernels.py): the same histograms
        # up to the last bit of an angle
        h = np.empty((n, nb))
        kernels.shape_context_histograms(
            np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(ctx, np.float64),
            np.ascontiguousarray(tangents, dtype=np.float64),
            np.ones(len(ctx)) if weights is None else np.ascontiguousarray(weights, np.float64),
            float(radius), int(radial_bins), int(angular_bins), h)
        return _normalised(h)
    dx, dy = pair_offsets(points, ctx) if offsets is None else offsets
    d2 = dx * dx + dy * dy
    ii, jj = np.nonzero((d2 > 0.0) & (d2 < radius * radius))
    ex = dx[ii, jj]
    ey = dy[ii, jj]
    dd = np.sqrt(d2[ii, jj])
    u = tangents[ii]
    lx = ex * u[:, 0] + ey * u[:, 1]
    ly = ey * u[:, 0] - ex * u[:, 1]
    r_in = radius / 2.0 ** (radial_bins - 1)
    rb = np.clip(np.floor(np.log2(np.maximum(dd, 1e-9) / r_in)).astype(int) + 1, 0,
                 radial_bins - 1)
    f = (np.arctan2(ly, lx) + np.pi) * (angular_bins / (2.0 * np.pi)) - 0.5
    f0 = np.floor(f)
    w1 = f - f0
    a0 = f0.astype(int) % angular_bins
    a1 = (a0 + 1) % angular_bins
    base = ii * nb + rb * angular_bins
    cw = 1.0 if weights is None else weights[jj]
    h = np.bincount(base + a0, weights=(1.0 - w1) * cw, minlength=n * nb)
    h += np.bincount(base + a1, weights=w1 * cw, minlength=n * nb)
    return _normalised(h.reshape(n, nb))


def _normalised(h: np.ndarray) -> np.ndarray:
    """Hellinger-normalise histograms (N, B): the square roots of each row's shares, float32."""
    s = h.sum(axis=1, keepdims=True)
    h = np.sqrt(h / np.where(s > 0.0, s, 1.0))
    return h.astype(np.float32)


def descriptor_distances(ref_desc: np.ndarray, new_desc: np.ndarray) -> np.ndarray:
    """Squared L2 distances (M, N) between new (rows) and reference (columns) descriptors."""
    rn = (ref_desc * ref_desc).sum(axis=1)
    nn = (new_desc * new_desc).sum(axis=1)
    return np.maximum(nn[:, None] + rn[None, :] - 2.0 * (new_desc @ ref_desc.T), 0.0)


def candidates(ref_desc: np.ndarray, new_desc: np.ndarray, k: int,
               both_ways: bool = False) -> np.ndarray:
    """
    Tentative correspondences L as an (|L|, 2) int array of (ref index i, new index i').

    For each new point its ``k`` nearest reference descriptors; with ``both_ways`` also each
    reference point's ``k`` nearest new descriptors (union). Sorted by (i', i), no duplicates.
    """
    m, n = len(new_desc), len(ref_desc)
    if m == 0 or n == 0 or k <= 0:
        return np.zeros((0, 2), dtype=np.int64)
    dist = descriptor_distances(ref_desc, new_desc)
    kk = min(k, n)
    top = np.argpartition(dist, kk - 1, axis=1)[:, :kk] if kk < n else \
        np.broadcast_to(np.arange(n), (m, n))
    codes = np.arange(m)[:, None] * n + top
    if both_ways:
        kr = min(k, m)
        topr = np.argpartition(dist, kr - 1, axis=0)[:kr, :] if kr < m else \
            np.broadcast_to(np.arange(m)[:, None], (m, n))
        codes = np.concatenate((codes.ravel(), (topr * n + np.arange(n)[None, :]).ravel()))
    codes = np.unique(codes.ravel())
    return np.column_stack((codes % n, codes // n)).astype(np.int64)
