"""
``ssm_localization replay BAG -o RESULTS.csv``.

Single-scan localization of every scan of a bag.
"""
from __future__ import annotations

import argparse
import time

from .arguments import add_max_map_cells, nonnegative_int
from ..config.params import load_configs
from ..evaluation.plotting import check_plot_path, plot_replay
from ..evaluation.replay import replay_scans, summarize, write_results_csv
from ..files.writing import check_output_file
from ..io.bag_reader import read_bag
from ..localization.localizer import GlobalLocalizer
from ..mapping.index import build_index, load_index
from ..mapping.map_io import load_map_yaml
from ..progress import TqdmProgress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('bag', help='rosbag2 directory or .mcap file')
    parser.add_argument('-o', '--output', required=True, help='RESULTS.csv to write')
    src = parser.add_mutually_exclusive_group()
    src.add_argument('--map', help='map_server YAML (default: the first /map message of the bag)')
    src.add_argument('--index', help='index .npz built by `ssm_localization index`')
    parser.add_argument('--scan-topic', default='/scan')
    parser.add_argument('--params', help='params YAML (flat, or a ROS params file)')
    parser.add_argument('--plot', help='write a PNG of the map, ground truth and estimates')
    parser.add_argument('--limit', type=nonnegative_int, default=0,
                        help='localize only the first N scans (0 = all)')
    add_max_map_cells(parser)
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    check_output_file(args.output, 'results file')
    if args.plot:
        check_plot_path(args.plot)
    index_cfg, loc_cfg = load_configs(args.params)
    index = load_index(args.index, max_cells=args.max_map_cells) if args.index else None
    grid = load_map_yaml(args.map, max_cells=args.max_map_cells) if args.map else None
    own_map = index is not None or grid is not None     # the bag's /map is not used then
    bag = read_bag(args.bag, scan_topic=args.scan_topic,
                   max_map_cells=0 if own_map else args.max_map_cells)
    if not bag.scans:
        raise ValueError(f'{args.bag}: no LaserScan messages on {args.scan_topic}')
    if index is None:
        if grid is None:
            grid = bag.map
        if grid is None:
            raise ValueError(f'{args.bag}: no /map message; pass --map or --index')
        t0 = time.perf_counter()
        with TqdmProgress('index', enabled=not args.quiet) as bar:
            index = build_index(grid, index_cfg, progress=bar)
        print(f'indexed map: {len(index.features)} nodes in {time.perf_counter() - t0:.2f} s')
    localizer = GlobalLocalizer(index, loc_cfg)
    scans = bag.scans[:args.limit] if args.limit > 0 else bag.scans
    rows = replay_scans(localizer, scans, bag.ground_truth, progress=not args.quiet)
    write_results_csv(rows, args.output)
    print(f'wrote {len(rows)} rows to {args.output}')
    if any(r.has_truth for r in rows):
        print(summarize(rows).format('replay'))
    if args.plot:
        plot_replay(index, rows, args.plot)
        print(f'wrote {args.plot}')
    return 0
