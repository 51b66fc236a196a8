"""
Campus-scale benchmark maps: the six real buildings and the simulated maps on one large grid.

``campus`` (27.6 M cells at 0.05 m): every real building is rebuilt from the even-numbered
scans of its CARMEN log with its poses turned and moved into the campus frame (a map built at
that orientation, not a resampled image), the simulated maps (the nav2 depot and
turtlebot3_world maps, the 100 m synthetic office of ``bench index``) are pasted as they are;
they lie apart on a grid of unknown cells, at least :data:`GAP` metres between the bounding
boxes of any two (more than the 30 m the localizer and the simulated laser see), so each
building's scans see exactly what they saw on the building's own map. The queries are each
building's odd-numbered scans (real) or random poses of the paper's protocol (simulated), with
their ground truth carried into the campus frame: localizing them tests finding the right place
among nine buildings' worth of candidates, and telling the buildings apart.

``office_30m``: the synthetic office of ``bench index`` grown to 274 m x 274 m (5480 x 5480 =
30 M cells), a worst case of dense, repetitive structure (corridors, rows of similar rooms).
``outdoor_30m``: a synthetic campus with outdoor parts, 270 m x 270 m (5400 x 5400 = 29 M
cells): buildings of rooms of random sizes among trees, posts, benches, fences and parked cars,
open ground far from all of them unknown (``synthetic.outdoor_map``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import json
import math
from pathlib import Path

import numpy as np

from .places import odd_scans, REAL_PLACES, sim_queries
from .synthetic import office_map, outdoor_map
from ..io.bag_records import ScanRecord
from ..io.bag_writer import write_bag
from ..io.carmen import build_map, CarmenLog, read_carmen_log
from ..mapping.map_io import load_map_yaml, OccupancyMap, save_map_yaml
from ..transforms import compose, Pose2

#: metres of unknown between the bounding boxes of two buildings (> the 30 m range of the
#: localizer's checks and of the simulated laser)
GAP = 31.0
#: metres of unknown between the buildings and the edge of the campus grid
BORDER = 2.0
#: campus resolution, metres per cell
RESOLUTION = 0.05
#: the buildings of the campus and the yaw (degrees) each is turned by; real buildings are
#: rebuilt from their logs at that yaw, simulated maps are pasted unturned
#: (the order is the packing's: it gives a 4674 x 5908 grid, 27.6 M cells)
SITES: tuple[tuple[str, float], ...] = (
    ('fr079', 15.0), ('depot', 0.0), ('office', 0.0), ('turtlebot3_world', 0.0),
    ('intel', 30.0), ('fhw', -10.0), ('aces', 20.0), ('edmonton', -8.0), ('csail', -12.0))
#: bumped whenever the layout changes, so a cached campus map is rebuilt
CAMPUS_VERSION = 1
#: side of the synthetic office, metres (5480 x 5480 cells at 0.05 m)
OFFICE_30M_SIZE = 274.0
#: side of ``outdoor_30m``, metres (5400 cells at 0.05 m)
OUTDOOR_30M_SIZE = 270.0


@dataclass(frozen=True)
class Site:
    """
    One building on the campus.

    ``transform`` maps the building's own frame (its log's or map's world frame) into the
    campus frame; ``cells`` is its block of the campus grid (row, col, height, width).
    """

    name: str
    real: bool
    transform: Pose2
    cells: tuple[int, int, int, int]


@dataclass(frozen=True)
class Campus:
    """The stitched map and its sites."""

    grid: OccupancyMap
    sites: tuple[Site, ...]


def _turned_log(log: CarmenLog, yaw: float) -> CarmenLog:
    """Return ``log`` with its poses turned by ``yaw`` about the world origin."""
    turn = (0.0, 0.0, yaw)
    return dataclasses.replace(log, poses=np.array([compose(turn, tuple(p)) for p in log.poses]))


def _site_grid(data: Path, name: str, yaw_deg: float) -> tuple[OccupancyMap, bool]:
    """Return the building's map in its turned frame, and whether it is a real building."""
    if name in REAL_PLACES:
        log = read_carmen_log(data / 'carmen' / f'{REAL_PLACES[name]}-corrected.log.gz')
        turned = _turned_log(log, math.radians(yaw_deg))
        return build_map(turned, indices=range(0, len(log), 2), max_cells=0), True
    if yaw_deg:
        raise ValueError(f'campus: simulated map {name} is pasted as it is, not turned')
    return _sim_grid(data, name), False


def _sim_grid(data: Path, name: str) -> OccupancyMap:
    """Return a simulated site's own map: a shared nav2 map, or the synthetic office."""
    return office_map() if name == 'office' else load_map_yaml(data / 'maps' / f'{name}.yaml')


def _pack(sizes: list[tuple[int, int]], gap: int,
          border: int) -> tuple[list[tuple[int, int]], int, int]:
    """
    Bottom-left packing: ``(row, col)`` of each (height, width) block, and the grid's shape.

    The blocks are placed in the given order, each where it keeps the bounding box of those
    placed so far smallest (ties: lowest row, then column), among the corners the placed blocks
    offer, ``gap`` cells from every other block and ``border`` cells from the grid's edge.
    """
    placed: list[tuple[int, int, int, int]] = []        # row0, col0, row1, col1
    corners = {(border, border)}
    for h, w in sizes:
        best = None
        for r, c in corners:
            if any(r < r1 + gap and r + h + gap > r0 and c < c1 + gap and c + w + gap > c0
                   for r0, c0, r1, c1 in placed):
                continue
            height = max([r + h] + [p[2] for p in placed])
            width = max([c + w] + [p[3] for p in placed])
            key = (height * width, r, c)
            best = key if best is None or key < best else best
        _, r, c = best
        placed.append((r, c, r + h, c + w))
        for p in placed:
            for q in placed:
                corners |= {(p[2] + gap, q[3] + gap), (p[2] + gap, q[1]), (p[0], q[3] + gap),
                            (p[2] + gap, border), (border, q[3] + gap)}
    height = max(p[2] for p in placed) + border
    width = max(p[3] for p in placed) + border
    return [(p[0], p[1]) for p in placed], height, width


def build_campus(data: Path) -> Campus:
    """Stitch the :data:`SITES` into one grid (see the module docstring)."""
    return stitch([(name, *_site_grid(data, name, yaw), yaw) for name, yaw in SITES],
                  GAP, BORDER)


def stitch(grids: list[tuple[str, OccupancyMap, bool, float]], gap: float,
           border: float) -> Campus:
    """
    Paste ``(name, map, real, yaw degrees)`` maps apart on one grid of unknown cells.

    The maps must share :data:`RESOLUTION` and have no yaw of their own; ``yaw`` says by how
    much each was turned (about its world origin) before its map was made, which each site's
    transform includes. They are packed by :func:`_pack`, ``gap`` metres apart and ``border``
    metres from the edge.
    """
    for name, grid, _, _ in grids:
        if abs(grid.resolution - RESOLUTION) > 1e-9 or grid.origin[2]:
            raise ValueError(f'campus: {name} must be an unturned map at {RESOLUTION} m a cell')
    places, height, width = _pack([g.shape for _, g, _, _ in grids],
                                  int(round(gap / RESOLUTION)), int(round(border / RESOLUTION)))
    cells = np.full((height, width), -1, dtype=np.int8)
    sites = []
    for (name, grid, real, yaw), (r0, c0) in zip(grids, places):
        h, w = grid.shape
        cells[r0:r0 + h, c0:c0 + w] = grid.data
        # the building's cell (r, c) is the campus cell (r + r0, c + c0); the turn was applied
        # about the building's world origin before the map was built
        move = (c0 * RESOLUTION - grid.origin[0], r0 * RESOLUTION - grid.origin[1], 0.0)
        sites.append(Site(name, real, compose(move, (0.0, 0.0, math.radians(yaw))),
                          (r0, c0, h, w)))
    return Campus(OccupancyMap(cells, RESOLUTION, (0.0, 0.0, 0.0)), tuple(sites))


def campus_map(data: Path, work: Path) -> Campus:
    """Return the campus; its map and sites are cached in ``work`` (built on first use)."""
    path = work / f'campus_v{CAMPUS_VERSION}.yaml'
    table = path.with_suffix('.json')
    if path.exists() and table.exists():
        grid = load_map_yaml(path, max_cells=0)
        sites = tuple(Site(d['name'], bool(d['real']), tuple(d['transform']),
                           tuple(d['cells'])) for d in json.loads(table.read_text()))
        return Campus(grid, sites)
    campus = build_campus(data)
    save_map_yaml(campus.grid, path)
    table.write_text(json.dumps([dataclasses.asdict(s) for s in campus.sites], indent=1))
    return campus


@dataclass(frozen=True)
class SiteQueries:
    """The query scans of one site, their ground truth in the campus frame (base poses)."""

    site: str
    scans: list[ScanRecord]
    truth: list[Pose2]


def site_queries(data: Path, site: Site, count: int, seed: int) -> SiteQueries:
    """
    Return the site's ``count`` queries.

    Real: odd-numbered scans evenly spread over the log (``places.odd_scans``; 0: all);
    simulated: random poses on the site's own map (the paper's protocol, seeded), ray-cast
    there: no other site lies within the laser's range, so the campus would give the same ranges.
    """
    if site.real:
        log = read_carmen_log(data / 'carmen' / f'{REAL_PLACES[site.name]}-corrected.log.gz')
        scans, truth = odd_scans(log, count)
    else:
        scans, by_stamp = sim_queries(_sim_grid(data, site.name), count, seed, {})
        truth = [by_stamp[s.stamp] for s in scans]
    return SiteQueries(site.name, scans, [compose(site.transform, p) for p in truth])


def office_30m() -> OccupancyMap:
    """Return the synthetic 30 M-cell office (5480 x 5480 cells, seed 0)."""
    return office_map(size=OFFICE_30M_SIZE)


def outdoor_30m() -> OccupancyMap:
    """Return the synthetic 29 M-cell campus with outdoor parts (5400 x 5400 cells, seed 0)."""
    return outdoor_map(size=OUTDOOR_30M_SIZE)


def write_query_bag(path: Path, grid: OccupancyMap, queries: list[SiteQueries],
                    period: float = 0.1) -> Path:
    """
    Write ``queries`` as one bag (``/map``, ``/scan``, ``/ground_truth``) for ``replay``.

    The scans are restamped ``period`` seconds apart in the given order (the buildings' own
    stamps would collide); returns the bag's path.
    """
    scans, truth = [], {}
    for q in queries:
        for scan, pose in zip(q.scans, q.truth):
            stamp = round(1.0 + period * len(scans), 6)
            scans.append(dataclasses.replace(scan, stamp=stamp))
            truth[stamp] = pose
    return write_bag(path, map=grid, scans=scans, ground_truth=truth, overwrite=True)
