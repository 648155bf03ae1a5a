"""Nearness-Diagram navigation on synthetic scans."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import STOP, Goal, RobotState, ScanData
from sessgan_controllers.nearness_diagram import (
    NearnessDiagramConfig,
    NearnessDiagramController,
    Situation,
)

pytestmark = pytest.mark.unit

# Two rooms split by a wall with a door at each end; 0.5 m cells, top row first.
TWO_DOORS = (
    '############',
    '#..........#',
    '#..........#',
    '#..........#',
    '#.########.#',
    '#..........#',
    '#..........#',
    '#..........#',
    '############',
)


def test_open_space_heads_straight_for_the_goal(scan_factory):
    controller = NearnessDiagramController()
    state = RobotState(0.0, 0.0, 0.0)
    decision = controller.decide(scan_factory(state), state, Goal(3.0, 1.0))
    assert decision.situation is Situation.HIGH_SAFETY_GOAL_IN_REGION
    assert decision.direction == pytest.approx(math.atan2(1.0, 3.0))
    assert decision.command.vx > 0.0 and decision.command.wz > 0.0


@pytest.mark.parametrize('goal_x, door_x', [(1.25, 0.75), (4.75, 5.25)])
def test_picks_the_door_towards_the_goal(scan_factory, goal_x, door_x):
    controller = NearnessDiagramController()
    state = RobotState(3.0, 1.25, math.pi / 2.0)  # lower room, facing the dividing wall
    goal = Goal(goal_x, 3.75)  # upper room, out of sight
    decision = controller.decide(scan_factory(state, TWO_DOORS), state, goal)
    assert not decision.goal_directed
    door_bearing = math.atan2(2.25 - state.y, door_x - state.x) - state.yaw
    assert decision.target_direction == pytest.approx(door_bearing, abs=math.radians(15.0))
    turn_sign = math.copysign(1.0, door_bearing)
    assert decision.command.wz * turn_sign > 0.0


def test_centres_between_close_walls(scan_factory):
    corridor = ('########', '........', '........', '########')  # 1 m wide corridor
    controller = NearnessDiagramController()
    state = RobotState(1.0, 0.8, 0.0)  # 0.3 m from the bottom (right) wall, 0.7 m from the top
    decision = controller.decide(scan_factory(state, corridor), state, Goal(3.5, 1.0))
    assert decision.situation is Situation.LOW_SAFETY_2 or \
        decision.situation is Situation.LOW_SAFETY_1
    assert decision.command.wz > 0.0  # turns away from the nearer (right-hand) wall
    assert decision.command.vx < controller.config.max_linear_speed


def test_one_sided_obstacle_is_low_safety_1(scan_factory):
    controller = NearnessDiagramController()
    state = RobotState(0.0, 0.0, 0.0)
    post = (0.3, 0.25, 0.05)  # a post ahead on the left, inside the security zone
    decision = controller.decide(scan_factory(state, discs=[post]), state, Goal(4.0, 0.0))
    assert decision.situation is Situation.LOW_SAFETY_1
    assert decision.direction < 0.0  # deviates to the right, away from the post
    assert decision.closest_obstacle < controller.config.security_distance


def test_wide_and_narrow_regions(scan_factory):
    # Goal hidden behind a wall segment ahead: the valleys beside it are wide.
    controller = NearnessDiagramController()
    state = RobotState(0.0, 0.0, 0.0)
    wall = [(3.0, y, 0.12) for y in np.arange(-1.5, 1.51, 0.1)]
    decision = controller.decide(scan_factory(state, discs=wall), state, Goal(5.0, 0.3))
    assert decision.situation is Situation.HIGH_SAFETY_WIDE_REGION
    # It aims past the wall's end with a margin, not at the end itself.
    assert abs(decision.direction) > math.atan2(1.6, 3.0)


def test_goal_reached_stops():
    controller = NearnessDiagramController()
    scan = ScanData(np.full(360, np.inf), -math.pi, math.radians(1.0), 0.05, 8.0)
    state = RobotState(1.0, 1.0, 0.3)
    decision = controller.decide(scan, state, Goal(1.05, 1.0))
    assert decision.situation is Situation.GOAL_REACHED
    assert decision.command == STOP
    assert controller.goal_reached(state, Goal(1.05, 1.0))


def test_closed_room_with_goal_outside_has_no_region(scan_factory):
    room = ('######', '#....#', '#....#', '#....#', '######')
    controller = NearnessDiagramController()
    state = RobotState(1.5, 1.25, 0.0)
    decision = controller.decide(scan_factory(state, room), state, Goal(10.0, 1.25))
    assert decision.situation is Situation.NO_REGION
    assert decision.command == STOP


def test_turns_in_place_only_for_a_direction_behind(scan_factory):
    controller = NearnessDiagramController()
    state = RobotState(0.0, 0.0, 0.0)
    behind = controller.decide(scan_factory(state), state, Goal(-3.0, 0.1))
    assert behind.command.vx == pytest.approx(0.0, abs=1e-9)
    assert behind.command.wz == pytest.approx(controller.config.max_angular_speed)
    # 60 degrees off: it drives an arc instead of turning on the spot.
    side = controller.decide(scan_factory(state), state, Goal(1.0, math.sqrt(3.0)))
    assert side.command.vx == pytest.approx(0.5 * controller.config.max_linear_speed)


def test_speed_floor_next_to_obstacles(scan_factory):
    corridor = ('#######', '.......', '#######')  # 0.5 m corridor, 5 cm clearance each side
    config = NearnessDiagramConfig(min_speed_factor=0.2, security_distance=0.3)
    controller = NearnessDiagramController(config)
    state = RobotState(1.0, 0.75, 0.0)
    command = controller.compute_command(scan_factory(state, corridor), state, Goal(3.0, 0.75))
    assert command.vx == pytest.approx(0.2 * config.max_linear_speed, rel=0.05)


def test_sparse_scan_fills_sectors_without_a_beam(scan_factory):
    room = ('######', '#....#', '#....#', '#....#', '######')
    controller = NearnessDiagramController()
    state = RobotState(1.5, 1.25, 0.0)
    sparse = scan_factory(state, room, beams=60)
    distances = controller.sector_distances(sparse)
    assert not np.isnan(distances).any()  # no fake free sectors between the beams


def test_rejects_bad_config():
    with pytest.raises(ValueError, match='robot_radius'):
        NearnessDiagramController(NearnessDiagramConfig(robot_radius=0.0))
    with pytest.raises(ValueError, match='min_speed_factor'):
        NearnessDiagramController(NearnessDiagramConfig(min_speed_factor=1.5))


def test_slows_to_stop_short_of_what_is_straight_ahead(scan_factory):
    controller = NearnessDiagramController()
    unlimited = NearnessDiagramController(NearnessDiagramConfig(braking_deceleration=0.0))
    state = RobotState(0.0, 0.0, 0.0)
    goal = Goal(5.0, 0.0)

    def commands(post_x: float):
        scan = scan_factory(state, discs=[(post_x, 0.0, 0.1)])
        return (controller.compute_command(scan, state, goal),
                unlimited.compute_command(scan, state, goal))

    far, far_unlimited = commands(3.0)
    assert far == far_unlimited  # room enough to stop
    # 0.5 m of room to the post: stop 0.1 m short of it, at 0.8 m/s^2, while it may come
    # closer at 0.5 m/s: v^2 / 1.6 + 0.5 v / 0.8 <= 0.4.
    near, near_unlimited = commands(0.8)
    assert near.vx == pytest.approx(-0.5 + math.sqrt(0.25 + 1.6 * 0.4), abs=0.02)
    assert near_unlimited.vx > near.vx and near.wz == near_unlimited.wz


def test_a_robot_that_cannot_turn_in_place_turns_on_arcs(scan_factory):
    config = NearnessDiagramConfig(min_turn_radius=0.5, reverse_speed=0.0)
    controller = NearnessDiagramController(config)
    state = RobotState(0.0, 0.0, 0.0)
    # The goal behind: the diff-drive robot turns in place, this one drives a 0.5 m arc.
    behind = controller.compute_command(scan_factory(state), state, Goal(-3.0, 0.1))
    assert behind.vx > 0.0
    assert abs(behind.wz) == pytest.approx(behind.vx / 0.5)
    # Facing a wall closer than the stop distance, the goal behind, it cannot turn: it stands
    # (the diff-drive robot turns in place).
    wall = ('####', '#..#', '#..#', '#..#', '####')
    facing = RobotState(0.75, 1.75, math.pi / 2.0)  # 0.05 m from the top wall's face
    command = controller.compute_command(scan_factory(facing, wall), facing, Goal(0.75, 0.6))
    assert command.vx == 0.0 and command.wz == 0.0
    spinning = NearnessDiagramController().compute_command(scan_factory(facing, wall), facing,
                                                           Goal(0.75, 0.6))
    assert spinning.vx == 0.0 and abs(spinning.wz) > 0.5
    # Allowed to reverse, it backs up on an arc that turns it the same way.
    backing = NearnessDiagramController(dataclasses.replace(config, reverse_speed=0.2))
    command = backing.compute_command(scan_factory(facing, wall), facing, Goal(0.75, 0.6))
    assert command.vx == pytest.approx(-0.2)
    assert command.wz == pytest.approx(math.copysign(0.2 / 0.5, spinning.wz))
    # With a wall behind it too (a 0.9 m deep box), it has no room at all.
    box = ('####', '#..#', '####')
    boxed = RobotState(0.75, 0.75, math.pi / 2.0)
    command = backing.compute_command(scan_factory(boxed, box), boxed, Goal(0.75, 0.6))
    assert command.vx == pytest.approx(0.0, abs=1e-9)
