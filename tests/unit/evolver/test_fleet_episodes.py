"""Fleet episodes in process: a controller per robot, per-robot metrics, and a trace bag
with every robot's topics (issue 13)."""

import pytest

from sessgan_core.fleet import FleetSpec
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.bag_export import write_trace_bag
from sessgan_evolver.bag_reading import read_bag_topics
from sessgan_evolver.episode_runner import EpisodeRunner
from sessgan_evolver.fault_picture import scene_from_bag

pytestmark = pytest.mark.unit


@pytest.fixture(scope='module')
def fleet():
    environment = make_environment(load_example_map('factory').cells, 'factory',
                                   'factory-fleet', seed=3, fleet=FleetSpec(2))
    assert environment.feasible and environment.robots == 2
    return environment


def test_each_robot_of_a_fleet_reaches_its_goal_with_its_own_controller(fleet):
    with EpisodeRunner('factory', 'reference_navigator') as runner:
        run = runner.run(fleet, seed=1, trace=True)
    metrics = run.metrics
    assert metrics['outcome'] == 'goal_reached', metrics['detail']
    assert (metrics['legs'], metrics['legs_completed'], metrics['failed_leg']) == (2, 2, -1)
    assert metrics['fault_collisions'] == 0, metrics['detail']
    other = run.trace.fleet[0]
    goal = fleet.fleet[0].goal
    # r1 drove its own route: from its start to within the goal tolerance of its goal.
    assert tuple(other.poses[0, :2]) == pytest.approx((fleet.fleet[0].start.x,
                                                       fleet.fleet[0].start.y), abs=1e-3)
    assert ((other.poses[-1, 0] - goal.x) ** 2 + (other.poses[-1, 1] - goal.y) ** 2) ** 0.5 \
        <= 0.5 + 1e-6
    assert len(run.trace.summary()['fleet']) == 1


def test_a_fleet_trace_bag_holds_every_robots_topics(fleet, tmp_path):
    with EpisodeRunner('factory', 'reference_navigator', time_limit=2.0) as runner:
        run = runner.run(fleet, seed=1, trace=True, keep_scans=True)
    assert run.metrics['outcome'] == 'timeout' and run.metrics['ticks'] == 40
    bag = write_trace_bag(tmp_path / 'bag', fleet, run.trace, {'controller': 'nav'})
    counts = {topic.topic: topic.message_count for topic in read_bag_topics(bag)}
    for robot in ('/r0', '/r1'):
        assert counts[f'{robot}/scan'] == counts[f'{robot}/odom'] == 41, counts
        assert counts[f'{robot}/cmd_vel'] == 40 and counts[f'{robot}/goal_pose'] == 1
    assert '/scan' not in counts
    # The fault picture draws each robot's own path from its own odom.
    scene = scene_from_bag(bag)
    assert tuple(scene.trajectory[0]) == pytest.approx((fleet.start.x, fleet.start.y), abs=1e-3)
    start = fleet.fleet[0].start
    assert len(scene.fleet[0].trajectory) == 41
    assert tuple(scene.fleet[0].trajectory[0]) == pytest.approx((start.x, start.y), abs=1e-3)
