"""The reference navigator's core on synthetic maps and scans: planning, replanning, stopping."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import STOP, Goal, MapData, RobotState, accepts_map
from sessgan_controllers.errors import InvalidConfigError
from sessgan_controllers.reference_navigator import (
    ROBOT_PRESETS,
    Mode,
    ReferenceNavigator,
    ReferenceNavigatorConfig,
)
from sessgan_controllers.registry import get_controller

pytestmark = pytest.mark.unit

# A 6 m x 4 m room with a 2 m x 1 m pillar in the middle: two ways round it.
ROOM = ['############',
        '#..........#',
        '#..........#',
        '#....##....#',
        '#....##....#',
        '#..........#',
        '#..........#',
        '############']


def grid_map(rows: list[str], resolution: float = 0.5) -> MapData:
    values = {'.': 0, '#': 100, 'o': 50}
    occupancy = np.array([[values[char] for char in row] for row in reversed(rows)],
                         dtype=np.int8)
    return MapData(occupancy, resolution)


def navigator(rows=ROOM, **overrides) -> ReferenceNavigator:
    controller = ReferenceNavigator(ReferenceNavigatorConfig(**overrides))
    controller.set_map(grid_map(rows))
    return controller


def test_robot_presets_fill_the_zero_parameters():
    for robot, preset in ROBOT_PRESETS.items():
        settings = ReferenceNavigatorConfig(robot=robot).resolved()
        for name, value in preset.items():
            assert getattr(settings, name) == value, (robot, name)
    custom = ReferenceNavigatorConfig(robot='car', max_speed=6.0).resolved()
    assert custom.max_speed == 6.0 and custom.robot_radius == ROBOT_PRESETS['car']['robot_radius']


@pytest.mark.parametrize('overrides, name', [
    ({'robot': 'tank'}, 'robot'),
    ({'max_speed': -1.0}, 'max_speed'),
    ({'lookahead_min': 2.0, 'lookahead_max': 1.0}, 'lookahead_min'),
    ({'replan_interval': 0}, 'replan_interval'),
    ({'min_speed_factor': 1.5}, 'min_speed_factor'),
])
def test_bad_parameters_are_named(overrides, name):
    with pytest.raises(InvalidConfigError, match=name):
        ReferenceNavigatorConfig(**overrides).validate()


def test_it_takes_the_map():
    # So do the paper's controllers, for their route guidance (test_route_guidance.py).
    assert accepts_map(get_controller('reference_navigator').make())


def test_without_a_map_it_stands_still(scan_factory):
    controller = ReferenceNavigator()
    state = RobotState(1.0, 1.0, 0.0)
    decision = controller.decide(scan_factory(state, grid=ROOM), state, Goal(5.0, 3.0))
    assert decision.mode is Mode.NO_MAP and decision.command == STOP


def test_it_plans_around_the_pillar_and_drives(scan_factory):
    controller = navigator()
    state = RobotState(1.0, 2.0, 0.0)
    decision = controller.decide(scan_factory(state, grid=ROOM), state, Goal(5.0, 2.0))
    assert decision.replanned and decision.path is not None
    assert decision.mode is Mode.FOLLOW
    assert decision.command.vx > 0.0 and decision.command.is_finite()
    points = decision.path.points
    assert np.all(controller.costmap.clearance_at(points) >= 0.35 - 1e-6)
    # The next step follows the same path.
    again = controller.decide(scan_factory(state, grid=ROOM), state, Goal(5.0, 2.0))
    assert not again.replanned and again.path is decision.path


def test_it_replans_around_something_the_scan_sees_on_its_path(scan_factory):
    controller = navigator(replan_interval=1)
    state = RobotState(1.0, 2.0, 0.0)
    goal = Goal(5.0, 2.0)
    first = controller.decide(scan_factory(state, grid=ROOM), state, goal)
    side = 1.0 if first.path.points[:, 1].mean() > 2.0 else -1.0  # above or below the pillar
    # An agent stands in that passage, 1 m wide, half-way round.
    agent = (3.0, 2.0 + side * 1.0, 0.2)
    blocked = scan_factory(state, grid=ROOM, discs=[agent])
    decision = controller.decide(blocked, state, goal)
    assert decision.replanned and 'blocked' in decision.detail
    assert decision.path is not None
    new_side = 1.0 if decision.path.points[:, 1].mean() > 2.0 else -1.0
    assert new_side == -side
    gaps = np.hypot(decision.path.points[:, 0] - agent[0], decision.path.points[:, 1] - agent[1])
    assert gaps.min() > agent[2] + 0.2


def test_with_no_way_through_it_stops_and_retries_at_its_interval(scan_factory):
    walled = ['#########',
              '#...#...#',
              '#...#...#',
              '#########']
    controller = navigator(walled, replan_interval=5)
    state = RobotState(1.0, 1.0, 0.0)
    scan = scan_factory(state, grid=walled)
    decisions = [controller.decide(scan, state, Goal(3.0, 1.0)) for _ in range(11)]
    assert all(d.mode is Mode.NO_PATH and d.command == STOP for d in decisions)
    assert [index for index, d in enumerate(decisions) if d.replanned] == [0, 5, 10]
    assert 'no path' in decisions[0].detail


def test_an_agent_in_the_only_corridor_stops_the_robot_until_it_leaves(scan_factory):
    corridor = ['##############',
                '#............#',
                '##############']
    corridor = [corridor[0], corridor[1], corridor[1], corridor[2]]  # 1 m wide
    controller = navigator(corridor, replan_interval=1)
    state = RobotState(1.0, 1.0, 0.0)
    goal = Goal(6.0, 1.0)
    assert controller.decide(scan_factory(state, grid=corridor), state, goal).mode is Mode.FOLLOW
    blocked = scan_factory(state, grid=corridor, discs=[(2.2, 1.0, 0.2)])
    decision = controller.decide(blocked, state, goal)
    assert decision.command.vx == 0.0 or decision.mode is Mode.NO_PATH
    assert decision.command.is_finite()
    for _ in range(3):
        decision = controller.decide(blocked, state, goal)
        assert decision.command.vx == 0.0 and decision.command.is_finite()
    # The agent is gone: the beams clear its marks and the robot goes on.
    clear = scan_factory(state, grid=corridor)
    for _ in range(3):
        decision = controller.decide(clear, state, goal)
    assert decision.mode is Mode.FOLLOW and decision.command.vx > 0.0


def test_low_obstacles_are_passable_for_the_flyer_only(scan_factory):
    rows = ['#########',
            '#...o...#',
            '#...o...#',
            '#...o...#',
            '#########']
    state = RobotState(1.0, 1.25, 0.0)
    goal = Goal(3.5, 1.25)
    cruising = RobotState(1.0, 1.25, 0.0, z=0.95)
    flyer = navigator(rows, robot='flyer').decide(scan_factory(state, grid=rows), cruising,
                                                  goal)
    assert flyer.mode is Mode.FOLLOW and flyer.path.length < 3.0
    ground = navigator(rows).decide(scan_factory(state, grid=rows), state, goal)
    assert ground.mode is Mode.NO_PATH and ground.command == STOP


def test_a_new_map_drops_the_path_and_the_goal_stops_the_robot(scan_factory):
    controller = navigator()
    state = RobotState(1.0, 2.0, 0.0)
    controller.decide(scan_factory(state, grid=ROOM), state, Goal(5.0, 2.0))
    assert controller.path is not None
    controller.set_map(grid_map(ROOM))
    assert controller.path is None
    at_goal = RobotState(5.0, 2.05, 0.0)
    decision = controller.decide(scan_factory(at_goal, grid=ROOM), at_goal, Goal(5.0, 2.0))
    assert decision.mode is Mode.GOAL_REACHED and decision.command == STOP
    assert controller.goal_reached(at_goal, Goal(5.0, 2.0))


@pytest.mark.parametrize('robot', ['diff_drive', 'car', 'flyer'])
def test_commands_stay_finite_and_within_the_robot_limits(scan_factory, robot):
    rows = ['#' * 40] + ['#' + '.' * 38 + '#'] * 18 + ['#' * 40]
    controller = navigator(rows, robot=robot)
    settings = controller.settings
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.uniform(3.0, 17.0), rng.uniform(3.0, 7.0)
        state = RobotState(x, y, rng.uniform(-math.pi, math.pi), vx=rng.uniform(0.0, 1.0),
                           z=0.95 if robot == 'flyer' else 0.0)
        decision = controller.decide(scan_factory(state, grid=rows, range_max=10.0), state,
                                     Goal(18.0, 8.0))
        command = decision.command
        assert command.is_finite()
        assert math.hypot(command.vx, command.vy) <= settings.max_speed + 1e-9
        if robot != 'flyer':
            assert command.vy == 0.0
        if robot == 'car':
            assert command.vx >= 0.0


def test_the_flyer_takes_off_in_place_then_navigates_holding_its_cruise_altitude(
        scan_factory):
    rows = ['#########',
            '#...o...#',
            '#...o...#',
            '#...o...#',
            '#########']
    controller = navigator(rows, robot='flyer')
    settings = controller.settings
    goal = Goal(3.5, 1.25)
    landed = RobotState(1.0, 1.25, 0.0)
    decision = controller.decide(scan_factory(landed, grid=rows), landed, goal)
    assert decision.mode is Mode.TAKEOFF and not controller.costmap.marks
    assert (decision.command.vx, decision.command.vy) == (0.0, 0.0)
    assert decision.command.vz == pytest.approx(
        min(settings.max_climb_rate, settings.climb_gain * settings.cruise_altitude))
    climbing = RobotState(1.0, 1.25, 0.0, z=settings.takeoff_altitude + 0.05)
    decision = controller.decide(scan_factory(climbing, grid=rows), climbing, goal)
    assert decision.mode is Mode.FOLLOW and decision.command.vx > 0.0
    assert decision.command.vz == pytest.approx(
        settings.climb_gain * (settings.cruise_altitude - climbing.z))
    with pytest.raises(InvalidConfigError, match='takeoff_altitude'):
        ReferenceNavigator(ReferenceNavigatorConfig(robot='flyer', cruise_altitude=0.3))
