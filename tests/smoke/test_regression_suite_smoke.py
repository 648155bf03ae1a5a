"""The CI path of a regression suite from scratch: evaluate's confirmed faults -> suite.yaml ->
`suite` with the controller that showed them (JUnit failures, exit 1) and with one that avoids
them (exit 0), through `ros2 run`."""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.smoke


def run(command: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(['ros2', 'run', 'sessgan_evolver', *command], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def junit_counts(path: Path) -> tuple[dict[str, str], dict[str, str]]:
    suite = ElementTree.parse(path).getroot().find('testsuite')
    assert suite is not None
    verdicts = {case.get('name') or '': next(p.get('value') or '' for p in case.iter('property')
                                             if p.get('name') == 'verdict')
                for case in suite.iter('testcase')}
    return dict(suite.attrib), verdicts


def test_confirmed_faults_fail_the_suite_and_a_controller_that_avoids_them_passes(
        ros_workspace, tmp_path):
    # Eight fresh maps of the shipped factory generator: the Nearness-Diagram robot collides
    # on some (measured: 2, confirmed); the reference navigator crosses the same maps.
    evaluate = run(['evaluate', '--controller', 'nearness_diagram', '--fresh-episodes', '8',
                    '--max-fault-records', '-1', '--repeats', '1', '--output-dir', 'found'],
                   tmp_path)
    assert evaluate.returncode == 0, evaluate.stderr[-3000:]
    suite_file = tmp_path / 'found' / 'suite.yaml'
    scenarios = yaml.safe_load(suite_file.read_text())['scenarios']
    assert scenarios, 'no confirmed fault to keep'
    confirmed = (f'shipped generator: {len(scenarios)} of ')
    assert confirmed in evaluate.stderr and 'distinct faults confirmed (1 re-runs' \
        in evaluate.stderr, evaluate.stderr[-3000:]
    assert confirmed in (tmp_path / 'found' / 'summary.md').read_text()
    assert all(entry['controller'] == 'nearness_diagram' for entry in scenarios)

    failing = run(['suite', str(suite_file), '--output-dir', 'ci-nd'], tmp_path)
    assert failing.returncode == 1, failing.stdout + failing.stderr[-3000:]
    counts, verdicts = junit_counts(tmp_path / 'ci-nd' / 'junit.xml')
    assert (counts['tests'], counts['failures'], counts['errors']) == (
        str(len(scenarios)), str(len(scenarios)), '0')
    assert set(verdicts) == {entry['name'] for entry in scenarios}
    assert (tmp_path / 'ci-nd' / 'summary.md').is_file()
    assert (tmp_path / 'ci-nd' / 'scenarios.csv').is_file()

    passing = run(['suite', str(suite_file), '--output-dir', 'ci-ref', '--controller',
                   'reference_navigator'], tmp_path)
    assert passing.returncode == 0, passing.stdout + passing.stderr[-3000:]
    counts, verdicts = junit_counts(tmp_path / 'ci-ref' / 'junit.xml')
    assert (counts['tests'], counts['failures']) == (str(len(scenarios)), '0')
    assert set(verdicts.values()) == {'pass'}

    broken = tmp_path / 'broken.yaml'
    broken.write_text(suite_file.read_text().replace(scenarios[0]['bag'], 'faults/missing'))
    refused = run(['suite', str(broken), '--output-dir', 'ci-broken'], tmp_path)
    assert refused.returncode == 2 and scenarios[0]['name'] in refused.stderr, refused.stderr
    assert not (tmp_path / 'ci-broken').exists()


def test_ctrl_c_stops_the_suite_and_reports_what_ran(ros_workspace, tmp_path):
    import os
    import signal
    import sys
    import time

    from sessgan_evolver.in_process import InProcessEvaluator
    from sessgan_gen.environment_sampler import EnvironmentSampler

    # A fresh map where Nearness-Diagram clips a wall (tests/unit/evolver's suite fixture).
    (environment,) = EnvironmentSampler().sample([1_000_000], scenario='factory')
    with InProcessEvaluator('factory', 'nearness_diagram',
                            record_directory=tmp_path / 'bags') as evaluator:
        bag = evaluator.run_environment(environment, 0).metrics['bag_path']
    assert bag
    count = 400  # far more than run in the second before the signal
    suite_file = tmp_path / 'suite.yaml'
    suite_file.write_text(yaml.safe_dump({'name': 'long', 'scenarios': [
        {'name': f'n{index:04d}', 'bag': bag} for index in range(count)]}))
    # --retries 1 makes the suite print a note once every scenario is prepared, just before
    # the first runs: the signal comes a second after it. SIGINT back to its default in the
    # child, as in a terminal: a test run started in the background (nohup, `&`, some CI
    # runners) hands its children SIGINT ignored, and this suite, with no rclpy to install a
    # handler, then ran on through the signal (the 'hang' a fixed 12 s wait did not cure).
    process = subprocess.Popen([sys.executable, '-m', 'sessgan_evolver.suite_cli',
                                str(suite_file), '--output', 'out', '--record', 'none',
                                '--retries', '1'],
                               cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, start_new_session=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert process.stderr is not None
    before = []
    while 'in-process lockstep episodes are exact' not in ''.join(before[-1:]):
        line = process.stderr.readline()
        assert line, ''.join(before)[-2000:]  # it ended before running anything
        before.append(line)
    time.sleep(1.0)
    os.killpg(process.pid, signal.SIGINT)
    stdout, stderr = process.communicate(timeout=300)
    stderr = ''.join(before) + stderr
    counts, verdicts = junit_counts(tmp_path / 'out' / 'junit.xml')
    ran = count - int(counts['skipped'])
    assert 0 < int(counts['skipped']) and int(counts['failures']) == ran, counts
    # Every scenario that ran reproduced its fault, but the run is incomplete: 130.
    assert process.returncode == 130, stdout + stderr[-2000:]
    assert 'interrupted' in stderr and 'Traceback' not in stderr, stderr[-2000:]
    assert list(verdicts.values()).count('not_run') == count - ran
    assert 'Interrupted' in (tmp_path / 'out' / 'summary.md').read_text()
