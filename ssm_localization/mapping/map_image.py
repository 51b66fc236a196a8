"""
Map images (PGM/PNG and the other formats Pillow reads) -> brightness, with the size guard.

The size is read from the PNM or PNG header before Pillow sees the file, so an image declaring
20000 x 20000 pixels is refused by :func:`~.map_limits.check_map_cells` without being decoded
(Pillow's own decompression-bomb error is also reported as a ``ValueError``). Truncated or
corrupt images raise ``ValueError`` naming the file.
"""
from __future__ import annotations

from pathlib import Path
import re
import struct
import warnings

import numpy as np
from PIL import Image, UnidentifiedImageError

from .map_limits import check_map_cells, MapTooLargeError
from ..files.reading import clip

_PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
#: PNM header: magic, then width and height separated by white space and ``#`` comments
_PNM_HEADER = re.compile(rb'P[1-6](?:\s+|#[^\n]*\n)+(\d+)(?:\s+|#[^\n]*\n)+(\d+)')


def header_size(path: str | Path) -> tuple[int, int] | None:
    """
    Return the ``(width, height)`` a PNG or PNM (PGM, PPM, PBM) header declares.

    Returns None for other formats or an unreadable header (Pillow then reads it).
    """
    with open(path, 'rb') as fh:
        head = fh.read(1024)
    if head.startswith(_PNG_SIGNATURE) and head[12:16] == b'IHDR' and len(head) >= 24:
        return struct.unpack('>II', head[16:24])
    match = _PNM_HEADER.match(head)
    if match:
        return int(match.group(1)), int(match.group(2))
    return None


class UnsupportedImage(ValueError):
    """An image that decodes but whose pixels have no agreed meaning as a map."""


def _decode(path: Path, max_cells: int, where: str) -> np.ndarray:
    """:func:`read_shade` without the translation of Pillow's errors."""
    with Image.open(path) as img:
        check_map_cells(*img.size, max_cells, where)
        img.load()
        mode = img.mode
        if mode.startswith('I;16') or (mode == 'I' and img.format == 'PPM'):
            # 16-bit samples; Pillow scales a PGM of any maxval above 255 to 0..65535
            return np.asarray(img, dtype=np.float64) / 65535.0
        if mode == 'I':
            raise UnsupportedImage(f'{where}: 32-bit integer pixels have no agreed full '
                                   f'scale; save the map as an 8- or 16-bit image (PGM or PNG)')
        if mode == 'F':
            return np.clip(np.asarray(img, dtype=np.float64), 0.0, 1.0)
        if mode not in ('L', 'RGB'):
            img = img.convert('RGBA' if 'A' in mode or mode == 'P' else 'RGB')
        a = np.asarray(img, dtype=np.float64)
    if a.ndim == 3:
        a = a[..., :3].mean(axis=2)
    return a / 255.0


def read_shade(path: str | Path, max_cells: int) -> np.ndarray:
    """
    Brightness in [0, 1] per pixel (mean of the colour channels; alpha ignored), row 0 at the top.

    Images of more than ``max_cells`` pixels (0: no limit) are refused before decoding.
    """
    path = Path(path)
    where = f'map image {path}'
    try:
        declared = header_size(path)
    except OSError as exc:
        raise ValueError(f'{where}: cannot read ({exc.strerror or exc})') from None
    if declared is not None:
        check_map_cells(*declared, max_cells, where)
    try:
        with warnings.catch_warnings():
            # metadata complaints of damaged files (TIFF tags, EXIF): the pixels decode or raise;
            # Pillow's size warning: max_cells rules
            warnings.simplefilter('ignore', UserWarning)
            warnings.simplefilter('ignore', Image.DecompressionBombWarning)
            return _decode(path, max_cells, where)
    except (MapTooLargeError, UnsupportedImage):
        raise
    except UnidentifiedImageError:
        raise ValueError(f'{where}: not a readable image') from None
    except Image.DecompressionBombError as exc:
        raise ValueError(f'{where}: refused by Pillow: {clip(exc)}') from None
    except (OSError, SyntaxError, ValueError, EOFError, IndexError, struct.error) as exc:
        # Pillow's plugins report truncated data and bad headers in all these ways
        raise ValueError(f'{where}: corrupt or truncated image ({clip(exc)})') from None
