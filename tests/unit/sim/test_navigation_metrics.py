"""Standard navigation metrics against hand-computed trajectories, and on a real episode."""

from __future__ import annotations

import math

import pytest

from sessgan_sim.metrics import (
    ContactKind,
    EpisodeMetrics,
    MetricsRecorder,
    NavigationAccumulator,
    Outcome,
    fleet_metrics,
)

pytestmark = pytest.mark.unit


def test_integrated_jerk_and_mean_clearance_of_a_hand_computed_trajectory():
    # period 0.1 s; body-frame velocities at the end of each tick, from rest:
    #   (1, 0, 0) (1, 0, 0) (0, 0, 0.5) (0, 0, 0.5)
    # accelerations (dv / 0.1): (10, 0, 0) (0, 0, 0) (-10, 0, 5) (0, 0, 0)
    # |delta a|: linear 10 + 10 + 10 = 30 m/s^2; angular 0 + 5 + 5 = 10 rad/s^2.
    navigation = NavigationAccumulator()
    for clearance, velocity in ((1.0, (1, 0, 0)), (0.5, (1, 0, 0)), (0.0, (0, 0, 0.5)),
                                (1.5, (0, 0, 0.5))):
        navigation.add(0.1, clearance, *velocity)
    assert navigation.linear_jerk == pytest.approx(30.0)
    assert navigation.angular_jerk == pytest.approx(10.0)
    assert navigation.mean_clearance == pytest.approx(0.75)


def test_linear_jerk_is_the_magnitude_of_the_acceleration_vector_change():
    # (0.3, 0.4) then a stop, period 0.1: a = (3, 4) then (-3, -4): |delta a| = 10.
    navigation = NavigationAccumulator()
    navigation.add(0.1, 1.0, 0.3, 0.4, 0.0)
    navigation.add(0.1, 1.0, 0.0, 0.0, 0.0)
    assert navigation.linear_jerk == pytest.approx(10.0) and navigation.angular_jerk == 0.0


def test_a_constant_velocity_after_the_start_adds_no_jerk():
    navigation = NavigationAccumulator()
    for _ in range(20):
        navigation.add(0.05, 2.0, 0.5, 0.0, 0.2)
    # Only the start from rest: a jumps to (10, 0, 4) and back to 0 once.
    assert navigation.linear_jerk == pytest.approx(10.0)
    assert navigation.angular_jerk == pytest.approx(4.0)
    assert NavigationAccumulator().mean_clearance != NavigationAccumulator().mean_clearance


def snapshot(outcome: Outcome, fault: bool = False, route_length: float = 4.0
             ) -> EpisodeMetrics:
    recorder = MetricsRecorder(clearance_range=5.0)
    recorder.record_motion(6.0)
    if fault:
        recorder.record_contact(1.0, -1, ContactKind.STATIC, 0.0, 0.0)
    for _ in range(30):
        recorder.record_tick(0.1, 1.0, False, 0.5)
        recorder.navigation.add(0.1, 1.0, 0.0, 0.0, 0.0)
    return recorder.snapshot(3.0, True, 0.1, outcome, '', route_length=route_length)


def test_snapshot_success_time_to_goal_path_ratio_and_mean_speed():
    reached = snapshot(Outcome.GOAL_REACHED)
    assert reached.success and reached.time_to_goal == 3.0
    assert reached.path_length_ratio == pytest.approx(6.0 / 4.0)
    assert reached.mean_speed == pytest.approx(2.0) and reached.mean_clearance == 1.0
    # Reached, but with a fault collision on the way: no success; the time is still known.
    bumped = snapshot(Outcome.GOAL_REACHED, fault=True)
    assert not bumped.success and bumped.time_to_goal == 3.0
    late = snapshot(Outcome.TIMEOUT, route_length=0.0)
    assert not late.success and math.isnan(late.time_to_goal)
    assert math.isnan(late.path_length_ratio)
    data = late.to_dict()
    assert data['time_to_goal'] is None and data['path_length_ratio'] is None
    assert data['success'] is False and data['mean_speed'] == pytest.approx(2.0)


def test_a_fleet_succeeds_when_every_robot_does():
    one, two = snapshot(Outcome.GOAL_REACHED), snapshot(Outcome.TIMEOUT)
    both = fleet_metrics([one, one], Outcome.GOAL_REACHED, '')
    assert both.success and both.time_to_goal == 3.0 and both.mean_clearance == 1.0
    mixed = fleet_metrics([one, two], Outcome.TIMEOUT, '')
    assert not mixed.success and math.isnan(mixed.time_to_goal)


def test_a_real_episode_has_consistent_navigation_metrics():
    from sessgan_core.token_map import load_example_map
    from sessgan_core.valid_tests import make_environment
    from sessgan_evolver.in_process import InProcessEvaluator

    environment = make_environment(load_example_map('factory').cells, 'factory', 'example')
    with InProcessEvaluator('factory', 'reference_navigator') as evaluator:
        metrics = evaluator.run_environment(environment, 1).metrics
    assert metrics['outcome'] == 'goal_reached' and metrics['success'] is True
    assert metrics['time_to_goal'] == metrics['simulation_time']
    assert metrics['path_length_ratio'] == pytest.approx(
        metrics['distance_travelled'] / environment.route_length)
    assert metrics['path_length_ratio'] >= 0.9  # no shorter than the route, give or take
    assert metrics['mean_speed'] == pytest.approx(
        metrics['distance_travelled'] / metrics['simulation_time'])
    assert metrics['mean_clearance'] >= metrics['min_clearance'] > 0
    assert metrics['linear_jerk'] > 0 and metrics['angular_jerk'] > 0


def test_navigation_columns_name_the_path_length_after_distance_travelled():
    from sessgan_sim.metrics import NAVIGATION_COLUMNS, navigation_columns

    data = snapshot(Outcome.GOAL_REACHED).to_dict()
    row = navigation_columns(data)
    assert tuple(row) == NAVIGATION_COLUMNS
    assert row['path_length'] == 6.0 and row['success'] is True and row['time_to_goal'] == 3.0
