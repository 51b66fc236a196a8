"""
Verification of a pose against the map (beyond the paper).

The scan's beams compared with beams ray-cast on the map from that pose.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class BeamCheck:
    """
    Ray-cast agreement of a scan with the map at a pose.

    Fractions of the checked beams (``consistent``, ``contradicting``, ``short``) and the counts
    the evidence of an answer is made of (``evidence.py``).
    """

    consistent: float     # |z - z_map| < tol, or no return where the map has no wall either
    contradicting: float  # z > z_map + tol (through a wall) or a return where the map has none
    short: float          # z < z_map - tol: unmapped object (clutter), neither good nor bad
    beams: int = 0        # beams checked
    returns: int = 0      # ... with a finite reading
    hits: int = 0         # returns within tol of the map's wall
    through: int = 0      # returns behind the map's wall or where the map has none
    shorts: int = 0       # returns in front of the map's wall
    missing: int = 0      # no return where the map has a wall well within the sensor's range

    def score(self, contradiction_weight: float) -> float:
        """Return ``consistent - contradiction_weight x contradicting`` (``LocalizerConfig``)."""
        return self.consistent - contradiction_weight * self.contradicting


def check_beams(measured: np.ndarray, expected: np.ndarray, tol: float = 0.15,
                rel_tol: float = 0.02, range_limit: float = math.inf) -> BeamCheck:
    """
    Compare measured ranges with ranges ray-cast on the map (``inf`` = no return / no hit).

    Beams with no return where the map expects none are consistent; a no-return where the map has
    a wall counts as neither (glass, dark surfaces), so only solid evidence contradicts a pose.
    ``missing`` counts the no-returns where the map has a wall within 90 % of ``range_limit``
    (the sensor's range), for the evidence of the answer.
    """
    z = np.asarray(measured, float)
    e = np.asarray(expected, float)
    n = max(len(z), 1)
    zf, ef = np.isfinite(z), np.isfinite(e)
    both = zf & ef
    t = tol + rel_tol * np.where(both, e, 0.0)
    with np.errstate(invalid='ignore'):
        diff = np.where(both, z - e, 0.0)
    hit = both & (np.abs(diff) < t)
    consistent = hit | (~zf & ~ef)
    contradicting = (both & (diff >= t)) | (zf & ~ef)
    short = both & (diff <= -t)
    with np.errstate(invalid='ignore'):
        missing = ~zf & ef & (e < 0.9 * range_limit)
    return BeamCheck(consistent=float(consistent.sum() / n),
                     contradicting=float(contradicting.sum() / n), short=float(short.sum() / n),
                     beams=int(len(z)), returns=int(zf.sum()), hits=int(hit.sum()),
                     through=int(contradicting.sum()), shorts=int(short.sum()),
                     missing=int(missing.sum()))
