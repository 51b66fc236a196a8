"""
Evidence measured on maps of coarser cells than the calibration maps (beyond the paper).

The confidence (``config/confidence.py``) was fitted on answers on maps of
:data:`~ssm_localization.config.confidence.CALIBRATION_RESOLUTION` (0.05 m) cells. Two of the
measurements its evidence rests on carry the map's cell size ``c``:

- the beam check (``verify.check_beams``) compares a range with the distance to the boundary of
  the first occupied cell the beam enters, and the wall's surface lies anywhere up to a cell
  behind that boundary: along a beam that meets the wall at incidence ``a`` (from its normal)
  up to ``c / cos a``. A right pose's grazing beams so read "through the wall" more often on
  coarse cells (on the Intel, ACES and Freiburg 079 maps built at 0.1 m: 7-15 % of the returns
  at right poses against 3-7 % at 0.05 m, most of the extra at incidences beyond 55°);
- the explained fraction (``mean exp(-r^2 / 2 sigma^2)``, ``score_sigma``) measures each
  endpoint's distance to the wall surface, which on cells of size ``c`` is placed to within a
  uniform error of variance ``c^2 / 12``.

So on a map of cells ``c`` coarser than the calibration's ``c0``, the beam tolerance grows by
``(c - c0) / max(cos a, MIN_COS)`` and ``score_sigma^2`` by ``(c^2 - c0^2) / 12``: the evidence
of a right pose then reads as it did on the maps the confidence was fitted on. On maps of ``c0``
or finer cells nothing changes (the answers are those the calibration measured).
"""
from __future__ import annotations

import math

import numpy as np

from ..config.confidence import CALIBRATION_RESOLUTION

#: incidences beyond acos(MIN_COS) (78.5°) count as this: the extra tolerance of a beam grazing a
#: wall stays within five times the extra cell size
MIN_COS = 0.2


def excess_cell(resolution: float) -> float:
    """Return how much coarser the map's cells are than the calibration maps' (metres, >= 0)."""
    return max(float(resolution) - CALIBRATION_RESOLUTION, 0.0)


def effective_score_sigma(score_sigma: float, resolution: float) -> float:
    """Return ``score_sigma`` widened by the extra quantization of cells coarser than c0."""
    if excess_cell(resolution) <= 0.0:
        return float(score_sigma)
    extra = (float(resolution) ** 2 - CALIBRATION_RESOLUTION ** 2) / 12.0
    return math.sqrt(float(score_sigma) ** 2 + extra)


def beam_tolerances(tolerance: float, excess: float, cos_incidence: np.ndarray) -> np.ndarray:
    """
    Return each beam's tolerance: ``tolerance + excess / max(|cos a|, MIN_COS)``.

    ``cos_incidence`` per beam, the cosine of the angle between the beam and the normal of the
    wall it meets (1 where unknown).
    """
    cos_a = np.maximum(np.abs(np.asarray(cos_incidence, float)), MIN_COS)
    return float(tolerance) + float(excess) / cos_a
