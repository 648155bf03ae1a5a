"""Conversions between ROS messages and the controllers' domain types (used by the nodes)."""

from __future__ import annotations

import struct

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import LaserScan

from sessgan_controllers.controller_interface import (
    Goal,
    MapData,
    RobotState,
    ScanData,
    VelocityCommand,
)
from sessgan_core.quaternion import yaw_from_quaternion


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
        z=float(pose.position.z),
        vz=float(twist.linear.z),
    )


_CDR_LITTLE_ENDIAN, _CDR_BIG_ENDIAN = b'\x00\x01', b'\x00\x00'


def odom_from_cdr(data: bytes) -> tuple[int, RobotState]:
    """(header stamp in ns, state) of a serialized nav_msgs/Odometry, as a raw subscription
    hands it over, read without building the message: rclpy's conversion of its two
    36-double covariance arrays costs ten times the rest (about 40 us a message).

    Classic CDR (the encapsulation Fast DDS and Cyclone DDS use for ROS 2 messages) is read
    in place; any other encapsulation goes through rclpy's deserialization.
    """
    kind = data[:2]
    if kind not in (_CDR_LITTLE_ENDIAN, _CDR_BIG_ENDIAN):
        msg = deserialize_message(data, Odometry)
        stamp = msg.header.stamp
        return stamp.sec * 1_000_000_000 + stamp.nanosec, state_from_odom(msg)
    order = '<' if kind == _CDR_LITTLE_ENDIAN else '>'
    body = memoryview(data)[4:]  # CDR aligns relative to the end of the encapsulation header
    sec, nanosec, frame_id_length = struct.unpack_from(order + 'iII', body, 0)
    offset = (12 + frame_id_length + 3) & ~3  # child_frame_id's length, 4-aligned
    (child_frame_id_length,) = struct.unpack_from(order + 'I', body, offset)
    offset = (offset + 4 + child_frame_id_length + 7) & ~7  # pose.pose, 8-aligned doubles
    x, y, z, qx, qy, qz, qw = struct.unpack_from(order + '7d', body, offset)
    offset += 8 * (7 + 36)  # past pose.pose and pose.covariance: twist.twist
    vx, vy, vz, _, _, wz = struct.unpack_from(order + '6d', body, offset)
    state = RobotState(x=x, y=y, yaw=yaw_from_quaternion(qx, qy, qz, qw), vx=vx, vy=vy, wz=wz,
                       z=z, vz=vz)
    return sec * 1_000_000_000 + nanosec, state


def map_from_msg(msg: OccupancyGrid) -> MapData:
    """The grid of a nav_msgs/OccupancyGrid; ValueError (naming the problem) for a grid that is
    empty, inconsistent or rotated."""
    info = msg.info
    width, height = int(info.width), int(info.height)
    if len(msg.data) != width * height:
        raise ValueError(f'map data has {len(msg.data)} cells but info says {width}x{height}')
    orientation = info.origin.orientation
    if abs(orientation.x) > 1e-6 or abs(orientation.y) > 1e-6 or abs(orientation.z) > 1e-6:
        raise ValueError('rotated map origins are not supported')
    occupancy = np.frombuffer(bytes(msg.data), dtype=np.int8).reshape(height, width).copy()
    grid = MapData(occupancy, float(info.resolution),
                   (float(info.origin.position.x), float(info.origin.position.y)))
    grid.validate()
    return grid


def goal_from_pose(msg: PoseStamped) -> Goal:
    return Goal(x=float(msg.pose.position.x), y=float(msg.pose.position.y))


def twist_from_command(command: VelocityCommand) -> Twist:
    twist = Twist()
    twist.linear.x = float(command.vx)
    twist.linear.y = float(command.vy)
    twist.linear.z = float(command.vz)
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
