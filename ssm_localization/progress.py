"""A dependency-free progress bar for long jobs (indexing a big map, replaying a bag)."""
from __future__ import annotations

import sys
import time
from typing import Callable, Iterable, Iterator, TextIO, TypeVar

T = TypeVar('T')

# progress(done, total, label): the callback type the ROS-free core accepts for long jobs.
ProgressCallback = Callable[[int, int, str], None]


class ProgressBar:
    """Draws ``label [#####.....] done/total  eta`` on a stream, at most ``hz`` times a second.

    On a non-tty stream (CI logs) it prints a line every 10 %% instead of redrawing.
    """

    def __init__(self, total: int, label: str = '', stream: TextIO | None = None,
                 hz: float = 5.0, enabled: bool = True):
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self._tty = hasattr(self.stream, 'isatty') and self.stream.isatty()
        self._min_dt = 1.0 / hz
        self._t0 = time.monotonic()
        self._last = 0.0
        self._last_decile = -1

    def __call__(self, done: int, total: int | None = None, label: str | None = None) -> None:
        self.update(done, total, label)

    def update(self, done: int, total: int | None = None, label: str | None = None) -> None:
        if not self.enabled:
            return
        if total:
            self.total = max(int(total), 1)
        if label is not None:
            self.label = label
        frac = min(max(done / self.total, 0.0), 1.0)
        now = time.monotonic()
        elapsed = now - self._t0
        eta = elapsed * (1 - frac) / frac if frac > 0 else float('nan')
        if self._tty:
            if now - self._last < self._min_dt and done < self.total:
                return
            self._last = now
            width = 30
            bar = '#' * int(frac * width) + '.' * (width - int(frac * width))
            self.stream.write(f'\r{self.label} [{bar}] {done}/{self.total} '
                              f'{elapsed:5.1f}s eta {eta:5.1f}s')
            if done >= self.total:
                self.stream.write('\n')
        else:
            decile = int(frac * 10)
            if decile == self._last_decile:
                return
            self._last_decile = decile
            self.stream.write(f'{self.label}: {done}/{self.total} ({frac:.0%}) '
                              f'{elapsed:.1f}s\n')
        self.stream.flush()


def track(items: Iterable[T], total: int, label: str = '', enabled: bool = True) -> Iterator[T]:
    """Iterate over ``items`` while drawing a progress bar."""
    bar = ProgressBar(total, label, enabled=enabled)
    for i, item in enumerate(items):
        yield item
        bar.update(i + 1)
