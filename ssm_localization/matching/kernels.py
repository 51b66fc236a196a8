"""
Compiled loops (numba) of the scan geometry numpy does in many small passes.

:func:`voxel_select`: the voxel-grid selection behind ``scan.downsample_even`` (one point per
occupied square cell, the one nearest the cell's centroid). numpy takes a dozen calls for it (the
cells' codes, ``unique``, three ``bincount``, ``lexsort``, ``sort``), each on a few hundred
points, so the calls' overhead is most of its cost; it runs several times per scan (the cell is
grown until the budget holds) and for each of a map index's thousands of virtual scans. The loop
gives the same indices bit for bit: the same cells, the centroids summed in the same order, the
nearest point with ties to the lower index (``test_scan.py`` compares them).

Without numba the compiled function is None and ``scan.py`` runs numpy; the Python source
(``*_python``) is what the tests compare the compiled loop with. docs/EXPERIMENTS.md
(2026-11-28, session 47) has the measurements.
"""
from __future__ import annotations

import numpy as np

from ..compiled import compile_loop


def voxel_select_python(points: np.ndarray, cell: float) -> np.ndarray:
    """
    Ascending indices of one point per occupied square cell of side ``cell``.

    ``points`` (N, 2) float64, finite; the point nearest its cell's centroid is kept (the lower
    index on a tie). The reference implementation, compiled by numba.
    """
    n = points.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    kx = np.empty(n, np.int64)
    ky = np.empty(n, np.int64)
    for i in range(n):
        kx[i] = np.int64(np.floor(points[i, 0] / cell))
        ky[i] = np.int64(np.floor(points[i, 1] / cell))
    low_x, low_y = kx.min(), ky.min()
    code = (kx - low_x) * (ky.max() - low_y + 1) + (ky - low_y)
    order = np.argsort(code, kind='mergesort')
    group = np.empty(n, np.int64)
    cells = 0
    for r in range(n):
        i = order[r]
        if r > 0 and code[i] != code[order[r - 1]]:
            cells += 1
        group[i] = cells
    cells += 1
    count = np.zeros(cells)
    sum_x = np.zeros(cells)
    sum_y = np.zeros(cells)
    for i in range(n):                  # in index order, as np.bincount sums
        count[group[i]] += 1.0
        sum_x[group[i]] += points[i, 0]
        sum_y[group[i]] += points[i, 1]
    cx = sum_x / count
    cy = sum_y / count
    best = np.full(cells, np.inf)
    pick = np.full(cells, -1, np.int64)
    for i in range(n):
        k = group[i]
        dx = points[i, 0] - cx[k]
        dy = points[i, 1] - cy[k]
        d = dx * dx + dy * dy
        if pick[k] < 0 or d < best[k]:
            best[k] = d
            pick[k] = i
    return np.sort(pick)


#: the compiled :func:`voxel_select_python`, or None without numba
voxel_select = compile_loop(voxel_select_python)
