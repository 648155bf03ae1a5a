"""Following a mission's waypoints: reach, dwell standing still, next goal; per-leg records
and the leg an episode failed on."""

import pytest

from sessgan_core.environment import Pose2D
from sessgan_sim.errors import EpisodeError
from sessgan_sim.metrics import STANDING_SPEED, Outcome
from sessgan_sim.mission import MissionEvent, MissionTracker, failed_leg

pytestmark = pytest.mark.unit

STATION, PLACE, HOME = Pose2D(5.0, 1.0, 0.0), Pose2D(5.0, 6.0, 1.0), Pose2D(1.0, 1.0, 3.0)
PERIOD = 0.05


def run_ticks(tracker, start, ticks, reached=False, distance=0.0, speed=0.0):
    """``ticks`` ticks from sim time ``start``; the events and the end time."""
    events = []
    now = start
    for _ in range(ticks):
        now = round(now + PERIOD, 9)
        events.append(tracker.update(now, reached, distance, speed, PERIOD))
    return events, now


def test_one_waypoint_is_the_plain_episode():
    tracker = MissionTracker([HOME], dwell_time=2.0, tolerance=0.5)
    assert tracker.goal == HOME and tracker.legs == 1
    assert tracker.update(1.0, False, 3.0, 0.5, PERIOD) is MissionEvent.NONE
    assert tracker.update(3.5, True, 0.4, 0.5, PERIOD) is MissionEvent.COMPLETE
    assert tracker.complete and tracker.legs_completed == 1
    assert tracker.leg_times == (3.5,)
    assert tracker.update(3.55, True, 0.4, 0.0, PERIOD) is MissionEvent.NONE


def test_the_next_goal_goes_out_after_standing_still_for_the_dwell_time():
    tracker = MissionTracker([STATION, PLACE, HOME], dwell_time=1.0, tolerance=0.5)
    assert tracker.update(4.0, True, 0.45, 0.3, PERIOD) is MissionEvent.ARRIVED
    assert tracker.dwelling and tracker.goal == STATION  # the station stays the goal
    # Reached, not done: a failure before the dwell ends fails this leg.
    assert tracker.legs_completed == 0 and tracker.leg_times == (4.0,)
    # Still rolling inside the tolerance: the dwell has not begun.
    events, now = run_ticks(tracker, 4.0, 40, distance=0.3, speed=STANDING_SPEED * 2)
    assert set(events) == {MissionEvent.NONE}
    # Standing: 19 ticks are not enough, the 20th (1.0 s) sends the next goal.
    events, now = run_ticks(tracker, now, 19, distance=0.3)
    assert set(events) == {MissionEvent.NONE}
    events, now = run_ticks(tracker, now, 1, distance=0.3)
    assert events == [MissionEvent.NEXT_LEG]
    assert tracker.goal == PLACE and tracker.leg == 1 and not tracker.dwelling
    assert tracker.records[0].departed == now and tracker.records[1].started == now
    assert tracker.legs_completed == 1 and tracker.leg_times == (4.0,)


def test_leaving_the_station_restarts_the_dwell():
    tracker = MissionTracker([STATION, HOME], dwell_time=1.0, tolerance=0.5)
    tracker.update(2.0, True, 0.4, 0.0, PERIOD)
    _, now = run_ticks(tracker, 2.0, 15, distance=0.3)
    _, now = run_ticks(tracker, now, 1, distance=0.8)  # pushed out of the tolerance
    events, now = run_ticks(tracker, now, 19, distance=0.3)
    assert set(events) == {MissionEvent.NONE}
    events, _ = run_ticks(tracker, now, 1, distance=0.3)
    assert events == [MissionEvent.NEXT_LEG]


def test_no_dwell_sends_the_next_goal_on_arrival():
    tracker = MissionTracker([STATION, HOME], dwell_time=0.0, tolerance=0.5)
    assert tracker.update(2.0, True, 0.4, 0.4, PERIOD) is MissionEvent.NEXT_LEG
    assert tracker.goal == HOME
    assert tracker.update(5.0, True, 0.4, 0.4, PERIOD) is MissionEvent.COMPLETE
    assert tracker.leg_times == (2.0, 3.0)


def test_leg_at_describe_and_failed_leg():
    tracker = MissionTracker([STATION, PLACE, HOME], dwell_time=1.0, tolerance=0.5)
    tracker.update(4.0, True, 0.3, 0.0, PERIOD)
    _, now = run_ticks(tracker, 4.0, 20, distance=0.3)  # leg 2 starts at 5.0 s
    assert tracker.leg == 1 and now == pytest.approx(5.0)
    assert tracker.leg_at(3.0) == 0 and tracker.leg_at(4.5) == 0  # the dwell: leg 1's
    assert tracker.leg_at(5.0) == 1 and tracker.leg_at(9.0) == 1
    assert tracker.describe_leg(1) == 'leg 2 of 3 (to station 2)'
    assert tracker.describe_leg(2) == 'leg 3 of 3 (home)'
    # The first fault collision names the leg, whatever the outcome.
    assert failed_leg(tracker, Outcome.GOAL_REACHED, [6.0, 2.0]) == 0
    assert failed_leg(tracker, Outcome.TIMEOUT, [7.5]) == 1
    # Without one, the leg in progress when the goal was not reached.
    for outcome in (Outcome.TIMEOUT, Outcome.STUCK, Outcome.COLLISION_LIMIT,
                    Outcome.CONTROLLER_UNRESPONSIVE):
        assert failed_leg(tracker, outcome, []) == 1
    for outcome in (Outcome.GOAL_REACHED, Outcome.CANCELLED, Outcome.INVALID_ENVIRONMENT, None):
        assert failed_leg(tracker, outcome, []) == -1


def test_a_mission_needs_a_waypoint_and_a_sane_dwell():
    with pytest.raises(EpisodeError):
        MissionTracker([], dwell_time=1.0, tolerance=0.5)
    with pytest.raises(EpisodeError):
        MissionTracker([HOME], dwell_time=-1.0, tolerance=0.5)


def test_a_mission_gets_the_scenario_time_limit_per_leg_and_its_dwells():
    from sessgan_core.missions import MissionSpec
    from sessgan_core.scenarios import get_scenario
    from sessgan_core.token_map import load_example_map
    from sessgan_core.valid_tests import make_environment
    from sessgan_sim.episode import ROUTE_TIME_FACTOR, Episode, EpisodeConfig

    cells = load_example_map('factory').cells
    plain = make_environment(cells, 'factory', 'plain', seed=2)
    mission = make_environment(cells, 'factory', 'mission', seed=2,
                               mission=MissionSpec(2, 3.0))
    scenario_limit = get_scenario('factory').time_limit
    with Episode() as episode:
        episode.reset(plain, EpisodeConfig(dummy_agents=0))
        top_speed = episode.robot.top_speed
        assert episode.config.time_limit == pytest.approx(max(
            scenario_limit, ROUTE_TIME_FACTOR * plain.route_length / top_speed))
        # The rule lives in the config: the episode applies it.
        assert EpisodeConfig().time_limit_for(plain, top_speed) == episode.config.time_limit
        assert EpisodeConfig(time_limit=7.0).time_limit_for(plain, top_speed) == 7.0
        episode.reset(mission, EpisodeConfig(dummy_agents=0))
        assert episode.config.time_limit == pytest.approx(max(
            3 * scenario_limit + 2 * 3.0,
            ROUTE_TIME_FACTOR * mission.route_length / top_speed + 2 * 3.0))
        observation = episode.reset(mission, EpisodeConfig(dummy_agents=0, time_limit=50.0))
        assert episode.config.time_limit == 50.0  # a given limit is the whole mission's
        assert observation.goal == mission.stations[0]
        assert episode.metrics().legs == 3 and episode.metrics().failed_leg == -1
