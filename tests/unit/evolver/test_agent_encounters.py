"""The screen's agent-encounter forecast: where the robot and the dummy agents meet, the
robot's way, its learnt speed, and the simulator seed the screened search picks by it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import tokens_to_occupancy
from sessgan_evolver.screened_search import (
    SPEED_PRIOR,
    SPEED_SAMPLES,
    RobotSpeed,
    ScreenedConfig,
    ScreenedSearch,
)
from sessgan_evolver.screening import (
    certify_route,
    closest_encounter,
    reactive_path,
)
from sessgan_evolver.search_methods import SearchMethodError
from sessgan_sim.agents import PatrolPath
from sessgan_sim.episode import PatrolPlanner

pytestmark = pytest.mark.unit

SMALL = ScreenedConfig(batch=3, reference_maps=4)


def test_a_robot_and_an_agent_crossing_at_the_same_moment_meet():
    way = np.array([[0.0, 0.0], [10.0, 0.0]])
    on_time = PatrolPath(np.array([[5.0, -5.0], [5.0, 5.0]]))
    assert closest_encounter(way, [on_time], 1.0, 1.0) == pytest.approx(0.0, abs=0.05)
    # Two metres late: the closest moment is at t = 6 s, (6, 0) against (5, -1).
    late = PatrolPath(np.array([[5.0, -7.0], [5.0, 7.0]]))
    assert closest_encounter(way, [late], 1.0, 1.0) == pytest.approx(math.sqrt(2), abs=0.05)
    # The nearest agent counts; a slower robot meets the late one.
    assert closest_encounter(way, [late, on_time], 1.0, 1.0) == pytest.approx(0.0, abs=0.05)
    assert closest_encounter(way, [late], 5.0 / 7.0, 1.0) == pytest.approx(0.0, abs=0.05)


def test_no_agents_no_encounter_and_bad_speeds_are_refused():
    way = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert closest_encounter(way, [], 1.0, 0.5) == math.inf
    with pytest.raises(SearchMethodError, match='robot speed must be positive'):
        closest_encounter(way, [PatrolPath(np.array([[1.0, 1.0]]))], 0.0, 0.5)


def test_the_reactive_path_takes_a_gap_the_certified_route_goes_around():
    # A lane of 0.45 m beside the route: a 1 m gap (0.44 m of clearance on the certificate
    # grid) is too narrow for the route but wide for the robot's 0.2 m radius.
    spec = dataclasses.replace(get_scenario('factory'), route_margin=0.25)
    occupancy = np.zeros((32, 32), dtype=np.int8)
    occupancy[[0, -1], :] = occupancy[:, [0, -1]] = 100
    occupancy[16, :] = 100  # a wall across the hall
    occupancy[16, 8:10] = 0  # the 1 m gap
    occupancy[16, 24:31] = 0  # a wide opening far to the east
    start, goal = (4.25, 4.25, 0.0), (4.25, 12.25, 0.0)
    candidate = certify_route(occupancy, spec, start, goal)
    assert candidate.feasible
    route = np.asarray(candidate.placement.certificate.points)
    assert route[:, 0].max() > 11.0  # the certified route goes round through the east
    way = reactive_path(candidate, spec)
    length = np.hypot(*np.diff(way, axis=0).T).sum()
    assert way[:, 0].max() < 5.5 and length < 10.0
    np.testing.assert_allclose(way[0], route[0], atol=0.2)
    np.testing.assert_allclose(way[-1], route[-1], atol=0.2)


def test_the_robot_speed_is_the_prior_until_the_run_has_measured_it():
    speed = RobotSpeed(prior=0.7)
    for _ in range(SPEED_SAMPLES - 1):
        speed.add({'outcome': 'goal_reached', 'distance_travelled': 10.0,
                   'simulation_time': 20.0})
    speed.add({'outcome': 'stuck', 'distance_travelled': 1.0, 'simulation_time': 20.0})
    assert speed.value == 0.7
    speed.add({'outcome': 'goal_reached', 'distance_travelled': 12.0,
               'simulation_time': 12.0})
    assert speed.value == pytest.approx((0.5 * (SPEED_SAMPLES - 1) + 1.0) / SPEED_SAMPLES)


def test_the_search_runs_the_seed_whose_agents_come_closest():
    search = ScreenedSearch('factory', 3, config=ScreenedConfig(
        batch=3, reference_maps=4, agent_seeds=5))
    assert search.robot_speed.prior == pytest.approx(SPEED_PRIOR * 1.0)  # diff_drive's top
    proposals = search.ask()
    assert [p.sim_seed for p in proposals] == [t.sim_seed for t in search._pending]
    test = search._pending[0]
    certified = certify_route(tokens_to_occupancy(test.cells, search.spec), search.spec,
                              *_route(test.environment))
    way = reactive_path(certified, search.spec)
    planner = PatrolPlanner(test.environment, search.episode_config)
    seeds = [11, 22, 33, 44, 55]
    forecasts = [closest_encounter(way, planner.patrols(seed), search.robot_speed.value, 0.5)
                 for seed in seeds]
    assert len(set(forecasts)) > 1  # the seeds' agents walk elsewhere
    test.sim_seed = seeds[0]  # its own, tried first; the search draws the others
    search._seed = iter(seeds[1:]).__next__
    search._draw_sim_seeds(test)
    assert test.seed_options == seeds
    search.pick_sim_seed(test, certified)
    assert test.sim_seed == seeds[int(np.argmin(forecasts))]
    assert test.encounter == min(forecasts)


def test_without_agents_or_with_one_seed_the_drawn_seed_runs():
    race = ScreenedSearch('racetrack', 0, config=ScreenedConfig(batch=1, reference_maps=2))
    race.ask()
    assert race._pending[0].encounter == math.inf
    one = ScreenedSearch('factory', 3, config=ScreenedConfig(batch=2, reference_maps=4,
                                                           agent_seeds=1))
    drawn: list[int] = []
    draw = one._seed

    def recorded() -> int:
        drawn.append(draw())
        return drawn[-1]

    one._seed = recorded
    one.ask()
    assert all(test.sim_seed in drawn for test in one._pending)
    assert all(math.isfinite(test.encounter) for test in one._pending)


def test_the_tricycle_controller_s_search_forecasts_for_the_tricycle():
    search = ScreenedSearch('factory', 0, config=SMALL, controller='tricycle_nearness_diagram')
    assert search.episode_config.robot == 'tricycle'
    assert ScreenedSearch('factory', 0, config=SMALL, controller='my_nav2_stack'
                          ).episode_config.robot == 'diff_drive'


def _route(environment):
    start, goal = environment.start, environment.goal
    return (start.x, start.y, start.yaw), (goal.x, goal.y, goal.yaw)


def test_picking_only_candidates_that_could_win_chooses_as_picking_all_would():
    # A trained surrogate in which a close encounter matters: the pick moves the scores.
    search = ScreenedSearch('factory', 5, config=ScreenedConfig(
        batch=4, reference_maps=4, fresh_candidates=6, agent_seeds=6))
    rng = np.random.default_rng(0)
    width = len(search._row(_any_test(search)))
    for _ in range(40):
        row = rng.normal(size=width)
        row[-2] = rng.uniform(0.0, 10.0)
        search.surrogate.add(row, bool(row[-2] < 3.0))
    search.surrogate.fit()
    search.told = search.config.surrogate_warmup
    lazy = search._best
    compared = 0

    def checked(candidates):
        nonlocal compared
        twins = [(dataclasses.replace(test, seed_options=list(test.seed_options)), certified)
                 for test, certified in candidates]
        for test, certified in twins:
            search.pick_sim_seed(test, certified)
        scores = [search._score(test, search._novelty(certified))
                  for test, certified in twins]
        chosen = lazy(candidates)
        best = twins[int(np.argmax(scores))][0]
        assert (chosen.sim_seed, chosen.map_seed) == (best.sim_seed, best.map_seed)
        compared += len(candidates) > 1
        return chosen

    search._best = checked
    search.ask()
    assert compared


def _any_test(search: ScreenedSearch):
    """A fresh test of ``search`` with its features (for the surrogate's row width)."""
    search.ask()
    return search._pending[0]
