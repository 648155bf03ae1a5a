"""The built-in controllers driving sessgan_sim's robots in-process, with their defaults.

Realistic defaults: each controller reaches the goal of its scenario's example map.
The Nearness-Diagram robot collides in a narrow dog-leg (the paper's narrow-space
fault): a circular diff-drive robot that can only turn on the spot when the
motion direction is 90 degrees off keeps rolling while it turns and hits the
corners of a one-cell zig-zag.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('pybullet')

from sessgan_controllers.registry import get_controller  # noqa: E402
from sessgan_controllers.types import Controller, Goal, observed  # noqa: E402
from sessgan_gen.environment import Environment  # noqa: E402
from sessgan_gen.navigation import make_environment  # noqa: E402
from sessgan_gen.scenarios import get_scenario  # noqa: E402
from sessgan_gen.token_map import load_example_map, read_token_map  # noqa: E402
from sessgan_sim.episode import Episode, EpisodeConfig  # noqa: E402
from sessgan_sim.metrics import EpisodeMetrics, Outcome  # noqa: E402

pytestmark = pytest.mark.unit

NARROW_DOG_LEG = Path(__file__).parents[2] / 'data' / 'narrow_dog_leg.txt'


def run_episode(environment: Environment, controller: Controller,
                config: EpisodeConfig) -> EpisodeMetrics:
    """One lockstep episode: a command per observation until the episode ends."""
    goal = Goal(environment.goal.x, environment.goal.y)
    with Episode() as episode:
        observation = episode.reset(environment, config)
        done = episode.done
        while not done:
            scan, state = observed(observation)
            command = controller.compute_command(scan, state, goal)
            observation, done, _ = episode.step((command.vx, command.vy, command.wz))
        return episode.metrics()


@pytest.mark.parametrize('scenario_name', ['factory', 'racetrack', 'drone'])
def test_default_controller_reaches_the_example_goal(scenario_name):
    scenario = get_scenario(scenario_name)
    spec = get_controller(scenario.controller)
    assert spec.robot == scenario.robot
    environment = make_environment(
        load_example_map(scenario_name).cells, scenario_name, f'{scenario_name}-example')
    assert environment.feasible
    metrics = run_episode(environment, spec.make(), EpisodeConfig(seed=0))
    assert metrics.outcome is Outcome.GOAL_REACHED, metrics.detail
    assert metrics.simulation_time < scenario.time_limit


def test_nearness_diagram_collides_in_a_narrow_dog_leg():
    token_map = read_token_map(NARROW_DOG_LEG, 'factory')
    environment = make_environment(token_map.cells, 'factory', 'narrow-dog-leg')
    assert environment.feasible  # a path exists for the footprint: failures are faults
    controller = get_controller('nearness_diagram').make()
    metrics = run_episode(environment, controller, EpisodeConfig(seed=0, dummy_agents=0))
    assert metrics.collisions > 0, metrics
    assert metrics.risk_score > 0.0
    assert metrics.outcome is not Outcome.GOAL_REACHED
