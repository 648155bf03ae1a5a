"""What `evaluate` writes beyond the failure rate: harness re-runs (summary.md, summary.csv,
episodes.csv), the simulator's count of NaN commands, uniqueness of maps smaller than a patch
(not applicable, not a crash), and the hint to pass --robots to a fleet stack."""

from __future__ import annotations

import csv
import dataclasses
import math

import numpy as np
import pytest
import torch

from sessgan_evolver import evaluate_cli
from sessgan_evolver.errors import HarnessFailureError
from sessgan_evolver.fresh_seed import (
    EPISODE_COLUMNS,
    PyramidSource,
    SeedPlan,
    episode_rows,
    evaluate_source,
    summary_table,
)
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_gen.environment_metrics import uniqueness_report
from sessgan_sim.metrics import Outcome

pytestmark = pytest.mark.unit
torch.set_num_threads(1)

PLAN = SeedPlan([(21, 5), (22, 6)], 0, 0, 0)


class SilentOnceEvaluator(InProcessEvaluator):
    """The in-process evaluator whose controller is silent on the first try of the first
    episode (a harness failure: run again, never a result) and whose every result counts two
    NaN commands the simulator replaced by a stop."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        run, silent = self.runner.run, [True]

        def flaky(*run_args, **run_kwargs):
            result = run(*run_args, **run_kwargs)
            metrics = {**result.metrics, 'invalid_commands': 2}
            if silent.pop() if silent else False:
                metrics.update(outcome=Outcome.CONTROLLER_UNRESPONSIVE.value,
                               detail='no controller subscribed to scan')
            return dataclasses.replace(result, metrics=metrics)

        self.runner.run = flaky  # type: ignore[method-assign]


def read_csv(path):
    with open(path, newline='', encoding='utf-8') as handle:
        return list(csv.DictReader(handle))


def test_a_harness_rerun_and_nan_commands_reach_the_episode_rows():
    with SilentOnceEvaluator('factory', time_limit=2.0) as evaluator:
        result = evaluate_source(PyramidSource('shipped', 'factory'), PLAN, evaluator)
    rows = episode_rows(result)
    assert result.summary.harness_reruns == 1
    assert [row['harness_reruns'] for row in rows] == [1, 0]
    assert {'invalid_commands', 'harness_reruns', 'detail'} <= set(EPISODE_COLUMNS)
    assert [row['invalid_commands'] for row in rows] == [2, 2]
    assert all(row['detail'] for row in rows)  # why each ended
    assert all(row['outcome'] != Outcome.CONTROLLER_UNRESPONSIVE.value for row in rows)


def test_evaluate_reports_its_harness_reruns_in_every_output(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(evaluate_cli, 'InProcessEvaluator', SilentOnceEvaluator)
    output = tmp_path / 'out'
    status = evaluate_cli.main(['--fresh-episodes', '2', '--time-limit', '2',
                                '--output-dir', str(output)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert 'harness re-runs 1' in captured.out
    (summary,) = read_csv(output / 'summary.csv')
    assert summary['harness_reruns'] == '1'
    episodes = read_csv(output / 'episodes.csv')
    assert [row['harness_reruns'] for row in episodes] == ['1', '0']
    assert [row['invalid_commands'] for row in episodes] == ['2', '2']
    assert 'Harness re-runs: 1 ' in (output / 'summary.md').read_text()


def test_evaluate_says_when_there_was_no_harness_rerun(tmp_path, capsys):
    output = tmp_path / 'out'
    assert evaluate_cli.main(['--fresh-episodes', '1', '--time-limit', '2',
                              '--output-dir', str(output)]) == 0, capsys.readouterr().err
    assert 'Harness re-runs: 0 ' in (output / 'summary.md').read_text()
    assert read_csv(output / 'summary.csv')[0]['harness_reruns'] == '0'
    assert read_csv(output / 'episodes.csv')[0]['harness_reruns'] == '0'


def test_uniqueness_of_a_patch_larger_than_the_maps_is_not_applicable():
    small = [np.eye(12, dtype=np.int64), np.zeros((12, 12), dtype=np.int64)]
    report = uniqueness_report(small)
    # 50 patches of 8x8: the identity's 25 show 9 diagonals, the zeros' 25 one pattern.
    assert report.per_size[8] == pytest.approx(100.0 * 10 / 50)
    assert math.isnan(report.per_size[16]) and math.isnan(report.mean)
    with pytest.raises(ValueError, match='no generated maps'):
        uniqueness_report([])


def test_evaluate_runs_maps_smaller_than_a_uniqueness_patch(tmp_path, capsys):
    output = tmp_path / 'out'
    status = evaluate_cli.main(['--width', '12', '--height', '12', '--fresh-episodes', '2',
                                '--time-limit', '2', '--cellular-automaton',
                                '--output-dir', str(output)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    assert 'Traceback' not in captured.err
    for row in read_csv(output / 'summary.csv'):
        assert row['uniqueness'] == '' and row['uniqueness_16x16'] == ''
        assert 0 < float(row['uniqueness_8x8']) <= 100
    assert '| n/a |' in (output / 'summary.md').read_text()


def test_the_summary_table_marks_a_missing_uniqueness_not_applicable():
    with InProcessEvaluator('factory', time_limit=2.0) as evaluator:
        result = evaluate_source(PyramidSource('small', 'factory', size=(12, 12)),
                                 SeedPlan([(21, 5)], 0, 0, 0), evaluator)
    assert result.summary.uniqueness is None and result.summary.uniqueness_16x16 is None
    assert result.summary.uniqueness_8x8 is not None
    assert '| n/a |' in summary_table([result.summary])


@pytest.mark.parametrize(('arguments', 'named'), [
    (['--width', '3', '--height', '3'], '--width 3'),  # below TPKL's 4x4 tiles
    (['--width', '8', '--height', '12'], '--width 8 --height 12'),  # below the coarsest scale
])
def test_evaluate_refuses_a_map_size_it_cannot_measure_before_writing(tmp_path, capsys,
                                                                     arguments, named):
    output = tmp_path / 'out'
    status = evaluate_cli.main(['--fresh-episodes', '1', '--output-dir', str(output),
                                *arguments])
    err = capsys.readouterr().err
    assert status == 2, err
    assert named in err and 'Traceback' not in err
    assert not output.exists()


def test_a_one_robot_evaluation_against_a_fleet_stack_suggests_robots():
    from sessgan_evolver.worker_episodes import fleet_stack_hint

    subscribed = {'/w0/r0/scan': 1, '/w0/r1/scan': 1, '/w1/r0/scan': 1}

    def count(topic: str) -> int:
        return subscribed.get(topic, 0)

    hint = fleet_stack_hint(count, ['/w0/evaluate', '/w1/evaluate'], robots=1)
    assert '--robots 2' in hint and '/w0/r0..r1' in hint and '/w1/r0' in hint
    assert fleet_stack_hint(count, ['/w0/evaluate'], robots=2) == ''
    assert fleet_stack_hint(lambda topic: 0, ['/w0/evaluate'], robots=1) == ''
    assert issubclass(HarnessFailureError, evaluate_cli.SessganEvolverError)


def test_a_run_folder_given_as_a_run_name_is_taken_with_a_note(tmp_path, capsys):
    """--run takes a name under --runs-root; a folder (relative or absolute) still works, and
    says where it belongs."""
    from sessgan_evolver.evaluate_cli import run_directory

    runs = tmp_path / 'runs'
    (runs / 'x').mkdir(parents=True)
    assert run_directory('x', runs) == runs / 'x'
    assert capsys.readouterr().err == ''
    assert run_directory(str(runs / 'x'), runs) == runs / 'x'  # absolute
    assert 'a run folder goes to --run-dir' in capsys.readouterr().err
