#!/usr/bin/env python3
"""
Learn the logistic weights w of eq. 4 (paper II.A) from generated matching problems.

The paper learns ``G_ab = 1 / (1 + exp(-w^T g_ij(i', j')))`` as a logistic-regression classifier
of pairs of correspondences. Training data (deterministic, ``--seed``):

* problems: real scan pairs (k, k+s), s in {1, 2, 3}, of the ACES log (kept apart from the Intel
  and Freiburg 079 scans the benchmark reports on), plus Table-2-style synthetic problems (one ACES
  scan + Gaussian noise 0-30 mm + swapped-x/y outliers) -- each new scan moved by a random
  +-400 mm / +-30 deg offset;
* for each problem the tentative correspondences L are built exactly as the matcher does
  (``prepare_scan`` + ``descriptors.candidates``); a candidate a = (i, i') is *correct* when the
  reference point lies within 0.1 m of the truly transformed new point;
* samples: non-conflicting pairs (a, b) of L whose zeroing rules do not already fire (random
  pairs plus pairs drawn among the correct candidates), labelled 1 when both a and b are
  correct, 0 otherwise, with features g = [1, dd^2, dtheta^2] (eq. 3);
* fit: L2-regularised logistic regression (scipy L-BFGS); by default both classes get equal
  total weight (``--no-balance`` to disable), so that G_ab is about 0.5 on the decision boundary.

Result (seed 0): w = (1.048, -129.0, -0.0759): a deformation tolerance of about 90 mm in distance
and almost none in the tangent angle, whose real-scan noise makes it a weak cue. The benchmark
(``ssm_localization bench scanmatch``, "Logistic weights" table) compares it with hand-set
weights (3, -200, -12.5): the two perform the same within noise.

Usage::

    .venv/bin/python scripts/learn_weights.py [--data ../shared/data]
                                              [--out config/matcher_weights.yaml]

Prints the weights and writes them to the YAML file; copy them into
``ssm_localization/config/matcher.py:LEARNED_WEIGHTS`` (the matcher default).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ssm_localization.bench.scanmatch import random_pose, synthetic_problem  # noqa: E402
from ssm_localization.config import MatcherConfig  # noqa: E402
from ssm_localization.io.carmen import read_carmen_log  # noqa: E402
from ssm_localization.matching.descriptors import candidates  # noqa: E402
from ssm_localization.matching.features import prepare_scan  # noqa: E402
from ssm_localization.transforms import apply, compose, inverse  # noqa: E402

CORRECT_TOL = 0.1


def problem_samples(ref_xy, new_xy, truth, cfg, rng, per_problem):
    """Deformation features (K, 3) and labels (K,) of sampled pairs of candidates."""
    rf = prepare_scan(ref_xy, cfg)
    nf = prepare_scan(new_xy, cfg)
    if rf.is_degenerate or nf.is_degenerate:
        return None
    L = candidates(rf.descriptors, nf.descriptors, cfg.k_candidates, cfg.both_ways)
    good = np.linalg.norm(rf.points[L[:, 0]] - apply(truth, nf.points[L[:, 1]]), axis=1) \
        < CORRECT_TOL
    a = rng.integers(0, len(L), per_problem)
    b = rng.integers(0, len(L), per_problem)
    # oversample pairs of correct candidates so the positive class is well represented
    gi = np.flatnonzero(good)
    if len(gi) >= 2:
        a2 = rng.choice(gi, per_problem // 4)
        b2 = rng.choice(gi, per_problem // 4)
        a, b = np.concatenate((a, a2)), np.concatenate((b, b2))
    ia, ja = L[a, 0], L[a, 1]
    ib, jb = L[b, 0], L[b, 1]
    ok = (ia != ib) & (ja != jb)
    dd = rf.dist[ia, ib].astype(float) - nf.dist[ja, jb]
    da = rf.angle[ia, ib].astype(float) - nf.angle[ja, jb]
    ok &= (np.abs(dd) <= cfg.max_dist_deform) & (np.abs(da) <= cfg.max_angle_deform)
    g = np.column_stack((np.ones(ok.sum()), dd[ok] ** 2, da[ok] ** 2))
    y = (good[a] & good[b])[ok].astype(float)
    return g, y


def generate(log, cfg, rng, n_real, n_synth, per_problem):
    gs, ys = [], []
    for _ in range(n_real):
        s = int(rng.integers(1, 4))
        k = int(rng.integers(0, len(log) - s))
        rel = compose(inverse(tuple(log.poses[k])), tuple(log.poses[k + s]))
        off = random_pose(rng)
        out = problem_samples(log.points(k), apply(off, log.points(k + s)),
                              compose(rel, inverse(off)), cfg, rng, per_problem)
        if out is not None:
            gs.append(out[0])
            ys.append(out[1])
    for _ in range(n_synth):
        ref = log.points(int(rng.integers(0, len(log))))
        new, truth, _ = synthetic_problem(ref, rng, float(rng.uniform(0.0, 0.03)),
                                          int(rng.integers(0, len(ref) // 3)))
        out = problem_samples(ref, new, truth, cfg, rng, per_problem)
        if out is not None:
            gs.append(out[0])
            ys.append(out[1])
    return np.vstack(gs), np.concatenate(ys)


def fit_logistic(g, y, balance=True, l2=1e-3):
    """Weighted, L2-regularised logistic regression on standardised features; returns w."""
    from scipy.optimize import minimize
    scale = np.array([1.0, g[:, 1].std() or 1.0, g[:, 2].std() or 1.0])
    X = g / scale
    sw = np.ones(len(y))
    if balance:
        pos = y.sum()
        sw = np.where(y > 0, 0.5 / max(pos, 1), 0.5 / max(len(y) - pos, 1)) * len(y)

    def loss(w):
        z = X @ w
        lz = np.logaddexp(0.0, -z)            # -log sigmoid(z)
        nll = (sw * (y * lz + (1 - y) * (z + lz))).sum() / len(y)
        p = 1.0 / (1.0 + np.exp(-z))
        grad = X.T @ (sw * (p - y)) / len(y)
        return nll + l2 * (w[1:] @ w[1:]), grad + 2 * l2 * np.r_[0.0, w[1:]]

    res = minimize(loss, np.zeros(3), jac=True, method='L-BFGS-B')
    return res.x / scale


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--data', type=Path, default=ROOT.parent / 'shared' / 'data')
    ap.add_argument('--log', default='aces-corrected.log.gz')
    ap.add_argument('--real', type=int, default=150, help='real scan-pair problems')
    ap.add_argument('--synthetic', type=int, default=100, help='Table-2-style problems')
    ap.add_argument('--per-problem', type=int, default=4000, help='pairs sampled per problem')
    ap.add_argument('--no-balance', dest='balance', action='store_false')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--out', type=Path, default=ROOT / 'config' / 'matcher_weights.yaml')
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    cfg = MatcherConfig()
    log = read_carmen_log(args.data / 'carmen' / args.log)
    g, y = generate(log, cfg, rng, args.real, args.synthetic, args.per_problem)
    w = fit_logistic(g, y, args.balance)
    z = g @ w
    acc = ((z > 0) == (y > 0))
    print(f'{len(y)} samples ({int(y.sum())} positive) from {args.log}')
    print(f'weights w = ({w[0]:.4g}, {w[1]:.4g}, {w[2]:.4g})  '
          f"[1, (d_ij - d_i'j')^2 in m^2, (theta_ij - theta_i'j')^2 in rad^2]")
    print(f'accuracy: positives {acc[y > 0].mean():.3f}, negatives {acc[y == 0].mean():.3f}')
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        '# Logistic weights w of eq. 4, learned by scripts/learn_weights.py\n'
        f'# (log {args.log}, seed {args.seed}, {args.real} real + {args.synthetic} synthetic '
        f'problems, balance={args.balance})\n'
        f'weights: [{w[0]:.6g}, {w[1]:.6g}, {w[2]:.6g}]\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
