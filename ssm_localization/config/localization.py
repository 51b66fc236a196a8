"""Localizer settings (paper section IV and the verification beyond it)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fields import param


@dataclass(frozen=True)
class LocalizerConfig:
    """Parameters of the localizer (the matcher's own come from the index it was built with)."""

    top_n: int = param(10, 'candidate nodes kept by the spectral coarse stage (paper: N = 5)')
    prefilter: int = param(20, 'nodes kept by descriptor voting before spectral ranking; 0 = all')
    vote_neighbours: int = param(8, 'nodes each query descriptor votes for (its nearest ones)')
    sigma_d: float = param(0.05, 'eq. (10) vicinity score distance scale, metres')
    laser_pose: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), "the laser's pose on the robot base (x, y, yaw); the nodes set it from "
        'laser_x/laser_y/laser_yaw')
    paper_mode: bool = param(False, 'plain paper pipeline: no prefilter, refinement or map check')
    fine_icp: bool = param(True, 'matcher ICP in the fine stage (better hypotheses on real scans)')
    fine_icp_iterations: int = param(15, 'matcher ICP iterations per candidate')
    fine_polish: bool = param(True, 'matcher least-squares polish after its ICP')
    fine_retries: int = param(0, 'matcher retries on further spectral clusters per candidate')
    fine_ransac_hypotheses: int = param(3, 'RANSAC hypotheses the matcher may refine per candidate')
    refine: bool = param(True, "Gauss-Newton on the map's wall surface")
    surface_depth: float = param(0.5, 'cells behind the occupied-cell boundary where walls are')
    refine_iterations: int = param(12, "Gauss-Newton iterations on the map's wall surface")
    refine_radius: tuple[float, float] = param(
        (0.3, 0.1), 'truncation radius, first to last iteration (m)')
    max_cast_range: float = param(30.0, 'ray-cast range for the beam check, metres')
    beam_tolerance: float = param(
        0.15, 'metres (+2 % of the range) for a beam to agree with the map')
    min_consistent: float = param(0.5, 'fewer beams agreeing with the map rejects a hypothesis')
    max_contradicting: float = param(0.3, 'more beams seeing through walls rejects it')
    contradiction_weight: float = param(
        2.0, 'fit = cost / inlier_distance^2 + this * through-wall fraction')
    max_fit: float = param(0.75, 'a best fit above this explains too little of the scan: failed')
    ambiguity_ratio: float = param(
        1.5, 'a distinct rival whose fit is within this factor: ambiguous')
    inlier_distance: float = param(0.1, 'endpoints further from the walls count as outliers (m)')
    distinct_xy: float = param(0.5, 'poses further apart than this are distinct (m) ')
    distinct_yaw: float = param(np.deg2rad(10.0), '... or than this (rad)')
    min_points: int = param(10, 'fewer valid beams than this: failed')
    max_position_std: float = param(
        0.15, 'a larger position std (m) of the refined fit: degenerate')

    def __post_init__(self) -> None:
        if self.top_n < 1:
            raise ValueError('top_n must be >= 1')
        if self.sigma_d <= 0:
            raise ValueError('sigma_d must be > 0')
