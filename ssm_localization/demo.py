"""
``python -m ssm_localization.demo --out DIR`` (what ``make demo`` runs).

1. Global localization of every scan of the bundled real bag ``bags/intel_queries`` (Intel
   Research Lab, map built from the log's even scans, queries = odd scans) on its own: prints
   success, precision, errors and latency against /ground_truth, writes DIR/intel_results.csv
   and DIR/intel_replay.png (the same as ``ssm_localization replay``).
2. Spectral scan matching of a real Intel scan pair moved by a random +-400 mm / +-30 deg
   offset (needs the Intel CARMEN log of the shared data, ``--data DIR`` or
   ``SSM_LOCALIZATION_DATA``): prints estimate, truth, error and time, writes
   DIR/scan_match.png.

Run it from the root of a source checkout (``bags/`` is found from the current directory).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys
import time

import numpy as np

from .bench.data import DATA_ENV, DATA_HELP, default_data_dir
from .cli.main import main as cli_main
from .evaluation.plotting import plot_match
from .io.carmen import read_carmen_log
from .matching.matcher import match_scans
from .transforms import apply, compose, inverse, wrap_angle

#: the committed Intel bag of a source checkout, relative to the current directory
DEFAULT_BAG = Path('bags') / 'intel_queries'


def replay_demo(bag: Path, out: Path) -> int:
    """Localize every scan of ``bag``; print the figures; write the CSV and the plot."""
    print(f'Single-scan global localization of every scan in {bag.name} (real Intel scans)')
    return cli_main(['replay', str(bag), '-o', str(out / 'intel_results.csv'),
                     '--plot', str(out / 'intel_replay.png')])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', type=Path, default=Path('out'))
    ap.add_argument('--data', type=Path, default=None, help=DATA_HELP)
    ap.add_argument('--k', type=int, default=300, help='reference scan of the Intel log')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--bag', type=Path, default=DEFAULT_BAG,
                    help='bag to localize (default: bags/intel_queries)')
    args = ap.parse_args(argv)
    if not args.bag.exists():
        ap.error(f'bag not found: {args.bag} (run from the root of a source checkout, or '
                 'pass --bag)')
    args.out.mkdir(parents=True, exist_ok=True)
    status = replay_demo(args.bag, args.out)
    print()

    path = (args.data or default_data_dir()) / 'carmen' / 'intel-corrected.log.gz'
    if not path.is_file():
        print(f'scan matching demo skipped: CARMEN log not found: {path} (pass --data DIR or '
              f'set {DATA_ENV})')
        return status
    log = read_carmen_log(path)
    k = args.k
    rng = np.random.default_rng(args.seed)
    off = (rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-np.pi / 6, np.pi / 6))
    ref = log.points(k)
    new = apply(off, log.points(k + 1))
    truth = compose(compose(inverse(tuple(log.poses[k])), tuple(log.poses[k + 1])), inverse(off))
    match_scans(ref, new)                      # warm-up (imports, caches)
    t0 = time.perf_counter()
    res = match_scans(ref, new)
    ms = 1000.0 * (time.perf_counter() - t0)
    e = np.array(res.pose) - np.array(truth)
    e[2] = wrap_angle(e[2])

    def fmt(p):
        return f'x={p[0]:+.3f} m  y={p[1]:+.3f} m  yaw={np.rad2deg(p[2]):+7.2f} deg'
    print(f'Spectral scan matching, Intel scans {k} and {k + 1} (+ random offset), '
          f'{len(ref)} / {len(new)} points')
    print(f'  estimate {fmt(res.pose)}  (ok={res.ok}, {len(res.inliers)} inliers)')
    print(f'  truth    {fmt(truth)}')
    print(f'  error    {np.hypot(e[0], e[1]) * 1e3:.1f} mm, {abs(np.rad2deg(e[2])):.3f} deg; '
          f'{ms:.1f} ms')
    png = plot_match(ref, new, res.pose, args.out / 'scan_match.png', pairs=res.inliers,
                     truth=truth, title=f'Intel scans {k} / {k + 1}: error '
                     f'{np.hypot(e[0], e[1]) * 1e3:.0f} mm, {abs(np.rad2deg(e[2])):.2f} deg')
    print(f'  wrote {png}')
    return status or (0 if res.ok else 1)


if __name__ == '__main__':
    sys.exit(main())
