"""
Hand-over of a pose to AMCL (or whatever else takes ``initialpose``), acknowledged.

AMCL takes ``initialpose`` only once it is configured (it keeps a pose received while inactive
and applies it at activation), and its subscription is volatile: a pose published before AMCL
exists is lost. :class:`HandOver` therefore publishes the pose on ``initialpose`` again every
``period`` seconds until a pose close to it comes back on the confirmation topic (AMCL's
``amcl_pose``, reliable + transient local, stamped with the scan AMCL last used), at most
``tries`` times; then it logs an error naming both topics. The pose keeps the stamp of its scan,
so AMCL moves it by the odometry since then (``initialpose`` semantics). A newer pose replaces
the one being handed over. With an empty confirmation topic the pose is published once.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import threading
from typing import Any, Callable

from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.clock import Clock, ClockType
from ssm_localization.ros.conversions import pose_from_msg, stamp_to_ns
from ssm_localization.ros.qos import LATCHED_QOS
from ssm_localization.transforms import wrap_angle


@dataclass(frozen=True)
class HandOverConfig:
    """Parameters ``handover_confirm_topic``, ``handover_period``, ``_tries``, ``_tolerance``."""

    confirm_topic: str = 'amcl_pose'
    period: float = 1.0
    tries: int = 30
    tolerance: float = 0.5


def confirms(handed: PoseWithCovarianceStamped, got: PoseWithCovarianceStamped,
             tolerance: float) -> bool:
    """
    Tell whether ``got`` (on the confirmation topic) acknowledges the ``handed`` pose.

    Same frame, stamped no earlier, within ``tolerance`` metres and ``tolerance`` radians.
    """
    if (got.header.frame_id or '').lstrip('/') != (handed.header.frame_id or '').lstrip('/'):
        return False
    if stamp_to_ns(got.header.stamp) < stamp_to_ns(handed.header.stamp):
        return False
    (x0, y0, a0), (x1, y1, a1) = pose_from_msg(handed.pose.pose), pose_from_msg(got.pose.pose)
    return (math.hypot(x1 - x0, y1 - y0) <= tolerance
            and abs(wrap_angle(a1 - a0)) <= tolerance)


class HandOver:
    """Publishes poses on ``initialpose`` until the confirmation topic acknowledges them."""

    def __init__(self, node: Any, publisher: Any, config: HandOverConfig,
                 callback_group: Any, log: Any) -> None:
        self._publisher = publisher
        self._config = config
        self._log = log
        self._node = node
        self._lock = threading.Lock()
        self._msg: PoseWithCovarianceStamped | None = None
        self._sent = 0
        self._sub = None
        self._timer = None
        if config.confirm_topic:
            self._sub = node.create_subscription(
                PoseWithCovarianceStamped, config.confirm_topic, self._on_confirmation,
                LATCHED_QOS, callback_group=callback_group)
            # steady time: retries are about processes starting, and go on in simulation
            # before /clock runs
            self._timer = node.create_timer(config.period, self._tick,
                                            callback_group=callback_group,
                                            clock=Clock(clock_type=ClockType.STEADY_TIME))
            self._timer.cancel()

    @property
    def pending(self) -> bool:
        """Tell whether a pose waits for its confirmation."""
        with self._lock:
            return self._msg is not None

    def start(self, msg: PoseWithCovarianceStamped) -> None:
        """Hand ``msg`` over (replacing a pose still waiting for its confirmation)."""
        with self._lock:
            self._msg = msg if self._timer is not None else None
            self._sent = 1
            self._publisher.publish(msg)
            if self._timer is not None:
                self._timer.reset()

    def stop(self) -> None:
        """Give up the pose being handed over (deactivation)."""
        with self._lock:
            self._msg = None
            if self._timer is not None:
                self._timer.cancel()

    def close(self) -> None:
        """Stop and destroy the timer and the subscription."""
        self.stop()
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
        if self._sub is not None:
            self._node.destroy_subscription(self._sub)
        self._timer = self._sub = None

    def _tick(self) -> None:
        with self._lock:
            msg = self._msg
            if msg is None:
                self._timer.cancel()
                return
            if self._sent >= self._config.tries:
                self._msg = None
                self._timer.cancel()
                give_up: Callable[[], None] = self._nobody_took_it
            else:
                self._sent += 1
                self._publisher.publish(msg)
                return
        give_up()

    def _nobody_took_it(self) -> None:
        self._log.error(
            f'hand-over: nobody took the pose published {self._config.tries} times on '
            f'{self._publisher.topic_name} (every {self._config.period:g} s): no pose within '
            f'{self._config.tolerance:g} m / rad of it came back on '
            f'{self._sub.topic_name}. Is AMCL running and active, with the same map frame? '
            '(parameters handover_confirm_topic, handover_tries, handover_period)')

    def _on_confirmation(self, got: PoseWithCovarianceStamped) -> None:
        with self._lock:
            msg = self._msg
            if msg is None or not confirms(msg, got, self._config.tolerance):
                return
            self._msg = None
            sent = self._sent
            self._timer.cancel()
        self._log.info(f'hand-over: {self._sub.topic_name} confirms the pose (published '
                       f'{sent} time{"s" if sent > 1 else ""} on {self._publisher.topic_name})')
