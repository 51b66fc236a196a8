"""Settings of the simulated query scans."""
from __future__ import annotations

from dataclasses import dataclass
import math

from .fields import param


@dataclass(frozen=True)
class SimulationConfig:
    """How to simulate query scans (lengths in metres, angles in degrees where named so)."""

    count: int = param(50, 'number of scans')
    beams: int = param(360, 'beams per scan')
    fov_deg: float = param(
        360.0, "field of view, degrees, centred on the sensor's x axis")
    max_range: float = param(30.0, 'range of the simulated laser, metres (no hit: +inf)')
    range_min: float = param(0.05, 'shortest reading of the simulated laser, metres')
    noise_sigma: float = param(0.01, 'Gaussian range noise (sigma), metres')
    clearance: float = param(
        0.3, 'minimum distance from the base to non-free cells, metres')
    clutter: int = param(0, 'unmapped discs near the robot per scan')
    clutter_radius: tuple[float, float] = param(
        (0.1, 0.3), '(min, max) radius of the clutter discs, metres')
    clutter_distance: tuple[float, float] = param(
        (1.0, 4.0), '(min, max) distance of a disc centre from the sensor, metres')
    short_fraction: float = param(0.0, 'fraction of beams replaced by a random shorter reading')
    sensor_offset: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), "the laser's pose on the base (x, y, yaw)")
    seed: int = param(0, 'random seed (poses depend only on it, the map and the clearance)')
    stamp0: float = param(1.0, 'stamp of the first scan, seconds')
    period: float = param(0.1, 'time between scans, seconds')

    def validate(self) -> None:
        if self.count < 1 or self.beams < 2:
            raise ValueError(f'simulation: count must be >= 1 and beams >= 2, '
                             f'got {self.count}, {self.beams}')
        if not 0.0 < self.fov_deg <= 360.0:
            raise ValueError(f'simulation: fov_deg must be in (0, 360], got {self.fov_deg}')
        if not (self.max_range > self.range_min >= 0.0):
            raise ValueError('simulation: need max_range > range_min >= 0')
        if self.noise_sigma < 0 or self.clearance < 0 or self.clutter < 0:
            raise ValueError('simulation: noise_sigma, clearance and clutter must be >= 0')
        if not 0.0 <= self.short_fraction <= 1.0:
            raise ValueError(f'simulation: short_fraction must be in [0, 1], '
                             f'got {self.short_fraction}')

    def angles(self) -> tuple[float, float]:
        """``(angle_min, angle_increment)`` of the simulated LaserScan."""
        fov = math.radians(self.fov_deg)
        if self.fov_deg >= 360.0:
            return -math.pi, 2.0 * math.pi / self.beams
        return -fov / 2.0, fov / (self.beams - 1)
