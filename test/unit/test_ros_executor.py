"""
shutdown_context: a signal that shuts the context down during the exit is a clean exit.

The race itself (rclpy's signal thread between ``try_shutdown``'s check and its shutdown) is
what test_ros_e2e.py's signal test met once on a new machine (then not in 48 exits); here its
two outcomes are made to happen on purpose.
"""
from __future__ import annotations

import pytest
import rclpy
from ssm_localization.ros import executor


class Context:
    """The default context's two states, as rclpy.ok / rclpy.try_shutdown see them."""

    def __init__(self, shut_by_signal: bool) -> None:
        self.up = True
        self.shut_by_signal = shut_by_signal

    def ok(self) -> bool:
        return self.up

    def try_shutdown(self) -> None:
        assert self.up                  # try_shutdown's own check passes ...
        if self.shut_by_signal:
            self.up = False             # ... then the signal thread shuts the context down
        raise RuntimeError('failed to shutdown: rcl_shutdown already called on the given '
                           'context')


@pytest.fixture
def context(monkeypatch, request):
    ctx = Context(request.param)
    monkeypatch.setattr(rclpy, 'ok', ctx.ok)
    monkeypatch.setattr(rclpy, 'try_shutdown', ctx.try_shutdown)
    return ctx


@pytest.mark.parametrize('context', [True], indirect=True)
def test_a_context_a_signal_shut_down_meanwhile_is_a_clean_exit(context):
    executor.shutdown_context()
    assert not context.up


@pytest.mark.parametrize('context', [False], indirect=True)
def test_a_shutdown_error_with_the_context_still_up_is_raised(context):
    with pytest.raises(RuntimeError, match='rcl_shutdown'):
        executor.shutdown_context()
