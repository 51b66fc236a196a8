"""``ssm_localization play BAG``: publish a bag's topics on live ROS topics (map latched)."""
from __future__ import annotations

import argparse

from .arguments import delay_seconds, nonnegative_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('bag', help='rosbag2 directory or .mcap file')
    parser.add_argument('--rate', type=nonnegative_float, default=1.0,
                        help='playback speed factor (1 = real time, 0 = as fast as possible)')
    parser.add_argument('--loop', action='store_true',
                        help='replay the timed topics forever (the map is published once)')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC', default=None,
                        help='only these topics (default: /map /scan /ground_truth /odom)')
    parser.add_argument('--scan-topic', default='/scan', help='the LaserScan topic of the bag')
    parser.add_argument('--start-offset', type=nonnegative_float, default=0.0, metavar='S',
                        help='skip the first S seconds after the first scan')
    parser.add_argument('--duration', type=nonnegative_float, default=0.0, metavar='S',
                        help='play only S seconds of bag time (0 = to the end)')
    parser.add_argument('--delay', type=delay_seconds, default=0.5, metavar='S',
                        help='wait S seconds after creating the publishers (discovery)')
    parser.add_argument('--wait-subscribers', type=nonnegative_float, default=0.0, metavar='S',
                        help='wait up to S seconds for a subscriber on every timed topic')
    parser.add_argument('--hold', type=nonnegative_float, default=0.0, metavar='S',
                        help='keep the latched map available S seconds after the end')
    parser.add_argument('--ros-args', dest='ros_args', nargs=argparse.REMAINDER, default=None,
                        help='ROS arguments (e.g. remapping: --ros-args -r scan:=front/scan)')


def run(args: argparse.Namespace) -> int:
    from ..ros.play import play_bag  # rclpy only when playing: the rest of the CLI is ROS-free
    ros_args = ['--ros-args', *args.ros_args] if args.ros_args else None
    return play_bag(args.bag, rate=args.rate, loop=args.loop, topics=args.topics,
                    scan_topic=args.scan_topic, start_offset=args.start_offset,
                    duration=args.duration, delay=args.delay,
                    wait_subscribers=args.wait_subscribers, hold=args.hold, ros_args=ros_args)
