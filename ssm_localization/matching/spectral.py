"""Spectral matching (paper II.B, eqs. 5-6): leading eigenvector of G and greedy binarization."""
from __future__ import annotations

import numpy as np


def leading_eigenvector(G: np.ndarray, iters: int = 50, tol: float = 1e-5,
                        x0: np.ndarray | None = None) -> np.ndarray:
    """
    Return unit Perron vector of a non-negative symmetric G by power iteration (relaxed eq. 6).

    Warm-started from ``x0`` (default: uniform); the result is non-negative (Perron-Frobenius),
    all zeros when G is 0.
    """
    n = G.shape[0]
    if n == 0:
        return np.zeros(0)
    x = np.full(n, 1.0 / np.sqrt(n), dtype=G.dtype) if x0 is None else \
        np.asarray(x0, dtype=G.dtype) / max(float(np.linalg.norm(x0)), 1e-30)
    for _ in range(iters):
        y = G @ x
        # one extra product per step (x <- G^2 x) halves the work on the convergence check
        y = G @ y
        ny = float(np.linalg.norm(y))
        if ny <= 0.0 or not np.isfinite(ny):
            return np.zeros(n)
        y /= ny
        if float(np.abs(y - x).max()) < tol:
            x = y
            break
        x = y
    return np.abs(x).astype(float)


def binarize(x: np.ndarray, pairs: np.ndarray, min_ratio: float = 0.0) -> np.ndarray:
    """
    Greedy discretisation of x* (II.B steps 1-3); returns indices into ``pairs``.

    Walk the candidates once in decreasing x*: accept a = (i, i') unless i or i' is already used
    (step 2 removes exactly those), stop at x* = 0 or below ``min_ratio * max(x*)`` (step 1).
    The accepted set never holds two pairs sharing a reference or a new index.
    """
    if len(x) == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.argsort(-x, kind='stable')
    stop = max(float(x[order[0]]) * min_ratio, 0.0)
    xs = x[order]
    cut = int(np.searchsorted(-xs, -stop, side='left'))  # entries with x > stop
    order = order[:cut].tolist()
    ci = pairs[:, 0].tolist()
    cj = pairs[:, 1].tolist()
    used_i: set[int] = set()
    used_j: set[int] = set()
    sel = []
    for a in order:
        i = ci[a]
        j = cj[a]
        if i in used_i or j in used_j:
            continue
        used_i.add(i)
        used_j.add(j)
        sel.append(a)
    return np.asarray(sel, dtype=np.int64)


def matching_score(G: np.ndarray, selected: np.ndarray) -> float:
    """``E = x^T G x`` (eq. 5) for the binary indicator of ``selected``."""
    if len(selected) == 0:
        return 0.0
    return float(G[np.ix_(selected, selected)].sum(dtype=np.float64))
