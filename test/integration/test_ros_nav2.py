"""
What nav2 expects of global_localizer, over DDS with the real node.

nav2's behavior-tree service ``reinitialize_global_localization`` (answered at once when a search
starts, never when none can), the acknowledged hand-over on ``initialpose`` (republished until a
stand-in AMCL confirms it on ``amcl_pose``, started late; a clear error when nobody does), a pose
on ``initialpose`` received before configure kept as the track prior, and the Trigger service's
honest failures. The stand-in AMCL is a plain rclpy subscriber / publisher in the test process.
"""
from __future__ import annotations

import time

from geometry_msgs.msg import PoseWithCovarianceStamped
from helpers import close_pose, LocalizerRig, synthetic_map
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ssm_localization import simulate, SimulationConfig
from ssm_localization.ros.conversions import (laser_scan_from_record, occupancy_grid_from_map,
                                              pose_from_msg)
from ssm_localization.ros.handover import confirms
from ssm_localization.ros.lifecycle import state_label
from ssm_localization.ros.qos import LATCHED_QOS
from std_srvs.srv import Empty, Trigger

pytestmark = pytest.mark.ros

POS_TOL, YAW_TOL = 0.15, 0.05
VOLATILE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def ros(ros_node_threads):
    """Return the harness with as many executor threads as the node's own main() uses."""
    return ros_node_threads


@pytest.fixture(scope='module')
def world():
    occ = synthetic_map(0)
    sim = simulate(occ, SimulationConfig(count=4, seed=5, clearance=0.4, noise_sigma=0.005,
                                         stamp0=100.0))
    return occ, sim


def _feed(rig, sim, until, timeout: float = 30.0, k: int = 0):
    """Publish the simulated scans (10 Hz, in turn) until ``until()``; return its value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = until()
        if value:
            return value
        rig.scan_pub.publish(laser_scan_from_record(sim.scans[k % len(sim.scans)]))
        k += 1
        time.sleep(0.1)
    return until()


def _truth(sim, msg):
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    k = min(range(len(sim.scans)), key=lambda i: abs(sim.scans[i].stamp - stamp))
    return sim.poses[k]


# ---------------------------------------------------------------------------- the BT service

def test_reinitialize_service_exists_only_when_configured_to_replace_amcls(ros):
    rig = LocalizerRig(ros, autostart=False)
    client = ros.node.create_client(Empty, 'reinitialize_global_localization')
    assert not client.wait_for_service(timeout_sec=1.0)
    # set while unconfigured: served from the next configure on
    assert rig.node.set_parameters([Parameter('serve_reinitialize_global_localization',
                                              value=True)])[0].successful
    change = ros.node.create_client(ChangeState, 'global_localizer/change_state')
    assert ros.call(change, ChangeState.Request(
        transition=Transition(id=Transition.TRANSITION_CONFIGURE))).success
    assert client.wait_for_service(timeout_sec=5.0)


def test_bt_call_is_not_answered_when_no_search_can_start(ros, world, capfd):
    """Unconfigured, then active without a map: no answer (the BT reads FAILURE); node up."""
    occ, sim = world
    rig = LocalizerRig(ros, autostart=False, serve_reinitialize_global_localization=True)
    client = ros.node.create_client(Empty, 'reinitialize_global_localization')
    assert client.wait_for_service(timeout_sec=10.0), 'served from the start (BT load time)'
    unanswered = client.call_async(Empty.Request())
    time.sleep(0.5)
    assert not unanswered.done()
    change = ros.node.create_client(ChangeState, 'global_localizer/change_state')
    for t in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
        assert ros.call(change, ChangeState.Request(transition=Transition(id=t))).success
    rig.scan_pub.publish(laser_scan_from_record(sim.scans[0]))      # a scan, but no map
    late = client.call_async(Empty.Request())
    time.sleep(0.5)
    assert not late.done() and not unanswered.done()
    err = capfd.readouterr().err
    assert 'reinitialize_global_localization: not answered' in err and 'not active' in err
    assert 'no map/index yet' in err
    # the node is up and answers the Trigger service with the reason
    res = rig.call_relocalize()
    assert not res.success and 'no map/index yet' in res.message
    assert state_label(rig.node) == 'active'


def test_bt_call_answered_at_once_and_the_robot_relocalized(ros, world, capfd):
    occ, sim = world
    rig = LocalizerRig(ros, serve_reinitialize_global_localization=True)
    rig.map_pub.publish(occupancy_grid_from_map(occ))
    assert rig.wait_ready()
    client = ros.node.create_client(Empty, 'reinitialize_global_localization')
    assert client.wait_for_service(timeout_sec=10.0)
    _feed(rig, sim, lambda: rig.node._mailbox.age() is not None, 10)
    t0 = time.monotonic()
    future = client.call_async(Empty.Request())
    assert ros.wait_for(future.done, 2.0, 0.001), 'answered once the search started'
    answered = time.monotonic() - t0
    n = len(rig.poses)
    assert _feed(rig, sim, lambda: len(rig.poses) > n, 30, k=1), 'no global_pose after the call'
    msg = rig.poses[-1]
    assert close_pose(pose_from_msg(msg.pose.pose), _truth(sim, msg), POS_TOL, YAW_TOL)
    assert answered < 0.5, f'{answered * 1000:.0f} ms'     # nav2's 20 ms on an idle machine
    err = ros.wait_for_log(capfd, 'reinitialize_global_localization: localized')
    assert 'reinitialize_global_localization: localized' in err


# ---------------------------------------------------------------------------- the hand-over

class StandInAmcl:
    """AMCL's side of the hand-over: initialpose in (volatile), amcl_pose out (latched)."""

    def __init__(self, ros):
        self.got: list = []
        self.pub = ros.node.create_publisher(PoseWithCovarianceStamped, 'amcl_pose',
                                             LATCHED_QOS)
        ros.node.create_subscription(PoseWithCovarianceStamped, 'initialpose', self._on_pose,
                                     VOLATILE)

    def _on_pose(self, msg):
        self.got.append(msg)
        self.pub.publish(msg)


def test_handover_republished_until_a_late_amcl_confirms(ros, world, capfd):
    occ, sim = world
    rig = LocalizerRig(ros, localize_on_start=True, publish_initialpose=True,
                       handover_period=0.2)
    rig.map_pub.publish(occupancy_grid_from_map(occ))
    assert rig.wait_ready()
    assert _feed(rig, sim, lambda: rig.poses, 30), 'localize_on_start published nothing'
    assert rig.node.handover.pending
    time.sleep(1.0)                     # nobody listens yet: several publications lost
    amcl = StandInAmcl(ros)
    assert ros.wait_for(lambda: amcl.got, 5.0), 'the late AMCL never got the pose'
    assert ros.wait_for(lambda: not rig.node.handover.pending, 5.0)
    time.sleep(0.6)
    n = len(amcl.got)
    time.sleep(0.6)
    assert len(amcl.got) == n, 'republished after the confirmation'
    handed = amcl.got[0]
    assert close_pose(pose_from_msg(handed.pose.pose), _truth(sim, handed), POS_TOL, YAW_TOL)
    assert handed.header.stamp == rig.poses[-1].header.stamp     # the scan's stamp, kept
    err = ros.wait_for_log(capfd, 'hand-over: ', 'confirms the pose (published')
    assert 'hand-over: ' in err and 'confirms the pose (published' in err


def test_handover_gives_up_with_a_clear_error(ros, world, capfd):
    occ, sim = world
    rig = LocalizerRig(ros, localize_on_start=True, publish_initialpose=True,
                       handover_period=0.1, handover_tries=3)
    rig.map_pub.publish(occupancy_grid_from_map(occ))
    assert rig.wait_ready()
    assert _feed(rig, sim, lambda: rig.poses, 30)
    assert ros.wait_for(lambda: not rig.node.handover.pending, 5.0)
    err = ros.wait_for_log(capfd, 'hand-over: nobody took', 'Is AMCL running and active')
    assert 'hand-over: nobody took the pose published 3 times on /initialpose' in err
    assert '/amcl_pose' in err and 'Is AMCL running and active' in err


def test_confirmation_needs_the_same_frame_a_later_stamp_and_a_close_pose():
    def msg(x, stamp, frame='map'):
        m = PoseWithCovarianceStamped()
        m.header.frame_id, m.header.stamp.sec = frame, stamp
        m.pose.pose.position.x = x
        m.pose.pose.orientation.w = 1.0
        return m
    handed = msg(1.0, 10)
    assert confirms(handed, msg(1.3, 11), 0.5)
    assert not confirms(handed, msg(1.3, 9), 0.5)            # older: AMCL's latched pose
    assert not confirms(handed, msg(2.0, 11), 0.5)           # elsewhere
    assert not confirms(handed, msg(1.0, 11, 'odom'), 0.5)


# ---------------------------------------------------------------------------- lifecycle

def test_initialpose_before_configure_is_the_track_prior(ros, world, capfd):
    occ, sim = world
    rig = LocalizerRig(ros, autostart=False, mode='track')
    pub = ros.node.create_publisher(PoseWithCovarianceStamped, 'initialpose', VOLATILE)
    prior = PoseWithCovarianceStamped()
    prior.header.frame_id = 'map'
    prior.pose.pose.position.x, prior.pose.pose.position.y = sim.poses[0][:2]
    prior.pose.pose.orientation.w = 1.0
    assert ros.wait_for(lambda: pub.get_subscription_count() > 0, 5.0)
    pub.publish(prior)
    assert ros.wait_for(lambda: rig.node._early_prior is not None, 5.0)
    change = ros.node.create_client(ChangeState, 'global_localizer/change_state')
    assert ros.call(change, ChangeState.Request(
        transition=Transition(id=Transition.TRANSITION_CONFIGURE))).success
    # kept for the track; its frame is judged against the map's once the map is indexed
    assert rig.node._pending_prior is not None and not rig.node.session.waiting_prior
    rig.map_pub.publish(occupancy_grid_from_map(occ))
    assert rig.wait_ready()
    assert ros.wait_for(lambda: rig.node.session.waiting_prior, 5.0)
    err = capfd.readouterr().err
    assert 'initialpose received before configure: kept' in err
    assert f'track: prior from initialpose x={sim.poses[0][0]:.3f}' in err


def test_trigger_reports_each_failure_honestly(ros, world):
    occ, sim = world
    rig = LocalizerRig(ros, autostart=False, scan_timeout=0.5)
    res = rig.call_relocalize()
    assert not res.success and 'unconfigured, not active' in res.message
    change = ros.node.create_client(ChangeState, 'global_localizer/change_state')
    for t in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
        assert ros.call(change, ChangeState.Request(transition=Transition(id=t))).success
    res = rig.call_relocalize()
    assert not res.success and 'no map/index yet' in res.message
    rig.map_pub.publish(occupancy_grid_from_map(occ))
    assert rig.wait_ready()
    res = rig.call_relocalize()
    assert not res.success and res.message.startswith('no scan received on /scan within 0.5')
    blind = laser_scan_from_record(sim.scans[0])
    blind.ranges = [float('inf')] * len(blind.ranges)       # nothing seen: nothing localized
    res = rig.call_relocalize(blind)
    assert not res.success and res.message.startswith('bad scan'), res.message
    res = rig.call_relocalize(laser_scan_from_record(sim.scans[0]))
    assert res.success and 'status=ok' in res.message
    trigger = ros.node.create_client(Trigger, 'relocalize')
    assert trigger.wait_for_service(timeout_sec=1.0)
