"""`suite --external` against a controller running as its own process beside a simulator:
a faulty controller fails the suite (every attempt, exit 1, a bag per failure), the fixed one
passes it (exit 0), one that fails every other episode is flaky, and a silent one is a harness
error (exit 3), never a pass or a fail."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest

from tests.graph.test_simulator_graph import start_external, start_simulator

pytestmark = pytest.mark.graph


def suite(*options: str) -> subprocess.CompletedProcess:
    return subprocess.run(['ros2', 'run', 'sessgan_evolver', 'suite', *options],
                          capture_output=True, text=True, timeout=400)


def junit_case(junit: Path) -> tuple[dict[str, str], dict[str, str]]:
    suite_element = ElementTree.parse(junit).getroot().find('testsuite')
    assert suite_element is not None
    case = suite_element.find('testcase')
    assert case is not None
    return dict(suite_element.attrib), {p.get('name') or '': p.get('value') or ''
                                        for p in case.iter('property')}


def test_external_controller_fails_the_suite_and_its_fix_passes(node_processes, room_bag,
                                                                tmp_path):
    start_simulator(node_processes, '/w0', 'dummy_agents:=0', f'bags_root:={tmp_path / "sim"}')
    blind = start_external(node_processes, '/w0', '--blind')

    failed = suite(str(room_bag), '--external', '--retries', '1', '--output',
                   str(tmp_path / 'blind'))
    assert failed.returncode == 1, failed.stdout + failed.stderr[-3000:]
    counts, props = junit_case(tmp_path / 'blind' / 'junit.xml')
    assert (counts['tests'], counts['failures'], counts['errors']) == ('1', '1', '0')
    assert props['verdict'] == 'fail' and props['attempts'] == '2', props
    assert props['attempt_outcomes'].count('fail:') == 2, props
    # A bag per attempt, written by the simulator and copied into the output over ROS.
    assert len(list((tmp_path / 'sim').rglob('episode.json'))) == 2
    assert Path(props['bag']).is_dir() and Path(props['bag']).is_relative_to(
        tmp_path / 'blind' / 'bags')
    assert len(list((tmp_path / 'blind' / 'bags').rglob('episode.json'))) == 2

    os.killpg(blind.process.pid, signal.SIGINT)
    blind.process.wait(timeout=15)
    start_external(node_processes, '/w0')
    fixed = suite(str(room_bag), '--external', '--retries', '1', '--output',
                  str(tmp_path / 'fixed'))
    assert fixed.returncode == 0, fixed.stdout + fixed.stderr[-3000:]
    counts, props = junit_case(tmp_path / 'fixed' / 'junit.xml')
    assert (counts['tests'], counts['failures']) == ('1', '0')
    assert props['verdict'] == 'pass' and props['attempt_outcomes'] == (
        'pass:goal_reached pass:goal_reached'), props
    # The straight line of an empty room is shorter than the certified route's grid steps.
    assert props['success'] == '1' and float(props['path_length_ratio']) > 0.5
    # --record failures: no bag of a pass. The blind run's bags were its own run's folder.
    assert not list((tmp_path / 'sim').glob('suite-fixed-*'))
    assert len(list((tmp_path / 'sim').glob('suite-blind-*'))) == 1


def test_a_fault_that_shows_now_and_then_is_flaky_and_silence_is_a_harness_error(
        node_processes, room_bag, tmp_path):
    start_simulator(node_processes, '/w0', 'dummy_agents:=0', 'controller_timeout:=1.0',
                    f'bags_root:={tmp_path / "sim"}')
    alternating = start_external(node_processes, '/w0', '--alternate')
    flaky = suite(str(room_bag), '--external', '--retries', '1', '--output',
                  str(tmp_path / 'flaky'), '--record', 'none')
    assert flaky.returncode == 0, flaky.stdout + flaky.stderr[-3000:]  # flaky is no failure
    counts, props = junit_case(tmp_path / 'flaky' / 'junit.xml')
    assert (counts['failures'], counts['errors']) == ('0', '0')
    assert props['verdict'] == 'flaky', props
    outcomes = props['attempt_outcomes'].split()
    assert len(outcomes) == 2 and 'pass:goal_reached' in outcomes, props
    assert sum(outcome.startswith('fail:') for outcome in outcomes) == 1, props
    case = ElementTree.parse(tmp_path / 'flaky' / 'junit.xml').getroot().find('.//testcase')
    assert case is not None and len(case.findall('flakyFailure')) == 1

    os.killpg(alternating.process.pid, signal.SIGINT)
    alternating.process.wait(timeout=15)
    start_external(node_processes, '/w0', '--silent')
    silent = suite(str(room_bag), '--external', '--harness-tries', '2', '--output',
                   str(tmp_path / 'silent'))
    assert silent.returncode == 3, silent.stdout + silent.stderr[-3000:]
    counts, props = junit_case(tmp_path / 'silent' / 'junit.xml')
    assert (counts['failures'], counts['errors']) == ('0', '1')
    assert props['verdict'] == 'error' and props['attempt_outcomes'] == (
        'harness:controller_unresponsive harness:controller_unresponsive'), props
    # The console says why, not only the JUnit file.
    assert 'harness error: no result in 2 attempt(s), last controller_unresponsive' in (
        silent.stderr), silent.stderr[-3000:]
    assert not (tmp_path / 'sim').exists() or not list((tmp_path / 'sim').rglob('episode.json'))


def test_ctrl_c_stops_an_external_suite_and_reports_what_ran(node_processes, room_bag,
                                                            tmp_path):
    import yaml

    simulator = start_simulator(node_processes, '/w0', 'dummy_agents:=0',
                                f'bags_root:={tmp_path / "sim"}')
    start_external(node_processes, '/w0')
    count = 400  # far more than run before the signal (40 ran in 12 s on a quiet machine)
    suite_file = tmp_path / 'suite.yaml'
    suite_file.write_text(yaml.safe_dump({'name': 'long', 'scenarios': [
        {'name': f'n{index:03d}', 'bag': str(room_bag)} for index in range(count)]}))
    # Started with SIGINT ignored, as a background job (`cmd &`, some CI runners) starts its
    # children: the suite must stop on the signal all the same (with rclpy's own handlers it
    # ended with an RCLError from the context they shut down). The smoke test's suite gets
    # SIGINT at its default, as in a terminal.
    process = subprocess.Popen([sys.executable, '-m', 'sessgan_evolver.suite_cli',
                                str(suite_file), '--external', '--output', str(tmp_path / 'out')],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    # Signalled once three episodes have ended (the suite runs one at a time on its one
    # worker, so it has the first results), not after a fixed wait: mid-suite on any machine.
    simulator.wait_for_output(r'(\]: episode \S+: \w+ after [\s\S]*){3}', timeout=300)
    assert process.poll() is None, 'the suite ended before it could be interrupted'
    os.killpg(process.pid, signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stdout + stderr[-3000:]  # every one that ran passed
    assert 'interrupted' in stderr and 'Traceback' not in stderr, stderr[-3000:]
    root = ElementTree.parse(tmp_path / 'out' / 'junit.xml').getroot()
    suite_element = root.find('testsuite')
    assert suite_element is not None
    skipped = int(suite_element.get('skipped') or 0)
    assert 0 < skipped < count and suite_element.get('failures') == '0', suite_element.attrib


def test_a_second_controller_driving_the_robot_is_warned_about(node_processes, ros_node,
                                                               room_bag, tmp_path):
    """Two stacks left running under one worker both drive its robot: the simulator's log
    says so (a user's mixed results had no other trace)."""
    import time

    simulator = start_simulator(node_processes, '/w0', 'dummy_agents:=0',
                                f'bags_root:={tmp_path / "sim"}')
    start_external(node_processes, '/w0', name='first_stack')
    start_external(node_processes, '/w0', name='second_stack')
    deadline = time.monotonic() + 60  # both up before the episode (slow to start under load)
    while ros_node.count_publishers('/w0/cmd_vel') < 2:
        assert time.monotonic() < deadline, 'the two stacks did not both publish cmd_vel'
        time.sleep(0.1)
    suite(str(room_bag), '--external', '--output', str(tmp_path / 'out'))
    simulator.wait_for_output(r'2 nodes publish on /w0/cmd_vel: more than one controller',
                              timeout=60)
