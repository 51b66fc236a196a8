"""
What a localizer derives from its map once: the layers every scan is matched against.

- the correlative search's likelihood pyramid (``correlative.py``),
- the wall-surface model of the refinement and the evidence (``refine.py``),
- the ray caster of the beam check (``mapping/raycast.py``),
- the pose voting's pooled node features (``voting.py``),
- the regions the correlative search looks in, each at its own yaws (``regions.py``).

Each is built to cost memory with what it holds (see their modules: the pyramid padded on one
side, the surface stored only near walls, the caster at two bytes a cell), and each exactly as
before: the numbers the localizer computes from them do not depend on how they are stored.
``build_map_layers`` takes a :data:`~ssm_localization.progress.LayerHook` so that ``bench
index`` can say what each layer costs.
"""
from __future__ import annotations

from dataclasses import dataclass

from .correlative import CorrelativeGrid
from .refine import exact_reach, SurfaceModel
from .regions import SearchRegions
from .voting import PoseVoting
from ..config.localization import LocalizerConfig
from ..mapping.index import MapIndex
from ..mapping.raycast import RayCaster
from ..progress import LayerHook, no_layers

#: names of the layers, in the order they are built
LAYER_NAMES = ('correlative grid', 'wall surface', 'ray caster', 'voting', 'search regions')


@dataclass(frozen=True, eq=False)
class MapLayers:
    """The map-only structures of a :class:`~.localizer.GlobalLocalizer`."""

    voting: PoseVoting
    grid: CorrelativeGrid
    surface: SurfaceModel
    caster: RayCaster
    regions: SearchRegions


def build_map_layers(index: MapIndex, cfg: LocalizerConfig,
                     layer: LayerHook = no_layers) -> MapLayers:
    """Return the layers of ``index`` for the localizer settings ``cfg``."""
    m = index.map
    thresh = index.config.occupied_thresh
    with layer(LAYER_NAMES[0]):
        grid = CorrelativeGrid(m, occupied_thresh=thresh, sigma=cfg.search_sigma,
                               depth=cfg.search_depth, max_range=cfg.max_cast_range,
                               coarsen=search_coarsening(m.width * m.height, m.resolution,
                                                         cfg),
                               workers=cfg.search_workers)
    with layer(LAYER_NAMES[1]):
        # exact wherever the refinement, the evidence or the explained fraction can look
        reach = exact_reach(cfg.score_sigma, max(cfg.refine_radius))
        surface = SurfaceModel.from_occupancy(m.occupied_mask(thresh), m.resolution, m.origin,
                                              cfg.surface_depth, reach=reach)
    with layer(LAYER_NAMES[2]):
        caster = index.ray_caster()     # the virtual scans' when the index was built here
    with layer(LAYER_NAMES[3]):
        voting = PoseVoting(index, cfg.vote_neighbours, cfg.vote_bin_xy, cfg.vote_bin_yaw,
                            search_dims=cfg.vote_descriptor_dims, workers=cfg.vote_workers)
    with layer(LAYER_NAMES[4]):
        regions = SearchRegions.build(grid, voting, index.node_xy)
    return MapLayers(voting=voting, grid=grid, surface=surface, caster=caster,
                     regions=regions)


def search_coarsening(cells: int, resolution: float, cfg: LocalizerConfig) -> int:
    """
    Return how many map cells wide a cell of the correlative search is.

    ``search_cell`` in map cells (at least one), doubled while the search grid would hold more
    than ``search_max_cells`` cells: the search's cost grows with its cells. Powers of two,
    because on the campus cells two and four times as wide kept the right answers and three
    times as wide lost some (CHANGELOG.rst, the search grid cap).
    """
    coarsen = max(1, round(cfg.search_cell / resolution))
    if cfg.search_max_cells > 0:
        while cells / coarsen ** 2 > cfg.search_max_cells:
            coarsen *= 2
    return coarsen
