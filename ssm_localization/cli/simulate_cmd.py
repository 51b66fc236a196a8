"""``ssm_localization simulate MAP.yaml -o BAGDIR``: simulated query scans on a map -> bag."""
from __future__ import annotations

import argparse

from .arguments import (add_max_map_cells, fraction, nonnegative_float, nonnegative_int,
                        offset_component, positive_float, positive_int, sensor_range)
from ..config.simulation import SimulationConfig
from ..files.writing import check_output_dir
from ..io.simulate import simulate_bag
from ..mapping.map_io import load_map_yaml
from ..progress import TqdmProgress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('map', help='map_server map (YAML + image)')
    parser.add_argument('-o', '--out', required=True, help='output bag directory')
    parser.add_argument('-n', '--count', type=positive_int, default=50, help='number of scans')
    parser.add_argument('--fov', type=positive_float, default=360.0,
                        help='field of view, degrees, centred forward')
    parser.add_argument('--beams', type=positive_int, default=360, help='beams per scan')
    parser.add_argument('--max-range', type=sensor_range, default=30.0, help='sensor range, m')
    parser.add_argument('--noise', type=nonnegative_float, default=0.01,
                        help='range noise sigma, m')
    parser.add_argument('--clearance', type=nonnegative_float, default=0.3,
                        help='minimum distance of the robot to obstacles/unknown, m')
    parser.add_argument('--clutter', type=nonnegative_int, default=0,
                        help='unmapped discs (r 0.1-0.3 m, 1-4 m away) per scan')
    parser.add_argument('--short-fraction', type=fraction, default=0.0,
                        help='fraction of beams replaced by random short readings')
    parser.add_argument('--sensor-offset', type=offset_component, nargs=3, default=(0.0, 0.0, 0.0),
                        metavar=('X', 'Y', 'YAW'), help='laser pose on the base (m, m, rad)')
    parser.add_argument('--seed', type=nonnegative_int, default=0, help='random seed')
    parser.add_argument('--force', action='store_true', help='overwrite an existing bag')
    add_max_map_cells(parser)
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    cfg = SimulationConfig(count=args.count, beams=args.beams, fov_deg=args.fov,
                           max_range=args.max_range, noise_sigma=args.noise,
                           clearance=args.clearance, clutter=args.clutter,
                           short_fraction=args.short_fraction,
                           sensor_offset=tuple(args.sensor_offset), seed=args.seed)
    cfg.validate()
    check_output_dir(args.out, 'bag', overwrite=args.force)
    occ_map = load_map_yaml(args.map, max_cells=args.max_map_cells)
    with TqdmProgress('simulate', enabled=not args.quiet) as bar:
        sim = simulate_bag(occ_map, args.out, cfg, overwrite=args.force, progress=bar)
    print(f'bag: {args.out} ({len(sim.scans)} scans, {cfg.beams} beams, fov {cfg.fov_deg:g} deg)')
    return 0
