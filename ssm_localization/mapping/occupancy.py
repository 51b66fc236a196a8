"""
Occupancy grid maps (numpy only): :class:`OccupancyMap` and nav_msgs/OccupancyGrid messages.

The grid follows nav_msgs/OccupancyGrid: ``data[r, c]`` in ``-1`` (unknown) or ``0..100``, row 0 at
the bottom (smallest y); cell (r, c) has its centre at
``origin_xy + R(origin_yaw) @ ((c + 0.5) res, (r + 0.5) res)``. Map files (YAML + image) are
read and written by ``map_io.py``.
"""
from __future__ import annotations

from dataclasses import dataclass
import hashlib
import math

import numpy as np

from .map_limits import check_map_cells, check_origin, check_resolution
from ..files.reading import echo
from ..transforms import apply, planar_yaw

#: largest magnitude of the resolution (nav_msgs/MapMetaData carries it as float32) and of the
#: origin's fields (checked against :data:`map_limits.MAX_ORIGIN` too)
FLOAT32_MAX = float(np.finfo(np.float32).max)


def fits_float32(v: float) -> bool:
    """Tell whether ``v`` is finite and within float32 range (what a map message carries)."""
    return math.isfinite(v) and abs(v) <= FLOAT32_MAX


def canonical(v: float) -> float:
    """
    Return the shortest decimal that rounds to the same float32 as ``v``.

    nav_msgs/MapMetaData carries the resolution as float32, a map YAML file as a decimal:
    ``0.05`` arrives as ``0.05000000074505806`` over the wire. The origin's yaw travels as a
    quaternion and comes back with rounding noise. Every map is stored with the canonical
    resolution and yaw, so the same map gives the same numbers, whichever way it came (the
    origin's x and y are float64 both ways and kept as they are).
    """
    return float(np.format_float_positional(np.float32(v), unique=True, trim='0'))


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """An occupancy grid (see module docstring for the cell convention)."""

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    frame_id: str = 'map'

    def __post_init__(self) -> None:
        data = np.asarray(self.data)
        if data.ndim != 2 or data.shape[0] < 1 or data.shape[1] < 1:
            raise ValueError(f'OccupancyMap.data: expected a non-empty (H, W) array, '
                             f'got shape {data.shape}')
        if not np.issubdtype(data.dtype, np.integer):
            raise ValueError(f'OccupancyMap.data: expected integers, got {data.dtype}')
        if data.size and (data.min() < -1 or data.max() > 100):
            raise ValueError('OccupancyMap.data: values must be -1 (unknown) or 0..100')
        res = float(self.resolution)
        if not (fits_float32(res) and res > 0.0):
            raise ValueError(f'OccupancyMap.resolution: expected a positive number within '
                             f'float32 range, got {res}')
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 3 or not all(map(fits_float32, origin)):
            raise ValueError(f'OccupancyMap.origin: expected finite (x, y, yaw) within float32 '
                             f'range, got {echo(self.origin)}')
        check_origin(origin, 'OccupancyMap')
        check_resolution(res, 'OccupancyMap')
        object.__setattr__(self, 'data', np.ascontiguousarray(data, dtype=np.int8))
        object.__setattr__(self, 'resolution', canonical(res))
        # the origin's x and y travel as float64 (geometry_msgs/Pose): kept as they are, since
        # rounding them to float32 would move a map with a UTM origin (5e6 m) by up to 0.25 m
        object.__setattr__(self, 'origin', (origin[0], origin[1], canonical(origin[2])))
        object.__setattr__(self, 'frame_id', str(self.frame_id))

    @property
    def height(self) -> int:
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    def occupied_mask(self, thresh: int = 65) -> np.ndarray:
        """Cells with occupancy ``>= thresh`` (bool (H, W))."""
        return self.data >= thresh

    def free_mask(self, thresh: int = 25) -> np.ndarray:
        """Known cells with occupancy ``<= thresh`` (bool (H, W))."""
        return (self.data >= 0) & (self.data <= thresh)

    def world_to_cell(self, xy) -> tuple[np.ndarray, np.ndarray]:
        """Integer ``(rows, cols)`` of the cells containing the (N, 2) points (may be off-grid)."""
        p = np.asarray(xy, dtype=float).reshape(-1, 2)
        ox, oy, oyaw = self.origin
        c, s = math.cos(oyaw), math.sin(oyaw)
        dx, dy = p[:, 0] - ox, p[:, 1] - oy
        u = (c * dx + s * dy) / self.resolution
        v = (-s * dx + c * dy) / self.resolution
        return np.floor(v).astype(np.int64), np.floor(u).astype(np.int64)

    def cell_to_world(self, rows, cols) -> np.ndarray:
        """Centres (N, 2) of the cells ``(rows, cols)``."""
        r = np.asarray(rows, dtype=float).reshape(-1)
        col = np.asarray(cols, dtype=float).reshape(-1)
        return apply(self.origin, np.column_stack((col + 0.5, r + 0.5)) * self.resolution)

    def in_bounds(self, rows, cols) -> np.ndarray:
        r, c = np.asarray(rows), np.asarray(cols)
        return (r >= 0) & (r < self.height) & (c >= 0) & (c < self.width)

    def checksum(self) -> str:
        """
        sha256 (hex) of the cells and the geometry (shape, resolution, origin).

        Geometry is hashed at float32 precision, as nav_msgs/OccupancyGrid carries it, so a map
        read from a YAML file and the same map received over the wire have the same checksum.
        """
        h = hashlib.sha256()
        h.update(np.asarray(self.data.shape, dtype='<i8').tobytes())
        h.update(np.asarray((self.resolution, *self.origin), dtype='<f4').tobytes())
        h.update(self.data.tobytes())
        return h.hexdigest()


# --------------------------------------------------------------------------- messages

def occupancy_map_from_msg(msg, max_cells: int = 0) -> OccupancyMap:
    """
    Return an :class:`OccupancyMap` from a nav_msgs/OccupancyGrid (rclpy or rosbags message).

    A map of more than ``max_cells`` cells (0, the default: no limit) raises
    :class:`~.map_limits.MapTooLargeError` before its data is converted.
    """
    try:
        info = msg.info
        width, height = int(info.width), int(info.height)
        resolution = float(info.resolution)
        pos, q = info.origin.position, info.origin.orientation
        quaternion = (float(q.x), float(q.y), float(q.z), float(q.w))
        frame_id = str(getattr(getattr(msg, 'header', None), 'frame_id', '') or 'map')
        raw = msg.data
    except AttributeError as exc:
        raise ValueError(f'OccupancyGrid message: missing field ({exc})') from None
    if width <= 0 or height <= 0:
        raise ValueError(f'OccupancyGrid message: empty map ({width} x {height})')
    try:
        yaw = planar_yaw(*quaternion, what='the origin orientation')
    except ValueError as exc:
        raise ValueError(f'OccupancyGrid message: {exc}') from None
    check_map_cells(width, height, max_cells, 'OccupancyGrid message')
    check_resolution(resolution, 'OccupancyGrid message')
    data = np.asarray(raw)
    if data.dtype.kind not in 'iu':
        data = np.asarray(raw, dtype=np.int64)
    unsigned = data.dtype.kind == 'u'
    data = data.astype(np.int16).reshape(-1)
    if data.size != width * height:
        raise ValueError(f'OccupancyGrid message: len(data) = {data.size} != width * height = '
                         f'{width} * {height}')
    if unsigned:
        data[data == 255] = -1                  # the uint8 view of int8 -1 (unknown)
    bad = np.flatnonzero((data < -1) | (data > 100))
    if bad.size:
        row, col = divmod(int(bad[0]), width)
        raise ValueError(f'OccupancyGrid message: {bad.size} cells hold values outside -1 '
                         f'(unknown) .. 100 (first: {int(data[bad[0]])} at row {row}, column '
                         f'{col}); not an occupancy grid')
    return OccupancyMap(data.reshape(height, width).astype(np.int8), resolution,
                        (float(pos.x), float(pos.y), yaw), frame_id)
