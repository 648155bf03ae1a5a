"""Velocity-projection avoidance on synthetic scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import STOP, Goal, RobotState, ScanData
from sessgan_controllers.errors import InvalidConfigError
from sessgan_controllers.velocity_projection import (
    VelocityProjectionConfig,
    VelocityProjectionController,
)

pytestmark = pytest.mark.unit

CRUISE = VelocityProjectionConfig().cruise_altitude
"""States below fly at the cruise altitude (take-off has its own tests)."""

CRUISING = RobotState(0.0, 0.0, 0.0, vx=1.0, z=CRUISE)
"""Flying along +x at 1 m/s."""
FAR_GOAL = Goal(10.0, 0.0)


def speed(command) -> float:
    return math.hypot(command.vx, command.vy)


def test_free_space_flies_to_the_goal_at_full_speed(scan_factory):
    controller = VelocityProjectionController()
    decision = controller.decide(scan_factory(CRUISING), CRUISING, FAR_GOAL)
    assert decision.direction == pytest.approx(0.0)
    assert speed(decision.command) == pytest.approx(controller.config.max_speed)
    assert decision.obstacles_in_view == 0


def test_obstacle_ahead_makes_it_slow_down_and_steer(scan_factory):
    controller = VelocityProjectionController()
    obstacle = (1.2, 0.0, 0.2)  # straight ahead, inside the look-ahead of 2 m
    decision = controller.decide(scan_factory(CRUISING, discs=[obstacle]), CRUISING, FAR_GOAL)
    assert decision.obstacles_in_view > 0
    assert decision.direction is not None and abs(decision.direction) > 0.1
    assert speed(decision.command) < controller.config.max_speed
    # It only steers within its field of view while moving.
    assert abs(decision.direction) <= controller.config.field_of_view / 2.0 + 1e-9


def test_obstacle_at_120_degrees_is_ignored(scan_factory):
    controller = VelocityProjectionController()
    beside = (0.45 * math.cos(math.radians(120.0)), 0.45 * math.sin(math.radians(120.0)), 0.2)
    decision = controller.decide(scan_factory(CRUISING, discs=[beside]), CRUISING, FAR_GOAL)
    assert decision.obstacles_in_view == 0
    assert decision.direction == pytest.approx(0.0)
    assert speed(decision.command) == pytest.approx(controller.config.max_speed)


def test_a_wide_field_of_view_sees_the_flank(scan_factory):
    flank = (0.3, 0.42, 0.1)  # 54 degrees off the motion direction, brushing the flyer's path
    narrow = VelocityProjectionController()
    wide = VelocityProjectionController(VelocityProjectionConfig(field_of_view=math.pi))
    scan = scan_factory(CRUISING, discs=[flank])
    assert narrow.decide(scan, CRUISING, FAR_GOAL).direction == pytest.approx(0.0)
    swerve = wide.decide(scan, CRUISING, FAR_GOAL)
    assert swerve.direction is not None and swerve.direction < 0.0  # away from the flank


def test_brakes_when_everything_in_view_is_blocked(scan_factory):
    controller = VelocityProjectionController()
    wall = [(0.8, y, 0.1) for y in np.arange(-1.5, 1.51, 0.1)]
    decision = controller.decide(scan_factory(CRUISING, discs=wall), CRUISING, FAR_GOAL)
    assert decision.direction is None
    assert speed(decision.command) == 0.0


def test_at_rest_it_looks_all_around(scan_factory):
    controller = VelocityProjectionController()
    at_rest = RobotState(0.0, 0.0, 0.0, z=CRUISE)
    wall = [(0.8, y, 0.1) for y in np.arange(-1.5, 1.51, 0.1)]
    decision = controller.decide(scan_factory(at_rest, discs=wall), at_rest, FAR_GOAL)
    assert decision.direction is not None
    assert abs(decision.direction) > controller.config.field_of_view / 2.0


def test_arrives_slowly_and_stops_at_the_goal():
    controller = VelocityProjectionController()
    empty = ScanData(np.full(360, np.inf), -math.pi, math.radians(1.0), 0.05, 8.0)
    state = RobotState(0.0, 0.0, 0.0, vx=0.5, z=CRUISE)
    near = controller.compute_command(empty, state, Goal(0.5, 0.0))
    assert speed(near) == pytest.approx(controller.config.arrival_gain * 0.5)
    assert controller.compute_command(empty, state, Goal(0.1, 0.0)) == STOP


def test_goal_next_to_a_wall_is_reachable(scan_factory):
    corner = ('#####', '#...#', '#...#', '#####')
    controller = VelocityProjectionController()
    state = RobotState(1.25, 1.25, 0.0, z=CRUISE)
    goal = Goal(0.75, 0.75)  # 0.25 m from two walls: 5 cm clearance for the 0.2 m flyer
    decision = controller.decide(scan_factory(state, corner), state, goal)
    _, bearing = goal.in_body_frame(state)
    assert decision.direction == pytest.approx(bearing)


def test_faces_its_motion_direction(scan_factory):
    controller = VelocityProjectionController()
    state = RobotState(0.0, 0.0, 0.0, z=CRUISE)
    command = controller.compute_command(scan_factory(state), state, Goal(0.0, 5.0))
    assert command.wz == pytest.approx(controller.config.max_yaw_rate)


def test_rejects_bad_config():
    with pytest.raises(ValueError, match='field_of_view'):
        VelocityProjectionController(VelocityProjectionConfig(field_of_view=0.0))


def test_ring_blocking_matches_the_swept_corridor():
    """The interval marking of blocked directions equals the brute-force stadium test."""
    controller = VelocityProjectionController()
    ring = controller._ring
    rng = np.random.default_rng(3)
    for _ in range(100):
        count = int(rng.integers(1, 30))
        angles = rng.uniform(-math.pi, math.pi, count)
        ranges = rng.uniform(0.05, 3.0, count)
        length, corridor = rng.uniform(0.5, 2.5), rng.uniform(0.2, 0.5)
        half_view = rng.uniform(0.2, math.pi)
        relative = (angles[None, :] - ring[:, None] + math.pi) % (2.0 * math.pi) - math.pi
        along = ranges * np.cos(relative)
        across = ranges * np.sin(relative)
        excess = along - np.clip(along, 0.0, length)
        expected = ((np.abs(relative) <= half_view)
                    & (excess ** 2 + across ** 2 < corridor ** 2)).any(axis=1)
        marked = controller._blocked_ring(angles, ranges, length, corridor, half_view)
        np.testing.assert_array_equal(marked, expected)


def test_takes_off_in_place_before_moving_and_then_holds_the_cruise_altitude(scan_factory):
    controller = VelocityProjectionController()
    config = controller.config
    landed = RobotState(0.0, 0.0, 0.0)
    command = controller.decide(scan_factory(landed), landed, FAR_GOAL).command
    assert (command.vx, command.vy) == (0.0, 0.0)
    assert command.vz == pytest.approx(min(config.max_climb_rate,
                                           config.climb_gain * config.cruise_altitude))
    assert command.vz > 0.5
    low = RobotState(0.0, 0.0, 0.0, z=config.takeoff_altitude - 0.01)
    assert speed(controller.decide(scan_factory(low), low, FAR_GOAL).command) == 0.0
    above = RobotState(0.0, 0.0, 0.0, z=config.takeoff_altitude + 0.01)
    command = controller.decide(scan_factory(above), above, FAR_GOAL).command
    assert speed(command) > 0.0
    assert command.vz == pytest.approx(config.climb_gain * (CRUISE - above.z))
    # Too high: it descends to the cruise altitude while flying.
    high = RobotState(0.0, 0.0, 0.0, vx=1.0, z=CRUISE + 0.2)
    command = controller.decide(scan_factory(high), high, FAR_GOAL).command
    assert command.vz == pytest.approx(-0.2 * config.climb_gain) and speed(command) > 0.0


def test_altitude_parameters_are_checked():
    with pytest.raises(InvalidConfigError, match='takeoff_altitude'):
        VelocityProjectionController(VelocityProjectionConfig(takeoff_altitude=1.5))
    with pytest.raises(InvalidConfigError, match='climb_gain'):
        VelocityProjectionController(VelocityProjectionConfig(climb_gain=0.0))
