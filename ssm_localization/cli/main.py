"""
The ``ssm_localization`` command line: one console script, one module per subcommand.

Each subcommand module exposes ``add_arguments(parser)`` and ``run(args) -> int``. Only
``play`` needs ROS (rclpy is imported when it runs) and only ``--plot`` needs matplotlib.

User errors end in one line on stderr, ``ssm_localization COMMAND: error: ...``, and exit
status 2: bad arguments (argparse), and the ``ValueError`` / ``OSError`` (missing, unreadable
or unwritable files) that the library raises at its boundaries, naming the file or field, and
a ``MemoryError`` (settings asking for more memory than there is). Subcommands check their
output paths before they start working.
"""
from __future__ import annotations

import argparse
from importlib import metadata
import sys

from . import bench_cmd, carmen_cmd, index_cmd, match_cmd, play_cmd, replay_cmd, simulate_cmd
from ..files.reading import clip

#: longest error line printed (messages that echo input are clipped where they are made too)
MAX_ERROR_CHARS = 600

# name -> (subcommand module, one-line help)
COMMANDS = {
    'index': (index_cmd, 'build the topological index (GVD nodes + virtual scans) of a map'),
    'replay': (replay_cmd, 'localize every scan of a bag offline and write RESULTS.csv'),
    'play': (play_cmd, 'publish a bag on live ROS topics (map latched)'),
    'match': (match_cmd, 'match two scans of a CARMEN log and plot the result'),
    'convert-carmen': (carmen_cmd, 'convert a CARMEN log into a map (YAML+PGM) and mcap bags'),
    'simulate': (simulate_cmd, 'generate a simulated query bag on a map'),
    'bench': (bench_cmd, 'benchmarks: scanmatch, index, localize, track, soak'),
}


class Parser(argparse.ArgumentParser):
    """
    An ``ArgumentParser`` whose usage errors are one line (``PROG: error: ...``, status 2).

    ``--help`` still shows the usage. Subcommand parsers are of this class too.
    """

    def error(self, message: str):
        self.exit(2, f'{self.prog}: error: {clip(message, MAX_ERROR_CHARS)} '
                     f'(see {self.prog} --help)\n')


def error_text(exc: BaseException) -> str:
    """One line for a user error: an ``OSError`` as ``file: reason``, else the message."""
    if isinstance(exc, OSError) and exc.strerror:
        names = ' -> '.join(str(n) for n in (exc.filename, exc.filename2) if n is not None)
        text = f'{names}: {exc.strerror}' if names else exc.strerror
    else:
        text = str(exc) or type(exc).__name__
    return clip(text, MAX_ERROR_CHARS)


def _version() -> str:
    """Return the installed version (setup.py's, as ``ssm_localization.__version__``)."""
    try:
        return metadata.version('ssm_localization')
    except metadata.PackageNotFoundError:      # run from a source tree that is not installed
        return 'unknown (not installed)'


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog='ssm_localization',
        description='Single-scan global localization with spectral scan matching.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {_version()}')
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
    except (OSError, ValueError) as exc:  # user errors: one clear line, no traceback
        print(f'ssm_localization {args.command}: error: {error_text(exc)}', file=sys.stderr)
        return 2
    except MemoryError as exc:            # settings that ask for more than the machine has
        print(f'ssm_localization {args.command}: error: out of memory '
              f'({error_text(exc)}): ask for fewer beams, scans or cells', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
