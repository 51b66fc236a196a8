"""Localizer settings (paper section IV and what v2 adds around it)."""
from __future__ import annotations

from dataclasses import dataclass
import math

from .fields import check_numbers, param


@dataclass(frozen=True)
class LocalizerConfig:
    """
    Parameters of the localizer (the matcher's own come from the index it was built with).

    Lengths in metres, angles in radians. See ``localization/localizer.py`` for the pipeline.
    """

    # -- pose voting and spectral matching (coarse and fine stages)
    vote_neighbours: int = param(20, 'map features each query point is paired with (nearest '
                                     'descriptors) to vote for a pose')
    vote_bin_xy: float = param(0.5, 'position bin of the pose-vote histogram, metres')
    vote_bin_yaw: float = param(math.radians(10.0), 'yaw bin of the pose-vote histogram, rad')
    vote_descriptor_dims: int = param(12, 'nearest descriptors are searched in this many leading '
                                          'principal axes with a k-d tree (0: exactly, by brute '
                                          'force: cost linear in the map size)')
    vote_workers: int = param(2, 'threads the nearest-descriptor query of the votes runs in '
                                 "(scipy's k-d tree workers; -1: every core); the answers are "
                                 'the same with any number')
    vote_peaks: int = param(16, 'strongest pose-vote peaks whose correspondences are matched '
                                'spectrally (eqs. 2-6)')
    top_n: int = param(10, 'peaks kept by the spectral coarse ranking (eq. 5) for the RANSAC '
                           'fine pose; paper mode: nodes kept (paper: N = 5)')
    fine_ransac_iterations: int = param(60, '2-point RANSAC draws per peak (eqs. 7-8)')
    fine_min_inliers: int = param(6, 'RANSAC inliers a peak needs to become a pose hypothesis '
                                     '(the refinement and the ray check judge it from there)')
    # -- correlative search over the whole map at the hypotheses' yaws
    search: bool = param(True, 'branch-and-bound correlative search over the whole map at the '
                               'yaws of the best hypotheses and their flips')
    search_seeds: int = param(4, 'hypotheses whose yaws (and flipped yaws) seed the search')
    search_spread: float = param(math.radians(1.0), 'searched yaws: each seed +- this, in '
                                                    'steps of search_step, rad')
    search_step: float = param(math.radians(1.0), 'yaw step of the correlative search, rad')
    search_min_score: float = param(0.5, 'correlative score (mean point likelihood) below which '
                                         'no pose is kept')
    search_ratio: float = param(0.95, 'keep search leaves within this ratio of the best one')
    search_keep: int = param(4, 'distinct search leaves added as hypotheses')
    search_rivals: int = param(8, 'after a search of several regions (a campus): further leaves, '
                                  'each another place, added as the rivals of the answer')
    search_depth: int = param(4, 'levels of the branch and bound (top windows 2^depth cells)')
    search_workers: int = param(2, 'threads the scoring of the largest sets of search windows '
                                   'runs in (-1: every core); the answers are the same with any '
                                   'number')
    search_sigma: float = param(0.1, 'width of the correlative likelihood, metres')
    search_cell: float = param(0.05, 'cell size of the search, metres (rounded to a whole number '
                                     'of map cells, at least one)')
    search_max_cells: int = param(8_000_000, 'a map with more cells is searched on cells 2, 4, '
                                             '... times search_cell wide, the fewest that keep '
                                             'the search grid within this many cells (0: no '
                                             'cap); the cost of a search grows with its cells')
    search_points: int = param(40, 'scan points (of the spatially even set) the search scores')
    search_alignments: int = param(2, "further seed yaws from aligning the scan's wall "
                                      "directions with the map's")
    search_more_alignments: int = param(3, 'an answer not ok gets a second look (maps of one '
                                           'region): the search once more at this many further '
                                           'alignment yaws, its places decided together with '
                                           'the first ones')
    search_more_spread: float = param(math.radians(3.0), "... and the first look's yaws once "
                                                         'more, out to +- this (beyond '
                                                         "search_spread): a scan's walls a few "
                                                         "degrees off the map's, rad")
    weak_min_inliers: int = param(4, 'a failed answer on a map of several regions gets a weak '
                                     'look: the search once more in their own regions at the '
                                     'yaws of the vote peaks whose RANSAC pose has this many '
                                     'inliers or more but fewer than fine_min_inliers, its places '
                                     'decided together with the first ones (0: off)')
    weak_min_confidence: float = param(0.9985, 'an answer the weak look turns ok stays ok '
                                               'only with this confidence or more, after its '
                                               'twin check (else ambiguous)')
    search_twins: bool = param(True, 'an ok answer on a map of several regions (a campus) is '
                                     'checked for twins: the search once more in every region '
                                     "at the answer's yaw and its flip, its places decided "
                                     'together with the first ones (a look-alike room '
                                     'elsewhere is a rival, not luck); costs latency')
    search_twins_below: float = param(1.0, 'the twin check of maps of several regions runs '
                                           'only for ok answers with a confidence of at most '
                                           'this (1: every ok answer)')
    search_twins_ratio: float = param(0.95, 'the twin check looks for places scoring this much '
                                            "of the answer's own correlative score or more")
    search_twins_beams: int = param(40, 'beams ray-cast at each place the twin check finds, to '
                                        'rank them (a quick beam check)')
    search_twins_keep: int = param(8, 'places of the twin check, best by the quick beam check, '
                                      'refined and decided with the first ones')
    search_twins_margin: float = param(0.05, 'only places whose quick beam check scores within '
                                             "this of the answer's own are kept")
    search_flips: bool = param(True, 'an ok answer on a map of one region (a building) is '
                                     'checked for its flip: the search once more over the map '
                                     "at the answer's yaw and its half turn, its places decided "
                                     'together with the first ones (a room that fits turned '
                                     'round is a rival, not a lost leaf)')
    search_budget: float = param(0.2, 'seconds after which the search stops with what it has')
    # -- refinement on the wall surface
    refine_hypotheses: int = param(8, 'hypotheses refined on the wall surface (best by '
                                      'correlative score)')
    refine_iterations: int = param(10, "Gauss-Newton iterations on the map's wall surface")
    refine_radius: tuple[float, float] = param(
        (0.5, 0.1), 'Gauss-Newton truncation radius, first to last iteration, metres')
    surface_depth: float = param(0.5, 'prior of where walls lie behind the occupied-cell '
                                      'boundary, cells (estimated per scan from there)')
    surface_depth_std: float = param(0.1, 'standard deviation of that prior, cells')
    polish_iterations: int = param(6, 'Gauss-Newton iterations of the best pose on every '
                                      'endpoint of the scan (0: none)')
    estimate_depth: bool = param(True, 'estimate the wall-surface offset from the scan itself')
    # -- verification and the answer
    verify_hypotheses: int = param(3, 'refined hypotheses checked by ray casting, at least (best '
                                      'explained first), and every one that could still win or '
                                      'be a rival')
    verify_margin: float = param(0.1, '... and every one whose explained fraction is within this '
                                      'of the best')
    verify_beams: int = param(120, 'beams (evenly chosen) ray-cast per verified hypothesis')
    max_cast_range: float = param(30.0, 'ray-cast range of the beam check and points used by '
                                        'the correlative search, metres')
    beam_tolerance: float = param(0.15, 'metres (+2 % of the range) for a beam to agree with '
                                        'the map')
    score_sigma: float = param(0.05, 'residual scale of the explained fraction '
                                     'mean(exp(-r^2 / 2 sigma^2)), metres')
    contradiction_weight: float = param(1.0, 'score = explained fraction - this x fraction of '
                                             'beams seeing through walls')
    max_contradicting: float = param(0.35, 'a pose with more of its beams seeing through walls '
                                           'is implausible; with no plausible pose: failed')
    min_score: float = param(0.4, 'a best pose scoring less (explained fraction minus the '
                                  'through-wall penalty): failed')
    ambiguity_margin: float = param(0.02, 'a distinct rival scoring within this of the best: '
                                          'ambiguous')
    rival_contradiction: float = param(
        0.1, 'a distinct pose that explains at least as much of the scan as the best and sees '
             'through at most this much more of its beams is a rival too (ambiguous): the best '
             "then wins only on beams through the map's specks")
    min_confidence: float = param(0.98, 'a pose that passes the rules is ok only when its '
                                        'calibrated confidence P(right | evidence) reaches '
                                        'this (the tuning split: 99.94 % of such answers right)')
    distinct_xy: float = param(0.5, 'poses further apart than this are distinct, metres')
    distinct_yaw: float = param(math.radians(10.0), '... or than this, rad')
    max_position_std: float = param(0.25, 'a larger reported position std along the weakest '
                                          'direction: ambiguous (2 sigma beyond the 0.5 m '
                                          'success tolerance: a corridor too bare to tell), m')
    min_scan_extent: float = param(1.0, 'a scan whose spatially even points lie within this '
                                        'of the sensor (90th percentile of their range) sees '
                                        'too little to tell places apart: ambiguous, metres')
    covariance_scale: float = param(100.0, 'Gauss-Newton covariance multiplier (neighbouring '
                                           'residuals are correlated)')
    min_position_std: float = param(0.04, 'floor of the reported position std, metres')
    min_yaw_std: float = param(math.radians(0.5), 'floor of the reported yaw std, rad')
    min_points: int = param(10, 'fewer valid beams than this: failed')
    laser_pose: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), "the laser's pose on the robot base (x, y, yaw); the nodes set it from "
        'laser_x/laser_y/laser_yaw')
    # -- the plain paper pipeline, for comparison
    paper_mode: bool = param(False, 'the plain paper pipeline: every node ranked by its spectral '
                                    'score, RANSAC + least squares on the top_n, the largest '
                                    'vicinity score wins, always ok')
    sigma_d: float = param(0.05, 'paper mode: eq. (10) vicinity score distance scale, metres')

    def __post_init__(self) -> None:
        positive = ('vote_neighbours', 'vote_bin_xy', 'vote_bin_yaw', 'vote_peaks', 'top_n',
                    'fine_ransac_iterations', 'fine_min_inliers', 'search_seeds', 'search_step',
                    'search_keep', 'search_depth', 'search_sigma', 'search_cell', 'search_budget',
                    'search_points', 'search_twins_beams',
                    'verify_beams', 'refine_hypotheses', 'verify_hypotheses', 'max_cast_range',
                    'surface_depth_std', 'beam_tolerance', 'score_sigma',
                    'distinct_xy', 'distinct_yaw', 'max_position_std', 'min_scan_extent',
                    'covariance_scale',
                    'sigma_d')
        nonnegative = ('vote_descriptor_dims', 'search_spread', 'search_alignments',
                       'search_more_alignments', 'search_more_spread', 'weak_min_inliers',
                       'search_rivals', 'search_max_cells', 'search_twins_keep',
                       'search_twins_margin',
                       'refine_iterations', 'polish_iterations', 'surface_depth',
                       'search_min_score', 'contradiction_weight', 'max_contradicting',
                       'min_score', 'verify_margin', 'ambiguity_margin', 'rival_contradiction',
                       'min_position_std',
                       'min_yaw_std', 'min_points')
        check_numbers(self, positive, nonnegative)
        for name in ('vote_workers', 'search_workers'):
            if getattr(self, name) != -1 and getattr(self, name) < 1:
                raise ValueError(f'LocalizerConfig.{name} must be -1 (every core) or at least '
                                 f'1, got {getattr(self, name)!r}')
        for name in ('min_confidence', 'search_twins_below', 'weak_min_confidence',
                     'search_twins_ratio'):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f'LocalizerConfig.{name} must be in [0, 1], got '
                                 f'{getattr(self, name)!r}')
        if not 0.0 < self.search_ratio <= 1.0:
            raise ValueError(f'LocalizerConfig.search_ratio must be in (0, 1], got '
                             f'{self.search_ratio!r}')
        lo, hi = (float(v) for v in self.refine_radius)
        if not (0 < hi <= lo and math.isfinite(lo)):
            raise ValueError(f'LocalizerConfig.refine_radius must be (first, last) with first >= '
                             f'last > 0, got {self.refine_radius!r}')
