"""
``map_indexer`` lifecycle node: builds the topological index of every map it receives.

Lifecycle: configure reads the parameters and creates the publisher; activate subscribes
``map`` (nav_msgs/OccupancyGrid, reliable + transient-local) and indexes each map in a worker
thread (the newest map wins; a half-built index is never published), publishing
``topological_map`` (visualization_msgs/MarkerArray, transient-local) and writing ``index_file``
when it is set; deactivate unsubscribes; cleanup drops the index. With ``autostart`` (default)
the node configures and activates itself.
"""
from __future__ import annotations

import dataclasses
from functools import partial
from pathlib import Path
import threading
from typing import Any

from nav_msgs.msg import OccupancyGrid
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from ssm_localization.mapping.index import build_index, MapIndex
from ssm_localization.ros import markers
from ssm_localization.ros.executor import spin
from ssm_localization.ros.index_builder import BuildJob, IndexBuilder
from ssm_localization.ros.index_source import map_label, write_index
from ssm_localization.ros.lifecycle import (answer_invalid_transitions, configured_state,
                                            FAILURE, schedule_autostart, SUCCESS, transition)
from ssm_localization.ros.maps import usable_map
from ssm_localization.ros.parameter_guard import ParameterGuard
from ssm_localization.ros.parameters import config_problem, indexer_parameters, node_configs
from ssm_localization.ros.qos import LATCHED_QOS
from visualization_msgs.msg import MarkerArray


class MapIndexerNode(LifecycleNode):
    """Indexes each map received on ``map`` while active; publishes ``topological_map``."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('map_indexer', **kwargs)
        answer_invalid_transitions(self)
        self._guard = ParameterGuard(self, indexer_parameters(), (), {},
                                     partial(configured_state, self),
                                     config_problem)
        values = self._guard.declare()
        self._group = ReentrantCallbackGroup()
        self._lock = threading.Lock()
        self.index = None
        self.builder = None
        self._map_sub = None
        self._checksum: str | None = None
        self._destroying = False
        if values['autostart']:
            schedule_autostart(self)
        else:
            self.get_logger().info('autostart is false: waiting for configure / activate')

    @transition('configure')
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self._destroying:
            return FAILURE
        values = self._guard.values()
        self.index_config = node_configs(values).index
        self.index_file = str(values['index_file'])
        self.max_map_cells = int(values['max_map_cells'])
        self.max_gvd_points = int(values['max_gvd_points'])
        self.marker_pub = self.create_lifecycle_publisher(MarkerArray, 'topological_map',
                                                          LATCHED_QOS)
        self.builder = IndexBuilder(self.get_logger(), self._on_index, self._on_error)
        return SUCCESS

    @transition('activate')
    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)
        self._map_sub = self.create_subscription(OccupancyGrid, 'map', self._on_map,
                                                 LATCHED_QOS, callback_group=self._group)
        if self.index is not None:
            self._publish(self.index)
        self.get_logger().info(f'waiting for a map on {self.resolve_topic_name("map")}')
        return result

    @transition('deactivate')
    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._unsubscribe()
        return super().on_deactivate(state)

    @transition('cleanup')
    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return SUCCESS

    @transition('shutdown')
    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._unsubscribe()
        self._release()
        return SUCCESS

    def _unsubscribe(self) -> None:
        if self._map_sub is not None:
            self.destroy_subscription(self._map_sub)
            self._map_sub = None

    def _release(self) -> None:
        if self.builder is not None:
            self.builder.stop()
            self.builder = None
            self.destroy_lifecycle_publisher(self.marker_pub)
        with self._lock:
            self.index, self._checksum = None, None

    def _on_map(self, msg: OccupancyGrid) -> None:
        occ = usable_map(msg, self.max_map_cells, self.get_logger())
        if occ is None or self.builder is None:
            return
        checksum = occ.checksum()
        busy = self.builder.busy         # with another map: this newer one must supersede it
        with self._lock:
            index = self.index if checksum == self._checksum and not busy else None
            if index is not None and index.map.frame_id != occ.frame_id:
                index = self.index = dataclasses.replace(index, map=occ)
                moved = True
            else:
                moved = False
        if index is not None and not moved:
            self.get_logger().info('received the same map again: keeping its index')
            return
        if index is not None:
            self.get_logger().info(f'the same map in frame {occ.frame_id!r}: keeping its index')
            self._publish(index)
            self._save(index)
            return
        label = map_label(occ, checksum)
        self.get_logger().info(f'{label}: indexing')
        cfg = self.index_config
        # the index is published and saved here, not localized on: no ray caster kept
        self.builder.submit(BuildJob(label, partial(build_index, occ, cfg,
                                                    keep_caster=False)))

    def _publish(self, index) -> None:
        frame = getattr(index.map, 'frame_id', 'map') or 'map'
        stamp = self.get_clock().now().nanoseconds
        self.marker_pub.publish(markers.marker_array(
            markers.index_markers(index, frame, stamp, self.max_gvd_points), frame, stamp))

    def _on_index(self, job: BuildJob, index: MapIndex) -> None:
        with self._lock:
            self.index, self._checksum = index, index.map_checksum
        self.get_logger().info(f'{job.label}: index ready, {len(index.node_xy)} nodes')
        self._publish(index)
        self._save(index)

    def _save(self, index) -> None:
        if self.index_file:
            write_index(index, Path(self.index_file).expanduser(), self.get_logger())

    def _on_error(self, job: BuildJob, exc: BaseException) -> None:
        self.get_logger().warning(f'{job.label}: indexing failed ({type(exc).__name__}: {exc}); '
                                  'keeping the previous index')

    def destroy_node(self) -> None:
        """Stop the index worker, then destroy the node."""
        self._destroying = True
        self._unsubscribe()
        self._release()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run ssm_localization map_indexer``."""
    return spin(MapIndexerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
