"""``ssm_localization replay BAG -o RESULTS.csv``: single-scan localization of every scan of a bag."""
from __future__ import annotations

import argparse
import time

from ..config.params import load_configs
from ..evaluation.plotting import plot_replay
from ..evaluation.replay import replay_scans, summarize, write_results_csv
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
    parser.add_argument('--limit', type=int, default=0, help='localize only the first N scans')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    index_cfg, loc_cfg = load_configs(args.params)
    bag = read_bag(args.bag, scan_topic=args.scan_topic)
    if not bag.scans:
        raise ValueError(f'{args.bag}: no LaserScan messages on {args.scan_topic}')
    if args.index:
        index = load_index(args.index)
    else:
        grid = load_map_yaml(args.map) if args.map else bag.map
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
