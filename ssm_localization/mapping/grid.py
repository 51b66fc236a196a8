"""
Occupancy grids from range scans at known poses (hit / miss counting along each beam).

Generic: any source of ``(ranges, poses, beam_angles)`` will do; ``io.carmen`` builds the maps of
the CARMEN logs with it.
"""
from __future__ import annotations

import numpy as np

from .map_limits import check_map_cells, MAX_MAP_CELLS
from .occupancy import OccupancyMap
from ..config.mapping import MapBuildConfig
from ..progress import ProgressCallback

#: most beam samples traversed in one vectorized batch (bounds the batch's memory whatever the
#: resolution; at the defaults it is ``chunk_beams`` beams of 1600 samples)
SAMPLES_PER_CHUNK = 32_000_000


def _beam_segments(ranges, poses, beam_angles, cfg: MapBuildConfig):
    """Flattened beams: start xy, unit direction, free length, has-hit flag."""
    r = np.asarray(ranges, dtype=float)
    hit = np.isfinite(r) & (r > 0.0) & (r <= cfg.max_range)
    length = np.where(hit, r, np.where(np.isfinite(r) & (r > cfg.max_range), cfg.max_range,
                                       min(cfg.free_cap, cfg.max_range)))
    ang = poses[:, 2:3] + np.asarray(beam_angles)[None, :]
    start = np.repeat(poses[:, :2], r.shape[1], axis=0)
    direction = np.column_stack((np.cos(ang).ravel(), np.sin(ang).ravel()))
    return start, direction, length.ravel(), hit.ravel()


def build_occupancy_grid(ranges: np.ndarray, poses: np.ndarray, beam_angles: np.ndarray,
                         config: MapBuildConfig | None = None,
                         progress: ProgressCallback | None = None,
                         max_cells: int = MAX_MAP_CELLS
                         ) -> tuple[np.ndarray, tuple[float, float, float]]:
    """
    Trinary occupancy grid (int8: 100 occupied, 0 free, -1 unknown) and its origin.

    ``ranges`` (S, n) with ``inf`` for no return, ``poses`` (S, 3) laser poses in the world
    frame, ``beam_angles`` (n,). Cells along each beam (sampled every half cell) count a miss,
    the end cell of a finite reading a hit. Rows grow with y, columns with x (OccupancyGrid).
    A grid of more than ``max_cells`` cells (0: no limit) raises
    :class:`~.map_limits.MapTooLargeError` before it is allocated.
    """
    cfg = config or MapBuildConfig()
    ranges = np.atleast_2d(np.asarray(ranges, dtype=float))
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    if ranges.size == 0 or len(ranges) != len(poses):
        raise ValueError(f'need scans and one pose per scan, got {ranges.shape} / {poses.shape}')
    if not np.all(np.isfinite(poses)):
        raise ValueError('scan poses must be finite')
    res = float(cfg.resolution)
    start, direction, length, hit = _beam_segments(ranges, poses, beam_angles, cfg)
    end = start + direction * length[:, None]
    lo = np.minimum(end.min(0), poses[:, :2].min(0)) - cfg.margin
    hi = np.maximum(end.max(0), poses[:, :2].max(0)) + cfg.margin
    origin = (round(float(np.floor(lo[0] / res) * res), 9),
              round(float(np.floor(lo[1] / res) * res), 9), 0.0)
    width = int(np.ceil((hi[0] - origin[0]) / res))
    height = int(np.ceil((hi[1] - origin[1]) / res))
    check_map_cells(width, height, max_cells, f'grid at resolution {res:g} m')
    org = np.array(origin[:2])
    hits = np.zeros(height * width, dtype=np.int64)
    misses = np.zeros(height * width, dtype=np.int64)

    def cell_index(xy):
        cr = np.floor((xy - org) / res).astype(np.int64)
        return np.clip(cr[:, 1], 0, height - 1) * width + np.clip(cr[:, 0], 0, width - 1)

    hits += np.bincount(cell_index(end[hit]), minlength=height * width)
    step = 0.5 * res
    free_len = np.where(hit, length - step, length)
    n_samples = np.maximum(np.ceil(free_len / step).astype(np.int64), 0)
    total = len(length)
    # Pass 1: beams with a return. Pass 2: beams without one clear space up to the cap, but
    # stop at the first cell pass 1 found occupied (no clearing behind walls).
    order = np.concatenate((np.flatnonzero(hit), np.flatnonzero(~hit)))
    n_hit = int(hit.sum())
    occupied = None
    done = 0
    for first_pass, ids in ((True, order[:n_hit]), (False, order[n_hit:])):
        if not first_pass:
            occupied = (hits >= cfg.min_hits) & (hits >= cfg.occupied_ratio * (hits + misses))
        longest = int(n_samples[ids].max()) if len(ids) else 1
        per_chunk = max(1, min(cfg.chunk_beams, SAMPLES_PER_CHUNK // max(longest, 1)))
        for a in range(0, len(ids), per_chunk):
            chunk = ids[a:a + per_chunk]
            counts = n_samples[chunk]
            beam = np.repeat(chunk, counts)
            done += len(chunk)
            if beam.size:
                offsets = np.cumsum(counts) - counts
                k = np.arange(beam.size) - np.repeat(offsets, counts)
                cells = cell_index(start[beam] + direction[beam] * (k * step)[:, None])
                keep = np.ones(cells.size, dtype=bool)   # one miss per beam and cell
                keep[1:] = (cells[1:] != cells[:-1]) | (beam[1:] != beam[:-1])
                if not first_pass:
                    blocked = occupied[cells]
                    stop = np.full(total, np.iinfo(np.int64).max)
                    np.minimum.at(stop, beam[blocked], k[blocked])
                    keep &= k < stop[beam]
                misses += np.bincount(cells[keep], minlength=height * width)
            if progress is not None:
                progress(done, total, 'building map')
    occupied = (hits >= cfg.min_hits) & (hits >= cfg.occupied_ratio * (hits + misses))
    data = np.full(height * width, -1, dtype=np.int8)
    data[misses > 0] = 0
    data[occupied] = 100
    return _crop_known(data.reshape(height, width), origin, res, cfg.margin)


def _crop_known(data: np.ndarray, origin, res: float, margin: float):
    """Crop the grid to its observed cells plus ``margin`` metres of unknown."""
    known = data != -1
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    if rows.size == 0:
        return data, origin
    m = int(round(margin / res))
    r0, r1 = max(rows[0] - m, 0), min(rows[-1] + m + 1, data.shape[0])
    c0, c1 = max(cols[0] - m, 0), min(cols[-1] + m + 1, data.shape[1])
    return (np.ascontiguousarray(data[r0:r1, c0:c1]),
            (round(origin[0] + c0 * res, 9), round(origin[1] + r0 * res, 9), origin[2]))


def build_grid_map(ranges: np.ndarray, poses: np.ndarray, beam_angles: np.ndarray,
                   config: MapBuildConfig | None = None,
                   progress: ProgressCallback | None = None,
                   max_cells: int = MAX_MAP_CELLS) -> OccupancyMap:
    """:func:`build_occupancy_grid` as an :class:`OccupancyMap` (frame ``map``)."""
    cfg = config or MapBuildConfig()
    data, origin = build_occupancy_grid(ranges, poses, beam_angles, cfg, progress, max_cells)
    return OccupancyMap(data=data, resolution=float(cfg.resolution), origin=origin)
