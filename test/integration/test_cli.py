"""
Test `ssm_localization replay` through cli.main.

RESULTS.csv contract, plot, user errors; ``--track`` and ``bench track``.
"""
from __future__ import annotations

import csv
import math
import re

from helpers import find_bag, shared_data
import numpy as np
import pytest
from ssm_localization import read_bag, save_map_yaml, write_bag
from ssm_localization.cli.main import main
from ssm_localization.config.confidence import CONFIDENCE_MODEL
from ssm_localization.config.localization import LocalizerConfig
from ssm_localization.mapping.map_io import OccupancyMap

REQUIRED = ['stamp', 'x', 'y', 'yaw', 'status', 'latency_ms', 'node', 'score']


@pytest.fixture(scope='module')
def depot_bag():
    path = find_bag('depot_sim')
    return path, read_bag(path)


def _read_csv(path):
    with open(path, newline='') as fh:
        rows = list(csv.reader(fh))
    return rows[0], [dict(zip(rows[0], r)) for r in rows[1:]]


def test_replay_cli_writes_results_and_plot(depot_bag, tmp_path, capsys):
    path, bag = depot_bag
    out, png = tmp_path / 'out.csv', tmp_path / 'out.png'
    rc = main(['replay', str(path), '-o', str(out), '--plot', str(png), '--limit', '5',
               '--quiet'])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    header, rows = _read_csv(out)
    assert header[:len(REQUIRED)] == REQUIRED
    assert len(rows) == 5
    assert [float(r['stamp']) for r in rows] == pytest.approx([s.stamp for s in bag.scans[:5]])
    for r in rows:
        assert r['status'] in ('ok', 'ambiguous', 'failed')
        assert float(r['latency_ms']) > 0
        int(r['node'])
        float(r['score'])
        if r['status'] == 'ok':
            truth = bag.ground_truth[float(r['stamp'])]
            assert math.hypot(float(r['x']) - truth[0], float(r['y']) - truth[1]) < 0.5
    assert sum(r['status'] == 'ok' for r in rows) >= 4
    assert png.is_file() and png.stat().st_size > 1000
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert 'success' in captured.out                 # /ground_truth present: figures printed


def test_replay_cli_with_map_file_on_a_bag_without_map(depot_bag, tmp_path, capsys):
    _, bag = depot_bag
    no_map = tmp_path / 'no_map'
    write_bag(no_map, map=None, scans=bag.scans[:2],
              ground_truth={s.stamp: bag.ground_truth[s.stamp] for s in bag.scans[:2]})
    out = tmp_path / 'out.csv'
    # no /map and no --map: a clear error, exit code 2, nothing written
    rc = main(['replay', str(no_map), '-o', str(out), '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2
    assert '/map' in err and '--map' in err and 'Traceback' not in err
    assert not out.exists()
    # with --map it works
    map_yaml = tmp_path / 'depot.yaml'
    save_map_yaml(bag.map, map_yaml)
    rc = main(['replay', str(no_map), '-o', str(out), '--map', str(map_yaml), '--quiet'])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert 'coarser' not in captured.out
    _, rows = _read_csv(out)
    assert [r['status'] for r in rows] == ['ok', 'ok']
    # the same map at 0.1 m cells (each 2 x 2 block occupied if any cell is): told so
    d = bag.map.data[:bag.map.height // 2 * 2, :bag.map.width // 2 * 2]
    blocks = d.reshape(d.shape[0] // 2, 2, d.shape[1] // 2, 2)
    coarse = np.where((blocks >= 65).any(axis=(1, 3)), 100,
                      np.where((blocks >= 0).any(axis=(1, 3)), 0, -1)).astype(np.int8)
    coarse_yaml = tmp_path / 'depot_10cm.yaml'
    save_map_yaml(OccupancyMap(coarse, 0.1, bag.map.origin), coarse_yaml)
    rc = main(['replay', str(no_map), '-o', str(out), '--map', str(coarse_yaml), '--quiet'])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "note: the map's cells are 0.1 m, coarser than the 0.05 m" in captured.out


def test_replay_cli_bag_without_scans(depot_bag, tmp_path, capsys):
    _, bag = depot_bag
    map_only = tmp_path / 'map_only'
    write_bag(map_only, map=bag.map)
    rc = main(['replay', str(map_only), '-o', str(tmp_path / 'out.csv'), '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2
    assert '/scan' in err and err.startswith('ssm_localization replay: error:')


def test_replay_cli_unknown_scan_topic(depot_bag, tmp_path, capsys):
    path, _ = depot_bag
    rc = main(['replay', str(path), '-o', str(tmp_path / 'out.csv'), '--scan-topic', '/laser',
               '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2 and '/laser' in err


def test_replay_cli_missing_bag(tmp_path, capsys):
    rc = main(['replay', str(tmp_path / 'nowhere'), '-o', str(tmp_path / 'out.csv')])
    err = capsys.readouterr().err
    assert rc == 2 and 'nowhere' in err


def test_replay_cli_bad_params(depot_bag, tmp_path, capsys):
    path, _ = depot_bag
    params = tmp_path / 'p.yaml'
    params.write_text('localizer: {top_nn: 3}\n')
    rc = main(['replay', str(path), '-o', str(tmp_path / 'out.csv'), '--params', str(params),
               '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2 and 'top_nn' in err


def test_replay_cli_params_are_used(depot_bag, tmp_path, capsys):
    """--params reaches the localizer: min_points above the beam count fails every scan."""
    path, _ = depot_bag
    params = tmp_path / 'p.yaml'
    params.write_text('global_localizer:\n  ros__parameters:\n'
                      '    localizer: {min_points: 100000}\n')
    out = tmp_path / 'out.csv'
    rc = main(['replay', str(path), '-o', str(out), '--params', str(params), '--limit', '2',
               '--quiet'])
    assert rc == 0, capsys.readouterr().err
    _, rows = _read_csv(out)
    assert [r['status'] for r in rows] == ['failed', 'failed']
    assert all(r['x'] in ('', 'nan') and r['node'] == '-1' for r in rows)


def test_replay_cli_requires_output(depot_bag):
    path, _ = depot_bag
    with pytest.raises(SystemExit) as info:
        main(['replay', str(path)])
    assert info.value.code == 2


def test_replay_cli_index_file(depot_bag, tmp_path, capsys):
    path, _ = depot_bag
    index = tmp_path / 'depot.npz'
    map_yaml = tmp_path / 'depot.yaml'
    save_map_yaml(depot_bag[1].map, map_yaml)
    assert main(['index', str(map_yaml), '-o', str(index)]) == 0
    out = tmp_path / 'out.csv'
    rc = main(['replay', str(path), '-o', str(out), '--index', str(index), '--limit', '2',
               '--quiet'])
    assert rc == 0, capsys.readouterr().err
    _, rows = _read_csv(out)
    assert len(rows) == 2 and all(r['status'] == 'ok' for r in rows)
    assert np.isfinite([float(r['x']) for r in rows]).all()


# --------------------------------------------------------------------------- --track

@pytest.fixture(scope='module')
def intel_track():
    path = find_bag('intel_track')
    return path, read_bag(path)


def _right(row, bag) -> bool:
    truth = bag.ground_truth[float(row['stamp'])]
    return (row['status'] == 'ok'
            and math.hypot(float(row['x']) - truth[0], float(row['y']) - truth[1]) <= 0.5
            and abs(math.remainder(float(row['yaw']) - truth[2], 2 * math.pi))
            <= math.radians(5))


def test_replay_track_writes_one_row_per_scan_and_recovers(intel_track, tmp_path, capsys):
    path, bag = intel_track
    out = tmp_path / 'track.csv'
    rc = main(['replay', str(path), '-o', str(out), '--track', '--quiet'])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    header, rows = _read_csv(out)
    assert header[:len(REQUIRED)] == REQUIRED and 'mode' in header
    assert len(rows) == len(bag.scans) == 180
    assert [float(r['stamp']) for r in rows] == pytest.approx([s.stamp for s in bag.scans])
    assert all(float(r['latency_ms']) > 0 for r in rows)
    assert {r['mode'] for r in rows} <= {'tracked', 'relocalized', 'lost'}
    assert sum(r['mode'] == 'tracked' for r in rows) >= 170
    success = sum(_right(r, bag) for r in rows) / len(rows)
    assert success >= 0.97
    wrong = [r['stamp'] for r in rows if r['status'] == 'ok' and not _right(r, bag)]
    assert len(wrong) <= 1, wrong
    line = next(ln for ln in captured.out.splitlines() if ln.startswith('track:'))
    assert 'success' in line and 'precision' in line and 'first fix 1 ' in line, line
    recoveries = re.search(r'recoveries ([0-9, ]+|-) \|', line).group(1)
    counts = [int(v) for v in recoveries.split(',')]
    assert len(counts) >= 2 and max(counts) <= 3, line       # the two kidnaps, at least


def test_replay_track_without_odometry(intel_track, tmp_path, capsys):
    path, bag = intel_track
    no_odom = tmp_path / 'no_odom'
    scans = bag.scans[:40]
    write_bag(no_odom, map=bag.map, scans=scans,
              ground_truth={s.stamp: bag.ground_truth[s.stamp] for s in scans})
    out = tmp_path / 'track.csv'
    rc = main(['replay', str(no_odom), '-o', str(out), '--track', '--quiet'])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert 'tracking without odometry (no /odom in the bag)' in captured.out
    _, rows = _read_csv(out)
    assert len(rows) == 40
    ok = [r for r in rows if r['status'] == 'ok']
    assert len(ok) >= 36 and sum(_right(r, bag) for r in ok) >= len(ok) - 1
    rc = main(['replay', str(path), '-o', str(out), '--track', '--no-odom', '--limit', '5',
               '--quiet'])
    assert rc == 0 and 'tracking without odometry (--no-odom)' in capsys.readouterr().out


def test_replay_track_interpolates_odometry_at_another_rate(intel_track, tmp_path, capsys):
    """/odom at 5 Hz, offset from the scans: interpolated at the scans' stamps as the node does."""
    path, bag = intel_track
    scans = bag.scans[:40]
    stamps = np.array([s.stamp for s in scans])
    poses = np.array([bag.odom[s] for s in stamps])
    times = np.arange(stamps[0] - 0.13, stamps[-1] + 0.2, 0.2)
    yaw = np.interp(times, stamps, np.unwrap(poses[:, 2]))
    odom = {float(t): (float(np.interp(t, stamps, poses[:, 0])),
                       float(np.interp(t, stamps, poses[:, 1])),
                       float(math.remainder(a, math.tau)))
            for t, a in zip(times, yaw)
            if np.abs(stamps - t).min() > 0.005                     # no stamp shared with a scan
            and not any(abs(t - stamps[k]) < 1.0 for k in (10, 11))}     # none near two scans
    odd = tmp_path / 'odom_5hz'
    write_bag(odd, map=bag.map, scans=scans, odom=odom,
              ground_truth={s.stamp: bag.ground_truth[s.stamp] for s in scans})
    out = tmp_path / 'track.csv'
    rc = main(['replay', str(odd), '-o', str(out), '--track', '--quiet'])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert 'tracking without odometry on 2 of 40 scans' in captured.out, captured.out
    _, rows = _read_csv(out)
    assert len(rows) == 40 and sum(r['mode'] == 'tracked' for r in rows) >= 36
    assert sum(_right(r, bag) for r in rows) >= 38


def test_replay_track_without_a_map_is_a_clear_error(intel_track, tmp_path, capsys):
    _, bag = intel_track
    no_map = tmp_path / 'no_map'
    write_bag(no_map, map=None, scans=bag.scans[:3])
    rc = main(['replay', str(no_map), '-o', str(tmp_path / 'o.csv'), '--track', '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2 and 'no /map message' in err, err
    assert not (tmp_path / 'o.csv').exists()


def test_replay_track_refuses_bad_tracker_params(intel_track, tmp_path, capsys):
    path, _ = intel_track
    params = tmp_path / 'p.yaml'
    params.write_text('tracker:\n  odom_alphas: [0.1, 0.1, -1.0, 0.1]\n')
    rc = main(['replay', str(path), '-o', str(tmp_path / 'o.csv'), '--track', '--params',
               str(params), '--quiet'])
    err = capsys.readouterr().err
    assert rc == 2 and 'odom_alphas' in err, err


def test_bench_track_kidnaps_the_short_laser_too(tmp_path, capsys):
    data = shared_data()
    shared_data('carmen', 'aces-corrected.log.gz')
    rc = main(['bench', 'track', '--sets', 'aces', '--scans', '40', '--data', str(data),
               '--work', str(tmp_path / 'work'), '--max-range', '3.5', '--random-kidnaps', '2'])
    out = capsys.readouterr().out
    assert rc == 0
    assert [ln.split(':')[0] for ln in out.splitlines() if 'random kidnaps' in ln] == [
        '  random kidnaps', '  random kidnaps at 3.5 m'], out
    for line in (ln for ln in out.splitlines() if 'random kidnaps' in ln):
        assert re.search(r': 2, wrong ok after them \d+, recovered within 3 scans \d/2', line)


def test_bench_track_prints_both_sequences_and_the_targets(tmp_path, capsys):
    data = shared_data()
    shared_data('carmen', 'aces-corrected.log.gz')
    rc = main(['bench', 'track', '--sets', 'aces', '--scans', '60', '--data', str(data),
               '--work', str(tmp_path / 'work'), '--plot-dir', str(tmp_path / 'plots'),
               '--reliability', str(tmp_path / 'rel.png')])
    out = capsys.readouterr().out
    assert rc == 0
    real = next(ln for ln in out.splitlines() if ln.startswith('aces   real'))
    kidnap = next(ln for ln in out.splitlines() if ln.startswith('aces   kidnap'))
    assert 'n=60 ' in real and 'n=36 ' in kidnap, out
    counts = re.search(r'recoveries ([0-9, ]+) \|', kidnap).group(1).split(',')
    assert len(counts) == 2 and all(1 <= int(c) <= 3 for c in counts), kidnap
    assert out.count('targets:') == 2
    # the odometry noise each tracked sequence learnt (ACES: better odometry than the alphas)
    learnt = re.findall(r'odometry noise learnt .*: position ([0-9.]+), heading ([0-9.]+), from '
                        r'the last (\d+) steps', out)
    assert len(learnt) == 2 and all(int(n) >= 10 for _, _, n in learnt), out
    assert all(float(pos) < 1.0 for pos, _, _ in learnt), learnt
    assert sorted(p.name for p in (tmp_path / 'plots').iterdir()) == [
        'track_aces_kidnap.png', 'track_aces_real.png']
    assert (tmp_path / 'work' / 'aces_even.yaml').is_file()
    # the tracker's confidence against the fraction right: every answer of both sequences
    # (ACES is a tuning log), binned; the bins' counts add up to them, the ok ones at the top
    head = re.search(r"reliability of the tracker's confidence, tuning split \((\d+) answers",
                     out)
    assert head and int(head.group(1)) == 60 + 36, out
    bins = re.findall(r'^  (\d\.\d\d)-(\d\.\d\d) +(\d+) +([0-9.]+) +([0-9.]+)', out, re.M)
    assert sum(int(n) for *_, n, _, _ in bins) == 96, out
    ok = sum(int(m.group(1)) for m in re.finditer(r' ok=(\d+) ', out))
    assert sum(int(n) for lo, _, n, _, _ in bins if float(lo) >= 0.9) >= ok
    assert (tmp_path / 'rel.png').stat().st_size > 0


def test_bench_localize_writes_every_answer_it_graded(tmp_path, capsys):
    # --answers: one CSV row per answer the reliability table pools (own scans through every
    # sensor, foreign scans), with what decided it; the rows agree with the printed figures
    data = shared_data()
    out_csv = tmp_path / 'answers.csv'
    rc = main(['bench', 'localize', '--sets', 'turtlebot3_world', 'depot_clutter', '-n', '3',
               '--sensors', 'full', 'fov90', '--foreign', '--foreign-places', 'depot',
               'turtlebot3_world', 'empty_room', '--foreign-n', '2', '--answers', str(out_csv),
               '--data', str(data), '--work', str(tmp_path / 'work')])
    out = capsys.readouterr().out
    assert rc == 0
    with out_csv.open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 * 2 * 3 + 6 * 2, out
    pooled = {m.group(1): int(m.group(2))
              for m in re.finditer(r'reliability, (\w+) split \((\d+) answers', out)}
    assert pooled == {split: sum(r['split'] == split for r in rows)
                      for split in ('tuning', 'validation')}, out
    for name, sensor in (('turtlebot3_world', 'full'), ('depot_clutter', 'fov90')):
        label = re.escape(name if sensor == 'full' else f'{name}+{sensor}')
        line = re.search(rf'^{label} +ssm .*ok=(\d+) ', out, re.M)
        mine = [r for r in rows if r['set'] == name and r['sensor'] == sensor]
        assert line and len(mine) == 3, out
        assert sum(r['status'] == 'ok' for r in mine) == int(line.group(1))
    for r in rows:
        confidence = float(r['confidence'])
        if r['kind'] == 'foreign':
            assert r['right'] == '0' and r['map'] != r['source'] and r['error_xy'] == ''
        if r['status'] == 'ok':
            assert r['decided_by'] == 'confidence'
            assert confidence >= LocalizerConfig().min_confidence
        if r['decided_by'] == 'rival':          # a pair at most CONFIDENCE_MODEL.pair
            k = int(r['look_alikes'])
            assert k >= 2
            assert confidence <= CONFIDENCE_MODEL.rival_cap(k) + 1e-6
        if r['decided_by'] == 'no pose':
            assert confidence == 0.0 and r['explained'] == ''
        else:
            assert 0.0 <= float(r['explained']) <= 1.0


def test_bench_localize_prints_the_foreign_ok_rate_of_both_searches(tmp_path, capsys):
    # three simulated places, two scans of each on the maps of the two others; with --peer the
    # exhaustive search localizes the same foreign scans and its ok rate is printed beside ours
    data = shared_data()
    rc = main(['bench', 'localize', '--sets', 'turtlebot3_world', '-n', '3', '--foreign',
               '--foreign-places', 'depot', 'turtlebot3_world', 'empty_room', '--foreign-n', '2',
               '--peer', '--data', str(data), '--work', str(tmp_path / 'work')])
    out = capsys.readouterr().out
    assert rc == 0
    maps = re.findall(r'map (\w+) +\[\w+\] ok of 2: (.*)', out)
    peers = re.findall(r'map (\w+) +exhaustive search, ok of 2: (.*)', out)
    assert [m for m, _ in maps] == [m for m, _ in peers] == ['depot', 'turtlebot3_world',
                                                             'empty_room'], out
    for (_, ours), (_, theirs) in zip(maps, peers):
        assert len(ours.split(', ')) == len(theirs.split(', ')) == 2
    total = re.search(r'foreign pairs, all: ok (\d+) of (\d+) = [0-9.]+%; exhaustive search: '
                      r'ok (\d+) of (\d+) = [0-9.]+%', out)
    assert total, out
    assert int(total.group(2)) == int(total.group(4)) == 12
    assert int(total.group(3)) == sum(int(c.rsplit(' ', 1)[1]) for _, t in peers
                                      for c in t.split(', '))
    # and the exhaustive search with this package's verdict, on the same scans
    fulls = re.findall(r'map (\w+) +exhaustive search with this verdict, ok of 2: (.*)', out)
    assert [m for m, _ in fulls] == [m for m, _ in maps], out
    full = re.search(r'foreign pairs, all: .*; with this verdict: ok (\d+) of (\d+) = ', out)
    assert full and int(full.group(2)) == 12, out
    assert int(full.group(1)) == sum(int(c.rsplit(' ', 1)[1]) for _, t in fulls
                                     for c in t.split(', '))


def test_bench_localize_peer_compares_both_exhaustive_searches(tmp_path, capsys):
    # --peer on a building's own scans: the exhaustive search with its own verdict and with this
    # package's (every yaw searched, the rest the package's), each compared on the same queries
    rc = main(['bench', 'localize', '--sets', 'turtlebot3_world', '-n', '4', '--peer',
               '--data', str(shared_data()), '--work', str(tmp_path / 'work')])
    out = capsys.readouterr().out
    assert rc == 0
    lines = {m.group(1): (int(m.group(2)), float(m.group(3)))
             for m in re.finditer(r'^turtlebot3_world +(ssm|peer|peer-v) +\[valid\] n= +(\d+) '
                                  r'.*\| success ([0-9.]+)%', out, re.M)}
    assert set(lines) == {'ssm', 'peer', 'peer-v'} and {n for n, _ in lines.values()} == {4}, out
    for what, label in (('peer', 'peer'), ('the exhaustive search with this verdict', 'peer-v')):
        line = re.search(rf'^  vs {what}: success ([0-9.]+)% vs ([0-9.]+)%.* -> success within '
                         r'1 point \(([-+][0-9.]+)\) (yes|NO)', out, re.M)
        assert line, out
        assert float(line.group(2)) == lines[label][1]
        gap = float(line.group(1)) - float(line.group(2))
        assert abs(float(line.group(3)) - gap) < 0.051
        assert (line.group(4) == 'yes') == (gap >= -1.0)


def test_out_of_memory_is_one_line_and_status_2(tmp_path, capsys, monkeypatch):
    """Settings that ask for more memory than there is (index.beams 10^8): no traceback."""
    from ssm_localization.cli import index_cmd

    def hungry(*args, **kwargs):
        raise MemoryError('Unable to allocate 92.4 GiB for an array')

    monkeypatch.setattr(index_cmd, 'build_index', hungry)
    path = tmp_path / 'room.yaml'
    data = np.zeros((40, 40), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    save_map_yaml(OccupancyMap(data, 0.05), path)
    assert main(['index', str(path), '-o', str(tmp_path / 'i.npz'), '--quiet']) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'error: out of memory (Unable to allocate 92.4 GiB' in err[0]
