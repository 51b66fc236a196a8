"""
Synthetic maps of the benchmarks: a deterministic office of any size, an outdoor campus.

``office_map`` draws corridors, blocks of rooms with doors and furniture, and open halls with
pillars; ``bench index`` indexes a 100 m one, ``bench localize --campus`` localizes on a 274 m
one (30 M cells) and the campus holds a 100 m one among the real buildings.

``outdoor_map`` draws a campus with outdoor parts: buildings of rooms of random sizes (split
again and again, a door in each wall) among trees, posts, benches, fences with gaps and parking
lots with rows of cars; open ground farther than :data:`OUTDOOR_SEEN` metres from anything a
laser returns from is unknown, as a map built by driving around has it. ``bench localize`` and
``bench index`` run a 270 m one (29 M cells) as ``outdoor_30m``.
"""
from __future__ import annotations

import numpy as np

from ..mapping.distance import clamped_squared_distance
from ..mapping.occupancy import OccupancyMap

#: metres from the nearest obstacle beyond which ``outdoor_map``'s open ground is unknown
OUTDOOR_SEEN = 12.0


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


def outdoor_map(size: float = 270.0, resolution: float = 0.05, seed: int = 0) -> OccupancyMap:
    """
    Return a deterministic campus with outdoor parts, ``size`` x ``size`` metres (module doc).

    At 270 m (other sizes: as many of each per hectare) six to nine buildings of 25-60 m, each a
    rectangle of rooms: split along its longer side at 30-70 % while a part is wider than 9 m,
    each inner wall with a 1 m door, two 1.5 m entrances, furniture against walls. Outside: 60
    groves of up to 30 trees (0.15-0.4 m trunks), posts every 15 m along six straight paths, 150
    benches, up to eight parking lots (four rows of up
    to 15 cars, 70 % of the places taken; 40 tries at a free place) and ten dashed fences.
    """
    rng = np.random.default_rng(seed)
    n = int(round(size / resolution))
    grid = np.zeros((n, n), dtype=np.int8)

    def scaled(count: int) -> int:      # the counts above are for 270 m: as many per hectare
        return max(1, int(round(count * (size / 270.0) ** 2)))

    taken = np.zeros((n, n), dtype=bool)          # building footprints, with a margin

    def cells(v: float) -> int:
        return int(round(v / resolution))

    def box(x0, y0, x1, y1, value=100):
        grid[max(cells(y0), 0):min(cells(y1), n), max(cells(x0), 0):min(cells(x1), n)] = value

    def disc(x, y, r):
        i, j, k = cells(y), cells(x), max(1, cells(r))
        r0, r1, c0, c1 = max(i - k, 0), min(i + k + 1, n), max(j - k, 0), min(j + k + 1, n)
        yy, xx = np.mgrid[r0:r1, c0:c1]
        grid[r0:r1, c0:c1][(yy - i) ** 2 + (xx - j) ** 2 <= k * k] = 100

    def rooms(x0, y0, x1, y1, wall=0.15, door=1.0):
        w, h = x1 - x0, y1 - y0
        if max(w, h) <= 9.0:
            for _ in range(int(rng.integers(0, 3))):       # furniture against a wall
                fw, fh = rng.uniform(0.5, 1.6, 2)
                fx = rng.uniform(x0 + 0.3, max(x0 + 0.4, x1 - fw - 0.3))
                fy = y0 + 0.3 if rng.random() < 0.5 else y1 - fh - 0.3
                box(fx, fy, fx + fw, fy + fh)
            return
        cut = float(rng.uniform(0.3, 0.7))
        if w >= h:
            xm = x0 + cut * w
            box(xm - wall / 2, y0, xm + wall / 2, y1)
            d = rng.uniform(y0 + 0.4, y1 - door - 0.4)
            box(xm - wall / 2, d, xm + wall / 2, d + door, 0)
            rooms(x0, y0, xm, y1)
            rooms(xm, y0, x1, y1)
        else:
            ym = y0 + cut * h
            box(x0, ym - wall / 2, x1, ym + wall / 2)
            d = rng.uniform(x0 + 0.4, x1 - door - 0.4)
            box(d, ym - wall / 2, d + door, ym + wall / 2, 0)
            rooms(x0, y0, x1, ym)
            rooms(x0, ym, x1, y1)

    for _ in range(scaled(int(rng.integers(6, 10)))):
        for _attempt in range(50):
            bw, bh = rng.uniform(25.0, 60.0, 2)
            x0, y0 = rng.uniform(8.0, size - 8.0 - bw), rng.uniform(8.0, size - 8.0 - bh)
            if not taken[cells(y0 - 6):cells(y0 + bh + 6), cells(x0 - 6):cells(x0 + bw + 6)].any():
                break
        else:
            continue
        taken[cells(y0 - 3):cells(y0 + bh + 3), cells(x0 - 3):cells(x0 + bw + 3)] = True
        box(x0, y0, x0 + bw, y0 + bh)
        box(x0 + 0.2, y0 + 0.2, x0 + bw - 0.2, y0 + bh - 0.2, 0)
        rooms(x0 + 0.2, y0 + 0.2, x0 + bw - 0.2, y0 + bh - 0.2)
        for side in range(2):                               # two entrances
            e = rng.uniform(2.0, bw - 3.5)
            yy = y0 if side == 0 else y0 + bh - 0.2
            box(x0 + e, yy, x0 + e + 1.5, yy + 0.2, 0)

    def outside(x, y) -> bool:
        return 1.0 < x < size - 1.0 and 1.0 < y < size - 1.0 and not taken[cells(y), cells(x)]

    for cx, cy in rng.uniform(0.0, size, (scaled(60), 2)):                      # groves of trees
        for x, y in rng.normal((cx, cy), 7.0, (30, 2)):
            if outside(x, y):
                disc(x, y, rng.uniform(0.15, 0.4))
    for _ in range(scaled(6)):                                           # posts along paths
        (x0, y0), angle = rng.uniform(0.0, size, 2), rng.uniform(0.0, np.pi)
        for t in np.arange(-size, size, 15.0):
            x, y = x0 + t * np.cos(angle), y0 + t * np.sin(angle)
            if outside(x, y):
                disc(x, y, 0.08)
    for x, y in rng.uniform(0.0, size, (scaled(150), 2)):                 # benches
        if outside(x, y) and outside(x + 1.8, y + 1.8):
            if rng.random() < 0.5:
                box(x, y, x + 1.8, y + 0.5)
            else:
                box(x, y, x + 0.5, y + 1.8)
    lots = 0
    for _ in range(40):                                                   # parking lots
        x0, y0 = rng.uniform(5.0, size - 45.0, 2)
        lot = (slice(cells(y0), cells(y0 + 27.0)), slice(cells(x0), cells(x0 + 40.0)))
        if lots == scaled(8) or taken[lot].any():
            continue
        lots += 1
        taken[lot] = True
        for row in range(4):
            for k in range(15):
                if rng.random() < 0.7:
                    box(x0 + 2.6 * k, y0 + 7.0 * row, x0 + 2.6 * k + 1.8, y0 + 7.0 * row + 4.5)
    for _ in range(scaled(10)):                                           # dashed fences
        x0, y0 = rng.uniform(5.0, size - 65.0, 2)
        length, along_x = rng.uniform(10.0, 60.0), rng.random() < 0.5
        for s in np.arange(0.0, length, 4.0):
            if along_x and outside(x0 + s, y0):
                box(x0 + s, y0, x0 + s + 3.2, y0 + 0.1)
            elif not along_x and outside(x0, y0 + s):
                box(x0, y0 + s, x0 + 0.1, y0 + s + 3.2)
    box(0, 0, size, 0.2)
    box(0, size - 0.2, size, size)
    box(0, 0, 0.2, size)
    box(size - 0.2, 0, size, size)
    seen = cells(OUTDOOR_SEEN)
    far = clamped_squared_distance(grid > 0, seen) >= seen * seen
    grid[far & (grid == 0)] = -1
    return OccupancyMap(grid, resolution, (0.0, 0.0, 0.0), 'map')
