"""localization/regions.py: the correlative search region by region, each at its own yaws."""
from __future__ import annotations

import dataclasses
import math

from helpers import BAGS
import numpy as np
import pytest
from ssm_localization import build_index, GlobalLocalizer, OccupancyMap, read_bag
from ssm_localization.bench.peer import FullSearchLocalizer
from ssm_localization.config.localization import LocalizerConfig
from ssm_localization.localization.correlative import CorrelativeResult
from ssm_localization.localization.localizer import (_by_correlation, Hypothesis, OK,
                                                     StageClock)
from ssm_localization.localization.regions import (
    pick_leaves, place_leaves, REGION_BATCH, REGION_HOT_BATCHES, REGION_RATIO, ring_yaws,
    SearchPlan, spread_yaws, with_region_bests)
from ssm_localization.mapping.raycast import beam_angles, cast_rays
from ssm_localization.transforms import apply, wrap_angle

RES = 0.05


def _building(data: np.ndarray, x0: float, y0: float, yaw: float, seed: int) -> None:
    """Draw a 16 m x 12 m building of rooms, turned by ``yaw`` about (x0, y0), into ``data``."""
    rng = np.random.default_rng(seed)
    walls = [(0, 0, 16, 0.2), (0, 11.8, 16, 12), (0, 0, 0.2, 12), (15.8, 0, 16, 12),
             (0, 5.9, 9, 6.1), (11, 5.9, 16, 6.1)]
    for x in rng.uniform(2, 14, 3):
        walls.append((x, 0, x + 0.2, rng.uniform(3, 5)))
    for _ in range(4):
        x, y = rng.uniform(1, 14), rng.uniform(7, 11)
        walls.append((x, y, x + rng.uniform(0.4, 1.2), y + rng.uniform(0.4, 1.2)))
    free = np.zeros(data.shape, bool)
    rows, cols = np.indices(data.shape)
    local = apply((0.0, 0.0, -yaw), np.column_stack(((cols.ravel() + 0.5) * RES - x0,
                                                     (rows.ravel() + 0.5) * RES - y0)))
    lx, ly = local[:, 0].reshape(data.shape), local[:, 1].reshape(data.shape)
    free |= (lx > 0) & (lx < 16) & (ly > 0) & (ly < 12)
    data[free] = 0
    for a, b, c, d in walls:
        data[(lx >= a) & (lx <= c) & (ly >= b) & (ly <= d)] = 100


@pytest.fixture(scope='module')
def campus():
    """Two buildings 38 m apart, one axis-aligned, one turned by 30 degrees."""
    data = np.full((500, 1700), -1, np.int8)
    _building(data, 2.0, 4.0, 0.0, 1)
    _building(data, 62.0, 2.0, math.radians(30.0), 2)
    occ = OccupancyMap(data, RES, (0.0, 0.0, 0.0))
    return occ, GlobalLocalizer(build_index(occ))


TURNED_TRUTH = (68.0, 9.0, 2.0)          # inside the turned building of `campus`


def _turned_scan(occ: OccupancyMap) -> tuple[np.ndarray, np.ndarray]:
    """Return the beam angles and ranges of a 360-beam scan at :data:`TURNED_TRUTH`."""
    angles = beam_angles(360)
    ranges = cast_rays(occ.occupied_mask(), RES, occ.origin, np.array([TURNED_TRUTH]), angles,
                       30.0)[0]
    return angles, ranges


def test_buildings_apart_are_regions_with_their_own_walls(campus):
    occ, loc = campus
    assert loc.regions.count == 2
    a, b = loc.regions.region_of(np.array([[10.0, 10.0], [68.0, 12.0]]))
    assert a != b and min(a, b) >= 0
    assert loc.regions.region_of(np.array([[37.0, 12.0]]))[0] == -1     # the gap
    # a scan turned by 30 degrees aligns with the turned building's walls
    angles = np.linspace(0.0, math.pi, 60)
    aligned = loc.regions.alignment_yaws(angles + math.radians(10.0), 2)
    for yaws, turn in ((aligned[a], 0.0), (aligned[b], math.radians(30.0))):
        errors = [abs(wrap_angle(2.0 * (y + math.radians(10.0) - turn))) / 2.0 for y in yaws]
        assert min(np.abs(np.mod(np.asarray(errors), math.pi / 2.0))) < math.radians(1.5)


def test_scan_of_the_turned_building_is_searched_at_its_yaw_and_found(campus):
    occ, loc = campus
    truth = TURNED_TRUTH
    angles, ranges = _turned_scan(occ)
    ranges = ranges + np.random.default_rng(0).normal(0.0, 0.01, len(ranges))
    query = loc.prepare_scan(ranges, angles[0], angles[1] - angles[0], 0.05, 30.0)
    plan = loc.search_plan(query, [])
    mine = loc.regions.region_of(np.array([truth[:2]]))[0]
    near = np.abs(wrap_angle(plan.yaws - truth[2])) < math.radians(1.5)
    assert (near & plan.allowed[:, mine]).any()
    assert not plan.allowed[:, mine].all()           # each yaw only where it belongs
    loc_ = loc.localize_scan(ranges, angles[0], angles[1] - angles[0], 0.05, 30.0)
    assert loc_.status == 'ok'
    assert math.hypot(loc_.pose[0] - truth[0], loc_.pose[1] - truth[1]) < 0.05


def _first_plan(campus) -> tuple:
    """Return the localizer, the turned building's query, one seed and the first plan."""
    occ, loc = campus
    angles, ranges = _turned_scan(occ)
    query = loc.prepare_scan(ranges, angles[0], angles[1] - angles[0], 0.05, 30.0)
    seeds = [(10.0, 10.0, 0.3)]
    return loc, query, seeds, loc.regions.plan(query.wall_angles, seeds, loc.config)


def _apart(a, b):
    """(len(a), len(b)) angles apart modulo a half turn."""
    return np.abs(wrap_angle(2.0 * (np.asarray(a)[:, None] - np.asarray(b)[None, :]))) / 2.0


def test_the_second_look_searches_each_region_at_its_next_alignments_only(campus):
    loc, query, seeds, first = _first_plan(campus)
    cfg = dataclasses.replace(loc.config, search_more_spread=loc.config.search_spread)
    more = loc.regions.plan(query.wall_angles, seeds, cfg, more=True)
    wider = loc.regions.alignment_yaws(
        query.wall_angles, cfg.search_alignments + cfg.search_more_alignments)
    seeded = loc.regions.region_of(np.array([seeds[0][:2]]))[0]
    for r in range(loc.regions.count):
        new = more.yaws[more.allowed[:, r]]
        assert len(new), 'every region has further alignments'
        # every new yaw lies around one of the region's next alignments ...
        nxt = wider[r][cfg.search_alignments:]
        assert (_apart(new, nxt).min(axis=1) <= cfg.search_spread + 1e-9).all()
        # ... whose centre the first plan did not search (its first alignments, the seed's yaw)
        centres = [y for y in nxt if _apart(new, [y]).min() < 1e-9]
        old = list(wider[r][:cfg.search_alignments]) + ([0.3] if r == seeded else [])
        assert centres and _apart(centres, old).min() > cfg.search_step
        assert _apart(centres, first.yaws[first.allowed[:, r]]).min() > 0.0


def test_the_second_look_searches_the_first_yaws_once_more_out_to_its_spread(campus):
    loc, query, seeds, first = _first_plan(campus)
    cfg = loc.config
    assert cfg.search_more_spread > cfg.search_spread + cfg.search_step
    narrow = loc.regions.plan(query.wall_angles, seeds,
                              dataclasses.replace(cfg, search_more_spread=0.0), more=True)
    more = loc.regions.plan(query.wall_angles, seeds, cfg, more=True)
    for r in range(loc.regions.count):
        old = first.yaws[first.allowed[:, r]]
        alignments = narrow.yaws[narrow.allowed[:, r]]
        new = more.yaws[more.allowed[:, r]]
        # the further alignments first, as without the ring, then the ring
        np.testing.assert_array_equal(new[:len(alignments)], alignments)
        ring = new[len(alignments):]
        assert len(ring)
        near = np.abs(wrap_angle(ring[:, None] - old[None, :])).min(axis=1)
        # beyond the first plan's yaws, within search_more_spread of its centres
        assert (near > 0.5 * cfg.search_step).all()
        assert (near <= cfg.search_more_spread - cfg.search_spread + 1e-9).all()
        # no yaw searched twice
        every = np.concatenate((alignments, ring))
        gaps = np.abs(wrap_angle(every[:, None] - every[None, :])) + np.eye(len(every))
        assert gaps.min() > 0.5 * cfg.search_step


def test_the_ring_of_a_yaw_is_its_steps_beyond_the_spread():
    cfg = LocalizerConfig()
    step = cfg.search_step
    near, far = (int(round(spread / step)) for spread in (cfg.search_spread,
                                                          cfg.search_more_spread))
    ring = ring_yaws([0.5], cfg)
    want = [0.5 + k * step + flip for flip in (0.0, math.pi)
            for k in range(-far, far + 1) if abs(k) > near]
    np.testing.assert_allclose(np.sort(ring), np.sort(want))
    # two centres 3 steps apart: the ring leaves out what the other's spread searches
    two = ring_yaws([0.5, 0.5 + 3 * step], cfg)
    searched = spread_yaws([0.5, 0.5 + 3 * step], cfg)
    assert np.abs(wrap_angle(two[:, None] - searched[None, :])).min() > 0.5 * step
    assert ring_yaws([], cfg).size == 0
    assert ring_yaws([0.5], dataclasses.replace(cfg, search_more_spread=0.0)).size == 0


def test_the_weak_look_searches_each_weak_pose_in_its_own_region_at_new_yaws_only(campus):
    loc, query, seeds, first = _first_plan(campus)
    cfg = loc.config
    turned = int(loc.regions.region_of(np.array([TURNED_TRUTH[:2]]))[0])
    seeded = int(loc.regions.region_of(np.array([seeds[0][:2]]))[0])
    assert turned != seeded
    x, y = TURNED_TRUTH[:2]
    weak = [(x, y, 1.2), (x + 1.0, y, 1.2), (10.0, 10.0, 0.3 + math.pi), (-500.0, -500.0, 2.5)]
    plan = loc.regions.plan(query.wall_angles, seeds, cfg, weak=weak)
    # only the turned building, at the one weak yaw lying in it (twice: one search) and its flip
    assert plan.allowed[:, turned].all() and plan.allowed.sum(axis=1).max() == 1
    centres = np.array([1.2, 1.2 + math.pi])
    apart = np.abs(wrap_angle(plan.yaws[:, None] - centres[None, :])).min(axis=1)
    assert (apart <= cfg.search_spread + 1e-9).all() and len(plan.yaws) == len(
        np.unique(np.round(plan.yaws, 9)))
    # the seed's flip in its own region and a pose in no region add nothing; a yaw the first
    # plan searched in that region is not searched again
    assert loc.regions.plan(query.wall_angles, seeds, cfg, weak=weak[2:]).yaws.size == 0
    done = first.yaws[first.allowed[:, turned]][0] + cfg.search_step / 2   # a searched centre
    again = loc.regions.plan(query.wall_angles, seeds, cfg,
                             weak=[(TURNED_TRUTH[0], TURNED_TRUTH[1], float(done))])
    assert again.yaws.size == 0


def test_a_failed_answer_gets_a_weak_look_whose_ok_needs_its_confidence(campus):
    """With no hypothesis and no alignment search, only the weak peaks can find the place."""
    occ, loc = campus
    angles, ranges = _turned_scan(occ)
    args = (ranges, angles[0], angles[1] - angles[0], 0.05, 30.0)
    blind = dataclasses.replace(loc.config, search_alignments=0, fine_min_inliers=10 ** 6,
                                weak_min_inliers=2)
    looked = GlobalLocalizer(loc.index, blind)
    hyps, weak = looked.spectral_peaks(looked.prepare_scan(*args))
    assert hyps == [] and weak                  # every peak a weak one
    answer = looked.localize_scan(*args)
    assert answer.status == OK and answer.confidence >= blind.weak_min_confidence
    assert math.hypot(answer.pose[0] - TURNED_TRUTH[0], answer.pose[1] - TURNED_TRUTH[1]) < 0.1
    assert 'twins' in answer.stages             # checked for twins whatever its confidence
    off = GlobalLocalizer(loc.index, dataclasses.replace(blind, weak_min_inliers=0))
    assert off.localize_scan(*args).status == 'failed'
    strict = GlobalLocalizer(loc.index, dataclasses.replace(blind, weak_min_confidence=1.0))
    refused = strict.localize_scan(*args)
    assert refused.status == 'ambiguous' and 'weak vote peaks' in refused.message
    assert refused.pose == answer.pose


def test_the_full_search_peer_searches_every_yaw_in_every_region(campus):
    """``bench localize --peer``'s package peer: the whole turn in both buildings, one answer."""
    occ, loc = campus
    truth = TURNED_TRUTH
    angles, ranges = _turned_scan(occ)
    args = (ranges, angles[0], angles[1] - angles[0], 0.05, 30.0)
    full = FullSearchLocalizer(loc)
    plan = full.search_plan(loc.prepare_scan(*args), [])
    assert plan.allowed.shape == (360, loc.regions.count) and plan.allowed.all()
    assert plan.labels is loc.regions.labels
    found = full.localize_scan(*args)
    assert found.status == 'ok', found.message
    assert math.hypot(found.pose[0] - truth[0], found.pose[1] - truth[1]) < 0.05


def test_a_regional_search_expands_its_windows_in_larger_steps(campus, monkeypatch):
    """Steps of ``REGION_BATCH`` windows on a map of regions: the leaves of the smaller steps."""
    occ, loc = campus
    angles, ranges = _turned_scan(occ)
    query = loc.prepare_scan(ranges, angles[0], angles[1] - angles[0], 0.05, 30.0)
    search, calls = loc.grid.search, []

    def spy(points, **kw):
        calls.append((points, kw))
        return search(points, **kw)

    monkeypatch.setattr(loc.grid, 'search', spy)
    assert loc.search_hypotheses(query, loc.search_plan(query, []))
    (points, kw), = calls
    assert (kw['batch'], kw['hot_batches'], kw['region_ratio']) == (
        REGION_BATCH, REGION_HOT_BATCHES, REGION_RATIO)
    assert REGION_BATCH > 2048
    found = search(points, **kw)
    small = search(points, **dict(kw, batch=2048, hot_batches=4, budget_s=None))
    assert found.complete and small.complete
    assert np.array_equal(found.poses, small.poses) and np.array_equal(found.scores, small.scores)


def test_one_building_is_one_region_searched_as_before():
    bag = read_bag(BAGS / 'depot_sim')
    loc = GlobalLocalizer(build_index(bag.map))
    assert loc.regions.count == 1
    for scan in bag.scans[:6]:
        query = loc.prepare_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                 scan.range_min, scan.range_max)
        hyps = loc.correlate(query, loc.spectral_hypotheses(query))
        assert loc.to_refine(hyps) == hyps[:loc.config.refine_hypotheses]
        seeds = _by_correlation(hyps)
        plan = loc.search_plan(query, [h.initial_pose for h in seeds])
        assert np.array_equal(plan.yaws, loc.search_yaws(query, [h.initial_pose[2]
                                                                 for h in seeds]))
        assert plan.allowed.all()
        assert loc.weak_look(query, [], [(0.0, 0.0, 0.0)], [], [], StageClock()) is None


def test_leaves_and_refinement_keep_each_regions_best():
    poses = np.array([[0, 0, 0], [0.01, 0, 0], [5, 0, 0], [9, 0, 0], [20, 0, 0], [30, 0, 0.0]])
    same = (lambda a, b: abs(a[0] - b[0]) < 0.5)
    plain = CorrelativeResult(poses, np.linspace(1, 0.5, 6), True)
    assert pick_leaves(plain, 2, same) == [0, 2]
    regional = CorrelativeResult(poses, np.linspace(1, 0.5, 6), True,
                                 regions=np.array([0, 0, 0, 1, 1, 2]))
    assert pick_leaves(regional, 2, same) == [0, 2, 3, 4, 5]     # 4: another place
    assert pick_leaves(regional, 2, same, rivals=0) == [0, 2, 3, 5]
    # rivals: other places of one region, as many as asked for
    apart = CorrelativeResult(np.array([[10.0 * i, 0, 0] for i in range(6)]),
                              np.linspace(1, 0.5, 6), True, regions=np.zeros(6, int))
    assert pick_leaves(apart, 1, same) == [0, 1]
    assert pick_leaves(apart, 1, same, rivals=3) == [0, 1, 2, 3]

    class Regions:
        count = 3

        @staticmethod
        def region_of(xy):
            return np.asarray(xy)[:, 0].astype(int) // 10

    ranked = [(x, 0.0, 0.0) for x in (1, 2, 3, 12, 25, 14, 27)]
    assert with_region_bests(Regions, ranked, 2, lambda p: p) == ranked[:2] + [ranked[3],
                                                                               ranked[4]]
    Regions.count = 1
    assert with_region_bests(Regions, ranked, 2, lambda p: p) == ranked[:2]


def _twin_answer(seed_b: int, turned: bool = False, below: float = 1.0) -> tuple:
    """
    Return a scan in building A of a campus whose building B is A's twin (``seed_b`` 1) or not (2).

    With the localizer (``search_twins`` on, every ``ok`` answer below ``below`` checked), the
    query, the answer decided on A's place alone (as when the search kept only one of two
    twins) and its places. ``turned``: B is drawn turned by a half turn right beside A, so the
    map is one region (one building whose two halves look alike turned round).
    """
    data = np.full((400, 1300), -1, np.int8)
    _building(data, 2.0, 4.0, 0.0, 1)
    if turned:
        _building(data, 34.0, 16.0, math.pi, seed_b)        # x 18-34 m, y 4-16 m
    else:
        _building(data, 42.0, 4.0, 0.0, seed_b)
    occ = OccupancyMap(data, RES, (0.0, 0.0, 0.0))
    loc = GlobalLocalizer(build_index(occ), LocalizerConfig(search_twins=True,
                                                            search_twins_below=below))
    assert loc.regions.count == (1 if turned else 2)
    truth = (8.0, 7.0, 0.4)
    angles = beam_angles(360)
    ranges = cast_rays(occ.occupied_mask(), RES, occ.origin, np.array([truth]), angles,
                       30.0)[0]
    query = loc.prepare_scan(ranges, float(angles[0]), float(angles[1] - angles[0]), 0.0, 30.0)
    clock = StageClock()
    hyps = loc.correlate(query, [Hypothesis(source='search', initial_pose=truth)])
    verified, others = loc.examine(query, hyps, clock)
    answer = loc.decide(query, verified, clock, others=others)
    return loc, query, answer, verified, others, clock


def test_the_twin_check_finds_the_twin_the_first_search_missed():
    loc, query, answer, verified, others, clock = _twin_answer(1)
    assert answer.status == OK and abs(answer.pose[0] - 8.0) < 0.05      # one twin: unique
    checked = loc.twin_check(query, answer, verified, others, clock)
    assert checked.status != OK and 'distinct poses fit' in checked.message
    twins = [h for h in checked.candidates if h.check is not None
             and math.hypot(h.pose[0] - 48.0, h.pose[1] - 7.0) < 0.1]
    assert twins and abs(twins[0].score - answer.score) < 0.02
    off = dataclasses.replace(loc.config, search_twins=False)
    assert GlobalLocalizer(loc.index, off).twin_check(query, answer, verified, others,
                                                      clock) is answer


def test_the_twin_check_of_several_regions_skips_answers_above_its_confidence():
    loc, query, answer, verified, others, clock = _twin_answer(1, below=0.99)
    assert loc.regions.count == 2 and answer.status == OK
    # a simulated scan of a twin alone explains all of it: confident, so not checked
    assert answer.confidence >= 0.99
    assert loc.twin_check(query, answer, verified, others, clock) is answer
    # ... which the default (1.0: every ok answer) does check
    assert LocalizerConfig().search_twins_below == 1.0
    default = GlobalLocalizer(loc.index, dataclasses.replace(loc.config, search_twins_below=1.0))
    assert default.twin_check(query, answer, verified, others, clock).status != OK
    # ... but an answer the weak look found is checked whatever its confidence
    forced = loc.twin_check(query, answer, verified, others, clock, always=True)
    assert forced.status != OK and 'distinct poses fit' in forced.message
    at = dataclasses.replace(loc.config, search_twins_below=answer.confidence)   # at most: on
    assert GlobalLocalizer(loc.index, at).twin_check(query, answer, verified, others,
                                                     clock).status != OK
    lower = dataclasses.replace(loc.config, search_twins_below=answer.confidence + 1e-6)
    checked = GlobalLocalizer(loc.index, lower).twin_check(query, answer, verified, others, clock)
    assert checked.status != OK and 'distinct poses fit' in checked.message
    # the flip check of a map of one region does not ask the confidence
    loc1, query1, answer1, verified1, others1, clock1 = _twin_answer(1, turned=True, below=0.0)
    assert loc1.twin_check(query1, answer1, verified1, others1, clock1).status != OK


def test_a_search_keeps_no_leaf_below_the_floor_it_is_given():
    loc, query, answer, verified, others, clock = _twin_answer(1)
    yaw = loc.laser_pose(answer.pose)[2]
    plan = SearchPlan(np.array([yaw]), np.ones((1, loc.regions.count), bool), loc.regions.labels)
    found = loc.search_hypotheses(query, plan)
    assert len(found) >= 2                          # both twins
    best = max(h.correlative for h in found)
    assert loc.search_hypotheses(query, plan, min_score=min(best + 0.01, 1.0)) == []
    assert all(h.correlative >= 0.9 * best
               for h in loc.search_hypotheses(query, plan, min_score=0.9 * best))


def test_a_place_is_the_best_leaf_of_its_metre_at_its_yaw():
    poses = np.array([(0.9, 0.9, 0.0), (1.05, 0.92, 0.0), (5.0, 5.0, 0.0), (0.9, 0.9, math.pi),
                      (0.95, 0.1, 0.0), (2.5, 0.9, 0.0)])
    # best first: the second leaf lies across a square's edge from the first, the fifth in the
    # first's square (both the first's place), the fourth at another yaw, the last 1.6 m away
    assert place_leaves(poses, 1.0).tolist() == [0, 2, 3, 5]
    assert place_leaves(np.zeros((0, 3))).tolist() == []


def test_the_twin_check_ranks_its_places_by_a_quick_ray_check():
    for seed_b, twins in ((1, 1), (2, 0)):
        loc, query, answer, verified, others, clock = _twin_answer(seed_b)
        laser = loc.laser_pose(answer.pose)
        plan = SearchPlan(np.array([laser[2], laser[2] + math.pi]),
                          np.ones((2, loc.regions.count), bool), loc.regions.labels)
        places = loc.twin_places(query, answer, plan)
        # the twin building's room is one place; the other building's places score fairly on
        # the search's points but see through its walls, and are not kept
        assert len(places) == twins
        if twins:
            assert math.hypot(places[0].initial_pose[0] - 48.0,
                              places[0].initial_pose[1] - 7.0) < 0.1
            none = GlobalLocalizer(loc.index, dataclasses.replace(loc.config,
                                                                  search_twins_keep=0))
            assert none.twin_places(query, answer, plan) == []


def test_the_quick_check_casts_a_place_at_its_leaf_and_refined_once():
    loc, query, answer, verified, others, clock = _twin_answer(1)
    laser = loc.laser_pose(answer.pose)
    twin = np.array(laser) + (40.0, 0.0, 0.0)                # B's room, A's 40 m to the right
    off = twin + (0.08, -0.06, math.radians(1.5))            # a leaf further off than a coarse one
    own, quick, poses = loc.quick_checks(query, laser, np.array([twin, off]))
    assert quick[0] == pytest.approx(own, abs=0.05)          # the twin checks as the answer
    # cast at the leaf alone the room scores less; refined once it scores as the room does
    cfg = loc.config
    angles, measured = query.picked_beams(cfg.search_twins_beams, cfg.max_cast_range)
    at_leaf = loc._checks([tuple(off)], angles, measured, query.range_max)[0]
    assert at_leaf.consistent - cfg.contradiction_weight * at_leaf.contradicting < quick[1]
    assert quick[1] == pytest.approx(own, abs=0.05)
    assert math.hypot(*(poses[1][:2] - twin[:2])) < 0.03
    assert abs(wrap_angle(poses[1][2] - twin[2])) < math.radians(0.3)


def test_the_twin_check_keeps_a_unique_answer():
    loc, query, answer, verified, others, clock = _twin_answer(2)
    assert answer.status == OK
    checked = loc.twin_check(query, answer, verified, others, clock)
    assert checked.status == OK
    assert math.hypot(checked.pose[0] - 8.0, checked.pose[1] - 7.0) < 0.05


def test_the_flip_check_finds_the_half_turned_look_alike_on_a_map_of_one_region():
    loc, query, answer, verified, others, clock = _twin_answer(1, turned=True)
    assert answer.status == OK and abs(answer.pose[0] - 8.0) < 0.05
    checked = loc.twin_check(query, answer, verified, others, clock)
    assert checked.status != OK and 'distinct poses fit' in checked.message
    # A's (8, 7), (6, 3) from A's corner (2, 4), is (28, 13) in B, 3 m and 6 m from its
    # corner (34, 16) turned round; the yaw 0.4 plus a half turn
    twins = [h for h in checked.candidates if h.check is not None
             and math.hypot(h.pose[0] - 28.0, h.pose[1] - 13.0) < 0.1
             and abs(wrap_angle(h.pose[2] - (0.4 - math.pi))) < 0.02]
    assert twins and abs(twins[0].score - answer.score) < 0.02
    off = dataclasses.replace(loc.config, search_flips=False)
    assert GlobalLocalizer(loc.index, off).twin_check(query, answer, verified, others,
                                                      clock) is answer
    # the twin check of several regions is a separate choice
    campus_off = dataclasses.replace(loc.config, search_twins=False)
    assert GlobalLocalizer(loc.index, campus_off).twin_check(
        query, answer, verified, others, clock).status != OK


def test_the_flip_check_keeps_a_unique_answer_on_a_map_of_one_region():
    loc, query, answer, verified, others, clock = _twin_answer(2, turned=True)
    assert answer.status == OK
    checked = loc.twin_check(query, answer, verified, others, clock)
    assert checked.status == OK
    assert math.hypot(checked.pose[0] - 8.0, checked.pose[1] - 7.0) < 0.05
