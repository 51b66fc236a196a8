"""
Pose refinement against the map itself (beyond the paper).

The paper stops at the RANSAC pose relative to a node's virtual scan, so its accuracy is bounded
by the virtual scan's sampling. Here the winning hypotheses are refined by Gauss-Newton on the
signed distance of the scan endpoints to the map's wall surface (``verify.py`` then checks them
by ray casting).

Where the wall surface lies inside the occupied cells depends on how the map was made: at the
boundary of the occupied cells for scans ray-cast on the same grid (the paper's Table 1 simulation
stops at the first occupied cell's boundary), about half a cell deeper for real scans on maps
built from real scans (beams end anywhere inside a wall cell). ``refine_poses`` can estimate that
offset from the scan itself (``estimate_depth``): one more unknown, the same for every point, with
a weak prior, observable whenever walls are seen from more than one side. Guessing it wrong would
cost about half a cell of accuracy.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from . import kernels
from ..mapping.distance import feature_transform, squared_distances
from ..transforms import Pose2, rotation, wrap_angle

#: lattice points per cell side of the precomputed signed distance
SUBDIVISION = 2
#: side of the lattice's tiles, lattice points (a power of two)
TILE = 32
_TILE_SHIFT = TILE.bit_length() - 1
#: tiles of a block of the build (the distance transforms run one block, plus its halo, at a time)
_BLOCK_TILES = 48
#: ``exp(-x^2 / 2)`` is exactly 0.0 in float64 beyond this x (``exp(-746)`` underflows)
EXP_UNDERFLOW = math.sqrt(2.0 * 746.0)
#: the tile table's ids of the two constant tiles: every point at least ``reach`` outside the
#: walls, every point at least ``reach`` inside them
FAR, DEEP = 0, 1


def exact_reach(score_sigma: float = 0.05, truncate: float = 0.3) -> float:
    """
    Return how far (m) from the wall surface its stored distance must be exact.

    Every use of it then gives the same numbers as an unclamped one: Gauss-Newton uses only the
    residuals within its first truncation radius ``truncate``, the evidence its fractions within
    0.15 m, and the explained fraction ``exp(-r^2 / 2 score_sigma^2)`` is exactly 0.0 in float64
    beyond :data:`EXP_UNDERFLOW` sigmas.
    """
    return max(EXP_UNDERFLOW * float(score_sigma), float(truncate), 0.15)


@dataclass(frozen=True, eq=False)
class SurfaceModel:
    """
    Signed distance to the boundary of occupied cells, shifted by ``depth`` metres.

    The exact distance is precomputed on a lattice of half-cell spacing: the closest point of a
    union of lattice-aligned boxes to a lattice point is itself a lattice point, so its squared
    distance in lattice units is an integer ``k``, and two Euclidean distance transforms give
    it exactly. Between lattice points it is interpolated bilinearly (exact along straight
    axis-aligned walls, within a few hundredths of a cell near corners), which makes a query
    four table look-ups per point.

    Storage grows with the walls, not with the map: ``k`` is stored signed (negative inside
    walls) as int16 (int32 if the reach needs it), exact up to ``reach`` metres from the
    surface and clamped beyond (see :func:`exact_reach`: no use of the model can tell); the
    lattice is cut into :data:`TILE` x :data:`TILE` tiles (stored with one more row and column
    so that the four corners of a look-up lie in one tile), and a tile that lies wholly beyond
    the reach outside the walls (open space, unknown space between buildings) or inside them is
    not stored: the tile table points it at one shared constant tile. A table of the float32
    distance of every stored ``k`` turns codes into the very values of a dense float32 lattice.
    """

    origin: Pose2
    resolution: float
    depth: float                # metres behind the occupied-cell boundary where the surface lies
    shape: tuple[int, int]      # (2H + 1, 2W + 1) lattice points
    tiles: np.ndarray           # (tile rows, tile cols) int32: the stored tile of each tile
    codes: np.ndarray           # (tiles * (TILE + 1)^2,) signed squared distances, lattice units
    values: np.ndarray          # (2 cap + 1,) float32 signed distance in cells of code - cap
    cap: int                    # the largest stored |code| (the clamp)

    @classmethod
    def from_occupancy(cls, occupied: np.ndarray, resolution: float, origin: Pose2,
                       surface_depth_cells: float = 0.5,
                       reach: float | None = None) -> 'SurfaceModel':
        """
        Return the model of the ``occupied`` cells, exact within ``reach`` metres of walls.

        ``reach`` defaults to :func:`exact_reach` of the localizer's defaults.
        """
        occupied = np.asarray(occupied, dtype=bool)
        if not occupied.any():
            raise ValueError('map has no occupied cells: nothing to refine against')
        res = float(resolution)
        reach = exact_reach() if reach is None else float(reach)
        # clamp in lattice units: exact wherever an interpolated value, shifted by at most a
        # cell of wall offset, can lie within reach (corners within 0.71 cells of the point)
        limit = int(math.ceil(SUBDIVISION * (reach / res + 1.71))) + 1
        cap = limit * limit
        # codes + cap index the value table: int16 while that sum fits
        dtype = np.int16 if 2 * cap <= np.iinfo(np.int16).max else np.int32
        h, w = occupied.shape
        shape = (SUBDIVISION * h + 1, SUBDIVISION * w + 1)
        n_ti = -(-(shape[0] - 1) // TILE)
        n_tj = -(-(shape[1] - 1) // TILE)
        tiles = np.empty((n_ti, n_tj), dtype=np.int32)
        side = TILE + 1
        stored = [np.full((1, side, side), cap, dtype), np.full((1, side, side), -cap, dtype)]
        count = 2
        for ti0 in range(0, n_ti, _BLOCK_TILES):
            for tj0 in range(0, n_tj, _BLOCK_TILES):
                nti, ntj = min(_BLOCK_TILES, n_ti - ti0), min(_BLOCK_TILES, n_tj - tj0)
                i0, j0 = ti0 * TILE, tj0 * TILE
                q = _signed_codes(occupied, i0, i0 + nti * TILE + 1, j0, j0 + ntj * TILE + 1,
                                  limit, dtype)
                rs, cs = q.strides
                view = np.lib.stride_tricks.as_strided(
                    q, (nti, ntj, side, side), (TILE * rs, TILE * cs, rs, cs), writeable=False)
                far = (view == cap).all(axis=(2, 3))
                deep = (view == -cap).all(axis=(2, 3))
                keep = ~far & ~deep
                ids = np.where(far, FAR, DEEP).astype(np.int32)
                ids[keep] = count + np.arange(int(keep.sum()), dtype=np.int32)
                count += int(keep.sum())
                if keep.any():
                    stored.append(view[keep])
                tiles[ti0:ti0 + nti, tj0:tj0 + ntj] = ids
        codes = np.concatenate(stored).reshape(-1)
        k = np.arange(-cap, cap + 1, dtype=np.int64)
        values = ((np.sign(k) * np.sqrt(np.abs(k).astype(np.float64))) / SUBDIVISION).astype(
            np.float32)
        return cls(origin=tuple(float(v) for v in origin), resolution=res,
                   depth=float(surface_depth_cells) * res, shape=shape, tiles=tiles,
                   codes=codes, values=values, cap=cap)

    @property
    def nbytes(self) -> int:
        """Bytes held by the model's arrays."""
        return int(self.tiles.nbytes + self.codes.nbytes + self.values.nbytes)

    def lattice_values(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Return the signed distance (float32, cells) at lattice points ``(i, j)`` (in range)."""
        tid = self.tiles[i >> _TILE_SHIFT, j >> _TILE_SHIFT].astype(np.int64)
        k = tid * (TILE + 1) ** 2 + (i & (TILE - 1)) * (TILE + 1) + (j & (TILE - 1))
        return self.values[self.codes[k].astype(np.int64) + self.cap]

    def signed_distance(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Signed distance (m) of map-frame points to the wall surface, its gradient, validity.

        Positive in free space, negative inside walls; points off the grid are invalid.
        """
        ox, oy, oyaw = self.origin
        rot = rotation(oyaw)
        scale = SUBDIVISION / self.resolution
        g = (np.asarray(pts, float).reshape(-1, 2) - (ox, oy)) @ rot * scale
        h, w = self.shape
        j0 = np.floor(g[:, 0]).astype(np.int64)
        i0 = np.floor(g[:, 1]).astype(np.int64)
        valid = (j0 >= 0) & (j0 < w - 1) & (i0 >= 0) & (i0 < h - 1)
        s = np.zeros(len(g))
        grad = np.zeros((len(g), 2))
        if not valid.any():
            return s, grad, valid
        i, j = i0[valid], j0[valid]
        fx, fy = g[valid, 0] - j, g[valid, 1] - i
        # the four corners lie in the tile of (i, j), which holds one more row and column
        tid = self.tiles[i >> _TILE_SHIFT, j >> _TILE_SHIFT].astype(np.int64)
        side = TILE + 1
        k = tid * side * side + (i & (TILE - 1)) * side + (j & (TILE - 1))
        codes, values, cap = self.codes, self.values, self.cap
        a = values[codes[k] + cap]
        b = values[codes[k + 1] + cap]
        c = values[codes[k + side] + cap]
        d = values[codes[k + side + 1] + cap]
        bottom = a + fx * (b - a)
        top = c + fx * (d - c)
        s[valid] = (bottom + fy * (top - bottom)) * self.resolution + self.depth
        dcol = (b - a) + fy * ((d - c) - (b - a))
        drow = top - bottom
        grad[valid] = np.column_stack((dcol, drow)) * SUBDIVISION @ rot.T
        return s, grad, valid

    def explained(self, pts: np.ndarray, offset=0.0, sigma: float = 0.05) -> np.ndarray:
        """
        Return the fraction of a scan explained: ``mean exp(-r^2 / 2 sigma^2)`` over its points.

        ``pts`` (..., N, 2) map-frame points; ``offset`` (...) metres added to their signed
        distances (the wall surface estimated deeper); points off the grid explain nothing.
        """
        pts = np.asarray(pts, float)
        shape = pts.shape[:-1]
        r, _, valid = self.signed_distance(pts)
        r = r.reshape(shape) + np.asarray(offset, float)[..., None]
        e = np.where(valid.reshape(shape), np.exp(-0.5 * (r / sigma) ** 2), 0.0)
        return e.mean(axis=-1) if shape[-1] else np.zeros(shape[:-1])


def _signed_codes(occupied: np.ndarray, i0: int, i1: int, j0: int, j1: int, limit: int,
                  dtype) -> np.ndarray:
    """
    Return the signed squared distances (lattice units) of lattice rows ``i0:i1``, cols ``j0:j1``.

    ``+k`` outside the walls (to the nearest lattice point touching an occupied sub-cell),
    ``-k`` inside (to the nearest touching a free one), 0 on the boundary (touching both);
    clamped at ``limit^2`` (beyond the limit inside: ``-limit^2``). Points beyond the lattice
    hold the clamp. Computed on the block plus a halo of ``limit`` lattice points, so every
    distance up to the limit is exact.
    """
    h, w = occupied.shape
    lh, lw = SUBDIVISION * h + 1, SUBDIVISION * w + 1
    cap = limit * limit
    out = np.full((i1 - i0, j1 - j0), cap, dtype=dtype)
    bi1, bj1 = min(i1, lh), min(j1, lw)
    if bi1 <= i0 or bj1 <= j0:
        return out
    # the window: block plus halo, in lattice points, within the lattice
    wi0, wi1 = max(i0 - limit, 0), min(bi1 + limit, lh)
    wj0, wj1 = max(j0 - limit, 0), min(bj1 + limit, lw)
    occ_v, free_v = _lattice_masks(occupied, wi0, wi1, wj0, wj1)
    # The nearest occupied point of a point outside the walls is a boundary point (it touches
    # a free sub-cell too: the straight line to it crosses free sub-cells only, the grid being
    # convex), and so is the nearest free point of a point inside them: one transform to the
    # boundary gives both distances.
    boundary = occ_v & free_v
    rows, cols = slice(i0 - wi0, bi1 - wi0), slice(j0 - wj0, bj1 - wj0)
    block = out[:bi1 - i0, :bj1 - j0]
    if boundary.any():
        ft = feature_transform(boundary)
        block[...] = np.minimum(squared_distances(ft, rows.start, rows.stop, cols.start,
                                                  cols.stop), cap)
        del ft
    inside = occ_v[rows, cols] & ~free_v[rows, cols]
    block[inside] = -block[inside]
    return out


def _lattice_masks(occupied: np.ndarray, i0: int, i1: int, j0: int,
                   j1: int) -> tuple[np.ndarray, np.ndarray]:
    """
    Lattice points ``i0:i1, j0:j1`` touching an occupied / a free sub-cell.

    Lattice point (i, j) touches the sub-cells (i - 1 .. i, j - 1 .. j) of the grid divided
    :data:`SUBDIVISION` times; outside the grid there is neither.
    """
    h, w = occupied.shape
    # sub-cell rows i0 - 1 .. i1 - 1, columns j0 - 1 .. j1 - 1 (outside the grid: neither)
    occ = np.zeros((i1 - i0 + 1, j1 - j0 + 1), dtype=bool)
    known = np.zeros_like(occ)
    sr0, sr1 = max(i0 - 1, 0), min(i1, SUBDIVISION * h)
    sc0, sc1 = max(j0 - 1, 0), min(j1, SUBDIVISION * w)
    if sr1 > sr0 and sc1 > sc0:
        sub_r = np.arange(sr0, sr1) // SUBDIVISION
        sub_c = np.arange(sc0, sc1) // SUBDIVISION
        cells = occupied[sub_r[0]:sub_r[-1] + 1, sub_c[0]:sub_c[-1] + 1]
        occ[sr0 - (i0 - 1):sr1 - (i0 - 1), sc0 - (j0 - 1):sc1 - (j0 - 1)] = \
            cells[sub_r - sub_r[0]][:, sub_c - sub_c[0]]
        known[sr0 - (i0 - 1):sr1 - (i0 - 1), sc0 - (j0 - 1):sc1 - (j0 - 1)] = True
    free = known & ~occ
    return _touches(occ), _touches(free)


def _touches(mask: np.ndarray) -> np.ndarray:
    """Lattice points with one of their four sub-cells in ``mask`` (one fewer each way)."""
    return mask[:-1, :-1] | mask[:-1, 1:] | mask[1:, :-1] | mask[1:, 1:]


@dataclass(frozen=True)
class RefineResult:
    pose: Pose2                 # refined laser pose in the map frame
    covariance: np.ndarray      # (3, 3) of (x, y, yaw)
    iterations: int
    depth: float = 0.0          # wall surface behind the occupied-cell boundary, metres
    explained: float = 0.0      # mean of exp(-r^2 / 2 sigma^2): the fraction of the scan explained


def refine_pose(surface: SurfaceModel, points: np.ndarray, pose: Pose2, **kwargs) -> RefineResult:
    """Refine one laser pose on the wall surface (see :func:`refine_poses`)."""
    return refine_poses(surface, points, np.array([pose], float), **kwargs)[0]


def refine_poses(surface: SurfaceModel, points: np.ndarray, poses: np.ndarray, *,
                 iterations: int = 12, huber: float = 0.1,
                 truncate: tuple[float, float] = (0.3, 0.1), min_sigma: float = 0.005,
                 estimate_depth: bool = False, depth_prior: float = 0.25,
                 score_sigma: float = 0.05) -> list[RefineResult]:
    """
    Gauss-Newton on ``sum rho(sdf(R p + t) + delta)`` for several laser poses at once (batched).

    The truncation radius shrinks from ``truncate[0]`` to ``truncate[1]`` so clutter and unmapped
    objects drop out; Huber weights soften the rest. The covariance is ``sigma^2 (J^T W J)^-1``
    (the pose block). All hypotheses share one signed-distance look-up per iteration, which is what
    makes refining many hypotheses affordable.
    ``estimate_depth``: ``delta``, the wall surface's offset behind the surface model's own depth,
    is a fourth unknown per pose, starting at 0, with a Gaussian prior of ``depth_prior`` cells
    and kept within the occupied cell; otherwise it stays 0. ``explained`` in each result is
    ``mean exp(-r^2 / 2 score_sigma^2)`` over all points at the final pose.
    """
    pts = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 2))
    x = np.array(poses, float).reshape(-1, 3)
    n_h, n_p = len(x), len(pts)
    dim = 4 if estimate_depth else 3
    res = surface.resolution
    lo, hi = -surface.depth, res - surface.depth           # the surface stays inside its cell
    delta = np.zeros(n_h)
    prior = (1.0 / (depth_prior * res)) ** 2 if estimate_depth else 0.0
    jtj = np.tile(np.eye(dim), (n_h, 1, 1))
    sigma2 = np.full(n_h, min_sigma ** 2)
    active = np.ones(n_h, dtype=bool)
    done_iters = np.zeros(n_h, dtype=int)
    for it in range(1, iterations + 1):
        if n_p < 3 or not active.any():
            break
        trunc = truncate[0] + (truncate[1] - truncate[0]) * min(
            1.0, (it - 1) / max(iterations // 2, 1))
        a, b, sse, used = _normal_equations(surface, pts, x, delta, active, dim, trunc, huber)
        if estimate_depth:      # prior on delta, in units of the current residual variance
            a[:, 3, 3] += prior * sigma2
            b[:, 3] += prior * sigma2 * delta
        enough = used >= 3
        step = np.zeros((n_h, dim))
        ok = active & enough
        if ok.any():
            step[ok] = -np.linalg.solve(a[ok] + 1e-9 * np.eye(dim), b[ok][..., None])[..., 0]
            jtj[ok] = a[ok]
            sigma2[ok] = np.maximum(sse[ok] / np.maximum(used[ok] - dim, 1), min_sigma ** 2)
        x += step[:, :3]
        x[:, 2] = wrap_angle(x[:, 2])
        if estimate_depth:
            delta = np.clip(delta + step[:, 3], lo, hi)
        done_iters[ok] = it
        active &= enough & ((np.hypot(step[:, 0], step[:, 1]) >= 1e-5)
                            | (np.abs(step[:, 2]) >= 1e-6))
    explained = surface.explained(_transform(x, pts)[0], delta, score_sigma)
    out = []
    for k in range(n_h):
        try:
            cov = sigma2[k] * np.linalg.inv(jtj[k])[:3, :3]
        except np.linalg.LinAlgError:
            cov = np.diag([1e3, 1e3, 1e3])
        out.append(RefineResult(
            pose=(float(x[k, 0]), float(x[k, 1]), float(x[k, 2])), covariance=cov,
            iterations=int(done_iters[k]), depth=float(surface.depth + delta[k]),
            explained=float(explained[k])))
    return out


def _normal_equations(surface: SurfaceModel, pts: np.ndarray, x: np.ndarray, delta: np.ndarray,
                      active: np.ndarray, dim: int, trunc: float, huber: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Return ``(a, b, sse, used)``: ``J^T W J``, ``J^T W r``, ``sum w r^2`` and the residuals used.

    Per pose (H, dim, dim), (H, dim), (H,), (H,) of one Gauss-Newton step: the residuals are the
    points' signed distances (plus ``delta``) within ``trunc``, Huber-weighted beyond ``huber``.
    Compiled in one pass when numba is there (``kernels.normal_equations``, the active poses
    only), else in numpy.
    """
    n_h, n_p = len(x), len(pts)
    if kernels.normal_equations is not None:
        a, b = np.zeros((n_h, dim, dim)), np.zeros((n_h, dim))
        sse, used = np.zeros(n_h), np.zeros(n_h, np.int64)
        ox, oy, oyaw = surface.origin
        frame = np.array([ox, oy, np.cos(oyaw), np.sin(oyaw),
                          SUBDIVISION / surface.resolution, float(SUBDIVISION)])
        kernels.normal_equations(x, delta, pts, active, surface.tiles, surface.codes,
                                 surface.values, surface.cap, TILE, frame, surface.shape[0],
                                 surface.shape[1], surface.resolution, surface.depth,
                                 float(trunc), float(huber), a, b, sse, used)
        return a, b, sse, used
    world, rel = _transform(x, pts)
    r, g, valid = surface.signed_distance(world.reshape(-1, 2))
    r = r.reshape(n_h, n_p) + delta[:, None]
    g, valid = g.reshape(n_h, n_p, 2), valid.reshape(n_h, n_p)
    use = valid & (np.abs(r) < trunc)
    absr = np.abs(r)
    wts = np.where(use, np.where(absr <= huber, 1.0, huber / np.maximum(absr, 1e-12)), 0.0)
    cols = [g, (g[..., 1] * rel[..., 0] - g[..., 0] * rel[..., 1])[..., None]]
    if dim == 4:
        cols.append(np.ones((n_h, n_p, 1)))
    jac = np.concatenate(cols, axis=2)
    a = np.einsum('hn,hni,hnj->hij', wts, jac, jac)
    b = np.einsum('hn,hni,hn->hi', wts, jac, r)
    return a, b, np.sum(wts * r ** 2, axis=1), use.sum(axis=1)


def _transform(poses: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, N, 2) points moved by each pose, and the rotated points (relative to each origin)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    rel = np.stack((c[:, None] * pts[:, 0] - s[:, None] * pts[:, 1],
                    s[:, None] * pts[:, 0] + c[:, None] * pts[:, 1]), axis=2)
    return rel + poses[:, None, :2], rel
