"""Mission stations: drawn deterministically from the map seed, with start and goal's
clearance, every leg certified; no stations is exactly the plain start -> goal episode."""

import dataclasses
import math

import numpy as np
import pytest

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.errors import InvalidEnvironmentError, InvalidMissionError
from sessgan_core.missions import MAX_MISSION_STATIONS, MissionSpec
from sessgan_core.route_certificate import map_clearance, required_clearances
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import (
    certify_mission,
    environment_is_feasible,
    make_environment,
)
from tests.unit.gen.served_maps import served_token_maps

pytestmark = pytest.mark.unit

SEEDS = {'factory': range(700_000, 700_030), 'drone': range(700_000, 700_010),
         'racetrack': range(700_000, 700_003)}


@pytest.fixture(scope='module')
def maps():
    return served_token_maps(SEEDS)


def as_tuple(environment: Environment):
    return (environment.start, environment.stations, environment.goal, environment.feasible,
            environment.route_length, environment.route_min_clearance, environment.dwell_time)


def test_no_stations_is_the_plain_episode_exactly(maps):
    for scenario, drawn in maps.items():
        for seed, cells in drawn:
            plain = make_environment(cells, scenario, 'e', seed=seed)
            mission = make_environment(cells, scenario, 'e', seed=seed, mission=MissionSpec(0))
            assert as_tuple(plain) == as_tuple(mission)
            assert plain.extra == mission.extra
            assert plain.stations == () and plain.legs == 1
            assert plain.waypoints == (plain.goal,)


@pytest.mark.parametrize('stations', [1, 3])
def test_stations_are_deterministic_clear_and_every_leg_is_certified(maps, stations):
    feasible = 0
    for scenario, drawn in maps.items():
        spec = get_scenario(scenario)
        place_need, route_need = required_clearances(spec)
        for seed, cells in drawn:
            plain = make_environment(cells, scenario, 'e', seed=seed)
            environment = make_environment(cells, scenario, 'e', seed=seed,
                                           mission=MissionSpec(stations, 1.5))
            again = make_environment(cells, scenario, 'e', seed=seed,
                                     mission=MissionSpec(stations, 1.5))
            assert as_tuple(environment) == as_tuple(again)
            if not environment.feasible:
                assert environment.stations == () and environment.extra['rejection']
                continue
            feasible += 1
            assert len(environment.stations) == stations and environment.legs == stations + 1
            assert environment.dwell_time == 1.5
            # The first leg is the plain episode; home is where the robot started.
            assert environment.start == plain.start
            assert environment.stations[0] == plain.goal
            assert (environment.goal.x, environment.goal.y) == (plain.start.x, plain.start.y)
            grid = map_clearance(environment.occupancy, environment.resolution,
                                 environment.origin, spec)
            for station in environment.stations:
                assert grid.clearance[grid.cell_of(station.x, station.y)] >= place_need - 1e-9
                assert all(math.isfinite(v) for v in (station.x, station.y, station.yaw))
            legs = certify_mission(environment)
            assert len(legs) == stations + 1 and all(leg is not None for leg in legs)
            lengths = [leg.length for leg in legs]
            assert environment.extra['leg_route_lengths'] == pytest.approx(lengths)
            assert environment.route_length == pytest.approx(sum(lengths))
            assert environment.route_min_clearance == pytest.approx(
                min(leg.bottleneck_clearance for leg in legs))
            assert environment.route_min_clearance >= route_need - 1e-9
            assert environment_is_feasible(environment)
            environment.validate()
    assert feasible >= 0.9 * sum(len(seeds) for seeds in SEEDS.values())


def test_stations_differ_between_seeds(maps):
    cells = load_example_map('factory').cells
    drawn = {make_environment(cells, 'factory', 'e', seed=seed,
                              mission=MissionSpec(2)).stations[1] for seed in range(20)}
    assert len(drawn) >= 10


def test_a_walled_in_station_makes_the_mission_infeasible():
    environment = make_environment(load_example_map('factory').cells, 'factory', 'e', seed=3,
                                   mission=MissionSpec(2))
    assert environment_is_feasible(environment)
    station = environment.stations[1]
    occupancy = environment.occupancy.copy()
    row, col = environment.cell_of(station.x, station.y)
    occupancy[row, col] = 100
    blocked = dataclasses.replace(environment, occupancy=occupancy)
    legs = certify_mission(blocked)
    assert legs[0] is not None and legs[1] is None and legs[2] is None
    assert not environment_is_feasible(blocked)


def test_an_infeasible_map_gets_no_stations():
    cells = np.ones((16, 16), dtype=np.int64)  # all wall
    environment = make_environment(cells, 'factory', 'e', mission=MissionSpec(2))
    assert not environment.feasible and environment.stations == ()


@pytest.mark.parametrize('spec, message', [
    (MissionSpec(-1), 'mission_stations'),
    (MissionSpec(MAX_MISSION_STATIONS + 1), 'mission_stations'),
    (MissionSpec(True), 'mission_stations'),
    (MissionSpec(1.5), 'mission_stations'),  # type: ignore[arg-type]
    (MissionSpec(1, -0.5), 'station_dwell_time'),
    (MissionSpec(1, math.nan), 'station_dwell_time'),
    (MissionSpec(1, math.inf), 'station_dwell_time'),
])
def test_mission_spec_refuses_what_cannot_work(spec, message):
    with pytest.raises(InvalidMissionError, match=message):
        spec.validate()
    with pytest.raises(InvalidMissionError, match=message):
        make_environment(load_example_map('factory').cells, 'factory', 'e', mission=spec)


def test_environment_validate_checks_stations_and_dwell():
    environment = make_environment(load_example_map('factory').cells, 'factory', 'e', seed=1,
                                   mission=MissionSpec(1))
    environment.validate()
    outside = dataclasses.replace(environment, stations=(Pose2D(-3.0, 1.0, 0.0),))
    with pytest.raises(InvalidEnvironmentError, match='station 1'):
        outside.validate()
    with pytest.raises(InvalidEnvironmentError, match='dwell time'):
        dataclasses.replace(environment, dwell_time=-1.0).validate()
    too_many = dataclasses.replace(environment,
                                   stations=(environment.start,) * (MAX_MISSION_STATIONS + 1))
    with pytest.raises(InvalidEnvironmentError, match='mission stations'):
        too_many.validate()
