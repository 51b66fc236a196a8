"""Maps received on a topic: OccupancyGrid -> OccupancyMap with the nodes' size guard."""
from __future__ import annotations

from nav_msgs.msg import OccupancyGrid
from ssm_localization.mapping.occupancy import occupancy_map_from_msg, OccupancyMap


def map_from_msg(msg: OccupancyGrid, max_cells: int) -> OccupancyMap:
    """
    Convert OccupancyGrid -> OccupancyMap with a size guard.

    The size is checked before the cells are converted (``mapping.map_limits``; ``max_cells``
    0: no limit). Raises ValueError with the reason.
    """
    occ = occupancy_map_from_msg(msg, max_cells)
    if not occ.free_mask().any():
        raise ValueError('map has no free cells: nothing to index')
    return occ


def usable_map(msg: OccupancyGrid, max_cells: int, logger) -> OccupancyMap | None:
    """:func:`map_from_msg`, or None after a logged warning: bad maps never stop a node."""
    try:
        return map_from_msg(msg, max_cells)
    except (ValueError, AttributeError) as exc:
        logger.warning(f'ignoring map: {exc}')
        return None
