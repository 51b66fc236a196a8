"""
Synthetic maps of the benchmarks: a deterministic office of any size.

``office_map`` draws corridors, blocks of rooms with doors and furniture, and open halls with
pillars; ``bench index`` indexes a 100 m one, ``bench localize --campus`` localizes on a 274 m
one (30 M cells) and the campus holds a 100 m one among the real buildings.
"""
from __future__ import annotations

import numpy as np

from ..mapping.occupancy import OccupancyMap


def office_map(size: float = 100.0, resolution: float = 0.05, seed: int = 0):
    """
    Return a deterministic synthetic office (corridors, rooms with doors, furniture, halls).

    ``size`` x ``size`` metres at ``resolution`` (default 2000 x 2000 cells), frame ``map``,
    origin (0, 0, 0). Walls are 0.15 m thick, corridors 2.4 m wide, doors 1 m wide.
    """
    rng = np.random.default_rng(seed)
    n = int(round(size / resolution))
    grid = np.zeros((n, n), dtype=np.int8)

    def cells(v: float) -> int:
        return int(round(v / resolution))

    def box(x0, y0, x1, y1, value=100):
        grid[max(cells(y0), 0):min(cells(y1), n), max(cells(x0), 0):min(cells(x1), n)] = value

    wall, corridor, door = 0.15, 2.4, 1.0
    box(0, 0, size, wall)
    box(0, size - wall, size, size)
    box(0, 0, wall, size)
    box(size - wall, 0, size, size)
    xs = np.arange(12.5, size, 25.0)   # vertical corridor centres
    ys = np.arange(10.0, size, 20.0)   # horizontal corridor centres
    xb = np.concatenate(([wall], xs + corridor / 2))
    xe = np.concatenate((xs - corridor / 2, [size - wall]))
    yb = np.concatenate(([wall], ys + corridor / 2))
    ye = np.concatenate((ys - corridor / 2, [size - wall]))
    for bx0, bx1 in zip(xb, xe):
        for by0, by1 in zip(yb, ye):
            if bx1 - bx0 < 4 or by1 - by0 < 4:
                continue
            kind = rng.random()
            if kind < 0.15:  # open hall with pillars
                for px in np.arange(bx0 + 3.0, bx1 - 2.0, 4.0):
                    for py in np.arange(by0 + 3.0, by1 - 2.0, 4.0):
                        box(px - 0.2, py - 0.2, px + 0.2, py + 0.2)
                continue
            # block outline, two rows of rooms split at mid-height
            box(bx0, by0, bx1, by0 + wall)
            box(bx0, by1 - wall, bx1, by1)
            box(bx0, by0, bx0 + wall, by1)
            box(bx1 - wall, by0, bx1, by1)
            ym = (by0 + by1) / 2
            box(bx0, ym - wall / 2, bx1, ym + wall / 2)
            for lower in (True, False):
                x = bx0
                while x < bx1 - 2.5:
                    width = float(rng.choice([3.0, 4.0, 5.0, 6.0]))
                    x1 = min(x + width, bx1)
                    if bx1 - x1 < 2.5:
                        x1 = bx1
                    if x1 < bx1:
                        box(x1 - wall / 2, by0 if lower else ym, x1 + wall / 2,
                            ym if lower else by1)
                    # door on the corridor side
                    dx = x + float(rng.uniform(0.4, max(0.5, x1 - x - door - 0.4)))
                    if lower:
                        box(dx, by0, dx + door, by0 + wall, 0)
                    else:
                        box(dx, by1 - wall, dx + door, by1, 0)
                    # furniture away from the door side
                    for _ in range(int(rng.integers(0, 3))):
                        fw, fh = rng.uniform(0.5, 1.5, 2)
                        fx = rng.uniform(x + 0.5, max(x + 0.6, x1 - fw - 0.5))
                        fy = (ym - fh - 0.3) if lower else (ym + 0.3)
                        box(fx, fy, fx + fw, fy + fh)
                    x = x1
    return OccupancyMap(grid, resolution, (0.0, 0.0, 0.0), 'map')
