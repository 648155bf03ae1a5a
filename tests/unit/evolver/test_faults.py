"""The failure rule, the distinct-fault grouping and confirmation."""

from __future__ import annotations

import numpy as np
import pytest

from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.episode_runner import EpisodeTrace
from sessgan_evolver.faults import (
    FaultError,
    FaultEvent,
    FaultKey,
    FaultRule,
    confirm,
    fault_key,
    first_fault_event,
    group_faults,
    is_valid_failure,
    key_of_failure,
)

pytestmark = pytest.mark.unit


def contact(kind, x=1.0, y=1.0, time=1.0, agent=-1):
    return {'time': time, 'x': x, 'y': y, 'kind': kind, 'agent': agent,
            'fault': kind != 'agent_into_robot'}


def metrics(outcome='goal_reached', contacts=(), feasible=True):
    faults = sum(c['fault'] for c in contacts)
    return {'outcome': outcome, 'collisions': len(contacts), 'fault_collisions': faults,
            'contacts': list(contacts), 'feasible': feasible, 'ticks': 10,
            'risk_score': 0.5 * len(contacts), 'proximity_time': 1.0}


def trace(end=(3.0, 4.0)):
    poses = np.array([[1.0, 1.0, 0.0], [end[0], end[1], 0.0]])
    return EpisodeTrace(times=np.array([0.0, 0.05]), poses=poses, twists=np.zeros((2, 3)),
                        commands=np.zeros((1, 3)), agents=np.zeros((2, 0, 2)))


@pytest.fixture(scope='module')
def example():
    return load_example_map('factory').cells


def test_the_failure_rule_is_the_simulators_controller_failure():
    assert not is_valid_failure(metrics())
    assert is_valid_failure(metrics('collision_limit', [contact('static')] * 10))
    assert is_valid_failure(metrics('goal_reached', [contact('robot_into_agent', agent=0)]))
    assert is_valid_failure(metrics('stuck')) and is_valid_failure(metrics('timeout'))
    # An agent driving into the robot is not its fault; nothing counts in an invalid test.
    assert not is_valid_failure(metrics('goal_reached', [contact('agent_into_robot', agent=1)]))
    assert not is_valid_failure(metrics('stuck', feasible=False))
    assert not is_valid_failure(metrics('goal_reached', [contact('static')], feasible=False))


def test_the_first_fault_event_is_the_first_contact_the_robot_caused(example):
    contacts = [contact('agent_into_robot', 0.5, 0.5, 0.2, agent=1),
                contact('robot_into_agent', 5.2, 6.1, 1.5, agent=0), contact('static', 1, 1, 2)]
    assert first_fault_event(metrics('stuck', contacts), trace()) == \
        FaultEvent('collision_agent', 5.2, 6.1, 1.5)
    assert first_fault_event(metrics('stuck', contacts[2:]), trace()).kind == 'collision_static'
    assert first_fault_event(metrics('timeout', contacts[:1]), trace(end=(7.0, 2.0))) == \
        FaultEvent('timeout', 7.0, 2.0, 0.05)
    broken = metrics('stuck')
    broken['fault_collisions'] = 1
    with pytest.raises(FaultError, match='no contact event'):
        first_fault_event(broken, trace())


def test_a_fleet_fault_is_placed_at_the_robot_that_failed():
    # A robot of a fleet that moved into another: its fault (a campaign stopped on it).
    bump = contact('robot_into_robot', 2.0, 3.0, 0.7)
    assert first_fault_event(metrics('goal_reached', [bump]), trace()) == \
        FaultEvent('collision_robot', 2.0, 3.0, 0.7)
    # Without a contact, where the robot the outcome comes from ended, not r0.
    fleet = trace(end=(3.0, 4.0))
    fleet.fleet = [trace(end=(6.0, 7.5)), trace(end=(1.0, 1.5))]
    stuck = {**metrics('stuck'), 'failed_leg': 1}
    assert first_fault_event(stuck, fleet) == FaultEvent('stuck', 6.0, 7.5, 0.05)
    assert first_fault_event({**stuck, 'failed_leg': 0}, fleet).x == 3.0
    with pytest.raises(FaultError, match='name robot r5 as failing, the trace has 3 robots'):
        first_fault_event({**stuck, 'failed_leg': 5}, fleet)
    # A mission's failed_leg is a leg, not a robot: one robot, its own end.
    assert first_fault_event({**stuck, 'failed_leg': 2}, trace(end=(8.0, 1.0))).x == 8.0


def test_same_kind_place_and_surroundings_is_one_fault(example):
    environment = make_environment(example, 'factory', 'a')
    rule = FaultRule()
    key = fault_key(environment, FaultEvent('collision_static', 5.2, 6.1, 1.0), rule)
    # Same coarse cell (2 m squares), a different point and time: the same fault.
    assert fault_key(environment, FaultEvent('collision_static', 4.1, 7.9, 9.0), rule) == key
    # Another coarse cell, or another kind: another fault.
    assert fault_key(environment, FaultEvent('collision_static', 6.1, 6.1, 1.0), rule) != key
    assert fault_key(environment, FaultEvent('collision_agent', 5.2, 6.1, 1.0), rule) != key
    assert (key.row, key.col) == (3, 2) and key.label.startswith('collision_static-r3c2-')
    # A change of the map far away keeps the fault; one in the context makes a new one.
    far, near = example.copy(), example.copy()
    far[28, 28] = 1 - far[28, 28]
    near[11, 7] = 1 - near[11, 7]  # row 11 lies in the context rows 10..17 of coarse row 3
    event = FaultEvent('collision_static', 5.2, 6.1, 1.0)
    assert fault_key(make_environment(far, 'factory', 'far'), event, rule) == key
    assert fault_key(make_environment(near, 'factory', 'near'), event, rule) != key
    # A place at the map's edge gets a context padded with 'outside'.
    edge = fault_key(environment, FaultEvent('timeout', 0.1, 0.1, 1.0), rule)
    assert (edge.row, edge.col) == (0, 0)
    with pytest.raises(FaultError):
        fault_key(environment, event, FaultRule(coarse_cells=0))


def test_only_valid_failures_have_a_key(example):
    environment = make_environment(example, 'factory', 'a')
    assert key_of_failure(environment, metrics(), None, FaultRule()) is None
    assert key_of_failure(environment, metrics('stuck', feasible=False), None,
                          FaultRule()) is None
    assert key_of_failure(environment, metrics('goal_reached', [contact('agent_into_robot')]),
                          None, FaultRule()) is None
    with pytest.raises(FaultError, match='trace'):
        key_of_failure(environment, metrics('stuck'), None, FaultRule())
    assert key_of_failure(environment, metrics('stuck'), trace(), FaultRule()).kind == 'stuck'


def test_grouping_and_confirmation(example):
    environment = make_environment(example, 'factory', 'a')
    a = fault_key(environment, FaultEvent('stuck', 1.0, 1.0, 1.0), FaultRule())
    b = fault_key(environment, FaultEvent('stuck', 9.0, 9.0, 1.0), FaultRule())
    entries = group_faults([None, b, a, b, None, a])
    assert [(e.key, e.occurrences) for e in entries] == [(b, [1, 3]), (a, [2, 5])]
    original = metrics('stuck')
    steady = confirm(entries[0], original, lambda: (dict(original), b, 0.5), repeats=3)
    assert steady.confirmed and steady.exact == 3 and steady.wall_time == 1.5
    answers = iter([(original, b, 0.1), (metrics('goal_reached'), None, 0.1),
                    (metrics('stuck', [contact('static')]), b, 0.1)])
    flaky = confirm(entries[0], original, lambda: next(answers), repeats=3)
    assert not flaky.confirmed and (flaky.reproduced, flaky.exact) == (2, 1)
    assert entries[0].confirmation is flaky
    assert not confirm(entries[1], original, lambda: (original, a, 0.0), 0).confirmed
    # A re-run that ends across the edge of the fault's coarse cell shows the same fault (a
    # clocked stack is not exactly repeatable); one two cells away or of another kind does not.
    beside = FaultKey(b.kind, b.row + 1, b.col - 1, 'other context')
    assert confirm(entries[0], original, lambda: (original, beside, 0.0), 2).confirmed
    for other in (FaultKey(b.kind, b.row + 2, b.col, 'x'), FaultKey('timeout', b.row, b.col,
                                                                     b.context)):
        assert not confirm(entries[0], original, lambda: (original, other, 0.0), 1).confirmed
