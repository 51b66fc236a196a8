"""
Euclidean distance transforms that cost a few bytes per cell (exact).

``scipy.ndimage.distance_transform_edt`` returns float64 distances and, on its way there, holds
the feature transform (8 bytes per cell), a grid of indices (8), the differences as float64
(16) and their sum: about 40 bytes per cell, 1.2 GB for a 30 M-cell map. The layers of the
index and of the localizer need less:

- :func:`feature_transform`: the nearest target cell of every cell (int32 rows and columns, what
  the GVD compares), and :func:`distances_from` its exact distances, filled in row bands;
- :func:`clamped_squared_distance`: the exact squared distance (an integer number of cells^2)
  up to a limit, computed block by block with a halo as wide as the limit (a target within
  the limit lies in the halo; beyond it the value is clamped), so only one block's transform is
  held at a time and blocks with no target near skip the transform.

Squared distances are integers, so the float distances made from them (``sqrt`` in float64)
are bit for bit those of scipy's transform.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

#: rows of a band when distances are filled from a feature transform
BAND_ROWS = 256
#: side of the blocks of :func:`clamped_squared_distance`, cells
BLOCK = 1024


def feature_transform(targets: np.ndarray) -> np.ndarray:
    """
    Return ``(2, H, W)`` int32: row and column of the nearest ``True`` cell of ``targets``.

    As ``distance_transform_edt(~targets, return_indices=True)`` computes it (the same ties),
    without its distances. ``targets`` must hold at least one ``True`` cell.
    """
    targets = np.asarray(targets, dtype=bool)
    ft = np.empty((2,) + targets.shape, dtype=np.int32)
    ndimage.distance_transform_edt(~targets, return_distances=False, return_indices=True,
                                   indices=ft)
    return ft


def squared_distances(ft: np.ndarray, r0: int = 0, r1: int | None = None, c0: int = 0,
                      c1: int | None = None) -> np.ndarray:
    """Return the squared distances (int64, cells^2) of cells ``[r0:r1, c0:c1]`` to ``ft``."""
    r1 = ft.shape[1] if r1 is None else r1
    c1 = ft.shape[2] if c1 is None else c1
    rows = np.arange(r0, r1, dtype=np.int64)[:, None]
    cols = np.arange(c0, c1, dtype=np.int64)[None, :]
    dr = ft[0, r0:r1, c0:c1].astype(np.int64) - rows
    dc = ft[1, r0:r1, c0:c1].astype(np.int64) - cols
    dr *= dr
    dc *= dc
    dr += dc
    return dr


def distances_from(ft: np.ndarray) -> np.ndarray:
    """
    Return the distances (float64, cells) of every cell to its feature cell ``ft``.

    Bit for bit ``distance_transform_edt``'s, filled :data:`BAND_ROWS` rows at a time.
    """
    h = ft.shape[1]
    out = np.empty(ft.shape[1:], dtype=np.float64)
    for r0 in range(0, h, BAND_ROWS):
        r1 = min(r0 + BAND_ROWS, h)
        np.sqrt(squared_distances(ft, r0, r1), out=out[r0:r1], dtype=np.float64)
    return out


def clamped_squared_distance(targets: np.ndarray, limit: int, dtype=np.int32,
                             block: int = BLOCK) -> np.ndarray:
    """
    Return ``min(d^2, limit^2)`` per cell, ``d`` its distance (cells) to the nearest target.

    ``targets`` (H, W) bool; ``d^2`` is an exact integer wherever ``d <= limit``, and
    ``limit^2`` wherever no target lies within ``limit`` cells (also where there is no target
    at all). Only cells of the grid count (nothing outside it is a target). ``dtype`` must hold
    ``limit^2``. Computed in ``block`` x ``block`` blocks, each with a halo of ``limit`` cells.
    """
    targets = np.asarray(targets, dtype=bool)
    limit = int(limit)
    if limit < 0:
        raise ValueError(f'clamped_squared_distance: limit must be >= 0, got {limit}')
    cap = limit * limit
    if cap > np.iinfo(dtype).max:
        raise ValueError(f'clamped_squared_distance: {np.dtype(dtype).name} cannot hold '
                         f'{limit}^2')
    h, w = targets.shape
    out = np.empty((h, w), dtype=dtype)
    for r0 in range(0, h, block):
        r1 = min(r0 + block, h)
        wr0, wr1 = max(r0 - limit, 0), min(r1 + limit, h)
        # rows with a target near this band: skip the band's transform where there is none
        band_any = targets[wr0:wr1].any(axis=0)
        for c0 in range(0, w, block):
            c1 = min(c0 + block, w)
            wc0, wc1 = max(c0 - limit, 0), min(c1 + limit, w)
            if not band_any[wc0:wc1].any():
                out[r0:r1, c0:c1] = cap
                continue
            ft = feature_transform(targets[wr0:wr1, wc0:wc1])
            k = squared_distances(ft, r0 - wr0, r1 - wr0, c0 - wc0, c1 - wc0)
            out[r0:r1, c0:c1] = np.minimum(k, cap)
    return out
