"""
Compiled loops of the correlative search (numba), for the steps numpy cannot do in one pass.

A window's score is the sum of a few dozen likelihoods gathered from the level grid
(``correlative.py``). In numpy that takes five passes over (windows, points) arrays: the rows of
cell offsets gathered, the window's cell added, the likelihoods gathered, cast and summed. The
loop below reads each offset once and keeps the sum in a register: on the 90 captured campus
searches it cut the search's time to 0.70 of numpy's (docs/EXPERIMENTS.md, 2026-11-28).

The sums are integers, so both ways give the same scores bit for bit
(``test_correlative.py``). Without numba (not installed, or a platform it does not support)
:data:`window_sums` is None and the search uses numpy. The functions are compiled in one
thread (``nogil``, no ``parallel``): the package's thread policy (``threads.py``) stands.
"""
from __future__ import annotations

import warnings

import numpy as np

try:
    import numba
except ImportError:                     # the numpy path of correlative._score is used instead
    numba = None


def window_sums_python(grid: np.ndarray, base: np.ndarray, yaw: np.ndarray, cell: np.ndarray,
                       out: np.ndarray) -> None:
    """
    ``out[w] = sum_j grid[clip(base[yaw[w], j] + cell[w])]``: the score of each window, unscaled.

    ``grid`` (G,) uint8 likelihoods of one level, flat; ``base`` (K, N) int64 the offsets of a
    scan's N points per yaw; ``yaw`` (W,) int64 and ``cell`` (W,) int64 each window's yaw and
    flat cell; ``out`` (W,) int32. Indices off the flat grid read its first or last cell, as
    ``np.take(..., mode='clip')`` does. The reference implementation, compiled by numba.
    """
    n = base.shape[1]
    last = grid.shape[0] - 1
    for w in range(yaw.shape[0]):
        row = yaw[w]
        at = cell[w]
        total = np.int64(0)
        for j in range(n):
            idx = base[row, j] + at
            if idx < 0:
                idx = 0
            elif idx > last:
                idx = last
            total += grid[idx]
        out[w] = total


def _compile(function):
    """Return ``function`` compiled by numba (cached on disk where it can be), or None."""
    if numba is None:
        return None
    try:
        return numba.njit(cache=True, nogil=True)(function)
    except RuntimeError as err:         # no writable cache directory: compile in each process
        warnings.warn(f'numba cannot cache {function.__name__} ({err}); compiling without cache',
                      RuntimeWarning, stacklevel=2)
        return numba.njit(nogil=True)(function)


#: the compiled :func:`window_sums_python`, or None without numba
window_sums = _compile(window_sums_python)


def warm_up() -> None:
    """Compile (or load from the cache) the functions above now, not at the first search."""
    if window_sums is not None:
        window_sums(np.zeros(2, np.uint8), np.zeros((1, 1), np.int64), np.zeros(1, np.int64),
                    np.zeros(1, np.int64), np.zeros(1, np.int32))
