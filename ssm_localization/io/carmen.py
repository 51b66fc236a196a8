"""
CARMEN laser logs (Radish / Freiburg "corrected" logs): parsing, map building, bag conversion.

``FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta timestamp hostname logger_timestamp``.
The ``x y theta`` of a FLASER line is the SLAM-corrected *laser* pose: used as ground truth.
Scanners sweep right to left over 180 degrees: reading ``i`` is at ``-pi/2 + i * pi / n``
(checked empirically: maps built with this convention fit the other scans better than with
``pi / (n - 1)``; see ``endpoint_fit``).
Raw odometry is rebuilt from the ODOM lines: after each FLASER line the log restarts odometry at
the corrected pose, so the increment between scans k and k+1 is ``inverse(reset_k) *
last_odom_k+1``.
"""
from __future__ import annotations

from dataclasses import dataclass
import gzip
from pathlib import Path
from typing import Iterator, Sequence
import zlib

import numpy as np
from scipy.ndimage import distance_transform_edt

from .bag_records import ScanRecord
from .bag_writer import write_bag
from ..config.mapping import MapBuildConfig
from ..files.reading import clip, input_file
from ..files.writing import atomic_dir, check_output_dir, check_output_file
from ..mapping.grid import build_grid_map
from ..mapping.map_io import OccupancyMap, save_map_yaml
from ..mapping.map_limits import MAX_MAP_CELLS
from ..progress import ProgressCallback
from ..transforms import apply, compose, inverse

#: no-return readings of the shared logs (the sensor maximum), by file-name prefix
NO_RETURN = {'intel': 81.83, 'aces': 50.0, 'freiburg-079': 81.91, 'csail': 81.91, 'fhw': 51.0,
             'edmonton': 51.0}
#: longest line read from a log (a FLASER line of 361 readings is about 3 kB)
MAX_LINE_CHARS = 1 << 20
#: most range readings a log may hold (400 MB as float64: 138 000 scans of 361 beams; the shared
#: logs hold 61 000 to 1.7 M): a few MB of gzip can expand to any number of lines
MAX_LOG_READINGS = 50_000_000


@dataclass(frozen=True)
class CarmenLog:
    """The FLASER scans of one log, in file order."""

    ranges: np.ndarray        # (S, n) metres; no-return readings replaced by +inf
    poses: np.ndarray         # (S, 3) corrected laser pose (x, y, theta) in the log's world frame
    stamps: np.ndarray        # (S,) seconds (as logged; may jump backwards)
    angle_min: float
    angle_increment: float
    max_range: float          # the no-return value of this log
    name: str
    odometry: np.ndarray | None = None   # (S, 3) raw odometry rebuilt from the ODOM lines

    def __len__(self) -> int:
        return len(self.ranges)

    def beam_angles(self) -> np.ndarray:
        n = self.ranges.shape[1]
        return self.angle_min + self.angle_increment * np.arange(n)

    def points(self, k: int) -> np.ndarray:
        """Scan ``k`` as (N, 2) points in its laser frame, scan order, no-returns dropped."""
        r = self.ranges[k]
        a = self.beam_angles()
        ok = np.isfinite(r) & (r > 0.0)
        return np.column_stack((r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])))


def _no_return_for(path: Path, ranges: np.ndarray) -> float:
    for prefix, value in NO_RETURN.items():
        if path.name.startswith(prefix):
            return value
    return float(np.max(ranges)) if ranges.size else np.inf


def _log_lines(path: Path) -> Iterator[tuple[int, str]]:
    """
    ``(line number, line)`` of a text or gzipped log.

    ``ValueError`` naming the file for binary garbage, a corrupt gzip stream or a line longer than
    :data:`MAX_LINE_CHARS`.
    """
    opener = gzip.open if path.suffix == '.gz' else open
    try:
        with opener(path, 'rt', encoding='utf-8') as fh:
            for lineno, line in enumerate(iter(lambda: fh.readline(MAX_LINE_CHARS + 1), ''), 1):
                if len(line) > MAX_LINE_CHARS:
                    raise ValueError(f'{path}:{lineno}: line longer than {MAX_LINE_CHARS} '
                                     f'characters; not a CARMEN log?')
                yield lineno, line
    except (OSError, EOFError, zlib.error, UnicodeDecodeError) as exc:
        raise ValueError(f'CARMEN log {path}: cannot read ({clip(exc)})') from None


def read_carmen_log(path: str | Path, max_range: float | None = None) -> CarmenLog:
    """
    Parse the FLASER lines of a (optionally gzipped) CARMEN log.

    Readings ``>= max_range`` (default: the log's known no-return value) become ``+inf``.
    Raises ``ValueError`` naming the file and line for malformed lines.
    """
    path = input_file(path, 'CARMEN log')
    rows, poses, stamps, odometry = [], [], [], []
    n_beams = None
    odo = None            # raw odometry at the last FLASER line
    reset = None          # the ODOM pose the log restarted from after the last FLASER line
    last = None           # the latest ODOM pose
    prev_raw = prev_pose = None   # the latest ODOM pose and the corrected pose at the last scan
    have_odom = True
    for lineno, line in _log_lines(path):
        if line.startswith('ODOM'):
            try:
                last = tuple(float(v) for v in line.split()[1:4])
            except ValueError:
                raise ValueError(f'{path}:{lineno}: malformed ODOM line') from None
            if len(last) != 3:
                raise ValueError(f'{path}:{lineno}: malformed ODOM line')
            if reset is None:
                reset = last
            continue
        if not line.startswith('FLASER'):
            continue
        tok = line.split()
        try:
            n = int(tok[1])
            vals = np.asarray(tok[2:2 + n], dtype=float)
            x, y, th = (float(v) for v in tok[2 + n:5 + n])
            stamp = float(tok[8 + n])
        except (IndexError, ValueError) as exc:
            raise ValueError(f'{path}:{lineno}: malformed FLASER line ({clip(exc)})') from None
        if n < 1 or len(vals) != n or (n_beams is not None and n != n_beams):
            raise ValueError(f'{path}:{lineno}: expected {n_beams or n} readings, got {len(vals)}')
        n_beams = n
        if (len(rows) + 1) * n > MAX_LOG_READINGS:
            raise ValueError(f'{path}:{lineno}: more than {MAX_LOG_READINGS} range readings: a '
                             f'log this long is refused (split it)')
        if odo is None:
            odo = last if last is not None else (0.0, 0.0, 0.0)
        elif last is not None:
            # increments count from the reset line (the corrected pose) when the log has
            # one, else from the raw odometry at the previous scan
            restarted = reset is not None and np.allclose(reset, prev_pose, atol=1e-6)
            base = reset if restarted or prev_raw is None else prev_raw
            odo = compose(odo, compose(inverse(base), last))
        else:
            have_odom = False
        odometry.append(odo)
        prev_raw, prev_pose = last, (x, y, th)
        reset = None
        rows.append(vals)
        poses.append((x, y, th))
        stamps.append(stamp)
    if not rows:
        raise ValueError(f'{path}: no FLASER lines')
    ranges = np.vstack(rows)
    limit = _no_return_for(path, ranges) if max_range is None else float(max_range)
    ranges = np.where(ranges >= limit - 1e-6, np.inf, ranges)
    n = ranges.shape[1]
    return CarmenLog(ranges=ranges, poses=np.asarray(poses), stamps=np.asarray(stamps),
                     angle_min=-np.pi / 2.0, angle_increment=np.pi / n, max_range=limit,
                     name=path.name.split('-corrected')[0].split('.')[0],
                     odometry=np.asarray(odometry, dtype=float) if have_odom else None)


# ---------------------------------------------------------------- map building

def select_scans(count: int, which: str = 'all', every: int = 1, first: int | None = None,
                 last: int | None = None, max_scans: int | None = None) -> np.ndarray:
    """Scan indices: ``which`` in even/odd/all within ``[first, last)``, every ``every``-th."""
    if which not in ('even', 'odd', 'all'):
        raise ValueError(f'scan selection must be even, odd or all, got {which!r}')
    if every < 1:
        raise ValueError(f'every must be >= 1, got {every}')
    idx = np.arange(count)[slice(first, last)]
    if which != 'all':
        idx = idx[idx % 2 == (0 if which == 'even' else 1)]
    idx = idx[::every]
    return idx[:max_scans] if max_scans is not None else idx


def build_map(log: CarmenLog, indices: Sequence[int] | None = None,
              config: MapBuildConfig | None = None, beam_angles: np.ndarray | None = None,
              progress: ProgressCallback | None = None,
              max_cells: int = MAX_MAP_CELLS) -> OccupancyMap:
    """
    Build the occupancy map of ``log`` from the scans ``indices`` (default: the even ones).

    A grid of more than ``max_cells`` cells (0: no limit) is refused before it is
    allocated.
    """
    idx = select_scans(len(log), 'even') if indices is None else np.asarray(indices, dtype=int)
    if idx.size == 0:
        raise ValueError(f'{log.name}: no scans selected for the map')
    angles = log.beam_angles() if beam_angles is None else np.asarray(beam_angles, dtype=float)
    return build_grid_map(log.ranges[idx], log.poses[idx], angles, config, progress, max_cells)


def endpoint_fit(occ_map: OccupancyMap, log: CarmenLog, indices: Sequence[int],
                 beam_angles: np.ndarray | None = None, max_range: float = 20.0) -> np.ndarray:
    """
    Return the distance (m) from each endpoint of the scans ``indices`` to the map.

    Finite endpoints (range < max_range) placed at their corrected poses, to the nearest occupied
    cell centre of ``occ_map``.
    """
    occ = np.asarray(occ_map.data) >= 65
    if not occ.any():
        raise ValueError('map has no occupied cells')
    dist = distance_transform_edt(~occ) * occ_map.resolution
    angles = log.beam_angles() if beam_angles is None else np.asarray(beam_angles, dtype=float)
    out = []
    ox, oy, oyaw = occ_map.origin
    for k in np.asarray(indices, dtype=int):
        r = log.ranges[k]
        ok = np.isfinite(r) & (r < max_range)
        pts = np.column_stack((r[ok] * np.cos(angles[ok]), r[ok] * np.sin(angles[ok])))
        local = apply(inverse((ox, oy, oyaw)), apply(log.poses[k], pts))
        col = np.floor(local[:, 0] / occ_map.resolution).astype(int)
        row = np.floor(local[:, 1] / occ_map.resolution).astype(int)
        inside = (row >= 0) & (row < occ.shape[0]) & (col >= 0) & (col < occ.shape[1])
        d = np.full(len(pts), np.inf)
        d[inside] = dist[row[inside], col[inside]]
        out.append(d)
    return np.concatenate(out) if out else np.zeros(0)


# ---------------------------------------------------------------- conversion to map + bag

def monotonic_stamps(stamps: np.ndarray, min_step: float = 1e-3) -> np.ndarray:
    """
    ``stamps`` made strictly increasing.

    A stamp that does not exceed its predecessor becomes the predecessor plus ``min_step`` (Intel's
    clock jumps backwards 4 times).
    """
    out = np.asarray(stamps, dtype=float).copy()
    for k in range(1, len(out)):
        if out[k] <= out[k - 1]:
            out[k] = out[k - 1] + min_step
    return out


def log_scan_records(log: CarmenLog, indices: Sequence[int]) -> list[ScanRecord]:
    """
    Return the scans ``indices`` as ``ScanRecord`` s.

    Frame ``laser``, float32 ranges, ``+inf`` for no return, ``range_max`` = the no-return value.
    """
    stamps = monotonic_stamps(log.stamps)
    return [ScanRecord.from_ranges(stamps[k], log.ranges[k].astype(np.float32), log.angle_min,
                                   log.angle_increment, range_min=0.0,
                                   range_max=float(log.max_range), frame_id='laser')
            for k in np.asarray(indices, dtype=int)]


def write_log_bag(log: CarmenLog, indices: Sequence[int], path: str | Path,
                  occ_map: OccupancyMap | None = None, with_odom: bool = True,
                  overwrite: bool = False, progress: ProgressCallback | None = None) -> Path:
    """
    Write a bag with /map, /scan, /ground_truth and /odom.

    /map is ``occ_map``, /scan the scans ``indices``, /ground_truth their corrected poses (the
    log's world frame is the map frame and the base is the laser), /odom the raw odometry rebuilt
    from the ODOM lines, when the log has it.
    """
    scans = log_scan_records(log, indices)
    idx = np.asarray(indices, dtype=int)
    gt = {s.stamp: tuple(float(v) for v in log.poses[k]) for s, k in zip(scans, idx)}
    odom = None
    if with_odom and log.odometry is not None:
        odom = {s.stamp: tuple(float(v) for v in log.odometry[k]) for s, k in zip(scans, idx)}
    return write_bag(path, map=occ_map, scans=scans, ground_truth=gt, odom=odom,
                     overwrite=overwrite, progress=progress)


@dataclass(frozen=True)
class ConversionResult:
    """What :func:`convert_carmen` wrote."""

    map_yaml: Path
    bag: Path | None
    map_scans: int
    query_scans: int
    map_shape: tuple[int, int]


def convert_carmen(log_path: str | Path, out_dir: str | Path, name: str | None = None,
                   map_scans: str = 'even', query_scans: str = 'odd', every: int = 1,
                   max_scans: int | None = None, first: int | None = None,
                   last: int | None = None, config: MapBuildConfig | None = None,
                   with_odom: bool = True, write_queries: bool = True, overwrite: bool = False,
                   bag_path: str | Path | None = None,
                   progress: ProgressCallback | None = None,
                   max_map_cells: int = MAX_MAP_CELLS) -> ConversionResult:
    """
    Convert a CARMEN log to a map and a query bag.

    ``OUT/NAME.yaml`` + ``.pgm`` is the map of the ``map_scans`` scans, the bag
    ``OUT/NAME_queries/`` holds the ``query_scans`` scans (every ``every``-th, at most
    ``max_scans``). ``first``/``last`` restrict both to the scan index
    range ``[first, last)``; ``bag_path`` overrides the bag's location. Every output path is
    checked before the map is built; a map of more than ``max_map_cells`` cells (0: no limit) is
    refused. The map is written before the bag is moved into place: when either fails, an existing
    bag is left as it was.
    """
    out_dir = check_output_dir(out_dir, 'output directory')
    log = read_carmen_log(log_path)
    name = name or log.name
    bag_path = Path(bag_path) if bag_path is not None else out_dir / f'{name}_queries'
    map_yaml = check_output_file(out_dir / f'{name}.yaml', 'map file')
    check_output_file(map_yaml.with_suffix('.pgm'), 'map file')
    if write_queries:
        check_output_dir(bag_path, 'bag', overwrite)
    m_idx = select_scans(len(log), map_scans, 1, first, last)
    q_idx = select_scans(len(log), query_scans, every, first, last, max_scans)
    if m_idx.size == 0:
        raise ValueError(f'{log_path}: no scans selected for the map')
    if write_queries and q_idx.size == 0:
        raise ValueError(f'{log_path}: no query scans selected')
    occ_map = build_map(log, m_idx, config, progress=progress, max_cells=max_map_cells)
    bag = None
    if write_queries:     # the map is written inside the bag's stage: either fails, no bag moves
        with atomic_dir(bag_path, 'bag', overwrite) as stage:
            write_log_bag(log, q_idx, stage, occ_map, with_odom, progress=progress)
            save_map_yaml(occ_map, map_yaml)
        bag = bag_path
    else:
        save_map_yaml(occ_map, map_yaml)
    return ConversionResult(map_yaml=map_yaml, bag=bag, map_scans=int(m_idx.size),
                            query_scans=int(q_idx.size) if write_queries else 0,
                            map_shape=occ_map.shape)
