"""Conversions between ROS messages and the controllers' domain types (no DDS)."""

from __future__ import annotations

import math

import pytest

pytest.importorskip('geometry_msgs')

from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402

from sessgan_controllers.controller_interface import VelocityCommand  # noqa: E402
from sessgan_controllers.messages import (  # noqa: E402
    odom_from_cdr,
    scan_from_msg,
    state_from_odom,
    twist_from_command,
    twist_stamped_from_command,
    yaw_from_quaternion,
)

pytestmark = pytest.mark.unit


def test_odometry_to_state():
    msg = Odometry()
    msg.pose.pose.position.x = 1.0
    msg.pose.pose.position.y = 2.0
    msg.pose.pose.orientation.z = math.sin(0.25)
    msg.pose.pose.orientation.w = math.cos(0.25)
    msg.twist.twist.linear.x = 0.4
    msg.twist.twist.linear.y = 0.1
    msg.twist.twist.angular.z = -0.2
    state = state_from_odom(msg)
    assert (state.x, state.y, state.vx, state.vy, state.wz) == pytest.approx(
        (1.0, 2.0, 0.4, 0.1, -0.2))
    assert state.yaw == pytest.approx(0.5)
    assert yaw_from_quaternion(0.0, 0.0, 1.0, 0.0) == pytest.approx(math.pi)


@pytest.mark.parametrize('frames', [('', ''), ('odom', 'base_footprint'), ('o', 'abcdefgh')])
def test_serialized_odometry_reads_like_the_message(frames):
    """The in-place CDR reader agrees with rclpy's deserialization, whatever string lengths
    shift the alignment of the doubles after them."""
    msg = Odometry()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345_678_901
    msg.header.frame_id, msg.child_frame_id = frames
    msg.pose.pose.position.x, msg.pose.pose.position.y = -3.25, 7.5
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(-1.1), math.cos(-1.1)
    msg.pose.covariance[0] = 99.0
    msg.twist.twist.linear.x, msg.twist.twist.linear.y = 0.8, -0.05
    msg.twist.twist.angular.z = 1.25
    msg.twist.covariance[35] = -99.0
    msg.pose.pose.position.z, msg.twist.twist.linear.z = 0.95, -0.3  # a flyer's altitude
    stamp, state = odom_from_cdr(serialize_message(msg))
    assert stamp == 12_345_678_901
    assert state == state_from_odom(msg)
    assert (state.z, state.vz) == (0.95, -0.3)


def test_scan_keeps_its_geometry_and_no_returns():
    msg = LaserScan()
    msg.angle_min, msg.angle_increment = -math.pi, math.radians(1.0)
    msg.range_min, msg.range_max = 0.12, 10.0
    msg.ranges = [2.0, math.inf, float('nan'), 0.05] + [3.0] * 356
    scan = scan_from_msg(msg)
    assert len(scan.ranges) == 360 and scan.range_max == pytest.approx(10.0)
    assert scan.valid()[:4].tolist() == [True, False, False, False]
    angles, ranges = scan.points()
    assert len(ranges) == 357 and angles[0] == pytest.approx(-math.pi)


def test_command_to_twist_and_twist_stamped():
    command = VelocityCommand(0.1, 0.2, 0.3, vz=-0.4)
    twist = twist_from_command(command)
    assert (twist.linear.x, twist.linear.y, twist.angular.z) == pytest.approx((0.1, 0.2, 0.3))
    assert twist.linear.z == pytest.approx(-0.4)
    stamp = LaserScan().header.stamp
    stamp.sec = 7
    stamped = twist_stamped_from_command(command, stamp, 'base_footprint')
    assert stamped.header.stamp.sec == 7 and stamped.header.frame_id == 'base_footprint'
    assert stamped.twist.angular.z == pytest.approx(0.3)
