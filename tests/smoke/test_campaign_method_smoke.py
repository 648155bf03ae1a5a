"""campaign --method through the real command: an ask/tell method on the ROS workers finds
exactly what it finds in process, and its faults are placed from the workers' failure bags."""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.smoke

# Six random maps, 8 sim seconds each: Nearness-Diagram reaches no goal that fast, so every
# valid map is a failure whose fault is where the robot ended.
RANDOM = ['--scenario', 'factory', '--method', 'random', '--budget', '6', '--time-limit', '8',
          '--seed', '4']


def run_campaign(tmp_path: Path, run: str, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ['ros2', 'run', 'sessgan_evolver', 'campaign', *RANDOM, '--run', run, '--runs-root',
         str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags'), *extra],
        capture_output=True, text=True, timeout=600)


def rows(run_dir: Path) -> list[dict]:
    with open(run_dir / 'metrics_episodes.csv') as handle:
        return list(csv.DictReader(handle))


def test_a_method_campaign_on_ros_workers_matches_the_in_process_one(ros_workspace, tmp_path):
    over_ros = run_campaign(tmp_path, 'ros', '--workers', '2')
    assert over_ros.returncode == 0, over_ros.stderr[-3000:]
    in_process = run_campaign(tmp_path, 'local', '--in-process')
    assert in_process.returncode == 0, in_process.stderr[-3000:]
    ros_rows, local_rows = rows(tmp_path / 'runs' / 'ros'), rows(tmp_path / 'runs' / 'local')
    assert len(ros_rows) == 6
    compared = ('environment_id', 'map_seed', 'sim_seed', 'outcome', 'ticks', 'collisions',
                'fault', 'situation')
    assert [[row[k] for k in compared] for row in ros_rows] == \
        [[row[k] for k in compared] for row in local_rows]
    failures = [row for row in ros_rows if row['fault']]
    assert failures, 'no failure: the test checks nothing'
    for row in failures:  # placed from the worker's bag, not '?'
        assert row['fault'] != '?' and Path(row['bag_path']).is_dir()
    config = json.loads((tmp_path / 'runs' / 'ros' / 'config.json').read_text())
    assert config['config']['method'] == 'random'
    assert ' '.join(RANDOM) in ' '.join(config['invocation']['command_line'])
    done = next(line for line in over_ros.stderr.splitlines() if '[campaign] done in' in line)
    assert f'{len(failures)} valid failures' in done
    assert f'{len({row["fault"] for row in failures})} distinct faults' in done
    situations = sum(row['situation'] == 'True' for row in failures)
    assert 0 < situations <= len(failures) and f', {situations} fault situations in ' in done
    report = (tmp_path / 'runs' / 'ros' / 'report' / 'report.md').read_text()
    assert report.index('## Faults found') < report.index('## Summary')
