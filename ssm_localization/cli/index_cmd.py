"""``ssm_localization index MAP.yaml -o INDEX.npz [--params PARAMS.yaml] [--plot OUT.png]``."""
from __future__ import annotations

import argparse
from pathlib import Path
import time

from .arguments import add_max_map_cells
from ..config.params import load_index_config
from ..evaluation.plotting import check_plot_path, plot_index
from ..files.writing import check_output_file
from ..mapping.index import build_index, save_index
from ..mapping.map_io import load_map_yaml
from ..progress import TqdmProgress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('map', help='nav2 map_server map (YAML + PGM/PNG)')
    parser.add_argument('-o', '--output', required=True, help='index file to write (.npz)')
    parser.add_argument('--params', help='YAML params: flat IndexConfig/TopologyConfig names or '
                                         'a ROS params file (map_indexer: ros__parameters:)')
    parser.add_argument('--plot', help='also draw map, GVD and nodes to this PNG')
    add_max_map_cells(parser)
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    inputs = (args.map, args.params)
    check_output_file(args.output, 'index file', inputs)
    if Path(args.output).suffix != '.npz':
        raise ValueError(f'index file {args.output}: expected a name ending in .npz')
    if args.plot:
        check_plot_path(args.plot, inputs)
    config = load_index_config(args.params) if args.params else None
    occ_map = load_map_yaml(args.map, max_cells=args.max_map_cells)
    t0 = time.perf_counter()
    with TqdmProgress('index', enabled=not args.quiet) as bar:
        index = build_index(occ_map, config, progress=bar)
    elapsed = time.perf_counter() - t0
    if len(index) == 0:     # the localizer would refuse it: no file that cannot be used
        raise ValueError(f'{args.map}: the map gives no nodes (no free space with walls around '
                         f'it at {occ_map.resolution:g} m a cell): nothing to localize against, '
                         f'{args.output} not written')
    if not any(len(f) for f in index.features):
        raise ValueError(f'{args.map}: no node of the map sees a wall (its virtual scans have no '
                         f'returns): nothing to localize against, {args.output} not written')
    path = save_index(index, args.output)
    kinds = ', '.join(f'{name} {n}' for name, n in index.kind_counts().items())
    print(f'{len(index)} nodes ({kinds}); built in {elapsed:.2f} s; '
          f'map {occ_map.width} x {occ_map.height} cells @ {occ_map.resolution:g} m; '
          f'wrote {path}')
    if args.plot:
        plot_index(index, args.plot, title=f'{args.map}: {len(index)} nodes')
        print(f'wrote {args.plot}')
    return 0
