"""Pairwise geometry (eqs. 2-3), potentials (eq. 4) and the affinity matrix G (II.B)."""
from __future__ import annotations

import numpy as np


def distance_table(points: np.ndarray) -> np.ndarray:
    """``d_ij = ||p_i - p_j||`` (eq. 2), (N, N) float32."""
    p = np.asarray(points, dtype=np.float32)
    dx = p[:, None, 0] - p[None, :, 0]
    dy = p[:, None, 1] - p[None, :, 1]
    dx *= dx
    dy *= dy
    dx += dy
    return np.sqrt(dx, out=dx)


def angle_table(tangents: np.ndarray) -> np.ndarray:
    """``theta_ij = arccos(u_i . u_j)`` (eq. 2), (N, N) float32 in [0, pi]."""
    u = np.asarray(tangents, dtype=float)
    return np.arccos(np.clip(u @ u.T, -1.0, 1.0)).astype(np.float32)


def deformation(d_ref, a_ref, d_new, a_new) -> np.ndarray:
    """``g_ij(i', j') = [1, (d_ij - d_i'j')^2, (theta_ij - theta_i'j')^2]`` (eq. 3), (..., 3)."""
    dd = np.asarray(d_ref, float) - np.asarray(d_new, float)
    da = np.asarray(a_ref, float) - np.asarray(a_new, float)
    return np.stack((np.ones_like(dd), dd * dd, da * da), axis=-1)


def potential(g: np.ndarray, w) -> np.ndarray:
    """``G_ab = 1 / (1 + exp(-w^T g))`` (eq. 4)."""
    return 1.0 / (1.0 + np.exp(-(np.asarray(g) @ np.asarray(w, dtype=float))))


def affinity_matrix(ref_dist: np.ndarray, ref_angle: np.ndarray, new_dist: np.ndarray,
                    new_angle: np.ndarray, pairs: np.ndarray, w, max_dist_deform: float,
                    max_angle_deform: float) -> np.ndarray:
    """
    Dense symmetric affinity G (|L|, |L|) float32 over tentative correspondences ``pairs``.

    ``G_ab`` is eq. 4 of the deformation (eq. 3) between a = (i, i') and b = (j, j'), set to 0 on
    the diagonal, for conflicting pairs (i = j or i' = j': the one-to-one mapping constraint) and
    when ``|d_ij - d_i'j'| > max_dist_deform`` or ``|theta_ij - theta_i'j'| > max_angle_deform``.
    """
    ci = pairs[:, 0]
    cj = pairs[:, 1]
    # two-step gathers (rows, then columns) are much faster than one fancy index over L x L
    dd = ref_dist.take(ci, axis=0).take(ci, axis=1)
    dd -= new_dist.take(cj, axis=0).take(cj, axis=1)
    da = ref_angle.take(ci, axis=0).take(ci, axis=1)
    da -= new_angle.take(cj, axis=0).take(cj, axis=1)
    w0, w1, w2 = (np.float32(v) for v in w)
    dd *= dd
    da *= da
    bad = dd > np.float32(max_dist_deform ** 2)
    bad |= da > np.float32(max_angle_deform ** 2)
    small = np.int16 if max(int(ci.max(initial=0)), int(cj.max(initial=0))) < 32767 else np.int64
    i16 = ci.astype(small)
    j16 = cj.astype(small)
    bad |= i16[:, None] == i16[None, :]
    bad |= j16[:, None] == j16[None, :]
    z = w1 * dd
    z += w2 * da
    z += w0
    np.negative(z, out=z)
    np.minimum(z, np.float32(80.0), out=z)
    np.exp(z, out=z)
    z += np.float32(1.0)
    np.reciprocal(z, out=z)
    z[bad] = 0.0
    return z
