"""Fleets: robots r1, r2, ... drawn deterministically from the map seed with start and goal's
clearance, apart from every other robot, each route certified among the others parked on
their goals; one robot is exactly the plain start -> goal episode."""

import dataclasses
import itertools
import json
import math

import numpy as np
import pytest

from sessgan_core.environment import MAX_ROBOTS, Environment, FleetRobot, Pose2D
from sessgan_core.errors import InvalidFleetError
from sessgan_core.fleet import (
    FleetRejection,
    FleetSpec,
    fleet_from_json,
    fleet_to_json,
    separation,
)
from sessgan_core.missions import MissionSpec
from sessgan_core.route_certificate import map_clearance, required_clearances
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import certify_fleet, environment_is_feasible, make_environment
from sessgan_gen.environment_sampler import EnvironmentSampler
from tests.unit.gen.served_maps import served_token_maps

pytestmark = pytest.mark.unit

SEEDS = {'factory': range(710_000, 710_012), 'drone': range(710_000, 710_004),
         'racetrack': range(710_000, 710_002)}


@pytest.fixture(scope='module')
def maps():
    return served_token_maps(SEEDS)


def as_tuple(environment: Environment):
    return (environment.start, environment.goal, environment.feasible, environment.fleet,
            environment.route_length, environment.route_min_clearance)


def test_one_robot_is_the_plain_episode_exactly(maps):
    for scenario, drawn in maps.items():
        for seed, cells in drawn:
            plain = make_environment(cells, scenario, 'e', seed=seed)
            one = make_environment(cells, scenario, 'e', seed=seed, fleet=FleetSpec(1))
            assert as_tuple(plain) == as_tuple(one) and plain.extra == one.extra
            assert one.fleet == () and one.robots == 1


def test_the_sampler_with_one_robot_draws_what_it_draws_without_the_option():
    sampler = EnvironmentSampler()
    seeds = [5, 6, 7]
    without = sampler.sample(seeds, scenario='factory')
    with_one = sampler.sample(seeds, scenario='factory', fleet=FleetSpec(1))
    for a, b in zip(without, with_one):
        assert np.array_equal(a.occupancy, b.occupancy)
        assert as_tuple(a) == as_tuple(b) and a.extra == b.extra
    fleets = sampler.sample(seeds, scenario='factory', fleet=FleetSpec(3))
    assert all(e.robots == 3 for e in fleets if e.feasible) and any(e.feasible for e in fleets)
    for a, b in zip(without, fleets):  # robot r0 keeps the plain episode's start and goal
        assert (a.start, a.goal) == (b.start, b.goal)


def check_fleet(environment: Environment, robots: int) -> None:
    """Every rule of sessgan_core.fleet on one feasible fleet environment."""
    spec = get_scenario(environment.scenario)
    place_need, route_need = required_clearances(spec)
    assert environment.robots == robots and len(environment.fleet) == robots - 1
    grid = map_clearance(environment.occupancy, environment.resolution, environment.origin,
                         spec)
    ends = [(environment.start, environment.goal)] + [(robot.start, robot.goal)
                                                     for robot in environment.fleet]
    for start, goal in ends:
        for pose in (start, goal):
            assert all(math.isfinite(v) for v in (pose.x, pose.y, pose.yaw))
            assert grid.clearance[grid.cell_of(pose.x, pose.y)] >= place_need - 1e-9
    # Every start and goal keeps two footprints with margins from every other robot's.
    for (a, robot_a), (b, robot_b) in itertools.combinations(
            [(pose, k) for k, pair in enumerate(ends) for pose in pair], 2):
        if robot_a != robot_b:
            assert math.dist((a.x, a.y), (b.x, b.y)) >= separation(spec) - 1e-9
    routes = certify_fleet(environment)
    assert len(routes) == robots and all(route is not None for route in routes)
    for k, route in enumerate(routes):
        assert route is not None and route.required_clearance == pytest.approx(route_need)
        # The route keeps its clearance from every other robot parked on its goal.
        parked = [goal for j, (_, goal) in enumerate(ends) if j != k]
        for cell in route.path:
            x, y = route.grid.centre(cell)
            for goal in parked:
                assert math.dist((x, y), (goal.x, goal.y)) - spec.robot_radius >= \
                    route_need - 1e-9
    assert [robot.route_length for robot in environment.fleet] == \
        pytest.approx([route.length for route in routes[1:] if route is not None])
    assert environment.route_length == pytest.approx(routes[0].length)  # type: ignore[union-attr]
    assert environment.route_min_clearance == pytest.approx(
        min(route.bottleneck_clearance for route in routes if route is not None))
    assert environment_is_feasible(environment)
    environment.validate()


@pytest.mark.parametrize('robots', [2, 4])
def test_fleets_are_deterministic_clear_apart_and_every_route_is_certified(maps, robots):
    feasible = 0
    for scenario, drawn in maps.items():
        for seed, cells in drawn:
            plain = make_environment(cells, scenario, 'e', seed=seed)
            environment = make_environment(cells, scenario, 'e', seed=seed,
                                           fleet=FleetSpec(robots))
            again = make_environment(cells, scenario, 'e', seed=seed, fleet=FleetSpec(robots))
            assert as_tuple(environment) == as_tuple(again)
            if not environment.feasible:
                assert environment.fleet == () and environment.extra['rejection']
                continue
            feasible += 1
            assert (environment.start, environment.goal) == (plain.start, plain.goal)
            check_fleet(environment, robots)
    assert feasible >= 0.8 * sum(len(seeds) for seeds in SEEDS.values())


def test_a_full_fleet_fits_the_example_factory():
    environment = make_environment(load_example_map('factory').cells, 'factory', 'e', seed=4,
                                   fleet=FleetSpec(MAX_ROBOTS))
    assert environment.feasible, environment.extra
    check_fleet(environment, MAX_ROBOTS)


def test_fleets_differ_between_seeds():
    cells = load_example_map('factory').cells
    drawn = {make_environment(cells, 'factory', 'e', seed=seed,
                              fleet=FleetSpec(2)).fleet[0].start for seed in range(12)}
    assert len(drawn) >= 6


def test_a_room_too_small_for_the_fleet_is_not_a_valid_test_and_says_why():
    room = np.zeros((8, 8), dtype=np.int64)  # a 4 m x 4 m empty factory room
    assert make_environment(room, 'factory', 'e', fleet=FleetSpec(2)).feasible
    environment = make_environment(room, 'factory', 'e', fleet=FleetSpec(MAX_ROBOTS))
    assert not environment.feasible and environment.fleet == ()
    assert environment.extra['rejection'] in (FleetRejection.NO_FLEET_ROOM,
                                              FleetRejection.NO_FLEET_ROUTE)
    assert environment.extra['rejection_detail'].startswith('robot r')
    # Robot r0's own draw is kept: the map failed only for the fleet.
    plain = make_environment(room, 'factory', 'e')
    assert (environment.start, environment.goal) == (plain.start, plain.goal)


def test_a_map_without_room_for_one_robot_gets_no_fleet():
    environment = make_environment(np.ones((16, 16), dtype=np.int64), 'factory', 'e',
                                   fleet=FleetSpec(3))
    assert not environment.feasible and environment.fleet == ()
    assert environment.extra['rejection'] == 'no_clear_cell'


def test_a_goal_parked_in_a_route_makes_the_fleet_infeasible():
    environment = make_environment(load_example_map('factory').cells, 'factory', 'e', seed=2,
                                   fleet=FleetSpec(2))
    assert environment_is_feasible(environment)
    # Robot r1 parked on robot r0's start: r0 cannot leave.
    robot = dataclasses.replace(environment.fleet[0], goal=environment.start)
    blocked = dataclasses.replace(environment, fleet=(robot,))
    assert certify_fleet(blocked)[0] is None
    assert not environment_is_feasible(blocked)


@pytest.mark.parametrize('robots', [0, -1, MAX_ROBOTS + 1, True, 1.5, '2'])
def test_fleet_spec_refuses_what_cannot_work(robots):
    with pytest.raises(InvalidFleetError, match=rf'robots .*got {robots!r}'):
        FleetSpec(robots).validate()
    with pytest.raises(InvalidFleetError, match='robots'):
        make_environment(load_example_map('factory').cells, 'factory', 'e',
                         fleet=FleetSpec(robots))


def test_a_fleet_with_mission_stations_is_refused():
    with pytest.raises(InvalidFleetError, match='robots=2 .*mission_stations=1'):
        FleetSpec(2).validate(mission_stations=1)
    with pytest.raises(InvalidFleetError, match='mission_stations'):
        make_environment(load_example_map('factory').cells, 'factory', 'e',
                         mission=MissionSpec(1), fleet=FleetSpec(2))
    FleetSpec(1).validate(mission_stations=3)  # one robot may run a mission


def test_fleet_json_round_trip():
    fleet = (FleetRobot(Pose2D(1.0, 2.0, 0.5), Pose2D(3.0, 4.0, -1.0), 7.25),
             FleetRobot(Pose2D(5.0, 6.0, 0.0), Pose2D(7.0, 8.0, 3.0)))
    assert fleet_from_json(json.loads(json.dumps(fleet_to_json(fleet)))) == fleet
    assert fleet_from_json(None) == () and fleet_from_json([]) == ()  # files without fleets


def test_environment_message_round_trip():
    pytest.importorskip('sessgan_interfaces')
    from sessgan_core.errors import InvalidEnvironmentError
    from sessgan_core.ros_conversion import environment_from_msg, environment_to_msg

    environment = make_environment(load_example_map('factory').cells, 'factory', 'e', seed=1,
                                   fleet=FleetSpec(3))
    assert environment.feasible
    msg = environment_to_msg(environment)
    assert len(msg.fleet_starts) == len(msg.fleet_goals) == len(msg.fleet_route_lengths) == 2
    back = environment_from_msg(msg)
    assert back.robots == 3
    for robot, returned in zip(environment.fleet, back.fleet):
        assert returned.route_length == robot.route_length
        for pose, other in ((robot.start, returned.start), (robot.goal, returned.goal)):
            assert (other.x, other.y, other.yaw) == pytest.approx((pose.x, pose.y, pose.yaw))
    assert environment_from_msg(environment_to_msg(make_environment(
        load_example_map('factory').cells, 'factory', 'e', seed=1))).fleet == ()
    msg.fleet_route_lengths = [1.0]
    with pytest.raises(InvalidEnvironmentError, match='got 2, 2 and 1'):
        environment_from_msg(msg)
