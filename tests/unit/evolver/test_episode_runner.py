"""In-process episodes: deterministic per seed, traces consistent with the metrics."""

from __future__ import annotations

import numpy as np
import pytest

from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.episode_runner import EpisodeRunner, EpisodeRunnerError
from sessgan_evolver.in_process import NOT_SIMULATED, InProcessEvaluator

pytestmark = pytest.mark.unit


@pytest.fixture(scope='module')
def factory():
    return make_environment(load_example_map('factory').cells, 'factory', 'example')


def test_same_seed_same_episode_and_the_trace_matches_the_metrics(factory):
    with EpisodeRunner('factory', time_limit=4.0) as runner:
        first = runner.run(factory, seed=3, trace=True)
        second = runner.run(factory, seed=3, trace=True, keep_scans=True)
        other = runner.run(factory, seed=4)
    ignore = {'wall_time'}
    assert {k: v for k, v in first.metrics.items() if k not in ignore} == \
        {k: v for k, v in second.metrics.items() if k not in ignore}
    assert other.trace is None
    trace = first.trace
    ticks = first.metrics['ticks']
    assert len(trace.times) == len(trace.poses) == len(trace.agents) == ticks + 1
    assert len(trace.commands) == ticks
    assert np.array_equal(trace.poses, second.trace.poses)
    assert trace.scans is None and second.trace.scans.shape == (ticks + 1, 360)
    assert len(trace.contacts) == first.metrics['collisions'] == len(first.metrics['contacts'])
    assert [c.to_dict() for c in trace.contacts] == first.metrics['contacts']
    assert trace.agents.shape[1] == 2  # the factory's two dummy agents
    assert trace.times[-1] == pytest.approx(first.metrics['simulation_time'])
    assert first.metrics['bag_path'] == '' and first.metrics['wall_time'] > 0


def test_the_runner_clock_times_the_run_and_the_parts_of_its_ticks(factory):
    # A clock that advances one second a reading: the parts of every tick take one reading
    # each, so each part's total is the tick count (benchmarks pass time.thread_time); the
    # reset is timed between two readings.
    readings = iter(range(1_000_000))
    with EpisodeRunner('factory', time_limit=1.0,
                       clock=lambda: float(next(readings))) as runner:
        run = runner.run(factory, seed=1)
        profile = runner.profile
    ticks = run.metrics['ticks']
    assert ticks == profile.ticks == 20
    assert profile.physics == profile.sensors == profile.metrics == profile.controller == ticks
    assert profile.reset == 1
    # Two readings for the reset, six a tick (controller two, step four), between the
    # runner's two.
    assert run.wall_time == 2 + 6 * ticks + 1


def test_bad_settings_are_named(factory):
    with pytest.raises(EpisodeRunnerError, match='unknown controller'):
        EpisodeRunner('factory', controller='no_such_controller')
    with pytest.raises(EpisodeRunnerError, match='time limit'):
        EpisodeRunner('factory', time_limit=-1.0)
    drone = make_environment(load_example_map('drone').cells, 'drone', 'drone')
    with EpisodeRunner('factory', time_limit=1.0) as runner, \
            pytest.raises(EpisodeRunnerError, match='drone map'):
        runner.run(drone, seed=0)


def test_maps_without_a_certified_route_are_not_simulated_when_asked(factory):
    walls = np.ones((32, 32), dtype=np.int64)
    invalid = make_environment(walls, 'factory', 'walls')
    assert not invalid.feasible
    seen = []
    with InProcessEvaluator('factory', time_limit=1.0, simulate_invalid=False,
                            observer=lambda env, seed, run, origin: seen.append(
                                (env.id, seed, run.metrics['outcome'], origin))) as evaluator:
        run = evaluator.run_environment(invalid, 7, 'test')
        assert run.metrics['outcome'] == 'invalid_environment'
        assert run.metrics['detail'] == NOT_SIMULATED and run.metrics['ticks'] == 0
        valid = evaluator.run_environment(factory, 7, 'test')
        assert valid.metrics['ticks'] > 0 and evaluator.episodes == 2
    assert seen == [('walls', 7, 'invalid_environment', 'test'),
                    ('example', 7, valid.metrics['outcome'], 'test')]


def test_the_controller_sees_what_its_node_decodes(factory):
    from sessgan_evolver.episode_runner import node_inputs
    from sessgan_sim.episode import Episode, EpisodeConfig

    with Episode() as episode:
        observation = episode.reset(factory, EpisodeConfig(seed=1))
    scan, state = node_inputs(observation)
    # LaserScan's float32 geometry, the yaw read back from the odometry quaternion.
    assert scan.angle_increment == float(np.float32(observation.lidar.angle_increment))
    assert scan.angle_increment != observation.lidar.angle_increment
    assert scan.range_max == float(np.float32(observation.lidar.range_max))
    assert np.array_equal(scan.ranges, observation.scan)
    assert state.yaw == pytest.approx(observation.pose.yaw, abs=1e-12)
    assert (state.x, state.y) == (observation.pose.x, observation.pose.y)


def test_a_controller_of_several_robots_gets_its_robot_and_the_map(factory):
    with EpisodeRunner('factory', controller='reference_navigator', time_limit=30.0) as runner:
        controller = runner.make_controller(factory)
        assert controller.config.robot == 'diff_drive'
        run = runner.run(factory, seed=0)
    # The reference navigator crosses the example map (the controllers' own tests say so).
    assert run.metrics['outcome'] == 'goal_reached' and run.metrics['fault_collisions'] == 0
    with pytest.raises(EpisodeRunnerError, match='does not drive'):
        EpisodeRunner('factory', controller='race_controller')


def test_as_in_a_campaign_the_controller_gets_the_map_and_its_robot(factory):
    # The node gets the map topic (the paper's controllers steer along a route on it), and a
    # campaign hosts the tricycle for the tricycle controller: in process the same.
    with EpisodeRunner('factory') as runner:
        # Seed 1: with seed 0 an agent holds the robot (test_controller_episodes says how).
        routed = runner.run(factory, seed=1)
    # Without the map, Nearness-Diagram is stuck in a dead end of this map.
    assert routed.metrics['outcome'] == 'goal_reached', routed.metrics['detail']
    with EpisodeRunner('factory', 'tricycle_nearness_diagram') as runner:
        assert runner.robot == 'tricycle' and runner.episode_config(0).robot == 'tricycle'
    with EpisodeRunner('racetrack', 'reference_navigator') as runner:
        assert runner.robot == 'car'


def test_in_process_episodes_get_the_time_limit_a_worker_gives():
    """Without a given limit, an in-process episode lasts as long as the same evaluate goal
    on a worker: the scenario's limit raised for a long route (it was the bare scenario
    limit in process, so a slow robot could time out on a long valid route only there)."""
    from sessgan_sim.episode import Episode
    from sessgan_sim.simulator_settings import SimulatorSettings

    corridor = np.ones((32, 32), dtype=np.int64)
    corridor[1:31, 1:5] = 0  # an L-shaped corridor 2 m wide and 30 m long: a route over
    corridor[27:31, 1:31] = 0  # 15 m needs more than 4 x 15 m / 1 m/s, the scenario's 60 s
    environment = make_environment(corridor, 'factory', 'long', seed=1)
    assert environment.feasible and environment.route_length > 15.0
    with EpisodeRunner('factory') as runner, Episode() as worker:
        in_process = runner.episode_config(0, environment).time_limit
        worker.reset(environment, SimulatorSettings().episode_config(seed=0))
        assert in_process == pytest.approx(worker.config.time_limit)
        assert in_process > 60.0
    with EpisodeRunner('factory', time_limit=5.0) as runner:
        assert runner.episode_config(0, environment).time_limit == 5.0
