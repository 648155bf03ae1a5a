"""The reference navigator driving sessgan_sim's robots in-process, on the simulator core.

Each scenario's example map, and the first fresh maps of the shipped generator (seeds 700000
on; the navigator was tuned on seeds 800000-800199): the robot of the scenario reaches the
goal without a fault collision (on the example maps without touching a wall at all). On
generated maps one failure in four is allowed (the benchmark,
tests/benchmarks/bench_reference_navigator.py, measures the rate over 100 maps per
scenario; the target is 90 %). Factory seed 700002 is such a failure today: an agent drives
into the robot standing still and shoves it against a wall, which the episode counts as the
robot's static collision.
"""

from __future__ import annotations

import pytest

from sessgan_controllers.controller_interface import Goal, MapData, observed
from sessgan_controllers.reference_navigator import ReferenceNavigator
from sessgan_controllers.registry import get_controller
from sessgan_core.environment import Environment
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.metrics import EpisodeMetrics, Outcome

pytestmark = pytest.mark.unit

SCENARIOS = ('factory', 'racetrack', 'drone')
GENERATED_SEEDS = range(700000, 700004)


def navigator_for(scenario: str) -> ReferenceNavigator:
    navigator = get_controller('reference_navigator').make(robot=get_scenario(scenario).robot)
    assert isinstance(navigator, ReferenceNavigator)
    return navigator


def run_episode(environment: Environment, seed: int) -> EpisodeMetrics:
    """One lockstep episode with the map handed over first, as the node does."""
    navigator = navigator_for(environment.scenario)
    navigator.set_map(MapData.of(environment))
    goal = Goal(environment.goal.x, environment.goal.y)
    with Episode() as episode:
        observation = episode.reset(environment, EpisodeConfig(seed=seed))
        done = episode.done
        while not done:
            command = navigator.compute_command(*observed(observation), goal)
            assert command.is_finite()
            observation, done, _ = episode.step(command.values())
        return episode.metrics()


@pytest.mark.parametrize('scenario', SCENARIOS)
def test_reference_navigator_reaches_the_example_goal(scenario):
    environment = make_environment(load_example_map(scenario).cells, scenario,
                                   f'{scenario}-example')
    assert environment.feasible
    metrics = run_episode(environment, seed=0)
    assert metrics.outcome is Outcome.GOAL_REACHED, metrics.detail
    assert metrics.fault_collisions == 0, metrics.detail
    assert metrics.static_collisions == 0


@pytest.mark.parametrize('scenario', SCENARIOS)
def test_reference_navigator_crosses_fresh_generated_maps(scenario):
    from sessgan_gen.environment_sampler import EnvironmentSampler

    environments = EnvironmentSampler().sample(list(GENERATED_SEEDS), scenario=scenario)
    valid = [environment for environment in environments if environment.feasible]
    assert valid, 'the shipped generator gave no valid map'
    results = {environment.seed: run_episode(environment, environment.seed)
               for environment in valid}
    successes = [seed for seed, metrics in results.items()
                 if metrics.outcome is Outcome.GOAL_REACHED and metrics.fault_collisions == 0]
    failures = {seed: (m.outcome, m.fault_collisions, m.detail) for seed, m in results.items()
                if seed not in successes}
    assert 4 * len(successes) >= 3 * len(valid), failures
