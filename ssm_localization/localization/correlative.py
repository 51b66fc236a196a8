"""
Correlative scan matching by branch and bound over a map (beyond the paper).

The exhaustive search Cartographer uses to relocalize (Hess et al. 2016, after Olson 2009): a
scan's points, rotated by each candidate yaw, are scored on a likelihood grid of the map (the
mean over points of ``exp(-d^2 / 2 sigma^2)``, ``d`` the distance of a point's cell to the nearest
occupied cell on a surface, :func:`surface_cells`); translations are searched by branch and bound
on precomputed grids whose level ``k`` holds the maximum of the likelihood over the ``2^k x 2^k``
cells anchored at each cell, so the score of a window of translations bounds the score of every
translation inside it.

Here the search runs best-first in batches (numpy): the most promising windows of the pool are
split into their four children together, leaves (single cells) set the bound, and windows whose
bound falls below ``max(min_score, ratio * best)`` are pruned. With ``ratio < 1`` it also returns
the rivals of the best pose (every leaf within that ratio), which is what an ambiguity test needs.

The localizer searches only a few yaws (those of its spectral hypotheses and their flips) over
the whole map, and the tracker a small window around its prediction; ``bench localize --peer``
runs the full search (every yaw at 1 degree) as the reference.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import time

import numpy as np
from scipy.ndimage import binary_erosion

from . import kernels
from ..mapping.distance import clamped_squared_distance
from ..mapping.occupancy import OccupancyMap
from ..threads import checked_workers, in_parts
from ..transforms import wrap_angle

#: likelihood values are stored as uint8 (0..255)
_SCALE = 255.0
#: the search expands the best windows of its pool, about this many batches of them, before it
#: looks at the rest again (``search``'s default ``hot_batches``)
HOT_BATCHES = 4
#: windows scored at a time, so that their cell indices (8 bytes per window and point) stay in
#: the cache; of 1024-32768 on the campus's captured searches 8192 was the fastest
_SCORE_CHUNK = 8192
#: a compiled scoring pass of at least this many look-ups (windows x points, about a
#: millisecond) is split among the grid's ``workers`` threads: a thread's start and join cost
#: tens of microseconds. At 2^18 Intel's and ACES' queries took 1-2 % longer, at 2^20 no
#: longer, and office_30m's 0.91 of one thread's time (docs/EXPERIMENTS.md, 2026-12-07)
_SPLIT_LOOKUPS = 1 << 20
#: float32 holds every integer below this exactly (sums of up to 65 793 points' likelihoods)
_FLOAT32_EXACT = 1 << 24
_EMPTY_POOL = (np.zeros(0, np.int64), np.zeros(0))


@dataclass(frozen=True)
class CorrelativeResult:
    """
    Leaves of one search, best first.

    ``poses`` (L, 3) map-frame sensor poses, ``scores`` (L,) their mean likelihood in [0, 1];
    ``complete`` is False when the time budget stopped the search early.
    """

    poses: np.ndarray
    scores: np.ndarray
    complete: bool
    regions: np.ndarray | None = None       # (L,) the region of each leaf (regional search)

    @property
    def best_pose(self) -> tuple[float, float, float] | None:
        return tuple(float(v) for v in self.poses[0]) if len(self.poses) else None

    @property
    def best_score(self) -> float:
        return float(self.scores[0]) if len(self.scores) else 0.0


class CorrelativeGrid:
    """
    The precomputed grids of one map; :meth:`search` runs one branch-and-bound search.

    ``sigma`` (m) is the width of the likelihood, ``depth`` the number of coarser levels (the top
    level's windows are ``2**depth`` cells wide), ``max_range`` (m) the farthest scan point used
    (farther points are dropped; the grids are padded by this much). Sensor positions are
    restricted to free cells (``free_thresh``). ``coarsen`` > 1 searches on cells that many map
    cells wide (the likelihood of a coarse cell is the best of its map cells, a coarse cell is
    free when one of them is): the leaves are that coarse, the search that much cheaper.
    ``workers``: threads the compiled scoring of a large set of windows is split among (-1: every
    core); the scores, and so the leaves, are the same with any number.
    """

    def __init__(self, occ_map: OccupancyMap, *, occupied_thresh: int = 65, free_thresh: int = 25,
                 sigma: float = 0.1, depth: int = 4, max_range: float = 30.0,
                 coarsen: int = 1, workers: int = 1) -> None:
        if depth < 1 or coarsen < 1:
            raise ValueError(f'CorrelativeGrid: depth and coarsen must be >= 1, got {depth}, '
                             f'{coarsen}')
        self.workers = checked_workers(workers, 'CorrelativeGrid')
        if not (sigma > 0 and max_range > 0):
            raise ValueError('CorrelativeGrid: sigma and max_range must be > 0')
        self.resolution = occ_map.resolution * coarsen
        self.origin = occ_map.origin
        self.depth = int(depth)
        self.max_range = float(max_range)
        occ = surface_cells(occ_map.occupied_mask(occupied_thresh))
        lik = _block_reduce(likelihood_grid(occ, occ_map.resolution, sigma), coarsen, np.max)
        del occ
        free = _block_reduce(occ_map.free_mask(free_thresh), coarsen, np.any)
        self.height, self.width = lik.shape
        h, w = lik.shape
        # Layout of the level grids, flat: rows of `_left` cells, the map row, `pad` cells. Every
        # point of a scan taken from inside the map lands within `pad` cells of it, so a point
        # right of the map reads the padding of its row and one left of the `_left` cells wraps
        # into the padding of the row before (both 0); the `_left` columns and `_top` rows hold
        # the windows of the coarser levels that reach into the map from the left and from
        # below. Points further below or above fall off the flat array, and the look-ups clip
        # them to its first or last cell (both 0). Exactly the values of a grid padded by `pad`
        # all round, at (h + 2^depth) (w + 2^depth + pad) cells instead of (h + 2 pad) (w + 2 pad).
        # Within each row, level k is stored by phase: the cells of columns 0, 2^k, 2^(k+1), ...
        # first, then those of columns 1, 2^k + 1, ... (the row's length a multiple of 2^depth).
        # Windows of level k are anchored at multiples of 2^k, so one point's cells in a row of
        # windows are neighbours in memory: the look-ups of a search stay in cache.
        self.pad = pad = (1 << self.depth) + int(math.ceil(self.max_range / self.resolution)) + 2
        self._top = self._left = 1 << self.depth
        self._wp = -(-(self._left + w + pad) // self._left) * self._left
        grid = np.zeros((self._top + h, self._wp), np.uint8)
        grid[self._top:, self._left:self._left + w] = lik
        del lik
        self._levels = [grid.ravel()]
        for k in range(1, self.depth + 1):
            grid = _window_max(grid, 1 << (k - 1))
            self._levels.append(_by_phase(grid, 1 << k))
        # Windows of level k are only ever anchored at multiples of 2^k (the top level's tile
        # the map, children split their parent), so whether a window holds a free cell is
        # kept once per 2^k x 2^k block: 4/3 of a byte per cell for all levels together.
        self._free = [free]
        for k in range(1, self.depth + 1):
            self._free.append(_block_reduce(self._free[-1], 2, np.any))
        kernels.warm_up()       # compiled (or loaded from the cache) before the first search

    # ------------------------------------------------------------------ geometry
    def _grid_yaws(self, yaws) -> np.ndarray:
        return np.asarray(yaws, float).ravel() - self.origin[2]

    def _to_grid(self, xy: np.ndarray) -> np.ndarray:
        """Map-frame points -> continuous grid coordinates (col, row)."""
        ox, oy, oyaw = self.origin
        c, s = math.cos(oyaw), math.sin(oyaw)
        d = np.asarray(xy, float).reshape(-1, 2) - (ox, oy)
        return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1])) \
            / self.resolution

    def poses_of(self, k: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                 thetas: np.ndarray) -> np.ndarray:
        """Map-frame poses of candidates (yaw index ``k``, sensor cell ``rows, cols``)."""
        ox, oy, oyaw = self.origin
        c, s = math.cos(oyaw), math.sin(oyaw)
        u = (np.asarray(cols) + 0.5) * self.resolution
        v = (np.asarray(rows) + 0.5) * self.resolution
        yaw = wrap_angle(thetas[np.asarray(k, int)] + oyaw)
        return np.column_stack((ox + c * u - s * v, oy + s * u + c * v, yaw))

    # ------------------------------------------------------------------ search
    def search(self, points: np.ndarray, *, yaws=None, angular_step: float = math.radians(1.0),
               window: tuple[float, float, float, float] | None = None, min_score: float = 0.5,
               ratio: float = 1.0, max_leaves: int = 256, batch: int = 2048,
               hot_batches: int = HOT_BATCHES, budget_s: float | None = None,
               regions: tuple[np.ndarray, np.ndarray] | None = None,
               region_ratio: float | None = None) -> CorrelativeResult:
        """
        Best poses of the sensor for ``points`` (N, 2) given in the sensor frame.

        ``yaws``: map-frame yaws to try (default: the full turn every ``angular_step``);
        ``window``: ``(x_min, y_min, x_max, y_max)`` map-frame box of sensor positions (default:
        the whole map); leaves scoring at least ``max(min_score, ratio * best)`` are returned,
        best first, at most ``max_leaves``. ``budget_s`` stops the search early (``complete``
        False) once that much time has passed. ``batch``: the most promising windows expanded per
        numpy step (larger batches: fewer Python steps, a little more work each; 2048 cut the
        search's p95 by a quarter on the real maps against 512, with the same answers);
        ``hot_batches``: about this many batches of the best windows are expanded before the
        rest of the pool is pruned and split again (the leaves are the same for any two).
        ``regions``: ``(labels, allowed)``, the region of each top-level window (-1: none) and
        which yaws are searched in which region ((K, R) bool): yaw ``k`` only in the windows of
        the regions ``r`` with ``allowed[k, r]`` (``regions.py``); default: every yaw everywhere.
        ``region_ratio`` (with ``regions``): besides the leaves within ``ratio`` of the best,
        every region is searched down to its own best leaf as long as that scores
        ``region_ratio`` of the best anywhere (a wall-dense region that matches every scan
        fairly well cannot hide the other regions' best places); the result then says each
        leaf's region.
        """
        if batch < 1 or hot_batches < 1:
            raise ValueError(f'CorrelativeGrid.search: batch and hot_batches must be >= 1, got '
                             f'{batch}, {hot_batches}')
        t0 = time.perf_counter()
        pts = np.asarray(points, float).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= self.max_range]
        if yaws is None:
            n = max(int(round(2.0 * math.pi / angular_step)), 1)
            yaws = self.origin[2] + 2.0 * math.pi * np.arange(n) / n
        thetas = self._grid_yaws(yaws)
        if len(pts) == 0 or len(thetas) == 0:
            return _empty()
        offsets = self._offsets(pts, thetas)
        bases: dict[int, np.ndarray] = {}

        def base(level: int) -> np.ndarray:
            if level not in bases:
                bases[level] = self._base(level, *offsets)
            return bases[level]

        norm = 1.0 / (_SCALE * len(pts))
        r0, r1, c0, c1 = self._window_cells(window)
        if r0 >= r1 or c0 >= c1:
            return _empty()
        top = 1 << self.depth
        rr, cc = np.meshgrid(np.arange(r0 - r0 % top, r1, top), np.arange(c0 - c0 % top, c1, top),
                             indexing='ij')
        rr, cc = rr.ravel(), cc.ravel()
        ok = self._any_free(self.depth, rr, cc)
        rr, cc = rr[ok], cc[ok]
        n_k = len(thetas)
        if regions is None:
            k = np.repeat(np.arange(n_k), len(rr))
            r = np.tile(rr, n_k)
            c = np.tile(cc, n_k)
            top_region = 0
        else:
            lab = regions[0][rr >> self.depth, cc >> self.depth]
            k, at = _allowed_windows(lab, regions[1])
            r, c, top_region = rr[at], cc[at], lab[at]
        ub = self._score(self.depth, base(self.depth), k, r, c, norm)
        best = -1.0
        # per region: each region's best leaf (one region, the whole map, without regions)
        labels = regions[0] if regions is not None and region_ratio is not None else None
        n_reg = regions[1].shape[1] if labels is not None else 1
        best_r = np.full(max(n_reg, 1), -1.0)
        floor = region_ratio if labels is not None else ratio

        def region(r, c):
            return labels[r >> self.depth, c >> self.depth] if labels is not None else 0

        # A window of the pool is one int64 (its yaw, cell, level and region, _WindowKeys) and
        # its bound: each step of the pool copies two arrays, not five. A window's region is
        # its top-level window's, so its children inherit it with the rest of the key.
        keys = _WindowKeys(self.height + top, self.width + top, n_k, self.depth, n_reg)
        key = keys.pack(k, r, c, self.depth, top_region if labels is not None else 0)

        def bound(key, reg=None):
            """Return the bound of the windows ``key`` (or of those in regions ``reg``)."""
            if labels is None:
                return max(min_score, ratio * best)
            # leaves within `ratio` of the best anywhere, and each region's own best
            reg = keys.region(key) if reg is None else reg
            return np.maximum(max(min_score, floor * best),
                              np.minimum(ratio * best, best_r[reg]))

        leaves: list[np.ndarray] = []
        complete = True

        def pruned(key, ub):
            """Return the windows ``key, ub`` whose bound reaches the current one."""
            keep = ub >= bound(key)
            return key[keep], ub[keep]

        # The pool in two parts: `hot`, the windows whose bound is at least `cut`, is expanded
        # batch by batch; `cold` (the rest, and children below `cut`) waits until `hot` is empty
        # and is then pruned and split again. Each step so works on a few batches' windows, not
        # on the whole pool (up to 10^5 windows on a campus-scale map).
        cold = [(key, ub)]
        hot = _EMPTY_POOL
        cut = -math.inf
        while True:
            if len(hot[0]):
                key, ub = pruned(*hot)
                if not len(key):
                    hot = _EMPTY_POOL
                    continue
            else:
                if not cold:
                    break
                key, ub = pruned(np.concatenate([p[0] for p in cold]),
                                 np.concatenate([p[1] for p in cold]))
                if not len(key):
                    break
                cold, cut = [], -math.inf
                if len(key) > hot_batches * batch:
                    cut = float(np.partition(ub, len(ub) - hot_batches * batch)
                                [len(ub) - hot_batches * batch])
                    up = ub >= cut
                    cold = [(key[~up], ub[~up])]
                    key, ub = key[up], ub[up]
            if budget_s is not None and time.perf_counter() - t0 > budget_s:
                complete = False
                break
            if len(key) > batch:
                take = np.argpartition(-ub, batch - 1)[:batch]
                rest = np.ones(len(key), bool)
                rest[take] = False
            else:
                take = np.arange(len(key))
                rest = np.zeros(len(key), bool)
            new_key, new_ub = [key[rest]], [ub[rest]]
            lev = keys.level(key[take])
            for level in np.unique(lev):
                parent = key[take[lev == level]]
                k, r, c = keys.yaw(parent), keys.row(parent), keys.col(parent)
                half = 1 << (int(level) - 1)
                ck = np.repeat(k, 4)
                cr = np.repeat(r, 4) + np.tile((0, 0, half, half), len(parent))
                cc_ = np.repeat(c, 4) + np.tile((0, half, 0, half), len(parent))
                # children (windows of `half` cells) that overlap the searched rectangle
                inside = (cr < r1) & (cr + half > r0) & (cc_ < c1) & (cc_ + half > c0)
                inside[inside] = self._any_free(int(level) - 1, cr[inside], cc_[inside])
                ck, cr, cc_ = ck[inside], cr[inside], cc_[inside]
                sc = self._score(int(level) - 1, base(int(level) - 1), ck, cr, cc_, norm)
                child = keys.children(parent, half)[inside]
                if level == 1:
                    good = sc >= bound(child)
                    if good.any():
                        leaves.append(np.column_stack((ck[good], cr[good], cc_[good], sc[good])))
                        best = max(best, float(sc[good].max()))
                        if labels is not None:
                            np.maximum.at(best_r, keys.region(child[good]), sc[good])
                else:
                    up = sc >= cut
                    new_key.append(child[up])
                    new_ub.append(sc[up])
                    cold.append((child[~up], sc[~up]))
            hot = (np.concatenate(new_key), np.concatenate(new_ub))
        if not leaves:
            return _empty(complete)
        lv = np.concatenate(leaves)
        rows_, cols_ = lv[:, 1].astype(np.int64), lv[:, 2].astype(np.int64)
        lv = lv[lv[:, 3] >= bound(None, region(rows_, cols_))]
        # best first; ties by yaw, row and column, not by when the search found them
        order = np.lexsort((lv[:, 2], lv[:, 1], lv[:, 0], -lv[:, 3]))
        if labels is None:
            lv = lv[order[:max_leaves]]
            leaf_regions = None
        else:
            # the best leaves, and the best of each region however far down it ranks
            lab = region(lv[order, 1].astype(np.int64), lv[order, 2].astype(np.int64))
            first = np.zeros(len(order), bool)
            first[np.unique(lab, return_index=True)[1]] = True
            first[:max_leaves] = True
            lv = lv[order[first]]
            leaf_regions = lab[first]
        poses = self.poses_of(lv[:, 0].astype(int), lv[:, 1], lv[:, 2], thetas)
        if window is not None:      # the searched cells cover the box; keep what lies in it
            x0, y0, x1, y1 = window
            inside = ((poses[:, 0] >= x0) & (poses[:, 0] <= x1) & (poses[:, 1] >= y0)
                      & (poses[:, 1] <= y1))
            poses, lv = poses[inside], lv[inside]
            leaf_regions = leaf_regions[inside] if leaf_regions is not None else None
        return CorrelativeResult(poses=poses, scores=lv[:, 3], complete=complete,
                                 regions=leaf_regions)

    def score_poses(self, points: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """Mean likelihood (level 0) of ``points`` (sensor frame) at each map-frame pose (P, 3)."""
        pts = np.asarray(points, float).reshape(-1, 2)
        pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= self.max_range]
        poses = np.asarray(poses, float).reshape(-1, 3)
        if len(pts) == 0 or len(poses) == 0:
            return np.zeros(len(poses))
        g = self._to_grid(poses[:, :2])
        cols, rows = np.floor(g[:, 0]).astype(np.int64), np.floor(g[:, 1]).astype(np.int64)
        thetas = self._grid_yaws(poses[:, 2])
        # the offsets assume the sensor at the centre of its cell: use each pose's own fraction
        frac = g - np.floor(g) - 0.5
        c, s = np.cos(thetas), np.sin(thetas)
        q = pts / self.resolution
        x = c[:, None] * q[None, :, 0] - s[:, None] * q[None, :, 1] + frac[:, 0:1] + 0.5
        y = s[:, None] * q[None, :, 0] + c[:, None] * q[None, :, 1] + frac[:, 1:2] + 0.5
        pr = np.floor(y).astype(np.int64) + rows[:, None]
        pc = np.floor(x).astype(np.int64) + cols[:, None]
        inside = (pr >= 0) & (pr < self.height) & (pc >= 0) & (pc < self.width)
        vals = np.where(inside, self._levels[0][np.where(inside, self._flat(pr, pc), 0)], 0)
        return vals.sum(axis=1, dtype=np.int64) / (_SCALE * len(pts))

    # ------------------------------------------------------------------ internals
    def _offsets(self, pts: np.ndarray, thetas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row and column offsets (K, N) of each point's cell from the sensor cell, per yaw."""
        c, s = np.cos(thetas), np.sin(thetas)
        q = pts / self.resolution
        x = c[:, None] * q[None, :, 0] - s[:, None] * q[None, :, 1] + 0.5
        y = s[:, None] * q[None, :, 0] + c[:, None] * q[None, :, 1] + 0.5
        return np.floor(y).astype(np.int64), np.floor(x).astype(np.int64)

    def _base(self, level: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Return the offsets of cells in level ``level``'s by-phase layout (see __init__)."""
        period = 1 << level
        return rows * self._wp + (cols % period) * (self._wp // period) + cols // period

    def level_grid(self, level: int) -> np.ndarray:
        """Return level ``level`` as a padded 2-D grid (rows and columns in map order)."""
        period = 1 << level
        rows = len(self._levels[level]) // self._wp
        by_phase = self._levels[level].reshape(rows, period, self._wp // period)
        return by_phase.transpose(0, 2, 1).reshape(rows, self._wp)

    def _score(self, level: int, base: np.ndarray, k, r, c, norm: float) -> np.ndarray:
        if len(k) == 0:
            return np.zeros(0)
        # windows of this level are anchored at multiples of 2^level (see _base)
        cell = ((np.asarray(r) + self._top) * self._wp
                + ((np.asarray(c) + self._left) >> level))
        grid, k = self._levels[level], np.asarray(k)
        if kernels.window_sums is not None:      # one compiled pass (kernels.py)
            sums = np.empty(len(k), np.int32)
            yaw, at = k.astype(np.int64, copy=False), cell.astype(np.int64, copy=False)

            def part(start: int, stop: int) -> None:
                kernels.window_sums(grid, base, yaw[start:stop], at[start:stop],
                                    sums[start:stop])

            # each window's sum is its own: split among threads, the same integers
            in_parts(part, len(k), self.workers if len(k) * base.shape[1] >= _SPLIT_LOOKUPS
                     else 1)
            return sums * norm
        # Each window's sum as a product with ones in float32: exact while the sums stay below
        # 2^24 (N < 65 793 points), and three times faster than numpy's sum along rows of a few
        # dozen uint8
        by_product = base.shape[1] * _SCALE < _FLOAT32_EXACT
        out = np.empty(len(k), np.float32 if by_product else np.int32)
        ones = np.ones(base.shape[1], np.float32) if by_product else None
        # in chunks of windows whose (chunk, N) cell indices stay in the cache
        for i in range(0, len(k), _SCORE_CHUNK):
            flat = np.take(base, k[i:i + _SCORE_CHUNK], axis=0)  # cells of the points: take
            flat += cell[i:i + _SCORE_CHUNK, None]               # and an in-place add
            # points above or below the padded grid fall off the flat array: its first and
            # last cells are padding (0)
            vals = np.take(grid, flat, mode='clip')
            if by_product:
                np.matmul(vals.astype(np.float32), ones, out=out[i:i + _SCORE_CHUNK])
            else:
                vals.sum(axis=1, dtype=np.int32, out=out[i:i + _SCORE_CHUNK])
        return out.astype(np.int32, copy=False) * norm

    def _flat(self, r, c):
        """Flat index of map cells ``(r, c)`` (may lie in the padding) in the level grids."""
        return (r + self._top) * self._wp + (c + self._left)

    def free_windows(self) -> np.ndarray:
        """Return which top-level windows (anchored at multiples of 2^depth) hold a free cell."""
        return self._free[self.depth]

    def _any_free(self, level: int, r, c) -> np.ndarray:
        """Tell whether the windows of ``level`` anchored at ``(r, c)`` hold a free cell."""
        return self._free[level][np.asarray(r) >> level, np.asarray(c) >> level]

    def _window_cells(self, window) -> tuple[int, int, int, int]:
        """Grid rows/cols ``[r0, r1) x [c0, c1)`` of the sensor positions to search."""
        h, w = self.height, self.width
        if window is None:
            return 0, h, 0, w
        x0, y0, x1, y1 = (float(v) for v in window)
        corners = self._to_grid(np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]]))
        c0, r0 = np.floor(corners.min(axis=0)).astype(int)
        c1, r1 = np.floor(corners.max(axis=0)).astype(int) + 1
        return max(int(r0), 0), min(int(r1), h), max(int(c0), 0), min(int(c1), w)


def likelihood_grid(occupied: np.ndarray, resolution: float, sigma: float) -> np.ndarray:
    """
    Return ``round(255 exp(-d^2 / 2 sigma^2))`` (uint8) per cell, ``d`` its distance (m) to walls.

    ``d`` is measured between cell centres to the nearest ``occupied`` cell. The value is 0
    beyond a few sigma, so distances are computed only that far (``mapping.distance``: exact
    squared distances, clamped) and turned into values by a table of every squared distance up
    to there: the same numbers as from the full distance transform, at a few bytes per cell.
    """
    table = _likelihood_table(resolution, sigma)
    limit = math.isqrt(len(table) - 1)
    k = clamped_squared_distance(occupied, limit, np.int32)
    return table[k]


def surface_cells(occupied: np.ndarray) -> np.ndarray:
    """
    Return the ``occupied`` cells with a neighbour (of eight) that is not: a solid's surface.

    A laser's return ends on the surface of what it hits, never inside it: scored against every
    occupied cell, the points of a scan would fit the inside of a filled shape (a parked car, a
    pillar, a rack drawn solid) perfectly. Cells on the map's border count as surface.
    """
    occ = np.asarray(occupied, bool)
    surface = binary_erosion(occ, np.ones((3, 3), bool), border_value=0)
    np.logical_not(surface, out=surface)
    surface &= occ
    return surface


def _likelihood_table(resolution: float, sigma: float) -> np.ndarray:
    """Return the likelihood (uint8) of each squared distance (cells^2), 0 at the last entry."""
    # exp(-d^2 / 2 sigma^2) < 0.5 / 255 beyond sigma * sqrt(2 ln 510)
    limit = int(math.ceil(sigma * math.sqrt(2.0 * math.log(2.0 * _SCALE)) / resolution)) + 1
    k = np.arange(limit * limit + 1, dtype=np.float64)
    dist = np.sqrt(k) * resolution
    table = np.round(_SCALE * np.exp(-0.5 * (dist / sigma) ** 2)).astype(np.uint8)
    if table[-1] != 0:
        raise ValueError('likelihood table: the last entry must be 0')
    return table


def _block_reduce(a: np.ndarray, f: int, op) -> np.ndarray:
    """``op`` over the ``f x f`` blocks of ``a`` (the last ones may be partial)."""
    if f == 1:
        return a
    h, w = a.shape
    pad = np.zeros(((h + f - 1) // f * f, (w + f - 1) // f * f), a.dtype)
    pad[:h, :w] = a
    return op(pad.reshape(pad.shape[0] // f, f, pad.shape[1] // f, f), axis=(1, 3))


def _by_phase(grid: np.ndarray, period: int) -> np.ndarray:
    """Return ``grid`` (rows a multiple of ``period`` long) flat, each row's columns by phase."""
    rows, cols = grid.shape
    return np.ascontiguousarray(grid.reshape(rows, cols // period, period).transpose(0, 2, 1)
                                ).reshape(-1)


def _window_max(grid: np.ndarray, s: int) -> np.ndarray:
    """
    ``out[r, c] = max(grid[r:r+2s, c:c+2s])`` given ``grid`` holds the s x s window maxima.

    On a boolean grid the maximum is ``any``.
    """
    out = grid.copy()
    np.maximum(out[:-s], grid[s:], out=out[:-s])
    out2 = out.copy()
    np.maximum(out2[:, :-s], out[:, s:], out=out2[:, :-s])
    return out2


class _WindowKeys:
    """
    One int64 per window of the search's pool: its column, row, yaw, level and region.

    Bit fields, lowest first, each as wide as its largest value needs (rows and columns below
    ``rows`` and ``cols``, yaws below ``yaws``, levels up to ``depth``, regions below
    ``regions``). Cells and levels are non-negative, so a child's key is its parent's plus its
    offset, minus one level.
    """

    def __init__(self, rows: int, cols: int, yaws: int, depth: int, regions: int) -> None:
        sizes = (cols, rows, yaws, depth + 1, regions)
        widths = [max(int(n - 1).bit_length(), 1) for n in sizes]
        if sum(widths) > 63:
            raise ValueError(f'CorrelativeGrid.search: {rows} x {cols} cells, {yaws} yaws and '
                             f'{regions} regions do not fit the window keys')
        self._shift = np.cumsum([0, *widths[:-1]]).tolist()
        self._mask = [(1 << w) - 1 for w in widths]

    def pack(self, k, r, c, level: int, region) -> np.ndarray:
        """Return the keys of the windows at yaws ``k``, cells ``(r, c)``, in ``region``."""
        sc, sr, sk, sl, sg = self._shift
        return ((np.asarray(c, np.int64) << sc) | (np.asarray(r, np.int64) << sr)
                | (np.asarray(k, np.int64) << sk) | (np.int64(level) << sl)
                | (np.asarray(region, np.int64) << sg))

    def _field(self, key: np.ndarray, i: int) -> np.ndarray:
        return (key >> self._shift[i]) & self._mask[i]

    def col(self, key: np.ndarray) -> np.ndarray:
        return self._field(key, 0)

    def row(self, key: np.ndarray) -> np.ndarray:
        return self._field(key, 1)

    def yaw(self, key: np.ndarray) -> np.ndarray:
        return self._field(key, 2)

    def level(self, key: np.ndarray) -> np.ndarray:
        return self._field(key, 3)

    def region(self, key: np.ndarray) -> np.ndarray:
        return key >> self._shift[4]

    def children(self, key: np.ndarray, half: int) -> np.ndarray:
        """Return the keys of the four windows of ``half`` cells in each window of ``key``."""
        sc, sr, _, sl, _ = self._shift
        step = np.array([0, half << sc, half << sr, (half << sr) + (half << sc)], np.int64)
        return (np.repeat(key - (np.int64(1) << sl), 4) + np.tile(step, len(key)))


def _allowed_windows(lab: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    Return ``(k, at)``: each yaw ``k`` with each window ``at`` of a region it is allowed in.

    ``lab`` (W,) the region of each window (-1: none), ``allowed`` (K, R). Yaw-major, the windows
    of each region in their order; built from the (yaw, region) pairs, so the cost is that of
    the output, not of every yaw times every window.
    """
    inside = np.flatnonzero(lab >= 0)
    order = inside[np.argsort(lab[inside], kind='stable')]       # windows grouped by region
    count = np.bincount(lab[inside], minlength=allowed.shape[1])
    start = np.cumsum(count) - count
    pk, pr = np.nonzero(allowed)                                 # (yaw, region) pairs
    sizes = count[pr]
    first = np.repeat(start[pr] - (np.cumsum(sizes) - sizes), sizes)
    return np.repeat(pk, sizes), order[first + np.arange(int(sizes.sum()))]


def _empty(complete: bool = True) -> CorrelativeResult:
    return CorrelativeResult(poses=np.zeros((0, 3)), scores=np.zeros(0), complete=complete)
