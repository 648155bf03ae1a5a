"""Build the robot-under-test messages (tf, goal) from core observations; the ones of every tick
(clock, odom, scan) are serialized directly by sessgan_sim.cdr."""

from __future__ import annotations

import math

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from tf2_msgs.msg import TFMessage

from sessgan_core.quaternion import quaternion_from_yaw_pitch
from sessgan_sim import cdr
from sessgan_sim.frames import (
    BASE_FOOTPRINT,
    BASE_LINK,
    MAP_FRAME,
    ODOM_FRAME,
    RANGE_DOWN_FRAME,
    SCAN_FRAME,
)


def time_msg(seconds: float) -> Time:
    sec, nanosec = cdr.stamp(seconds)
    return Time(sec=sec, nanosec=nanosec)


def _set_yaw(quaternion, yaw: float, pitch: float = 0.0) -> None:
    quaternion.x, quaternion.y, quaternion.z, quaternion.w = quaternion_from_yaw_pitch(yaw, pitch)


def transform(stamp: Time, parent: str, child: str, x: float = 0.0, y: float = 0.0,
              z: float = 0.0, yaw: float = 0.0, pitch: float = 0.0) -> TransformStamped:
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    msg.transform.translation.x = float(x)
    msg.transform.translation.y = float(y)
    msg.transform.translation.z = float(z)
    _set_yaw(msg.transform.rotation, yaw, pitch)
    return msg


def dynamic_tf_msg(stamp: Time, x: float, y: float, yaw: float, z: float = 0.0,
                   prefix: str = '') -> TFMessage:
    """map->odom (identity: perfect localisation) and odom->base_footprint (``z``: a flyer's
    altitude); a fleet robot's frames carry its ``prefix`` ('r1/'), map is shared."""
    return TFMessage(transforms=[
        transform(stamp, MAP_FRAME, prefix + ODOM_FRAME),
        transform(stamp, prefix + ODOM_FRAME, prefix + BASE_FOOTPRINT, x, y, z, yaw)])


def static_tf_msg(stamp: Time, base_height: float, scan_height: float,
                  range_down: bool = False, prefix: str = '') -> TFMessage:
    """base_footprint->base_link->base_scan, and with ``range_down`` base_link->
    base_range_down (at the body's underside, x axis down), all in one message (tf_static
    convention); every frame with a fleet robot's ``prefix``."""
    transforms = [transform(stamp, prefix + BASE_FOOTPRINT, prefix + BASE_LINK, z=base_height),
                  transform(stamp, prefix + BASE_LINK, prefix + SCAN_FRAME,
                            z=scan_height - base_height)]
    if range_down:
        transforms.append(transform(stamp, prefix + BASE_LINK, prefix + RANGE_DOWN_FRAME,
                                    z=-base_height, pitch=math.pi / 2))
    return TFMessage(transforms=transforms)


def goal_msg(stamp: Time, x: float, y: float, yaw: float) -> PoseStamped:
    msg = PoseStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = MAP_FRAME
    msg.pose.position.x = float(x)
    msg.pose.position.y = float(y)
    _set_yaw(msg.pose.orientation, yaw)
    return msg


def twist_values(msg) -> tuple[float, float, float, float]:
    """(vx, vy, wz, vz) of a Twist or TwistStamped (vz: linear.z, a flyer's climb rate)."""
    twist: Twist = getattr(msg, 'twist', msg)
    return (float(twist.linear.x), float(twist.linear.y), float(twist.angular.z),
            float(twist.linear.z))
