"""Map-side settings (paper section III): GVD topology, the index, occupancy-grid building."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .matcher import MatcherConfig


@dataclass(frozen=True)
class TopologyConfig:
    """GVD and node selection parameters (lengths in metres).

    ``min_clearance``: robot radius; cells nearer an obstacle are not traversable.
    ``free_thresh``: occupancy at or below which a cell is free (others, unknown included, are
    obstacles). ``ridge_ratio``: minimum separation of the two nearest obstacle points, as a
    fraction of the clearance, for a cell to be on the GVD (0.5: they subtend >= 29 deg).
    ``spur_factor``, ``weak_spur_factor``, ``min_spur_length``: pruning (module doc).
    ``merge_radius``: nodes closer than this are merged. ``dead_end_nodes``, ``region_nodes``:
    enable the extras; ``arc_spacing``: maximum geodesic spacing of nodes along the GVD
    (0 disables arc nodes).
    ``min_region_area``: free regions smaller than this (m^2) get no region node.
    """

    min_clearance: float = 0.2
    free_thresh: int = 25
    ridge_ratio: float = 0.5
    spur_factor: float = 1.5
    weak_spur_factor: float = 2.0
    min_spur_length: float = 0.5
    merge_radius: float = 0.5
    dead_end_nodes: bool = True
    region_nodes: bool = True
    arc_spacing: float = 2.5
    min_region_area: float = 0.5

    def __post_init__(self) -> None:
        for name in ('min_clearance', 'ridge_ratio', 'spur_factor', 'weak_spur_factor',
                     'min_spur_length', 'merge_radius', 'arc_spacing', 'min_region_area'):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f'TopologyConfig.{name}: expected a number >= 0, got {v!r}')
        if not 0 <= self.free_thresh <= 100:
            raise ValueError(f'TopologyConfig.free_thresh: expected 0..100, got '
                             f'{self.free_thresh!r}')


@dataclass(frozen=True)
class IndexConfig:
    """Index parameters. ``beams`` virtual beams over 360 deg from -pi counterclockwise,
    ``max_range`` (m) of the virtual laser, ``sensor_pose`` (x, y, yaw) of the laser on the robot
    (Table 1: x_sens, y_sens, theta_sens), ``occupied_thresh``: occupancy at or above which a cell
    stops a beam (unknown cells do not)."""

    topology: TopologyConfig = field(default_factory=TopologyConfig)
    beams: int = 360
    max_range: float = 20.0
    sensor_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    occupied_thresh: int = 65
    matcher: MatcherConfig = field(default_factory=MatcherConfig)

    def __post_init__(self) -> None:
        if not isinstance(self.beams, int) or isinstance(self.beams, bool) or self.beams < 8:
            raise ValueError(f'IndexConfig.beams: expected an integer >= 8, got {self.beams!r}')
        if not (isinstance(self.max_range, (int, float)) and self.max_range > 0
                and math.isfinite(self.max_range)):
            raise ValueError(f'IndexConfig.max_range: expected a number > 0, got '
                             f'{self.max_range!r}')
        pose = tuple(float(v) for v in self.sensor_pose)
        if len(pose) != 3 or not all(map(math.isfinite, pose)):
            raise ValueError(f'IndexConfig.sensor_pose: expected finite (x, y, yaw), got '
                             f'{self.sensor_pose!r}')
        object.__setattr__(self, 'sensor_pose', pose)
        if not 1 <= self.occupied_thresh <= 100:
            raise ValueError(f'IndexConfig.occupied_thresh: expected 1..100, got '
                             f'{self.occupied_thresh!r}')


@dataclass(frozen=True)
class MapBuildConfig:
    """Occupancy-grid building from scans at known poses (hit / miss counting)."""

    resolution: float = 0.05
    margin: float = 1.0            # metres of unknown border around the observed area
    max_range: float = 40.0        # finite readings beyond this only clear space up to it
    free_cap: float = 5.0          # no-return beams clear space up to this distance
    occupied_ratio: float = 0.3    # occupied if hits >= ratio * (hits + misses)
    min_hits: int = 1
    chunk_beams: int = 20000       # beams traversed per vectorized batch
