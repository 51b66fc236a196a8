"""
What each layer of an index and of a localizer costs: memory and time, layer by layer.

:class:`LayerMeter` is a :data:`~ssm_localization.progress.LayerHook`: ``build_index`` and
``GlobalLocalizer`` call it around each layer they build. It measures with ``tracemalloc``
(numpy reports its buffers to it) what the layer keeps (the traced memory after it, less
before) and its peak while it is built (the intermediates it frees again), both relative to
what was held before it started. Tracing slows Python's own allocations, so the times of a
traced run are not those of an untraced one.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
import time
import tracemalloc


@dataclass(frozen=True)
class LayerCost:
    """One layer: seconds to build, bytes kept, peak bytes above what was held before it."""

    name: str
    seconds: float
    kept: int
    peak: int


class LayerMeter:
    """Record a :class:`LayerCost` per layer built (``costs``, in the order built)."""

    def __init__(self) -> None:
        self.costs: list[LayerCost] = []
        if not tracemalloc.is_tracing():
            tracemalloc.start()

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        t0 = time.perf_counter()
        yield
        seconds = time.perf_counter() - t0
        now, peak = tracemalloc.get_traced_memory()
        self.costs.append(LayerCost(name, seconds, now - before, peak - before))

    def as_dicts(self) -> list[dict]:
        """Return the costs as plain dicts (JSON)."""
        return [c.__dict__.copy() for c in self.costs]


def format_layers(costs: list[dict], cells: int, notes: dict[str, str] | None = None) -> str:
    """
    Return a table of layer costs: MB kept, bytes per map cell, MB peak, seconds.

    ``notes``: a remark after a layer's row, by layer name (a layer counted with another).
    """
    notes = notes or {}
    lines = [f'  {"layer":18s} {"kept MB":>8s} {"B/cell":>7s} {"peak MB":>8s} '
             f'{"B/cell":>7s} {"s":>6s}']
    for c in costs:
        note = f'  ({notes[c["name"]]})' if c['name'] in notes else ''
        lines.append(f'  {c["name"]:18s} {c["kept"] / 1e6:8.1f} {c["kept"] / cells:7.2f} '
                     f'{c["peak"] / 1e6:8.1f} {c["peak"] / cells:7.2f} {c["seconds"]:6.2f}'
                     f'{note}')
    kept = sum(c['kept'] for c in costs)
    lines.append(f'  {"all layers kept":18s} {kept / 1e6:8.1f} {kept / cells:7.2f}')
    return '\n'.join(lines)
