"""Conversions between ROS messages and the controllers' domain types (used by the nodes)."""

from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan

from sessgan_controllers.types import Goal, RobotState, ScanData, VelocityCommand


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw in radians of a quaternion (rotation about z after any roll and pitch)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def scan_from_msg(msg: LaserScan) -> ScanData:
    return ScanData(
        ranges=np.asarray(msg.ranges, dtype=float),
        angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment),
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
    )


def state_from_odom(msg: Odometry) -> RobotState:
    """Pose from ``pose.pose`` (odom frame), velocity from ``twist.twist`` (child, body frame)."""
    pose, twist = msg.pose.pose, msg.twist.twist
    orientation = pose.orientation
    return RobotState(
        x=float(pose.position.x),
        y=float(pose.position.y),
        yaw=yaw_from_quaternion(orientation.x, orientation.y, orientation.z, orientation.w),
        vx=float(twist.linear.x),
        vy=float(twist.linear.y),
        wz=float(twist.angular.z),
    )


def goal_from_pose(msg: PoseStamped) -> Goal:
    return Goal(x=float(msg.pose.position.x), y=float(msg.pose.position.y))


def twist_from_command(command: VelocityCommand) -> Twist:
    twist = Twist()
    twist.linear.x = float(command.vx)
    twist.linear.y = float(command.vy)
    twist.angular.z = float(command.wz)
    return twist


def twist_stamped_from_command(
    command: VelocityCommand, stamp: Time, frame_id: str
) -> TwistStamped:
    """A TwistStamped carrying ``command`` with the given header stamp and frame."""
    message = TwistStamped()
    message.header.stamp = stamp
    message.header.frame_id = frame_id
    message.twist = twist_from_command(command)
    return message
