"""
Everyday lasers made from better ones: a shorter range or a narrower field of view.

The benchmark logs come from SICK scanners (50-80 m, 180 deg); robots more often carry a 3.5 m
TurtleBot3 LDS or a 12 m RPLIDAR, or see only the beams in front of them. ``SensorLimits`` turns a
scan into what such a sensor would have read: readings beyond ``max_range`` become no-returns
(``+inf``, and ``range_max`` says so), beams outside the central ``fov`` are dropped.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .bag_records import ScanRecord


@dataclass(frozen=True)
class SensorLimits:
    """A sensor no better than ``max_range`` metres and ``fov`` radians (None: as recorded)."""

    name: str
    max_range: float | None = None
    fov: float | None = None

    def apply(self, scan: ScanRecord) -> ScanRecord:
        """Return ``scan`` as this sensor would have read it."""
        ranges = np.asarray(scan.ranges, dtype=np.float32)
        angle_min, range_max = scan.angle_min, scan.range_max
        if self.fov is not None and len(ranges):
            angles = scan.beam_angles()
            mid = 0.5 * (angles[0] + angles[-1])
            keep = np.abs(angles - mid) <= 0.5 * self.fov + 1e-9
            if keep.any():
                angle_min = float(angles[np.argmax(keep)])
            ranges = ranges[keep]
        if self.max_range is not None:
            with np.errstate(invalid='ignore'):
                ranges = np.where(ranges > self.max_range, np.float32(np.inf), ranges)
            range_max = min(range_max, self.max_range)
        return ScanRecord.from_ranges(scan.stamp, ranges, angle_min, scan.angle_increment,
                                      time_increment=scan.time_increment,
                                      scan_time=scan.scan_time, range_min=scan.range_min,
                                      range_max=range_max, frame_id=scan.frame_id)


#: the variants ``bench localize --sensors`` and the calibration run on
EVERYDAY_SENSORS = {
    'full': SensorLimits('full'),
    'range3.5': SensorLimits('range3.5', max_range=3.5),
    'range12': SensorLimits('range12', max_range=12.0),
    'fov90': SensorLimits('fov90', fov=math.radians(90.0)),
    'fov120': SensorLimits('fov120', fov=math.radians(120.0)),
}
