"""
Lifecycle helpers shared by the nodes (rclpy.lifecycle, ROS 2 Jazzy).

- :func:`transition`: wraps an ``on_configure`` / ``on_activate`` / ... method so an exception
  is logged with its reason and the transition fails cleanly (rclpy turns an uncaught
  exception into ERROR without a word);
- :func:`schedule_autostart`: parameter ``autostart``: configure and activate once spinning;
- :func:`state_label`: the node's current state (``unconfigured``, ``inactive``, ``active``,
  ``finalized`` or a transition state);
- :func:`answer_invalid_transitions`: ``change_state`` with a transition the current state does
  not offer answers ``success: false`` (rclpy raises inside the service, leaving the caller
  without an answer).
"""
from __future__ import annotations

import functools
from typing import Any, Callable

from lifecycle_msgs.msg import State
from lifecycle_msgs.srv import ChangeState
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE
UNCONFIGURED = State.PRIMARY_STATE_UNCONFIGURED

Transition = Callable[[Any, LifecycleState], TransitionCallbackReturn]


def transition(name: str) -> Callable[[Transition], Transition]:
    """Decorate a transition callback: log it, and turn an exception into a logged FAILURE."""
    def decorate(method: Transition) -> Transition:
        @functools.wraps(method)
        def wrapper(self, state: LifecycleState) -> TransitionCallbackReturn:
            self.get_logger().info(f'{name} (from {state.label})')
            try:
                result = method(self, state)
            except Exception as exc:  # noqa: BLE001 - reported to the caller as FAILURE
                self.get_logger().error(f'{name} failed: {type(exc).__name__}: {exc}')
                return FAILURE
            if result != SUCCESS:
                self.get_logger().error(f'{name} failed')
            return result
        return wrapper
    return decorate


def state_id(node: LifecycleNode) -> int:
    """Return the current state id (lifecycle_msgs/State constants)."""
    return int(node._state_machine.current_state[0])


def state_label(node: LifecycleNode) -> str:
    """Return the current state's label."""
    return str(node._state_machine.current_state[1])


def configured_state(node: LifecycleNode) -> str | None:
    """Return the state label while configure-time parameters are in use, else None."""
    return None if state_id(node) == UNCONFIGURED else state_label(node)


def schedule_autostart(node: LifecycleNode, delay_sec: float = 0.0) -> None:
    """
    Configure, then activate, ``node`` once its executor spins (parameter ``autostart``).

    A failed step is logged and leaves the node where it stopped (unconfigured or inactive),
    still answering its services and ``get_state`` / ``change_state``.
    """
    timer = None

    def start() -> None:
        timer.cancel()
        node.destroy_timer(timer)
        if state_id(node) != UNCONFIGURED:
            return          # a lifecycle manager (or a user) was quicker
        if node.trigger_configure() != SUCCESS:
            node.get_logger().error('autostart: configure failed; the node stays unconfigured '
                                    '(fix the cause, then: ros2 lifecycle set '
                                    f'{node.get_fully_qualified_name()} configure)')
            return
        if node.trigger_activate() != SUCCESS:
            node.get_logger().error('autostart: activate failed; the node stays inactive')
            return
        node.get_logger().info('autostart: active')

    timer = node.create_timer(delay_sec, start)


def available_transitions(node: LifecycleNode) -> dict[int, str]:
    """``{transition id: label}`` of the transitions the current state offers."""
    return {int(t[0]): str(t[1]) for t in node._state_machine.available_transitions}


def answer_invalid_transitions(node: LifecycleNode) -> None:
    """Make ``NODE/change_state`` answer ``success: false`` for a transition not offered now."""
    service = node._service_change_state
    original = service.callback

    def change_state(request: ChangeState.Request, response: ChangeState.Response):
        offered = available_transitions(node)
        wanted = request.transition.label or request.transition.id
        if request.transition.label:
            ok = request.transition.label in offered.values()
        else:
            ok = int(request.transition.id) in offered
        if not ok:
            node.get_logger().warning(
                f'change_state: transition {wanted!r} is not possible from state '
                f'{state_label(node)} (possible: {", ".join(sorted(offered.values()))})')
            response.success = False
            return response
        return original(request, response)

    service.callback = change_state
