"""
localization/resolution.py: the evidence on maps of coarser cells than the calibration maps.

On maps of the calibration's cell size (or finer) nothing changes; on coarser ones the beam
check's tolerance grows with the extra cell size over the cosine of each beam's incidence, and
the explained fraction's residual scale with the extra quantization.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from ssm_localization import build_index, GlobalLocalizer, LocalizerConfig
from ssm_localization.config.confidence import CALIBRATION_RESOLUTION
from ssm_localization.localization.resolution import (beam_tolerances, effective_score_sigma,
                                                      excess_cell, MIN_COS)
from ssm_localization.localization.verify import check_beams
from ssm_localization.mapping.map_io import OccupancyMap
from ssm_localization.mapping.raycast import cast_rays


def test_nothing_changes_on_maps_of_the_calibration_cells_or_finer():
    for res in (CALIBRATION_RESOLUTION, 0.025, 0.01):
        assert excess_cell(res) == 0.0
        assert effective_score_sigma(0.05, res) == 0.05
        assert effective_score_sigma(0.07, res) == 0.07


def test_coarser_cells_widen_the_residual_scale_by_their_extra_quantization():
    for res in (0.1, 0.2):
        want = math.sqrt(0.05 ** 2 + (res ** 2 - CALIBRATION_RESOLUTION ** 2) / 12.0)
        assert effective_score_sigma(0.05, res) == pytest.approx(want)
        assert excess_cell(res) == pytest.approx(res - CALIBRATION_RESOLUTION)
    assert effective_score_sigma(0.05, 0.2) > effective_score_sigma(0.05, 0.1) > 0.05


def test_beam_tolerance_grows_with_the_incidence_and_is_capped_for_grazing_beams():
    tol = beam_tolerances(0.15, 0.05, np.array([1.0, 0.5, -0.5, 0.1, 0.0]))
    assert tol == pytest.approx([0.2, 0.25, 0.25, 0.15 + 0.05 / MIN_COS, 0.15 + 0.05 / MIN_COS])
    assert np.all(beam_tolerances(0.15, 0.0, np.array([1.0, 0.0])) == 0.15)


def _room(res: float) -> OccupancyMap:
    """Return a 12 m x 8 m room with a 2 m x 1 m pillar, walls 0.2 m thick, cells of ``res``."""
    h, w = int(round(8.0 / res)), int(round(12.0 / res))
    t = int(round(0.2 / res))
    d = np.zeros((h, w), np.int8)
    d[:t, :] = d[-t:, :] = 100
    d[:, :t] = d[:, -t:] = 100
    r0, r1, c0, c1 = (int(round(v / res)) for v in (5.0, 6.0, 3.0, 5.0))
    d[r0:r1, c0:c1] = 100
    return OccupancyMap(d, res)


@pytest.fixture(scope='module', params=[0.05, 0.1])
def room(request):
    occ = _room(request.param)
    return occ, GlobalLocalizer(build_index(occ))


def test_the_localizer_takes_the_settings_as_configured_on_calibration_cells(room):
    occ, loc = room
    cfg = LocalizerConfig()
    if occ.resolution == CALIBRATION_RESOLUTION:
        assert loc.score_sigma == cfg.score_sigma
    else:
        assert loc.score_sigma == pytest.approx(effective_score_sigma(cfg.score_sigma, 0.1))
        assert loc.score_sigma > cfg.score_sigma


def test_incidence_is_the_cosine_between_the_beam_and_the_wall_normal(room):
    occ, loc = room
    pose = np.array([6.0, 2.0, 0.0])               # 1.8 m above the bottom wall's surface
    angles = -np.radians([90.0, 60.0, 30.0])       # meeting it at 0, 30 and 60 deg incidence
    expected = loc.caster.cast(pose[None], angles, 30.0)[0]
    cos = loc._incidence(pose, angles, expected)
    assert cos == pytest.approx(np.cos(np.radians([0.0, 30.0, 60.0])), abs=0.05)
    none = loc._incidence(pose, angles, np.full(3, np.inf))     # no wall met: 1
    assert np.all(none == 1.0)


def test_a_grazing_return_just_behind_the_boundary_is_a_hit_only_on_coarse_cells(room):
    """The surface lies within a cell of the boundary: up to a cell / cos(a) along the beam."""
    occ, loc = room
    cfg = loc.config
    pose = (6.0, 2.0, 0.0)
    angles = np.radians([-10.0, -15.0])            # 80 and 75 deg incidence on the bottom wall
    expected = cast_rays(occ.occupied_mask(), occ.resolution, occ.origin, np.array([pose]),
                         angles, 30.0)[0]
    measured = expected + 0.15 + 0.02 * expected + 0.05     # past the calibration's tolerance
    got = loc._checks([pose], angles, measured, 30.0)[0]
    plain = check_beams(measured, expected, tol=cfg.beam_tolerance, range_limit=30.0)
    assert plain.through == 2 and plain.hits == 0
    if occ.resolution == CALIBRATION_RESOLUTION:
        assert got == plain
    else:
        assert got.hits == 2 and got.through == 0
