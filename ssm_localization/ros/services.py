"""
Services that may decline to answer.

A std_srvs/Empty answer can only say "done": a caller such as nav2's behavior-tree node
``ReinitializeGlobalLocalization`` reads any answer as success, and no answer within its
``server_timeout`` as failure. :func:`create_withholding_service` lets a callback return
``None`` to send no answer at all, which is the only honest "no" such a caller can receive.
"""
from __future__ import annotations

from typing import Any, Callable

from rclpy.node import Node
from rclpy.service import Service


def create_withholding_service(node: Node, srv_type: Any, name: str,
                               callback: Callable[[Any, Any], Any], **kwargs: Any) -> Service:
    """
    Create a service whose ``callback(request, response)`` may return None: no answer is sent.

    rclpy's executor sends whatever the callback returns with ``Service.send_response``; the
    service returned here skips None instead (rclpy would raise TypeError in the executor).
    """
    service = node.create_service(srv_type, name, callback, **kwargs)
    send = service.send_response

    def send_or_withhold(response: Any, header: Any) -> None:
        if response is not None:
            send(response, header)

    service.send_response = send_or_withhold
    return service
