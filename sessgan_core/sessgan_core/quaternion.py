"""Planar rotations as quaternions (x, y, z, w): the one place the project converts yaw.

Used by the message conversions of every package (generator, simulator, controllers) and by
the simulator's physics; plain math, no ROS.
"""

from __future__ import annotations

import math


def quaternion_from_yaw(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` radians about z."""
    half = 0.5 * yaw
    return 0.0, 0.0, math.sin(half), math.cos(half)


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Yaw in radians (-pi, pi] of a quaternion: its rotation about z after any roll and
    pitch."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_from_yaw_pitch(yaw: float, pitch: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``pitch`` radians about y, then by ``yaw`` about z (no
    roll): a downward-looking sensor's frame has pitch pi/2 (its x axis points down)."""
    half_yaw, half_pitch = 0.5 * yaw, 0.5 * pitch
    cos_yaw, sin_yaw = math.cos(half_yaw), math.sin(half_yaw)
    cos_pitch, sin_pitch = math.cos(half_pitch), math.sin(half_pitch)
    return -sin_pitch * sin_yaw, sin_pitch * cos_yaw, cos_pitch * sin_yaw, cos_pitch * cos_yaw
