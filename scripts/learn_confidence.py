#!/usr/bin/env python3
"""
Calibrate the confidence ``P(right | evidence)`` of the localizer's answers (logistic regression).

Labelled answers (``bench/places.py``) on the *calibration split* only -- the real buildings
Intel, ACES and FHW and the simulated depot and empty room; Freiburg 079, CSAIL, Edmonton and
the TurtleBot3 maps are the validation split, never looked at here:
- own scans: ``--own`` odd-numbered scans per building (random poses on the simulated maps),
  each through the five sensors of ``io/sensors.py`` (as recorded, 3.5 m and 12 m range, 90 and
  120 deg field of view); right when the pose lies within 0.5 m / 5 deg of the truth;
- foreign scans: ``--foreign`` scans of every other place of the split on each map, as recorded,
  at 3.5 m and at 120 deg; never right.
Every answer comes from the localizer with ``min_confidence`` 0, so that its status says whether
the rules alone accept the pose. The model is fitted on the answers the rules accept (those are
the ones it decides): a logistic regression of the evidence and boosted regression trees grown
from its score (``calibration.BOOSTING``, monotone in the evidence of ``MONOTONE``: a score that
can weigh one piece of evidence by another, which a regression alone cannot), then an isotonic
map of the score to a probability, fitted on scores cross-fitted by building (each building
scored by a model that did not see it). Foreign answers are weighted to make up
``--foreign-share`` of all answers (28 %: the share in ``bench localize --sensors ...
--foreign``'s protocol), so the probabilities
are calibrated for that mix. An answer the rules refuse reports the rate at which such answers
were right here (same weights), by reason. Prints the fit, a table of thresholds (precision of
the own answers, ``ok`` rate of the foreign ones) and the reliability of the fitted
probabilities; writes ``ssm_localization/config/confidence_model.json`` (package data, loaded as
``CONFIDENCE_MODEL``). Pick ``LocalizerConfig.min_confidence`` from the table.

``--tracker`` fits the tracker's model instead (``TRACK_CONFIDENCE_MODEL``, a logistic
regression written to ``config/track_confidence_model.yaml`` and copied into
``config/confidence.py``): the same evidence
plus how far the scan's own pose lies from the motion prediction, on tracked answers of the
calibration logs (Intel, ACES, FHW) through three sensors (as recorded, 3.5 m, 120 deg): the
odd-numbered scans in order with odometry, the two-kidnap sequence, 20 random single kidnaps,
20 slips the odometry misses (a verified track, then a scan 0.5-2.5 m on from the same stretch
of the log: a wrong prediction the track's own history vouches for), and tracks started from a
wrong prior (0.3-2.5 m and up to 20 deg off the truth, every 4th scan). The tracker runs with
both confidence thresholds at 0, so that a wrong track it would keep by its rules alone is kept
and labelled; its answers that the rules accept are fitted.

``--recalibrate ANSWERS.csv`` refits only the global model's last step, the map from its
probability to the fraction right, on the tuning split of a ``bench localize --answers`` run of
the model that ships (``recalibrate``; the shipped model was recalibrated so on 2026-12-08).

Usage::

    .venv/bin/python scripts/learn_confidence.py --data ../shared/data [--work bench_data]
    .venv/bin/python scripts/learn_confidence.py --data ../shared/data --tracker
    .venv/bin/python scripts/learn_confidence.py --recalibrate answers.csv
"""
from __future__ import annotations

import argparse
from collections import Counter
import csv
import dataclasses
import datetime
import json
from pathlib import Path
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ssm_localization.bench.data import data_dir, DATA_HELP  # noqa: E402
from ssm_localization.bench.places import (answers_on, foreign, load_place,  # noqa: E402
                                           real_map, REAL_PLACES)
from ssm_localization.config.confidence import CONFIDENCE_MODEL, REFUSED_REASONS  # noqa: E402
from ssm_localization.config.localization import LocalizerConfig  # noqa: E402
from ssm_localization.config.tracking import TrackerConfig  # noqa: E402
from ssm_localization.evaluation.calibration import (BOOSTING, compose_calibration,  # noqa: E402
                                                     fit_confidence, format_reliability,
                                                     isotonic_knots, recalibration_points,
                                                     reliability)
from ssm_localization.evaluation.replay import within_success  # noqa: E402
from ssm_localization.io.sensors import EVERYDAY_SENSORS  # noqa: E402
from ssm_localization.io.sequences import (KIDNAP_AFTER, KIDNAP_BEFORE,  # noqa: E402
                                           kidnap_sequence, log_sequence, splice_kidnaps)
from ssm_localization.localization.confidence import feature_values  # noqa: E402
from ssm_localization.localization.localizer import GlobalLocalizer  # noqa: E402
from ssm_localization.localization.tracker import TRACKED, Tracker  # noqa: E402
from ssm_localization.mapping.index import build_index  # noqa: E402
import yaml  # noqa: E402, I100

CALIBRATION = ('intel', 'aces', 'fhw', 'depot', 'empty_room')
TRACK_LOGS = ('intel', 'aces', 'fhw')
TRACK_SENSORS = ('full', 'range3.5', 'fov120')
#: the evidence both models weigh; 'hit' is left out (hit + through + short = 1 over the returns)
SHARED_FEATURES = ('through', 'short', 'missing', 'on_wall', 'unknown', 'unexplained_runs',
                   'explained', 'margin', 'log_position_std', 'log_yaw_std', 'log_scan_length',
                   'log_extent')
#: the global model's: how many distinct places score nearly as well, how much of the scan
#: returned at all, and how many returns were checked
FEATURES = SHARED_FEATURES + ('close_rivals', 'near_rivals', 'return_fraction', 'log_returns')
TRACK_FEATURES = SHARED_FEATURES + ('log_prior_distance', 'log_scan_position_std')
#: the direction in which each feature may move the global model's score (+1 up, -1 down; left
#: out: free): worse evidence never earns more trust, also far outside the calibration data
#: (``short`` is clutter in front of a right pose's walls as often as a wrong pose's; how much
#: of the scan returned depends on the place as much as on the pose)
MONOTONE = {'through': -1, 'missing': -1, 'on_wall': 1, 'unknown': -1, 'unexplained_runs': -1,
            'explained': 1, 'margin': 1, 'log_position_std': -1, 'log_yaw_std': -1,
            'log_scan_length': 1, 'log_extent': 1, 'close_rivals': -1, 'near_rivals': -1,
            'log_returns': 1}
DEFAULT_OUT = ROOT / 'ssm_localization' / 'config' / 'confidence_model.json'
DEFAULT_TRACK_OUT = ROOT / 'config' / 'track_confidence_model.yaml'
DEFAULT_CACHE = Path('bench_data') / 'confidence_answers.json'
DEFAULT_TRACK_CACHE = Path('bench_data') / 'track_confidence_answers.json'
FOREIGN_SENSORS = ('full', 'range3.5', 'fov120')
THRESHOLDS = (0.5, 0.7, 0.8, 0.85, 0.9, 0.93, 0.94, 0.95, 0.97, 0.98, 0.99)


def refusal(answer) -> str:
    """Return why the rules refused an answer (``min_confidence`` 0: every refusal is a rule's)."""
    if answer.status == 'failed':
        return 'implausible'
    return 'degenerate' if answer.message.startswith('degenerate') else 'rival'


@dataclasses.dataclass(frozen=True)
class Labelled:
    """What the fit needs of one answer (kept in ``--cache`` to refit without localizing)."""

    map: str                  # noqa: A003
    source: str
    sensor: str
    status: str
    message: str
    right: bool
    values: dict | None       # feature_values of its evidence; None: no pose

    @property
    def own(self) -> bool:
        return self.map == self.source

    @property
    def ok(self) -> bool:
        return self.status == 'ok'


def collect(args) -> list[Labelled]:
    """Localize the calibration split's answers (or read them from ``--cache``)."""
    if args.cache and args.cache.exists() and not args.fresh:
        cached = [Labelled(**d) for d in json.loads(args.cache.read_text())]
        need = set(TRACK_FEATURES if args.tracker else FEATURES)
        if all(a.values is None or need <= set(a.values) for a in cached):
            return cached
        print(f'{args.cache} lacks some features: localizing again', flush=True)
    if args.tracker:
        answers = track(args)
    else:
        answers = [Labelled(a.map, a.source, a.sensor, a.loc.status, a.loc.message, a.right,
                            feature_values(a.loc.evidence) if a.loc.evidence is not None
                            else None) for a in localize(args)]
    if args.cache:
        args.cache.parent.mkdir(parents=True, exist_ok=True)
        args.cache.write_text(json.dumps([dataclasses.asdict(a) for a in answers]))
    return answers


def track(args) -> list[Labelled]:
    """Return the tracked answers (mode ``tracked``) of the calibration logs, labelled."""
    config = TrackerConfig(min_confidence=0.0, lost_confidence=0.0)
    out: list[Labelled] = []

    def run(name, sensor, tracker, scans, odom, truth):
        limits = EVERYDAY_SENSORS[sensor]
        for scan, od, gt in zip(scans, odom, truth):
            res = tracker.track(limits.apply(scan), od, scan.stamp)
            if res.mode == TRACKED and res.evidence is not None:
                out.append(Labelled(name, name, sensor, res.status, res.message,
                                    within_success(res.pose, gt),
                                    feature_values(res.evidence)))

    for name in TRACK_LOGS:
        t0 = time.perf_counter()
        log, grid = real_map(args.data, args.work, REAL_PLACES[name])
        localizer = GlobalLocalizer(build_index(grid))
        real = log_sequence(log, name=name)
        rng = np.random.default_rng(args.seed)
        truth = np.array(real.truth)
        pairs = []
        while len(pairs) < 20:
            i, j = (int(v) for v in rng.integers(KIDNAP_BEFORE - 1, len(real) - KIDNAP_AFTER, 2))
            if np.hypot(*(truth[i, :2] - truth[j, :2])) >= 1.0:
                pairs.append((i, j))
        near = []                       # the odometry misses a slip of 0.5-2.5 m
        while len(near) < 20:
            i = int(rng.integers(KIDNAP_BEFORE - 1, len(real) - KIDNAP_AFTER - 8))
            for j in range(i + 1, min(i + 8, len(real) - KIDNAP_AFTER)):
                if 0.5 <= np.hypot(*(truth[i, :2] - truth[j, :2])) <= 2.5:
                    near.append((i, j))
                    break
        sequences = [real, kidnap_sequence(real), splice_kidnaps(real, pairs),
                     splice_kidnaps(real, near)]
        for sensor in TRACK_SENSORS:
            for seq in sequences:
                run(name, sensor, Tracker(localizer, config), seq.scans, seq.odom, seq.truth)
            for k in range(1, len(real), 4):          # a track started from a wrong prior
                dist, bearing = rng.uniform(0.3, 2.5), rng.uniform(-np.pi, np.pi)
                x, y, yaw = real.truth[k - 1]
                prior = (x + dist * np.cos(bearing), y + dist * np.sin(bearing),
                         yaw + rng.uniform(-0.35, 0.35))
                tracker = Tracker(localizer, config)
                tracker.set_prior(prior)
                run(name, sensor, tracker, real.scans[k - 1:k + 1], real.odom[k - 1:k + 1],
                    real.truth[k - 1:k + 1])
        print(f'{name}: {len(out)} tracked answers so far ({time.perf_counter() - t0:.0f} s)',
              flush=True)
    return out


def localize(args) -> list:
    places = {name: load_place(name, args.data, args.work,
                               args.own if name in REAL_PLACES else args.sim)
              for name in CALIBRATION}
    config = LocalizerConfig(min_confidence=0.0)
    answers = []
    for name in CALIBRATION:
        t0 = time.perf_counter()
        localizer = GlobalLocalizer(build_index(places[name].grid), config)
        answers += answers_on(localizer, name, places[name], tuple(EVERYDAY_SENSORS))
        for other in CALIBRATION:
            if foreign(name, other):
                answers += answers_on(localizer, name, places[other], FOREIGN_SENSORS,
                                      limit=args.foreign, seed=args.seed)
        print(f'{name}: {len(answers)} answers so far ({time.perf_counter() - t0:.0f} s)',
              flush=True)
    return answers


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--data', type=Path, default=None, help=DATA_HELP)
    ap.add_argument('--work', type=Path, default=Path('bench_data'))
    ap.add_argument('--own', type=int, default=150, help='own scans per real building')
    ap.add_argument('--sim', type=int, default=150, help='own scans per simulated map')
    ap.add_argument('--foreign', type=int, default=40, help='scans per ordered foreign pair')
    ap.add_argument('--l2', type=float, default=10.0)
    ap.add_argument('--foreign-share', type=float, default=0.28,
                    help='weight of the foreign answers as a share of all answers')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--out', type=Path, default=DEFAULT_OUT)
    ap.add_argument('--cache', type=Path, default=DEFAULT_CACHE,
                    help='labelled answers are kept here; a later run refits from them')
    ap.add_argument('--fresh', action='store_true', help='localize again even if cached')
    ap.add_argument('--tracker', action='store_true',
                    help="fit the tracker's model (TRACK_CONFIDENCE_MODEL) instead")
    ap.add_argument('--recalibrate', type=Path, metavar='ANSWERS_CSV',
                    help="refit only the shipped model's probabilities: an isotonic map of the "
                         'confidence the tuning split reported to the fraction right, from a '
                         '`bench localize --answers` file')
    args = ap.parse_args(argv)
    if args.recalibrate:
        return recalibrate(args)
    args.data = data_dir(args.data)
    if args.tracker:
        return fit_tracker(args)
    answers = collect(args)
    n_foreign = sum(not a.own for a in answers)
    w_foreign = args.foreign_share / (1.0 - args.foreign_share) * \
        (len(answers) - n_foreign) / max(n_foreign, 1)
    weight = {id(a): 1.0 if a.own else w_foreign for a in answers}
    print(f'{len(answers)} answers, {n_foreign} foreign (weight {w_foreign:.3f} each)')
    with_pose = [a for a in answers if a.values is not None]
    accepted = [a for a in with_pose if a.ok]
    refused: dict[str, float] = {}
    for reason in REFUSED_REASONS:
        these = [a for a in with_pose if not a.ok and refusal(a) == reason]
        total = sum(weight[id(a)] for a in these)
        refused[reason] = round(sum(weight[id(a)] * a.right for a in these) / total, 4) \
            if these else 0.0
        print(f'refused ({reason}): {len(these)} answers, right {refused[reason]:.3f}')
    values = [a.values for a in accepted]
    labels = [a.right for a in accepted]
    model = fit_confidence(values, labels, FEATURES, groups=[a.map for a in accepted],
                           weight=[weight[id(a)] for a in accepted], refused=refused,
                           split='calibration: ' + ', '.join(CALIBRATION),
                           boosted=dict(BOOSTING, monotone=[MONOTONE.get(f, 0) for f in FEATURES]))
    p = np.array([model.probability(v) for v in values])
    print(f'{len(accepted)} answers the rules accept ({sum(labels)} right); {len(model.trees)} '
          f'trees (isotonic map: {len(model.calibration)} knots); splits per feature:')
    splits = Counter(model.features[n[0]] for t in model.trees for n in t if n[0] >= 0)
    for name in model.features:
        print(f'  {name:18s} {splits[name]}')
    real_own = np.array([a.own and a.map in REAL_PLACES for a in accepted])
    own_full = [a for a in answers if a.own and a.map in REAL_PLACES and a.sensor == 'full']
    n_foreign = Counter(a.sensor for a in answers if not a.own)
    print('threshold | own real (all sensors): ok, wrong ok, precision | own real full scans: '
          'success | foreign: ok rate by sensor')
    index = {id(a): k for k, a in enumerate(accepted)}
    for t in THRESHOLDS:
        ok = p >= t
        own_ok = ok & real_own
        wrong = int(np.sum(own_ok & ~np.array(labels)))
        succ = sum(a.right and id(a) in index and p[index[id(a)]] >= t for a in own_full)
        fok = Counter(a.sensor for a, k in zip(accepted, ok) if k and not a.own)
        rates = ', '.join(f'{s} {fok[s] / max(n_foreign[s], 1):.2%}' for s in FOREIGN_SENSORS)
        print(f'  {t:.2f} | {int(own_ok.sum())}, {wrong}, '
              f'{1 - wrong / max(int(own_ok.sum()), 1):.4f} | '
              f'{succ / max(len(own_full), 1):.3f} | {rates}')
    for t in (0.85, 0.9, 0.94, 0.95):
        per = []
        for b in sorted({a.map for a in own_full}):
            mine = [a for a in own_full if a.map == b]
            got = sum(a.right and id(a) in index and p[index[id(a)]] >= t for a in mine)
            per.append(f'{b} {got}/{len(mine)}')
        print(f'  own full scans right and ok at {t}: ' + ', '.join(per))
    print('reliability of the fitted probabilities (answers the rules accept):')
    print(format_reliability(reliability(p, labels)))
    print('(in-sample; bench localize --foreign --reliability measures it on the validation '
          'split)')
    write_model(args, model, len(accepted), sum(labels))
    return 0


def fit_tracker(args) -> int:
    """Fit, print and write the tracker's model (see the module doc)."""
    if args.cache == DEFAULT_CACHE:
        args.cache = DEFAULT_TRACK_CACHE
    if args.out == DEFAULT_OUT:
        args.out = DEFAULT_TRACK_OUT
    answers = collect(args)
    accepted = [a for a in answers if a.ok]
    labels = [a.right for a in accepted]
    model = fit_confidence([a.values for a in accepted], labels, TRACK_FEATURES,
                           groups=[a.map for a in accepted], l2=args.l2,
                           split='tracker calibration: ' + ', '.join(TRACK_LOGS))
    p = np.array([model.probability(a.values) for a in accepted])
    print(f'{len(answers)} tracked answers, {len(accepted)} the rules accept '
          f'({sum(labels)} right); weights on standardised features '
          f'(isotonic map: {len(model.calibration)} knots):')
    for name, w in zip(model.features, model.weights):
        print(f'  {name:18s} {w:+.3f}')
    print('threshold | by sensor: ok, wrong ok, precision, success (right and ok / all tracked)')
    for t in THRESHOLDS:
        parts = []
        for sensor in TRACK_SENSORS:
            mine = [k for k, a in enumerate(accepted) if a.sensor == sensor]
            ok = [k for k in mine if p[k] >= t]
            wrong = sum(not labels[k] for k in ok)
            total = sum(a.sensor == sensor for a in answers)
            parts.append(f'{sensor} {len(ok)}, {wrong}, {1 - wrong / max(len(ok), 1):.4f}, '
                         f'{(len(ok) - wrong) / max(total, 1):.3f}')
        print(f'  {t:.2f} | ' + ' | '.join(parts))
    write_model(args, model, len(accepted), sum(labels))
    print('TRACK_CONFIDENCE_MODEL = ' + repr(model))
    return 0


def recalibrate(args) -> int:
    """
    Compose the shipped model's isotonic map with one fitted on a benchmark's tuning split.

    The pipeline around the model keeps improving after a fit (second looks, twin and flip
    checks): answers that reach the same evidence are then right more often than when the model
    was fitted, and its probabilities grow cautious. This refits only the last step, the map
    from the reported confidence to the fraction right, on the answers of ``bench localize
    --answers`` that the model decided (``decided_by`` ``confidence``) on the *tuning* split;
    the validation split is only printed. The composed map orders answers as before, so the
    thresholds of ``LocalizerConfig`` carry over as ``new = map(old)`` (printed). With it, the
    cap of a pair of look-alikes (``ConfidenceModel.pair``): the rate at which the tuning
    split's answers refused for one distinct rival were right where the recalibrated model
    says more than 2/3.
    """
    with open(args.recalibrate, newline='', encoding='utf-8') as f:
        every = list(csv.DictReader(f))
    rows = [r for r in every if r['decided_by'] == 'confidence']
    split = {name: [(float(r['confidence']), r['right'] == '1') for r in rows
                    if r['split'] == name] for name in ('tuning', 'validation')}
    if not split['tuning']:
        raise SystemExit(f'{args.recalibrate}: no tuning-split answers decided by the model')
    old = CONFIDENCE_MODEL
    agree = np.mean([abs(old.probability({f: float(r[f]) for f in old.features})
                         - float(r['confidence'])) < 1e-3 for r in rows])
    if agree < 0.9:                 # a few differ: rounded features at a tree's split
        raise SystemExit(f'{args.recalibrate}: only {agree:.0%} of its confidences are the '
                         f"shipped model's; recalibrate from a run of the model that ships")
    conf = np.array([c for c, _ in split['tuning']])
    right = np.array([y for _, y in split['tuning']], dtype=float)
    outer = isotonic_knots(conf, right)
    model = dataclasses.replace(old, calibration=compose_calibration(old.calibration, outer))
    # the best of a pair of look-alikes: how often right where the model says more than 2/3
    pairs = [r for r in every if r['split'] == 'tuning' and r['decided_by'] == 'rival'
             and r['look_alikes'] == '2'
             and model.probability({f: float(r[f]) for f in model.features}) > 2.0 / 3.0]
    if pairs:
        model = dataclasses.replace(model, pair=round(float(np.mean(
            [r['right'] == '1' for r in pairs])), 4))
    print(f'pairs of look-alikes the model puts above 2/3 on the tuning split: {len(pairs)}, '
          f'the best right {model.pair:.3f} of the time (ConfidenceModel.pair)')
    xs, qs = recalibration_points(outer)

    def new(c: float) -> float:
        return float(np.interp(c, xs, qs))

    print(f'{len(conf)} tuning answers decided by the model ({int(right.sum())} right); '
          f'the map of their confidence to the fraction right ({len(outer)} knots):')
    for c, q in outer:
        print(f'  {c:.4f} -> {q:.4f}')
    for name, answers in split.items():
        print(f'{name} split ({len(answers)} answers): before')
        print(format_reliability(reliability([c for c, _ in answers], [y for _, y in answers])))
        print(f'{name} split: after')
        print(format_reliability(reliability([new(c) for c, _ in answers],
                                             [y for _, y in answers])))
    print('threshold then -> now | by split: ok, wrong ok')
    for t in THRESHOLDS:
        parts = [f'{name} {sum(c >= t for c, _ in a)}, {sum(c >= t and not y for c, y in a)}'
                 for name, a in split.items()]
        print(f'  {t:.2f} -> {new(t):.4f} | ' + ' | '.join(parts))
    doc = json.loads(Path(DEFAULT_OUT).read_text())
    doc['model'] = json.loads(json.dumps(dataclasses.asdict(model)))
    doc['recalibrated'] = {'by': 'scripts/learn_confidence.py --recalibrate',
                           'date': datetime.date.today().isoformat(),
                           'answers': int(len(conf)), 'right': int(right.sum()),
                           'outer': [list(k) for k in outer],
                           'fitted': [list(k) for k in old.calibration]}
    args.out.write_text(json.dumps(doc, indent=None, separators=(',', ':')) + '\n')
    print(f'wrote {args.out}')
    return 0


def write_model(args, model, answers: int, right: int) -> None:
    """Write the model to ``--out``: JSON (the global model, package data) or YAML (safe_dump)."""
    doc = {'fitted_by': 'scripts/learn_confidence.py' + (' --tracker' if args.tracker else ''),
           'date': datetime.date.today().isoformat(), 'answers': answers, 'right': int(right),
           'model': json.loads(json.dumps(dataclasses.asdict(model)))}
    if not model.trees:
        del doc['model']['trees']
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if args.out.suffix == '.json':
        args.out.write_text(json.dumps(doc, indent=None, separators=(',', ':')) + '\n')
    else:
        header = '# The confidence model P(right | evidence); see scripts/learn_confidence.py\n'
        args.out.write_text(header + yaml.safe_dump(doc, sort_keys=False))
    print(f'wrote {args.out}')


if __name__ == '__main__':
    sys.exit(main())
