"""
Occupancy grid maps: nav2 map_server YAML + image files and nav_msgs/OccupancyGrid messages.

The grid follows nav_msgs/OccupancyGrid: ``data[r, c]`` in ``-1`` (unknown) or ``0..100``, row 0 at
the bottom (smallest y); cell (r, c) has its centre at
``origin_xy + R(origin_yaw) @ ((c + 0.5) res, (r + 0.5) res)``. Image row 0 is the top of the map,
so loading and saving flip the rows.
"""
from __future__ import annotations

from dataclasses import dataclass
import hashlib
import math
from pathlib import Path

import numpy as np
from PIL import Image

from .map_image import read_shade
from .map_limits import check_map_cells, check_resolution, MAX_MAP_CELLS
from ..files.reading import echo, input_file
from ..files.writing import atomic_files
from ..files.yaml_input import load_yaml_file
from ..transforms import apply, planar_yaw

#: how map_server reads the image's pixels (the map YAML's ``mode``)
MAP_IMAGE_MODES = ('trinary', 'scale', 'raw')


#: largest magnitude of the resolution and origin: nav_msgs/OccupancyGrid carries them as float32
FLOAT32_MAX = float(np.finfo(np.float32).max)


def _fits_float32(v: float) -> bool:
    return math.isfinite(v) and abs(v) <= FLOAT32_MAX


def canonical(v: float) -> float:
    """
    Return the shortest decimal that rounds to the same float32 as ``v``.

    nav_msgs/OccupancyGrid carries the resolution and origin as float32, a map YAML file as
    decimals: ``0.05`` arrives as ``0.05000000074505806`` over the wire. Every map is stored with
    the canonical value, so the same map gives the same numbers, whichever way it came.
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
        if not (_fits_float32(res) and res > 0.0):
            raise ValueError(f'OccupancyMap.resolution: expected a positive number within '
                             f'float32 range, got {res}')
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 3 or not all(map(_fits_float32, origin)):
            raise ValueError(f'OccupancyMap.origin: expected finite (x, y, yaw) within float32 '
                             f'range, got {echo(self.origin)}')
        check_resolution(res, 'OccupancyMap')
        object.__setattr__(self, 'data', np.ascontiguousarray(data, dtype=np.int8))
        object.__setattr__(self, 'resolution', canonical(res))
        object.__setattr__(self, 'origin', tuple(canonical(v) for v in origin))
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


# --------------------------------------------------------------------------- map_server files

def _field(doc: dict, name: str, path: Path, kind, required: bool = True, default=None):
    if name not in doc:
        if required:
            raise ValueError(f'{path}: missing field {name!r}')
        return default
    value = doc[name]
    try:
        if kind is float:
            if isinstance(value, bool):
                raise TypeError
            out = float(value)
            if not math.isfinite(out):
                raise TypeError
            return out
        if kind is bool:  # map_server accepts 0/1 or true/false
            if isinstance(value, bool) or value in (0, 1):
                return bool(value)
            raise TypeError
        if kind is str:
            if not isinstance(value, str) or not value:
                raise TypeError
            return value
        if kind == 'origin':
            if not isinstance(value, (list, tuple)) or len(value) != 3:
                raise TypeError
            out3 = tuple(float(v) for v in value)
            if any(isinstance(v, bool) for v in value) or not all(map(math.isfinite, out3)):
                raise TypeError
            return out3
    except (TypeError, ValueError):
        pass
    want = {float: 'a number', bool: '0/1 or true/false', str: 'a non-empty string',
            'origin': 'a list [x, y, yaw] of 3 numbers'}[kind]
    raise ValueError(f'{path}: field {name!r} must be {want}, got {echo(value)}')


def load_map_yaml(path: str | Path, max_cells: int = MAX_MAP_CELLS) -> OccupancyMap:
    """
    Load a nav2 map_server map (YAML + PGM/PNG), following map_server's ``loadMapFromFile``.

    ``p = 1 - shade`` (``shade`` if ``negate``); trinary: ``p > occupied_thresh`` -> 100,
    ``p < free_thresh`` -> 0, else -1; scale: the same with a linear 0..100 between the
    thresholds; raw: the pixel value (``-1`` outside 0..100). Alpha is ignored.

    Bounded: the YAML is read with :func:`~ssm_localization.files.yaml_input.load_yaml_file`
    (size and alias limits) and an image of more than ``max_cells`` pixels (0: no limit) is
    refused from its header, before decoding. Bad input raises ``ValueError`` (missing files
    ``FileNotFoundError``) naming the file and field.
    """
    path = input_file(path, 'map YAML')
    doc = load_yaml_file(path, 'map YAML')
    if not isinstance(doc, dict):
        raise ValueError(f'{path}: expected a mapping with image, resolution, origin, ...')
    image = _field(doc, 'image', path, str)
    resolution = _field(doc, 'resolution', path, float)
    check_resolution(resolution, str(path))
    origin = _field(doc, 'origin', path, 'origin')
    if not all(map(_fits_float32, (resolution, *origin))):
        raise ValueError(f"{path}: fields 'resolution' and 'origin' must be within float32 "
                         f'range (|v| <= {FLOAT32_MAX:.3g}), as map messages carry them')
    negate = _field(doc, 'negate', path, bool, required=False, default=False)
    occ_t = _field(doc, 'occupied_thresh', path, float, required=False, default=0.65)
    free_t = _field(doc, 'free_thresh', path, float, required=False, default=0.25)
    if not 0.0 <= occ_t <= 1.0:
        raise ValueError(f"{path}: field 'occupied_thresh' must be in [0, 1], got {occ_t}")
    if not 0.0 <= free_t <= 1.0:
        raise ValueError(f"{path}: field 'free_thresh' must be in [0, 1], got {free_t}")
    if free_t > occ_t:
        raise ValueError(f'{path}: free_thresh ({free_t}) must not exceed occupied_thresh '
                         f'({occ_t})')
    mode = doc.get('mode', 'trinary')
    if mode not in MAP_IMAGE_MODES:
        raise ValueError(f"{path}: field 'mode' must be one of {MAP_IMAGE_MODES}, "
                         f'got {echo(mode)}')
    img_path = Path(image)
    if not img_path.is_absolute():
        img_path = path.parent / img_path
    try:
        input_file(img_path, 'map image')
    except (FileNotFoundError, ValueError) as exc:
        raise type(exc)(f'{path}: {exc}') from None
    shade = read_shade(img_path, max_cells)
    data = _shade_to_occupancy(shade, mode, negate, occ_t, free_t)
    return OccupancyMap(np.flipud(data), resolution, origin, 'map')


def _shade_to_occupancy(shade: np.ndarray, mode: str, negate: bool, occ_t: float,
                        free_t: float) -> np.ndarray:
    if mode == 'raw':
        v = np.round(shade * 255.0)
        return np.where((v >= 0) & (v <= 100), v, -1).astype(np.int8)
    p = shade if negate else 1.0 - shade
    out = np.full(shade.shape, -1, dtype=np.int8)
    if mode == 'scale':
        span = max(occ_t - free_t, 1e-12)
        out[:] = np.rint(np.clip((p - free_t) / span, 0.0, 1.0) * 100.0).astype(np.int8)
    out[p > occ_t] = 100
    out[p < free_t] = 0
    return out


def save_map_yaml(occ_map: OccupancyMap, yaml_path: str | Path) -> Path:
    """
    Write ``yaml_path`` and a trinary PGM beside it (same stem); returns the PGM path.

    Occupied (``>= 65``) -> 0, free (``0..25``) -> 254, anything else -> 205 (unknown), with
    ``occupied_thresh: 0.65``, ``free_thresh: 0.196`` as map_saver writes them. Both files are
    written or neither (:func:`~ssm_localization.files.writing.atomic_files`).
    """
    yaml_path = Path(yaml_path)
    pgm = yaml_path.with_suffix('.pgm')
    img = np.full(occ_map.shape, 205, dtype=np.uint8)
    img[occ_map.free_mask()] = 254
    img[occ_map.occupied_mask()] = 0
    x, y, yaw = occ_map.origin
    with atomic_files(pgm, yaml_path, what='map file') as (tmp_pgm, tmp_yaml):
        Image.fromarray(np.flipud(img), mode='L').save(tmp_pgm, format='PPM')
        tmp_yaml.write_text(
            f'image: {pgm.name}\nmode: trinary\nresolution: {occ_map.resolution!r}\n'
            f'origin: [{x!r}, {y!r}, {yaw!r}]\nnegate: 0\noccupied_thresh: 0.65\n'
            f'free_thresh: 0.196\n')
    return pgm


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
