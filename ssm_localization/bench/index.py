"""
``ssm_localization bench index``: index build time, localizer start-up and memory per map.

Every map is indexed in a fresh subprocess (``python -m ssm_localization.bench.index --worker
SPEC``) so that its memory is honest: the table shows the index build's wall time, the time the
localizer then takes to derive its map layers (``GlobalLocalizer``), the peak RSS of the whole
process (``VmHWM`` from /proc: interpreter, imports, the map, the index and the localizer, as a
user running ``ssm_localization replay`` has them) and its peak during the build alone (reset
after the map is loaded). A second subprocess per map (``--layers`` worker) builds the same with
``tracemalloc`` and prints what each layer costs: the memory it keeps, its peak while built (the
intermediates it frees), in MB and bytes per map cell, and its time under tracing.
Maps: the shared nav2 maps, maps built from the shared CARMEN logs (when present; built by
``io.carmen.build_map`` with its defaults, saved as YAML+PGM in a temporary directory), any
``--extra MAP.yaml``, a deterministic synthetic 100 m x 100 m office at 0.05 m (2000 x 2000);
``--campus`` adds the campus of ``bench/campus.py`` (the six real buildings and three simulated
maps on one 27.6 M-cell grid), the synthetic 274 m office (30 M cells) and the synthetic 270 m
outdoor campus (29 M cells, ``synthetic.outdoor_map``).
Targets (2-core machine): depot / turtlebot3_world < 1 s; the office < 10 s and < 1 GB; the
campus and the two synthetic 30 M-cell maps: index < 30 s, whole process < 2 GB.
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

from .campus import campus_map, office_30m, outdoor_30m
from .data import data_dir, DATA_HELP
from .memory import format_layers, LayerMeter
from .synthetic import office_map
from ..cli.arguments import positive_int
from ..io.carmen import build_map, read_carmen_log
from ..localization.localizer import GlobalLocalizer
from ..mapping.index import build_index
from ..mapping.map_io import load_map_yaml, OccupancyMap, save_map_yaml

__all__ = ['add_arguments', 'run']

#: (index build s, whole-process peak MB) targets by map name
TARGETS = {'depot': (1.0, None), 'turtlebot3_world': (1.0, None), 'office': (10.0, 1024.0),
           'campus': (30.0, 2048.0), 'office_30m': (30.0, 2048.0),
           'outdoor_30m': (30.0, 2048.0)}
#: layers built once and counted with another (the localizer's ray caster is the virtual scans')
SHARED_LAYERS = {'ray caster': 'the caster of the virtual scans, counted there'}
#: map specs that are not YAML files: the synthetic offices, the campus (``campus:DATA:WORK``)
SYNTHETIC = {'office': office_map, 'office_30m': office_30m, 'outdoor_30m': outdoor_30m}


def _load(spec: str) -> OccupancyMap:
    if spec in SYNTHETIC and not Path(spec).is_file():     # a file of that name is the file
        return SYNTHETIC[spec]()
    if spec.startswith('campus:'):
        _, data, work = spec.split(':', 2)
        return campus_map(Path(data), Path(work)).grid
    return load_map_yaml(spec, max_cells=0)


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
    """Index one map and build its localizer in this process; print one JSON line."""
    occ_map = _load(spec)
    loaded = _rss_kb('VmHWM')           # the peak so far: imports and map loading
    _reset_peak()
    t0 = time.perf_counter()
    index = build_index(occ_map)
    t_index = time.perf_counter() - t0
    build_peak = _rss_kb('VmHWM')
    t0 = time.perf_counter()
    GlobalLocalizer(index)
    t_localizer = time.perf_counter() - t0
    whole = max(loaded, _rss_kb('VmHWM'))
    print(json.dumps({'time': t_index, 'localizer_time': t_localizer,
                      'peak_mb': whole / 1024.0, 'build_peak_mb': build_peak / 1024.0,
                      'nodes': len(index), 'kinds': index.kind_counts(),
                      'cells': f'{occ_map.width}x{occ_map.height}',
                      'n_cells': occ_map.width * occ_map.height, 'res': occ_map.resolution}))


def _layers_worker(spec: str) -> None:
    """Build the index and the localizer layer by layer under tracemalloc; print JSON."""
    occ_map = _load(spec)
    meter = LayerMeter()
    index = build_index(occ_map, layer=meter)
    GlobalLocalizer(index, layer=meter)
    print(json.dumps({'map_mb': occ_map.data.nbytes / 1e6, 'layers': meter.as_dicts()}))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--extra', action='append', default=[], metavar='MAP.yaml',
                        help='also benchmark this map (repeatable)')
    parser.add_argument('--no-carmen', action='store_true',
                        help='skip the maps built from the shared CARMEN logs')
    parser.add_argument('--no-office', action='store_true',
                        help='skip the synthetic 2000 x 2000 office map')
    parser.add_argument('--campus', action='store_true',
                        help='also the campus (27.6 M cells: the six real buildings and three '
                             'simulated maps, bench/campus.py), the 30 M-cell synthetic office '
                             'and the 29 M-cell synthetic outdoor campus')
    parser.add_argument('--only-campus', action='store_true',
                        help='only the campus and the two synthetic 30 M-cell maps')
    parser.add_argument('--no-layers', action='store_true',
                        help='skip the per-layer memory breakdown (a second, traced build)')
    parser.add_argument('--repeat', type=positive_int, default=1,
                        help='runs per map; the fastest is reported (default 1)')
    parser.add_argument('--data', default=None,
                        help=DATA_HELP + ' (without it, only --extra maps and the office)')
    parser.add_argument('--work', default='bench_data', help='where the campus map is cached')


def _shared_data(arg: str | None) -> Path | None:
    """Return the data directory; None (said on stderr) when the default one is missing."""
    if arg:
        return data_dir(arg)
    try:
        return data_dir()
    except FileNotFoundError as exc:
        print(f'shared maps and CARMEN logs skipped: {exc}', file=sys.stderr)
        return None


def _specs(args: argparse.Namespace, shared: Path | None, tmp: Path) -> list[tuple[str, str]]:
    """Return ``(name, spec)`` of the maps to benchmark (CARMEN maps built into ``tmp``)."""
    specs: list[tuple[str, str]] = []
    if not args.only_campus:
        for name in ('depot', 'tb3_sandbox', 'turtlebot3_world', 'empty_room'):
            if shared and (shared / 'maps' / f'{name}.yaml').is_file():
                specs.append((name, str(shared / 'maps' / f'{name}.yaml')))
        if shared and not args.no_carmen:  # built here, so the worker's peak is the build alone
            for log in sorted((shared / 'carmen').glob('*.log.gz')):
                name = log.name.split('-corrected')[0]
                yaml_path = tmp / f'{name}.yaml'
                save_map_yaml(build_map(read_carmen_log(log)), yaml_path)
                specs.append((name, str(yaml_path)))
        for extra in args.extra:
            if not Path(extra).is_file():
                raise FileNotFoundError(f'--extra map not found: {extra}')
            specs.append((Path(extra).stem, extra))
        if not args.no_office:
            specs.append(('office', 'office'))
    if args.campus or args.only_campus:
        if shared is None:
            raise FileNotFoundError('--campus needs the shared data (--data DIR)')
        work = Path(args.work)
        campus_map(shared, work)        # built and cached here, not in the timed worker
        specs.append(('campus', f'campus:{shared}:{work}'))
        specs.append(('office_30m', 'office_30m'))
        specs.append(('outdoor_30m', 'outdoor_30m'))
    return specs


def _worker_json(flag: str, spec: str) -> tuple[dict | None, str]:
    proc = subprocess.run([sys.executable, '-m', 'ssm_localization.bench.index', flag, spec],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        return None, (proc.stderr.strip().splitlines() or ['?'])[-1]
    return json.loads(proc.stdout.strip().splitlines()[-1]), ''


def run(args: argparse.Namespace) -> int:
    shared = _shared_data(args.data)
    tmp = tempfile.TemporaryDirectory(prefix='ssm_bench_index_')
    specs = _specs(args, shared, Path(tmp.name))
    print(f'{"map":18s} {"cells":>11s} {"res":>5s} {"nodes":>6s} {"index s":>8s} '
          f'{"local. s":>8s} {"peak MB":>8s} {"build MB":>8s}  target')
    failed = False
    breakdowns = []
    for name, spec in specs:
        best = None
        for _ in range(max(args.repeat, 1)):
            res, error = _worker_json('--worker', spec)
            if res is None:
                print(f'{name:18s} FAILED: {error}')
                failed = True
                break
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
              f'{best["time"]:8.2f} {best["localizer_time"]:8.2f} {best["peak_mb"]:8.0f} '
              f'{best["build_peak_mb"]:8.0f}  {verdict}', flush=True)
        if not args.no_layers:
            layers, error = _worker_json('--layers', spec)
            breakdowns.append((name, best['n_cells'], layers, error))
    for name, cells, layers, error in breakdowns:
        if layers is None:
            print(f'{name}: layer breakdown FAILED: {error}')
            failed = True
            continue
        print(f'{name}: memory per layer ({cells / 1e6:.1f} M cells; the map itself '
              f'{layers["map_mb"]:.1f} MB; traced, so slower)')
        print(format_layers(layers['layers'], cells, SHARED_LAYERS))
    tmp.cleanup()
    return 1 if failed else 0


if __name__ == '__main__':
    if len(sys.argv) == 3 and sys.argv[1] == '--worker':
        _worker(sys.argv[2])
    elif len(sys.argv) == 3 and sys.argv[1] == '--layers':
        _layers_worker(sys.argv[2])
    else:
        sys.exit('usage: python -m ssm_localization.bench.index --worker|--layers MAP_SPEC')
