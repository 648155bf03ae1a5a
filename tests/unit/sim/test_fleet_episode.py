"""Fleet episodes: several robots under test in one world (issue 13)."""

import math

import numpy as np
import pytest

from sessgan_core.environment import Environment, FleetRobot, Pose2D
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.errors import EpisodeError, InvalidConfigError
from sessgan_sim.metrics import ContactKind, Outcome, is_controller_failure
from sessgan_sim.robots import BodyCommand
from sessgan_sim.sensors import LidarConfig

pytestmark = pytest.mark.unit

VALUES = {'#': 100, '.': 0}
HALL = ['####################',
        '#..................#',
        '#..................#',
        '#..................#',
        '####################']
"""Interior x in [0.5, 9.5] m, y in [0.5, 2.0] m (0.5 m cells)."""
FORWARD = BodyCommand(0.5, 0.0, 0.0)
STAND = BodyCommand()


def hall(r0=((1.0, 1.25, 0.0), (9.0, 1.25)), r1=((9.0, 1.25, math.pi), (1.0, 1.25)),
         **fields) -> Environment:
    grid = np.array([[VALUES[char] for char in row] for row in reversed(HALL)], dtype=np.int8)
    (start, goal), (start1, goal1) = r0, r1
    return Environment('fleet', 'factory', grid, 0.5, Pose2D(*start), Pose2D(*goal),
                       fleet=(FleetRobot(Pose2D(*start1), Pose2D(*goal1)),), **fields)


def config(**overrides) -> EpisodeConfig:
    base = {'lidar': LidarConfig(noise_std=0.0), 'dummy_agents': 0, 'stuck_timeout': 0.0,
            'time_limit': 30.0}
    base.update(overrides)
    return EpisodeConfig(**base)


def run(episode: Episode, commands, limit: int = 2000):
    """Step a fixed command per robot until the episode ends (or ``limit`` ticks)."""
    for _ in range(limit):
        if episode.done:
            break
        episode.step_fleet(commands)
    return episode.metrics()


@pytest.fixture
def episode():
    with Episode() as running:
        yield running


def test_each_robot_sees_the_other_in_its_scan(episode):
    episode.reset(hall(), config())
    first, second = episode.observations()
    radius = episode.robot.footprint_radius
    ahead = len(first.scan) // 2  # beams run from -pi to pi: the middle one looks ahead
    # 8 m between centres; the other robot's circle is seen before the far wall.
    assert first.scan[ahead] == pytest.approx(8.0 - radius, abs=0.02)
    assert second.scan[ahead] == pytest.approx(8.0 - radius, abs=0.02)


def test_a_head_on_crash_is_the_fault_of_both(episode):
    episode.reset(hall(), config())
    metrics = run(episode, [FORWARD, FORWARD], limit=400)
    r0, r1 = episode.robot_metrics(0), episode.robot_metrics(1)
    assert [event.kind for event in r0.contacts][:1] == [ContactKind.ROBOT_INTO_ROBOT]
    assert [event.kind for event in r1.contacts][:1] == [ContactKind.ROBOT_INTO_ROBOT]
    assert r0.contacts[0].other_robot == 1 and r1.contacts[0].other_robot == 0
    assert metrics.robot_into_robot_collisions >= 2 and metrics.fault_collisions >= 2
    assert is_controller_failure(metrics)


def test_driving_into_a_standing_robot_is_only_the_movers_fault(episode):
    episode.reset(hall(r1=((5.0, 1.25, math.pi), (1.0, 1.25))), config())
    run(episode, [FORWARD, STAND], limit=400)
    r0, r1 = episode.robot_metrics(0), episode.robot_metrics(1)
    assert r0.contacts and {event.kind for event in r0.contacts} == {ContactKind.ROBOT_INTO_ROBOT}
    assert r1.contacts and {event.kind for event in r1.contacts} == {
        ContactKind.ROBOT_HIT_BY_ROBOT}
    assert r1.fault_collisions == 0 and r0.fault_collisions == len(r0.contacts)
    assert r0.min_clearance == 0.0 and r0.proximity_time > 0  # the other robot is an obstacle


def test_robots_passing_each_other_reach_their_goals_and_the_episode_ends(episode):
    lanes = hall(r0=((1.0, 0.9, 0.0), (9.0, 0.9)), r1=((9.0, 1.7, math.pi), (1.0, 1.7)))
    observations = episode.reset(lanes, config(time_limit=60.0)) and episode.observations()
    assert [observation.goal for observation in observations] == [Pose2D(9.0, 0.9),
                                                                  Pose2D(1.0, 1.7)]
    fast = BodyCommand(0.5, 0.0, 0.0)
    results = episode.step_fleet([fast, STAND])
    assert not results[0].done and results[0].outcome is None
    assert episode.driving() == [0, 1]
    for _ in range(400):  # r1 waits; r0 arrives and stands while r1 goes on
        if episode.robot_metrics(0).outcome is not None:
            break
        episode.step_fleet([fast, STAND])
    assert episode.robot_metrics(0).outcome is Outcome.GOAL_REACHED and not episode.done
    assert episode.driving() == [1]  # the tick loop waits for r1's commands alone
    run(episode, [fast, STAND], limit=20)  # r0 brakes to a stop, whatever it is sent
    parked = episode.robots[0].position
    metrics = run(episode, [fast, fast], limit=600)
    assert episode.robots[0].position == pytest.approx(parked, abs=0.01)
    assert metrics.outcome is Outcome.GOAL_REACHED and metrics.legs_completed == 2
    assert metrics.collisions == 0 and 'r0: goal_reached' in metrics.detail
    assert episode.driving() == []


def test_the_fleets_outcome_is_the_first_failing_robots(episode):
    episode.reset(hall(), config(time_limit=3.0))
    metrics = run(episode, [FORWARD, STAND])
    assert metrics.outcome is Outcome.TIMEOUT and metrics.failed_leg in (0, 1)
    assert 'r0: timeout' in metrics.detail and 'r1: timeout' in metrics.detail


def test_a_fleet_steps_with_a_command_per_robot(episode):
    episode.reset(hall(), config())
    with pytest.raises(EpisodeError, match='step_fleet'):
        episode.step(FORWARD)
    with pytest.raises(EpisodeError, match='2 robot'):
        episode.step_fleet([FORWARD])


def test_a_fleet_start_inside_a_wall_is_an_invalid_environment(episode):
    episode.reset(hall(r1=((9.6, 1.25, 0.0), (1.0, 1.25))), config())
    metrics = episode.metrics()
    assert episode.done and metrics.outcome is Outcome.INVALID_ENVIRONMENT
    assert 'robot r1' in metrics.detail


def test_a_fleet_needs_the_analytic_lidar(episode):
    with pytest.raises(InvalidConfigError, match='analytic'):
        episode.reset(hall(), config(lidar=LidarConfig(caster='pybullet')))


def test_the_same_seed_gives_the_same_fleet_episode(episode):
    results = []
    for _ in range(2):
        episode.reset(hall(), config(seed=5, lidar=LidarConfig(), dummy_agents=1))
        scans = []
        for _ in range(120):
            if episode.done:
                break
            observations = [result.observation for result in
                            episode.step_fleet([FORWARD, BodyCommand(0.3, 0.0, 0.2)])]
            scans.append(np.concatenate([observation.scan for observation in observations]))
        results.append((episode.metrics().to_dict(), np.array(scans)))
    assert results[0][0] == results[1][0]
    np.testing.assert_array_equal(results[0][1], results[1][1])


def test_a_fleet_where_a_robot_timed_out_does_not_read_goal_reached():
    """r0 reached its goal early after a fault collision, r1 timed out later: the episode's
    outcome is r1's timeout (it read goal_reached, from r0, though a robot never arrived)."""
    from types import SimpleNamespace

    def record(index, outcome, ticks, faults):
        return SimpleNamespace(index=index, outcome=outcome, ticks=ticks,
                               recorder=SimpleNamespace(fault_collisions=faults))

    fleet = object.__new__(Episode)
    fleet._records = [record(0, Outcome.GOAL_REACHED, 100, 1),
                      record(1, Outcome.TIMEOUT, 600, 0)]
    assert fleet._fleet_outcome() == (Outcome.TIMEOUT, 1)
    fleet._records[1] = record(1, Outcome.GOAL_REACHED, 300, 0)
    assert fleet._fleet_outcome() == (Outcome.GOAL_REACHED, 0)  # the fault collision's robot
    fleet._records[0] = record(0, Outcome.GOAL_REACHED, 100, 0)
    assert fleet._fleet_outcome() == (Outcome.GOAL_REACHED, -1)
