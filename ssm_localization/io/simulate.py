"""
Simulated query scans on an occupancy map.

Random free-space poses, ray casting, range noise, unmapped clutter (discs near the robot that
occlude beams), spurious short readings, field of view.

Deterministic for a given seed; the poses depend only on the seed, the map and the clearance, so
a clean and a cluttered run with the same seed share their poses.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from .bag_records import ScanRecord
from .bag_writer import write_bag
from ..config.simulation import SimulationConfig
from ..mapping.occupancy import OccupancyMap
from ..mapping.raycast import cast_rays
from ..progress import ProgressCallback
from ..transforms import compose


@dataclass(frozen=True, eq=False)
class Simulation:
    """Simulated scans and their truth."""

    scans: list[ScanRecord]      # frame 'laser'
    poses: np.ndarray            # (P, 3) base poses in the map frame (the ground truth)
    sensor_poses: np.ndarray     # (P, 3) laser poses in the map frame
    clean_ranges: np.ndarray     # (P, B) ray-cast ranges on the map, before clutter and noise
    config: SimulationConfig


def sample_free_poses(occ_map: OccupancyMap, count: int, clearance: float,
                      rng: np.random.Generator) -> np.ndarray:
    """
    Return (count, 3) poses uniform over free cells at least ``clearance`` from non-free cells.

    Unknown counts as an obstacle; positions are uniform within the cell, yaw in [-pi, pi).
    """
    free = occ_map.free_mask()
    dist = distance_transform_edt(free) * occ_map.resolution
    rows, cols = np.nonzero(free & (dist >= max(clearance, 0.0) + 0.5 * occ_map.resolution))
    if rows.size == 0:
        raise ValueError(f'map has no free cell with clearance {clearance} m')
    pick = rng.integers(0, rows.size, size=count)
    xy = occ_map.cell_to_world(rows[pick] + rng.uniform(-0.5, 0.5, count),
                               cols[pick] + rng.uniform(-0.5, 0.5, count))
    yaw = rng.uniform(-math.pi, math.pi, count)
    return np.column_stack((xy, yaw))


def _disc_ranges(sensor_poses: np.ndarray, angles: np.ndarray, cfg: SimulationConfig,
                 rng: np.random.Generator) -> np.ndarray:
    """(P, B) ranges to ``cfg.clutter`` random discs per scan (inf where no disc is hit)."""
    p, n = len(sensor_poses), cfg.clutter
    out = np.full((p, len(angles)), np.inf)
    if n == 0:
        return out
    lo_a, hi_a = float(angles.min()), float(angles.max())
    bearing = rng.uniform(lo_a, hi_a, (p, n))            # within the field of view
    dist = rng.uniform(*cfg.clutter_distance, (p, n))
    radius = rng.uniform(*cfg.clutter_radius, (p, n))
    radius = np.minimum(radius, np.maximum(dist - 0.05, 0.01))   # never covers the sensor
    cx, cy = dist * np.cos(bearing), dist * np.sin(bearing)      # sensor frame
    ux, uy = np.cos(angles), np.sin(angles)
    b = cx[..., None] * ux + cy[..., None] * uy                  # (P, N, B) along the beam
    perp2 = (dist ** 2)[..., None] - b ** 2
    disc = radius[..., None] ** 2 - perp2
    t = np.where((disc >= 0) & (b > 0), b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    return t.min(axis=1)


def simulate(occ_map: OccupancyMap, config: SimulationConfig | None = None,
             progress: ProgressCallback | None = None) -> Simulation:
    """Simulate ``config.count`` scans at random poses of ``occ_map`` (see SimulationConfig)."""
    cfg = config or SimulationConfig()
    cfg.validate()
    pose_rng, clutter_rng, noise_rng = (np.random.default_rng(s) for s in
                                        np.random.SeedSequence(cfg.seed).spawn(3))
    poses = sample_free_poses(occ_map, cfg.count, cfg.clearance, pose_rng)
    sensor = np.array([compose(p, cfg.sensor_offset) for p in poses])
    angle_min, inc = cfg.angles()
    angles = angle_min + inc * np.arange(cfg.beams)
    clean = np.empty((cfg.count, cfg.beams))
    step = 25
    for a in range(0, cfg.count, step):
        clean[a:a + step] = cast_rays(occ_map.occupied_mask(), occ_map.resolution,
                                      occ_map.origin, sensor[a:a + step], angles, cfg.max_range)
        if progress is not None:
            progress(min(a + step, cfg.count), cfg.count, 'ray casting')
    ranges = np.minimum(clean, _disc_ranges(sensor, angles, cfg, clutter_rng))
    if cfg.short_fraction > 0:
        short = noise_rng.random(ranges.shape) < cfg.short_fraction
        upper = np.minimum(ranges, cfg.max_range)
        spurious = cfg.range_min + noise_rng.random(ranges.shape) * (upper - cfg.range_min)
        ranges = np.where(short, np.maximum(spurious, cfg.range_min), ranges)
    if cfg.noise_sigma > 0:
        noisy = ranges + noise_rng.normal(0.0, cfg.noise_sigma, ranges.shape)
        ranges = np.where(np.isfinite(ranges), np.maximum(noisy, cfg.range_min), ranges)
    ranges = np.where(ranges > cfg.max_range, np.inf, ranges)
    scans = [ScanRecord.from_ranges(cfg.stamp0 + k * cfg.period, ranges[k], angle_min, inc,
                                    range_min=cfg.range_min, range_max=cfg.max_range,
                                    scan_time=cfg.period, frame_id='laser')
             for k in range(cfg.count)]
    return Simulation(scans=scans, poses=poses, sensor_poses=sensor, clean_ranges=clean,
                      config=cfg)


def simulate_bag(occ_map: OccupancyMap, path: str | Path, config: SimulationConfig | None = None,
                 overwrite: bool = False, progress: ProgressCallback | None = None) -> Simulation:
    """Simulate and write a bag with /map, /scan and /ground_truth (base poses)."""
    sim = simulate(occ_map, config, progress)
    gt = {s.stamp: tuple(float(v) for v in p) for s, p in zip(sim.scans, sim.poses)}
    write_bag(path, map=occ_map, scans=sim.scans, ground_truth=gt, overwrite=overwrite)
    return sim
