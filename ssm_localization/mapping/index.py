"""
Topological index of a grid map (paper section III): GVD nodes with virtual 360-degree scans.

``build_index`` extracts the nodes (``topology.py``), casts a virtual scan at every node
(``raycast.py``, Table 1: the virtual laser's pose is the node pose ``(x, y, 0)`` composed with
the sensor pose on the robot) and precomputes the matcher's per-scan features
(``matching.features.prepare_scan``). ``save_index`` / ``load_index`` store it as a versioned
``.npz`` without pickles: arrays, the map checksum and every parameter as a JSON string.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
import zipfile
import zlib

import numpy as np

from .index_file import (check_declared, check_values, declared_arrays, FEATURE_PREFIX as _FEAT,
                         stored_version, WrongVersion)
from .map_limits import check_map_cells, MapTooLargeError, MAX_MAP_CELLS
from .occupancy import OccupancyMap
from .raycast import beam_angles as _beam_angles
from .raycast import RayCaster
from .topology import build_topology, count_kinds
from ..config.convert import config_from_json, config_to_json
from ..config.mapping import IndexConfig
from ..files.reading import clip, input_file
from ..files.writing import atomic_files
from ..matching.features import prepare_scan, ScanFeatures
from ..progress import LayerHook, no_layers, ProgressCallback
from ..transforms import compose

#: Version of the ``.npz`` layout written by :func:`save_index`; other versions are refused.
FORMAT_VERSION = 1

__all__ = ['FORMAT_VERSION', 'MapIndex', 'build_index', 'save_index', 'load_index']


def _empty(shape, dtype) -> np.ndarray:
    return np.zeros(shape, dtype=dtype)


@dataclass(frozen=True, eq=False)
class MapIndex:
    """
    A built index.

    Per node k: ``node_xy[k]`` (map frame), ``node_kind[k]`` (:class:`NodeKind`),
    ``node_sensor_pose[k]`` the virtual laser's pose (map frame), ``ranges[k]`` its virtual scan
    over ``beam_angles`` (inf: no return), ``features[k]`` the matcher features of that scan
    (points in the laser frame). ``gvd_mask`` (H, W) bool, ``edges`` (E, 2) node pairs adjacent
    along the GVD, ``node_clearance`` (K,) brushfire distance (m) at the nodes. (The localizer
    derives its wall model from ``map`` at start-up.)
    """

    map: OccupancyMap  # noqa: A003 - public field name
    node_xy: np.ndarray
    node_kind: np.ndarray
    node_sensor_pose: np.ndarray
    ranges: np.ndarray
    beam_angles: np.ndarray
    features: list[ScanFeatures]
    gvd_mask: np.ndarray
    config: IndexConfig
    map_checksum: str
    version: int = FORMAT_VERSION
    edges: np.ndarray = field(default_factory=lambda: _empty((0, 2), np.int64))
    node_clearance: np.ndarray = field(default_factory=lambda: _empty((0,), np.float64))

    def __len__(self) -> int:
        return len(self.node_xy)

    def kind_counts(self) -> dict[str, int]:
        return count_kinds(self.node_kind)

    def ray_caster(self) -> RayCaster:
        """
        Return the ray caster of ``map`` (its cells occupied from ``config.occupied_thresh``).

        The one :func:`build_index` cast the virtual scans with, when this index was built in
        this process (the localizer's beam check casts on the same cells, so it is built once:
        2 s of a 30 M-cell map's start-up); otherwise built on first use and kept. Not stored in
        the file, not copied by ``dataclasses.replace`` (another map may come with the copy).
        """
        caster = self.__dict__.get('_caster')
        if caster is None:
            caster = _ray_caster(self.map, self.config)
            object.__setattr__(self, '_caster', caster)
        return caster


def _ray_caster(occ_map: OccupancyMap, cfg: IndexConfig) -> RayCaster:
    return RayCaster(occ_map.occupied_mask(cfg.occupied_thresh), occ_map.resolution,
                     occ_map.origin)


#: names of the layers :func:`build_index` builds, in order
INDEX_LAYERS = ('topology', 'virtual scans', 'features')


def build_index(occ_map: OccupancyMap, config: IndexConfig | None = None,
                progress: ProgressCallback | None = None,
                layer: LayerHook = no_layers, keep_caster: bool = True) -> MapIndex:
    """
    Nodes, virtual scans and their matcher features for ``occ_map`` (paper section III).

    ``layer`` is told when each of :data:`INDEX_LAYERS` is built (``bench index`` measures
    their memory); the intermediates of each are released before the next starts.
    ``keep_caster``: keep the ray caster of the virtual scans for a localizer built on the index
    in this process (:meth:`MapIndex.ray_caster`; 2 bytes a cell), or drop it (an index that is
    only saved or published).
    """
    cfg = config or IndexConfig()
    if not isinstance(occ_map, OccupancyMap):
        raise ValueError(f'build_index: expected an OccupancyMap, got {type(occ_map).__name__}')
    user = progress or (lambda done, total, label: None)

    def report(done: int, total: int, label: str, lo: int = 0, hi: int = 100) -> None:
        # one 0..100 scale over the stages: topology 0-30, scans 30-60, features 60-100
        user(lo + (hi - lo) * done // max(total, 1), 100, label)

    with layer(INDEX_LAYERS[0]):
        topo = build_topology(occ_map, cfg.topology,
                              lambda d, t, label: report(d, t, f'topology ({label})', 0, 30))
        # what the index keeps of it (not the clearance of every cell)
        node_xy, node_kind, gvd_mask = topo.node_xy, topo.node_kind, topo.gvd_mask
        edges, node_clearance = topo.edges, topo.node_clearance
        del topo
    k = len(node_xy)
    with layer(INDEX_LAYERS[1]):
        poses = np.array([compose((float(x), float(y), 0.0), cfg.sensor_pose)
                          for x, y in node_xy], dtype=float).reshape(-1, 3)
        angles = _beam_angles(cfg.beams)
        caster = _ray_caster(occ_map, cfg)
        ranges = np.full((k, len(angles)), np.inf)
        chunk = 128
        for s in range(0, k, chunk):
            report(s, k, 'virtual scans', 30, 60)
            ranges[s:s + chunk] = caster.cast(poses[s:s + chunk], angles, cfg.max_range)
    with layer(INDEX_LAYERS[2]):
        cos, sin = np.cos(angles), np.sin(angles)
        features = []
        for i in range(k):
            if i % 16 == 0:
                report(i, k, 'features', 60, 100)
            ok = np.isfinite(ranges[i])
            pts = np.column_stack((ranges[i, ok] * cos[ok], ranges[i, ok] * sin[ok]))
            # no ICP set: the nodes' features are voted with (``voting.py``) and, in the
            # paper's pipeline, matched without ICP; it was a third of this stage's time
            features.append(prepare_scan(pts, cfg.matcher, fine=False))
    report(k, k, 'done')
    index = MapIndex(map=occ_map, node_xy=node_xy, node_kind=node_kind,
                     node_sensor_pose=poses, ranges=ranges, beam_angles=angles,
                     features=features, gvd_mask=gvd_mask, config=cfg,
                     map_checksum=occ_map.checksum(), version=FORMAT_VERSION,
                     edges=edges, node_clearance=node_clearance)
    if keep_caster:
        object.__setattr__(index, '_caster', caster)    # the localizer's beam check casts with it
    return index


# --------------------------------------------------------------------------- npz storage


def save_index(index: MapIndex, path: str | Path) -> Path:
    """Write ``index`` to ``path`` (compressed npz, no pickled objects); returns the path."""
    path = Path(path)
    arrays: dict[str, np.ndarray] = {
        'format_version': np.asarray(FORMAT_VERSION, dtype=np.int64),
        'config_json': np.asarray(config_to_json(index.config)),
        'map_checksum': np.asarray(index.map_checksum),
        'map_data': index.map.data,
        'map_resolution': np.asarray(index.map.resolution, dtype=np.float64),
        'map_origin': np.asarray(index.map.origin, dtype=np.float64),
        'map_frame_id': np.asarray(index.map.frame_id),
        'node_xy': np.asarray(index.node_xy, dtype=np.float64).reshape(-1, 2),
        'node_kind': np.asarray(index.node_kind, dtype=np.int8),
        'node_sensor_pose': np.asarray(index.node_sensor_pose, dtype=np.float64).reshape(-1, 3),
        'node_clearance': np.asarray(index.node_clearance, dtype=np.float64),
        'edges': np.asarray(index.edges, dtype=np.int64).reshape(-1, 2),
        'ranges': np.asarray(index.ranges, dtype=np.float64),
        'beam_angles': np.asarray(index.beam_angles, dtype=np.float64),
        'gvd_mask': np.asarray(index.gvd_mask, dtype=bool),
    }
    per_node = [f.to_arrays() for f in index.features]
    names = [f.name for f in dataclasses.fields(ScanFeatures)]
    arrays['feature_fields'] = np.asarray(names)
    for name in names:
        parts = [np.asarray(d[name]) for d in per_node]
        lengths = [len(p) if p.ndim else 1 for p in parts]
        arrays[f'{_FEAT}{name}__offsets'] = np.concatenate(([0], np.cumsum(lengths))).astype(
            np.int64)
        if parts:
            arrays[f'{_FEAT}{name}'] = np.concatenate([np.atleast_1d(p) for p in parts])
        else:
            arrays[f'{_FEAT}{name}'] = np.zeros((0,))
    for key, a in arrays.items():
        if a.dtype == object:
            raise ValueError(f'save_index: {key} would need pickling')
    with atomic_files(path, what='index file') as (tmp,):
        with open(tmp, 'wb') as fh:
            np.savez_compressed(fh, **arrays)
    return path


def load_index(path: str | Path, expected_map: OccupancyMap | None = None,
               max_cells: int = MAX_MAP_CELLS) -> MapIndex:
    """
    Read an index written by :func:`save_index` (never unpickles).

    Raises ``ValueError`` for a file of another format version, a corrupt file, a map of more
    than ``max_cells`` cells (0: no limit; checked from the array headers before anything is
    decompressed), or (with ``expected_map``) an index built for another map;
    ``FileNotFoundError`` if it is missing.
    """
    path = input_file(path, 'index file')
    try:
        declared = declared_arrays(path)
        for name in ('map_data', 'gvd_mask'):
            shape = declared.get(name, ((0, 0), None))[0]
            if len(shape) != 2:
                raise ValueError(f'{name} has shape {shape}, expected (H, W)')
            check_map_cells(shape[1], shape[0], max_cells, f'{path}: {name}')
        version = stored_version(path, declared)     # another version: another layout
        if version != FORMAT_VERSION:
            raise WrongVersion(f'{path}: index format version {version}, this ssm_localization '
                               f'reads version {FORMAT_VERSION}; rebuild it with '
                               f'`ssm_localization index`')
        k, beams = check_declared(declared)
        with np.load(path, allow_pickle=False) as z:
            data = {key: z[key] for key in z.files}
        check_values(data, k)
    except KeyError as exc:
        raise ValueError(f'{path}: index file lacks array {exc}') from None
    except (ValueError, OSError, zipfile.BadZipFile, EOFError, zlib.error) as exc:
        if isinstance(exc, (MapTooLargeError, WrongVersion)):
            raise
        raise ValueError(f'{path}: not a readable index file ({clip(exc)})') from None
    try:
        occ_map = OccupancyMap(data['map_data'], float(data['map_resolution']),
                               tuple(data['map_origin'].tolist()), str(data['map_frame_id']))
        checksum = str(data['map_checksum'])
        if occ_map.checksum() != checksum:
            raise ValueError('stored map does not match its checksum (corrupt file)')
        if expected_map is not None and expected_map.checksum() != checksum:
            raise ValueError(f'index was built for another map (checksum {checksum[:12]}..., '
                             f'expected {expected_map.checksum()[:12]}...); rebuild it for '
                             f'this map')
        try:
            config = config_from_json(IndexConfig, str(data['config_json']))
        except (ValueError, TypeError, AttributeError, RecursionError) as exc:
            raise ValueError(f'stored parameters do not fit this ssm_localization '
                             f'({clip(exc)}); rebuild the index') from None
        if config.beams != beams:
            raise ValueError(f'stored parameters say {config.beams} beams, the virtual scans '
                             f'have {beams} (corrupt file)')
        names = [str(n) for n in data['feature_fields']]
        if set(names) != {f.name for f in dataclasses.fields(ScanFeatures)}:
            raise ValueError(f'scan features stored with fields {names} do not match this '
                             f'scan matcher; rebuild the index')
        features = []
        offs = {n: data[f'{_FEAT}{n}__offsets'] for n in names}
        for i in range(k):
            arrs = {n: data[f'{_FEAT}{n}'][offs[n][i]:offs[n][i + 1]] for n in names}
            features.append(ScanFeatures.from_arrays(arrs))
        width = config.matcher.desc_radial_bins * config.matcher.desc_angular_bins
        if k and data[f'{_FEAT}descriptors'].shape[1] != width:
            raise ValueError(f'descriptors {data[f"{_FEAT}descriptors"].shape[1]} wide, the '
                             f'stored matcher parameters make {width} (corrupt file)')
        index = MapIndex(
            map=occ_map, node_xy=data['node_xy'], node_kind=data['node_kind'],
            node_sensor_pose=data['node_sensor_pose'], ranges=data['ranges'],
            beam_angles=data['beam_angles'], features=features, gvd_mask=data['gvd_mask'],
            config=config, map_checksum=checksum,
            version=version, edges=data['edges'], node_clearance=data['node_clearance'])
    except (ValueError, TypeError, IndexError, OverflowError) as exc:
        raise ValueError(f'{path}: {clip(exc)}') from None
    return index            # every shape was checked from the headers (check_declared)
