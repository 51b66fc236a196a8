"""The worker thread both nodes index maps in: the newest submitted job wins."""
from __future__ import annotations

from dataclasses import dataclass
import threading
import time
from typing import Any, Callable, Generic, Hashable, TypeVar

from ssm_localization.progress import ProgressCallback

R = TypeVar('R')


class Superseded(Exception):
    """Raised inside a build (from its progress callback) when a newer job is waiting."""


@dataclass(frozen=True, eq=False)
class BuildJob(Generic[R]):
    """
    One job for :class:`IndexBuilder`: ``run(progress)`` returns its result.

    ``label`` names it in the log; ``key`` (optional) lets :meth:`IndexBuilder.has_job` find it.
    """

    label: str
    run: Callable[[ProgressCallback], R]
    key: Hashable = None


class IndexBuilder:
    """
    Runs :class:`BuildJob` s in one worker thread; the newest submitted job wins.

    :meth:`submit` replaces a queued job that has not started; a running job is aborted at its
    next progress report (``Superseded``) or its result is dropped. ``on_done(job, result)`` /
    ``on_error(job, exc)`` run in the worker thread.
    """

    def __init__(self, logger: Any, on_done: Callable[[BuildJob, Any], None],
                 on_error: Callable[[BuildJob, BaseException], None], log_period: float = 5.0):
        self._logger = logger
        self._on_done = on_done
        self._on_error = on_error
        self._log_period = log_period
        self._cv = threading.Condition()
        self._pending: BuildJob | None = None
        self._running: BuildJob | None = None
        self._stop = False
        self._thread = threading.Thread(target=self._run, name='index_builder', daemon=True)
        self._thread.start()

    @property
    def busy(self) -> bool:
        """Tell whether a job is queued or running."""
        with self._cv:
            return self._pending is not None or self._running is not None

    def status(self) -> str:
        """Return the label of the running (else the queued) job, or ``'idle'``."""
        with self._cv:
            job = self._running or self._pending
            return job.label if job is not None else 'idle'

    def has_job(self, key: Hashable) -> bool:
        """Tell whether a job submitted with ``key`` (not None) is queued or running."""
        with self._cv:
            return key is not None and any(job is not None and job.key == key
                                           for job in (self._pending, self._running))

    def submit(self, job: BuildJob) -> None:
        """Queue ``job``, replacing a queued one; a running one is superseded."""
        with self._cv:
            if self._pending is not None:
                self._logger.info(f'{job.label}: replaces the queued {self._pending.label}')
            elif self._running is not None:
                self._logger.info(f'{job.label}: supersedes {self._running.label} (in progress)')
            self._pending = job
            self._cv.notify_all()

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Wait until no job is queued or running; False on timeout."""
        with self._cv:
            return self._cv.wait_for(lambda: self._pending is None and self._running is None,
                                     timeout)

    def stop(self) -> None:
        """Drop the queued job, abort the running one at its next progress report, end."""
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
                job, self._pending = self._pending, None
                self._running = job
            try:
                result = job.run(self._progress(job.label))
                if self._superseded():
                    raise Superseded()
                self._on_done(job, result)
            except Superseded:
                self._logger.info(f'{job.label}: dropped, a newer map arrived')
            except Exception as exc:  # noqa: BLE001 - any failure of a job is reported, not fatal
                self._on_error(job, exc)
            finally:
                with self._cv:
                    self._running = None
                    self._cv.notify_all()

    def _progress(self, label: str) -> ProgressCallback:
        """Return the progress callback of one job: logs now and then, raises Superseded."""
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
        return progress
