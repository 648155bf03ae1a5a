"""tests/benchmarks/plot_fault_finding.py: reading the benchmark's report folders."""

from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

SCRIPT = Path(__file__).resolve().parents[2] / 'benchmarks' / 'plot_fault_finding.py'


def load_script():
    spec = importlib.util.spec_from_file_location('plot_fault_finding', SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def report(folder: Path, rows: list[tuple[str, int, float]]) -> Path:
    folder.mkdir(parents=True)
    with open(folder / 'runs.csv', 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['method', 'search_seed', 'episodes', 'confirmed_per_1000'])
        writer.writerows([(method, seed, 100, value) for method, seed, value in rows])
    return folder


def test_runs_are_grouped_by_robot_budget_and_method_and_later_folders_replace(tmp_path):
    plot = load_script()
    old = report(tmp_path / 'old' / 'factory-nearness_diagram-100',
                 [('random', 100, 120.0), ('screened', 100, 200.0), ('random', 101, 140.0),
                  ('screened', 101, 260.0)])
    new = report(tmp_path / 'new' / 'factory-nearness_diagram-100-effort2',
                 [('screened', 100, 300.0), ('screened', 101, 340.0)])
    values = plot.read_runs([old, new])
    assert values[('factory, nearness_diagram', 100, 'random')] == {100: 120.0, 101: 140.0}
    assert values[('factory, nearness_diagram', 100, 'screened')] == {100: 300.0, 101: 340.0}

    png = tmp_path / 'matrix.png'
    assert plot.main([str(old), str(new), '--png', str(png), '--goal', '2.8']) == 0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_a_folder_that_is_not_a_benchmark_report_is_refused(tmp_path):
    plot = load_script()
    with pytest.raises(SystemExit, match='no runs.csv'):
        plot.read_runs([tmp_path])
    named_wrong = report(tmp_path / 'my-results', [('random', 0, 1.0)])
    with pytest.raises(SystemExit, match='<scenario>-<controller>-<budget>'):
        plot.read_runs([named_wrong])
    empty = report(tmp_path / 'factory-nearness_diagram-100', [])
    with pytest.raises(SystemExit, match='no runs'):
        plot.read_runs([empty])
    (empty / 'runs.csv').write_text('method,search_seed\nrandom,0\n')
    with pytest.raises(SystemExit, match='no column confirmed_per_1000'):
        plot.read_runs([empty])
