"""Scan matcher settings (paper section II) and the eq. 4 weights."""
from __future__ import annotations

from dataclasses import dataclass
import math

from .fields import param

PREPARE_FIELDS = ('max_points', 'min_spacing', 'context_spacing', 'tangent_method',
                  'tangent_radius', 'gap', 'desc_radius', 'length_cap', 'desc_radial_bins',
                  'desc_angular_bins', 'icp_max_points', 'icp_min_spacing', 'normal_radius')
#: logistic weights w of eq. 4 learned by ``scripts/learn_weights.py`` (see its docstring)
LEARNED_WEIGHTS = (1.04795, -129.019, -0.0759161)
#: hand-set weights: sigma_d = 50 mm, sigma_theta = 0.2 rad, w0 = 3
HAND_WEIGHTS = (3.0, -200.0, -12.5)
#: the settings that must be > 0, >= 0 and >= 1 (lengths, tolerances; off-switches; counts)
_POSITIVE = ('min_spacing', 'context_spacing', 'tangent_radius', 'gap', 'desc_radius',
             'max_dist_deform', 'max_angle_deform', 'power_tol', 'ransac_threshold',
             'icp_max_dist', 'icp_min_dist', 'normal_radius', 'polish_gate', 'overlap_dist')
_NONNEGATIVE = ('length_cap', 'binarize_min_ratio', 'ransac_min_span', 'icp_min_spacing',
                'retry_overlap', 'icp_iterations', 'polish_iterations', 'retries', 'seed')
_AT_LEAST_ONE = ('desc_radial_bins', 'desc_angular_bins', 'power_iterations',
                 'ransac_iterations', 'ransac_hypotheses', 'min_inliers', 'icp_max_points')


@dataclass(frozen=True)
class MatcherConfig:
    """Scan matcher settings (lengths in metres, angles in radians); defaults are tuned."""

    # preprocessing (matching/scan.py, features.py)
    max_points: int = param(100, 'point budget after spatially even downsampling')
    min_spacing: float = param(0.05, 'smallest voxel side of the downsampling')
    context_spacing: float = param(0.1, 'voxel side of the context set (tangents, descriptors)')
    tangent_method: str = param('pca', "'pca' (robust, default) or 'eq1' (paper eq. 1 verbatim)")
    tangent_radius: float = param(0.3, 'PCA neighbourhood of the tangents')
    gap: float = param(0.5, 'eq. 1 only: neighbour jump treated as a gap')
    # descriptors and tentative correspondences L (matching/descriptors.py)
    desc_radius: float = param(2.0, 'radius of the local shape descriptors, metres')
    length_cap: float = param(0.3, 'descriptor votes weighted by scan length up to this (0: off)')
    desc_radial_bins: int = param(4, 'radial (log-distance) bins of the local shape descriptors')
    desc_angular_bins: int = param(8, 'angular bins of the local shape descriptors')
    k_candidates: int = param(3, 'reference candidates per new point')
    both_ways: bool = param(False, 'also k new candidates per reference point')
    # affinity (eqs. 3-4) and its zeroing rules
    weights: tuple[float, float, float] = param(
        LEARNED_WEIGHTS, 'logistic weights of the pairwise affinity (eq. 4)')
    max_dist_deform: float = param(0.3, "|d_ij - d_i'j'| above this: G_ab = 0")
    max_angle_deform: float = param(0.6, "|theta_ij - theta_i'j'| above this: G_ab = 0")
    # spectral solution (eqs. 5-6)
    power_iterations: int = param(40, 'power iterations for the leading eigenvector of G (eq. 6)')
    power_tol: float = param(1e-5, 'convergence tolerance of the power iteration')
    binarize_min_ratio: float = param(
        0.0, 'stop binarizing below this fraction of max x* (paper: 0)')
    # pose estimation (II.C)
    ransac_iterations: int = param(200, 'RANSAC iterations of the fine pose (paper II.C)')
    ransac_threshold: float = param(0.15, 'RANSAC inlier distance, metres')
    ransac_min_span: float = param(0.3, 'RANSAC: minimum spread of a 2-pair sample, metres')
    ransac_weighted: bool = param(False, 'draw / count pairs weighted by x* (beyond the paper)')
    ransac_hypotheses: int = param(3, 'distinct hypotheses refined when overlap is low')
    seed: int = param(0, 'random seed of RANSAC (results are reproducible)')
    min_inliers: int = param(6, 'fewer RANSAC inliers than this: no match')
    # point-to-line ICP refinement (beyond the paper)
    icp: bool = param(True, 'refine each match by point-to-line ICP (beyond the paper)')
    icp_iterations: int = param(10, 'point-to-line ICP iterations per match')
    icp_max_dist: float = param(
        0.3, 'ICP pair gate at the start (then 3x the median pair distance), metres')
    icp_min_dist: float = param(0.05, 'smallest ICP pair gate, metres')
    icp_max_points: int = param(400, 'budget of the denser point set used by ICP')
    icp_min_spacing: float = param(0.0, 'smallest voxel side of the ICP point set, metres')
    normal_radius: float = param(0.25, 'PCA neighbourhood of the ICP normals')
    polish: bool = param(True, 'after ICP: point-to-point LS on mutual nearest neighbours')
    polish_gate: float = param(
        0.05, 'mutual nearest neighbours closer than this take part in the polish, metres')
    polish_iterations: int = param(1, 'least-squares polish iterations')
    # retries on the next spectral cluster when the pose explains too little (beyond the paper)
    retries: int = param(
        1,
        'retries on the next spectral cluster when the pose explains too little of the new scan')
    retry_overlap: float = param(0.6, 'fraction of new ICP points within overlap_dist')
    overlap_dist: float = param(
        0.1, 'a new point closer than this to the reference counts as overlapping, metres')

    def __post_init__(self):
        if self.max_points < 3:
            raise ValueError('MatcherConfig.max_points must be >= 3')
        if self.k_candidates < 1:
            raise ValueError('MatcherConfig.k_candidates must be >= 1')
        if self.tangent_method not in ('pca', 'eq1'):
            raise ValueError("MatcherConfig.tangent_method must be 'pca' or 'eq1'")
        if len(self.weights) != 3:
            raise ValueError('MatcherConfig.weights must have 3 values (eq. 4)')
        object.__setattr__(self, 'weights', tuple(float(v) for v in self.weights))
        for name in _POSITIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'MatcherConfig.{name} must be a finite number > 0, '
                                 f'got {value!r}')
        for name in _NONNEGATIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'MatcherConfig.{name} must be a finite number >= 0, '
                                 f'got {value!r}')
        for name in _AT_LEAST_ONE:
            if getattr(self, name) < 1:
                raise ValueError(f'MatcherConfig.{name} must be >= 1, '
                                 f'got {getattr(self, name)!r}')
        if not all(math.isfinite(w) for w in self.weights):
            raise ValueError(f'MatcherConfig.weights must be finite, got {self.weights!r}')
