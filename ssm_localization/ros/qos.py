"""QoS profiles the nodes and the bag player share."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Reliable + transient-local, depth 1: what map_server offers and what latecomers need.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

# Services that may receive bursts of calls: the request reader and the response writer keep
# this many samples, so a burst is taken (and answered) rather than overwritten in DDS.
SERVICE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=256,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
