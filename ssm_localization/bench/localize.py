"""
``ssm_localization bench localize``: global localization figures per data set.

Data sets (``--sets``):
- ``depot``, ``tb3_sandbox``, ``turtlebot3_world``: the paper protocol (section V.B): random poses
  in free space, 360 beams over 360 deg, range noise sigma 10 mm;
- ``depot_clutter``: 8 unmapped discs near the robot and 5 % random short ranges;
- ``depot_fov180``: a 180 deg field of view;
- ``intel``, ``aces``, ``fr079``, ``csail``, ``fhw``, ``edmonton``: real scans; the map is built
  from the even-numbered scans of the CARMEN log, the queries are the odd-numbered scans (ground
  truth: the corrected poses);
- ``intel_clutter``, ``aces_clutter``, ``fr079_clutter`` (``all``): simulated scans with clutter
  on those real-built maps;
- ``campus`` (``--campus``): the six real buildings and three simulated maps on one 27.6 M-cell
  grid (``bench/campus.py``), ``--campus-n`` queries of each building (its odd-numbered scans /
  random poses), one line per building and the campus pooled; ``office_30m`` (``--campus``):
  the synthetic office grown to 30 M cells, ``-n`` random poses; ``outdoor_30m`` (``--campus``):
  a synthetic campus with outdoor parts, 29 M cells, ``-n`` random poses with clutter (people,
  moved cars: eight unmapped discs near the robot and 5 % short readings, as ``*_clutter``).
Every set runs with the same defaults (no per-set parameter). The ``TUNING_SETS`` are those the
defaults were chosen on (the localizer's: depot and its variants, Intel, ACES) or the confidence
was calibrated on (Intel, ACES, FHW, depot, the empty room); every other set is a validation set
that was only measured. Each line says which split its set belongs to, and the run ends with
both splits pooled.

Prints per set: counts of ok / ambiguous / failed, success (ok and within 0.5 m / 5 deg),
precision (right / answered ok), the median position error of the ok answers, the covariance
coverage (right ok answers whose position error lies inside the reported 2-sigma ellipse), latency
p50 / p95, and where the misses were lost (:func:`miss_stage`); ``--paper`` adds the plain paper
pipeline, ``--peer`` the exhaustive correlative search of ``bench/peer.py`` on the same queries,
with the ratio of their p95 latencies, twice: with its own verdict (``peer``: ``ok`` when no
distinct place scores within 2 %) and with this package's (``peer-v``: the package's localizer
searching every yaw over the whole map, so that the difference is only in the places found).
``--sensors`` localizes every set again through everyday sensors (``io/sensors.py``: range cut
to 3.5 / 12 m, field of view cut to 90 / 120 deg); ``--foreign`` localizes ``--foreign-n``
scans of every place on the map of every other place (:func:`run_foreign`: negative controls,
never right) and prints the ``ok`` rates. At the end the reliability of the reported confidence
per split (every answer of the run, foreign ones included), drawn by ``--reliability PNG``;
``--answers CSV`` writes every one of those answers with what decided it and its evidence
(``bench/answers.py``).
"""
from __future__ import annotations

import argparse
from collections import Counter
import dataclasses
import math
from pathlib import Path
import time

import numpy as np

from .answers import AnswerLog, decided_by
from .campus import campus_map, office_30m, outdoor_30m, site_queries, SiteQueries, write_query_bag
from .data import data_dir, DATA_HELP
from .peer import ExhaustiveLocalizer, FullSearchLocalizer
from .places import (answers_on, foreign, load_place, MAP_RESOLUTION, MapVariant, real_grid,
                     REAL_PLACES, SIM_PLACES, sim_queries)
from ..cli.arguments import nonnegative_int, positive_int
from ..config.params import load_configs
from ..evaluation.calibration import reliability_report
from ..evaluation.plotting import plot_reliability, plot_replay
from ..evaluation.replay import ResultRow, summarize, within_success
from ..io.sensors import EVERYDAY_SENSORS
from ..localization.localizer import AMBIGUOUS, GlobalLocalizer, Hypothesis, Localization, OK
from ..mapping.index import build_index
from ..mapping.map_io import load_map_yaml
from ..transforms import Pose2

CLUTTER = {'clutter': 8, 'short_fraction': 0.05}
SIM_SETS = {
    'depot': ('depot', {}),
    'tb3_sandbox': ('tb3_sandbox', {}),
    'turtlebot3_world': ('turtlebot3_world', {}),
    'depot_clutter': ('depot', CLUTTER),
    'depot_fov180': ('depot', {'fov_deg': 180.0}),
}
REAL_SETS = REAL_PLACES
#: simulated clutter on the maps built from the real logs
REAL_SIM_SETS = {f'{k}_clutter': (k, CLUTTER) for k in ('intel', 'aces', 'fr079')}
DEFAULT_SETS = list(SIM_SETS) + list(REAL_SETS)
#: success within this many points of an exhaustive search on the same queries (issue target)
PEER_POINTS = 1.0
#: the campus-scale sets (``--campus``): 25-30 M cells each
CAMPUS_SETS = ['campus', 'office_30m', 'outdoor_30m']
#: the synthetic campus-scale maps and their queries' extras, by set name: outdoors, people and
#: moved cars the map does not hold (the clutter of the clutter sets)
LARGE_SYNTHETIC = {'office_30m': (office_30m, {}), 'outdoor_30m': (outdoor_30m, CLUTTER)}
ALL_SETS = DEFAULT_SETS + list(REAL_SIM_SETS) + CAMPUS_SETS
#: the sets the defaults were chosen on (the localizer's on depot, Intel and ACES; the confidence
#: model calibrated on Intel, ACES, FHW, depot and the empty room, by
#: ``scripts/learn_confidence.py``); every other set is a validation set, only ever measured
TUNING_SETS = frozenset({'depot', 'depot_clutter', 'depot_fov180', 'intel', 'aces', 'fhw',
                         'empty_room'})


def split_of(name: str, tuning: frozenset[str] = TUNING_SETS) -> str:
    """Return ``'tuning'`` for a set the defaults were chosen on, else ``'validation'``."""
    return 'tuning' if name in tuning else 'validation'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--sets', nargs='+', default=DEFAULT_SETS, choices=ALL_SETS + ['all'])
    parser.add_argument('-n', type=int, default=500, help='queries per simulated set')
    parser.add_argument('--real-max', type=nonnegative_int, default=0,
                        help='at most this many real queries per log (0 = all odd scans)')
    parser.add_argument('--quick', action='store_true', help='-n 60 and --real-max 60')
    parser.add_argument('--campus', action='store_true',
                        help='also the campus-scale sets: campus (six real buildings and three '
                             'simulated maps on one 27.6 M-cell grid), office_30m and '
                             'outdoor_30m')
    parser.add_argument('--campus-n', type=positive_int, default=100,
                        help='queries per building of the campus set (default 100)')
    parser.add_argument('--campus-bags', metavar='DIR',
                        help='with the campus-scale sets: also write their queries as bags '
                             '(DIR/campus, DIR/office_30m, ..., with /map and /ground_truth) for '
                             '`ssm_localization replay`')
    parser.add_argument('--paper', action='store_true', help='also run the plain paper pipeline')
    parser.add_argument('--peer', action='store_true',
                        help='also run the exhaustive correlative search on the same queries, '
                             "with its own verdict (peer) and with this package's (peer-v); "
                             'with --foreign: on the foreign scans too, and print their ok rates')
    parser.add_argument('--seed', type=nonnegative_int, default=1)
    parser.add_argument('--data', default=None, help=DATA_HELP)
    parser.add_argument('--work', default='bench_data', help='where generated maps are cached')
    parser.add_argument('--params', help='params YAML applied to every set')
    parser.add_argument('--plot-dir', help='write one replay plot per set here')
    parser.add_argument('--sensors', nargs='+', default=['full'], choices=list(EVERYDAY_SENSORS),
                        help='also localize every set through these everyday sensors (range cut '
                             'to 3.5 / 12 m, field of view cut to 90 / 120 deg)')
    parser.add_argument('--foreign', action='store_true',
                        help='negative controls: scans of every place on the map of every other '
                             'place (--foreign-places), --foreign-n a pair; prints the ok rate')
    places = list(REAL_PLACES) + list(SIM_PLACES)
    parser.add_argument('--foreign-places', nargs='+', default=places, choices=places)
    parser.add_argument('--foreign-n', type=positive_int, default=40,
                        help='scans per ordered foreign pair')
    parser.add_argument('--reliability', metavar='PNG',
                        help='write the reliability diagram (reported confidence vs observed '
                             'precision, per split) of every answer of the run')
    parser.add_argument('--map-resolution', type=float, default=MAP_RESOLUTION, metavar='M',
                        help='cell size of the maps built from the real logs (the real sets, '
                             'their clutter variants, the real places of --foreign), metres; '
                             f'default {MAP_RESOLUTION:g}; the nav2 maps and the campus-scale '
                             'sets keep their own')
    parser.add_argument('--map-dilate', type=int, default=0, metavar='N',
                        help="the same maps' walls grown by N cells (the thick walls of many "
                             'SLAM maps); the queries stay those of the map as built')
    parser.add_argument('--map-specks', type=float, default=0.0, metavar='F',
                        help='the same maps with a fraction F of their free cells made '
                             'occupied (seeded specks: passing people, noise)')
    parser.add_argument('--answers', metavar='CSV',
                        help='write every answer of the run (own scans through every sensor, '
                             'foreign scans, campus): set, split, sensor, status, what decided '
                             'it, confidence, right, errors and the evidence features')


def map_variant(args: argparse.Namespace) -> MapVariant:
    """Return the real maps' variant that ``--map-resolution/-dilate/-specks`` ask for."""
    return MapVariant(args.map_resolution, args.map_dilate, args.map_specks)


def _hypothesis_right(localizer: GlobalLocalizer, h: Hypothesis, truth: Pose2) -> bool:
    """Return whether ``h`` was right: its initial pose, or its refined pose once refined."""
    return (within_success(localizer.base_pose(h.initial_pose), truth)
            or (h.refined and within_success(h.pose, truth)))


def miss_stage(localizer: GlobalLocalizer, loc: Localization, truth: Pose2) -> str | None:
    """
    Where a scan not answered right was lost (None when it was answered right).

    Stages, first that applies: no hypothesis near the truth at all; lost in refinement; refined
    but not among the verified; ranked below a wrong pose; right but refused (ambiguous: a rival /
    degenerate geometry / a confidence below ``min_confidence``; failed: explains too little / a
    confidence below one half).
    """
    if loc.status == OK and within_success(loc.pose, truth):
        return None
    cands = loc.candidates
    if not cands:
        return f'no hypothesis at all ({loc.status})'
    if not any(_hypothesis_right(localizer, h, truth) for h in cands):
        return f'no right hypothesis ({loc.status})'
    if not any(h.refined and within_success(h.pose, truth) for h in cands):
        return f'right one lost in refinement ({loc.status})'
    if not any(h.check is not None and within_success(h.pose, truth) for h in cands):
        return f'right one refined, not verified ({loc.status})'
    if not within_success(loc.pose, truth):
        return f'ranked below a wrong pose ({loc.status})'
    how, _ = decided_by(loc)
    if loc.status == AMBIGUOUS:
        return {'degenerate': 'right but ambiguous: degenerate geometry',
                'confidence': 'right but ambiguous: confidence below min_confidence'}.get(
                    how, 'right but ambiguous: a rival within the margin')
    if how == 'confidence':
        return 'right but failed: confidence below one half'
    return 'right but failed: explains too little'


def _coverage(cov: np.ndarray, pose: Pose2, truth: Pose2) -> bool:
    """Return the position error lies inside the 2-sigma ellipse of the reported covariance."""
    e = np.array(pose[:2]) - np.array(truth[:2])
    try:
        return float(e @ np.linalg.solve(np.asarray(cov)[:2, :2], e)) <= 4.0
    except np.linalg.LinAlgError:
        return False


@dataclasses.dataclass
class SetRun:
    """One localizer on one set: result rows, the covariance test, the miss stages."""

    rows: list[ResultRow]
    covered: list[bool]
    stages: Counter
    spectral_found: int


def run_set(localizer, scans, truth: dict, breakdown: bool = True,
            log: AnswerLog | None = None, **labels: str) -> SetRun:
    """Localize ``scans``; with ``log``, add each answer to it with the ``labels``."""
    rows, covered, stages, spectral = [], [], Counter(), 0
    for scan in scans:
        gt = truth.get(scan.stamp)
        loc = localizer.localize_scan(scan.ranges, scan.angle_min, scan.angle_increment,
                                      scan.range_min, scan.range_max)
        rows.append(ResultRow.from_localization(scan.stamp, loc, gt))
        if log is not None:
            log.add(loc, gt, **labels)
        if gt is None:
            continue
        if loc.status == OK and within_success(loc.pose, gt):
            covered.append(_coverage(loc.covariance, loc.pose, gt))
            if breakdown:
                spectral += any('spectral' in h.found_by and _hypothesis_right(localizer, h, gt)
                                for h in loc.candidates)
        elif breakdown:
            stages[miss_stage(localizer, loc, gt)] += 1
    return SetRun(rows, covered, stages, spectral)


def _line(name: str, label: str, run: SetRun, split: str | None = None) -> str:
    s = summarize(run.rows)
    cover = f'{np.mean(run.covered):.1%}' if run.covered else 'n/a'
    return (f'{name:16s} {label:6s} [{(split or split_of(name))[:5]}] n={s.n:4d} ok={s.ok} '
            f'amb={s.ambiguous} fail={s.failed} | '
            f'success {s.success_rate:.1%} precision {s.precision:.2%} | median xy '
            f'{s.median_xy_mm:.1f} mm yaw {s.median_yaw_deg:.2f} deg | 2-sigma coverage {cover} | '
            f'latency p50 {s.latency_p50_ms:.0f} p95 {s.latency_p95_ms:.0f} ms')


def _breakdown(run: SetRun) -> str:
    successes = sum(r.right for r in run.rows)
    misses = sum(run.stages.values())
    parts = [f'{v} {k}' for k, v in run.stages.most_common()]
    found = f'right pose among the spectral hypotheses in {run.spectral_found}/{successes} ' \
            f'successes (the rest: correlative search only)'
    return f'  misses {misses}: ' + ('; '.join(parts) if parts else 'none') + f' | {found}'


def _compare(ours: SetRun, peer: SetRun, what: str = 'peer') -> str:
    """Compare the package with a peer on the same queries, one line (the 1-point target)."""
    a, b = summarize(ours.rows), summarize(peer.rows)
    ratio = a.latency_p95_ms / max(b.latency_p95_ms, 1e-9)
    gap = (a.success_rate - b.success_rate) * 100.0
    checks = [(f'success within {PEER_POINTS:g} point ({gap:+.1f})', gap >= -PEER_POINTS - 1e-9),
              ('precision', a.precision >= b.precision or math.isnan(b.precision)),
              ('p95 <= half', ratio <= 0.5)]
    verdict = ', '.join(f'{k} {"yes" if v else "NO"}' for k, v in checks)
    return (f'  vs {what}: success {a.success_rate:.1%} vs {b.success_rate:.1%}, precision '
            f'{a.precision:.2%} vs {b.precision:.2%}, p95 {a.latency_p95_ms:.0f} vs '
            f'{b.latency_p95_ms:.0f} ms (ratio {ratio:.2f}) -> {verdict}')


def run(args: argparse.Namespace) -> int:
    if args.quick:
        args.n, args.real_max = 60, 60
    sets = [s for s in ALL_SETS if s not in CAMPUS_SETS] if 'all' in args.sets else args.sets
    if args.campus:
        sets = [s for s in sets if s not in CAMPUS_SETS] + CAMPUS_SETS
    data, work = data_dir(args.data), Path(args.work)
    index_cfg, loc_cfg = load_configs(args.params)
    variant = map_variant(args)
    if variant != MapVariant():
        print(f'maps of the real buildings: {variant}', flush=True)
    built: dict[tuple[str, str], object] = {}     # (map, localizer kind): built once per map

    def once(map_name: str, kind: str, make):
        if (map_name, kind) not in built:
            built[map_name, kind] = make()
        return built[map_name, kind]

    log = AnswerLog() if args.answers else None
    pooled: dict[str, list[ResultRow]] = {}
    sensed: dict[tuple[str, str], list[ResultRow]] = {}
    for name in sets:
        t0 = time.perf_counter()
        if name == 'campus':
            run_campus(args, data, work, index_cfg, loc_cfg, pooled, log)
            print(f'  ({name}: {time.perf_counter() - t0:.0f} s)', flush=True)
            continue
        if name in LARGE_SYNTHETIC:
            make, extra = LARGE_SYNTHETIC[name]
            map_name, grid = name, make()
            scans, truth = sim_queries(grid, args.n, args.seed, extra)
            if args.campus_bags:
                bag = write_query_bag(Path(args.campus_bags) / name, grid, [SiteQueries(
                    name, scans, [truth[s.stamp] for s in scans])])
                print(f'  wrote {bag}', flush=True)
        elif name in REAL_SETS:
            map_name, place = name, load_place(name, data, work, args.real_max,
                                               variant=variant)
            grid, scans = place.grid, place.scans
            truth = dict(zip((s.stamp for s in scans), place.truth))
        elif name in REAL_SIM_SETS:
            map_name, extra = REAL_SIM_SETS[name]
            grid = real_grid(data, work, REAL_SETS[map_name], resolution=variant.resolution)
            scans, truth = sim_queries(grid, args.n, args.seed, extra)
            grid = variant.degrade(grid)
        else:
            map_name, extra = SIM_SETS[name]
            grid = load_map_yaml(data / 'maps' / f'{map_name}.yaml')
            scans, truth = sim_queries(grid, args.n, args.seed, extra)
        localizer = once(map_name, 'ssm',
                         lambda: GlobalLocalizer(build_index(grid, index_cfg), loc_cfg))
        index = localizer.index
        labels = {'set': name, 'split': split_of(name), 'kind': 'own', 'map': map_name,
                  'source': map_name}
        ours = run_set(localizer, scans, truth, log=log, sensor='full', **labels)
        print(_line(name, 'ssm', ours), flush=True)
        print(_breakdown(ours), flush=True)
        pooled.setdefault(split_of(name), []).extend(ours.rows)
        for sensor in args.sensors:
            if sensor == 'full':
                continue
            limits = EVERYDAY_SENSORS[sensor]
            weak = run_set(localizer, [limits.apply(s) for s in scans], truth, breakdown=False,
                           log=log, sensor=sensor, **labels)
            print(_line(f'{name}+{sensor}', 'ssm', weak, split_of(name)), flush=True)
            sensed.setdefault((split_of(name), sensor), []).extend(weak.rows)
        if args.plot_dir:
            plot_replay(index, ours.rows, Path(args.plot_dir) / f'{name}.png', title=name)
        if args.paper:
            paper_cfg = dataclasses.replace(loc_cfg, paper_mode=True, top_n=5)
            paper = run_set(once(map_name, 'paper', lambda: GlobalLocalizer(index, paper_cfg)),
                            scans, truth, breakdown=False)
            print(_line(name, 'paper', paper), flush=True)
        if args.peer and name in CAMPUS_SETS:
            print('  --peer: not run on the campus-scale sets (an exhaustive search over 30 M '
                  'cells at every yaw)', flush=True)
        elif args.peer:
            peer_of = once(map_name, 'peer', lambda: ExhaustiveLocalizer(index, ours=localizer))
            peer = run_set(peer_of, scans, truth, breakdown=False)
            print(_line(name, 'peer', peer), flush=True)
            print(_compare(ours, peer), flush=True)
            full_of = once(map_name, 'full', lambda: FullSearchLocalizer(localizer))
            full = run_set(full_of, scans, truth, breakdown=False)
            print(_line(name, 'peer-v', full), flush=True)
            print(_compare(ours, full, 'the exhaustive search with this verdict'), flush=True)
        print(f'  ({name}: {time.perf_counter() - t0:.0f} s)', flush=True)
    for split, rows in sorted(pooled.items(), reverse=True):
        s = summarize(rows)
        print(f'{split} split, pooled: n={s.n} success {s.success_rate:.1%} precision '
              f'{s.precision:.2%} | latency p50 {s.latency_p50_ms:.0f} p95 '
              f'{s.latency_p95_ms:.0f} ms', flush=True)
    for (split, sensor), rows in sorted(sensed.items(), reverse=True):
        s = summarize(rows)
        print(f'{split} split, {sensor}, pooled: n={s.n} success {s.success_rate:.1%} '
              f'precision {s.precision:.2%}', flush=True)
    # reliability: every answer with its confidence, right when its pose is within the bounds
    graded = {split: [(r.confidence, r.correct) for r in rows]
              for split, rows in pooled.items()}
    for (split, _), rows in sensed.items():
        graded[split] += [(r.confidence, r.correct) for r in rows]
    if args.foreign:
        for split, pairs in run_foreign(args, data, work, once, index_cfg, loc_cfg,
                                        log).items():
            graded.setdefault(split, []).extend(pairs)
    tables, text = reliability_report(graded)
    if text:
        print(text, flush=True)
    if args.reliability and tables:
        print(f'wrote {plot_reliability(tables, args.reliability)}')
    if log is not None:
        print(f'wrote {log.write(args.answers)} ({len(log.rows)} answers)')
    return 0


def run_campus(args: argparse.Namespace, data: Path, work: Path, index_cfg, loc_cfg,
               pooled: dict[str, list[ResultRow]], log: AnswerLog | None = None) -> None:
    """
    Localize ``--campus-n`` queries of every building of the campus on the campus map.

    One line per building (``campus:NAME``, in its building's split), then the campus pooled
    and where its misses were lost; the rows join the pooled splits.
    """
    campus = campus_map(data, work)
    t0 = time.perf_counter()
    localizer = GlobalLocalizer(build_index(campus.grid, index_cfg), loc_cfg)
    print(f'campus: {campus.grid.width} x {campus.grid.height} cells, {len(localizer.index)} '
          f'nodes, {localizer.regions.count} search regions (index and localizer '
          f'{time.perf_counter() - t0:.0f} s)', flush=True)
    runs, queries = [], []
    for site in campus.sites:
        q = site_queries(data, site, args.campus_n, args.seed)
        queries.append(q)
        truth = dict(zip((s.stamp for s in q.scans), q.truth))
        one = run_set(localizer, q.scans, truth, log=log, set=f'campus:{site.name}',
                      split=split_of(site.name), sensor='full', kind='own', map='campus',
                      source=site.name)
        print(_line(f'campus:{site.name}', 'ssm', one, split_of(site.name)), flush=True)
        pooled.setdefault(split_of(site.name), []).extend(one.rows)
        runs.append(one)
    allrun = SetRun([r for x in runs for r in x.rows], [c for x in runs for c in x.covered],
                    sum((x.stages for x in runs), Counter()),
                    sum(x.spectral_found for x in runs))
    print(_line('campus', 'ssm', allrun, 'mixed'), flush=True)
    print(_breakdown(allrun), flush=True)
    if args.campus_bags:
        bag = write_query_bag(Path(args.campus_bags) / 'campus', campus.grid, queries)
        print(f'  wrote {bag}', flush=True)


def run_foreign(args: argparse.Namespace, data: Path, work: Path, once, index_cfg,
                loc_cfg, log: AnswerLog | None = None) -> dict[str, list[tuple[float, bool]]]:
    """
    Localize the scans of every place on the map of every other place; print the ok rates.

    ``--foreign-n`` scans a pair (a seeded choice among the place's odd-numbered scans, or
    simulated poses), as recorded. A pair is in the tuning split when both places are. Returns
    the (confidence, right) pairs of every answer by split (never right: the scan is not on
    that map). With ``--peer`` the exhaustive search localizes the same scans, with its own
    verdict (its ``ok`` rate is what its success on the buildings' own scans costs in trust) and
    with this package's (:class:`FullSearchLocalizer`: what searching every yaw would cost).
    """
    names = args.foreign_places
    variant = map_variant(args)
    places = {n: load_place(n, data, work, 0 if n in REAL_PLACES else args.foreign_n, seed=7,
                            variant=variant)
              for n in names}
    print(f'foreign scans: {args.foreign_n} scans of each place on the map of each other '
          f'place (ok = a confident pose on a map the scan is not from)', flush=True)
    counts: dict[str, Counter] = {}          # kind -> answers, ours ok, the peers' ok
    graded: dict[str, list[tuple[float, bool]]] = {}
    for a in names:
        grid = places[a].grid
        localizer = once(a, 'ssm', lambda: GlobalLocalizer(build_index(grid, index_cfg),
                                                           loc_cfg))
        peers = ([once(a, 'peer', lambda: ExhaustiveLocalizer(localizer.index, ours=localizer)),
                  once(a, 'full', lambda: FullSearchLocalizer(localizer))]
                 if args.peer else [])
        cells, peer_cells, full_cells = [], [], []
        for b in names:
            if not foreign(a, b):
                continue
            got = list(answers_on(localizer, a, places[b], limit=args.foreign_n, seed=args.seed))
            ok = sum(x.ok for x in got)
            peer_ok, full_ok = (
                (sum(x.ok for x in answers_on(p, a, places[b], limit=args.foreign_n,
                                              seed=args.seed)) for p in peers)
                if peers else (0, 0))
            split = 'tuning' if split_of(a) == split_of(b) == 'tuning' else 'validation'
            kind = ('real' if a in REAL_PLACES and b in REAL_PLACES else 'simulated') + ' ' + split
            counts.setdefault(kind, Counter()).update(n=len(got), ok=ok, peer=peer_ok,
                                                      full=full_ok)
            graded.setdefault(split, []).extend((x.loc.confidence, False) for x in got)
            if log is not None:
                for x in got:
                    log.add(x.loc, None, set=f'{b}@{a}', split=split, sensor='full',
                            kind='foreign', map=a, source=b)
            cells.append(f'{b} {ok}')
            peer_cells.append(f'{b} {peer_ok}')
            full_cells.append(f'{b} {full_ok}')
        print(f'  map {a:16s} [{split_of(a)[:5]}] ok of {args.foreign_n}: ' + ', '.join(cells),
              flush=True)
        if peers:
            print(f'  map {a:16s} exhaustive search, ok of {args.foreign_n}: '
                  + ', '.join(peer_cells), flush=True)
            print(f'  map {a:16s} exhaustive search with this verdict, ok of {args.foreign_n}: '
                  + ', '.join(full_cells), flush=True)
    total = sum(counts.values(), Counter())
    for kind, c in [*sorted(counts.items()), ('all', total)]:
        what = kind if kind == 'all' else f'{kind} (map and scans both tuning, else validation)'
        print(f'foreign pairs, {what}: ok {c["ok"]} of {c["n"]} = {c["ok"] / max(c["n"], 1):.2%}'
              + _peer_rate(args.peer, c), flush=True)
    return graded


def _peer_rate(shown: bool, c: Counter) -> str:
    """Return the exhaustive searches' foreign ``ok`` rates for a summary line ('' without)."""
    if not shown:
        return ''
    n = max(c['n'], 1)
    return (f'; exhaustive search: ok {c["peer"]} of {c["n"]} = {c["peer"] / n:.2%}; with this '
            f'verdict: ok {c["full"]} of {c["n"]} = {c["full"] / n:.2%}')
