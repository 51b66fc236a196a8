"""
The evidence of an answer and its calibrated confidence (localization/evidence.py, confidence.py).

The features on hand-built scans, the beam counts, the fit and the reliability bins, the model
shipped against the files they were written to, and the verdicts a right pose, a wrong one and a
scan of another building must get.
"""
from __future__ import annotations

import dataclasses
import json
import math

from helpers import BAGS, REPO
import numpy as np
import pytest
from ssm_localization import build_index, GlobalLocalizer, read_bag
from ssm_localization.config.confidence import (CONFIDENCE_MODEL, ConfidenceModel, load_model,
                                                TRACK_CONFIDENCE_MODEL)
from ssm_localization.config.localization import LocalizerConfig
from ssm_localization.evaluation.calibration import (BOOSTING, compose_calibration,
                                                     fit_confidence, isotonic_knots,
                                                     recalibration_points, reliability,
                                                     tree_values)
from ssm_localization.files.yaml_input import load_yaml_file
from ssm_localization.localization.confidence import (feature_values, resolution_warning,
                                                      within_circle, within_right)
from ssm_localization.localization.evidence import Evidence, rival_counts, unexplained_runs
from ssm_localization.localization.verify import check_beams
from ssm_localization.mapping.map_io import OccupancyMap


# --------------------------------------------------------------------------- features

def _wall(x0: float, x1: float, step: float = 0.05) -> np.ndarray:
    x = np.arange(x0, x1 + 1e-9, step)
    return np.column_stack((x, np.full_like(x, 2.0)))


def test_unexplained_runs_count_long_stretches_only():
    pts = _wall(0.0, 10.0)                          # 10 m of wall in sweep order
    off = np.zeros(len(pts), bool)
    assert unexplained_runs(pts, off) == (0.0, pytest.approx(10.0))
    off[(pts[:, 0] > 2.0) & (pts[:, 0] < 2.5)] = True         # a person: 0.4 m, not counted
    assert unexplained_runs(pts, off)[0] == 0.0
    off[(pts[:, 0] > 5.0) & (pts[:, 0] < 8.0)] = True         # an unmapped wall: 2.9 m
    fraction, length = unexplained_runs(pts, off)
    assert fraction == pytest.approx(2.9 / 10.0, abs=0.01) and length == pytest.approx(10.0)


def test_unexplained_runs_do_not_bridge_gaps():
    """Two unexplained stretches of 0.8 m across a 3 m gap are two short ones, not one long."""
    pts = np.vstack((_wall(0.0, 0.8), _wall(3.8, 4.6)))
    fraction, length = unexplained_runs(pts, np.ones(len(pts), bool))
    assert fraction == 0.0 and length == pytest.approx(1.6)


def test_beam_counts():
    inf = np.inf
    expected = np.array([2.0, 2.0, 2.0, 2.0, 2.0, inf, inf, 20.0])
    measured = np.array([2.05, 3.0, 1.0, inf, 2.0, 5.0, inf, inf])
    c = check_beams(measured, expected, tol=0.15, range_limit=10.0)
    assert (c.beams, c.returns, c.hits, c.through, c.shorts) == (8, 5, 2, 2, 1)
    # no return where the map has a wall: 2 m is within 90 % of the 10 m range, 20 m is not
    assert c.missing == 1
    assert c.consistent == pytest.approx(3 / 8) and c.contradicting == pytest.approx(2 / 8)


def _evidence(**kw) -> Evidence:
    base = {'hit': 0.95, 'through': 0.02, 'short': 0.03, 'missing': 0.0, 'on_wall': 0.97,
            'unknown': 0.01, 'unexplained_runs': 0.0, 'explained': 0.9, 'margin': 0.6,
            'position_std': 0.05, 'yaw_std': 0.01, 'returns': 120, 'scan_length': 25.0,
            'extent': 8.0}
    base.update(kw)
    return Evidence(**base)


@pytest.mark.parametrize('change', [
    {'hit': 0.6, 'through': 0.3}, {'margin': 0.02}, {'unexplained_runs': 0.3},
    {'explained': 0.6}, {'scan_length': 3.0, 'extent': 1.5, 'returns': 40},
])
def test_the_shipped_model_trusts_less_whatever_the_evidence_loses(change):
    """Every kind of worse evidence lowers the confidence (the weights have the right signs)."""
    good = CONFIDENCE_MODEL.probability(feature_values(_evidence()))
    worse = CONFIDENCE_MODEL.probability(feature_values(_evidence(**change)))
    assert worse < good, change


# --------------------------------------------------------------------------- calibration

def test_fit_recovers_a_known_logistic_model_and_its_probabilities_are_calibrated():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4000, 2))
    p = 1.0 / (1.0 + np.exp(-(0.5 + 2.0 * x[:, 0] - 1.0 * x[:, 1])))
    y = rng.random(4000) < p
    groups = [f'building {k % 4}' for k in range(4000)]
    model = fit_confidence([{'a': a, 'b': b} for a, b in x], y, ('a', 'b'), groups, l2=1e-3)
    w = np.array(model.weights) / np.array(model.scale)
    assert w == pytest.approx([2.0, -1.0], rel=0.15)
    # the isotonic map is monotone and close to the logistic curve it stands for
    knots = np.array(model.calibration)
    assert len(knots) >= 5 and np.all(np.diff(knots, axis=0) >= 0)
    logistic = 1.0 / (1.0 + np.exp(-knots[:, 0]))
    assert np.abs(knots[:, 1] - logistic).max() < 0.15
    probs = [model.probability({'a': a, 'b': b}) for a, b in x]
    for b in reliability(probs, y):
        if b.count >= 100:        # within three binomial standard deviations
            sigma = math.sqrt(b.mean_confidence * (1 - b.mean_confidence) / b.count)
            assert abs(b.gap) < 3 * sigma + 0.01, b


def test_isotonic_knots_pool_violators_and_never_say_certain():
    z = np.arange(10.0)
    y = np.array([0, 0, 1, 0, 0, 1, 1, 1, 1, 1], bool)        # one violator pair at 2-4
    knots = isotonic_knots(z, y, min_weight=1.0)
    probs = [p for _, p in knots]
    assert probs == sorted(probs) and 0.0 < probs[0] and probs[-1] < 1.0
    assert knots[1] == pytest.approx((3.0, (1 + 0.5) / (3 + 1)))       # 2, 3, 4 pooled
    # light blocks are merged into a neighbour
    assert all(b >= 0 for b in np.diff([k for k, _ in isotonic_knots(z, y, min_weight=4.0)]))
    assert len(isotonic_knots(z, y, min_weight=4.0)) < len(knots)


def test_calibrated_probability_interpolates_the_knots():
    model = dataclasses.replace(CONFIDENCE_MODEL, calibration=((-1.0, 0.1), (1.0, 0.9)))
    assert model.calibrated(-5.0) == 0.1 and model.calibrated(5.0) == 0.9
    assert model.calibrated(0.0) == pytest.approx(0.5)
    assert dataclasses.replace(model, calibration=()).calibrated(0.0) == 0.5
    with pytest.raises(ValueError, match='knots'):
        dataclasses.replace(model, calibration=((1.0, 0.9), (-1.0, 0.1)))


def test_a_recalibration_composes_exactly_and_keeps_the_order():
    """compose_calibration: the model's map, then a map of its probability to the right rate."""
    inner = ((-2.0, 0.1), (0.0, 0.5), (1.0, 0.5), (3.0, 0.95))        # with a flat stretch
    outer = ((0.2, 0.1), (0.6, 0.8), (0.9, 0.99))
    composed = dataclasses.replace(CONFIDENCE_MODEL,
                                   calibration=compose_calibration(inner, outer))
    old = dataclasses.replace(CONFIDENCE_MODEL, calibration=inner)
    xs, qs = recalibration_points(outer)
    assert xs[0] == 0.0 and xs[-1] == 1.0 and np.all(np.diff(qs) > 0)
    z = np.linspace(-4.0, 5.0, 301)
    new = np.array([composed.calibrated(v) for v in z])
    assert new == pytest.approx(np.interp([old.calibrated(v) for v in z], xs, qs))
    assert np.all(np.diff(new) >= 0)
    # strictly increasing wherever the old map is: a threshold carries over exactly
    rising = np.diff([old.calibrated(v) for v in z]) > 0
    assert np.all(np.diff(new)[rising] > 0)
    t = 0.7
    assert all((old.calibrated(v) >= t) == (composed.calibrated(v) >= np.interp(t, xs, qs))
               for v in z)
    with pytest.raises(ValueError, match='no isotonic map'):
        compose_calibration((), outer)


def test_the_shipped_recalibration_is_recorded_and_reproduced():
    """The shipped map is the fitted one composed with the recorded recalibration."""
    doc = json.loads((REPO / 'ssm_localization' / 'config' / 'confidence_model.json').read_text())
    again = doc['recalibrated']
    assert again['answers'] > 1000 and 0 < again['right'] <= again['answers']
    outer = [tuple(k) for k in again['outer']]
    fitted = tuple(tuple(k) for k in again['fitted'])
    assert np.array(compose_calibration(fitted, outer)) == pytest.approx(
        np.array(CONFIDENCE_MODEL.calibration))
    with pytest.raises(ValueError, match='pair'):
        dataclasses.replace(CONFIDENCE_MODEL, pair=1.5)
    # ok is no looser than before the recalibration: min_confidence on the fitted map's scale
    xs, qs = recalibration_points(outer)
    assert np.interp(LocalizerConfig().min_confidence, qs, xs) >= 0.93


def test_within_right_is_the_gaussian_mass_inside_the_success_bounds():
    assert within_right(np.diag([1e-6, 1e-6, 1e-8])) == pytest.approx(1.0)
    # isotropic 0.5 m: 1 - exp(-1/2) in position, yaw certain
    assert within_right(np.diag([0.25, 0.25, 1e-8])) == pytest.approx(1 - math.exp(-0.5))
    # yaw std 5 deg: erf(1 / sqrt 2) = 0.6827
    assert within_right(np.diag([1e-6, 1e-6, math.radians(5.0) ** 2])) == \
        pytest.approx(0.6827, abs=1e-4)
    grown = [within_right(np.diag([s ** 2, s ** 2, (s / 5) ** 2])) for s in (0.05, 0.2, 0.5, 2.0)]
    assert grown == sorted(grown, reverse=True) and grown[-1] < 0.05


def test_within_circle_is_exact_for_elongated_errors():
    """The 2-D Gaussian's mass in the circle, against Monte Carlo, whatever its axis ratio."""
    rng = np.random.default_rng(3)
    for cov in (np.diag([0.01, 0.5]), np.array([[0.1, 0.08], [0.08, 0.1]]),
                np.diag([1e-6, 1.0])):
        e = rng.multivariate_normal([0.0, 0.0], cov, 200_000)
        assert within_circle(cov, 0.5) == pytest.approx(np.mean(np.hypot(*e.T) <= 0.5),
                                                        abs=0.004)
    # a corridor's error (long along the axis) keeps more mass than the isotropic bound says
    corridor = np.diag([0.3 ** 2, 0.02 ** 2, 1e-8])
    assert within_right(corridor) > 1 - math.exp(-0.5 ** 2 / (2 * 0.3 ** 2)) + 0.05


def test_reliability_bins():
    bins = reliability([0.05, 0.05, 0.95, 0.999, 1.0], [False, True, True, True, True])
    assert [b.count for b in bins if b.count] == [2, 1, 2]
    assert bins[0].observed == 0.5 and bins[-1].observed == 1.0 and bins[-1].high == 1.0
    assert math.isnan(bins[3].observed)


def test_a_bins_interval_tells_chance_from_miscalibration():
    """Wilson's interval: 40 of 50 right is consistent with 0.75 reported, not with 0.6 or 0.9."""
    from ssm_localization.evaluation.calibration import format_reliability, ReliabilityBin
    fair = ReliabilityBin(0.7, 0.8, 50, 0.75, 40)
    low, high = fair.interval()
    assert low == pytest.approx(0.6696, abs=1e-3) and high == pytest.approx(0.8876, abs=1e-3)
    assert not fair.beyond_chance
    assert ReliabilityBin(0.6, 0.7, 50, 0.6, 40).beyond_chance
    assert ReliabilityBin(0.9, 0.99, 50, 0.95, 40).beyond_chance
    assert ReliabilityBin(0.99, 1.0, 400, 0.998, 400).interval()[1] == 1.0
    table = format_reliability([fair, ReliabilityBin(0.9, 0.99, 50, 0.95, 40)])
    assert 'OFF by more than 2 points, within chance' in table
    assert 'OFF by more than 2 points, beyond chance' in table and '0.670-0.888' in table


def test_model_needs_consistent_fields():
    with pytest.raises(ValueError, match='2 features'):
        ConfidenceModel(('a', 'b'), (0.0,), (1.0,), (1.0,), 0.0)
    with pytest.raises(ValueError, match='scales > 0'):
        ConfidenceModel(('a',), (0.0,), (0.0,), (1.0,), 0.0)
    with pytest.raises(ValueError, match='refused'):
        ConfidenceModel(('a',), (0.0,), (1.0,), (1.0,), 0.0, refused={'rival': 2.0})


def test_the_tracker_model_is_the_calibrated_one():
    """The tracker's model is config/track_confidence_model.yaml, by learn_confidence --tracker."""
    doc = load_yaml_file(REPO / 'config' / 'track_confidence_model.yaml', 'confidence model')
    fitted = ConfidenceModel.from_dict(doc['model'])
    assert fitted.features == TRACK_CONFIDENCE_MODEL.features
    for key in ('mean', 'scale', 'weights', 'calibration'):
        assert np.array(getattr(fitted, key)) == pytest.approx(
            np.array(getattr(TRACK_CONFIDENCE_MODEL, key)), rel=1e-9)
    assert fitted.intercept == pytest.approx(TRACK_CONFIDENCE_MODEL.intercept, rel=1e-9)
    assert fitted.refused == TRACK_CONFIDENCE_MODEL.refused and not fitted.trees


def test_the_global_model_is_package_data_of_boosted_trees():
    """CONFIDENCE_MODEL is confidence_model.json beside config/confidence.py, installed with it."""
    path = REPO / 'ssm_localization' / 'config' / 'confidence_model.json'
    assert load_model(path) == CONFIDENCE_MODEL
    assert CONFIDENCE_MODEL.trees and CONFIDENCE_MODEL.weights      # a regression and trees
    assert 'calibration' in CONFIDENCE_MODEL.split
    setup = (REPO / 'setup.py').read_text()
    assert "package_data={'ssm_localization.config': ['*.json']}" in setup
    # every feature the trees split on is one feature_values makes
    made = feature_values(_evidence())
    assert {CONFIDENCE_MODEL.features[n[0]] for t in CONFIDENCE_MODEL.trees for n in t
            if n[0] >= 0} <= set(made)


def test_trees_are_evaluated_as_written():
    tree = ((0, 0.5, 1, 2, 0.0), (-1, 0.0, -1, -1, -1.0), (1, 2.0, 3, 4, 0.0),
            (-1, 0.0, -1, -1, 0.5), (-1, 0.0, -1, -1, 2.0))
    model = ConfidenceModel(('a', 'b'), (), (), (), 0.25, trees=(tree, tree))
    assert model.logit({'a': 0.5, 'b': 9.0}) == pytest.approx(0.25 - 2.0)      # a <= 0.5: left
    assert model.logit({'a': 0.6, 'b': 2.0}) == pytest.approx(0.25 + 1.0)
    assert model.logit({'a': 0.6, 'b': 2.1}) == pytest.approx(0.25 + 4.0)
    assert tree_values(tree, np.array([[0.5, 9.0], [0.6, 2.0], [0.6, 2.1]])) == \
        pytest.approx([-1.0, 0.5, 2.0])
    doc = json.loads(json.dumps(dataclasses.asdict(model)))
    assert ConfidenceModel.from_dict(doc) == model
    for bad in (((0, 0.5, 0, 2, 0.0), (-1, 0.0, -1, -1, 1.0)),      # a child before its parent
                ((5, 0.5, 1, 1, 0.0), (-1, 0.0, -1, -1, 1.0)),      # no feature 5
                ((-1, 0.0, -1, -1, math.nan),)):
        with pytest.raises(ValueError, match='tree|finite'):
            ConfidenceModel(('a', 'b'), (), (), (), 0.0, trees=(bad,))


def test_boosted_trees_weigh_one_feature_by_another():
    """Right when two features agree in sign: no linear score can tell, boosted trees can."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-1.0, 1.0, (2000, 2))
    right = x[:, 0] * x[:, 1] > 0
    values = [{'a': a, 'b': b} for a, b in x]
    groups = [f'building {k % 3}' for k in range(len(x))]
    boosted = fit_confidence(values, right, ('a', 'b'), groups, boosted=BOOSTING)
    linear = fit_confidence(values, right, ('a', 'b'), groups)
    for model, least, most in ((boosted, 0.95, 1.0), (linear, 0.0, 0.6)):
        p = np.array([model.probability(v) for v in values])
        assert least <= np.mean((p >= 0.5) == right) <= most
    assert boosted.trees and not linear.trees


def test_rivals_are_counted_by_their_lead():
    assert rival_counts(0.8, []) == (pytest.approx(0.8), 0, 0)
    assert rival_counts(0.8, [0.77, 0.72, 0.5]) == (pytest.approx(0.03), 1, 2)
    assert rival_counts(0.8, [0.9]) == (pytest.approx(-0.1), 1, 1)


# --------------------------------------------------------------------------- verdicts

@pytest.fixture(scope='module')
def depot():
    bag = read_bag(BAGS / 'depot_sim')
    return bag, GlobalLocalizer(build_index(bag.map))


def test_a_right_pose_is_ok_with_a_high_confidence(depot):
    bag, loc = depot
    for scan in bag.scans[:3]:
        out = loc.localize_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                scan.range_min, scan.range_max)
        truth = bag.ground_truth_of(scan)
        assert out.status == 'ok', out.message
        assert math.hypot(out.pose[0] - truth[0], out.pose[1] - truth[1]) < 0.05
        assert out.confidence >= loc.config.min_confidence
        assert f'confidence {out.confidence:.3f}' in out.message
        assert out.evidence.hit > 0.9 and out.evidence.margin > 0.1


def test_a_wrong_pose_has_the_evidence_against_it(depot):
    """The same scan judged 1.5 m and 20 deg off its pose: beams through walls, no trust."""
    bag, loc = depot
    scan = bag.scans[0]
    query = loc.prepare_scan(scan.ranges, scan.angle_min, scan.angle_increment, scan.range_min,
                             scan.range_max)
    right = loc.localize_query(query)
    best = next(h for h in right.candidates if h.check is not None)
    x, y, yaw = best.laser_pose
    moved = dataclasses.replace(best, laser_pose=(x + 1.5, y, yaw + math.radians(20.0)),
                                check=None)
    wrong = loc.verify(query, [moved])[0]
    assert moved.check is None and wrong.check is not None        # a value: verify returns it
    ev = loc.evidence(query, wrong, rivals=[best.score])
    p = CONFIDENCE_MODEL.probability(feature_values(ev))
    assert ev.margin < 0 and ev.hit < 0.5 and ev.through > 0.2
    assert p < 0.5 < right.confidence


def _rooms() -> OccupancyMap:
    """Return a floor of offices unlike the Intel lab: rooms 6 m x 5 m, a table in each."""
    res = 0.05
    d = np.zeros((200, 300), np.int8)
    d[[0, -1], :] = 100
    d[:, [0, -1]] = 100
    for r0 in range(0, 200, 100):
        for c0 in range(0, 300, 120):
            d[r0:r0 + 100, c0] = 100
            d[r0 + 100 - 1, c0:c0 + 120] = 100
            d[r0 + 40:r0 + 60, c0] = 0                                          # door
            d[r0 + 40:r0 + 50, c0 + 40:c0 + 70] = 100                           # table
    return OccupancyMap(d, res)


def test_a_scan_of_another_building_is_refused_for_lack_of_evidence():
    loc = GlobalLocalizer(build_index(_rooms()))
    bag = read_bag(BAGS / 'intel_queries')
    for scan in bag.scans[:8]:
        out = loc.localize_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                scan.range_min, scan.range_max)
        assert out.status != 'ok', out.message
        assert out.confidence < loc.config.min_confidence


def test_a_map_of_coarser_cells_than_the_calibration_buildings_gets_a_warning():
    for res in (0.05, 0.05000001, 0.025, 0.01):
        assert resolution_warning(res) == ''
    for res in (0.06, 0.1, 0.2):
        note = resolution_warning(res)
        assert f'{res:g} m' in note and 'coarser than the 0.05 m' in note
    for res, warned in ((0.05, False), (0.1, True)):
        n = int(round(3.0 / res))                   # a 3 m room with a table
        d = np.zeros((n, n), np.int8)
        d[:2, :] = d[-2:, :] = d[:, :2] = d[:, -2:] = 100
        d[n // 4:n // 3, n // 5:n // 2] = 100
        loc = GlobalLocalizer(build_index(OccupancyMap(d, res)))
        assert bool(loc.calibration_warning) == warned
