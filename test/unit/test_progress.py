"""progress.py: the tqdm adapter the command line draws the core's progress callbacks with."""
from __future__ import annotations

from ssm_localization.progress import TqdmProgress


def test_stages_restart_the_bar_and_reach_the_total(capsys):
    with TqdmProgress('index') as bar:
        bar(10, 100, 'topology')
        bar(30, 100, 'topology')
        assert (bar._bar.n, bar._bar.total) == (30, 100)
        bar(40, 100, 'features')            # a new stage on the same 0..100 scale
        assert (bar._bar.n, bar._bar.desc) == (40, 'features')
        bar(3, 7, 'writing bag')            # another job with its own total
        assert (bar._bar.n, bar._bar.total) == (3, 7)
        bar(7, 7, 'writing bag')
    err = capsys.readouterr().err
    assert 'writing bag' in err and '7/7' in err


def test_disabled_bar_prints_nothing(capsys):
    with TqdmProgress('index', enabled=False) as bar:
        for i in range(5):
            bar(i, 5, 'x')
    assert capsys.readouterr().err == ''


def test_a_job_that_fails_before_its_first_report_prints_nothing(capsys):
    try:
        with TqdmProgress('convert'):
            raise ValueError('bad input')
    except ValueError:
        pass
    assert capsys.readouterr().err == ''       # the error line stays the only line
