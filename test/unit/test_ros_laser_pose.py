"""
The laser pose source.

TF first, the laser_* parameters as the fallback (with a stand-in TF buffer: tf2_ros has no PyPI
wheel).
"""
from __future__ import annotations

import math

from geometry_msgs.msg import TransformStamped
import pytest
from ssm_localization.ros import laser_pose
from ssm_localization.ros.laser_pose import LaserPoseSource, mount_from_transform

PARAMS = (0.1, -0.05, 0.2)


def _transform(x=0.0, y=0.0, z=0.0, roll=0.0, pitch=0.0, yaw=0.0) -> TransformStamped:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    msg = TransformStamped()
    msg.transform.translation.x, msg.transform.translation.y = x, y
    msg.transform.translation.z = z
    q = msg.transform.rotation
    q.w = cr * cp * cy + sr * sp * sy
    q.x = sr * cp * cy - cr * sp * sy
    q.y = cr * sp * cy + sr * cp * sy
    q.z = cr * cp * sy - sr * sp * cy
    return msg


class StandInBuffer:
    """
    tf2_ros.Buffer's lookup_transform.

    Answers for known (target, source) pairs, else raises as tf2 does; counts the lookups.
    """

    def __init__(self, transforms: dict | None = None) -> None:
        self.transforms = dict(transforms or {})
        self.calls: list[tuple[str, str]] = []

    def lookup_transform(self, target, source, time, timeout=None):
        self.calls.append((target, source))
        if (target, source) not in self.transforms:
            raise LookupError(f'"{source}" passed to lookupTransform argument source_frame '
                              'does not exist.')
        return self.transforms[(target, source)]


def _source(buffer=None, **kw):
    logs: list[str] = []
    return LaserPoseSource('base_link', PARAMS, logs.append, buffer=buffer, **kw), logs


def test_without_tf2_the_parameters_are_used_and_logged_once():
    source, logs = _source(None)
    assert not source.uses_tf
    for _ in range(3):
        mount = source.mount('laser')
        assert mount.pose == PARAMS and mount.source == 'parameters' and not mount.mirrored
    assert len(logs) == 1 and 'tf2_ros is not installed' in logs[0]
    assert 'laser_x/laser_y/laser_yaw' in logs[0]


def test_tf_answer_wins_and_is_remembered_per_frame():
    buffer = StandInBuffer({('base_link', 'laser'): _transform(0.25, 0.1, 0.3, yaw=0.5)})
    source, logs = _source(buffer)
    mount = source.mount('/laser')           # a leading slash is tolerated, as in AMCL
    assert mount.source == 'tf' and mount.pose == pytest.approx((0.25, 0.1, 0.5))
    assert source.mount('laser') is mount
    assert buffer.calls == [('base_link', 'laser')]    # rigid mount: asked once
    assert len(logs) == 1 and 'from tf' in logs[0] and 'TF base_link <- laser' in logs[0]


def test_fallback_until_tf_answers_then_switch_logged():
    buffer = StandInBuffer()
    source, logs = _source(buffer)
    first = source.mount('laser')
    assert first.source == 'parameters' and first.pose == PARAMS
    assert 'TF has no base_link <- laser' in first.detail and 'does not exist' in first.detail
    source.mount('laser')
    assert len(logs) == 1                    # the same fallback is not logged again
    buffer.transforms[('base_link', 'laser')] = _transform(0.3, yaw=-0.4)
    switched = source.mount('laser')
    assert switched.source == 'tf' and switched.pose == pytest.approx((0.3, 0.0, -0.4))
    assert len(logs) == 2 and 'from tf' in logs[1]


def test_scan_in_base_frame_and_scan_without_frame():
    source, logs = _source(StandInBuffer())
    assert source.mount('base_link').pose == (0.0, 0.0, 0.0)
    assert source.mount('base_link').source == 'base frame'
    empty = source.mount('')
    assert empty.source == 'parameters' and 'no frame_id' in empty.detail
    assert len(logs) == 2


def test_upside_down_and_tilted_mounts():
    pose, mirrored, tilt = mount_from_transform(_transform(0.1, roll=math.pi, yaw=0.3).transform)
    assert mirrored and tilt == pytest.approx(0.0, abs=1e-9)
    assert pose[:2] == pytest.approx((0.1, 0.0)) and pose[2] == pytest.approx(0.3)
    buffer = StandInBuffer({('base_link', 'laser'): _transform(pitch=0.2)})
    mount, = [_source(buffer)[0].mount('laser')]
    assert 'tilted by 11.5 deg' in mount.detail and not mount.mirrored
    bad = _transform()
    bad.transform.rotation.w = 0.0
    with pytest.raises(ValueError):
        mount_from_transform(bad.transform)
    nan = StandInBuffer({('base_link', 'laser'): bad})
    assert _source(nan)[0].mount('laser').source == 'parameters'


def test_for_node_without_tf2_ros_falls_back_to_the_parameters():
    if laser_pose.TF_AVAILABLE:
        pytest.skip('tf2_ros is installed here: the node tests cover the TF listener')
    logs: list[str] = []
    source = LaserPoseSource.for_node(None, 'base_link', PARAMS, logs.append)
    assert not source.uses_tf
    assert source.mount('laser').source == 'parameters' and 'not installed' in logs[0]
    source.close()
