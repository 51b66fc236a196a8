"""The ``ssm_localization`` command line: one console script, one module per subcommand.

Each subcommand module exposes ``add_arguments(parser)`` and ``run(args) -> int``; modules are
imported lazily so ``ssm_localization index`` never imports rclpy or matplotlib.
"""
from __future__ import annotations

import argparse
import importlib
import sys

# name -> (module under ssm_localization.cli, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    'index': ('index_cmd', 'build the topological index (GVD nodes + virtual scans) of a map'),
    'replay': ('replay_cmd', 'localize every scan of a bag offline and write RESULTS.csv'),
    'play': ('play_cmd', 'publish a bag on live ROS topics (map latched)'),
    'match': ('match_cmd', 'match two scans of a CARMEN log and plot the result'),
    'convert-carmen': ('carmen_cmd', 'convert a CARMEN log into a map (YAML+PGM) and mcap bags'),
    'simulate': ('simulate_cmd', 'generate a simulated query bag on a map'),
    'bench': ('bench_cmd', 'benchmarks: scanmatch, index, localize'),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='ssm_localization',
        description='Single-scan global localization with spectral scan matching.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for name, (module, help_text) in COMMANDS.items():
        sp = sub.add_parser(name, help=help_text, description=help_text)
        mod = importlib.import_module(f'{__name__}.{module}')
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
