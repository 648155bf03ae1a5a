"""The built-in controllers driving sessgan_sim's robots in-process, with their defaults.

Realistic defaults: each controller reaches the goal of its scenario's example map.
A zig-zag too narrow for a certified route makes the Nearness-Diagram robot collide,
but that is not a controller failure. Each paper controller fails the way its docstring
says, and steering for the goal alone (no route on the map) traps a reactive method.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from sessgan_controllers.controller_interface import (
    STOP,
    Controller,
    Goal,
    MapData,
    accepts_map,
    observed,
)
from sessgan_controllers.registry import get_controller
from sessgan_core.environment import Environment, Pose2D
from sessgan_core.route_certificate import certify, map_clearance, required_clearances
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import load_example_map, read_token_map
from sessgan_core.valid_tests import make_environment
from sessgan_gen.environment_sampler import EnvironmentSampler
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.metrics import EpisodeMetrics, Outcome, is_controller_failure

pytestmark = pytest.mark.unit

NARROW_DOG_LEG = Path(__file__).parents[2] / 'data' / 'narrow_dog_leg.txt'


def run_episode(environment: Environment, controller: Controller,
                config: EpisodeConfig) -> EpisodeMetrics:
    """One lockstep episode as the controller node runs it: the map first (to a controller
    that plans on it), a command per observation, a stop once the goal is reached."""
    if accepts_map(controller):
        controller.set_map(MapData.of(environment))
    goal = Goal(environment.goal.x, environment.goal.y)
    with Episode() as episode:
        observation = episode.reset(environment, config)
        done = episode.done
        while not done:
            scan, state = observed(observation)
            command = (STOP if controller.goal_reached(state, goal)
                       else controller.compute_command(scan, state, goal))
            observation, done, _ = episode.step(command.values())
        return episode.metrics()


def example(scenario_name: str) -> Environment:
    return make_environment(load_example_map(scenario_name).cells, scenario_name,
                            f'{scenario_name}-example')


@pytest.mark.parametrize('scenario_name', ['factory', 'racetrack', 'drone'])
def test_default_controller_reaches_the_example_goal(scenario_name):
    scenario = get_scenario(scenario_name)
    spec = get_controller(scenario.controller)
    assert spec.robot == scenario.robot
    environment = example(scenario_name)
    assert environment.feasible
    # Seed 1: with seed 0 a factory agent's patrol ends just past where Nearness-Diagram
    # waits for it, and the agent keeps turning back off the waiting robot until the
    # collision limit (agent_into_robot contacts: not a failure).
    metrics = run_episode(environment, spec.make(), EpisodeConfig(seed=1))
    assert metrics.outcome is Outcome.GOAL_REACHED, metrics.detail
    assert metrics.simulation_time < scenario.time_limit


def test_a_zig_zag_with_5_cm_per_side_is_not_a_valid_test():
    # The Nearness-Diagram robot hits the corners of a one-cell zig-zag, but a corridor that
    # leaves a 0.4 m robot 5 cm per side has no certified route: not the controller's fault.
    token_map = read_token_map(NARROW_DOG_LEG, 'factory')
    environment = make_environment(token_map.cells, 'factory', 'narrow-dog-leg')
    assert not environment.feasible
    environment.start = Pose2D(1.25, 14.25, 0.0)  # the start room
    environment.goal = Pose2D(6.75, 8.25)         # the goal room
    # Without its protective field (stopping short of what is straight ahead), as the
    # reference implementation drives.
    controller = get_controller('nearness_diagram').make(braking_deceleration=0.0)
    metrics = run_episode(environment, controller, EpisodeConfig(seed=0, dummy_agents=0))
    assert metrics.collisions > 0 and metrics.fault_collisions > 0, metrics
    assert not is_controller_failure(metrics)


def test_steering_for_the_goal_alone_fails_where_the_route_gets_through():
    # Without a route on the map the race car takes the wrong branch at the start of the
    # example track (test_default_controller_reaches_the_example_goal: with it, it arrives).
    spec = get_controller(get_scenario('racetrack').controller)
    metrics = run_episode(example('racetrack'), spec.make(use_map=False),
                          EpisodeConfig(seed=0, dummy_agents=0))
    assert metrics.outcome is Outcome.STUCK, metrics.detail
    assert is_controller_failure(metrics)


def test_a_way_of_its_own_is_not_stuck():
    # Without the route, Nearness-Diagram crosses the example factory by a way the
    # certificate does not use (7.8 m driven, against 11.0 m along the route), moving away
    # from the goal on the certified route's field for more than the stuck window. Until
    # 2026-11-28 the stuck rule, which knew only that field, ended it stuck 10 s in.
    spec = get_controller(get_scenario('factory').controller)
    metrics = run_episode(example('factory'), spec.make(use_map=False),
                          EpisodeConfig(seed=0, dummy_agents=0))
    assert metrics.outcome is Outcome.GOAL_REACHED, metrics.detail
    assert metrics.distance_travelled < 9.0


class RecordingController:
    """A controller whose commands are kept in ``commands``."""

    def __init__(self, controller: Controller) -> None:
        self.controller = controller
        self.commands: list = []

    def compute_command(self, scan, state, goal):
        command = self.controller.compute_command(scan, state, goal)
        self.commands.append(command)
        return command

    def __getattr__(self, name: str):
        return getattr(self.controller, name)


def test_the_tricycle_needs_room_to_turn_where_nearness_diagram_turns_on_the_spot():
    # The example factory's start faces a wall 0.7 m away, the route turning 45 degrees
    # through a door beside it: the diff-drive robot turns in place and drives on; the robot
    # that cannot turn in place has to back up first (a three-point turn), and without
    # reversing it stops in front of the wall.
    environment = example('factory')
    config = EpisodeConfig(seed=0, dummy_agents=0)
    spinning = RecordingController(get_controller('nearness_diagram').make())
    turning = run_episode(environment, spinning, config)
    assert turning.outcome is Outcome.GOAL_REACHED and turning.fault_collisions == 0
    assert min(command.vx for command in spinning.commands) >= 0.0
    spec = get_controller('tricycle_nearness_diagram')
    assert spec.robot == 'tricycle'
    config = dataclasses.replace(config, robot=spec.robot)
    backing = RecordingController(spec.make())
    tricycle = run_episode(environment, backing, config)
    assert tricycle.outcome is Outcome.GOAL_REACHED and tricycle.fault_collisions == 0
    assert min(command.vx for command in backing.commands[:40]) < 0.0  # in the first 2 s
    assert tricycle.simulation_time > turning.simulation_time
    stuck = run_episode(environment, spec.make(reverse_speed=0.0), config)
    assert stuck.outcome is Outcome.STUCK and stuck.distance_travelled < 1.0


def branch_track(angle: float) -> Environment:
    """A 5 m wide straight of 100 m with a 30 m branch leaving it at 60 m, ``angle`` degrees
    off the straight; the start at the straight's beginning, the goal near the branch's end,
    joined by a certified route."""
    size, width, junction = 110, 5.0, (65.0, 8.0)
    heading = math.radians(angle)
    centres = [(5.0 + along, 8.0) for along in np.arange(0.0, 100.0, 0.25)]
    centres += [(junction[0] + along * math.cos(heading), junction[1] + along * math.sin(heading))
                for along in np.arange(0.0, 30.0, 0.25)]
    rows, cols = np.mgrid[0:size, 0:size]
    cells = np.ones((size, size), dtype=int)  # out of bounds
    for x, y in centres:
        cells[np.hypot(cols + 0.5 - x, rows + 0.5 - y) <= 0.5 * width] = 0  # track
    environment = make_environment(cells, 'racetrack', f'branch-{angle:.0f}')
    environment.start = Pose2D(8.0, 8.0, 0.0)
    environment.goal = Pose2D(junction[0] + 27.0 * math.cos(heading),
                              junction[1] + 27.0 * math.sin(heading))
    spec = get_scenario('racetrack')
    grid = map_clearance(environment.occupancy, environment.resolution, environment.origin,
                         spec)
    route = certify(grid, grid.cell_of(environment.start.x, environment.start.y),
                    grid.cell_of(environment.goal.x, environment.goal.y),
                    required_clearances(spec)[1])
    assert route is not None
    environment.feasible, environment.route_length = True, route.length
    return environment


@pytest.mark.parametrize('angle, speed_gain, runs_wide', [
    (60.0, None, False), (90.0, None, True), (90.0, 0.5, False)])
def test_the_race_car_does_not_brake_for_a_sharp_turn_it_has_not_reached(angle, speed_gain,
                                                                         runs_wide):
    # Down a long straight the car is as fast as the free distance ahead allows; a branch
    # leaving it at 90 degrees asks for a turn its speed no longer allows by the time it
    # steers (no anticipatory braking): it runs wide into the barrier. A 60 degree branch,
    # or the same turn at a slower speed policy, it takes cleanly.
    overrides = {} if speed_gain is None else {'speed_gain': speed_gain}
    controller = get_controller('race_controller').make(**overrides)
    metrics = run_episode(branch_track(angle), controller, EpisodeConfig(seed=0))
    if runs_wide:
        assert metrics.static_collisions > 0 and is_controller_failure(metrics), metrics
    else:
        assert metrics.outcome is Outcome.GOAL_REACHED and metrics.fault_collisions == 0, \
            metrics


def test_the_flyer_with_altitude_still_flies_into_an_agent_outside_its_view():
    """The paper's drone fault stays reachable now that the flyer takes off and cruises: on
    generated drone map 1000261 the flyer, at the agents' altitude, moves into an agent its
    60-degree view missed; with a full field of view it reaches the goal untouched. (Map
    1000061 showed it until the agent rules of 2026-11-28; 1000261 is the first map from
    1000000 on that shows it since: 1000041 and 1000172 end in a drive into an agent too,
    but one a full view does not avoid.)"""
    environment = EnvironmentSampler().sample([1000261], scenario='drone')[0]
    assert environment.feasible
    config = EpisodeConfig(seed=int(environment.seed))
    spec = get_controller('velocity_projection')
    narrow = run_episode(environment, spec.make(), config)
    assert narrow.robot_into_agent_collisions >= 1, narrow.contacts
    assert is_controller_failure(narrow)
    full_view = run_episode(environment, spec.make(field_of_view=2.0 * math.pi), config)
    assert full_view.outcome is Outcome.GOAL_REACHED and full_view.collisions == 0
