"""
Compiled loops (numba) of the two stages numpy does in many passes: search and refinement.

:func:`window_sums`: a window's score in the correlative search (``correlative.py``) is the sum
of a few dozen likelihoods gathered from a level grid. numpy takes five passes over (windows,
points) arrays for it: the rows of cell offsets gathered, the window's cell added, the
likelihoods gathered, cast and summed; the loop reads each offset once and keeps the sum in a
register. The sums are integers, so both ways give the same scores bit for bit. On the 90
captured campus searches it cut the search's time to 0.70 of numpy's.

:func:`normal_equations`: one Gauss-Newton step of the refinement (``refine.py``) per pose, the
points moved, their signed distances looked up and the normal equations summed in one pass,
where numpy builds a dozen (poses, points) arrays. The same sums up to the order of their terms
(poses within 1e-15 m on the campus's refinements); 0.37 of numpy's time there.

Without numba (not installed, or a platform it does not support) both are None and the callers
use numpy; the Python sources (``*_python``) are what the tests compare the compiled loops with.
They run in one thread (``nogil``, no ``parallel``): the package's thread policy
(``threads.py``) stands. docs/EXPERIMENTS.md (2026-11-28) has the measurements.
"""
from __future__ import annotations

import numpy as np

from ..compiled import compile_loop


def window_sums_python(grid: np.ndarray, base: np.ndarray, yaw: np.ndarray, cell: np.ndarray,
                       out: np.ndarray) -> None:
    """
    ``out[w] = sum_j grid[clip(base[yaw[w], j] + cell[w])]``: the score of each window, unscaled.

    ``grid`` (G,) uint8 likelihoods of one level, flat; ``base`` (K, N) int64 the offsets of a
    scan's N points per yaw; ``yaw`` (W,) int64 and ``cell`` (W,) int64 each window's yaw and
    flat cell; ``out`` (W,) int32. Indices off the flat grid read its first or last cell, as
    ``np.take(..., mode='clip')`` does. The reference implementation, compiled by numba.
    """
    n = base.shape[1]
    last = grid.shape[0] - 1
    for w in range(yaw.shape[0]):
        row = yaw[w]
        at = cell[w]
        total = np.int64(0)
        for j in range(n):
            idx = base[row, j] + at
            if idx < 0:
                idx = 0
            elif idx > last:
                idx = last
            total += grid[idx]
        out[w] = total


#: the compiled :func:`window_sums_python`, or None without numba
window_sums = compile_loop(window_sums_python)


def normal_equations_python(x: np.ndarray, delta: np.ndarray, pts: np.ndarray,
                            active: np.ndarray, tiles: np.ndarray, codes: np.ndarray,
                            values: np.ndarray, cap: int, tile: int, frame: np.ndarray,
                            shape_h: int, shape_w: int, resolution: float, depth: float,
                            trunc: float, huber: float, a: np.ndarray, b: np.ndarray,
                            sse: np.ndarray, used: np.ndarray) -> None:
    """
    One Gauss-Newton step's sums for each active pose (``refine.refine_poses``), in one pass.

    Per pose ``x[h]`` and point: the point moved by the pose, its signed distance to the wall
    surface bilinear on the lattice and its gradient (``SurfaceModel.signed_distance``), the
    residual ``r`` (plus ``delta[h]``), its Huber weight ``w`` when ``|r| < trunc``, and
    ``J = (dr/dx, dr/dy, dr/dyaw[, 1])``: ``a[h] += w J J^T``, ``b[h] += w J r``, ``sse[h] +=
    w r^2``, ``used[h] += 1``. ``a`` (H, D, D) with D 3 or 4 (the wall offset as a fourth
    unknown), ``b`` (H, D), ``sse`` (H,) and ``used`` (H,) start at zero; inactive poses are
    skipped. The surface is ``SurfaceModel``'s: ``tiles``, ``codes``, ``values``, ``cap``,
    ``tile`` (its :data:`refine.TILE`) and ``frame``, the lattice's ``(x0, y0, cos, sin, lattice
    points per metre, lattice points per cell)``; ``shape_h``, ``shape_w`` its lattice points.
    """
    dim = a.shape[1]
    side = tile + 1
    shift = 0
    while (1 << shift) < tile:
        shift += 1
    x0, y0, co, si, scale, per_cell = frame[0], frame[1], frame[2], frame[3], frame[4], frame[5]
    for h in range(x.shape[0]):
        if not active[h]:
            continue
        c, s = np.cos(x[h, 2]), np.sin(x[h, 2])
        for n in range(pts.shape[0]):
            rx = c * pts[n, 0] - s * pts[n, 1]
            ry = s * pts[n, 0] + c * pts[n, 1]
            dx, dy = rx + x[h, 0] - x0, ry + x[h, 1] - y0
            gx = (dx * co + dy * si) * scale
            gy = (dy * co - dx * si) * scale
            if not (abs(gx) < 1e15 and abs(gy) < 1e15):     # NaN, inf: off the lattice
                continue
            j = int(np.floor(gx))
            i = int(np.floor(gy))
            if j < 0 or j >= shape_w - 1 or i < 0 or i >= shape_h - 1:
                continue
            fx, fy = gx - j, gy - i
            k = (int(tiles[i >> shift, j >> shift]) * side * side + (i & (tile - 1)) * side
                 + (j & (tile - 1)))
            va = values[int(codes[k]) + cap]
            vb = values[int(codes[k + 1]) + cap]
            vc = values[int(codes[k + side]) + cap]
            vd = values[int(codes[k + side + 1]) + cap]
            bottom = va + fx * (vb - va)
            top = vc + fx * (vd - vc)
            r = (bottom + fy * (top - bottom)) * resolution + depth + delta[h]
            if not abs(r) < trunc:
                continue
            u = ((vb - va) + fy * ((vd - vc) - (vb - va))) * per_cell
            v = (top - bottom) * per_cell
            jx = u * co - v * si
            jy = u * si + v * co
            jyaw = jy * rx - jx * ry
            w = 1.0 if abs(r) <= huber else huber / max(abs(r), 1e-12)
            jac = (jx, jy, jyaw, 1.0)
            for p in range(dim):
                b[h, p] += w * jac[p] * r
                for q in range(dim):
                    a[h, p, q] += w * jac[p] * jac[q]
            sse[h] += w * r * r
            used[h] += 1


#: the compiled :func:`normal_equations_python`, or None without numba
normal_equations = compile_loop(normal_equations_python)


def warm_up() -> None:
    """Compile (or load from the cache) the functions above now, not at their first call."""
    if window_sums is not None:
        window_sums(np.zeros(2, np.uint8), np.zeros((1, 1), np.int64), np.zeros(1, np.int64),
                    np.zeros(1, np.int64), np.zeros(1, np.int32))
    if normal_equations is not None:
        for dim in (3, 4):
            normal_equations(np.zeros((1, 3)), np.zeros(1), np.zeros((1, 2)), np.ones(1, bool),
                             np.zeros((1, 1), np.int32), np.zeros(33 * 33, np.int16),
                             np.zeros(1, np.float32), 0, 32, np.zeros(6), 3, 3, 1.0, 0.0, 1.0,
                             1.0, np.zeros((1, dim, dim)), np.zeros((1, dim)), np.zeros(1),
                             np.zeros(1, np.int64))
