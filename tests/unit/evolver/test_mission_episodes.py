"""Mission episodes with the reference navigator in process: per-leg metrics, the failed leg,
and the trace bag's goals."""

import pytest

from sessgan_core.missions import MissionSpec
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.bag_export import write_trace_bag
from sessgan_evolver.bag_reading import iter_bag_messages, read_bag_topics
from sessgan_evolver.episode_runner import EpisodeRunner
from sessgan_evolver.fault_picture import scene_from_bag, scene_from_run, write_scene_png
from sessgan_sim.bag_recording import jazzy_typestore

pytestmark = pytest.mark.unit

DWELL = 2.0


@pytest.fixture(scope='module')
def runner():
    with EpisodeRunner('factory', 'reference_navigator') as runner:
        yield runner


@pytest.fixture(scope='module')
def mission():
    return make_environment(load_example_map('factory').cells, 'factory', 'factory-mission',
                            seed=0, mission=MissionSpec(1, DWELL))


def test_a_completed_mission_has_every_leg(runner, mission):
    run = runner.run(mission, seed=1, trace=True)
    metrics = run.metrics
    assert metrics['outcome'] == 'goal_reached', metrics['detail']
    assert metrics['detail'].startswith('completed the mission: reached home, the last of 2')
    assert (metrics['legs'], metrics['legs_completed'], metrics['failed_leg']) == (2, 2, -1)
    first, second = metrics['leg_times']
    # The goal changed once: when the robot had stood at the station for the dwell time.
    rows = [row for row, *_ in run.trace.goals]
    assert len(rows) == 2 and rows[0] == 0
    assert run.trace.goals[0][1:3] == (mission.stations[0].x, mission.stations[0].y)
    assert run.trace.goals[1][1:3] == (mission.goal.x, mission.goal.y)
    sent = run.trace.times[rows[1]]
    assert sent >= first + DWELL - 1e-6
    assert sent + second == pytest.approx(metrics['simulation_time'])
    # Standing at the station for the whole dwell.
    before = (run.trace.times > sent - DWELL + 1e-6) & (run.trace.times <= sent)
    assert abs(run.trace.twists[before, 0]).max() <= 0.05


def test_a_mission_that_runs_out_of_time_names_the_leg(runner, mission, tmp_path):
    plain = make_environment(load_example_map('factory').cells, 'factory', 'factory-plain',
                             seed=0)
    first_leg = runner.run(plain, seed=1).metrics
    assert first_leg['outcome'] == 'goal_reached'
    limited = EpisodeRunner('factory', 'reference_navigator',
                            time_limit=first_leg['simulation_time'] + DWELL + 4.0)
    with limited:
        run = limited.run(mission, seed=1, trace=True, keep_scans=True)
    metrics = run.metrics
    assert metrics['outcome'] == 'timeout'
    assert (metrics['legs'], metrics['legs_completed'], metrics['failed_leg']) == (2, 1, 1)
    (first,) = metrics['leg_times']
    assert 0 < first < metrics['simulation_time'] - DWELL
    assert metrics['detail'].endswith('failed on leg 2 of 2 (home)')

    bag = write_trace_bag(tmp_path / 'bag', mission, run.trace, {
        'controller': 'nav', 'metrics': {k: v for k, v in metrics.items() if k != 'bag_path'}})
    counts = {topic.topic: topic.message_count for topic in read_bag_topics(bag)}
    assert counts['/goal_pose'] == 2 and counts['/waypoints'] == 1
    store = jazzy_typestore()
    path = store.deserialize_cdr(next(iter_bag_messages(bag, ['/waypoints'])).data,
                                 'nav_msgs/msg/Path')
    assert [(p.pose.position.x, p.pose.position.y) for p in path.poses] == \
        [(mission.stations[0].x, mission.stations[0].y), (mission.goal.x, mission.goal.y)]

    # The fault picture shows the stations and the route through every leg, from the run and
    # from the bag alike.
    for scene in (scene_from_run(mission, run.trace, metrics), scene_from_bag(bag)):
        assert scene.stations == [(mission.stations[0].x, mission.stations[0].y)]
        station_cell = mission.cell_of(*scene.stations[0])
        assert any(mission.cell_of(*corner) == station_cell for corner in scene.route)
        assert tuple(scene.route[-1]) == pytest.approx((mission.goal.x, mission.goal.y))
    assert write_scene_png(scene, tmp_path / 'fault.png').stat().st_size > 0


def test_campaigns_ask_for_missions_through_one_validated_spec():
    from sessgan_evolver.campaign import CampaignConfig
    from sessgan_evolver.errors import CampaignError
    from sessgan_evolver.in_process import InProcessEvaluator

    with pytest.raises(CampaignError, match='mission_stations'):
        CampaignConfig(mission_stations=-1).validate()
    with pytest.raises(CampaignError, match='station_dwell_time'):
        CampaignConfig(mission_stations=1, station_dwell_time=-2.0).validate()
    config = CampaignConfig(mission_stations=2, station_dwell_time=1.0)
    config.validate()
    # Every leg and dwell gets a plain episode's wall time.
    plain = CampaignConfig().episode_timeout_for(1024)
    assert config.episode_timeout_for(1024) > 2.5 * plain
    with InProcessEvaluator('factory', mission=config.mission()) as evaluator:
        environments = evaluator.sample(b'', [11, 12], generation=0, member=0)
    assert all(len(e.stations) == 2 and e.dwell_time == 1.0 for e in environments
               if e.feasible)
    assert any(e.feasible for e in environments)


def test_compare_refuses_a_bad_mission_and_passes_a_good_one_to_its_campaigns():
    from sessgan_evolver.comparison import CompareConfig
    from sessgan_evolver.errors import CompareError

    with pytest.raises(CompareError, match='mission_stations'):
        CompareConfig(mission_stations=99).validate()
    config = CompareConfig(mission_stations=1, station_dwell_time=0.5)
    config.validate()
    campaign = config.campaign_config(seed=3)
    assert (campaign.mission_stations, campaign.station_dwell_time) == (1, 0.5)
