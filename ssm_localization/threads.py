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

Two stages are the exception, each by its own parameter, and neither spins: the pose votes'
k-d tree query runs in ``localizer.vote_workers`` (2) threads of scipy's, which split the query
points among them and are joined when it returns; the correlative search scores its largest
sets of windows in ``localizer.search_workers`` (2) threads (:func:`in_parts`, the compiled loop
releases the GIL). Paired per query, the answers are the same; with the other core idle the time
is lower on the largest maps, with it busy within a few per cent of one thread's
(docs/EXPERIMENTS.md, 2026-12-02 and 2026-12-07).
"""
from __future__ import annotations

import itertools
import os
import threading
from typing import Callable, MutableMapping

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


def checked_workers(workers: int, owner: str) -> int:
    """Return ``workers``, -1 (every core) or at least 1; else a ValueError naming ``owner``."""
    if workers != -1 and workers < 1:
        raise ValueError(f'{owner}: workers must be -1 (every core) or at least 1, got '
                         f'{workers!r}')
    return int(workers)


def worker_count(workers: int) -> int:
    """Return the threads ``workers`` asks for: itself, or every core for -1."""
    return (os.cpu_count() or 1) if workers == -1 else max(int(workers), 1)


def in_parts(task: Callable[[int, int], None], n: int, workers: int, chunks: int = 4) -> None:
    """
    Run ``task(start, stop)`` over ``[0, n)`` in parts, shared among ``workers`` threads.

    The range is cut into ``chunks`` parts a worker; the calling thread and ``workers - 1``
    threads started for the call each take the next part not yet taken until none is left, so
    a thread the operating system does not schedule in time (the other core busy) holds up at
    most the part it took, never a fixed share. The threads are joined before the call returns
    (nothing is left waiting or spinning) and an error of any part is raised here. With one
    worker (or ``n`` < 2) ``task(0, n)`` runs in the calling thread. The parts must not depend
    on one another: each writes its own slice of the result.
    """
    workers = min(worker_count(workers), n)
    if workers <= 1:
        task(0, n)
        return
    count = min(workers * max(int(chunks), 1), n)
    bounds = [n * i // count for i in range(count + 1)]
    parts = itertools.count()
    taking = threading.Lock()           # each part is taken once, with or without a GIL
    errors: list[BaseException] = []

    def take() -> None:
        try:
            while True:
                with taking:
                    i = next(parts)
                if i >= count or errors:
                    return
                task(bounds[i], bounds[i + 1])
        except BaseException as err:        # re-raised in the calling thread
            errors.append(err)

    threads = [threading.Thread(target=take, daemon=True) for _ in range(workers - 1)]
    for thread in threads:
        thread.start()
    take()
    for thread in threads:
        thread.join()
    if errors:
        raise errors[0]
