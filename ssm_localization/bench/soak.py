"""
``ssm_localization bench soak``.

Memory and pose rate of ``global_localizer`` in continuous mode on a looping bag (a soak test).
The driver lives in ``ros/soak.py``; only this command needs rclpy, so it is imported when the
command runs.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..cli.arguments import positive_float
from ..evaluation.plotting import check_plot_path

#: the committed Intel bag of a source checkout, relative to the current directory
DEFAULT_BAG = Path('bags') / 'intel_queries'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--bag', type=Path, default=DEFAULT_BAG,
                        help='bag with /map and /scan (default: bags/intel_queries, the committed '
                             'Intel bag of a source checkout)')
    parser.add_argument('--minutes', type=positive_float, default=10.0)
    parser.add_argument('--rate', type=positive_float, default=10.0, help='scans per second')
    parser.add_argument('--sample', type=positive_float, default=5.0,
                        help='seconds between samples')
    parser.add_argument('--warmup', type=positive_float, default=60.0,
                        help='seconds before the RSS must stay flat')
    parser.add_argument('--param', action='append', default=[], metavar='NAME:=VALUE',
                        help='a parameter of the node (repeatable)')
    parser.add_argument('--plot', type=check_plot_path, help='write RSS and rate over time here')


def run(args: argparse.Namespace) -> int:
    from ..ros.soak import soak  # rclpy only for this command: the rest of the CLI is ROS-free
    return soak(args.bag, args.minutes, args.rate, args.sample, args.warmup,
                params=tuple(args.param), plot=args.plot)
