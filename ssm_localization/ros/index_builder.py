"""The worker thread both nodes index maps in: the newest submitted job wins."""
from __future__ import annotations

import threading
import time
from typing import Any, Callable


class Superseded(Exception):
    """Raised inside a build (from its progress callback) when a newer job is waiting."""


class IndexBuilder:
    """
    Runs index jobs in one worker thread; the newest submitted job wins.

    ``submit(label, job, key)`` queues ``job(progress) -> MapIndex``, replacing a queued job
    that has not started; a running job is aborted at its next progress report (``Superseded``)
    or its result is dropped. :meth:`has_job` tells whether the job of a ``key`` is queued or
    running. ``on_done(index, label)`` / ``on_error(exc, label)`` run in the worker.
    """

    def __init__(self, logger, on_done: Callable[[Any, str], None],
                 on_error: Callable[[BaseException, str], None], log_period: float = 5.0):
        self._logger = logger
        self._on_done = on_done
        self._on_error = on_error
        self._log_period = log_period
        self._cv = threading.Condition()
        self._pending: tuple[str, Callable, Any] | None = None
        self._running: str | None = None
        self._running_key: Any = None
        self._stop = False
        self._thread = threading.Thread(target=self._run, name='index_builder', daemon=True)
        self._thread.start()

    @property
    def busy(self) -> bool:
        with self._cv:
            return self._pending is not None or self._running is not None

    def status(self) -> str:
        with self._cv:
            return self._running or (self._pending[0] if self._pending else 'idle')

    def has_job(self, key: Any) -> bool:
        """Tell whether a job submitted with ``key`` (not None) is queued or running."""
        with self._cv:
            return key is not None and (
                (self._pending is not None and self._pending[2] == key)
                or (self._running is not None and self._running_key == key))

    def submit(self, label: str, job: Callable, key: Any = None) -> None:
        with self._cv:
            if self._pending is not None:
                self._logger.info(f'{label}: replaces the queued {self._pending[0]}')
            elif self._running is not None:
                self._logger.info(f'{label}: supersedes {self._running} (in progress)')
            self._pending = (label, job, key)
            self._cv.notify_all()

    def wait_idle(self, timeout: float | None = None) -> bool:
        with self._cv:
            return self._cv.wait_for(lambda: self._pending is None and self._running is None,
                                     timeout)

    def stop(self) -> None:
        with self._cv:
            self._stop = True
            self._pending = None
            self._cv.notify_all()
        self._thread.join(timeout=2.0)

    def _superseded(self) -> bool:
        with self._cv:
            return self._pending is not None or self._stop

    def _run(self) -> None:
        while True:
            with self._cv:
                self._cv.wait_for(lambda: self._pending is not None or self._stop)
                if self._stop:
                    return
                label, job, key = self._pending
                self._pending, self._running, self._running_key = None, label, key
            t0 = time.monotonic()
            last = [t0, -1]

            def progress(done: int, total: int, what: str = '') -> None:
                if self._superseded():
                    raise Superseded()
                now = time.monotonic()
                decile = int(10 * done / total) if total else 0
                if now - last[0] >= self._log_period or (decile > last[1] and decile % 5 == 0):
                    last[0], last[1] = now, decile
                    self._logger.info(f'{label}: {what or "indexing"} {done}/{total} '
                                      f'({now - t0:.1f} s)')
            try:
                index = job(progress)
                if self._superseded():
                    raise Superseded()
                self._on_done(index, label)
            except Superseded:
                self._logger.info(f'{label}: dropped, a newer map arrived')
            except Exception as exc:  # noqa: BLE001 - any failure of a job is reported, not fatal
                self._on_error(exc, label)
            finally:
                with self._cv:
                    self._running, self._running_key = None, None
                    self._cv.notify_all()
