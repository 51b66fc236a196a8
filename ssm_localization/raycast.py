"""Virtual range scans by exact grid traversal (paper section III, Table 1).

Table 1 marches each beam in steps of ``Delta d``; here every beam visits exactly the cells it
crosses (Amanatides & Woo's DDA), vectorized over all beams of all poses at once: the loop runs
over traversal steps, not over rays, and finished rays are dropped as it goes. The range is the
distance from the sensor to the boundary of the first occupied cell it enters.
"""
from __future__ import annotations

import math

import numpy as np


def cast_rays(occupied: np.ndarray, resolution: float, origin, sensor_poses, beam_angles,
              max_range: float) -> np.ndarray:
    """Ranges (P, B) float64 of beams ``beam_angles`` (B,) from ``sensor_poses`` (P, 3).

    ``occupied`` (H, W) bool follows nav_msgs/OccupancyGrid (row 0 at the bottom); ``origin`` is
    the grid's ``(x, y, yaw)``; poses are in the map frame, beam angles relative to the sensor.
    ``inf`` where no occupied cell is entered within ``max_range`` (or the beam leaves the grid);
    a sensor inside an occupied cell reads 0. Outside the grid counts as free.
    """
    occ = np.asarray(occupied, dtype=bool)
    if occ.ndim != 2:
        raise ValueError(f'occupied: expected an (H, W) array, got shape {occ.shape}')
    res = float(resolution)
    if not (math.isfinite(res) and res > 0):
        raise ValueError(f'resolution: expected a positive number, got {resolution}')
    poses = np.asarray(sensor_poses, dtype=float).reshape(-1, 3)
    angles = np.asarray(beam_angles, dtype=float).reshape(-1)
    n_p, n_b = len(poses), len(angles)
    out = np.full((n_p, n_b), np.inf)
    if out.size == 0 or occ.size == 0 or not max_range > 0:
        return out
    h, w = occ.shape
    ox, oy, oyaw = (float(v) for v in origin)
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
    active = valid & (t0 < t1) & (t0 <= t_max)
    ids = np.flatnonzero(active)
    if ids.size == 0:
        return out
    ux, uy, px, py, t0, t1 = ux[ids], uy[ids], px[ids], py[ids], t0[ids], t1[ids]
    inv_x, inv_y = inv_x[ids], inv_y[ids]
    # Entry point (nudged along the ray so that floor() picks the cell being entered).
    eps = 1e-9
    ex = px + ux * (t0 + eps * (t0 > 0))
    ey = py + uy * (t0 + eps * (t0 > 0))
    col = np.clip(np.floor(ex), 0, w - 1).astype(np.int64)
    row = np.clip(np.floor(ey), 0, h - 1).astype(np.int64)
    step_x = np.where(ux > 0, 1, -1)
    step_y = np.where(uy > 0, 1, -1)
    with np.errstate(divide='ignore', invalid='ignore'):
        next_x = np.where(ux > 0, col + 1.0, col.astype(float))
        next_y = np.where(uy > 0, row + 1.0, row.astype(float))
        tmx = np.where(ux != 0, (next_x - px) * inv_x, np.inf)
        tmy = np.where(uy != 0, (next_y - py) * inv_y, np.inf)
        tdx = np.where(ux != 0, np.abs(inv_x), np.inf)
        tdy = np.where(uy != 0, np.abs(inv_y), np.inf)
    # Padded flat grid: 0 free, 1 occupied, 2 outside (one cell all round, ends the ray).
    wp = w + 2
    code = np.full((h + 2, wp), 2, dtype=np.uint8)
    code[1:-1, 1:-1] = occ
    code = code.ravel()
    flat = (row + 1) * wp + (col + 1)
    dflat_x = step_x
    dflat_y = step_y * wp
    t = t0.copy()
    ranges = out.reshape(-1)
    while ids.size:
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
        xs = tmx < tmy
        t = np.where(xs, tmx, tmy)
        flat += np.where(xs, dflat_x, dflat_y)
        tmx = np.where(xs, tmx + tdx, tmx)
        tmy = np.where(xs, tmy, tmy + tdy)
    return out


def beam_angles(beams: int) -> np.ndarray:
    """``beams`` angles evenly covering a full turn, counterclockwise from ``-pi``."""
    n = int(beams)
    if n < 1:
        raise ValueError(f'beams: expected a positive integer, got {beams}')
    return -math.pi + 2.0 * math.pi * np.arange(n) / n
