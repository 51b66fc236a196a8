"""
Map files: nav2 map_server YAML + image files (PyYAML and Pillow).

The grid itself, :class:`~.occupancy.OccupancyMap`, and its conversion from
nav_msgs/OccupancyGrid live in ``occupancy.py`` (numpy only) and are re-exported here. Image row
0 is the top of the map, grid row 0 the bottom, so loading and saving flip the rows.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from PIL import Image

from .map_image import read_shade
from .map_limits import check_origin, check_resolution, MAX_MAP_CELLS
from .occupancy import (canonical, fits_float32, FLOAT32_MAX,  # noqa: F401 - re-exported
                        occupancy_map_from_msg, OccupancyMap)
from ..files.reading import echo, input_file
from ..files.writing import atomic_files
from ..files.yaml_input import load_yaml_file

#: how map_server reads the image's pixels (the map YAML's ``mode``)
MAP_IMAGE_MODES = ('trinary', 'scale', 'raw')


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
    except (TypeError, ValueError, OverflowError):     # OverflowError: a 400-digit integer
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
    if not fits_float32(resolution):
        raise ValueError(f"{path}: field 'resolution' must be within float32 range (|v| <= "
                         f'{FLOAT32_MAX:.3g}), as map messages carry it')
    check_origin(origin, str(path))
    negate = _field(doc, 'negate', path, bool, required=False, default=False)
    # required, as nav2's map_server requires them (a default would read a map other than nav2
    # serves, or silently the usual unknown grey 205 as free with 0.25)
    occ_t = _field(doc, 'occupied_thresh', path, float)
    free_t = _field(doc, 'free_thresh', path, float)
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
