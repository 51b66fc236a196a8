"""The thread helpers: one BLAS thread by default, work shared among a few threads."""
from __future__ import annotations

import os
import threading
import time

import pytest
from ssm_localization.threads import in_parts, limit_blas_threads, THREAD_VARIABLES, worker_count


def test_limit_blas_threads_sets_only_what_is_unset():
    env = {'OMP_NUM_THREADS': '4'}
    unset = limit_blas_threads(env)
    assert set(unset) == set(THREAD_VARIABLES) - {'OMP_NUM_THREADS'}
    assert env['OMP_NUM_THREADS'] == '4' and env['OPENBLAS_NUM_THREADS'] == '1'


def test_worker_count_is_every_core_for_minus_one():
    assert worker_count(-1) == (os.cpu_count() or 1)
    assert worker_count(3) == 3


@pytest.mark.parametrize('n, workers', [(10, 2), (10, 3), (7, 7), (3, 8), (1, 2), (0, 2),
                                        (5, 1)])
def test_the_parts_cover_the_range_once_each(n, workers):
    seen = []

    def task(start, stop):
        seen.append((start, stop))

    in_parts(task, n, workers)
    returned = len(seen)
    time.sleep(0.05)
    assert len(seen) == returned                                # no part after the return
    covered = sorted(i for a, b in seen for i in range(a, b))
    assert covered == list(range(n))
    assert len(seen) == (1 if min(workers, n) <= 1 else min(4 * workers, n))


def test_a_stalled_thread_holds_up_only_the_part_it_took():
    """A thread not scheduled (here: sleeping) does not keep a fixed share of the parts."""
    main = threading.current_thread()
    taken = []

    def task(start, stop):
        taken.append(threading.current_thread() is main)
        if threading.current_thread() is not main:
            time.sleep(0.3)

    in_parts(task, 80, 2)
    assert len(taken) == 8 and taken.count(False) <= 1 and taken.count(True) >= 7


def test_an_error_in_another_thread_is_raised_in_the_caller():
    def task(start, stop):
        if start == 0:
            raise ValueError('part one')

    with pytest.raises(ValueError, match='part one'):
        in_parts(task, 10, 2)
