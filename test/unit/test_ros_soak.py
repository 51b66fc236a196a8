"""ros/soak.py: the soak verdict (the soak itself runs for minutes: `bench soak`)."""
from __future__ import annotations

import os

from ssm_localization.ros.soak import report, rss_mb, Sample


def _samples(rss):
    return [Sample(t=5.0 * (k + 1), rss_mb=v, pose_rate=9.5) for k, v in enumerate(rss)]


def test_flat_memory_passes_and_growth_fails(capsys):
    assert report(_samples([100, 180, 200, 201, 203, 202, 204]), 15.0, 0.10) == 0
    assert 'flat within 10%: yes' in capsys.readouterr().out
    assert report(_samples([100, 200, 205, 215, 225, 240]), 15.0, 0.10) == 1
    assert 'flat within 10%: NO' in capsys.readouterr().out


def test_too_short_a_soak_has_no_verdict(capsys):
    assert report(_samples([100, 110]), 60.0, 0.10) == 1
    assert 'too short' in capsys.readouterr().out


def test_rss_of_this_process():
    assert 10.0 < rss_mb(os.getpid()) < 10000.0
