"""
The specks of an occupancy grid: occupied components of a few cells (beyond the paper).

A map made by SLAM keeps, as a few occupied cells, whatever stood still for a scan or two while
it was recorded: people, their legs, a chair's leg. The beam check (``localization/verify.py``)
counts the returns through walls that passed only such specks, and the tracker does not hold
them against a pose (``tracker.forgive_specks``).

The components are labelled tile by tile, each tile with a margin as wide as a speck can
reach, so the memory is a few megabytes whatever the map's size.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

#: 8-connectivity: cells touching at a corner are one component, as a ray sees them
_EIGHT = np.ones((3, 3), dtype=bool)
#: rows and columns of a tile
TILE = 1024


def speck_mask(occupied: np.ndarray, max_cells: float, tile: int = TILE) -> np.ndarray | None:
    """
    Return the occupied cells whose 8-connected component has at most ``max_cells`` cells.

    ``None`` when ``max_cells`` is below one cell or no component is that small. A speck with a
    cell in a tile lies within ``max_cells - 1`` cells of it, so it is whole in the tile and its
    margin of ``max_cells`` cells; a component that reaches the margin's outer edge (where the
    map goes on) may go on beyond it and is not a speck there.
    """
    limit = math.floor(max_cells + 1e-9) if math.isfinite(max_cells) else 0
    occ = np.asarray(occupied, dtype=bool)
    if limit < 1 or occ.ndim != 2:
        return None
    h, w = occ.shape
    step = max(int(tile), 1)
    mask = np.zeros(occ.shape, dtype=bool)
    for r0 in range(0, h, step):
        for c0 in range(0, w, step):
            r1, c1 = min(r0 + step, h), min(c0 + step, w)
            if not occ[r0:r1, c0:c1].any():
                continue
            top, left = max(r0 - limit, 0), max(c0 - limit, 0)
            bottom, right = min(r1 + limit, h), min(c1 + limit, w)
            labels, count = ndimage.label(occ[top:bottom, left:right], structure=_EIGHT)
            small = np.bincount(labels.ravel(), minlength=count + 1) <= limit
            small[0] = False
            for cut, edge in ((top > 0, labels[0]), (bottom < h, labels[-1]),
                              (left > 0, labels[:, 0]), (right < w, labels[:, -1])):
                if cut:
                    small[edge] = False
            mask[r0:r1, c0:c1] = small[labels[r0 - top:r1 - top, c0 - left:c1 - left]]
    return mask if mask.any() else None
