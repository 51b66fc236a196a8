"""``map_indexer`` node: builds the topological index of every map it receives.

Subscribes ``map`` (nav_msgs/OccupancyGrid, reliable + transient-local), builds the index
(GVD nodes + virtual scans) in a worker thread, publishes ``topological_map``
(visualization_msgs/MarkerArray, transient-local) and writes ``index_file`` when it is set.
A newer map supersedes the one being indexed; a half-built index is never published.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from nav_msgs.msg import OccupancyGrid
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from visualization_msgs.msg import MarkerArray

from ssm_localization.config import IndexConfig
from ssm_localization.mapping.index import build_index, save_index
from ssm_localization.ros import markers
from ssm_localization.ros.executor import spin
from ssm_localization.ros.index_builder import IndexBuilder
from ssm_localization.ros.maps import usable_map
from ssm_localization.ros.parameters import (build_config, declare_table, indexer_parameters,
                                             laser_pose_of)
from ssm_localization.ros.qos import LATCHED_QOS


class MapIndexerNode(Node):
    """Indexes each map received on ``map``; publishes ``topological_map``."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('map_indexer', **kwargs)
        values = declare_table(self, indexer_parameters())
        self.laser_pose = laser_pose_of(values)
        self.index_config = build_config(IndexConfig, 'index', values, self.laser_pose)
        self.index_file = str(values['index_file'])
        self.max_map_cells = int(values['max_map_cells'])
        self.max_gvd_points = int(values['max_gvd_points'])
        self.index = None
        self._group = ReentrantCallbackGroup()
        self.marker_pub = self.create_publisher(MarkerArray, 'topological_map', LATCHED_QOS)
        self.create_subscription(OccupancyGrid, 'map', self._on_map, LATCHED_QOS,
                                 callback_group=self._group)
        self.builder = IndexBuilder(self.get_logger(), self._on_index, self._on_error)
        self.get_logger().info(f'waiting for a map on {self.resolve_topic_name("map")}')

    def _on_map(self, msg: OccupancyGrid) -> None:
        occ = usable_map(msg, self.max_map_cells, self.get_logger())
        if occ is None:
            return
        label = f'map {occ.width}x{occ.height} @ {occ.resolution:g} m ({occ.checksum()[:8]})'
        self.get_logger().info(f'{label}: indexing')
        cfg = self.index_config
        self.builder.submit(label, lambda progress: build_index(occ, cfg, progress=progress))

    def _on_index(self, index, label: str) -> None:
        self.index = index
        n = len(index.node_xy)
        self.get_logger().info(f'{label}: index ready, {n} nodes')
        frame = getattr(index.map, 'frame_id', 'map') or 'map'
        stamp = self.get_clock().now().nanoseconds
        self.marker_pub.publish(markers.marker_array(
            markers.index_markers(index, frame, stamp, self.max_gvd_points), frame, stamp))
        if self.index_file:
            path = Path(self.index_file).expanduser()
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                save_index(index, path)
                self.get_logger().info(f'index written to {path}')
            except (OSError, ValueError) as exc:
                self.get_logger().error(f'cannot write index file {path}: {exc}')

    def _on_error(self, exc: BaseException, label: str) -> None:
        self.get_logger().warning(f'{label}: indexing failed ({type(exc).__name__}: {exc}); '
                                  'keeping the previous index')

    def destroy_node(self) -> None:
        self.builder.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return spin(MapIndexerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
