"""``ssm_localization convert-carmen LOG -o OUTDIR``: CARMEN log -> map (YAML+PGM) + query bag."""
from __future__ import annotations

import argparse

from .arguments import add_max_map_cells, nonnegative_int, positive_float, positive_int
from ..config.mapping import MapBuildConfig
from ..io.carmen import convert_carmen
from ..progress import TqdmProgress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('log', help='CARMEN log (.log or .log.gz) with corrected FLASER poses')
    parser.add_argument('-o', '--out', required=True, help='output directory')
    parser.add_argument('--name', help='base name of the outputs (default: from the log name)')
    parser.add_argument('--map-scans', choices=('even', 'odd', 'all'), default='even',
                        help='scans that build the map (default: even)')
    parser.add_argument('--query-scans', choices=('even', 'odd', 'all'), default='odd',
                        help='scans written to the query bag (default: odd)')
    parser.add_argument('--every', type=positive_int, default=1,
                        help='keep every N-th query scan')
    parser.add_argument('--max-scans', type=positive_int, help='at most this many query scans')
    parser.add_argument('--first', type=nonnegative_int,
                        help='first scan index used (map and queries)')
    parser.add_argument('--last', type=nonnegative_int,
                        help='scan index to stop before (map and queries)')
    parser.add_argument('--resolution', type=positive_float, default=0.05,
                        help='map resolution, m')
    parser.add_argument('--free-cap', type=positive_float, default=5.0,
                        help='no-return beams clear space up to this distance, m')
    parser.add_argument('--no-odom', action='store_true', help='do not write /odom')
    parser.add_argument('--bag-out', help='bag directory (default: OUTDIR/NAME_queries)')
    parser.add_argument('--no-bag', action='store_true', help='only write the map')
    parser.add_argument('--force', action='store_true', help='overwrite an existing bag')
    add_max_map_cells(parser)
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    with TqdmProgress('convert', enabled=not args.quiet) as bar:
        res = _convert(args, bar)
    h, w = res.map_shape
    print(f'map: {res.map_yaml} ({w} x {h} cells, {res.map_scans} scans)')
    if res.bag is not None:
        print(f'bag: {res.bag} ({res.query_scans} scans)')
    return 0


def _convert(args, bar):
    return convert_carmen(args.log, args.out, name=args.name, map_scans=args.map_scans,
                          query_scans=args.query_scans, every=args.every,
                          max_scans=args.max_scans, first=args.first, last=args.last,
                          config=MapBuildConfig(resolution=args.resolution,
                                                free_cap=args.free_cap),
                          with_odom=not args.no_odom, write_queries=not args.no_bag,
                          overwrite=args.force, bag_path=args.bag_out, progress=bar,
                          max_map_cells=args.max_map_cells)
