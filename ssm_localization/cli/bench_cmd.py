"""``ssm_localization bench {scanmatch,index,localize,soak,track}``: benchmarks, as tables."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..bench import index, localize, scanmatch, soak, track
from ..evaluation.plotting import check_plot_path
from ..files.writing import check_output_dir, check_output_file

BENCHES = {
    'scanmatch': (scanmatch, 'scan matching accuracy (paper Table 2, Fig. 4, real scan pairs)'),
    'index': (index, 'index build time and peak memory per map'),
    'localize': (localize, 'global localization success, precision, error and latency per data '
                           'set'),
    'soak': (soak, 'memory and pose rate of global_localizer in continuous mode on a looping '
                   'bag'),
    'track': (track, 'tracking with odometry: success, precision, first fix, recovery after '
                     'kidnaps and latency per CARMEN log'),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest='bench', metavar='BENCH', required=True)
    for name, (mod, help_text) in BENCHES.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        mod.add_arguments(sp)
        sp.set_defaults(_bench=mod.run)


def check_outputs(args: argparse.Namespace) -> None:
    """Check the output paths a benchmark writes at its end before it starts (ValueError)."""
    if getattr(args, 'answers', None):
        check_output_file(args.answers, 'answers file')
    if getattr(args, 'reliability', None):
        check_plot_path(args.reliability)
    if getattr(args, 'plot_dir', None):
        check_output_dir(args.plot_dir, 'plot folder')
    named = [Path(p).resolve() for p in (getattr(args, 'answers', None),
                                         getattr(args, 'reliability', None)) if p]
    if len(set(named)) != len(named):
        raise ValueError('--answers and --reliability name the same file')


def run(args: argparse.Namespace) -> int:
    check_outputs(args)
    return int(args._bench(args) or 0)
