"""
Verification of a pose against the map (beyond the paper).

The scan's beams compared with beams ray-cast on the map from that pose.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BeamCheck:
    """Ray-cast agreement of a scan with the map at a pose (fractions of the valid beams)."""

    consistent: float     # |z - z_map| < tol
    contradicting: float  # z > z_map + tol: the beam went through a wall
    short: float          # z < z_map - tol: unmapped object (clutter), neither good nor bad

    @property
    def score(self) -> float:
        return self.consistent - 2.0 * self.contradicting


def check_beams(measured: np.ndarray, expected: np.ndarray, tol: float = 0.15,
                rel_tol: float = 0.02) -> BeamCheck:
    """
    Compare measured ranges with ranges ray-cast on the map (``inf`` = no return / no hit).

    Beams with no return where the map expects none are consistent; a no-return where the map has
    a wall counts as neither (glass, dark surfaces), so only solid evidence contradicts a pose.
    """
    z = np.asarray(measured, float)
    e = np.asarray(expected, float)
    n = max(len(z), 1)
    zf, ef = np.isfinite(z), np.isfinite(e)
    both = zf & ef
    t = tol + rel_tol * np.where(both, e, 0.0)
    with np.errstate(invalid='ignore'):
        diff = np.where(both, z - e, 0.0)
    consistent = (both & (np.abs(diff) < t)) | (~zf & ~ef)
    contradicting = (both & (diff >= t)) | (zf & ~ef)
    short = both & (diff <= -t)
    return BeamCheck(consistent=float(consistent.sum() / n),
                     contradicting=float(contradicting.sum() / n), short=float(short.sum() / n))
