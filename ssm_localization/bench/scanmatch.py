"""
``ssm_localization bench scanmatch``: spectral scan matching accuracy on real CARMEN scans.

Protocols (paper V.A): Table 2 (noise 10 mm, 60 swapped-x/y outliers, random pose +-400 mm /
+-30 deg), Fig. 4 (success / matching rate vs noise with 72 outliers and vs outlier ratio at 5 mm),
real scan pairs (k, k+s) of the same log with the same random offset. Also: coverage of the
tentative correspondences L vs k, learned vs hand-set weights of eq. 4, and the ICP refinement.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
from pathlib import Path
import time

import numpy as np
from scipy.spatial import cKDTree

from .data import data_dir, DATA_ENV, DATA_HELP
from ..config.matcher import HAND_WEIGHTS, MatcherConfig
from ..io.carmen import read_carmen_log
from ..matching.descriptors import candidates
from ..matching.features import prepare_scan
from ..matching.matcher import match_features
from ..transforms import apply, compose, inverse, wrap_angle

SCANS = {'intel': ('intel-corrected.log.gz', 26),
         'freiburg-079': ('freiburg-079-corrected.log.gz', 1000)}
POS_TOL, ANG_TOL = 0.05, np.deg2rad(1.0)            # Table 2 / Fig. 4 success
REAL_POS_TOL, REAL_ANG_TOL = 0.15, np.deg2rad(3.0)  # real pairs success
CORRECT_TOL = 0.1                                   # a pair (i, i') is correct within this


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--data', type=Path, default=None, help=DATA_HELP)
    parser.add_argument('--trials', type=int, default=500, help='Table 2 trials (default 500)')
    parser.add_argument('--fig4-trials', type=int, default=30, help='trials per Fig. 4 point')
    parser.add_argument('--pairs', type=int, default=100, help='real pairs per step s')
    parser.add_argument('--ablation-trials', type=int, default=100,
                        help='trials per row of the L / weights / ICP tables')
    parser.add_argument('--quick', action='store_true', help='few trials (well under a minute)')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--scans', nargs='+', default=list(SCANS), choices=list(SCANS))
    parser.add_argument('--intel-scan', type=int, default=SCANS['intel'][1],
                        help='Intel scan used for Table 2 / Fig. 4 (default %(default)s)')
    parser.add_argument('--freiburg-scan', type=int, default=SCANS['freiburg-079'][1],
                        help='Freiburg 079 scan used for Table 2 / Fig. 4 (default %(default)s)')
    parser.add_argument('--only', nargs='+', default=None,
                        choices=['table2', 'fig4', 'real', 'candidates', 'weights', 'icp'])


@dataclass
class Trial:
    err: np.ndarray      # (3,) x, y (m), yaw (rad)
    ms: float
    cpu_ms: float
    rate: float          # matching rate (correct consistent pairs / inlier points of the new scan)
    coverage: float      # fraction of new inlier points whose true partner is in L
    n_candidates: int


def random_pose(rng, max_xy=0.4, max_yaw=np.deg2rad(30.0)):
    return (rng.uniform(-max_xy, max_xy), rng.uniform(-max_xy, max_xy),
            rng.uniform(-max_yaw, max_yaw))


def synthetic_problem(ref: np.ndarray, rng, sigma: float, n_out: int):
    """
    Paper V.A: noise, then ``n_out`` outliers (x and y swapped), then a random pose.

    Returns ``(new_xy, truth, outlier_mask)`` with ``p_ref = R(truth) p_new + t``.
    """
    new = ref + rng.normal(0.0, sigma, ref.shape)
    out = np.zeros(len(ref), dtype=bool)
    if n_out > 0:
        idx = rng.choice(len(ref), min(n_out, len(ref)), replace=False)
        new[idx] = new[idx][:, ::-1]
        out[idx] = True
    truth = random_pose(rng)
    return apply(inverse(truth), new), truth, out


def run_trial(ref_xy, new_xy, truth, outlier, config) -> Trial:
    t0, c0 = time.perf_counter(), time.process_time()
    rf = prepare_scan(ref_xy, config)
    nf = prepare_scan(new_xy, config)
    res = match_features(rf, nf, config)
    ms = 1000.0 * (time.perf_counter() - t0)
    cpu_ms = 1000.0 * (time.process_time() - c0)
    err = np.array(res.pose) - np.array(truth)
    err[2] = wrap_angle(err[2])
    if not np.all(np.isfinite(err)):
        err = np.array([np.inf, np.inf, np.pi])
    # ground-truth partner of each downsampled new point: nearest downsampled ref point
    moved = apply(truth, nf.points)
    d = np.linalg.norm(moved[:, None, :] - rf.points[None, :, :], axis=2)
    partner = np.argmin(d, axis=1)
    has = (d[np.arange(len(moved)), partner] < CORRECT_TOL) & ~outlier[nf.source_index]
    n_in = max(int(has.sum()), 1)
    pairs = res.pairs
    if len(pairs):
        p_ref = np.asarray(ref_xy)[pairs[:, 0]]
        p_new = apply(truth, np.asarray(new_xy)[pairs[:, 1]])
        good = (np.linalg.norm(p_ref - p_new, axis=1) < CORRECT_TOL) & ~outlier[pairs[:, 1]]
        rate = float(good.sum()) / n_in
    else:
        rate = 0.0
    L = candidates(rf.descriptors, nf.descriptors, config.k_candidates, config.both_ways)
    inL = np.zeros((len(rf), len(nf)), dtype=bool)
    inL[L[:, 0], L[:, 1]] = True
    cov = float(inL[partner[has], np.flatnonzero(has)].sum()) / n_in
    return Trial(err, ms, cpu_ms, min(rate, 1.0), cov, len(L))


def summarize(trials: list[Trial], pos_tol=POS_TOL, ang_tol=ANG_TOL) -> dict:
    e = np.array([t.err for t in trials])
    ok = (np.hypot(e[:, 0], e[:, 1]) < pos_tol) & (np.abs(e[:, 2]) < ang_tol)
    eo = e[ok] if ok.any() else np.full((1, 3), np.nan)
    return {'n': len(trials), 'success': 100.0 * ok.mean(), 'mean': eo.mean(axis=0),
            'std': eo.std(axis=0), 'median_abs': np.median(np.abs(e), axis=0),
            'ms': float(np.median([t.ms for t in trials])),
            'cpu_ms': float(np.median([t.cpu_ms for t in trials])),
            'rate': 100.0 * float(np.mean([t.rate for t in trials])),
            'coverage': 100.0 * float(np.mean([t.coverage for t in trials])),
            'L': float(np.mean([t.n_candidates for t in trials]))}


def table2(ref, rng, config, trials, sigma=0.01, n_out=60):
    out = []
    for _ in range(trials):
        new, truth, outl = synthetic_problem(ref, rng, sigma, n_out)
        out.append(run_trial(ref, new, truth, outl, config))
    return summarize(out)


def true_overlap(ref_xy, new_xy, truth, dist=0.2) -> float:
    """Fraction of the new scan's points within ``dist`` of a reference point at the true pose."""
    d, _ = cKDTree(ref_xy).query(apply(truth, new_xy), distance_upper_bound=dist)
    return float(np.mean(d < dist))


def real_pairs(log, rng, config, step, n_pairs):
    """
    Return scans k and k+step with the truth from the corrected poses, plus a random offset.

    Also reports the success over the pairs that truly overlap by at least 50 %.
    """
    ks = rng.choice(len(log) - step, n_pairs, replace=False)
    out, ovs = [], []
    for k in ks:
        ref = log.points(int(k))
        new = log.points(int(k) + step)
        rel = compose(inverse(tuple(log.poses[k])), tuple(log.poses[k + step]))
        off = random_pose(rng)
        truth = compose(rel, inverse(off))
        new_off = apply(off, new)
        out.append(run_trial(ref, new_off, truth, np.zeros(len(new), bool), config))
        ovs.append(true_overlap(ref, new_off, truth))
    s = summarize(out, REAL_POS_TOL, REAL_ANG_TOL)
    sub = [t for t, o in zip(out, ovs) if o >= 0.5]
    s['n_ov'] = len(sub)
    s['success_ov'] = summarize(sub, REAL_POS_TOL, REAL_ANG_TOL)['success'] if sub else np.nan
    return s


def _row_t2(label, s):
    m, sd = s['mean'], s['std']
    return (f'{label:<24} {m[0] * 1e3:7.2f} {sd[0] * 1e3:6.2f} {m[1] * 1e3:7.2f} '
            f'{sd[1] * 1e3:6.2f} '
            f'{np.rad2deg(m[2]):7.3f} {np.rad2deg(sd[2]):6.3f} {s["success"]:6.1f} {s["ms"]:6.2f} '
            f'{s["cpu_ms"]:6.2f}')


T2_HEAD = (f'{"":<24} {"x mu":>7} {"x sd":>6} {"y mu":>7} {"y sd":>6} {"th mu":>7} {"th sd":>6} '
           f'{"succ%":>6} {"ms":>6} {"cpu ms":>6}')


def run(args: argparse.Namespace) -> int:
    if args.quick:
        args.trials, args.fig4_trials, args.pairs, args.ablation_trials = 60, 8, 30, 30
    data = data_dir(args.data) / 'carmen'
    if not data.is_dir():
        raise FileNotFoundError(f'data directory not found: {data} (pass --data DIR or set '
                                f'{DATA_ENV})')
    only = set(args.only or ['table2', 'fig4', 'real', 'candidates', 'weights', 'icp'])
    cfg = MatcherConfig(seed=args.seed)
    logs = {name: read_carmen_log(data / SCANS[name][0]) for name in args.scans}
    which = {'intel': args.intel_scan, 'freiburg-079': args.freiburg_scan}
    refs = {name: logs[name].points(which[name]) for name in args.scans}
    t_start = time.perf_counter()
    print('scans: ' + ', '.join(f'{n} #{which[n]} ({len(refs[n])} points)' for n in refs))
    print(f'config: max_points={cfg.max_points} k={cfg.k_candidates} icp={cfg.icp} '
          f'weights={cfg.weights}')

    if 'table2' in only:
        print(f'\n== Table 2: sigma 10 mm, 60 outliers, pose +-400 mm / +-30 deg, '
              f'{args.trials} trials (errors in mm / deg over successes; success < 50 mm & '
              f'< 1 deg; ms = median wall time per match incl. prepare_scan of both scans, '
              f'cpu ms = median process CPU time)')
        print(T2_HEAD)
        print(f'{"paper SSM (362 pts)":<24} {0.10:7.2f} {10.40:6.2f} {-0.30:7.2f} {7.09:6.2f} '
              f'{0.02:7.3f} {0.10:6.3f}')
        for name, ref in refs.items():
            s = table2(ref, np.random.default_rng(args.seed), cfg, args.trials)
            print(_row_t2(name, s))

    if 'fig4' in only:
        print(f'\n== Fig. 4: success % / matching rate % ({args.fig4_trials} trials per point)')
        sigmas = [0.0, 0.01, 0.02, 0.03, 0.04, 0.05]
        ratios = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]
        print('(a) 72 outliers, noise sigma mm: ' + ' '.join(f'{s * 1e3:>11.0f}' for s in sigmas))
        for name, ref in refs.items():
            cells = []
            for sg in sigmas:
                s = table2(ref, np.random.default_rng(args.seed + 1), cfg, args.fig4_trials, sg,
                           72)
                cells.append(f'{s["success"]:5.0f}/{s["rate"]:5.1f}')
            print(f'{name:<32} ' + ' '.join(f'{c:>11}' for c in cells))
        print('(b) sigma 5 mm, outliers/inliers: ' + ' '.join(f'{r:>11.1f}' for r in ratios))
        for name, ref in refs.items():
            cells = []
            for r in ratios:
                n_out = int(round(r * len(ref) / (1.0 + r)))
                s = table2(ref, np.random.default_rng(args.seed + 2), cfg, args.fig4_trials,
                           0.005, n_out)
                cells.append(f'{s["success"]:5.0f}/{s["rate"]:5.1f}')
            print(f'{name:<33} ' + ' '.join(f'{c:>11}' for c in cells))

    if 'real' in only:
        print(f'\n== Real pairs: scans k and k+s, truth from corrected poses, + random offset '
              f'+-400 mm / +-30 deg; {args.pairs} pairs per s; success < 150 mm & < 3 deg')
        print(f'{"":<16} {"s":>3} {"succ%":>6} {"med dx mm":>10} {"med dy mm":>10} '
              f'{"med dth deg":>11} {"ms":>6} {"succ% ov>=50%":>14} {"n ov>=50%":>9}')
        for name, log in logs.items():
            for step in (1, 3, 5):
                s = real_pairs(log, np.random.default_rng(args.seed + step), cfg, step, args.pairs)
                ma = s['median_abs']
                print(f'{name:<16} {step:>3} {s["success"]:6.1f} {ma[0] * 1e3:10.1f} '
                      f'{ma[1] * 1e3:10.1f} {np.rad2deg(ma[2]):11.3f} {s["ms"]:6.2f} '
                      f'{s["success_ov"]:14.1f} {s["n_ov"]:9d}')

    n_ab = args.ablation_trials
    if 'candidates' in only:
        print(f'\n== Tentative correspondences L vs k ({n_ab} trials; coverage = % of new inlier '
              f'points whose true partner is in L)')
        print(f'{"":<16} {"k":>3} {"both":>5} {"|L|":>6} {"T2 cov%":>8} {"T2 succ%":>8} '
              f'{"T2 ms":>6} {"real cov%":>9} {"real succ%":>10}')
        for name, ref in refs.items():
            for k, both in ((1, False), (2, False), (3, False), (5, False), (3, True), (8, False)):
                c = replace(cfg, k_candidates=k, both_ways=both)
                s = table2(ref, np.random.default_rng(args.seed + 3), c, n_ab)
                r = real_pairs(logs[name], np.random.default_rng(args.seed + 4), c, 3, n_ab)
                print(f'{name:<16} {k:>3} {str(both):>5} {s["L"]:6.0f} {s["coverage"]:8.1f} '
                      f'{s["success"]:8.1f} {s["ms"]:6.2f} {r["coverage"]:9.1f} '
                      f'{r["success"]:10.1f}')

    if 'weights' in only:
        print(f'\n== Logistic weights w of eq. 4 ({n_ab} trials; '
              f'learned: scripts/learn_weights.py)')
        print(f'{"":<16} {"weights":<30} {"T2 succ%":>8} {"T2 rate%":>8} {"real s=3 succ%":>14}')
        for name, ref in refs.items():
            for label, w in (('learned', cfg.weights), ('hand-set', HAND_WEIGHTS)):
                c = replace(cfg, weights=w)
                s = table2(ref, np.random.default_rng(args.seed + 5), c, n_ab, 0.02, 72)
                r = real_pairs(logs[name], np.random.default_rng(args.seed + 6), c, 3, n_ab)
                wtxt = label + ' (' + ', '.join(f'{v:.3g}' for v in w) + ')'
                print(f'{name:<16} {wtxt:<30} {s["success"]:8.1f} {s["rate"]:8.1f} '
                      f'{r["success"]:14.1f}')
        print('(T2 here: sigma 20 mm, 72 outliers)')

    if 'icp' in only:
        print(f'\n== Refinement after RANSAC + least squares ({n_ab} trials)')
        print(f'{"":<24}' + T2_HEAD[24:] + f' {"real s=5 succ%":>14} {"med dxy mm":>10}')
        for name, ref in refs.items():
            for label, c in (('no ICP', replace(cfg, icp=False)),
                             ('ICP point-to-line', replace(cfg, polish=False)),
                             ('ICP + mutual-NN polish', cfg)):
                s = table2(ref, np.random.default_rng(args.seed + 7), c, n_ab)
                r = real_pairs(logs[name], np.random.default_rng(args.seed + 8), c, 5, n_ab)
                print(_row_t2(f'{name[:6]} {label}', s) +
                      f' {r["success"]:14.1f} {np.hypot(*r["median_abs"][:2]) * 1e3:10.1f}')
    print(f'\ntotal {time.perf_counter() - t_start:.1f} s')
    return 0
