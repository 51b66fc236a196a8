"""
The map-size guard shared by the command line, the library and the ROS nodes.

A grid of ``width x height`` cells costs several bytes per cell to index (distance transforms,
the GVD, float images while decoding), so oversized maps are refused by their declared size,
before any memory is spent on them.

The default is what fits a 2 GB process: indexing and localizing on the densest map measured,
the synthetic office of ``bench/synthetic.py`` at 6000 x 6000 cells (wall-to-wall rooms, 13 301
nodes), peaks at 1.85 GB as a whole process (``bench index``); maps with open or unknown space
between buildings cost less (the 27.6 M-cell campus: 0.9 GB).
"""
from __future__ import annotations

import math

from ..matching.scan import MAX_ANGLE

#: default limit: 36 M cells (a 300 m x 300 m site at 5 cm); 0 disables the guard
MAX_MAP_CELLS = 36_000_000


#: map resolutions accepted, metres per cell: a laser map finer than a millimetre or coarser than
#: 10 m is a unit mistake (a resolution in mm or km), not a map to localize in
MIN_RESOLUTION = 1e-3
MAX_RESOLUTION = 10.0


#: map origins accepted: x and y within this many metres of 0 (UTM northings reach 1e7 m; a
#: float64 resolves 1.5e-8 m at 1e8, a 1e16 origin only 2 m), the yaw within a full turn either
#: way (beyond it a yaw in degrees, or a field never set)
MAX_ORIGIN = 1e8
MAX_ORIGIN_YAW = MAX_ANGLE


class MapTooLargeError(ValueError):
    """A map whose cell count exceeds the configured ``max_map_cells``."""


def check_map_cells(width: int, height: int, max_cells: int, where: str = 'map') -> None:
    """
    Raise :class:`MapTooLargeError` when ``width * height > max_cells``.

    ``max_cells`` 0 means no limit; ``ValueError`` for a negative limit. The message names
    ``where``.
    """
    if max_cells < 0:
        raise ValueError(f'max_map_cells must be >= 0 (0 = no limit), got {max_cells}')
    cells = int(width) * int(height)
    if max_cells and cells > max_cells:
        raise MapTooLargeError(f'{where}: map of {int(width)} x {int(height)} cells exceeds '
                               f'max_map_cells = {max_cells} (0 = no limit)')


def check_resolution(resolution: float, where: str = 'map') -> float:
    """
    Return ``resolution`` as a float if it is a plausible map resolution.

    ``ValueError`` naming ``where`` unless it lies in [:data:`MIN_RESOLUTION`,
    :data:`MAX_RESOLUTION`] metres per cell.
    """
    res = float(resolution)
    if not MIN_RESOLUTION <= res <= MAX_RESOLUTION:
        raise ValueError(f'{where}: resolution {res!r} m per cell is outside '
                         f'[{MIN_RESOLUTION}, {MAX_RESOLUTION}] (a unit mistake?)')
    return res


def check_origin(origin, where: str = 'map') -> tuple[float, float, float]:
    """
    Return ``origin`` as ``(x, y, yaw)`` floats if it is a plausible map origin.

    ``ValueError`` naming ``where`` unless all three are finite, ``|x|, |y| <=``
    :data:`MAX_ORIGIN` and ``|yaw| <=`` :data:`MAX_ORIGIN_YAW`.
    """
    x, y, yaw = (float(v) for v in origin)
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
        raise ValueError(f'{where}: origin ({x!r}, {y!r}, {yaw!r}) must be finite')
    if max(abs(x), abs(y)) > MAX_ORIGIN:
        raise ValueError(f'{where}: origin ({x:g}, {y:g}) lies more than {MAX_ORIGIN:g} m from '
                         '0, where coordinates lose their precision (shift the map frame)')
    if abs(yaw) > MAX_ORIGIN_YAW:
        raise ValueError(f'{where}: origin yaw {yaw:g} rad lies beyond a full turn (degrees '
                         'for radians?)')
    return x, y, yaw
