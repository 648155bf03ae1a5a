"""Metric definitions: risk score, contact events, proximity time, JSON output."""

import json
import math

import pytest

from sessgan_sim.metrics import (
    CONTACT_DEBOUNCE,
    ContactKind,
    EpisodeMetrics,
    MetricsRecorder,
    Outcome,
    risk_score,
)

pytestmark = pytest.mark.unit


def test_risk_score_is_collisions_times_proximity_share():
    assert risk_score(3, 2.0, 8.0) == pytest.approx(0.75)
    assert risk_score(0, 5.0, 10.0) == 0.0
    assert risk_score(4, 0.0, 10.0) == 0.0


def test_risk_score_is_zero_without_simulation_time():
    assert risk_score(2, 0.0, 0.0) == 0.0


def test_contact_events_are_debounced_per_partner():
    recorder = MetricsRecorder(clearance_range=1.0)
    static = ContactKind.STATIC

    def touch(time, partner=-1, kind=static):
        return recorder.record_contact(time, partner, kind, 1.0, 2.0)

    assert touch(1.0)
    assert not touch(1.01) and not touch(1.0 + CONTACT_DEBOUNCE)  # same contact, flickering
    assert touch(2.0 + CONTACT_DEBOUNCE)  # apart for more than the debounce time: new event
    assert touch(2.6, partner=0, kind=ContactKind.AGENT_INTO_ROBOT)  # another partner
    assert not touch(2.61, partner=0, kind=ContactKind.ROBOT_INTO_AGENT)  # still the same event
    assert recorder.collisions == 3 and recorder.fault_collisions == 2
    assert [event.kind for event in recorder.contacts] == [static, static,
                                                           ContactKind.AGENT_INTO_ROBOT]
    assert recorder.contacts[0].to_dict() == {'time': 1.0, 'x': 1.0, 'y': 2.0, 'kind': 'static',
                                              'agent': -1, 'fault': True, 'robot': 0,
                                              'other_robot': -1}


def test_a_shove_into_a_wall_says_so_in_the_record():
    recorder = MetricsRecorder(clearance_range=1.0)
    recorder.record_contact(1.0, 2, ContactKind.AGENT_INTO_ROBOT, 0.0, 0.0)  # agent 2 drives in
    recorder.record_contact(1.2, -1, ContactKind.AGENT_INTO_ROBOT, 0.0, 0.0)  # into the wall
    recorder.record_contact(3.0, -1, ContactKind.ROBOT_HIT_BY_ROBOT, 0.0, 0.0)  # by a robot
    recorder.record_contact(5.0, -1, ContactKind.STATIC, 0.0, 0.0)
    agent, wall, robot_wall, static = (event.to_dict() for event in recorder.contacts)
    assert 'note' not in agent and 'note' not in static
    assert (wall['agent'], wall['note']) == (-1, 'shoved into a static obstacle by an agent')
    assert robot_wall['note'] == 'shoved into a static obstacle by another robot under test'


def test_proximity_time_counts_only_close_ticks_without_contact():
    recorder = MetricsRecorder(clearance_range=1.0)
    recorder.record_tick(0.05, clearance=0.1, touching=False, proximity_distance=0.25)
    recorder.record_tick(0.05, clearance=0.3, touching=False, proximity_distance=0.25)
    recorder.record_tick(0.05, clearance=0.0, touching=True, proximity_distance=0.25)
    recorder.record_tick(0.05, clearance=0.2, touching=False, proximity_distance=0.25)
    assert recorder.ticks == 4
    assert recorder.proximity_time == pytest.approx(0.10)
    assert recorder.min_clearance == 0.0


def test_min_clearance_is_capped_at_the_clearance_range():
    recorder = MetricsRecorder(clearance_range=0.25)
    recorder.record_tick(0.05, clearance=0.25, touching=False, proximity_distance=0.25)
    assert recorder.min_clearance == 0.25
    assert recorder.proximity_time == 0.0


def test_snapshot_applies_the_risk_formula():
    recorder = MetricsRecorder(clearance_range=1.0)
    recorder.record_contact(0.5, -1, ContactKind.STATIC, 0.0, 0.0)
    recorder.record_contact(2.0, -1, ContactKind.STATIC, 0.0, 0.0)
    recorder.record_contact(3.0, 1, ContactKind.AGENT_INTO_ROBOT, 0.0, 0.0)
    for _ in range(10):
        recorder.record_tick(0.1, clearance=0.1, touching=False, proximity_distance=0.25)
    metrics = recorder.snapshot(simulation_time=4.0, feasible=True, distance_to_goal=2.5,
                                outcome=Outcome.TIMEOUT, detail='time limit')
    assert metrics.collisions == 3 and metrics.fault_collisions == 2
    assert metrics.static_collisions == 2 and metrics.agent_into_robot_collisions == 1
    assert metrics.proximity_time == pytest.approx(1.0)
    assert metrics.risk_score == pytest.approx(3 * 1.0 / 4.0)
    assert metrics.fault_risk_score == pytest.approx(2 * 1.0 / 4.0)
    assert metrics.outcome is Outcome.TIMEOUT


def test_to_dict_is_json_ready():
    metrics = EpisodeMetrics(
        collisions=1, proximity_time=0.5, simulation_time=2.0, risk_score=0.25, feasible=False,
        min_clearance=0.0, distance_travelled=1.0, final_distance_to_goal=math.inf, ticks=40,
        outcome=Outcome.STUCK, invalid_commands=2, detail='x')
    data = metrics.to_dict()
    assert data['outcome'] == 'stuck'
    assert data['final_distance_to_goal'] is None
    assert json.loads(json.dumps(data)) == data


def test_outcome_values_are_the_contract_strings():
    assert {outcome.value for outcome in Outcome} == {
        'goal_reached', 'collision_limit', 'timeout', 'stuck', 'controller_unresponsive',
        'invalid_environment', 'cancelled', 'harness_error', 'overloaded'}
    assert Outcome('stuck') is Outcome.STUCK
    assert Outcome.STUCK == 'stuck'
