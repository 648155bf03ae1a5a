"""Path followers: rotation shim, regulated pure pursuit, car speed profile, holonomic pursuit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import RobotState
from sessgan_controllers.path_following import (
    CarLimits,
    DiffDriveLimits,
    HolonomicLimits,
    PathTracker,
    braking_speed,
    follow_car,
    follow_diff_drive,
    follow_holonomic,
    free_distance,
    proximity_factor,
    speed_profile,
)
from sessgan_controllers.path_planning import Path

pytestmark = pytest.mark.unit

DIFF = DiffDriveLimits(max_angular_speed=1.8, angular_deceleration=3.0,
                       lateral_acceleration=0.6, rotate_speed=1.5, rotate_start_angle=0.785,
                       rotate_stop_angle=0.25)
CAR = CarLimits(wheelbase=0.7, max_steering_angle=0.5, lateral_acceleration=6.0)
FLYER = HolonomicLimits(yaw_gain=2.0, max_yaw_rate=1.5)


def straight(length: float, spacing: float = 0.05) -> Path:
    count = int(round(length / spacing)) + 1
    return Path.from_points(np.stack((np.linspace(0.0, length, count), np.zeros(count)), axis=1))


def straight_then_turn(before: float, radius: float, turn: float, after: float,
                       spacing: float = 0.1) -> Path:
    """A straight of ``before`` m, a left arc of ``radius`` m through ``turn`` rad, a straight."""
    first = np.stack((np.arange(0.0, before, spacing), np.zeros(int(math.ceil(before / spacing)))),
                     axis=1)
    angles = np.arange(0.0, turn, spacing / radius)
    arc = np.stack((before + radius * np.sin(angles), radius * (1.0 - np.cos(angles))), axis=1)
    end = np.array([before + radius * math.sin(turn), radius * (1.0 - math.cos(turn))])
    direction = np.array([math.cos(turn), math.sin(turn)])
    tail = end + np.arange(0.0, after, spacing)[:, None] * direction
    return Path.from_points(np.vstack((first, arc, tail)), curvature_window=0.5)


def test_rotation_shim_turns_in_place_before_driving():
    state = RobotState(0.0, 0.0, 0.0)
    carrot = np.array([0.0, 1.0])  # 90 degrees to the left
    command, rotating = follow_diff_drive(state, carrot, 0.7, DIFF, rotating=False)
    assert rotating and command.vx == 0.0 and command.wz > 0.0
    # Still turning at 18 degrees off (above the stop angle), slower: it must stop on the
    # heading ...
    turned = RobotState(0.0, 0.0, math.radians(72.0))
    command, rotating = follow_diff_drive(turned, carrot, 0.7, DIFF, rotating=True)
    assert rotating and command.vx == 0.0 and 0.0 < command.wz < DIFF.rotate_speed
    # ... and driving once within the stop angle.
    aligned = RobotState(0.0, 0.0, math.radians(80.0))
    command, rotating = follow_diff_drive(aligned, carrot, 0.7, DIFF, rotating=True)
    assert not rotating and command.vx > 0.0 and command.wz > 0.0


def test_regulated_pure_pursuit_slows_on_curvature():
    state = RobotState(0.0, 0.0, 0.0)
    ahead, _ = follow_diff_drive(state, np.array([0.8, 0.0]), 0.7, DIFF, rotating=False)
    assert ahead.vx == pytest.approx(0.7) and ahead.wz == pytest.approx(0.0)
    curving, _ = follow_diff_drive(state, np.array([0.5, 0.4]), 0.7, DIFF, rotating=False)
    curvature = 2.0 * 0.4 / (0.5 ** 2 + 0.4 ** 2)
    assert curving.vx == pytest.approx(math.sqrt(DIFF.lateral_acceleration / curvature))
    assert curving.vx < ahead.vx
    assert curving.wz == pytest.approx(curving.vx * curvature)


def test_speed_profile_slows_for_curves_and_the_goal():
    path = straight_then_turn(before=4.0, radius=0.5, turn=math.pi / 2, after=2.0, spacing=0.05)
    profile = speed_profile(path, max_speed=0.7, lateral_acceleration=0.6, deceleration=0.8,
                            end_speed=0.1, max_curvature_speed=1.8)
    assert profile[0] == pytest.approx(0.7)
    in_turn = np.abs(path.curvature) > 1.9
    assert profile[in_turn].max() <= math.sqrt(0.6 * 0.5) + 0.05
    assert profile[-1] == pytest.approx(0.1)


def test_regulated_speed_falls_near_obstacles_ahead(scan_factory):
    state = RobotState(0.0, 0.0, 0.0)
    open_scan = scan_factory(state, discs=[(0.0, 0.6, 0.1)])  # beside the robot: ignored
    assert proximity_factor(open_scan, 0.2, 0.0, 0.5, 0.3) == 1.0
    near = scan_factory(state, discs=[(0.65, 0.0, 0.1)])  # 0.35 m from the footprint
    factor = proximity_factor(near, 0.2, 0.0, 0.5, 0.3)
    assert factor == pytest.approx(0.35 / 0.5, abs=0.03)
    touching = scan_factory(state, discs=[(0.35, 0.0, 0.1)])
    assert proximity_factor(touching, 0.2, 0.0, 0.5, 0.3) == pytest.approx(0.3)


def test_an_obstacle_on_the_path_limits_speed_to_its_braking_distance():
    path = straight(5.0)
    tracker = PathTracker(path, search_distance=2.0)
    assert tracker.update(0.0, 0.05) == pytest.approx(0.05)
    points = np.array([[3.0, 0.1], [1.0, 1.0]])  # one on the path, one well beside it
    free = free_distance(path, tracker.index, 4.0, points, radius=0.25)
    assert free == pytest.approx(3.0 - math.sqrt(0.25 ** 2 - 0.1 ** 2), abs=0.06)
    assert free_distance(path, tracker.index, 2.0, points, radius=0.25) == math.inf
    assert braking_speed(free, 0.8, 0.15) == pytest.approx(math.sqrt(2 * 0.8 * (free - 0.15)))
    assert braking_speed(0.1, 0.8, 0.15) == 0.0


def test_car_brakes_before_a_sharp_turn():
    # 40 m of straight, then a 90-degree turn of 3 m radius.
    path = straight_then_turn(before=40.0, radius=3.0, turn=math.pi / 2, after=10.0,
                              spacing=0.25)
    profile = speed_profile(path, max_speed=12.0, lateral_acceleration=6.0, deceleration=6.0,
                            end_speed=1.0)
    turn_speed = math.sqrt(6.0 / (1.0 / 3.0))
    arc = path.arc_length
    turn_start = 40.0
    assert profile[arc < 5.0].max() == pytest.approx(12.0)  # full speed far from the turn
    in_turn = (arc > turn_start + 1.0) & (arc < turn_start + 3.0 * math.pi / 2 - 1.0)
    assert profile[in_turn].max() <= turn_speed * 1.1
    # Braking distance: at d metres before the turn the speed is at most sqrt(vt^2 + 2 a d).
    for distance in (2.0, 5.0, 8.0):
        index = int(np.searchsorted(arc, turn_start - distance))
        assert profile[index] <= math.sqrt((turn_speed * 1.1) ** 2 + 2.0 * 6.0 * distance) + 1e-6
        assert profile[index] < 12.0
    # The braking starts (v^2 - vt^2) / (2 a) before the turn, not at the turn.
    slowing = arc[np.flatnonzero(profile < 11.9)[0]]
    expected = turn_start - (12.0 ** 2 - turn_speed ** 2) / (2.0 * 6.0)
    assert slowing == pytest.approx(expected, abs=1.5)


def test_car_pursuit_respects_the_steering_lock():
    state = RobotState(0.0, 0.0, 0.0, vx=5.0)
    command = follow_car(state, np.array([3.0, 0.5]), 8.0, CAR)
    curvature = command.wz / command.vx
    assert 0.0 < curvature < math.tan(CAR.max_steering_angle) / CAR.wheelbase
    assert command.vx <= math.sqrt(CAR.lateral_acceleration / curvature) + 1e-9
    sharp = follow_car(state, np.array([0.0, 2.0]), 8.0, CAR)
    assert sharp.wz / sharp.vx == pytest.approx(math.tan(0.5) / 0.7)
    assert follow_car(state, np.array([-3.0, 0.1]), 8.0, CAR).wz > 0.0  # behind: full lock


def test_flyer_moves_holonomically_towards_the_carrot():
    state = RobotState(1.0, 1.0, 0.0)
    command = follow_holonomic(state, np.array([1.0, 2.0]), 1.2, FLYER)  # straight to its left
    assert command.vx == pytest.approx(0.0, abs=1e-9)
    assert command.vy == pytest.approx(1.2)  # sideways at once, no turning first
    assert command.wz == pytest.approx(FLYER.max_yaw_rate)  # heading follows the motion
    facing = RobotState(1.0, 1.0, math.pi / 2)
    command = follow_holonomic(facing, np.array([1.0, 2.0]), 1.2, FLYER)
    assert command.vx == pytest.approx(1.2) and command.wz == pytest.approx(0.0, abs=1e-9)


def test_tracker_follows_progress_and_does_not_skip_ahead():
    # A hairpin: out along y = 0, back along y = 0.3.
    out = np.stack((np.linspace(0.0, 3.0, 61), np.zeros(61)), axis=1)
    back = np.stack((np.linspace(3.0, 0.0, 61), np.full(61, 0.3)), axis=1)
    path = Path.from_points(np.vstack((out, back)))
    tracker = PathTracker(path, search_distance=1.0)
    tracker.update(0.5, 0.2)  # closer to the way back, which lies far ahead along the path
    assert tracker.travelled == pytest.approx(0.5, abs=0.05)
    np.testing.assert_allclose(tracker.carrot(0.5), (1.0, 0.0), atol=0.06)
