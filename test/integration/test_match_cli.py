"""``ssm_localization match``, the demo, ``plot_match`` and the scan-matching benchmark."""
from __future__ import annotations

import argparse

from helpers import room_scan, shared_data
import numpy as np
import pytest
from ssm_localization.transforms import apply, inverse


def test_plot_match_writes_png(tmp_path):
    pytest.importorskip('matplotlib')
    from ssm_localization import match_scans
    from ssm_localization.evaluation.plotting import plot_match
    ref = room_scan((0.0, 0.0, 0.0))
    truth = (0.2, -0.1, 0.3)
    new = apply(inverse(truth), ref)
    res = match_scans(ref, new)
    out = plot_match(ref, new, res.pose, tmp_path / 'm.png', pairs=res.inliers, truth=truth,
                     title='test')
    assert out.is_file() and out.read_bytes()[:4] == b'\x89PNG'
    # a failed match (NaN pose) still plots
    out2 = plot_match(ref, new, (np.nan, np.nan, np.nan), tmp_path / 'f.png')
    assert out2.is_file()


def test_match_command(tmp_path, capsys):
    pytest.importorskip('matplotlib')
    from ssm_localization.cli import match_cmd
    carmen = shared_data('carmen')
    p = argparse.ArgumentParser()
    match_cmd.add_arguments(p)
    args = p.parse_args([str(carmen / 'freiburg-079-corrected.log.gz'), '--k', '200', '--s', '2',
                         '--offset', '0.3', '-0.2', '20', '--plot', str(tmp_path / 'm.png')])
    assert match_cmd.run(args) == 0
    text = capsys.readouterr().out
    assert 'estimate' in text and 'truth' in text and 'error' in text
    err_mm = float(text.split('error')[1].split('mm')[0])
    assert err_mm < 150
    assert (tmp_path / 'm.png').is_file()
    bad = p.parse_args([str(carmen / 'intel-corrected.log.gz'), '--k', '5000'])
    with pytest.raises(ValueError, match='--k'):
        match_cmd.run(bad)


def test_demo(tmp_path, capsys):
    pytest.importorskip('matplotlib')
    from ssm_localization import demo
    shared_data('carmen', 'intel-corrected.log.gz')
    assert demo.main(['--out', str(tmp_path), '--data', str(shared_data())]) == 0
    assert (tmp_path / 'scan_match.png').is_file()
    assert (tmp_path / 'intel_replay.png').stat().st_size > 0
    rows = (tmp_path / 'intel_results.csv').read_text().splitlines()
    assert rows[0].startswith('stamp,x,y,yaw,status,latency_ms,node,score') and len(rows) > 50
    out = capsys.readouterr().out
    assert 'error' in out and 'success' in out and 'precision' in out


def test_bench_quick_runs(capsys):
    from ssm_localization.bench import scanmatch
    shared_data('carmen', 'freiburg-079-corrected.log.gz')
    p = argparse.ArgumentParser()
    scanmatch.add_arguments(p)
    args = p.parse_args(['--quick', '--only', 'table2', '--trials', '5',
                         '--data', str(shared_data())])
    args.quick = False          # keep --trials 5
    assert scanmatch.run(args) == 0
    out = capsys.readouterr().out
    assert 'Table 2' in out and 'intel' in out and 'freiburg-079' in out
