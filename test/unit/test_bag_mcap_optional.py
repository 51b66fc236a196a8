"""
``mcap`` is optional (rosdistro has no key for it).

Without it a damaged bag gets an error saying what to install, and intact bags read as before
(rosbags reads mcap itself).
"""
from __future__ import annotations

import math
import shutil
import sys

import numpy as np
import pytest
from ssm_localization.io.bag_reader import MCAP_MISSING, read_bag
from ssm_localization.io.bag_records import ScanRecord
from ssm_localization.io.bag_writer import write_bag


@pytest.fixture
def without_mcap(monkeypatch):
    """Make ``import mcap`` fail as on a system where it is not installed."""
    for name in [m for m in sys.modules if m == 'mcap' or m.startswith('mcap.')]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, 'mcap', None)


def test_damaged_bag_without_mcap_names_the_missing_package(tmp_path, without_mcap):
    rng = np.random.default_rng(0)
    scans = [ScanRecord.from_ranges(10.0 + 0.1 * k, rng.uniform(1, 5, 360), -math.pi,
                                    math.pi / 180) for k in range(600)]
    path = write_bag(tmp_path / 'bag', scans=scans, compress=False)
    assert len(read_bag(path).scans) == len(scans)          # intact: no mcap needed
    cut = tmp_path / 'cut'
    shutil.copytree(path, cut)
    mcap_file = next(cut.glob('*.mcap'))
    with open(mcap_file, 'r+b') as fh:
        fh.truncate(mcap_file.stat().st_size // 2)
    with pytest.raises(ValueError, match='truncated or corrupt') as info:
        read_bag(cut)
    assert MCAP_MISSING in str(info.value) and 'pip install mcap' in str(info.value)
