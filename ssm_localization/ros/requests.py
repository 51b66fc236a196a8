"""
The newest scan, and service calls waiting for the next one (a bounded queue, one worker).

A ``relocalize`` / ``global_localization`` call asks for the next scan received after the call.
:meth:`RequestQueue.submit` gives the call a :class:`concurrent.futures.Future` to wait on, or
raises :class:`Refused` at once when ``capacity`` calls are already waiting. One worker thread
waits for a scan newer than the oldest waiting call, localizes it once and answers every call
made before that scan with the same result, so a burst of calls costs one localization. A call
that sees no scan within its ``scan_timeout`` is answered with that reason;
:meth:`RequestQueue.cancel_all` answers every waiting call (deactivation).

The service callbacks wait on their Future in an executor thread (rclpy Jazzy re-runs pending
coroutine callbacks in a busy loop, so awaiting would spin a core while a call waits): the node's
executor has ``capacity`` threads more than it otherwise needs, so waiting calls never starve the
scan, map and lifecycle callbacks, and a call beyond ``capacity`` still finds a thread to be
refused on.

Answers to many calls go out in groups of :data:`ANSWER_GROUP`, :data:`GROUP_PAUSE` apart: with
rmw_fastrtps every client of a service in a process receives every answer into its own queue
before filtering its own, so a burst of answers would overflow clients with the default queue
depth (10).
"""
from __future__ import annotations

from concurrent.futures import Future
from dataclasses import dataclass
import threading
import time
from typing import Any, Callable

ANSWER_GROUP = 8       # answers sent together
GROUP_PAUSE = 0.02     # s between groups


class Refused(Exception):
    """A call or scan that cannot be served now; the message says why, for the caller."""


@dataclass(frozen=True)
class Answer:
    """What a service call gets back: ``ok`` with a message, or the reason why not."""

    ok: bool
    message: str


class ScanMailbox:
    """The newest scan with a sequence number; waiters wake on every new scan."""

    def __init__(self) -> None:
        self._cv = threading.Condition()
        self._msg: Any = None
        self._seq = 0
        self._received = 0.0      # time.monotonic() of the stored scan

    @property
    def seq(self) -> int:
        """How many scans have arrived so far."""
        with self._cv:
            return self._seq

    def put(self, msg: Any) -> None:
        """Store a new scan (subscription callback)."""
        with self._cv:
            self._msg = msg
            self._seq += 1
            self._received = time.monotonic()
            self._cv.notify_all()

    def age(self) -> float | None:
        """Return the seconds since the stored scan arrived, or None without one."""
        with self._cv:
            return None if self._msg is None else time.monotonic() - self._received

    def clear(self) -> None:
        """Forget the stored scan (the sequence number keeps counting)."""
        with self._cv:
            self._msg = None

    def wake(self) -> None:
        """Wake every waiter (to let it see a stop flag)."""
        with self._cv:
            self._cv.notify_all()

    def wait_newer(self, seq: int, timeout: float | None,
                   stop: threading.Event) -> tuple[Any, int] | None:
        """
        Return the newest scan once one with a number above ``seq`` arrived.

        Returns None on timeout or when ``stop`` is set.
        """
        with self._cv:
            ok = self._cv.wait_for(
                lambda: (self._seq > seq and self._msg is not None) or stop.is_set(), timeout)
            if not ok or stop.is_set():
                return None
            return self._msg, self._seq


@dataclass
class _Call:
    seq0: int             # scans seen when the call arrived: it needs a newer one
    deadline: float       # time.monotonic() by which a scan must have arrived
    timeout: float
    future: Future


class RequestQueue:
    """
    Service calls waiting for the next scan, answered in batches by one worker thread.

    ``serve(scan_msg) -> Answer`` localizes one scan; ``no_scan(timeout) -> str`` words the
    answer for a call that saw no scan in time.
    """

    def __init__(self, mailbox: ScanMailbox, capacity: int,
                 serve: Callable[[Any], Answer], no_scan: Callable[[float], str]) -> None:
        if capacity < 1:
            raise ValueError(f'RequestQueue capacity must be >= 1, got {capacity}')
        self.capacity = capacity
        self._mailbox = mailbox
        self._serve = serve
        self._no_scan = no_scan
        self._cv = threading.Condition()
        self._calls: list[_Call] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='request_queue', daemon=True)
        self._thread.start()

    def __len__(self) -> int:
        with self._cv:
            return len(self._calls)

    def submit(self, timeout: float) -> Future:
        """
        Queue a call that waits at most ``timeout`` s for a scan; return its Future.

        Raises :class:`Refused` when the queue is full or stopped.
        """
        future = Future()
        with self._cv:
            if self._stop.is_set():
                raise Refused('not accepting calls: the node is shutting down')
            if len(self._calls) >= self.capacity:
                raise Refused(f'busy: {self.capacity} calls are already waiting for a scan; '
                              'try again shortly')
            self._calls.append(_Call(self._mailbox.seq, time.monotonic() + timeout, timeout,
                                     future))
            self._cv.notify_all()
        return future

    def cancel_all(self, reason: str) -> int:
        """Answer every waiting call with ``reason``; return how many there were."""
        with self._cv:
            calls, self._calls = self._calls, []
        _resolve_all(calls, lambda call: Answer(False, reason))
        self._mailbox.wake()
        return len(calls)

    def stop(self, reason: str) -> None:
        """Answer the waiting calls with ``reason`` and end the worker."""
        self._stop.set()
        with self._cv:
            self._cv.notify_all()
        self.cancel_all(reason)
        self._thread.join(timeout=5.0)

    def _expire(self, now: float) -> None:
        with self._cv:
            late = [c for c in self._calls if c.deadline <= now]
            self._calls = [c for c in self._calls if c.deadline > now]
        _resolve_all(late, lambda call: Answer(False, self._no_scan(call.timeout)))

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._cv:
                self._cv.wait_for(lambda: self._calls or self._stop.is_set())
                if self._stop.is_set():
                    return
                oldest = min(c.seq0 for c in self._calls)
                earliest = min(c.deadline for c in self._calls)
            got = self._mailbox.wait_newer(oldest, max(0.0, earliest - time.monotonic()),
                                           self._stop)
            if got is None:
                self._expire(time.monotonic())
                continue
            msg, seq = got
            with self._cv:
                if not any(c.seq0 < seq for c in self._calls):
                    continue         # the calls it was for were cancelled meanwhile
            try:
                answer = self._serve(msg)
            except Exception as exc:  # noqa: BLE001 - every call gets an answer, whatever happens
                answer = Answer(False, f'localization error: {type(exc).__name__}: {exc}')
            with self._cv:
                done = [c for c in self._calls if c.seq0 < seq]
                self._calls = [c for c in self._calls if c.seq0 >= seq]
            _resolve_all(done, lambda call: answer)


def _resolve_all(calls: list[_Call], answer_of: Callable[[_Call], Answer]) -> None:
    """Answer ``calls`` in groups of ANSWER_GROUP, GROUP_PAUSE apart."""
    for i, call in enumerate(calls):
        if i and i % ANSWER_GROUP == 0:
            time.sleep(GROUP_PAUSE)
        _resolve(call.future, answer_of(call))


def _resolve(future: Future, answer: Answer) -> None:
    try:
        future.set_result(answer)
    except Exception:  # noqa: BLE001 - already resolved (InvalidStateError): first answer wins
        pass
