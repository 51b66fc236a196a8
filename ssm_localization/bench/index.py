"""
``ssm_localization bench index``: index build time and peak memory per map.

Every map is indexed in a fresh subprocess (``python -m ssm_localization.bench.index --worker
SPEC``) so that its peak RSS is honest; the table shows the build wall time, the peak RSS of the
process during the build (``VmHWM`` from /proc, reset after imports and map loading) and its
increase over the RSS before the build.
Maps: the shared nav2 maps, maps built from the shared CARMEN logs (when present; built by
``io.carmen.build_map`` with its defaults, saved as YAML+PGM in a temporary directory), any
``--extra MAP.yaml`` and a deterministic synthetic 100 m x 100 m office at 0.05 m (2000 x 2000).
Targets (2-core machine): depot / turtlebot3_world < 1 s; the office < 10 s and < 1 GB.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from .data import data_dir, DATA_HELP
from ..io.carmen import build_map, read_carmen_log
from ..mapping.index import build_index
from ..mapping.map_io import load_map_yaml, OccupancyMap, save_map_yaml

TARGETS = {'depot': (1.0, None), 'turtlebot3_world': (1.0, None), 'office': (10.0, 1024.0)}


def office_map(size: float = 100.0, resolution: float = 0.05, seed: int = 0):
    """
    Return a deterministic synthetic office (corridors, rooms with doors, furniture, halls).

    ``size`` x ``size`` metres at ``resolution`` (default 2000 x 2000 cells), frame ``map``,
    origin (0, 0, 0). Walls are 0.15 m thick, corridors 2.4 m wide, doors 1 m wide.
    """
    rng = np.random.default_rng(seed)
    n = int(round(size / resolution))
    grid = np.zeros((n, n), dtype=np.int8)

    def cells(v: float) -> int:
        return int(round(v / resolution))

    def box(x0, y0, x1, y1, value=100):
        grid[max(cells(y0), 0):min(cells(y1), n), max(cells(x0), 0):min(cells(x1), n)] = value

    wall, corridor, door = 0.15, 2.4, 1.0
    box(0, 0, size, wall)
    box(0, size - wall, size, size)
    box(0, 0, wall, size)
    box(size - wall, 0, size, size)
    xs = np.arange(12.5, size, 25.0)   # vertical corridor centres
    ys = np.arange(10.0, size, 20.0)   # horizontal corridor centres
    xb = np.concatenate(([wall], xs + corridor / 2))
    xe = np.concatenate((xs - corridor / 2, [size - wall]))
    yb = np.concatenate(([wall], ys + corridor / 2))
    ye = np.concatenate((ys - corridor / 2, [size - wall]))
    for bx0, bx1 in zip(xb, xe):
        for by0, by1 in zip(yb, ye):
            if bx1 - bx0 < 4 or by1 - by0 < 4:
                continue
            kind = rng.random()
            if kind < 0.15:  # open hall with pillars
                for px in np.arange(bx0 + 3.0, bx1 - 2.0, 4.0):
                    for py in np.arange(by0 + 3.0, by1 - 2.0, 4.0):
                        box(px - 0.2, py - 0.2, px + 0.2, py + 0.2)
                continue
            # block outline, two rows of rooms split at mid-height
            box(bx0, by0, bx1, by0 + wall)
            box(bx0, by1 - wall, bx1, by1)
            box(bx0, by0, bx0 + wall, by1)
            box(bx1 - wall, by0, bx1, by1)
            ym = (by0 + by1) / 2
            box(bx0, ym - wall / 2, bx1, ym + wall / 2)
            for lower in (True, False):
                x = bx0
                while x < bx1 - 2.5:
                    width = float(rng.choice([3.0, 4.0, 5.0, 6.0]))
                    x1 = min(x + width, bx1)
                    if bx1 - x1 < 2.5:
                        x1 = bx1
                    if x1 < bx1:
                        box(x1 - wall / 2, by0 if lower else ym, x1 + wall / 2,
                            ym if lower else by1)
                    # door on the corridor side
                    dx = x + float(rng.uniform(0.4, max(0.5, x1 - x - door - 0.4)))
                    if lower:
                        box(dx, by0, dx + door, by0 + wall, 0)
                    else:
                        box(dx, by1 - wall, dx + door, by1, 0)
                    # furniture away from the door side
                    for _ in range(int(rng.integers(0, 3))):
                        fw, fh = rng.uniform(0.5, 1.5, 2)
                        fx = rng.uniform(x + 0.5, max(x + 0.6, x1 - fw - 0.5))
                        fy = (ym - fh - 0.3) if lower else (ym + 0.3)
                        box(fx, fy, fx + fw, fy + fh)
                    x = x1
    return OccupancyMap(grid, resolution, (0.0, 0.0, 0.0), 'map')


def _load(spec: str):
    if spec.startswith('office'):
        return office_map()
    return load_map_yaml(spec)


def _rss_kb(field: str) -> float:
    """
    Read VmRSS / VmHWM (kB) of this process from /proc.

    ru_maxrss where /proc is missing; note that ru_maxrss can carry the parent's peak over fork +
    exec.
    """
    try:
        for line in Path('/proc/self/status').read_text().splitlines():
            if line.startswith(field + ':'):
                return float(line.split()[1])
    except OSError:
        pass
    return float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def _reset_peak() -> None:
    """Reset VmHWM to the current RSS (Linux: ``echo 5 > /proc/self/clear_refs``)."""
    try:
        Path('/proc/self/clear_refs').write_text('5')
    except OSError:
        pass


def _worker(spec: str) -> None:
    """Index one map in this process and print one JSON line."""
    occ_map = _load(spec)
    base = _rss_kb('VmRSS')
    _reset_peak()
    t0 = time.perf_counter()
    index = build_index(occ_map)
    elapsed = time.perf_counter() - t0
    peak = _rss_kb('VmHWM')
    print(json.dumps({'time': elapsed, 'peak_mb': peak / 1024.0,
                      'delta_mb': (peak - base) / 1024.0,
                      'nodes': len(index), 'kinds': index.kind_counts(),
                      'cells': f'{occ_map.width}x{occ_map.height}',
                      'res': occ_map.resolution}))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--extra', action='append', default=[], metavar='MAP.yaml',
                        help='also benchmark this map (repeatable)')
    parser.add_argument('--no-carmen', action='store_true',
                        help='skip the maps built from the shared CARMEN logs')
    parser.add_argument('--no-office', action='store_true',
                        help='skip the synthetic 2000 x 2000 office map')
    parser.add_argument('--repeat', type=int, default=1,
                        help='runs per map; the fastest is reported (default 1)')
    parser.add_argument('--data', default=None,
                        help=DATA_HELP + ' (without it, only --extra maps and the office)')


def _shared_data(arg: str | None) -> Path | None:
    """Return the data directory; None (said on stderr) when the default one is missing."""
    if arg:
        return data_dir(arg)
    try:
        return data_dir()
    except FileNotFoundError as exc:
        print(f'shared maps and CARMEN logs skipped: {exc}', file=sys.stderr)
        return None


def run(args: argparse.Namespace) -> int:
    specs: list[tuple[str, str]] = []
    shared = _shared_data(args.data)
    for name in ('depot', 'tb3_sandbox', 'turtlebot3_world', 'empty_room'):
        if shared and (shared / 'maps' / f'{name}.yaml').is_file():
            specs.append((name, str(shared / 'maps' / f'{name}.yaml')))
    tmp = tempfile.TemporaryDirectory(prefix='ssm_bench_index_')
    if shared and not args.no_carmen:  # built here, so the worker's peak is the build alone
        for log in sorted((shared / 'carmen').glob('*.log.gz')):
            name = log.name.split('-corrected')[0]
            yaml_path = Path(tmp.name) / f'{name}.yaml'
            save_map_yaml(build_map(read_carmen_log(log)), yaml_path)
            specs.append((name, str(yaml_path)))
    for extra in args.extra:
        if not Path(extra).is_file():
            raise FileNotFoundError(f'--extra map not found: {extra}')
        specs.append((Path(extra).stem, extra))
    if not args.no_office:
        specs.append(('office', 'office'))
    print(f'{"map":18s} {"cells":>11s} {"res":>5s} {"nodes":>6s} {"build s":>8s} '
          f'{"peak MB":>8s} {"+MB":>7s}  target')
    failed = False
    for name, spec in specs:
        best = None
        for _ in range(max(args.repeat, 1)):
            proc = subprocess.run([sys.executable, '-m', 'ssm_localization.bench.index',
                                   '--worker', spec], capture_output=True, text=True)
            if proc.returncode != 0:
                print(f'{name:18s} FAILED: {proc.stderr.strip().splitlines()[-1:]}')
                failed = True
                break
            res = json.loads(proc.stdout.strip().splitlines()[-1])
            if best is None or res['time'] < best['time']:
                best = res
        if best is None:
            continue
        t_max, mb_max = TARGETS.get(name, (None, None))
        verdict = ''
        if t_max is not None:
            ok = best['time'] < t_max and (mb_max is None or best['peak_mb'] < mb_max)
            verdict = ('met' if ok else 'MISSED') + f' (< {t_max:g} s' + \
                (f', < {mb_max:g} MB)' if mb_max else ')')
        print(f'{name:18s} {best["cells"]:>11s} {best["res"]:5.2f} {best["nodes"]:6d} '
              f'{best["time"]:8.2f} {best["peak_mb"]:8.0f} {best["delta_mb"]:7.0f}  {verdict}')
    tmp.cleanup()
    return 1 if failed else 0


if __name__ == '__main__':
    if len(sys.argv) == 3 and sys.argv[1] == '--worker':
        _worker(sys.argv[2])
    else:
        sys.exit('usage: python -m ssm_localization.bench.index --worker MAP_SPEC')
