"""``ssm_localization simulate MAP.yaml -o BAGDIR``: simulated query scans on a map -> bag."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..config.simulation import SimulationConfig
from ..io.simulate import simulate_bag
from ..mapping.map_io import load_map_yaml
from ..progress import TqdmProgress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('map', help='map_server map (YAML + image)')
    parser.add_argument('-o', '--out', required=True, help='output bag directory')
    parser.add_argument('-n', '--count', type=int, default=50, help='number of scans')
    parser.add_argument('--fov', type=float, default=360.0,
                        help='field of view, degrees, centred forward')
    parser.add_argument('--beams', type=int, default=360, help='beams per scan')
    parser.add_argument('--max-range', type=float, default=30.0, help='sensor range, m')
    parser.add_argument('--noise', type=float, default=0.01, help='range noise sigma, m')
    parser.add_argument('--clearance', type=float, default=0.3,
                        help='minimum distance of the robot to obstacles/unknown, m')
    parser.add_argument('--clutter', type=int, default=0,
                        help='unmapped discs (r 0.1-0.3 m, 1-4 m away) per scan')
    parser.add_argument('--short-fraction', type=float, default=0.0,
                        help='fraction of beams replaced by random short readings')
    parser.add_argument('--sensor-offset', type=float, nargs=3, default=(0.0, 0.0, 0.0),
                        metavar=('X', 'Y', 'YAW'), help='laser pose on the base (m, m, rad)')
    parser.add_argument('--seed', type=int, default=0, help='random seed')
    parser.add_argument('--force', action='store_true', help='overwrite an existing bag')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')


def run(args: argparse.Namespace) -> int:
    cfg = SimulationConfig(count=args.count, beams=args.beams, fov_deg=args.fov,
                           max_range=args.max_range, noise_sigma=args.noise,
                           clearance=args.clearance, clutter=args.clutter,
                           short_fraction=args.short_fraction,
                           sensor_offset=tuple(args.sensor_offset), seed=args.seed)
    cfg.validate()
    if Path(args.out).exists() and not args.force:
        raise ValueError(f'bag exists already (use --force to overwrite): {args.out}')
    occ_map = load_map_yaml(args.map)
    with TqdmProgress('simulate', enabled=not args.quiet) as bar:
        sim = simulate_bag(occ_map, args.out, cfg, overwrite=args.force, progress=bar)
    print(f'bag: {args.out} ({len(sim.scans)} scans, {cfg.beams} beams, fov {cfg.fov_deg:g} deg)')
    return 0
