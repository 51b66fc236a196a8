"""
One BLAS/OpenMP thread unless the user chose otherwise.

Imported first by the package, before numpy loads.

The package's matrix products are small (100 x 32 by 32 x 20000 at most). On a 2-core machine
with other work on it, the worker threads of a multithreaded BLAS spin against the main thread
and every stage slows down: measured on Intel with another process busy, localization p50 46 ms
with one thread and 103 ms with OpenBLAS's default. Set ``OPENBLAS_NUM_THREADS`` (or
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``) before starting to override; once numpy is loaded,
changing them has no effect.
"""
from __future__ import annotations

import os

THREAD_VARIABLES = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')

for _name in THREAD_VARIABLES:
    os.environ.setdefault(_name, '1')
