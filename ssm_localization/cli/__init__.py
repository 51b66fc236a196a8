"""The ``ssm_localization`` command line: one console script, one module per subcommand.

Each subcommand module exposes ``add_arguments(parser)`` and ``run(args) -> int``. Only
``play`` needs ROS (rclpy is imported when it runs) and only ``--plot`` needs matplotlib.
"""
from __future__ import annotations

import argparse
import sys

from . import (bench_cmd, carmen_cmd, index_cmd, match_cmd, play_cmd, replay_cmd,
               simulate_cmd)

# name -> (subcommand module, one-line help)
COMMANDS = {
    'index': (index_cmd, 'build the topological index (GVD nodes + virtual scans) of a map'),
    'replay': (replay_cmd, 'localize every scan of a bag offline and write RESULTS.csv'),
    'play': (play_cmd, 'publish a bag on live ROS topics (map latched)'),
    'match': (match_cmd, 'match two scans of a CARMEN log and plot the result'),
    'convert-carmen': (carmen_cmd, 'convert a CARMEN log into a map (YAML+PGM) and mcap bags'),
    'simulate': (simulate_cmd, 'generate a simulated query bag on a map'),
    'bench': (bench_cmd, 'benchmarks: scanmatch, index, localize'),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='ssm_localization',
        description='Single-scan global localization with spectral scan matching.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name, (mod, help_text) in COMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        mod.add_arguments(sp)
        sp.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        return 130
    except (FileNotFoundError, ValueError) as exc:  # user errors: one clear line, no traceback
        print(f'ssm_localization {args.command}: error: {exc}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
