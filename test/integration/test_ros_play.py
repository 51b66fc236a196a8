"""``ssm_localization play``: bag timeline and publishing (in-process, localhost DDS)."""
from __future__ import annotations

import argparse
import time

from geometry_msgs.msg import PoseStamped
from helpers import find_bag
from nav_msgs.msg import OccupancyGrid, Odometry
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan
from ssm_localization.ros.conversions import stamp_to_sec
from ssm_localization.ros.play import BagPlayer, timeline
from ssm_localization.ros.qos import LATCHED_QOS

pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def intel():
    from ssm_localization import read_bag
    return read_bag(find_bag('intel_queries'))


def test_timeline_order_topics_and_window(intel):
    grid, items = timeline(intel)
    assert isinstance(grid, OccupancyGrid) and grid.header.frame_id == 'map'
    stamps = [it.stamp for it in items]
    assert stamps == sorted(stamps)
    topics = {it.topic for it in items}
    assert topics == {'/scan', '/ground_truth', '/odom'}
    assert sum(it.topic == '/scan' for it in items) == len(intel.scans)
    first_scan = next(it for it in items if it.topic == '/scan')
    assert isinstance(first_scan.msg, LaserScan)
    # at equal stamps the scan goes first
    k = stamps.index(first_scan.stamp)
    assert items[k].topic == '/scan'

    grid, items = timeline(intel, topics=['scan'])
    assert grid is None and {it.topic for it in items} == {'/scan'}
    t0 = intel.scans[0].stamp
    k = 10
    _, items = timeline(intel, topics=['/scan', '/ground_truth'],
                        start_offset=intel.scans[k].stamp - t0 - 1e-4, duration=2e-4)
    assert [it.topic for it in items] == ['/scan', '/ground_truth']
    assert items[0].stamp == intel.scans[k].stamp
    assert isinstance(items[1].msg, PoseStamped)


def test_player_publishes_latched_map_and_timed_topics(ros, intel):
    grid, items = timeline(intel)
    items = items[:30]
    maps = ros.collect(OccupancyGrid, 'map', LATCHED_QOS)
    scans = ros.collect(LaserScan, 'scan', QoSProfile(depth=100,
                                                      reliability=ReliabilityPolicy.RELIABLE))
    sensor = ros.collect(LaserScan, 'scan', qos_profile_sensor_data)   # best effort matches
    truth = ros.collect(PoseStamped, 'ground_truth', 100)
    odom = ros.collect(Odometry, 'odom', 100)
    player = ros.add(BagPlayer(grid, items, context=ros.context))
    assert player.wait_for_subscribers(10)
    time.sleep(0.3)
    t0 = time.monotonic()
    sent = player.play(rate=0.0, log=lambda _: None)
    assert sent == len(items) + 1 and time.monotonic() - t0 < 5
    n_scans = sum(it.topic == '/scan' for it in items)
    assert ros.wait_for(lambda: len(scans) == n_scans and len(maps) == 1, 10)
    assert ros.wait_for(lambda: len(truth) == sum(it.topic == '/ground_truth' for it in items), 5)
    assert len(odom) == sum(it.topic == '/odom' for it in items)
    assert len(sensor) >= 1
    assert (maps[0].info.width, maps[0].info.height) == (intel.map.width, intel.map.height)
    np.testing.assert_array_equal(np.asarray(maps[0].data, np.int8), intel.map.data.ravel())
    got = [stamp_to_sec(m.header.stamp) for m in scans]
    np.testing.assert_allclose(got, [s.stamp for s in intel.scans[:n_scans]], atol=1e-6)
    np.testing.assert_allclose(np.asarray(scans[0].ranges), intel.scans[0].ranges)

    late = ros.collect(OccupancyGrid, 'map', LATCHED_QOS)      # a latecomer still gets the map
    assert ros.wait_for(lambda: len(late) == 1, 5)


def test_player_rate_is_respected(ros, intel):
    _, items = timeline(intel, topics=['/scan'])
    items = items[:3]
    span = items[-1].stamp - items[0].stamp
    player = ros.add(BagPlayer(None, items, context=ros.context))
    rate = span / 0.6                   # the 3 scans over 0.6 s of wall time
    t0 = time.monotonic()
    player.play(rate=rate, log=lambda _: None)
    assert 0.5 < time.monotonic() - t0 < 1.5


def test_play_cli_arguments():
    from ssm_localization.cli import play_cmd
    parser = argparse.ArgumentParser()
    play_cmd.add_arguments(parser)
    args = parser.parse_args(['bags/x', '--rate', '0', '--loop', '--topics', '/scan', '/map',
                              '--ros-args', '-r', 'scan:=front/scan'])
    assert args.rate == 0 and args.loop and args.topics == ['/scan', '/map']
    assert args.ros_args == ['-r', 'scan:=front/scan']
    for bad in (['--rate', '-1'], ['--rate', 'nan'], ['--duration', '-2']):   # refused when parsed
        with pytest.raises(SystemExit) as info:
            parser.parse_args(['bags/x', *bad])
        assert info.value.code == 2


def test_play_refuses_bad_ros_arguments_and_a_scan_topic_of_another_type(intel):
    """One clear error each (the command line prints it with status 2), not a traceback."""
    from ssm_localization import BagError
    from ssm_localization.ros.play import play_bag
    bag = find_bag('intel_queries')
    with pytest.raises(ValueError, match='ROS arguments --ros-args --bogus'):
        play_bag(bag, ros_args=['--ros-args', '--bogus'], delay=0.0)
    with pytest.raises(BagError, match='/ground_truth has type'):
        play_bag(bag, scan_topic='/ground_truth', delay=0.0)


def test_a_scan_topic_the_bag_lacks_is_said_not_passed_over():
    """A misspelled ``--scan-topic`` warns, naming the topics the bag has; unselected, no word."""
    from ssm_localization import read_bag
    from ssm_localization.ros.play import missing_scan_topic
    bag = find_bag('intel_queries')
    data = read_bag(bag, scan_topic='/nope', require_scans=False)
    warning = missing_scan_topic(data, '/nope')
    assert warning.startswith('no messages on /nope in the bag') and '/scan' in warning
    assert missing_scan_topic(data, 'nope', topics=['/map', '/odom']) == ''   # not selected
    assert missing_scan_topic(read_bag(bag), '/scan') == ''
