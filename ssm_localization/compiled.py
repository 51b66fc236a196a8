"""
numba, when it is installed: a loop compiled once (cached on disk where it can be), or None.

The package's compiled loops (``matching/kernels.py``, ``localization/kernels.py``) each keep
their Python source beside the compiled function; without numba (not installed, or a platform it
does not support) the compiled one is None and the callers run numpy instead. Compiled loops run
in the calling thread (``nogil``, no ``parallel``), so the thread policy of ``threads.py`` stands.
"""
from __future__ import annotations

from typing import Callable
import warnings

try:
    import numba
except ImportError:                     # the callers' numpy code runs instead
    numba = None
    warnings.warn('numba is not installed (a requirement of ssm_localization): the correlative '
                  'search, the refinement and the voxel selection of scans run in numpy, about a '
                  'quarter slower on large maps', RuntimeWarning, stacklevel=2)


def compile_loop(function: Callable) -> Callable | None:
    """Return ``function`` compiled by numba (cached on disk where it can be), or None."""
    if numba is None:
        return None
    try:
        return numba.njit(cache=True, nogil=True)(function)
    except RuntimeError as err:         # no writable cache directory: compile in each process
        warnings.warn(f'numba cannot cache {function.__name__} ({err}); compiling without cache',
                      RuntimeWarning, stacklevel=2)
        return numba.njit(nogil=True)(function)
