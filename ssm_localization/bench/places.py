"""
The benchmarks' places and labelled answers (shared data found by ``--data``).

A *place* is a map with query scans and their ground truth: a real building (the map of the
even-numbered scans of its CARMEN log, the odd-numbered scans as queries) or a simulated map
(random poses, 360 beams, 10 mm noise: the paper's protocol). An *answer* is one query localized
on one place's map and labelled:
- ``own``: the place's own scans, right when ``ok``-or-not the pose lies within 0.5 m / 5 deg;
- ``foreign``: scans of another place, never right (they are not on this map at all).
Each can be taken through an everyday sensor first (``io/sensors.py``).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np
from scipy import ndimage

from ..config.mapping import MapBuildConfig
from ..config.simulation import SimulationConfig
from ..evaluation.replay import within_success
from ..io.bag_records import ScanRecord
from ..io.carmen import build_map, CarmenLog, log_scan_records, read_carmen_log
from ..io.sensors import EVERYDAY_SENSORS, SensorLimits
from ..io.simulate import simulate
from ..localization.localizer import GlobalLocalizer, Localization, OK
from ..mapping.map_io import load_map_yaml, OccupancyMap, save_map_yaml
from ..transforms import Pose2

#: the shared logs, by short name
REAL_PLACES = {'intel': 'intel', 'aces': 'aces', 'fr079': 'freiburg-079', 'csail': 'csail',
               'fhw': 'fhw', 'edmonton': 'edmonton'}
#: the shared nav2 maps
SIM_PLACES = ('depot', 'tb3_sandbox', 'turtlebot3_world', 'empty_room')
#: maps of one and the same place (TurtleBot3's world and sandbox): never foreign to each other
SAME_PLACE = (frozenset({'tb3_sandbox', 'turtlebot3_world'}),)
#: cell size of the maps built from the logs unless a benchmark asks for another (metres): the
#: map builder's default, that of the real buildings the confidence was calibrated on
MAP_RESOLUTION = MapBuildConfig().resolution


def sim_queries(grid, n: int, seed: int, extra: dict):
    sim = simulate(grid, SimulationConfig(count=n, seed=seed, **extra))
    truth = {s.stamp: tuple(float(v) for v in p) for s, p in zip(sim.scans, sim.poses)}
    return sim.scans, truth


def odd_scans(log: CarmenLog, count: int) -> tuple[list[ScanRecord], list[Pose2]]:
    """
    Return the queries of a log: ``count`` odd-numbered scans spread evenly over it (0: all).

    With their corrected poses, the ground truth (the map is built from the even-numbered ones).
    """
    odd = list(range(1, len(log), 2))
    if count and len(odd) > count:
        step = len(odd) / count
        odd = [odd[int(i * step)] for i in range(count)]
    return log_scan_records(log, odd), [tuple(float(v) for v in log.poses[k]) for k in odd]


def real_map(data: Path, work: Path, name: str, resolution: float = MAP_RESOLUTION):
    """
    Return the CARMEN log ``name`` and the map of its even-numbered scans.

    The map is cached in ``work``; ``resolution`` is its cell size (metres).
    """
    log = read_carmen_log(data / 'carmen' / f'{name}-corrected.log.gz')
    return log, real_grid(data, work, name, log, resolution)


def real_grid(data: Path, work: Path, name: str, log: CarmenLog | None = None,
              resolution: float = MAP_RESOLUTION):
    """Return the map of :func:`real_map`; the log is read only to build a map not cached yet."""
    # the cell size in the name to the micrometre (49.6 mm and 50.4 mm are two maps)
    map_yaml = work / (f'{name}_even.yaml' if resolution == MAP_RESOLUTION
                       else f'{name}_even_{round(resolution * 1000, 3):g}mm.yaml')
    if map_yaml.exists():
        cached = load_map_yaml(map_yaml)
        if math.isclose(cached.resolution, resolution, rel_tol=1e-6):
            return cached
    if log is None:
        log = read_carmen_log(data / 'carmen' / f'{name}-corrected.log.gz')
    grid = build_map(log, indices=range(0, len(log), 2),
                     config=MapBuildConfig(resolution=resolution))
    save_map_yaml(grid, map_yaml)       # creates work/
    return grid


@dataclass(frozen=True)
class MapVariant:
    """
    How a benchmark's real maps differ from those built from the even scans at 0.05 m.

    The queries stay the building's scans (or, for simulated scans on a real map, are cast on
    the map as built): only the map the localizer is given changes, as a user's map differs
    from the world. ``resolution``: the cell size the map is built at (metres); ``dilate``: the
    occupied cells grown by this many cells (8-connected), the thick walls of many SLAM maps
    (their boundary a cell nearer the free space per cell grown); ``specks``: this fraction of
    the free cells made occupied (seeded), the specks a map keeps of passing people and noise.
    """

    resolution: float = MAP_RESOLUTION
    dilate: int = 0
    specks: float = 0.0

    def __post_init__(self) -> None:
        if not (self.resolution > 0 and self.dilate >= 0 and 0.0 <= self.specks < 1.0):
            raise ValueError(f'MapVariant: resolution > 0, dilate >= 0 and specks in [0, 1), '
                             f'got {self}')

    def degrade(self, grid: OccupancyMap) -> OccupancyMap:
        """Return ``grid`` with the walls grown and the specks added (itself if neither)."""
        if not self.dilate and not self.specks:
            return grid
        d = grid.data.copy()
        if self.dilate:
            grown = ndimage.binary_dilation(d >= 65, np.ones((3, 3), bool),
                                            iterations=self.dilate)
            d[grown] = 100
        if self.specks:
            free = np.flatnonzero(d.ravel() == 0)
            rng = np.random.default_rng(0)
            d.ravel()[rng.choice(free, int(round(self.specks * len(free))), replace=False)] = 100
        return OccupancyMap(d, grid.resolution, grid.origin, grid.frame_id)

    def __str__(self) -> str:
        parts = [f'{self.resolution:g} m cells'] + (
            [f'walls grown by {self.dilate} cells'] if self.dilate else []) + (
            [f'{self.specks:.2%} of the free cells specks'] if self.specks else [])
        return ', '.join(parts)


@dataclass(frozen=True)
class Place:
    """A map and query scans with their ground truth (base poses in the map frame)."""

    name: str
    grid: OccupancyMap
    scans: list[ScanRecord]
    truth: list[Pose2]


@dataclass(frozen=True)
class Answer:
    """One labelled answer: which map, whose scans, through which sensor, and what came out."""

    map: str                 # noqa: A003 - the place whose map was used
    source: str              # the place whose scan it is
    sensor: str
    loc: Localization
    right: bool              # the pose lies within the success bounds of the truth

    @property
    def own(self) -> bool:
        return self.map == self.source

    @property
    def ok(self) -> bool:
        return self.loc.status == OK


def foreign(a: str, b: str) -> bool:
    """Tell whether scans of place ``b`` are foreign to the map of place ``a``."""
    return a != b and not any({a, b} <= s for s in SAME_PLACE)


def load_place(name: str, data: Path, work: Path, count: int, seed: int = 1,
               variant: MapVariant = MapVariant()) -> Place:
    """
    Return the place ``name`` with ``count`` queries.

    Real: ``count`` odd-numbered scans evenly spread over the log (0: all), the map built and
    degraded as ``variant`` says; simulated: ``count`` random poses (seeded) on the map as
    shipped.
    """
    if name in REAL_PLACES:
        log, grid = real_map(data, work, REAL_PLACES[name], variant.resolution)
        return Place(name, variant.degrade(grid), *odd_scans(log, count))
    if name in SIM_PLACES:
        grid = load_map_yaml(data / 'maps' / f'{name}.yaml')
        scans, truth = sim_queries(grid, count, seed, {})
        return Place(name, grid, scans, [truth[s.stamp] for s in scans])
    raise ValueError(f'unknown place {name!r} (real: {sorted(REAL_PLACES)}, simulated: '
                     f'{list(SIM_PLACES)})')


def answers_on(localizer: GlobalLocalizer, map_name: str, place: Place,
               sensors: Sequence[str] = ('full',), limit: int = 0,
               seed: int = 0) -> Iterator[Answer]:
    """
    Localize the scans of ``place`` on ``localizer``'s map (that of ``map_name``).

    ``localizer``: anything with ``localize_scan`` (the exhaustive search of ``bench/peer.py``
    too). Own scans are labelled against their truth; foreign ones are never right. ``limit`` > 0
    takes that many of the place's scans (a seeded random choice, the same for every map).
    """
    own = map_name == place.name
    picks = np.arange(len(place.scans))
    if limit and len(picks) > limit:
        picks = np.sort(np.random.default_rng(seed).choice(picks, limit, replace=False))
    for sensor in sensors:
        limits: SensorLimits = EVERYDAY_SENSORS[sensor]
        for k in picks:
            scan = limits.apply(place.scans[k])
            loc = localizer.localize_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                          scan.range_min, scan.range_max)
            right = own and within_success(loc.pose, place.truth[k])
            yield Answer(map_name, place.name, sensor, loc, right)
