"""
``ssm_localization match LOG.gz --k 100 --s 3 [--plot out.png]``.

Match two scans of a CARMEN log (scan k as reference, scan k+s as new), print the estimate against
the corrected poses.
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
import time

import numpy as np

from .arguments import nonnegative_int, offset_component, positive_int
from ..config.matcher import MatcherConfig
from ..evaluation.plotting import check_plot_path, plot_match
from ..io.carmen import read_carmen_log
from ..matching.matcher import match_scans
from ..transforms import apply, compose, inverse, wrap_angle


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('log', type=Path, help='CARMEN log (.log or .log.gz)')
    parser.add_argument('--k', type=nonnegative_int, default=0,
                        help='reference scan index (default 0)')
    parser.add_argument('--s', type=int, default=1, help='new scan = k + s (default 1)')
    parser.add_argument('--offset', type=offset_component, nargs=3, metavar=('X', 'Y', 'YAW_DEG'),
                        default=None, help='extra rigid offset applied to the new scan')
    parser.add_argument('--max-points', type=positive_int, default=None,
                        help='matcher point budget')
    parser.add_argument('--no-icp', action='store_true', help='skip the ICP refinement')
    parser.add_argument('--seed', type=nonnegative_int, default=0, help='RANSAC seed')
    parser.add_argument('--plot', type=Path, default=None, help='write a PNG of the match')


def run(args: argparse.Namespace) -> int:
    if args.plot:
        check_plot_path(args.plot)
    log = read_carmen_log(args.log)
    j = args.k + args.s
    if not (0 <= args.k < len(log) and 0 <= j < len(log)):
        raise ValueError(f'--k {args.k} / --s {args.s}: scans must be in 0..{len(log) - 1}')
    cfg = MatcherConfig(seed=args.seed, icp=not args.no_icp)
    if args.max_points:
        cfg = dataclasses.replace(cfg, max_points=args.max_points)
    ref = log.points(args.k)
    new = log.points(j)
    truth = compose(inverse(tuple(log.poses[args.k])), tuple(log.poses[j]))
    if args.offset is not None:
        off = (args.offset[0], args.offset[1], np.deg2rad(args.offset[2]))
        new = apply(off, new)
        truth = compose(truth, inverse(off))
    t0 = time.perf_counter()
    res = match_scans(ref, new, cfg)
    ms = 1000.0 * (time.perf_counter() - t0)
    err = np.array(res.pose) - np.array(truth)
    err[2] = wrap_angle(err[2])

    def fmt(p):
        return f'x={p[0]:+.3f} m  y={p[1]:+.3f} m  yaw={np.rad2deg(p[2]):+.2f} deg'
    print(f'{log.name}: scan {args.k} ({len(ref)} points) <- scan {j} ({len(new)} points)')
    print(f'estimate  {fmt(res.pose)}   ok={res.ok} {res.message}')
    print(f'truth     {fmt(truth)}')
    print(f'error     {np.hypot(err[0], err[1]) * 1e3:.1f} mm, {abs(np.rad2deg(err[2])):.3f} deg')
    print(f'pairs {len(res.pairs)}, inliers {len(res.inliers)}, score {res.score:.1f}, '
          f'overlap {res.overlap:.2f}, {ms:.1f} ms')
    if args.plot:
        out = plot_match(ref, new, res.pose, args.plot, pairs=res.inliers, truth=truth,
                         title=f'{log.name} scan {args.k} vs {j}: error '
                               f'{np.hypot(err[0], err[1]) * 1e3:.0f} mm / '
                               f'{abs(np.rad2deg(err[2])):.2f} deg')
        print(f'wrote {out}')
    return 0 if res.ok else 1
