"""Map-side settings (paper section III): GVD topology, the index, occupancy-grid building."""
from __future__ import annotations

from dataclasses import dataclass
import math

from .fields import check_numbers, param
from .matcher import MatcherConfig


@dataclass(frozen=True)
class TopologyConfig:
    """GVD and node selection (lengths in metres; the algorithm: ``mapping/topology.py``)."""

    min_clearance: float = param(
        0.2, 'robot radius, metres: cells nearer an obstacle are not traversable')
    free_thresh: int = param(
        25, 'occupancy at or below which a cell is free (others, unknown included, are obstacles)')
    ridge_ratio: float = param(
        0.5,
        'minimum separation of the two nearest obstacle points, as a fraction of the clearance, '
        'for a cell to be on the GVD (0.5: they subtend >= 29 deg)')
    spur_factor: float = param(
        1.5,
        'terminal GVD arcs (spurs) shorter than this times the clearance of their junction are '
        'pruned')
    weak_spur_factor: float = param(
        2.0, 'spur_factor is multiplied by this for weak arcs (wall noise)')
    min_spur_length: float = param(
        0.5, 'spurs and skeleton pieces shorter than this are pruned, metres')
    merge_radius: float = param(0.5, 'nodes closer than this are merged, metres')
    dead_end_nodes: bool = param(True, 'add nodes at the dead ends of GVD arcs')
    region_nodes: bool = param(
        True, 'add one node to every GVD component / free region without a node')
    arc_spacing: float = param(
        2.5, 'maximum geodesic spacing of nodes along the GVD, metres (0 disables arc nodes)')
    min_region_area: float = param(0.5, 'free regions smaller than this (m^2) get no region node')

    def __post_init__(self) -> None:
        check_numbers(self, nonnegative=('min_clearance', 'ridge_ratio', 'spur_factor',
                                         'weak_spur_factor', 'min_spur_length', 'merge_radius',
                                         'arc_spacing', 'min_region_area'))
        if not 0 <= self.free_thresh <= 100:
            raise ValueError(f'TopologyConfig.free_thresh: expected 0..100, got '
                             f'{self.free_thresh!r}')


@dataclass(frozen=True)
class IndexConfig:
    """Index parameters. The ``beams`` virtual beams cover 360 deg from -pi counterclockwise."""

    topology: TopologyConfig = param(
        help='GVD and node selection (TopologyConfig)', default_factory=TopologyConfig)
    beams: int = param(360, 'beams of each virtual scan taken at a topological node (full turn)')
    max_range: float = param(
        20.0, 'range of the virtual laser when casting the node scans, metres')
    sensor_pose: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0),
        "the laser's pose on the robot (x, y, yaw; Table 1: x_sens, y_sens, theta_sens); the "
        'nodes set it from laser_x/laser_y/laser_yaw')
    occupied_thresh: int = param(
        65, 'occupancy at or above which a cell stops a virtual beam (unknown cells do not)')
    matcher: MatcherConfig = param(
        help='scan matcher settings (MatcherConfig); the localizer matches with these too',
        default_factory=MatcherConfig)

    def __post_init__(self) -> None:
        if not isinstance(self.beams, int) or isinstance(self.beams, bool) or self.beams < 8:
            raise ValueError(f'IndexConfig.beams: expected an integer >= 8, got {self.beams!r}')
        check_numbers(self, positive=('max_range',))
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

    resolution: float = param(0.05, 'cell size of the map, metres')
    margin: float = param(1.0, 'unknown border around the observed area, metres')
    max_range: float = param(
        40.0, 'finite readings beyond this (metres) only clear space up to it')
    free_cap: float = param(5.0, 'no-return beams clear space up to this distance, metres')
    occupied_ratio: float = param(0.3, 'occupied if hits >= ratio * (hits + misses)')
    min_hits: int = param(1, 'a cell with fewer hits is never occupied')
    chunk_beams: int = param(20000, 'beams traversed per vectorized batch')

    def __post_init__(self) -> None:
        check_numbers(self, positive=('resolution', 'max_range'),
                      nonnegative=('margin', 'free_cap'))
        if not (isinstance(self.occupied_ratio, (int, float))
                and 0.0 <= self.occupied_ratio <= 1.0):
            raise ValueError(f'MapBuildConfig.occupied_ratio: expected 0..1, got '
                             f'{self.occupied_ratio!r}')
        for name in ('min_hits', 'chunk_beams'):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f'MapBuildConfig.{name}: expected an integer >= 1, got {v!r}')
