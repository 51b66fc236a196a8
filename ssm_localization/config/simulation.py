"""Settings of the simulated query scans."""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class SimulationConfig:
    """How to simulate query scans (lengths in metres, angles in degrees where named so)."""

    count: int = 50
    beams: int = 360
    fov_deg: float = 360.0            # centred on the sensor's x axis
    max_range: float = 30.0           # no hit within it -> +inf
    range_min: float = 0.05
    noise_sigma: float = 0.01         # Gaussian range noise
    clearance: float = 0.3            # minimum distance from the base to non-free cells
    clutter: int = 0                  # unmapped discs per scan
    clutter_radius: tuple[float, float] = (0.1, 0.3)
    clutter_distance: tuple[float, float] = (1.0, 4.0)   # disc centre from the sensor
    short_fraction: float = 0.0       # fraction of beams replaced by a random shorter reading
    sensor_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # laser pose on the base
    seed: int = 0
    stamp0: float = 1.0
    period: float = 0.1

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
