"""
Test ``global_localizer`` in ``mode: track`` over DDS, and the ROS glue of tracking.

The node runs in-process (DDS on localhost, unique domain); the committed bag
``bags/intel_track`` (real Intel scans 1-2 m apart, raw odometry, two kidnaps) is played scan by
scan on ``odom`` and ``scan``, and the ``global_pose`` stream is checked against its ground truth.
"""
from __future__ import annotations

import copy
import math
import time

from geometry_msgs.msg import PoseWithCovarianceStamped
from helpers import find_bag
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from ssm_localization import read_bag
from ssm_localization.ros.conversions import (covariance6, pose_from_msg, pose_msg, stamp_to_sec,
                                              time_msg)
from ssm_localization.ros.lifecycle import state_label
from ssm_localization.ros.odometry import (CLOCK_RESET, map_to_odom, MapOdomBroadcaster,
                                           OdometryBuffer, OdometrySource, transform_pose)
from ssm_localization.ros.play import timeline
from ssm_localization.ros.qos import LATCHED_QOS
from ssm_localization.transforms import compose, wrap_angle
from std_srvs.srv import Trigger

pytestmark = pytest.mark.ros


def _right(pose, truth) -> bool:
    return (math.hypot(pose[0] - truth[0], pose[1] - truth[1]) <= 0.5
            and abs(float(wrap_angle(pose[2] - truth[2]))) <= math.radians(5))


def _odometry(pose, stamp: float) -> Odometry:
    msg = Odometry()
    msg.header.stamp = time_msg(stamp)
    msg.header.frame_id, msg.child_frame_id = 'odom', 'base_link'
    msg.pose.pose = pose_msg(pose)
    return msg


class TrackingNode:
    """A GlobalLocalizerNode in track mode with map, odom, scan and initialpose publishers."""

    def __init__(self, ros, **params) -> None:
        from ssm_localization.ros.global_localizer import GlobalLocalizerNode
        params = {'mode': 'track', 'publish_markers': False, **params}
        self.ros = ros
        self.node = ros.add(GlobalLocalizerNode(
            context=ros.context, parameter_overrides=[Parameter(k, value=v)
                                                      for k, v in params.items()]))
        self.map_pub = ros.node.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
        self.scan_pub = ros.node.create_publisher(LaserScan, 'scan', qos_profile_sensor_data)
        self.odom_pub = ros.node.create_publisher(
            Odometry, 'odom', QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self.prior_pub = ros.node.create_publisher(PoseWithCovarianceStamped, 'initialpose', 10)
        self.poses = ros.collect(PoseWithCovarianceStamped, 'global_pose', LATCHED_QOS)
        assert ros.wait_for(lambda: state_label(self.node) == 'active', 10), 'not autostarted'

    def ready(self, grid: OccupancyGrid, timeout: float = 120.0) -> bool:
        self.map_pub.publish(grid)
        return bool(self.ros.wait_for(
            lambda: self.node.map_state().phase.reported == 'ready', timeout, 0.05))

    def step(self, scan: LaserScan, odom: Odometry | None, timeout: float = 30.0) -> None:
        """Publish the odometry (until the node has it), then the scan until it was tracked."""
        session = self.node.session
        if odom is not None:
            have = len(session.odometry.buffer)
            end = time.monotonic() + timeout
            while len(session.odometry.buffer) == have and time.monotonic() < end:
                self.odom_pub.publish(odom)
                time.sleep(0.02)
        count, last = session.count, self.node._last
        end = time.monotonic() + timeout
        while session.count == count and time.monotonic() < end:
            self.scan_pub.publish(scan)
            self.ros.wait_for(lambda: session.count > count, 0.5)
        assert session.count > count, 'the scan was not tracked'
        self.ros.wait_for(lambda: self.node._last is not last, 5.0)   # and its result stored

    def settle(self, quiet: float = 0.5, timeout: float = 30.0) -> None:
        """Wait until no scan was tracked for ``quiet`` s (scans still on their way)."""
        session = self.node.session
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            count = session.count
            if not self.ros.wait_for(lambda: session.count != count, quiet):
                return


@pytest.fixture(scope='module')
def bag():
    data = read_bag(find_bag('intel_track'))
    assert data.map is not None and data.odom and data.ground_truth
    grid, items = timeline(data, topics=['/map', '/scan', '/odom'])
    scans = [it for it in items if it.topic == '/scan']
    odom = {it.stamp: it.msg for it in items if it.topic == '/odom'}
    truth = [data.ground_truth[it.stamp] for it in scans]
    kidnaps = [k for k in range(1, len(truth))
               if math.dist(truth[k][:2], truth[k - 1][:2]) > 3.0]
    assert len(kidnaps) == 2
    return grid, scans, odom, truth, kidnaps


def test_track_mode_follows_the_bag_and_recovers_from_kidnaps(ros, bag):
    grid, scans, odom, truth, kidnaps = bag
    node = TrackingNode(ros)
    assert node.ready(grid)
    stamp_index = {round(it.stamp, 6): k for k, it in enumerate(scans)}
    for it in scans:
        node.step(it.msg, odom[it.stamp])
    assert node.node.session.count == len(scans)
    assert ros.wait_for(lambda: round(stamp_to_sec(node.poses[-1].header.stamp), 6)
                        == round(scans[-1].stamp, 6) if node.poses else False, 5.0)
    published = {}
    for msg in node.poses:
        k = stamp_index[round(stamp_to_sec(msg.header.stamp), 6)]
        published[k] = pose_from_msg(msg.pose.pose)
        assert msg.header.frame_id == 'map'
        assert np.all(np.isfinite(msg.pose.covariance))
    right = {k for k, pose in published.items() if _right(pose, truth[k])}
    assert len(published) >= 0.95 * len(scans), f'{len(published)} poses of {len(scans)} scans'
    assert len(right) >= len(published) - 1, sorted(set(published) - right)
    for start in [0] + kidnaps:            # first fix and each recovery within 3 scans,
        fix = next(k for k in sorted(right) if k >= start)    # no wrong pose before it
        assert fix - start < 3, (start, fix)
        assert all(k in right for k in published if start <= k < fix), (start, fix)


def test_a_blind_scan_reaches_the_tracker_and_coasts(ros, bag):
    """Track mode lets a scan with no return through: the map agrees, the track coasts on."""
    grid, scans, odom, truth, _ = bag
    node = TrackingNode(ros, publish_markers=True)
    assert node.ready(grid)
    node.step(scans[0].msg, odom[scans[0].stamp])
    assert node.node._last is not None and node.node._last.status == 'ok'
    blind = copy.deepcopy(scans[1].msg)
    blind.ranges = [math.inf] * len(blind.ranges)     # nothing within 0.3 m: nothing seen
    blind.range_max = 0.3
    node.step(blind, odom[scans[1].stamp])
    last = node.node._last
    assert 'coasting on odometry' in last.message, last.message
    assert _right(last.pose, truth[1])
    node.step(scans[2].msg, odom[scans[2].stamp])
    assert node.node._last.status == 'ok' and _right(node.node._last.pose, truth[2])


def test_track_mode_takes_initialpose_and_the_service_answer_as_prior(ros, bag):
    grid, scans, odom, truth, _ = bag
    node = TrackingNode(ros)
    assert node.ready(grid)
    prior = PoseWithCovarianceStamped()
    prior.header.frame_id = 'map'
    prior.pose.pose = pose_msg(compose(truth[10], (0.2, -0.1, 0.05)))
    prior.pose.covariance = covariance6(np.diag([0.09, 0.09, 0.02]))
    node.prior_pub.publish(prior)
    assert ros.wait_for(lambda: node.node.session.waiting_prior, 5.0)
    node.step(scans[10].msg, odom[scans[10].stamp])
    last = node.node._last
    assert last.status == 'ok' and last.message.startswith('tracked'), last.message
    assert _right(last.pose, truth[10])
    # relocalize in track mode: answered from the next scan, the track goes on from it
    client = ros.node.create_client(Trigger, 'relocalize')
    assert client.wait_for_service(timeout_sec=10.0)
    future = client.call_async(Trigger.Request())
    while not future.done():
        node.odom_pub.publish(odom[scans[11].stamp])
        node.scan_pub.publish(scans[11].msg)
        time.sleep(0.05)
    assert future.result().success, future.result().message
    node.settle()                      # scan 11, sent again and again, is not taken for scan 12
    node.step(scans[12].msg, odom[scans[12].stamp])
    last = node.node._last
    assert last.status == 'ok' and last.message.startswith('tracked'), last.message
    assert _right(last.pose, truth[12])


def test_a_new_map_frame_does_not_restart_the_track(ros, bag, capfd):
    """The same map in another frame keeps the tracker and its laser-mount localizer."""
    grid, scans, odom, _, _ = bag

    def in_base_frame(scan):
        msg = copy.deepcopy(scan)
        msg.header.frame_id = 'base_link'      # mount (0, 0, 0), not laser_x: a variant
        return msg
    node = TrackingNode(ros, laser_x=0.1)
    assert node.ready(grid)
    node.step(in_base_frame(scans[0].msg), odom[scans[0].stamp])
    session = node.node.session
    tracker = session._tracker
    assert tracker is not None and tracker.localizer is not node.node.source.served.localizer
    moved = copy.deepcopy(grid)
    moved.header.frame_id = 'world'
    node.map_pub.publish(moved)
    assert ros.wait_for(lambda: node.node._marks_frame == 'world', 10)   # markers redrawn
    node.step(in_base_frame(scans[1].msg), odom[scans[1].stamp])
    assert session._tracker is tracker
    assert 'laser mount changed' not in capfd.readouterr().err


def test_a_prior_before_the_map_is_judged_in_the_maps_frame(ros, bag):
    """An initialpose that comes before the map is checked against the map's own frame."""
    grid, _, _, truth, _ = bag
    world = copy.deepcopy(grid)
    world.header.frame_id = 'world'
    for frame, taken in (('world', True), ('map', False)):
        node = TrackingNode(ros)
        prior = PoseWithCovarianceStamped()
        prior.header.frame_id = frame
        prior.pose.pose = pose_msg(truth[10])
        prior.pose.covariance = covariance6(np.diag([0.09, 0.09, 0.02]))
        node.prior_pub.publish(prior)
        assert ros.wait_for(lambda: node.node._pending_prior is not None, 5.0), frame
        assert not node.node.session.waiting_prior
        assert node.ready(world)
        assert ros.wait_for(lambda: node.node._pending_prior is None, 5.0)
        assert node.node.session.waiting_prior is taken, frame
        ros.remove(node.node)


def test_track_mode_parameters_are_checked(ros):
    from ssm_localization.ros.global_localizer import GlobalLocalizerNode
    with pytest.raises(Exception, match='tracker'):
        GlobalLocalizerNode(context=ros.context, parameter_overrides=[
            Parameter('mode', value='track'),
            Parameter('tracker.window_xy', value=[2.0, 1.0])])


# ---------------------------------------------------------------------------- ROS glue

def test_odometry_buffer_interpolates_and_refuses_stale_odometry():
    buf = OdometryBuffer(max_age=0.5)
    assert buf.pose_at(1.0) is None
    buf.add(_odometry((0.0, 0.0, 3.1), 10.0))
    buf.add(_odometry((1.0, 2.0, -3.1), 10.2))
    buf.add(_odometry((5.0, 5.0, 0.0), 10.1))            # out of order: dropped
    assert len(buf) == 2
    x, y, yaw = buf.pose_at(10.1)
    assert (x, y) == pytest.approx((0.5, 1.0))
    assert abs(float(wrap_angle(yaw - math.pi))) < 1e-6      # the short way round
    assert buf.pose_at(10.2) == pytest.approx((1.0, 2.0, -3.1))
    assert buf.pose_at(10.6) == pytest.approx((1.0, 2.0, -3.1))   # nearest within 0.5 s
    assert buf.pose_at(10.8) is None and buf.pose_at(9.0) is None
    bad = _odometry((0.0, 0.0, 0.0), 11.0)
    bad.pose.pose.position.x = math.nan
    buf.add(bad)
    assert len(buf) == 2
    buf.add(_odometry((7.0, 7.0, 0.0), 10.2 - CLOCK_RESET - 3.0))     # the bag played again
    assert len(buf) == 1 and buf.pose_at(10.2 - CLOCK_RESET - 3.0) == (7.0, 7.0, 0.0)


def test_replay_uses_the_nodes_odom_max_age():
    from ssm_localization.evaluation.tracking import ODOM_MAX_AGE
    from ssm_localization.ros.parameters import NODE_PARAMS
    assert NODE_PARAMS['odom_max_age'][0] == ODOM_MAX_AGE


class _TfBuffer:
    """A stand-in for tf2_ros.Buffer: one fixed odom <- base_link transform."""

    def __init__(self, pose) -> None:
        self.pose, self.asked = pose, []

    def lookup_transform(self, target, source, time_, timeout):
        from ssm_localization.ros.odometry import transform_stamped
        self.asked.append((target, source))
        if self.pose is None:
            raise RuntimeError('no transform')
        return transform_stamped(self.pose, 0, target, source)


def test_odometry_from_tf_when_the_topic_is_silent():
    tf = _TfBuffer((3.0, -1.0, 0.5))
    source = OdometrySource(OdometryBuffer(0.5), '/odom', 'base_link', tf)
    assert source.pose_at(5.0) == pytest.approx((3.0, -1.0, 0.5))
    assert tf.asked == [('odom', 'base_link')] and source.last_source.startswith('TF')
    source.buffer.add(_odometry((1.0, 1.0, 0.0), 5.0))
    assert source.pose_at(5.0) == (1.0, 1.0, 0.0) and source.last_source == 'odom topic'
    assert OdometrySource(OdometryBuffer(0.5), 'odom', 'base_link',
                          _TfBuffer(None)).pose_at(5.0) is None


def test_map_to_odom_is_broadcast_as_amcl_does():
    map_base, odom_base = (10.0, 5.0, 1.0), (2.0, -1.0, 0.3)
    t = map_to_odom(map_base, odom_base)
    assert compose(t, odom_base) == pytest.approx(map_base)
    sent = []

    class Sender:
        def sendTransform(self, msg):  # noqa: N802 - tf2_ros's name
            sent.append(msg)
    caster = MapOdomBroadcaster(Sender(), 'odom', tolerance=1.0)
    assert not caster.update(None, odom_base, 5.0, 'map')         # nothing before a pose
    assert caster.update(map_base, odom_base, 5.0, 'map')
    assert caster.update(None, None, 6.0, 'map')                  # the last one again
    assert len(sent) == 2 and sent[0].header.frame_id == 'map'
    assert sent[0].child_frame_id == 'odom'
    assert stamp_to_sec(sent[0].header.stamp) == pytest.approx(6.0)   # + transform_tolerance
    assert transform_pose(sent[1].transform) == pytest.approx(t)


def test_a_scan_delivered_twice_is_tracked_once():
    """The same stamp again (or one out of order) is skipped; a clock reset is tracked."""
    from ssm_localization import build_index, GlobalLocalizer
    from ssm_localization.config import TrackerConfig
    from ssm_localization.evaluation.replay import match_truth
    from ssm_localization.ros.tracking import TrackSession
    data = read_bag(find_bag('intel_track'))
    loc = GlobalLocalizer(build_index(data.map))
    odom = match_truth([s.stamp for s in data.scans], data.odom)
    buffer = OdometryBuffer(max_age=0.5)
    session = TrackSession(TrackerConfig(), OdometrySource(buffer, 'odom', 'base_link', None),
                           None, lambda line: None)

    def track(k: int, stamp: float):
        buffer.add(_odometry(odom[k], stamp))
        return session.track(loc, data.scans[k], time_msg(stamp), 'map')
    t0 = data.scans[0].stamp
    assert track(0, t0).ok and session.count == 1
    assert track(0, t0) is None and session.count == 1            # delivered twice
    assert track(1, data.scans[1].stamp).ok and session.count == 2
    late = data.scans[1].stamp - 0.5 * CLOCK_RESET
    assert track(0, late) is None and session.count == 2          # out of order
    reset = data.scans[1].stamp - CLOCK_RESET - 5.0                  # a bag played again
    assert track(2, reset) is not None and session.count == 3
