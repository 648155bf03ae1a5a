"""A campaign against real nodes: an episode its controller left unanswered (one missed tick,
as a starved process misses one) is run again and never recorded; the console says so."""

from __future__ import annotations

import csv
import subprocess

import pytest

from tests.graph.test_simulator_graph import start_external

pytestmark = pytest.mark.graph


def test_an_episode_its_controller_missed_is_rerun_not_recorded(node_processes, tmp_path):
    node_processes.start(['ros2', 'run', 'sessgan_sim', 'simulator', '--ros-args', '-r',
                          '__ns:=/w0', '-p', 'dummy_agents:=0'], name='simulator_w0')
    start_external(node_processes, '/w0', '--mute-first-scan')
    result = subprocess.run(
        ['ros2', 'run', 'sessgan_evolver', 'campaign', '--external', '--scenario', 'factory',
         '--method', 'sessgan', '--generations', '1', '--population', '1',
         '--maps-per-member', '2',
         '--time-limit', '10', '--seed', '5', '--no-record-failures', '--run', 'missed',
         '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags')],
        capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    log = result.stderr
    assert 'controller_unresponsive' in log and 'a harness failure, not a result' in log, log
    assert 'harness re-runs' in log
    with open(tmp_path / 'runs' / 'missed' / 'metrics_episodes.csv') as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 2
    assert 'controller_unresponsive' not in {row['outcome'] for row in rows}
    with open(tmp_path / 'runs' / 'missed' / 'metrics_generations.csv') as handle:
        assert int(next(csv.DictReader(handle))['harness_reruns']) >= 1
    assert 'Harness re-runs:' in (tmp_path / 'runs' / 'missed' / 'report' /
                                  'report.md').read_text()
