"""
What an index file (``.npz``, ``index.save_index``) may hold, checked before and after loading.

An index file is untrusted input: a user's download, a stale file, a tampered one. Its format
version is read first and alone (:func:`stored_version`: another version has another layout,
and saying so is the useful answer). Before any other array is decompressed,
:func:`check_declared` reads the ``.npy`` headers of its members (:func:`declared_arrays`) and
refuses members the layout does not have, shapes that do not fit
together (every per-node array has the same number of nodes K, every virtual scan the same number
of beams B, a node's features at most one per beam), and a total that would not fit the memory
budget of the largest map the package loads (a few kilobytes of zeros deflate from gigabytes).
After loading, :func:`check_values` refuses values no index build writes (NaN and inf where a
pose, a feature or a clearance is stored, node kinds and edges out of range, offsets that do
not split the rows). Each refusal is a ``ValueError`` naming the array.
"""
from __future__ import annotations

import math
from pathlib import Path
import zipfile

import numpy as np

from .topology import NODE_KIND_NAMES
from ..matching.scan import MAX_BEAMS

#: arrays of one value (a version, a string, a resolution) and their greatest item size, bytes
SCALARS = {'format_version': 8, 'config_json': 4 << 20, 'map_checksum': 4 << 10,
           'map_resolution': 8, 'map_frame_id': 4 << 10}
#: the per-scan feature arrays (``ScanFeatures``' fields) and their trailing shapes; -1: any
#: width up to :data:`MAX_WIDTH`
FEATURE_TAILS = {'points': (2,), 'tangents': (2,), 'descriptors': (-1,), 'source_index': (),
                 'fine_points': (2,), 'fine_normals': (2,), 'fine_weights': ()}
FEATURE_PREFIX = 'feat__'
MAX_WIDTH = 4096
#: the declared arrays may total at most this many bytes per map cell, plus :data:`SPARE_BYTES`
#: (the map and its GVD mask take 2 per cell; the campus's 3993 nodes about 60 MB more)
BYTES_PER_CELL = 4
SPARE_BYTES = 1 << 30

Declared = dict[str, tuple[tuple[int, ...], np.dtype]]


def declared_arrays(path: Path) -> Declared:
    """
    ``{name: (shape, dtype)}`` of the arrays of an ``.npz`` file from their ``.npy`` headers.

    Without decompressing their data (a small file may declare gigabytes).
    """
    out = {}
    with zipfile.ZipFile(path) as zf:
        for member in zf.namelist():
            with zf.open(member) as fh:
                version = np.lib.format.read_magic(fh)
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read_header(fh)
            out[member.removesuffix('.npy')] = (tuple(int(n) for n in shape), np.dtype(dtype))
    return out


def _nbytes(shape: tuple[int, ...], dtype: np.dtype) -> int:
    return math.prod(shape) * dtype.itemsize


def check_declared(declared: Declared) -> tuple[int, int]:
    """
    Refuse a layout no index build writes; return ``(K nodes, B beams)``.

    Members, shapes and item sizes from the headers alone (:func:`declared_arrays`); the map's
    cell count is checked against the caller's limit before this.
    """
    def shape(name: str) -> tuple[int, ...]:
        if name not in declared:
            raise KeyError(name)
        return declared[name][0]

    def expect(name: str, want: tuple[int, ...]) -> None:
        if shape(name) != want:
            raise ValueError(f'array {name} has shape {shape(name)}, expected {want}')

    for name, itemsize in SCALARS.items():
        expect(name, ())
        if declared[name][1].itemsize > itemsize:
            raise ValueError(f'array {name} holds items of {declared[name][1].itemsize} bytes '
                             f'(at most {itemsize})')
    h, w = shape('map_data')
    expect('gvd_mask', (h, w))
    expect('map_origin', (3,))
    if len(shape('node_xy')) != 2 or shape('node_xy')[1] != 2:
        raise ValueError(f"array node_xy has shape {shape('node_xy')}, expected (K, 2)")
    if len(shape('beam_angles')) != 1:
        raise ValueError(f"array beam_angles has shape {shape('beam_angles')}, expected (B,)")
    k, b = shape('node_xy')[0], shape('beam_angles')[0]
    if not 0 <= k <= h * w:
        raise ValueError(f'{k} nodes on a map of {h * w} cells')
    if not 0 < b <= MAX_BEAMS:
        raise ValueError(f'{b} beams per virtual scan (1..{MAX_BEAMS})')
    for name, want in (('node_kind', (k,)), ('node_sensor_pose', (k, 3)),
                       ('node_clearance', (k,)), ('ranges', (k, b))):
        expect(name, want)
    edges = shape('edges')
    if len(edges) != 2 or edges[1] != 2 or edges[0] > 16 * k + 16:
        raise ValueError(f'array edges has shape {edges}, expected (E, 2) with E <= 16 K + 16')
    stored = [n for n in declared if n.startswith(FEATURE_PREFIX)]
    wanted = [f'{FEATURE_PREFIX}{n}{end}' for n in FEATURE_TAILS for end in ('', '__offsets')]
    if shape('feature_fields') != (len(FEATURE_TAILS),) or sorted(stored) != sorted(wanted):
        raise ValueError('scan features stored with other fields than this scan matcher uses; '
                         'rebuild the index')
    allowed = {*SCALARS, 'map_data', 'gvd_mask', 'map_origin', 'node_xy', 'beam_angles',
               'node_kind', 'node_sensor_pose', 'node_clearance', 'ranges', 'edges',
               'feature_fields', *wanted}
    for name, tail in FEATURE_TAILS.items():
        key = f'{FEATURE_PREFIX}{name}'
        expect(f'{key}__offsets', (k + 1,))
        got = shape(key)
        width_ok = got == (0,) or (len(got) == 1 + len(tail)       # (0,): an empty index's
                                   and all(t in (g, -1) for g, t in zip(got[1:], tail))
                                   and all(0 < g <= MAX_WIDTH for g in got[1:]))
        if not width_ok or got[0] > k * b:
            raise ValueError(f'array {key} has shape {got}, expected (N, *{tail}) with at most '
                             f'one row per beam of the K x B = {k} x {b} virtual beams')
    unknown = sorted(set(declared) - allowed)
    if unknown:
        raise ValueError(f'unexpected arrays {unknown[:5]} (not an index this package wrote)')
    total = sum(_nbytes(s, d) for s, d in declared.values())
    budget = BYTES_PER_CELL * h * w + SPARE_BYTES
    if total > budget:
        raise ValueError(f'its arrays declare {total / 2 ** 20:.0f} MiB, more than an index of a '
                         f'{h} x {w} map needs ({budget / 2 ** 20:.0f} MiB)')
    return k, b


class WrongVersion(ValueError):
    """An index file of another format version (another layout: rebuild it)."""


def stored_version(path: Path, declared: Declared) -> int:
    """
    Return the file's format version, read alone (a whole number in one value of 8 bytes at most).

    Read before the layout is checked: a file of another version has another layout, and
    saying so is the useful answer.
    """
    if 'format_version' not in declared:
        raise ValueError('not an ssm_localization index (no format_version)')
    shape, dtype = declared['format_version']
    if shape != () or dtype.itemsize > SCALARS['format_version']:
        raise ValueError(f'array format_version has shape {shape} and items of {dtype.itemsize} '
                         f'bytes, expected one value')
    with np.load(path, allow_pickle=False) as z:
        version = z['format_version']
    if version.dtype.kind not in 'iu':
        raise ValueError(f'format_version {version.item()!r} is not a whole number')
    return int(version)


def _finite(data: dict[str, np.ndarray], name: str) -> None:
    a = data[name]
    if a.dtype.kind not in 'iuf' or not np.isfinite(a).all():
        raise ValueError(f'array {name} holds non-numbers, NaN or inf')


def check_values(data: dict[str, np.ndarray], k: int) -> None:
    """Refuse values no index build writes."""
    # (the map's own fields are OccupancyMap's to check, as for a map from YAML or a message)
    for name in ('node_xy', 'node_sensor_pose', 'node_clearance', 'beam_angles',
                 *(f'{FEATURE_PREFIX}{n}' for n in FEATURE_TAILS)):
        _finite(data, name)
    ranges = data['ranges']
    if ranges.dtype.kind != 'f' or np.isnan(ranges).any() or (ranges < 0.0).any():
        raise ValueError('array ranges holds NaN or negative ranges (inf is a beam with no '
                         'return)')
    kinds = data['node_kind']
    if kinds.dtype.kind not in 'iu' or ((kinds < 0) | (kinds >= len(NODE_KIND_NAMES))).any():
        raise ValueError(f'array node_kind holds kinds outside 0..{len(NODE_KIND_NAMES) - 1}')
    edges = data['edges']
    if edges.dtype.kind not in 'iu' or ((edges < 0) | (edges >= k)).any():
        raise ValueError(f'array edges holds node numbers outside 0..{k - 1}')
    for name in FEATURE_TAILS:
        offsets = data[f'{FEATURE_PREFIX}{name}__offsets']
        rows = len(data[f'{FEATURE_PREFIX}{name}'])
        if (offsets.dtype.kind not in 'iu' or offsets[0] != 0 or offsets[-1] != rows
                or (np.diff(offsets) < 0).any()):
            raise ValueError(f'array {FEATURE_PREFIX}{name}__offsets does not split its '
                             f'{rows} rows among the nodes')
