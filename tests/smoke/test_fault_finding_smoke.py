"""Tiny runs of the fault-finding commands: an in-process campaign, its fresh-seed evaluation
and a comparison of three methods (the screened search among them), through `ros2 run`."""

from __future__ import annotations

import csv
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.smoke


def run(command: list[str], cwd: Path) -> subprocess.CompletedProcess:
    result = subprocess.run(['ros2', 'run', 'sessgan_evolver', *command], cwd=cwd,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    return result


def test_campaign_in_process_then_fresh_seeds_then_compare(ros_workspace, tmp_path):
    campaign = run(['campaign', '--in-process', '--method', 'sessgan', '--generations', '2',
                    '--population', '3',
                    '--maps-per-member', '1', '--time-limit', '4', '--seed', '3',
                    '--seed-schedule', 'rotating', '--run', 'tiny', '--runs-root', 'runs',
                    '--bags-root', 'bags'], tmp_path)
    assert 'report:' in campaign.stdout
    assert (tmp_path / 'runs' / 'tiny' / 'report' / 'report.md').exists()
    # Its failure bags (4 s are too short to cross a factory) as a regression suite: in
    # process every one fails again, exactly.
    bags = sorted((tmp_path / 'bags' / 'tiny').rglob('episode.json'))
    assert bags and 'regression suite:' in campaign.stdout
    suite = subprocess.run(['ros2', 'run', 'sessgan_evolver', 'suite', 'runs/tiny/suite.yaml',
                            '--output', 'ci', '--record', 'none'], cwd=tmp_path,
                           capture_output=True, text=True, timeout=600)
    assert suite.returncode == 1, suite.stdout + suite.stderr[-3000:]
    assert f'{len(bags)} scenarios: {len(bags)} fail' in suite.stdout

    run(['evaluate', '--run', 'tiny', '--member', 'final', '--shipped', '--fresh-episodes',
         '2', '--time-limit', '4', '--output-dir', 'fresh'], tmp_path)
    with open(tmp_path / 'fresh' / 'summary.csv') as handle:
        generators = [row['generator'] for row in csv.DictReader(handle)]
    assert generators == ['shipped generator', 'tiny g1 m0', 'tiny g1 m1', 'tiny g1 m2']
    with open(tmp_path / 'fresh' / 'episodes.csv') as handle:
        assert len(list(csv.DictReader(handle))) == 8

    run(['compare', '--methods', 'random,cellular_automaton,screened', '--search-seeds',
         '0,1,2', '--budget', '3', '--time-limit', '3', '--fresh-episodes', '2', '--repeats',
         '1', '--output', 'compare'], tmp_path)
    for name in ('report.md', 'compare.png', 'failing_maps.png', 'runs.csv'):
        assert (tmp_path / 'compare' / name).stat().st_size > 0
    with open(tmp_path / 'compare' / 'runs.csv') as handle:
        runs = list(csv.DictReader(handle))
    screened = [row for row in runs if row['method'] == 'screened']
    assert len(screened) == 3 and all(int(row['episodes']) == 3 for row in screened)
    assert all(0 < float(row['cheap_wall']) < float(row['search_wall']) for row in screened)
