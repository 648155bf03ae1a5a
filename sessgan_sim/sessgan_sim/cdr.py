"""The messages the simulator publishes every tick, serialized directly (no ROS imports).

rclpy publishes bytes as they are. Building clock, odom and scan as Python message objects and
having rclpy convert them costs about 35 us a tick, a tenth of the simulator's share of a
lockstep tick; packing them here costs a fifth of that, and the same bytes go into failure bags.

Format: classic CDR, little endian, with its 4-byte encapsulation header (what ROS 2's DDS
implementations exchange); every field aligned to its own size, counted from after the header.
tests/unit/sim/test_cdr.py checks that each reads back as the message rclpy would send.
"""

from __future__ import annotations

import struct

import numpy as np

from sessgan_core.quaternion import quaternion_from_yaw

ENCAPSULATION = b'\x00\x01\x00\x00'
_ZERO_COVARIANCE = bytes(36 * 8)
_STAMP = struct.Struct('<iI')


def stamp(seconds: float) -> tuple[int, int]:
    """(sec, nanosec) of builtin_interfaces/Time for a time in seconds."""
    return divmod(int(round(seconds * 1e9)), 1_000_000_000)


def _align(buffer: bytearray, size: int) -> None:
    buffer += bytes(-(len(buffer) - len(ENCAPSULATION)) % size)


def _string(buffer: bytearray, text: str) -> None:
    _align(buffer, 4)
    data = text.encode() + b'\0'
    buffer += struct.pack('<I', len(data))
    buffer += data


def _header(time: tuple[int, int], frame_id: str) -> bytearray:
    buffer = bytearray(ENCAPSULATION)
    buffer += _STAMP.pack(*time)
    _string(buffer, frame_id)
    return buffer


def clock(time: tuple[int, int]) -> bytes:
    """rosgraph_msgs/Clock."""
    return ENCAPSULATION + _STAMP.pack(*time)


def odometry(time: tuple[int, int], frame_id: str, child_frame_id: str, x: float, y: float,
             yaw: float, vx: float, vy: float, wz: float, z: float = 0.0,
             vz: float = 0.0) -> bytes:
    """nav_msgs/Odometry: pose in ``frame_id``, twist in ``child_frame_id``, no covariance;
    ``z`` and ``vz`` are a flyer's altitude and climb rate."""
    buffer = _header(time, frame_id)
    _string(buffer, child_frame_id)
    _align(buffer, 8)
    buffer += struct.pack('<7d', x, y, z, *quaternion_from_yaw(yaw))
    buffer += _ZERO_COVARIANCE
    buffer += struct.pack('<6d', vx, vy, vz, 0.0, 0.0, wz)
    buffer += _ZERO_COVARIANCE
    return bytes(buffer)


def laser_scan(time: tuple[int, int], frame_id: str, ranges: np.ndarray, angle_min: float,
               angle_increment: float, range_min: float, range_max: float,
               scan_time: float) -> bytes:
    """sensor_msgs/LaserScan without intensities; ``ranges`` in metres."""
    buffer = _header(time, frame_id)
    _align(buffer, 4)
    angle_max = angle_min + angle_increment * (len(ranges) - 1)
    buffer += struct.pack('<7f', angle_min, angle_max, angle_increment, 0.0, scan_time,
                          range_min, range_max)
    buffer += struct.pack('<I', len(ranges))
    buffer += np.ascontiguousarray(ranges, dtype='<f4').tobytes()
    buffer += struct.pack('<I', 0)
    return bytes(buffer)


RANGE_INFRARED = 1
"""sensor_msgs/Range radiation_type of an infrared (or laser) ranger."""


def range_reading(time: tuple[int, int], frame_id: str, reading: float, field_of_view: float,
                  min_range: float, max_range: float,
                  radiation_type: int = RANGE_INFRARED) -> bytes:
    """sensor_msgs/Range; ``reading`` in metres (REP 117 infinities), variance 0 (unknown)."""
    buffer = _header(time, frame_id)
    buffer += struct.pack('<B', radiation_type)
    _align(buffer, 4)
    buffer += struct.pack('<5f', field_of_view, min_range, max_range, reading, 0.0)
    return bytes(buffer)
