"""
Both nodes as lifecycle nodes over DDS.

Transitions through ``NODE/change_state``, each state's behaviour, the nav2-facing outputs
(``global_localization``, ``candidates``, ``/diagnostics``) and ``localize_on_start``, checked
against a bag's ground truth.
"""
from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped
from helpers import find_bag, LocalizerRig, REPO, ros_params, synthetic_map
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from ssm_localization.config.localization import LocalizerConfig
from ssm_localization.io.bag_reader import read_bag
from ssm_localization.ros.conversions import (laser_scan_from_record, occupancy_grid_from_map,
                                              pose_from_msg)
from ssm_localization.ros.map_indexer import MapIndexerNode
from ssm_localization.ros.qos import LATCHED_QOS
from ssm_localization.transforms import wrap_angle
from std_srvs.srv import Empty, Trigger
from visualization_msgs.msg import MarkerArray
import yaml

pytestmark = pytest.mark.ros


@pytest.fixture
def ros(ros_node_threads):
    """Return the harness with as many executor threads as the node's own main() uses."""
    return ros_node_threads


def _close(pose, truth, pos=0.2, yaw=0.05) -> bool:
    return (math.hypot(pose[0] - truth[0], pose[1] - truth[1]) < pos
            and abs(float(wrap_angle(pose[2] - truth[2]))) < yaw)


class Lifecycle:
    """get_state / change_state clients of one node."""

    def __init__(self, ros, name: str) -> None:
        self.ros = ros
        self.get = ros.node.create_client(GetState, f'{name}/get_state')
        self.change_client = ros.node.create_client(ChangeState, f'{name}/change_state')

    def state(self) -> str:
        res = self.ros.call(self.get, GetState.Request(), 10.0)
        assert res is not None, 'get_state did not answer'
        return res.current_state.label

    def change(self, transition: int) -> bool:
        res = self.ros.call(self.change_client,
                            ChangeState.Request(transition=Transition(id=transition)), 30.0)
        assert res is not None, 'change_state did not answer'
        return res.success


class Bag:
    """The committed depot_sim bag: map, scans and their ground truth."""

    def __init__(self) -> None:
        data = read_bag(find_bag('depot_sim'))
        self.map = data.map
        self.scans = [s for s in data.scans if s.stamp in data.ground_truth]
        self.truth = data.ground_truth


@pytest.fixture(scope='module')
def bag():
    return Bag()


class Rig(LocalizerRig):
    """The shared rig plus the lifecycle, ``global_localization`` and the published topics."""

    def __init__(self, ros, **params) -> None:
        params.setdefault('localizer.surface_depth', 0.0)      # simulated bag
        super().__init__(ros, **params)
        self.lifecycle = Lifecycle(ros, 'global_localizer')
        self.empty_client = ros.node.create_client(Empty, 'global_localization')
        self.setter = ros.node.create_client(SetParameters, 'global_localizer/set_parameters')
        self.initial = ros.collect(PoseWithCovarianceStamped, 'initialpose', 10)
        self.candidates = ros.collect(PoseArray, 'candidates', LATCHED_QOS)
        self.diagnostics = ros.collect(DiagnosticArray, '/diagnostics', 10)
        self.markers = ros.collect(MarkerArray, 'topological_map', LATCHED_QOS)

    def set_remote(self, name: str, value: int):
        """Set an integer parameter over DDS (the node's set_parameters service)."""
        req = SetParameters.Request(parameters=[ParameterMsg(name=name, value=ParameterValue(
            type=ParameterType.PARAMETER_INTEGER, integer_value=value))])
        res = self.ros.call(self.setter, req, 10.0)
        assert res is not None, 'set_parameters did not answer'
        return res.results[0]

    def our_status(self, arr: DiagnosticArray):
        return next((s for s in arr.status if 'global_localizer' in s.name), None)


def test_global_localizer_lifecycle_over_change_state(ros, bag):
    rig = Rig(ros, autostart=False)
    lc = rig.lifecycle
    scan0 = laser_scan_from_record(bag.scans[0])

    # unconfigured: clear answers, invalid transitions refused, node alive
    assert lc.state() == 'unconfigured'
    res = rig.call_relocalize(scan0, 10)
    assert not res.success and 'unconfigured' in res.message and 'configure' in res.message
    t0 = time.monotonic()
    rig.call(rig.empty_client, Empty.Request(), scan0, 10)       # answered, not left hanging
    assert time.monotonic() - t0 < 2.0
    assert not lc.change(Transition.TRANSITION_ACTIVATE)
    assert not lc.change(Transition.TRANSITION_DEACTIVATE)
    assert lc.state() == 'unconfigured'

    # configure: the map is indexed while inactive; calls are refused as inactive
    rig.map_pub.publish(occupancy_grid_from_map(bag.map))
    assert lc.change(Transition.TRANSITION_CONFIGURE)
    assert lc.state() == 'inactive'
    assert rig.wait_ready()
    res = rig.call_relocalize(scan0, 10)
    assert not res.success and 'inactive' in res.message and 'activate' in res.message
    assert not rig.poses and not rig.markers, 'an inactive node publishes nothing'

    # activate: global_localization (Empty) localizes the next scan and publishes
    assert lc.change(Transition.TRANSITION_ACTIVATE)
    assert lc.state() == 'active'
    assert ros.wait_for(lambda: rig.markers, 5), 'index markers published on activation'
    for k in (0, len(bag.scans) // 2):
        scan = bag.scans[k]
        n = len(rig.poses)
        rig.call(rig.empty_client, Empty.Request(), laser_scan_from_record(scan))
        assert ros.wait_for(lambda: len(rig.poses) > n, 5), 'no global_pose'
        pose = pose_from_msg(rig.poses[-1].pose.pose)
        assert _close(pose, bag.truth[scan.stamp]), (pose, bag.truth[scan.stamp])
        # candidates: ranked hypotheses, best first, in the map frame
        assert ros.wait_for(lambda: rig.candidates and rig.candidates[-1].header.stamp ==
                            rig.poses[-1].header.stamp, 5)
        cands = rig.candidates[-1]
        assert cands.header.frame_id == 'map' and 1 <= len(cands.poses) <= 10
        assert _close(pose_from_msg(cands.poses[0]), pose, 1e-6, 1e-6)
    # /diagnostics: OK with the key values of the last result
    assert ros.wait_for(lambda: any(rig.our_status(a) is not None and
                                    {v.key: v.value for v in rig.our_status(a).values}
                                    .get('status') == 'ok' for a in rig.diagnostics), 5)
    status = next(rig.our_status(a) for a in reversed(rig.diagnostics)
                  if rig.our_status(a) is not None)
    values = {v.key: v.value for v in status.values}
    assert status.level == DiagnosticStatus.OK and status.message.startswith('ok')
    assert values['map'] == 'ready' and values['lifecycle'] == 'active'
    assert values['map_note'] == ''            # 0.05 m cells: what the confidence knows
    assert int(values['node']) >= -1 and float(values['score']) > 0
    assert float(values['latency_ms']) > 0 and int(values['candidates']) == len(cands.poses)
    # the calibrated confidence of an ok answer reaches min_confidence
    assert float(values['confidence']) >= LocalizerConfig().min_confidence
    assert f"confidence={float(values['confidence']):.3f}" in status.message

    # deactivate: a waiting call is answered at once, later calls refused, nothing published
    future = rig.client.call_async(Trigger.Request())
    time.sleep(0.3)
    assert lc.change(Transition.TRANSITION_DEACTIVATE)
    assert ros.wait_for(future.done, 5)
    assert not future.result().success and 'deactivated' in future.result().message
    n = len(rig.poses)
    res = rig.call_relocalize(scan0, 10)
    assert not res.success and 'inactive' in res.message
    assert len(rig.poses) == n

    # configure-time parameters: refused while configured, taken while unconfigured
    result = rig.set_remote('localizer.top_n', 3)
    assert not result.successful and 'unconfigured' in result.reason
    # cleanup, configure again (the index is rebuilt from the latched map), shutdown
    assert lc.change(Transition.TRANSITION_CLEANUP)
    assert lc.state() == 'unconfigured' and rig.node.map_state().phase.reported == 'no map'
    assert rig.set_remote('localizer.top_n', 3).successful
    result = rig.set_remote('localizer.top_n', 0)           # the core refuses it: so do we
    assert not result.successful and 'top_n' in result.reason
    assert lc.change(Transition.TRANSITION_CONFIGURE) and rig.wait_ready()
    assert rig.node.localizer_config.top_n == 3
    assert lc.change(Transition.TRANSITION_ACTIVATE)
    res = rig.call_relocalize(scan0)
    assert res.success, res.message
    assert lc.change(Transition.TRANSITION_ACTIVE_SHUTDOWN)
    assert lc.state() == 'finalized'
    res = rig.call_relocalize(scan0, 10)
    assert not res.success and 'finalized' in res.message


def test_rviz_config_qos_matches_the_publishers(ros):
    """The QoS the RViz config subscribes with matches what the running node offers."""
    rviz = yaml.safe_load((REPO / 'rviz' / 'ssm_localization.rviz').read_text())
    displays = {d['Topic']['Value']: d['Topic'] for d in
                rviz['Visualization Manager']['Displays'] if 'Topic' in d}
    rig = Rig(ros)
    assert ros.wait_for(lambda: rig.lifecycle.state() == 'active', 10)
    durability = {DurabilityPolicy.TRANSIENT_LOCAL: 'Transient Local',
                  DurabilityPolicy.VOLATILE: 'Volatile'}
    reliability = {ReliabilityPolicy.RELIABLE: 'Reliable',
                   ReliabilityPolicy.BEST_EFFORT: 'Best Effort'}
    for topic in ('/global_pose', '/candidates', '/topological_map'):
        infos = ros.wait_for(lambda: [i for i in ros.node.get_publishers_info_by_topic(topic)
                                      if i.node_name == 'global_localizer'], 5)
        assert infos, f'global_localizer does not publish {topic}'
        qos = infos[0].qos_profile
        shown = displays[topic.lstrip('/')]          # relative in the RViz config
        assert shown['Durability Policy'] == durability[qos.durability], topic
        assert shown['Reliability Policy'] == reliability[qos.reliability], topic


def test_autostart_and_localize_on_start_hand_over_on_initialpose(ros, bag):
    """
    Default autostart.

    Active with no lifecycle call; localize_on_start publishes a right initialpose with no service
    call, then stays on demand (no confirmation topic: the pose is published once; the
    acknowledged hand-over: test_ros_nav2.py).
    """
    rig = Rig(ros, localize_on_start=True, publish_initialpose=True, handover_confirm_topic='')
    assert ros.wait_for(lambda: rig.lifecycle.state() == 'active', 10)
    rig.map_pub.publish(occupancy_grid_from_map(bag.map))
    picks = [bag.scans[k] for k in np.linspace(0, len(bag.scans) - 1, 6).astype(int)]
    end = time.monotonic() + 60
    k = 0
    while not rig.initial and time.monotonic() < end:
        rig.scan_pub.publish(laser_scan_from_record(picks[k % len(picks)]))
        k += 1
        time.sleep(0.1)
    assert rig.initial, 'no initialpose from localize_on_start'
    msg = rig.initial[0]
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    scan = min(picks, key=lambda s: abs(s.stamp - stamp))
    assert abs(scan.stamp - stamp) < 1e-6 and msg.header.frame_id == 'map'
    assert _close(pose_from_msg(msg.pose.pose), bag.truth[scan.stamp])
    # back to on demand: more scans, no more poses
    n = len(rig.poses)
    for scan in picks:
        rig.scan_pub.publish(laser_scan_from_record(scan))
        time.sleep(0.1)
    time.sleep(0.5)
    assert len(rig.poses) == n and len(rig.initial) == 1


def test_map_indexer_lifecycle(ros):
    node = ros.add(MapIndexerNode(context=ros.context, parameter_overrides=ros_params(
        autostart=False)))
    lc = Lifecycle(ros, 'map_indexer')
    got = ros.collect(MarkerArray, 'topological_map', LATCHED_QOS)
    pub = ros.node.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
    pub.publish(occupancy_grid_from_map(synthetic_map(0)))
    assert lc.state() == 'unconfigured'
    assert lc.change(Transition.TRANSITION_CONFIGURE) and lc.state() == 'inactive'
    time.sleep(0.5)
    assert node.index is None and not got, 'inactive: no map taken'
    assert lc.change(Transition.TRANSITION_ACTIVATE)
    assert ros.wait_for(lambda: node.index is not None, 60) and ros.wait_for(lambda: got, 5)
    assert lc.change(Transition.TRANSITION_DEACTIVATE)
    first = node.index
    pub.publish(occupancy_grid_from_map(synthetic_map(2)))
    time.sleep(0.5)
    assert node.index is first, 'inactive: new maps are not indexed'
    assert lc.change(Transition.TRANSITION_CLEANUP) and node.index is None
    assert not lc.change(Transition.TRANSITION_DEACTIVATE)
    assert lc.change(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
    assert lc.state() == 'finalized'
