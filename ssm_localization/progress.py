"""
Progress of long jobs (indexing a big map, building a map from a log, writing a bag).

The ROS-free core takes a ``progress(done, total, label)`` callback (:data:`ProgressCallback`);
the command line draws it with tqdm through :class:`TqdmProgress` (tqdm is imported when the
first bar is drawn: the core does not need it).
"""
from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext
from typing import Any, Callable

# progress(done, total, label): the callback type the ROS-free core accepts for long jobs.
ProgressCallback = Callable[[int, int, str], None]

# layer(name): a context manager around the building of one layer of an index or a localizer
# (``bench index`` measures the memory of each); the core calls it when it is given one.
LayerHook = Callable[[str], AbstractContextManager]


def no_layers(name: str) -> AbstractContextManager:
    """Return the :data:`LayerHook` that observes nothing."""
    return nullcontext()


class TqdmProgress:
    """
    A :data:`ProgressCallback` drawn as a tqdm bar on stderr.

    A new ``label`` or ``total`` starts the bar over (a job reporting several stages).
    ``enabled=False`` draws nothing; nor does a job that fails before its first report (its error
    stays the only line).
    """

    def __init__(self, label: str = '', enabled: bool = True):
        self._label = label
        self._enabled = enabled
        self._bar: Any = None      # the tqdm bar, made at the first report

    def __call__(self, done: int, total: int, label: str = '') -> None:
        if self._bar is None:
            from tqdm import tqdm
            self._bar = tqdm(desc=self._label, disable=not self._enabled, leave=True,
                             dynamic_ncols=True)
        bar = self._bar
        if (total and total != bar.total) or (label and label != self._label):
            self._label = label or self._label
            bar.reset(total=total or None)
            bar.set_description_str(self._label, refresh=False)
        bar.update(done - bar.n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()

    def __enter__(self) -> 'TqdmProgress':
        return self

    def __exit__(self, *exc) -> None:
        self.close()
