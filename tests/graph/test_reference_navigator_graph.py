"""The reference navigator as its own process against a simulator worker, over real topics.

Per scenario, the navigator (with the scenario's robot) drives to the goal of the scenario's
example map (a valid test: start, goal and route certified): in lockstep, answering every
scan, and against a clocked simulator at 4x real time, on its own sim-time timer like Nav2's
controller server. Success as the benchmark counts it: the goal without a fault collision (an
agent may still drive into the robot standing still). On a busy machine a clocked episode may
end overloaded (the navigator could not keep pace with sim time): no result, so it is run
again at half the pace, as campaigns do with --adaptive-rtf
(tests/benchmarks/bench_clocked_under_load.py runs these with every core saturated).
"""

from __future__ import annotations

import pytest

from tests.graph.test_simulator_graph import (
    environment_msg,
    evaluate,
    evaluate_with_reruns,
    start_simulator,
)

pytestmark = pytest.mark.graph

ROBOTS = {'factory': 'diff_drive', 'racetrack': 'car', 'drone': 'flyer'}


def start_navigator(node_processes, namespace: str, robot: str, *parameters: str):
    # The simulator publishes its clock in its namespace; a node's sim time comes from /clock.
    command = ['ros2', 'run', 'sessgan_controllers', 'reference_navigator', '--ros-args',
               '-r', f'__ns:={namespace}', '-r', f'/clock:={namespace}/clock',
               '-p', 'use_sim_time:=true', '-p', f'robot:={robot}']
    for parameter in parameters:
        command += ['-p', parameter]
    return node_processes.start(command, name=f'reference_navigator{namespace.replace("/", "_")}')


def example_environment(scenario: str):
    from sessgan_core.token_map import load_example_map

    return environment_msg(load_example_map(scenario).cells, scenario, f'{scenario}-example')


@pytest.mark.parametrize('scenario', sorted(ROBOTS))
def test_reference_navigator_reaches_the_goal_in_lockstep(node_processes, ros_node, scenario):
    namespace = f'/nav_lockstep_{scenario}'
    start_simulator(node_processes, namespace)
    navigator = start_navigator(node_processes, namespace, ROBOTS[scenario])
    metrics, _ = evaluate(ros_node, namespace, example_environment(scenario), timeout=300)
    assert metrics.feasible
    assert metrics.outcome == 'goal_reached', (metrics.outcome, metrics.detail)
    assert metrics.fault_collisions == 0, metrics.detail
    assert 'New map' in navigator.output(), 'the navigator never got the map'


@pytest.mark.parametrize('scenario', sorted(ROBOTS))
def test_reference_navigator_reaches_the_goal_on_its_timer_in_clocked_mode(
        node_processes, ros_node, scenario):
    namespace = f'/nav_clocked_{scenario}'
    start_simulator(node_processes, namespace, 'mode:=clocked', 'real_time_factor:=4.0',
                    'expected_command_period:=0.05')  # the navigator's 20 Hz
    start_navigator(node_processes, namespace, ROBOTS[scenario], 'control_mode:=timer',
                    'control_rate_hz:=20.0')
    metrics, _, _ = evaluate_with_reruns(ros_node, namespace, example_environment(scenario),
                                      timeout=600)
    assert metrics.feasible
    assert metrics.outcome == 'goal_reached', (metrics.outcome, metrics.detail)
    assert metrics.fault_collisions == 0, metrics.detail
