"""A stack that cannot keep pace with a clocked simulator (issue 21): its episode ends
overloaded, a harness outcome that is run again (slower with --adaptive-rtf), never a
failure, a bag or a fitness.

The external controller's ``--stall`` sleeps 0.2 s wall time after every 20th scan, as a
process the scheduler leaves out does: at 4x real time each stall is 0.8 sim s without a
command against 1 s of commands every tick (about 44 % of the sim time in late gaps, the
rule's limit is 10 %); at 0.5x (the fourth try with --adaptive-rtf) it is 0.1 sim s, two
ticks, not late.
"""

from __future__ import annotations

import csv
import subprocess

import pytest

from tests.graph.test_regression_suite_graph import junit_case, suite
from tests.graph.test_simulator_graph import (
    environment_msg,
    evaluate,
    room,
    start_external,
    start_simulator,
)

pytestmark = pytest.mark.graph


def start_clocked_worker(node_processes, bags_root) -> None:
    """A simulator under /w0 at 4x real time, for the clocked suites below."""
    start_simulator(node_processes, '/w0', 'dummy_agents:=0', 'mode:=clocked',
                    'real_time_factor:=4.0', f'bags_root:={bags_root}')


def test_a_stalling_stack_in_clocked_mode_ends_overloaded_not_as_a_failure(
        node_processes, ros_node, tmp_path):
    namespace = '/overload'
    start_simulator(node_processes, namespace, 'mode:=clocked', 'real_time_factor:=4.0',
                    'dummy_agents:=0', f'bags_root:={tmp_path}')
    start_external(node_processes, namespace, '--stall')
    metrics, _ = evaluate(ros_node, namespace, environment_msg(room(), 'factory', 'room'),
                          time_limit=60.0, record_directory='stalled')
    assert metrics.outcome == 'overloaded', (metrics.outcome, metrics.detail)
    assert 'could not keep pace with sim time' in metrics.detail
    assert 'observed command period of' in metrics.detail, metrics.detail
    assert 'real_time_factor 4' in metrics.detail
    assert not metrics.success
    assert metrics.bag_path == '' and not (tmp_path / 'stalled').exists()


def test_a_fleet_robot_whose_stack_stalls_ends_the_clocked_episode_overloaded(
        node_processes, ros_node):
    from sessgan_core.ros_conversion import environment_to_msg
    from tests.graph.test_fleet_graph import crossing_environment

    namespace = '/overload_fleet'
    start_simulator(node_processes, namespace, 'mode:=clocked', 'real_time_factor:=4.0',
                    'dummy_agents:=0')
    start_external(node_processes, f'{namespace}/r0')
    start_external(node_processes, f'{namespace}/r1', '--stall')
    metrics, _ = evaluate(ros_node, namespace, environment_to_msg(crossing_environment()),
                          time_limit=60.0, timeout=300)
    assert metrics.outcome == 'overloaded', (metrics.outcome, metrics.detail)
    # The stalling robot is named (the steady one may be too, on a machine busy starting
    # both stacks: every robot that could not keep pace is).
    assert 'robot r1: the stack could not keep pace' in metrics.detail, metrics.detail


def test_a_campaign_reruns_an_overloaded_episode_slower_and_never_records_it(
        node_processes, tmp_path):
    node_processes.start(['ros2', 'run', 'sessgan_sim', 'simulator', '--ros-args', '-r',
                          '__ns:=/w0', '-p', 'dummy_agents:=0', '-p', 'mode:=clocked',
                          '-p', 'real_time_factor:=4.0', '-p', f'bags_root:={tmp_path}'],
                         name='simulator_w0')
    start_external(node_processes, '/w0', '--stall')
    result = subprocess.run(
        ['ros2', 'run', 'sessgan_evolver', 'campaign', '--external', '--scenario', 'factory',
         '--method', 'sessgan', '--generations', '1', '--population', '1',
         '--maps-per-member', '1', '--time-limit', '10', '--seed', '5', '--run', 'stalled',
         '--adaptive-rtf',
         '--harness-tries', '5', '--no-record-failures', '--runs-root', str(tmp_path / 'runs'),
         '--bags-root', str(tmp_path / 'bags')],
        capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    log = result.stderr
    assert 'overloaded (worker /w0/evaluate: the stack could not keep pace' in log, log[-3000:]
    assert 'running it again at 0.5 x the real-time factor (try 2 of 5)' in log, log[-3000:]
    with open(tmp_path / 'runs' / 'stalled' / 'metrics_episodes.csv') as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 1 and rows[0]['outcome'] != 'overloaded'
    with open(tmp_path / 'runs' / 'stalled' / 'metrics_generations.csv') as handle:
        assert int(next(csv.DictReader(handle))['harness_reruns']) >= 1


def test_a_clocked_suite_never_fails_a_scenario_on_an_overloaded_attempt(node_processes, room_bag,
                                                                         tmp_path):
    start_clocked_worker(node_processes, tmp_path / 'sim')
    start_external(node_processes, '/w0', '--stall')

    starved = suite(str(room_bag), '--external', '--harness-tries', '2', '--output',
                    str(tmp_path / 'starved'))
    assert starved.returncode == 3, starved.stdout + starved.stderr[-3000:]  # no result
    counts, props = junit_case(tmp_path / 'starved' / 'junit.xml')
    assert (counts['failures'], counts['errors']) == ('0', '1')
    assert props['verdict'] == 'error' and props['attempt_outcomes'] == (
        'harness:overloaded harness:overloaded'), props
    assert not (tmp_path / 'sim').exists() or not list((tmp_path / 'sim').rglob('episode.json'))

    slowed = suite(str(room_bag), '--external', '--harness-tries', '5', '--adaptive-rtf',
                   '--output', str(tmp_path / 'slowed'))
    assert slowed.returncode == 0, slowed.stdout + slowed.stderr[-3000:]
    counts, props = junit_case(tmp_path / 'slowed' / 'junit.xml')
    assert (counts['failures'], counts['errors']) == ('0', '0')
    outcomes = props['attempt_outcomes'].split()
    assert props['verdict'] == 'pass' and outcomes[0] == 'harness:overloaded', props
    assert outcomes[-1] == 'pass:goal_reached', props
    # The summary says how the worker ran the scenarios, and how they were recorded.
    summary = (tmp_path / 'slowed' / 'summary.md').read_text()
    assert '* worker /w0: clocked at 4x real time' in summary, summary
    assert '* recorded: 1 lockstep' in summary, summary


def test_a_clocked_suite_does_not_judge_a_stack_s_late_first_command(node_processes, room_bag,
                                                                   tmp_path):
    """A stack that sends its first command of the episode 5 s wall late (20 sim s at 4x, past
    the 10 s stuck timeout) is not judged for that wait: its stuck rule and time limit start
    with its first command, and the wall-clock controller_startup_timeout bounds the wait. So
    the delayed attempt reaches the goal and passes. (It used to end stuck: the machine's
    timing recorded as the stack's failure.)"""
    start_clocked_worker(node_processes, tmp_path / 'sim')
    start_external(node_processes, '/w0', '--late-start-alternate')  # the first goal: late
    late = suite(str(room_bag), '--external', '--retries', '1', '--output',
                 str(tmp_path / 'late'), '--record', 'none')
    assert late.returncode == 0, late.stdout + late.stderr[-3000:]
    counts, props = junit_case(tmp_path / 'late' / 'junit.xml')
    assert (counts['failures'], counts['errors']) == ('0', '0')
    assert props['verdict'] == 'pass', props
    # Both attempts, the late one and the prompt one, reach the goal.
    assert props['attempt_outcomes'].split() == ['pass:goal_reached'] * 2, props
