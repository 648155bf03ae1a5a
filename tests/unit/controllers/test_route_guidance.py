"""Route guidance of the paper's controllers: a route on the map and the waypoint ahead on it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sessgan_controllers.controller_interface import Goal, MapData, RobotState, accepts_map
from sessgan_controllers.registry import get_controller
from sessgan_controllers.route_guidance import RouteGuidanceConfig, RouteGuide

pytestmark = pytest.mark.unit

# A 6 x 4 m room (0.5 m cells, top row first) with a wall from the bottom up to 2.5 m between
# the robot on the left and the goal on the right: the way round is over the top.
ROOM = [
    '############',
    '#..........#',
    '#..........#',
    '#....#.....#',
    '#....#.....#',
    '#....#.....#',
    '#....#.....#',
    '############',
]
START = RobotState(1.25, 1.25, 0.0)
GOAL = Goal(4.25, 1.25)


def room_map(rows: list[str] = ROOM) -> MapData:
    grid = np.array([[100 if char == '#' else 0 for char in row] for row in reversed(rows)],
                    dtype=np.int8)
    return MapData(grid, 0.5)


def guide(**overrides) -> RouteGuide:
    values = dict(robot_radius=0.2, route_clearance=0.1, waypoint_distance=1.0,
                  replan_deviation=0.5, planning_resolution=0.1)
    values.update(overrides)
    return RouteGuide(RouteGuidanceConfig(**values))


def test_without_a_map_the_waypoint_is_the_goal():
    waypoint = guide().waypoint(START, GOAL)
    assert waypoint.target == GOAL and waypoint.is_goal


def test_the_waypoint_leads_round_the_wall_on_the_route():
    route_guide = guide()
    route_guide.set_map(room_map())
    waypoint = route_guide.waypoint(START, GOAL)
    assert not waypoint.is_goal
    # Straight towards the goal is the wall; the waypoint lies up the left side, 1 m of route
    # from the robot, with room to pass.
    assert waypoint.target.y > START.y + 0.6
    assert waypoint.target.x < 2.5
    assert math.hypot(waypoint.target.x - START.x, waypoint.target.y - START.y) \
        == pytest.approx(1.0, abs=0.1)
    route = route_guide.route
    assert route is not None and route.points[:, 1].max() > 2.5 + 0.2  # over the wall's top


def test_the_last_stretch_steers_for_the_goal_itself():
    route_guide = guide()
    route_guide.set_map(room_map())
    near_goal = RobotState(4.25, 2.0, -math.pi / 2)
    waypoint = route_guide.waypoint(near_goal, GOAL)
    assert waypoint.is_goal and waypoint.target == GOAL


def test_a_robot_off_the_route_gets_a_new_one_and_a_new_goal_too():
    route_guide = guide()
    route_guide.set_map(room_map())
    route_guide.waypoint(START, GOAL)
    assert route_guide.plans == 1
    route_guide.waypoint(RobotState(1.3, 1.4, 0.5), GOAL)  # on the way: no new route
    assert route_guide.plans == 1
    route_guide.waypoint(RobotState(2.25, 1.25, 0.0), GOAL)  # pushed 1 m off the route
    assert route_guide.plans == 2
    route_guide.waypoint(RobotState(2.25, 1.25, 0.0), Goal(5.25, 3.25))
    assert route_guide.plans == 3
    route_guide.reset()
    assert route_guide.route is None and route_guide.plans == 0


def test_no_route_or_use_map_false_steers_for_the_goal():
    walled_in = [row[:6] + '#' + row[7:] for row in ROOM]  # the wall reaches the top
    route_guide = guide()
    route_guide.set_map(room_map(walled_in))
    assert route_guide.waypoint(START, GOAL) == route_guide.waypoint(START, GOAL)
    assert route_guide.waypoint(START, GOAL).target == GOAL
    off = guide(enabled=False)
    off.set_map(room_map())
    assert off.waypoint(START, GOAL).target == GOAL


def test_bad_guidance_values_are_named():
    with pytest.raises(ValueError, match='waypoint_distance'):
        guide(waypoint_distance=0.0)
    with pytest.raises(ValueError, match='route_clearance'):
        guide(route_clearance=-0.1)


@pytest.mark.parametrize('name', ['nearness_diagram', 'tricycle_nearness_diagram',
                                  'velocity_projection', 'race_controller'])
def test_the_paper_controllers_take_the_map(name):
    controller = get_controller(name).make()
    assert accepts_map(controller)
    controller.set_map(room_map())
    assert get_controller(name).make(use_map=False).guide.costmap is None
