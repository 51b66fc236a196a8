"""``ssm_localization bench localize``: global localization figures per data set.

Data sets (``--sets``):
- ``depot``, ``tb3_sandbox``, ``turtlebot3_world``: the paper protocol (section V.B): random poses
  in free space, 360 beams over 360 deg, range noise sigma 10 mm;
- ``depot_clutter``: 8 unmapped discs near the robot and 5 % random short ranges;
- ``depot_fov180``: a 180 deg field of view;
- ``intel``, ``aces``, ``fr079``: real scans; the map is built from the even-numbered scans of the
  CARMEN log, the queries are the odd-numbered scans (ground truth: the corrected poses).
Simulated scans stop at the first occupied cell's boundary, so those sets use the ``boundary``
wall model (``surface_depth = 0``); the real sets use wall centres (``0.5``). See localization/refine.py.

Prints per set: success (ok and within 0.5 m / 5 deg), precision (correct / answered ok), median
and mean x, y, yaw errors, latency p50/p95; with ``--paper`` also the plain paper pipeline
(all nodes ranked, N = 5, RANSAC + least squares, largest vicinity score, always ``ok``).
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from ..config.params import load_configs
from ..config.simulation import SimulationConfig
from ..evaluation.plotting import plot_replay
from ..evaluation.replay import replay_scans, summarize
from ..io.carmen import build_map, log_scan_records, read_carmen_log
from ..io.simulate import simulate
from ..localization.localizer import GlobalLocalizer
from ..mapping.index import build_index
from ..mapping.map_io import load_map_yaml, save_map_yaml

SIM_SETS = {
    'depot': ('depot', {}),
    'tb3_sandbox': ('tb3_sandbox', {}),
    'turtlebot3_world': ('turtlebot3_world', {}),
    'depot_clutter': ('depot', {'clutter': 8, 'short_fraction': 0.05}),
    'depot_fov180': ('depot', {'fov_deg': 180.0}),
}
REAL_SETS = {'intel': 'intel', 'aces': 'aces', 'fr079': 'freiburg-079'}
DEFAULT_SETS = list(SIM_SETS) + list(REAL_SETS)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--sets', nargs='+', default=DEFAULT_SETS, choices=DEFAULT_SETS + ['all'])
    parser.add_argument('-n', type=int, default=500, help='queries per simulated set')
    parser.add_argument('--real-max', type=int, default=0,
                        help='at most this many real queries per log (0 = all odd scans)')
    parser.add_argument('--quick', action='store_true', help='-n 60 and --real-max 60')
    parser.add_argument('--paper', action='store_true', help='also run the plain paper pipeline')
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--data', default=None, help='shared data dir (default ../shared/data)')
    parser.add_argument('--work', default='bench_data', help='where generated maps are cached')
    parser.add_argument('--params', help='params YAML applied to every set')
    parser.add_argument('--plot-dir', help='write one replay plot per set here')


def _data_dir(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    here = Path(__file__).resolve().parents[2]
    for cand in (here.parent / 'shared' / 'data', Path.cwd().parent / 'shared' / 'data'):
        if cand.exists():
            return cand
    raise FileNotFoundError('shared data not found; pass --data')


def _sim_queries(grid, n: int, seed: int, extra: dict):
    sim = simulate(grid, SimulationConfig(count=n, seed=seed, **extra))
    truth = {s.stamp: tuple(float(v) for v in p) for s, p in zip(sim.scans, sim.poses)}
    return sim.scans, truth


def _real_queries(data: Path, work: Path, name: str, limit: int):
    log = read_carmen_log(data / 'carmen' / f'{name}-corrected.log.gz')
    map_yaml = work / f'{name}_even.yaml'
    if map_yaml.exists():
        grid = load_map_yaml(map_yaml)
    else:
        grid = build_map(log, indices=range(0, len(log), 2))
        work.mkdir(parents=True, exist_ok=True)
        save_map_yaml(grid, map_yaml)
    odd = list(range(1, len(log), 2))
    if limit and len(odd) > limit:
        step = len(odd) / limit
        odd = [odd[int(i * step)] for i in range(limit)]
    scans = log_scan_records(log, odd)
    truth = {s.stamp: tuple(float(v) for v in log.poses[k]) for s, k in zip(scans, odd)}
    return grid, scans, truth


def run(args: argparse.Namespace) -> int:
    if args.quick:
        args.n, args.real_max = 60, 60
    sets = DEFAULT_SETS if 'all' in args.sets else args.sets
    data, work = _data_dir(args.data), Path(args.work)
    index_cfg, loc_cfg = load_configs(args.params)
    indexes: dict[str, object] = {}
    lines = []
    for name in sets:
        t0 = time.perf_counter()
        if name in SIM_SETS:
            map_name, extra = SIM_SETS[name]
            grid = load_map_yaml(data / 'maps' / f'{map_name}.yaml')
            scans, truth = _sim_queries(grid, args.n, args.seed, extra)
            depth = 0.0
        else:
            map_name = name
            grid, scans, truth = _real_queries(data, work, REAL_SETS[name], args.real_max)
            depth = 0.5
        if map_name not in indexes:
            indexes[map_name] = build_index(grid, index_cfg)
        index = indexes[map_name]
        variants = [('ssm', dataclasses.replace(loc_cfg, surface_depth=depth))]
        if args.paper:
            variants.append(('paper', dataclasses.replace(loc_cfg, paper_mode=True, top_n=5)))
        for label, cfg in variants:
            loc = GlobalLocalizer(index, cfg)
            rows = replay_scans(loc, scans, truth, progress=False)
            line = summarize(rows).format(f'{name:17s} {label:5s} nodes={len(index.features):4d}')
            print(line, flush=True)
            lines.append(line)
            if args.plot_dir and label == 'ssm':
                Path(args.plot_dir).mkdir(parents=True, exist_ok=True)
                plot_replay(index, rows, Path(args.plot_dir) / f'{name}.png', title=name)
        print(f'  ({name}: {time.perf_counter() - t0:.0f} s)', flush=True)
    return 0
