"""Yaw <-> quaternion, and that the project converts in this one place only."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from sessgan_core.quaternion import (
    quaternion_from_yaw,
    quaternion_from_yaw_pitch,
    yaw_from_quaternion,
)

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[3]


@pytest.mark.parametrize('yaw', [0.0, 0.3, -1.2, math.pi / 2, 3.0, -3.0])
def test_round_trip_and_unit_length(yaw):
    x, y, z, w = quaternion_from_yaw(yaw)
    assert (x, y) == (0.0, 0.0)
    assert math.isclose(x * x + y * y + z * z + w * w, 1.0)
    assert math.isclose(yaw_from_quaternion(x, y, z, w), yaw, abs_tol=1e-12)


def test_yaw_of_a_rolled_quaternion_ignores_the_roll():
    roll, yaw = 0.4, 1.1
    # q = q_yaw * q_roll (roll about x first, then yaw about z)
    cr, sr, cy, sy = math.cos(roll / 2), math.sin(roll / 2), math.cos(yaw / 2), math.sin(yaw / 2)
    assert math.isclose(yaw_from_quaternion(cy * sr, sy * sr, sy * cr, cy * cr), yaw)


def rotate(quaternion, vector):
    """``vector`` turned by the unit ``quaternion`` (x, y, z, w)."""
    x, y, z, w = quaternion
    vx, vy, vz = vector
    # v' = v + 2 w (q x v) + 2 q x (q x v)
    cx, cy, cz = y * vz - z * vy, z * vx - x * vz, x * vy - y * vx
    dx, dy, dz = y * cz - z * cy, z * cx - x * cz, x * cy - y * cx
    return (vx + 2 * (w * cx + dx), vy + 2 * (w * cy + dy), vz + 2 * (w * cz + dz))


@pytest.mark.parametrize('yaw', [0.0, 0.7, -2.0])
def test_yaw_pitch_points_a_down_looking_sensor_down(yaw):
    quaternion = quaternion_from_yaw_pitch(yaw, math.pi / 2)
    assert math.isclose(sum(value * value for value in quaternion), 1.0)
    assert rotate(quaternion, (1.0, 0.0, 0.0)) == pytest.approx((0.0, 0.0, -1.0), abs=1e-12)
    # Its y axis keeps the yaw.
    assert rotate(quaternion, (0.0, 1.0, 0.0)) == pytest.approx(
        (-math.sin(yaw), math.cos(yaw), 0.0), abs=1e-12)
    assert quaternion_from_yaw_pitch(yaw, 0.0) == pytest.approx(quaternion_from_yaw(yaw))


def test_no_package_has_its_own_copy_of_the_conversion():
    copies = re.compile(r'atan2\(2\.0 \* \(|sin\(\w+ / 2(\.0)?\)')
    found = [str(path.relative_to(ROOT)) for folder in ('sessgan_core', 'sessgan_gen',
                                                        'sessgan_sim', 'sessgan_evolver',
                                                        'controllers')
             for path in (ROOT / folder).rglob('*.py') if copies.search(path.read_text())]
    assert found == ['sessgan_core/sessgan_core/quaternion.py']
