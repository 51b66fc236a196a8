"""
Virtual range scans by exact grid traversal (paper section III, Table 1).

Table 1 marches each beam in steps of ``Delta d``; here every beam visits exactly the cells it
crosses (Amanatides & Woo's DDA), vectorized over all beams of all poses at once: the loop runs
over traversal steps, not over rays, and finished rays are dropped as it goes. The range is the
distance from the sensor to the boundary of the first occupied cell it enters.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage


class RayCaster:
    """
    Ray casting on one grid; precomputes the padded grid and its distance transform once.

    Beams advance by exact cell-to-cell steps (DDA); where the distance transform shows that no
    occupied cell is near, a beam first jumps ahead by a safe distance (``D - sqrt(2)`` cells
    for a cell whose centre is ``D`` cells from the nearest occupied cell centre), then resumes
    the exact traversal, so the result is the same as the plain traversal, only faster.
    ``accelerate=False`` skips the distance transform (cheaper for a few rays on a big grid).
    """

    #: below this many unfinished rays, :meth:`cast` finishes them one by one in plain Python
    tail_rays = 128

    def __init__(self, occupied: np.ndarray, resolution: float, origin,
                 accelerate: bool = True) -> None:
        occ = np.asarray(occupied, dtype=bool)
        if occ.ndim != 2:
            raise ValueError(f'occupied: expected an (H, W) array, got shape {occ.shape}')
        res = float(resolution)
        if not (math.isfinite(res) and res > 0):
            raise ValueError(f'resolution: expected a positive number, got {resolution}')
        self.resolution = res
        self.origin = tuple(float(v) for v in origin)
        self.shape = occ.shape
        h, w = occ.shape
        # Padded flat grid: 0 free, 1 occupied, 2 outside (one cell all round, ends the ray).
        code = np.full((h + 2, w + 2), 2, dtype=np.uint8)
        code[1:-1, 1:-1] = occ
        self._code = code.ravel()
        if not accelerate:
            self._skip = np.zeros(code.size, dtype=np.float32)
        elif occ.any():
            edt = ndimage.distance_transform_edt(code != 1).astype(np.float32)
            self._skip = np.maximum(edt - np.float32(math.sqrt(2.0) + 1e-3), 0).ravel()
        else:
            self._skip = np.full(code.size, np.inf, dtype=np.float32)

    def cast(self, sensor_poses, beam_angles, max_range: float) -> np.ndarray:
        """Ranges (P, B) of beams ``beam_angles`` (B,) from ``sensor_poses`` (P, 3)."""
        res = self.resolution
        h, w = self.shape
        poses = np.asarray(sensor_poses, dtype=float).reshape(-1, 3)
        angles = np.asarray(beam_angles, dtype=float).reshape(-1)
        n_p, n_b = len(poses), len(angles)
        out = np.full((n_p, n_b), np.inf)
        if out.size == 0 or not max_range > 0:
            return out
        ox, oy, oyaw = self.origin
        # Sensor positions and beam directions in grid units (cells), grid frame.
        c0, s0 = math.cos(oyaw), math.sin(oyaw)
        dx, dy = poses[:, 0] - ox, poses[:, 1] - oy
        gx = (c0 * dx + s0 * dy) / res
        gy = (-s0 * dx + c0 * dy) / res
        theta = (poses[:, 2] - oyaw)[:, None] + angles[None, :]
        ux = np.cos(theta).ravel()
        uy = np.sin(theta).ravel()
        px = np.repeat(gx, n_b)
        py = np.repeat(gy, n_b)
        valid = np.isfinite(px) & np.isfinite(py) & np.isfinite(ux) & np.isfinite(uy)
        t_max = min(float(max_range), 1e12) / res
        # Clip every ray to the grid rectangle [0, W] x [0, H] (slab method).
        with np.errstate(divide='ignore', invalid='ignore'):
            inv_x = 1.0 / ux
            inv_y = 1.0 / uy
            tx1, tx2 = (0.0 - px) * inv_x, (w - px) * inv_x
            ty1, ty2 = (0.0 - py) * inv_y, (h - py) * inv_y
        # Rays parallel to an axis: inside the slab -> (-inf, inf), outside -> empty.
        par_x = ux == 0.0
        par_y = uy == 0.0
        in_x = (px >= 0) & (px < w)
        in_y = (py >= 0) & (py < h)
        tx_lo = np.where(par_x, np.where(in_x, -np.inf, np.inf), np.minimum(tx1, tx2))
        tx_hi = np.where(par_x, np.where(in_x, np.inf, -np.inf), np.maximum(tx1, tx2))
        ty_lo = np.where(par_y, np.where(in_y, -np.inf, np.inf), np.minimum(ty1, ty2))
        ty_hi = np.where(par_y, np.where(in_y, np.inf, -np.inf), np.maximum(ty1, ty2))
        t0 = np.maximum(np.maximum(tx_lo, ty_lo), 0.0)
        t1 = np.minimum(np.minimum(tx_hi, ty_hi), t_max)
        ids = np.flatnonzero(valid & (t0 < t1) & (t0 <= t_max))
        if ids.size == 0:
            return out
        ux, uy, px, py, t, t1 = ux[ids], uy[ids], px[ids], py[ids], t0[ids], t1[ids]
        inv_x, inv_y = inv_x[ids], inv_y[ids]
        wp = w + 2
        with np.errstate(divide='ignore', invalid='ignore'):
            tdx = np.where(ux != 0, np.abs(inv_x), np.inf)
            tdy = np.where(uy != 0, np.abs(inv_y), np.inf)
        dflat_x = np.where(ux > 0, 1, -1)
        dflat_y = np.where(uy > 0, wp, -wp)
        flat, tmx, tmy = self._locate(px, py, ux, uy, inv_x, inv_y, t, t > 0)
        code, skip = self._code, self._skip
        ranges = out.reshape(-1)
        while ids.size:
            if ids.size <= self.tail_rays:
                self._finish(ranges, ids, flat, t, t1, tmx, tmy, tdx, tdy, dflat_x, dflat_y,
                             px, py, ux, uy, inv_x, inv_y)
                break
            cell = code[flat]
            over = t > t1
            hit = (cell == 1) & ~over
            done = (cell != 0) | over
            if hit.any():
                ranges[ids[hit]] = t[hit] * res
            if done.any():
                keep = ~done
                if not keep.any():
                    break
                ids, flat, t, t1 = ids[keep], flat[keep], t[keep], t1[keep]
                tmx, tmy, tdx, tdy = tmx[keep], tmy[keep], tdx[keep], tdy[keep]
                dflat_x, dflat_y = dflat_x[keep], dflat_y[keep]
                ux, uy, px, py = ux[keep], uy[keep], px[keep], py[keep]
                inv_x, inv_y = inv_x[keep], inv_y[keep]
            jump = skip[flat]
            far = jump >= 2.0
            if far.any():  # safe jump through free space, then re-enter the exact traversal
                j = np.flatnonzero(far)
                tj = np.minimum(t[j] + jump[j], t1[j] + 1.0)
                t[j] = tj
                flat[j], tmx[j], tmy[j] = self._locate(px[j], py[j], ux[j], uy[j], inv_x[j],
                                                       inv_y[j], tj, np.zeros(len(j), bool))
                near = np.flatnonzero(~far)
            else:
                near = None
            if near is None:
                xs = tmx < tmy
                t = np.where(xs, tmx, tmy)
                flat += np.where(xs, dflat_x, dflat_y)
                tmx = np.where(xs, tmx + tdx, tmx)
                tmy = np.where(xs, tmy, tmy + tdy)
            elif near.size:
                a, b = tmx[near], tmy[near]
                xs = a < b
                t[near] = np.where(xs, a, b)
                flat[near] += np.where(xs, dflat_x[near], dflat_y[near])
                tmx[near] = np.where(xs, a + tdx[near], a)
                tmy[near] = np.where(xs, b, b + tdy[near])
        return out

    def _finish(self, ranges, ids, flat, t, t1, tmx, tmy, tdx, tdy, dflat_x, dflat_y,
                px, py, ux, uy, inv_x, inv_y) -> None:
        """
        Finish the last few rays one by one in plain Python.

        The same steps, in the same floating-point operations, as the vectorized loop of
        :meth:`cast` (so the same ranges), without its per-step numpy overhead, which dominates
        once few rays are left (the long ones, often grazing a wall cell by cell).
        """
        code, skip, res = memoryview(self._code), memoryview(self._skip), self.resolution
        h, w = self.shape
        wp = w + 2
        rays = zip(ids.tolist(), flat.tolist(), t.tolist(), t1.tolist(), tmx.tolist(),
                   tmy.tolist(), tdx.tolist(), tdy.tolist(), dflat_x.tolist(), dflat_y.tolist(),
                   px.tolist(), py.tolist(), ux.tolist(), uy.tolist(), inv_x.tolist(),
                   inv_y.tolist())
        for ray, f, ti, t_end, ax, ay, dx, dy, sx, sy, x0, y0, vx, vy, ix, iy in rays:
            while True:
                cell = code[f]
                over = ti > t_end
                if cell == 1 and not over:
                    ranges[ray] = ti * res
                if cell != 0 or over:
                    break
                jump = skip[f]
                if jump >= 2.0:      # as in _locate, without the nudge
                    ti = min(ti + jump, t_end + 1.0)
                    col = min(max(math.floor(x0 + vx * ti), -1), w)
                    row = min(max(math.floor(y0 + vy * ti), -1), h)
                    ax = ((col + 1.0 if vx > 0 else float(col)) - x0) * ix if vx != 0 else math.inf
                    ay = ((row + 1.0 if vy > 0 else float(row)) - y0) * iy if vy != 0 else math.inf
                    f = (row + 1) * wp + (col + 1)
                elif ax < ay:
                    ti, f, ax = ax, f + sx, ax + dx
                else:
                    ti, f, ay = ay, f + sy, ay + dy

    def _locate(self, px, py, ux, uy, inv_x, inv_y, t, nudge):
        """
        Flat padded index of the cell at ray parameter ``t`` and its next boundary crossings.

        ``nudge``: move a hair along the ray first so that ``floor`` picks the cell being
        entered at a boundary.
        """
        h, w = self.shape
        tt = t + 1e-9 * nudge
        col = np.clip(np.floor(px + ux * tt), -1, w).astype(np.int64)
        row = np.clip(np.floor(py + uy * tt), -1, h).astype(np.int64)
        with np.errstate(divide='ignore', invalid='ignore'):
            next_x = np.where(ux > 0, col + 1.0, col.astype(float))
            next_y = np.where(uy > 0, row + 1.0, row.astype(float))
            tmx = np.where(ux != 0, (next_x - px) * inv_x, np.inf)
            tmy = np.where(uy != 0, (next_y - py) * inv_y, np.inf)
        return (row + 1) * (w + 2) + (col + 1), tmx, tmy


def cast_rays(occupied: np.ndarray, resolution: float, origin, sensor_poses, beam_angles,
              max_range: float) -> np.ndarray:
    """
    Ranges (P, B) float64 of beams ``beam_angles`` (B,) from ``sensor_poses`` (P, 3).

    ``occupied`` (H, W) bool follows nav_msgs/OccupancyGrid (row 0 at the bottom); ``origin`` is
    the grid's ``(x, y, yaw)``; poses are in the map frame, beam angles relative to the sensor.
    ``inf`` where no occupied cell is entered within ``max_range`` (or the beam leaves the grid);
    a sensor inside an occupied cell reads 0. Outside the grid counts as free. For many calls on
    one grid, build a :class:`RayCaster` once and call its ``cast``.
    """
    occ = np.asarray(occupied, dtype=bool)
    n_rays = np.size(sensor_poses) // 3 * np.size(beam_angles)
    # the distance transform pays off only with enough rays per grid cell
    caster = RayCaster(occ, resolution, origin, accelerate=16 * n_rays >= occ.size)
    return caster.cast(sensor_poses, beam_angles, max_range)


def beam_angles(beams: int) -> np.ndarray:
    """``beams`` angles evenly covering a full turn, counterclockwise from ``-pi``."""
    n = int(beams)
    if n < 1:
        raise ValueError(f'beams: expected a positive integer, got {beams}')
    return -math.pi + 2.0 * math.pi * np.arange(n) / n
