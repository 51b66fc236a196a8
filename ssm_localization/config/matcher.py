"""Scan matcher settings (paper section II) and the eq. 4 weights."""
from __future__ import annotations

from dataclasses import dataclass

PREPARE_FIELDS = ('max_points', 'min_spacing', 'context_spacing', 'tangent_method',
                  'tangent_radius', 'gap', 'desc_radius', 'length_cap', 'desc_radial_bins',
                  'desc_angular_bins', 'icp_max_points', 'icp_min_spacing', 'normal_radius')
#: logistic weights w of eq. 4 learned by ``scripts/learn_weights.py`` (see its docstring)
LEARNED_WEIGHTS = (1.04795, -129.019, -0.0759161)
#: hand-set weights: sigma_d = 50 mm, sigma_theta = 0.2 rad, w0 = 3
HAND_WEIGHTS = (3.0, -200.0, -12.5)


@dataclass(frozen=True)
class MatcherConfig:
    """Scan matcher settings (lengths in metres, angles in radians); defaults are tuned."""

    # preprocessing (scan.py)
    max_points: int = 100            # point budget after spatially even downsampling
    min_spacing: float = 0.05        # smallest voxel side of the downsampling
    context_spacing: float = 0.1     # voxel side of the context set (tangents, descriptors)
    tangent_method: str = 'pca'      # 'pca' (robust, default) or 'eq1' (paper eq. 1 verbatim)
    tangent_radius: float = 0.3      # PCA neighbourhood of the tangents
    gap: float = 0.5                 # eq. 1 only: neighbour jump treated as a gap
    # descriptors and tentative correspondences L (descriptors.py)
    desc_radius: float = 2.0
    length_cap: float = 0.3          # descriptor votes weighted by scan length up to this (0: off)
    desc_radial_bins: int = 4
    desc_angular_bins: int = 8
    k_candidates: int = 3            # reference candidates per new point
    both_ways: bool = False          # also k new candidates per reference point
    # affinity (eqs. 3-4) and its zeroing rules
    weights: tuple[float, float, float] = LEARNED_WEIGHTS
    max_dist_deform: float = 0.3     # |d_ij - d_i'j'| above this: G_ab = 0
    max_angle_deform: float = 0.6    # |theta_ij - theta_i'j'| above this: G_ab = 0
    # spectral solution (eqs. 5-6)
    power_iterations: int = 40
    power_tol: float = 1e-5
    binarize_min_ratio: float = 0.0  # stop binarizing below this fraction of max x* (paper: 0)
    # pose estimation (II.C)
    ransac_iterations: int = 200
    ransac_threshold: float = 0.15
    ransac_min_span: float = 0.3
    ransac_weighted: bool = False    # draw / count pairs weighted by x* (beyond the paper)
    ransac_hypotheses: int = 3       # distinct hypotheses refined when overlap is low
    seed: int = 0
    min_inliers: int = 6
    # point-to-line ICP refinement (beyond the paper)
    icp: bool = True
    icp_iterations: int = 10
    icp_max_dist: float = 0.3
    icp_min_dist: float = 0.05
    icp_max_points: int = 400        # budget of the denser point set used by ICP
    icp_min_spacing: float = 0.0
    normal_radius: float = 0.25      # PCA neighbourhood of the ICP normals
    polish: bool = True              # after ICP: point-to-point LS on mutual nearest neighbours
    polish_gate: float = 0.05
    polish_iterations: int = 1
    # retries on the next spectral cluster when the pose explains too little (beyond the paper)
    retries: int = 1
    retry_overlap: float = 0.6       # fraction of new ICP points within overlap_dist
    overlap_dist: float = 0.1

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
