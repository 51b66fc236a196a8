"""
RequestQueue / ScanMailbox: batched answers, deadlines, bounded queue, cancellation.

The same queue over DDS, with many clients: test_ros_hostile.py.
"""
from __future__ import annotations

import threading
import time

import pytest
from ssm_localization.ros.requests import Answer, Refused, RequestQueue, ScanMailbox


def _wait(futures, timeout=5.0):
    end = time.monotonic() + timeout
    while not all(f.done() for f in futures) and time.monotonic() < end:
        time.sleep(0.01)
    return [f.result() if f.done() else None for f in futures]


class Server:
    def __init__(self, capacity=8, delay=0.0):
        self.mailbox = ScanMailbox()
        self.served: list = []
        self.delay = delay
        self.queue = RequestQueue(self.mailbox, capacity, self._serve,
                                  lambda t: f'no scan within {t:g} s')

    def _serve(self, msg):
        self.served.append(msg)
        time.sleep(self.delay)
        if msg == 'boom':
            raise RuntimeError('kaput')
        return Answer(True, f'localized {msg}')


def test_a_burst_is_answered_by_one_localization_of_the_next_scan():
    s = Server(capacity=50)
    s.mailbox.put('old')                      # before the calls: not theirs
    futures = [s.queue.submit(2.0) for _ in range(50)]
    assert all(not isinstance(f, str) for f in futures)
    time.sleep(0.05)
    assert not s.served and len(s.queue) == 50
    s.mailbox.put('scan1')
    answers = _wait(futures)
    assert all(a is not None and a.ok and a.message == 'localized scan1' for a in answers)
    assert s.served == ['scan1']
    s.queue.stop('bye')


def test_full_queue_refuses_at_once_with_a_reason():
    s = Server(capacity=3)
    futures = [s.queue.submit(5.0) for _ in range(3)]
    for _ in range(2):
        with pytest.raises(Refused, match='^busy: 3 calls'):
            s.queue.submit(5.0)
    s.mailbox.put('scan')
    assert all(a.ok for a in _wait(futures))
    s.queue.stop('bye')


def test_calls_without_a_scan_time_out_each_at_its_own_deadline():
    s = Server()
    short, long_ = s.queue.submit(0.2), s.queue.submit(1.0)
    t0 = time.monotonic()
    first = _wait([short])[0]
    assert not first.ok and first.message == 'no scan within 0.2 s'
    assert 0.15 < time.monotonic() - t0 < 0.6 and not long_.done()
    s.mailbox.put('scan')                     # the longer call still gets it
    assert _wait([long_])[0].message == 'localized scan'
    s.queue.stop('bye')


def test_calls_during_a_localization_wait_for_the_following_scan():
    s = Server(delay=0.3)
    first = s.queue.submit(3.0)
    s.mailbox.put('scan1')
    time.sleep(0.1)                           # scan1 is being localized
    second = s.queue.submit(3.0)
    assert _wait([first])[0].message == 'localized scan1'
    time.sleep(0.05)
    assert not second.done()
    s.mailbox.put('scan2')
    assert _wait([second])[0].message == 'localized scan2'
    s.queue.stop('bye')


def test_errors_and_cancellation_still_answer_every_call():
    s = Server()
    boom = s.queue.submit(3.0)
    s.mailbox.put('boom')
    answer = _wait([boom])[0]
    assert not answer.ok and 'RuntimeError: kaput' in answer.message
    waiting = [s.queue.submit(30.0) for _ in range(4)]
    assert s.queue.cancel_all('deactivated') == 4
    assert all(a.message == 'deactivated' and not a.ok for a in _wait(waiting))
    late = s.queue.submit(30.0)
    s.queue.stop('shutting down')
    assert _wait([late])[0].message == 'shutting down'
    with pytest.raises(Refused, match='shutting down'):
        s.queue.submit(1.0)


def test_capacity_must_be_positive():
    with pytest.raises(ValueError):
        RequestQueue(ScanMailbox(), 0, lambda m: None, str)


def test_mailbox_wait_newer_stops_on_the_stop_event():
    box = ScanMailbox()
    stop = threading.Event()
    threading.Timer(0.1, lambda: (stop.set(), box.wake())).start()
    t0 = time.monotonic()
    assert box.wait_newer(0, 5.0, stop) is None and time.monotonic() - t0 < 1.0
