"""`ssm_localization replay` through cli.main: RESULTS.csv contract, plot, user errors."""
from __future__ import annotations

import csv
import math

from conftest import find_bag
import numpy as np
import pytest
from ssm_localization import read_bag, save_map_yaml, write_bag
from ssm_localization.cli import main

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
    assert rc == 0, capsys.readouterr().err
    _, rows = _read_csv(out)
    assert [r['status'] for r in rows] == ['ok', 'ok']


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
