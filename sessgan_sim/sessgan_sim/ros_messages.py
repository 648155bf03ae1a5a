"""Build the robot-under-test messages (scan, odom, tf, clock, goal) from core observations."""

from __future__ import annotations

import array
import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

MAP_FRAME = 'map'
ODOM_FRAME = 'odom'
BASE_FOOTPRINT = 'base_footprint'
BASE_LINK = 'base_link'
SCAN_FRAME = 'base_scan'


def time_msg(seconds: float) -> Time:
    nanoseconds = int(round(seconds * 1e9))
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def clock_msg(stamp: Time) -> Clock:
    return Clock(clock=stamp)


def _set_yaw(quaternion, yaw: float) -> None:
    quaternion.z = math.sin(yaw / 2.0)
    quaternion.w = math.cos(yaw / 2.0)


def scan_msg(stamp: Time, ranges: np.ndarray, angle_min: float, angle_increment: float,
             range_min: float, range_max: float, scan_time: float) -> LaserScan:
    msg = LaserScan()
    msg.header.stamp = stamp
    msg.header.frame_id = SCAN_FRAME
    msg.angle_min = float(angle_min)
    msg.angle_increment = float(angle_increment)
    msg.angle_max = float(angle_min + angle_increment * (len(ranges) - 1))
    msg.range_min = float(range_min)
    msg.range_max = float(range_max)
    msg.scan_time = float(scan_time)
    values = array.array('f')
    values.frombytes(np.ascontiguousarray(ranges, dtype=np.float32).tobytes())
    msg.ranges = values
    return msg


def odom_msg(stamp: Time, x: float, y: float, yaw: float,
             vx: float, vy: float, wz: float, z: float = 0.0) -> Odometry:
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = ODOM_FRAME
    msg.child_frame_id = BASE_FOOTPRINT
    msg.pose.pose.position.x = float(x)
    msg.pose.pose.position.y = float(y)
    msg.pose.pose.position.z = float(z)
    _set_yaw(msg.pose.pose.orientation, yaw)
    msg.twist.twist.linear.x = float(vx)
    msg.twist.twist.linear.y = float(vy)
    msg.twist.twist.angular.z = float(wz)
    return msg


def transform(stamp: Time, parent: str, child: str, x: float = 0.0, y: float = 0.0,
              z: float = 0.0, yaw: float = 0.0) -> TransformStamped:
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    msg.transform.translation.x = float(x)
    msg.transform.translation.y = float(y)
    msg.transform.translation.z = float(z)
    _set_yaw(msg.transform.rotation, yaw)
    return msg


def dynamic_tf_msg(stamp: Time, odom: Odometry) -> TFMessage:
    """map->odom (identity: perfect localisation) and odom->base_footprint."""
    pose = odom.pose.pose
    to_base = TransformStamped()
    to_base.header.stamp = stamp
    to_base.header.frame_id = ODOM_FRAME
    to_base.child_frame_id = BASE_FOOTPRINT
    to_base.transform.translation.x = pose.position.x
    to_base.transform.translation.y = pose.position.y
    to_base.transform.translation.z = pose.position.z
    to_base.transform.rotation = pose.orientation
    return TFMessage(transforms=[transform(stamp, MAP_FRAME, ODOM_FRAME), to_base])


def static_tf_msg(stamp: Time, base_height: float, scan_height: float) -> TFMessage:
    """base_footprint->base_link->base_scan, all in one message (tf_static convention)."""
    return TFMessage(transforms=[
        transform(stamp, BASE_FOOTPRINT, BASE_LINK, z=base_height),
        transform(stamp, BASE_LINK, SCAN_FRAME, z=scan_height - base_height),
    ])


def goal_msg(stamp: Time, x: float, y: float, yaw: float) -> PoseStamped:
    msg = PoseStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = MAP_FRAME
    msg.pose.position.x = float(x)
    msg.pose.position.y = float(y)
    _set_yaw(msg.pose.orientation, yaw)
    return msg


def twist_values(msg) -> tuple[float, float, float]:
    """(vx, vy, wz) of a Twist or TwistStamped."""
    twist: Twist = getattr(msg, 'twist', msg)
    return float(twist.linear.x), float(twist.linear.y), float(twist.angular.z)
