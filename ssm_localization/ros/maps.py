"""Maps received on a topic: OccupancyGrid -> OccupancyMap with the nodes' size guard."""
from __future__ import annotations

from nav_msgs.msg import OccupancyGrid
from ssm_localization.mapping.map_io import occupancy_map_from_msg, OccupancyMap


def map_from_msg(msg: OccupancyGrid, max_cells: int) -> OccupancyMap:
    """
    Convert OccupancyGrid -> OccupancyMap with a size guard.

    Raises ValueError with the reason.
    """
    cells = int(msg.info.width) * int(msg.info.height)
    if max_cells > 0 and cells > max_cells:
        raise ValueError(f'map of {msg.info.width} x {msg.info.height} cells exceeds '
                         f'max_map_cells = {max_cells}')
    if not msg.info.resolution > 0.0:
        raise ValueError(f'map resolution must be > 0, got {msg.info.resolution}')
    occ = occupancy_map_from_msg(msg)
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
