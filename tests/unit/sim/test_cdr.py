"""The simulator's hand-serialized tick messages read back as the messages rclpy would send,
in as many bytes (rclpy leaves its alignment padding uninitialised, so bytes are not compared)."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip('rclpy')

from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import LaserScan, Range  # noqa: E402

from sessgan_sim import cdr  # noqa: E402

pytestmark = pytest.mark.unit


def assert_same(data: bytes, expected) -> None:
    reference = serialize_message(expected)  # float32 fields rounded as on the wire
    assert deserialize_message(data, type(expected)) == deserialize_message(reference,
                                                                            type(expected))
    assert len(data) == len(reference)


@pytest.mark.parametrize('seconds', [0.0, 0.05, 12.345678901, 3599.95])
def test_clock(seconds):
    sec, nanosec = cdr.stamp(seconds)
    expected = Clock()
    expected.clock.sec, expected.clock.nanosec = sec, nanosec
    assert_same(cdr.clock((sec, nanosec)), expected)
    assert sec + nanosec * 1e-9 == pytest.approx(seconds)


@pytest.mark.parametrize('frames', [('odom', 'base_footprint'), ('', ''), ('o', 'abcdefgh')])
def test_odometry(frames):
    expected = Odometry()
    expected.header.stamp.sec, expected.header.stamp.nanosec = 7, 250_000_000
    expected.header.frame_id, expected.child_frame_id = frames
    pose, twist = expected.pose.pose, expected.twist.twist
    pose.position.x, pose.position.y, pose.position.z = 1.5, -2.25, 0.3
    pose.orientation.z, pose.orientation.w = math.sin(-2.5 / 2), math.cos(-2.5 / 2)
    twist.linear.x, twist.linear.y, twist.angular.z = 0.7, -0.1, 1.9
    data = cdr.odometry((7, 250_000_000), *frames, 1.5, -2.25, -2.5, 0.7, -0.1, 1.9, z=0.3)
    assert_same(data, expected)


@pytest.mark.parametrize('frame_id', ['base_scan', 'ab'])
def test_laser_scan(frame_id):
    ranges = np.random.default_rng(3).uniform(0.1, 10.0, 360).astype(np.float32)
    ranges[5] = np.inf
    expected = LaserScan()
    expected.header.stamp.sec, expected.header.stamp.nanosec = 1, 5
    expected.header.frame_id = frame_id
    increment = 2 * math.pi / 360
    expected.angle_min, expected.angle_increment = -math.pi, increment
    expected.angle_max = -math.pi + increment * 359
    expected.range_min, expected.range_max, expected.scan_time = 0.12, 10.0, 0.05
    expected.ranges = ranges.tolist()
    data = cdr.laser_scan((1, 5), frame_id, ranges, -math.pi, increment, 0.12, 10.0, 0.05)
    assert_same(data, expected)
    assert np.array_equal(deserialize_message(data, LaserScan).ranges, ranges)


@pytest.mark.parametrize('frame_id, reading', [('base_range_down', 0.734), ('abc', math.inf),
                                               ('x', -math.inf), ('abcd', 0.0)])
def test_range(frame_id, reading):
    expected = Range()
    expected.header.stamp.sec, expected.header.stamp.nanosec = 3, 50_000_000
    expected.header.frame_id = frame_id
    expected.radiation_type = Range.INFRARED
    expected.field_of_view, expected.min_range, expected.max_range = 0.05, 0.0, 4.0
    expected.range = reading
    data = cdr.range_reading((3, 50_000_000), frame_id, reading, 0.05, 0.0, 4.0)
    assert_same(data, expected)


def test_odometry_carries_altitude_and_climb_rate():
    message = deserialize_message(
        cdr.odometry((1, 0), 'odom', 'base_footprint', 1.0, 2.0, 0.5, 0.3, 0.0, 0.1,
                     z=0.8, vz=-0.4), Odometry)
    assert message.pose.pose.position.z == 0.8
    assert message.twist.twist.linear.z == -0.4
