"""evaluate, compare and campaign --method with --external against a stack that runs in its
own process, as a Nav2 user runs theirs: a simulator and tests/graph/external_controller.py
(--blind: it drives straight ahead whatever it sees, so valid maps end in failures) under /w0,
started here; the commands start nothing and use what is up, like campaign --external."""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path

import pytest

from tests.graph.test_simulator_graph import start_external

pytestmark = pytest.mark.graph

SHORT = ['--scenario', 'factory', '--time-limit', '15']


@pytest.fixture
def external_stack(node_processes, tmp_path):
    """A lockstep simulator (its bags under tmp_path/worker_bags) and the blind external
    controller under /w0."""
    simulator = node_processes.start(['ros2', 'run', 'sessgan_sim', 'simulator', '--ros-args',
                                      '-r', '__ns:=/w0', '-p',
                                      f'bags_root:={tmp_path / "worker_bags"}'],
                                     name='simulator')
    start_external(node_processes, '/w0', '--blind')
    simulator.wait_for_output('simulator ready', timeout=120.0)
    return node_processes


def command(stack, tool: str, *arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run(['ros2', 'run', 'sessgan_evolver', tool, *arguments],
                          capture_output=True, text=True, timeout=900,
                          env={**os.environ, **stack.env})


def read_csv(path: Path) -> list[dict]:
    with open(path) as handle:
        return list(csv.DictReader(handle))


def test_evaluate_and_compare_run_on_the_external_stack(external_stack, tmp_path):
    evaluated = command(external_stack, 'evaluate', '--external', *SHORT, '--fresh-episodes',
                        '3', '--max-fault-records', '1', '--repeats', '1', '--output-dir',
                        str(tmp_path / 'evaluate'))
    assert evaluated.returncode == 0, evaluated.stderr[-4000:]
    assert 'external workers: /w0/evaluate' in evaluated.stderr
    (summary,) = read_csv(tmp_path / 'evaluate' / 'summary.csv')
    episodes = read_csv(tmp_path / 'evaluate' / 'episodes.csv')
    assert len(episodes) == 3 and int(summary['maps']) == 3
    failures = [row for row in episodes if row['valid_failure'] == 'True']
    assert failures and int(summary['valid_failures']) == len(failures)
    # The worker wrote them under its own bags_root, in the subdirectory the command named,
    # and the command copied each over ROS into <output>/worker_bags/, byte for byte.
    written = list((tmp_path / 'worker_bags' / 'external' / 'evaluate').glob('*/episode.json'))
    assert written
    for episode_json in written:
        copy = tmp_path / 'evaluate' / 'worker_bags' / episode_json.parent.name
        assert {f.name: f.read_bytes() for f in copy.iterdir()} == \
            {f.name: f.read_bytes() for f in episode_json.parent.iterdir()}
    # Fault keys come from the worker's bags: the first contact the robot caused, else where
    # it ended (stuck, timeout).
    for row in failures:
        kind = row['fault'].split('-r')[0]
        assert kind.startswith('collision_') if int(row['fault_collisions']) else \
            kind == row['outcome'], row
    assert int(summary['distinct_faults']) == len({row['fault'] for row in failures})
    (record,) = (tmp_path / 'evaluate' / 'faults').glob('*/*')
    facts = json.loads((record / 'episode.json').read_text())
    assert facts['confirmation']['reproduced'] == 1
    assert facts['fault']['kind'] == failures[0]['fault'].split('-r')[0]
    assert facts['controller'] == 'external' and facts['namespace'] == '/w0'
    assert (record / 'fault.png').stat().st_size > 0
    assert 'on the external workers' in (tmp_path / 'evaluate' / 'summary.md').read_text()

    # sessgan too: a generation of 2 members x 1 map goes to the worker as one batch.
    compared = command(external_stack, 'compare', '--external', *SHORT, '--methods',
                       'random,sessgan', '--search-seeds', '0', '--budget', '2',
                       '--population', '2', '--maps-per-member', '1', '--fresh-episodes', '2',
                       '--repeats', '1', '--max-fault-records', '1', '--output-dir',
                       str(tmp_path / 'compare'))
    assert compared.returncode == 0, compared.stderr[-4000:]
    runs = read_csv(tmp_path / 'compare' / 'runs.csv')
    assert [run['method'] for run in runs] == ['random', 'sessgan']
    assert [int(run['episodes']) for run in runs] == [2, 2]
    run = runs[0]
    assert int(run['valid_failures']) >= 1
    assert int(run['confirmed_faults']) >= 1  # re-run on the worker, same fault
    assert int(run['confirmed_faults']) <= int(run['distinct_faults'])
    fresh = read_csv(tmp_path / 'compare' / 'fresh_seed.csv')
    assert len(fresh) == 2 and all(int(row['maps']) == 2 for row in fresh)
    report = (tmp_path / 'compare' / 'report.md').read_text()
    assert '# Fault finding: factory, external' in report
    assert 'on the external workers' in report
    assert list((tmp_path / 'compare' / 'faults' / 'random-seed0').glob('*/fault.png'))


def test_a_method_campaign_runs_on_the_external_stack(external_stack, tmp_path):
    """campaign --external --method random: no generator, no worker started; its faults are
    placed from the external worker's failure bags."""
    ran = command(external_stack, 'campaign', '--external', *SHORT, '--method', 'random',
                  '--budget', '3', '--run', 'ext', '--runs-root', str(tmp_path / 'runs'),
                  '--bags-root', str(tmp_path / 'bags'))
    assert ran.returncode == 0, ran.stderr[-4000:]
    assert 'worker found: /w0/evaluate' in ran.stderr
    episodes = read_csv(tmp_path / 'runs' / 'ext' / 'metrics_episodes.csv')
    assert len(episodes) == 3
    failures = [row for row in episodes if row['fault']]
    assert failures, 'no failure: the test checks nothing'
    assert all(row['fault'] != '?' and Path(row['bag_path']).is_dir() for row in failures)
    assert not list((tmp_path / 'runs' / 'ext' / 'logs').glob('*.log')), 'it started a process'
    # The worker's bags (its own bags_root) were collected into the campaign's bags/<run>/,
    # byte for byte, over the worker's bags service (--worker-bags keep: both copies remain).
    for row in failures:
        copy = Path(row['bag_path'])
        assert copy.parent == (tmp_path / 'bags' / 'ext').resolve()
        original = tmp_path / 'worker_bags' / 'ext' / copy.name
        assert {f.name: f.read_bytes() for f in copy.iterdir()} == \
            {f.name: f.read_bytes() for f in original.iterdir()}
    assert ran.stderr.count('collected from /w0') == len(failures)
    done = next(line for line in ran.stderr.splitlines() if '[campaign] done in' in line)
    assert f'{len(failures)} valid failures' in done
