"""
Compiled loops (numba) of the scan features numpy builds in many small passes.

A map index prepares the features of each of its thousands of virtual scans (``features.py``),
a few hundred points each: numpy's calls on such small arrays cost more than their arithmetic.

- :func:`voxel_select`: the voxel-grid selection behind ``scan.downsample_even`` (one point per
  occupied square cell, the one nearest the cell's centroid), run several times per scan while
  the cell grows to the budget. The same indices bit for bit: the same cells, the centroids
  summed in ``np.bincount``'s order, the nearest point with ties to the lower index.
- :func:`neighbourhood_moments`: the sums behind ``scan.robust_tangents`` (each point's radius
  grown to its 4th nearest context point, the count, first and second moments of the context
  within it), bit for bit, each sum taken in numpy's pairwise order (:func:`pairwise_sum`).
- :func:`shape_context_histograms`: the histograms of ``descriptors.shape_context``; the
  bearings are numba's ``atan2`` where numpy has its own, so a float64 sum may differ in a last
  bit (the float32 descriptors of office_30m's 10 894 nodes came out identical).

On office_30m's nodes the features took 0.53 of numpy's time (12.4 -> 6.5 s). Without numba
each compiled function is None and the callers run numpy; the Python sources (``*_python``) are
what ``test_scan.py`` compares the compiled loops and numpy with. docs/EXPERIMENTS.md has the
measurements (2026-11-28, 16 h UTC).
"""
from __future__ import annotations

import numpy as np

from ..compiled import compile_loop


def voxel_select_python(points: np.ndarray, cell: float) -> np.ndarray:
    """
    Ascending indices of one point per occupied square cell of side ``cell``.

    ``points`` (N, 2) float64, finite; the point nearest its cell's centroid is kept (the lower
    index on a tie). The cells are told apart by an open-addressing table of their codes rather
    than by sorting (numba compiles a sort in seconds). The reference implementation, compiled
    by numba.
    """
    n = points.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    kx = np.empty(n, np.int64)
    ky = np.empty(n, np.int64)
    for i in range(n):
        kx[i] = np.int64(np.floor(points[i, 0] / cell))
        ky[i] = np.int64(np.floor(points[i, 1] / cell))
    low_x, low_y, high_y = kx[0], ky[0], ky[0]
    for i in range(1, n):
        low_x = min(low_x, kx[i])
        low_y = min(low_y, ky[i])
        high_y = max(high_y, ky[i])
    span_y = high_y - low_y + 1
    size = 1
    while size < 2 * n:
        size *= 2
    codes = np.empty(size, np.int64)
    slots = np.full(size, -1, np.int64)         # the cell in each slot, -1: free
    group = np.empty(n, np.int64)
    cells = 0
    for i in range(n):
        code = (kx[i] - low_x) * span_y + (ky[i] - low_y)
        mixed = (code ^ (code >> 16)) * 0x45D9F3B   # spread every bit of the code to the low ones
        slot = (mixed ^ (mixed >> 16)) & (size - 1)
        while slots[slot] >= 0 and codes[slot] != code:
            slot = (slot + 1) & (size - 1)
        if slots[slot] < 0:
            slots[slot] = cells
            codes[slot] = code
            cells += 1
        group[i] = slots[slot]
    count = np.zeros(cells)
    sum_x = np.zeros(cells)
    sum_y = np.zeros(cells)
    for i in range(n):                  # in index order, as np.bincount sums
        count[group[i]] += 1.0
        sum_x[group[i]] += points[i, 0]
        sum_y[group[i]] += points[i, 1]
    best = np.full(cells, np.inf)
    pick = np.full(cells, -1, np.int64)
    for i in range(n):
        k = group[i]
        dx = points[i, 0] - sum_x[k] / count[k]
        dy = points[i, 1] - sum_y[k] / count[k]
        d = dx * dx + dy * dy
        if pick[k] < 0 or d < best[k]:
            best[k] = d
            pick[k] = i
    keep = np.zeros(n, np.bool_)
    for k in range(cells):
        keep[pick[k]] = True
    out = np.empty(cells, np.int64)
    j = 0
    for i in range(n):
        if keep[i]:
            out[j] = i
            j += 1
    return out


#: the compiled :func:`voxel_select_python`, or None without numba
voxel_select = compile_loop(voxel_select_python)


def block_sum_python(values: np.ndarray, lo: int, n: int) -> float:
    """
    ``values[lo:lo + n]``, at most 128 terms, summed as numpy sums a block of a row.

    Fewer than 8 terms one by one; else eight running sums combined as ``((r0 + r1) + (r2 +
    r3)) + ((r4 + r5) + (r6 + r7))``, then the terms left over.
    """
    if n < 8:
        res = 0.0
        for i in range(n):
            res += values[lo + i]
        return res
    r0, r1, r2, r3 = values[lo], values[lo + 1], values[lo + 2], values[lo + 3]
    r4, r5, r6, r7 = values[lo + 4], values[lo + 5], values[lo + 6], values[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += values[lo + i]
        r1 += values[lo + i + 1]
        r2 += values[lo + i + 2]
        r3 += values[lo + i + 3]
        r4 += values[lo + i + 4]
        r5 += values[lo + i + 5]
        r6 += values[lo + i + 6]
        r7 += values[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += values[lo + i]
        i += 1
    return res


#: the compiled :func:`block_sum_python`, or None without numba
block_sum = compile_loop(block_sum_python)


def pairwise_sum_python(values: np.ndarray, n: int, tasks: np.ndarray,
                        partial: np.ndarray) -> float:
    """
    ``values[:n]`` summed in numpy's order for a row of a reduction along the last axis.

    numpy sums a contiguous row pairwise: up to 128 terms as :func:`block_sum_python`; a longer
    row split in two at a multiple of 8 below its half, each part summed so, then added. Here
    without recursion (numba cannot cache a recursive function that others call): ``tasks``
    (at least 128, 2) int64 and ``partial`` (at least 64,) float64 are scratch stacks. So the
    compiled loops give the sums ``np.sum(..., axis=1)`` gives, bit for bit (``test_scan.py``
    checks rows of every length up to 600).
    """
    if n <= 128:
        return block_sum(values, 0, n)
    tasks[0, 0], tasks[0, 1] = 0, n
    top, done = 1, 0
    while top > 0:
        top -= 1
        lo, size = tasks[top, 0], tasks[top, 1]
        if size < 0:                            # both halves summed: add them
            done -= 1
            partial[done - 1] = partial[done - 1] + partial[done]
        elif size <= 128:
            partial[done] = block_sum(values, lo, size)
            done += 1
        else:                                   # the first half runs first, then the second
            half = size // 2
            half -= half % 8
            tasks[top, 0], tasks[top, 1] = 0, -1
            tasks[top + 1, 0], tasks[top + 1, 1] = lo + half, size - half
            tasks[top + 2, 0], tasks[top + 2, 1] = lo, half
            top += 3
    return partial[0]


#: the compiled :func:`pairwise_sum_python` (the loop below calls it), or None
pairwise_sum = compile_loop(pairwise_sum_python)


def neighbourhood_moments_python(points: np.ndarray, context: np.ndarray, kth: int,
                                 r2_min: float, r2_max: float, out: np.ndarray) -> None:
    """
    Sum the moments of each point's neighbourhood for ``scan.robust_tangents`` into ``out``.

    ``points`` (N, 2), ``context`` (C, 2); ``dx``, ``dy``: the context points' offsets from
    each point (taken pair by pair, as numpy's (N, C) arrays hold them). Point ``i``'s squared
    radius is ``clip(1.0001 d2_(kth), r2_min, r2_max)``, ``d2_(kth)`` the ``kth`` smallest
    (from 0) of its squared distances ``d2 = dx^2 + dy^2`` (``r2_min`` when ``kth`` < 1); with
    ``m = d2 <= r2`` (0 or 1), ``out[i] = sum_j (m, m dx, m dy, m dx dx, m dx dy, m dy dy)``,
    each product and each sum as numpy forms them (:func:`pairwise_sum_python`).
    """
    n, c = points.shape[0], context.shape[0]
    rows = np.empty((6, c))
    dx = np.empty(c)
    dy = np.empty(c)
    smallest = np.empty(max(kth + 1, 1))
    tasks = np.empty((128, 2), np.int64)
    partial = np.empty(64)
    for i in range(n):
        for j in range(c):
            dx[j] = context[j, 0] - points[i, 0]
            dy[j] = context[j, 1] - points[i, 1]
        r2 = r2_min
        if kth >= 1:
            filled = 0
            for j in range(c):
                d2 = dx[j] * dx[j] + dy[j] * dy[j]
                if filled <= kth:
                    at = filled
                    filled += 1
                elif d2 < smallest[kth]:
                    at = kth
                else:
                    continue
                while at > 0 and smallest[at - 1] > d2:
                    smallest[at] = smallest[at - 1]
                    at -= 1
                smallest[at] = d2
            r2 = min(max(smallest[kth] * 1.0001, r2_min), r2_max)
        for j in range(c):
            x, y = dx[j], dy[j]
            m = 1.0 if x * x + y * y <= r2 else 0.0
            mx, my = m * x, m * y
            rows[0, j] = m
            rows[1, j] = mx
            rows[2, j] = my
            rows[3, j] = mx * x
            rows[4, j] = mx * y
            rows[5, j] = my * y
        for k in range(6):
            out[i, k] = pairwise_sum(rows[k], c, tasks, partial)


#: the compiled :func:`neighbourhood_moments_python`, or None without numba
neighbourhood_moments = compile_loop(neighbourhood_moments_python)


def shape_context_histograms_python(points: np.ndarray, context: np.ndarray,
                                    tangents: np.ndarray, weights: np.ndarray, radius: float,
                                    radial_bins: int, angular_bins: int,
                                    out: np.ndarray) -> None:
    """
    Fill ``out`` with the log-polar histograms of ``descriptors.shape_context``, unnormalised.

    ``points`` (N, 2) and their unit ``tangents`` (N, 2), ``context`` (C, 2) and ``weights``
    (C,) each context point's vote; ``out`` (N, radial_bins *
    angular_bins) float64 is overwritten. Each neighbour within ``radius`` (and not at the point
    itself) votes in its radial bin, split linearly between the two nearest angular bins; the
    votes for the nearer and the farther bin are summed apart, then added, as the two
    ``np.bincount`` of the numpy form do.
    """
    n, c = points.shape[0], context.shape[0]
    nb = radial_bins * angular_bins
    r_in = radius / 2.0 ** (radial_bins - 1)
    rr = radius * radius
    scale = angular_bins / (2.0 * np.pi)
    first = np.empty(nb)
    second = np.empty(nb)
    for i in range(n):
        first[:] = 0.0
        second[:] = 0.0
        ux, uy = tangents[i, 0], tangents[i, 1]
        for j in range(c):
            ex, ey = context[j, 0] - points[i, 0], context[j, 1] - points[i, 1]
            d2 = ex * ex + ey * ey
            if not (d2 > 0.0 and d2 < rr):
                continue
            lx = ex * ux + ey * uy
            ly = ey * ux - ex * uy
            rb = int(np.floor(np.log2(max(np.sqrt(d2), 1e-9) / r_in))) + 1
            rb = min(max(rb, 0), radial_bins - 1)
            f = (np.arctan2(ly, lx) + np.pi) * scale - 0.5
            f0 = np.floor(f)
            w1 = f - f0
            a0 = int(f0) % angular_bins
            a1 = (a0 + 1) % angular_bins
            first[rb * angular_bins + a0] += (1.0 - w1) * weights[j]
            second[rb * angular_bins + a1] += w1 * weights[j]
        for k in range(nb):
            out[i, k] = first[k] + second[k]


#: the compiled :func:`shape_context_histograms_python`, or None without numba
shape_context_histograms = compile_loop(shape_context_histograms_python)
