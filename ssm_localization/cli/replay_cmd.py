"""
``ssm_localization replay BAG -o RESULTS.csv``.

Localize every scan of a bag: by default every scan on its own (single-scan global
localization); ``--track`` tracks the scans in order with the bag's ``/odom`` interpolated at
their stamps as the node does (without odometry where there is none within ``--odom-max-age``),
falling back on global localization when the track is lost
(``localization/tracker.py``).
"""
from __future__ import annotations

import argparse
import time

from .arguments import add_max_map_cells, nonnegative_float, nonnegative_int
from ..config.params import load_all_configs
from ..evaluation.plotting import check_plot_path, plot_replay
from ..evaluation.replay import match_truth, replay_scans, summarize, write_results_csv
from ..evaluation.tracking import ODOM_MAX_AGE, odometry_at, summarize_track, track_scans
from ..files.writing import check_output_file
from ..io.bag_reader import read_bag
from ..localization.localizer import GlobalLocalizer
from ..localization.tracker import Tracker
from ..mapping.index import build_index, load_index
from ..mapping.map_io import load_map_yaml
from ..mapping.map_limits import MapTooLargeError
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
    parser.add_argument('--track', action='store_true',
                        help='track the scans in order with /odom (tracker parameters: the '
                             '`tracker` section of --params); global localization when lost')
    parser.add_argument('--no-odom', action='store_true',
                        help='with --track: ignore /odom (track without odometry)')
    parser.add_argument('--odom-max-age', type=nonnegative_float, default=ODOM_MAX_AGE,
                        metavar='S', help='with --track: odometry is interpolated at each scan '
                                          'stamp; a scan with none within S seconds is tracked '
                                          "without (the node's odom_max_age)")
    parser.add_argument('--limit', type=nonnegative_int, default=0,
                        help='localize only the first N scans (0 = all)')
    add_max_map_cells(parser)
    parser.add_argument('--allow-map-mismatch', action='store_true',
                        help='with --map / --index: localize even when the bag holds a /map '
                             'that differs from that map (poses are then in the frame of the '
                             "given map, not of the bag's)")
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    inputs = (args.bag, args.map, args.index, args.params)
    check_output_file(args.output, 'results file', inputs)
    if args.plot:
        check_plot_path(args.plot, inputs)
    index_cfg, loc_cfg, track_cfg = load_all_configs(args.params)
    index = load_index(args.index, max_cells=args.max_map_cells) if args.index else None
    grid = load_map_yaml(args.map, max_cells=args.max_map_cells) if args.map else None
    bag = _read_bag(args)
    if not bag.scans:
        raise ValueError(f'{args.bag}: no LaserScan messages on {args.scan_topic}')
    if bag.map is not None and (index is not None or grid is not None):
        given = index.map_checksum if index is not None else grid.checksum()
        _check_same_map(args, bag.map.checksum(), given)
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
    if localizer.calibration_warning:
        print(f'note: {localizer.calibration_warning}')
    scans = bag.scans[:args.limit] if args.limit > 0 else bag.scans
    if args.track:
        stamps = [s.stamp for s in scans]
        odom = odometry_at(stamps, {} if args.no_odom else bag.odom, args.odom_max_age)
        missing = sum(o is None for o in odom)
        if args.no_odom:
            print('tracking without odometry (--no-odom)')
        elif not bag.odom:
            print('tracking without odometry (no /odom in the bag)')
        elif missing:
            print(f'tracking without odometry on {missing} of {len(odom)} scans (no /odom '
                  f'within {args.odom_max_age:g} s of their stamps)')
        rows = track_scans(Tracker(localizer, track_cfg), scans, odom,
                           match_truth(stamps, bag.ground_truth), progress=not args.quiet)
    else:
        rows = replay_scans(localizer, scans, bag.ground_truth, progress=not args.quiet)
    write_results_csv(rows, args.output)
    print(f'wrote {len(rows)} rows to {args.output}')
    if args.track:
        print(summarize_track(rows).format('track'))
    elif any(r.has_truth for r in rows):
        print(summarize(rows).format('replay'))
    if args.plot:
        plot_replay(index, rows, args.plot)
        print(f'wrote {args.plot}')
    return 0


def _read_bag(args: argparse.Namespace):
    """
    Return the bag's scans, poses and its /map (when there is one).

    With ``--map`` / ``--index`` the bag's own /map is read only to compare it with the given
    map; one too large for ``--max-map-cells`` is then skipped with a note.
    """
    given = bool(args.map or args.index)
    try:
        return read_bag(args.bag, scan_topic=args.scan_topic, max_map_cells=args.max_map_cells)
    except MapTooLargeError:
        if not given:
            raise
        print(f"note: the bag's /map exceeds --max-map-cells; not compared with "
              f'{args.map or args.index}')
        return read_bag(args.bag, scan_topic=args.scan_topic, read_map=False)


def _check_same_map(args: argparse.Namespace, bag_checksum: str, given_checksum: str) -> None:
    """
    Refuse a ``--map`` / ``--index`` built from another map than the bag's /map.

    Its poses would be in that other map's frame: compared with the bag's ground truth, or
    handed to a robot on the bag's map, they would be wrong while looking confident.
    ``--allow-map-mismatch`` turns the refusal into a warning.
    """
    if bag_checksum == given_checksum:
        return
    what = f'--index {args.index}' if args.index else f'--map {args.map}'
    text = (f"{what} was built from another map than the bag's /map (checksum "
            f'{given_checksum[:12]} vs {bag_checksum[:12]})')
    if not args.allow_map_mismatch:
        raise ValueError(f'{text}: poses would be in the frame of that other map. Rebuild the '
                         f'index from the map the bag was recorded on, or pass '
                         f'--allow-map-mismatch to localize on it anyway')
    print(f'warning: {text}; localizing on it anyway (--allow-map-mismatch): poses and '
          f'ground-truth figures are in its frame')
