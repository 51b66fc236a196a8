"""CARMEN laser logs (Radish / Freiburg "corrected" logs): parsing, map building, bag conversion.

``FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta timestamp hostname logger_timestamp``.
The ``x y theta`` of a FLASER line is the SLAM-corrected *laser* pose: used as ground truth.
Scanners sweep right to left over 180 degrees: reading ``i`` is at ``-pi/2 + i * pi / n``
(checked empirically: maps built with this convention fit the other scans better than with
``pi / (n - 1)``; see ``endpoint_fit``).
Raw odometry is rebuilt from the ODOM lines: after each FLASER line the log restarts odometry at the
corrected pose, so the increment between scans k and k+1 is ``inverse(reset_k) * last_odom_k+1``.
"""
from __future__ import annotations

import gzip
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from ..progress import ProgressCallback
from ..transforms import compose, inverse

if TYPE_CHECKING:
    from ..mapping.map_io import OccupancyMap

#: no-return readings of the shared logs (the sensor maximum), by file-name prefix
NO_RETURN = {'intel': 81.83, 'aces': 50.0, 'freiburg-079': 81.91}


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


def read_carmen_log(path: str | Path, max_range: float | None = None) -> CarmenLog:
    """Parse the FLASER lines of a (optionally gzipped) CARMEN log.

    Readings ``>= max_range`` (default: the log's known no-return value) become ``+inf``.
    Raises ``ValueError`` naming the file and line for malformed lines.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f'CARMEN log not found: {path}')
    opener = gzip.open if path.suffix == '.gz' else open
    rows, poses, stamps, odometry = [], [], [], []
    n_beams = None
    odo = None            # raw odometry at the last FLASER line
    reset = None          # the ODOM pose the log restarted from after the last FLASER line
    last = None           # the latest ODOM pose
    prev_raw = prev_pose = None   # the latest ODOM pose and the corrected pose at the last scan
    have_odom = True
    with opener(path, 'rt') as fh:
        for lineno, line in enumerate(fh, 1):
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
                raise ValueError(f'{path}:{lineno}: malformed FLASER line ({exc})') from None
            if len(vals) != n or (n_beams is not None and n != n_beams):
                raise ValueError(f'{path}:{lineno}: expected {n_beams or n} readings, got {len(vals)}')
            n_beams = n
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

@dataclass(frozen=True)
class MapBuildConfig:
    """Occupancy-grid building from scans at known poses (hit / miss counting)."""

    resolution: float = 0.05
    margin: float = 1.0            # metres of unknown border around the observed area
    max_range: float = 40.0        # finite readings beyond this only clear space up to it
    free_cap: float = 5.0          # no-return beams clear space up to this distance
    occupied_ratio: float = 0.3    # occupied if hits >= ratio * (hits + misses)
    min_hits: int = 1
    chunk_beams: int = 20000       # beams traversed per vectorized batch


def _beam_segments(ranges, poses, beam_angles, cfg: MapBuildConfig):
    """Flattened beams: start xy, unit direction, free length, has-hit flag."""
    r = np.asarray(ranges, dtype=float)
    hit = np.isfinite(r) & (r > 0.0) & (r <= cfg.max_range)
    length = np.where(hit, r, np.where(np.isfinite(r) & (r > cfg.max_range), cfg.max_range,
                                       min(cfg.free_cap, cfg.max_range)))
    ang = poses[:, 2:3] + np.asarray(beam_angles)[None, :]
    start = np.repeat(poses[:, :2], r.shape[1], axis=0)
    direction = np.column_stack((np.cos(ang).ravel(), np.sin(ang).ravel()))
    return start, direction, length.ravel(), hit.ravel()


def build_occupancy_grid(ranges: np.ndarray, poses: np.ndarray, beam_angles: np.ndarray,
                         config: MapBuildConfig | None = None,
                         progress: ProgressCallback | None = None
                         ) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Trinary occupancy grid (int8: 100 occupied, 0 free, -1 unknown) and its origin.

    ``ranges`` (S, n) with ``inf`` for no return, ``poses`` (S, 3) laser poses in the world
    frame, ``beam_angles`` (n,). Cells along each beam (sampled every half cell) count a miss,
    the end cell of a finite reading a hit. Rows grow with y, columns with x (OccupancyGrid).
    """
    cfg = config or MapBuildConfig()
    ranges = np.atleast_2d(np.asarray(ranges, dtype=float))
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    if ranges.size == 0 or len(ranges) != len(poses):
        raise ValueError(f'need scans and one pose per scan, got {ranges.shape} / {poses.shape}')
    if not np.all(np.isfinite(poses)):
        raise ValueError('scan poses must be finite')
    res = float(cfg.resolution)
    start, direction, length, hit = _beam_segments(ranges, poses, beam_angles, cfg)
    end = start + direction * length[:, None]
    lo = np.minimum(end.min(0), poses[:, :2].min(0)) - cfg.margin
    hi = np.maximum(end.max(0), poses[:, :2].max(0)) + cfg.margin
    origin = (round(float(np.floor(lo[0] / res) * res), 9),
              round(float(np.floor(lo[1] / res) * res), 9), 0.0)
    width = int(np.ceil((hi[0] - origin[0]) / res))
    height = int(np.ceil((hi[1] - origin[1]) / res))
    org = np.array(origin[:2])
    hits = np.zeros(height * width, dtype=np.int64)
    misses = np.zeros(height * width, dtype=np.int64)

    def cell_index(xy):
        cr = np.floor((xy - org) / res).astype(np.int64)
        return np.clip(cr[:, 1], 0, height - 1) * width + np.clip(cr[:, 0], 0, width - 1)

    hits += np.bincount(cell_index(end[hit]), minlength=height * width)
    step = 0.5 * res
    free_len = np.where(hit, length - step, length)
    n_samples = np.maximum(np.ceil(free_len / step).astype(np.int64), 0)
    total = len(length)
    # Pass 1: beams with a return. Pass 2: beams without one clear space up to the cap, but
    # stop at the first cell pass 1 found occupied (no clearing behind walls).
    order = np.concatenate((np.flatnonzero(hit), np.flatnonzero(~hit)))
    n_hit = int(hit.sum())
    occupied = None
    done = 0
    for first_pass, ids in ((True, order[:n_hit]), (False, order[n_hit:])):
        if not first_pass:
            occupied = (hits >= cfg.min_hits) & (hits >= cfg.occupied_ratio * (hits + misses))
        for a in range(0, len(ids), cfg.chunk_beams):
            chunk = ids[a:a + cfg.chunk_beams]
            counts = n_samples[chunk]
            beam = np.repeat(chunk, counts)
            done += len(chunk)
            if beam.size:
                offsets = np.cumsum(counts) - counts
                k = np.arange(beam.size) - np.repeat(offsets, counts)
                cells = cell_index(start[beam] + direction[beam] * (k * step)[:, None])
                keep = np.ones(cells.size, dtype=bool)   # one miss per beam and cell
                keep[1:] = (cells[1:] != cells[:-1]) | (beam[1:] != beam[:-1])
                if not first_pass:
                    blocked = occupied[cells]
                    stop = np.full(total, np.iinfo(np.int64).max)
                    np.minimum.at(stop, beam[blocked], k[blocked])
                    keep &= k < stop[beam]
                misses += np.bincount(cells[keep], minlength=height * width)
            if progress is not None:
                progress(done, total, 'building map')
    occupied = (hits >= cfg.min_hits) & (hits >= cfg.occupied_ratio * (hits + misses))
    data = np.full(height * width, -1, dtype=np.int8)
    data[misses > 0] = 0
    data[occupied] = 100
    return _crop_known(data.reshape(height, width), origin, res, cfg.margin)


def _crop_known(data: np.ndarray, origin, res: float, margin: float):
    """Crop the grid to its observed cells plus ``margin`` metres of unknown."""
    known = data != -1
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    if rows.size == 0:
        return data, origin
    m = int(round(margin / res))
    r0, r1 = max(rows[0] - m, 0), min(rows[-1] + m + 1, data.shape[0])
    c0, c1 = max(cols[0] - m, 0), min(cols[-1] + m + 1, data.shape[1])
    return (np.ascontiguousarray(data[r0:r1, c0:c1]),
            (round(origin[0] + c0 * res, 9), round(origin[1] + r0 * res, 9), origin[2]))


def select_scans(count: int, which: str = 'all', every: int = 1, first: int | None = None,
                 last: int | None = None, max_scans: int | None = None) -> np.ndarray:
    """Scan indices: ``which`` in even/odd/all within ``[first, last)``, every ``every``-th."""
    if which not in ('even', 'odd', 'all'):
        raise ValueError(f"scan selection must be even, odd or all, got {which!r}")
    if every < 1:
        raise ValueError(f'every must be >= 1, got {every}')
    idx = np.arange(count)[slice(first, last)]
    if which != 'all':
        idx = idx[idx % 2 == (0 if which == 'even' else 1)]
    idx = idx[::every]
    return idx[:max_scans] if max_scans is not None else idx


def build_map(log: CarmenLog, indices: Sequence[int] | None = None,
              config: MapBuildConfig | None = None, beam_angles: np.ndarray | None = None,
              progress: ProgressCallback | None = None) -> 'OccupancyMap':
    """Occupancy map of ``log`` from the scans ``indices`` (default: the even ones)."""
    from ..mapping.map_io import OccupancyMap
    idx = select_scans(len(log), 'even') if indices is None else np.asarray(indices, dtype=int)
    if idx.size == 0:
        raise ValueError(f'{log.name}: no scans selected for the map')
    angles = log.beam_angles() if beam_angles is None else np.asarray(beam_angles, dtype=float)
    data, origin = build_occupancy_grid(log.ranges[idx], log.poses[idx], angles, config, progress)
    cfg = config or MapBuildConfig()
    return OccupancyMap(data=data, resolution=float(cfg.resolution), origin=origin)


def endpoint_fit(occ_map: 'OccupancyMap', log: CarmenLog, indices: Sequence[int],
                 beam_angles: np.ndarray | None = None, max_range: float = 20.0) -> np.ndarray:
    """Distance (m) from each finite endpoint (range < max_range) of the scans ``indices``, placed
    at their corrected poses, to the nearest occupied cell centre of ``occ_map``."""
    from scipy.ndimage import distance_transform_edt

    from ..transforms import apply
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
    """``stamps`` made strictly increasing: a stamp that does not exceed its predecessor becomes
    the predecessor plus ``min_step`` (Intel's clock jumps backwards 4 times)."""
    out = np.asarray(stamps, dtype=float).copy()
    for k in range(1, len(out)):
        if out[k] <= out[k - 1]:
            out[k] = out[k - 1] + min_step
    return out


def log_scan_records(log: CarmenLog, indices: Sequence[int]) -> list:
    """:class:`~ssm_localization.bags.ScanRecord` s of the scans ``indices`` (frame ``laser``,
    float32 ranges, ``+inf`` for no return, ``range_max`` = the no-return value)."""
    from .bags import ScanRecord
    stamps = monotonic_stamps(log.stamps)
    return [ScanRecord.from_ranges(stamps[k], log.ranges[k].astype(np.float32), log.angle_min,
                                   log.angle_increment, range_min=0.0,
                                   range_max=float(log.max_range), frame_id='laser')
            for k in np.asarray(indices, dtype=int)]


def write_log_bag(log: CarmenLog, indices: Sequence[int], path: str | Path,
                  occ_map: 'OccupancyMap | None' = None, with_odom: bool = True,
                  overwrite: bool = False, progress: ProgressCallback | None = None) -> Path:
    """A bag with /map (``occ_map``), /scan (the scans ``indices``), /ground_truth (their
    corrected poses: the log's world frame is the map frame and the base is the laser) and
    /odom (raw odometry rebuilt from the ODOM lines, when the log has it)."""
    from .bags import write_bag
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
                   progress: ProgressCallback | None = None) -> ConversionResult:
    """CARMEN log -> ``OUT/NAME.yaml`` + ``.pgm`` (map of the ``map_scans`` scans) and the bag
    ``OUT/NAME_queries/`` (the ``query_scans`` scans, every ``every``-th, at most ``max_scans``).
    ``first``/``last`` restrict both to the scan index range ``[first, last)``; ``bag_path``
    overrides the bag's location."""
    from ..mapping.map_io import save_map_yaml
    log = read_carmen_log(log_path)
    name = name or log.name
    out_dir = Path(out_dir)
    bag_path = Path(bag_path) if bag_path is not None else out_dir / f'{name}_queries'
    if write_queries and bag_path.exists() and not overwrite:
        raise FileExistsError(f'bag exists already (use --force): {bag_path}')
    m_idx = select_scans(len(log), map_scans, 1, first, last)
    q_idx = select_scans(len(log), query_scans, every, first, last, max_scans)
    if m_idx.size == 0:
        raise ValueError(f'{log_path}: no scans selected for the map')
    occ_map = build_map(log, m_idx, config, progress=progress)
    map_yaml = out_dir / f'{name}.yaml'
    save_map_yaml(occ_map, map_yaml)
    bag = None
    if write_queries:
        if q_idx.size == 0:
            raise ValueError(f'{log_path}: no query scans selected')
        bag = write_log_bag(log, q_idx, bag_path, occ_map, with_odom, overwrite, progress)
    return ConversionResult(map_yaml=map_yaml, bag=bag, map_scans=int(m_idx.size),
                            query_scans=int(q_idx.size) if write_queries else 0,
                            map_shape=occ_map.shape)
