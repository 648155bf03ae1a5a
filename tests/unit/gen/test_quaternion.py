"""Yaw <-> quaternion, and that the project converts in this one place only."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from sessgan_gen.quaternion import quaternion_from_yaw, yaw_from_quaternion

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


def test_no_package_has_its_own_copy_of_the_conversion():
    copies = re.compile(r'atan2\(2\.0 \* \(|sin\(\w+ / 2(\.0)?\)')
    found = [str(path.relative_to(ROOT)) for folder in ('sessgan_gen', 'sessgan_sim',
                                                        'sessgan_evolver', 'controllers')
             for path in (ROOT / folder).rglob('*.py') if copies.search(path.read_text())]
    assert found == ['sessgan_gen/sessgan_gen/quaternion.py']
