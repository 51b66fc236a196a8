"""
One BLAS/OpenMP thread for the processes this package starts, unless the user chose otherwise.

The package's matrix products are small (100 x 32 by 32 x 20000 at most). On a 2-core machine
with other work on it, the worker threads of a multithreaded BLAS spin against the main thread
and every stage slows down: measured on Intel with another process busy, localization p50 46 ms
with one thread and 103 ms with OpenBLAS's default.

BLAS libraries read these variables once, when numpy loads them, so they are set where a process
starts, before numpy is imported: by the console scripts (``ssm_localization``,
``global_localizer``, ``map_indexer``; see ``entry_points.py``). Importing the package changes
nothing. Set ``OPENBLAS_NUM_THREADS`` (or ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``) before
starting to override; a program that imports the library can call :func:`limit_blas_threads`
before it imports numpy to get the same default.

One stage is the exception, by its own parameter: the pose votes' k-d tree query runs in
``localizer.vote_workers`` (2) threads of scipy's, which split the query points among them and
are joined when it returns (nothing spins). Paired per query, with the other core idle and with
it busy, the answers are the same and the time not worse (docs/EXPERIMENTS.md, 2026-12-02).
"""
from __future__ import annotations

import os
from typing import MutableMapping

THREAD_VARIABLES = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')


def limit_blas_threads(environ: MutableMapping[str, str] | None = None) -> list[str]:
    """
    Set each of :data:`THREAD_VARIABLES` that is not set to ``'1'``; return the names set.

    ``environ`` defaults to ``os.environ``; call it before numpy is imported.
    """
    env = os.environ if environ is None else environ
    unset = [name for name in THREAD_VARIABLES if name not in env]
    for name in unset:
        env[name] = '1'
    return unset
