"""Episodes the test harness ended are run again and never recorded; a lost failure bag is
reported, never a crash (sessgan_evolver.harness, in_process, campaign)."""

from __future__ import annotations

import copy
import csv
import errno

import pytest
import torch

from sessgan_evolver import campaign_cli, in_process
from sessgan_evolver.campaign import Campaign, CampaignConfig
from sessgan_evolver.errors import HarnessFailureError
from sessgan_evolver.harness import HarnessRetries
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_sim.metrics import HARNESS_OUTCOMES, EpisodeMetrics, Outcome, is_controller_failure

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


def test_a_harness_failure_is_rerun_and_counted_and_the_last_try_stops_the_run():
    retries = HarnessRetries(3)
    retries.failed('a', 'map-a', 'controller_unresponsive', 'no cmd_vel within 2.0 s')
    retries.succeeded('a')
    retries.failed('a', 'map-a', 'controller_unresponsive', 'no cmd_vel within 2.0 s')
    retries.failed('a', 'map-a', 'controller_unresponsive', 'no cmd_vel within 2.0 s')
    assert retries.reruns == 3  # succeeded() forgot the first: two failures of three so far
    with pytest.raises(HarnessFailureError,
                       match='controller under test was silent on every one of 3 tries of '
                             'episode map-a'):
        retries.failed('a', 'map-a', 'controller_unresponsive', 'no cmd_vel within 2.0 s')
    mixed = HarnessRetries(2)
    mixed.failed('b', 'map-b', 'a worker process died', 'logs in /tmp')
    with pytest.raises(HarnessFailureError, match='harness failed on every one of 2 tries'):
        mixed.failed('b', 'map-b', 'cancelled', 'the simulator was shut down')
    with pytest.raises(HarnessFailureError, match='harness_tries'):
        HarnessRetries(0)


def test_a_harness_outcome_is_no_controller_failure():
    for outcome in HARNESS_OUTCOMES:
        metrics = EpisodeMetrics(
            collisions=2, proximity_time=1.0, simulation_time=5.0, risk_score=0.4,
            feasible=True, min_clearance=0.0, distance_travelled=1.0,
            final_distance_to_goal=3.0, ticks=100, outcome=outcome, detail='',
            fault_collisions=2)
        assert not is_controller_failure(metrics)  # so no failure bag is written either
    assert is_controller_failure(dataclass_copy(metrics, outcome=Outcome.COLLISION_LIMIT))


def dataclass_copy(metrics, **changes):
    import dataclasses
    return dataclasses.replace(metrics, **changes)


def silent_runner(evaluator: InProcessEvaluator, silent_calls: set[int] | None):
    """Make the evaluator's runner end the calls in ``silent_calls`` (every call: None) as a
    silent controller would, with a fault collision that must not count."""
    real = evaluator.runner.run
    calls = []

    def run(environment, seed, **options):
        result = real(environment, seed, **options)
        calls.append(environment.id)
        if silent_calls is None or len(calls) in silent_calls:
            result = copy.copy(result)
            result.metrics = {**result.metrics, 'outcome': 'controller_unresponsive',
                              'detail': 'no cmd_vel within 2.0 s wall time',
                              'fault_collisions': 1, 'collisions': 1}
        return result

    evaluator.runner.run = run
    return calls


def small_config(**changes) -> CampaignConfig:
    values = dict(scenario='factory', generations=1, population=2, maps_per_member=1, seed=3,
                  time_limit=2.0)
    values.update(changes)
    return CampaignConfig(**values)


def rows(path) -> list[dict]:
    with open(path) as handle:
        return list(csv.DictReader(handle))


def test_an_unresponsive_episode_is_rerun_not_recorded(tmp_path):
    from sessgan_evolver.campaign_cli import report_result

    config = small_config(record_failures=True, generations=2)
    logs: list[str] = []
    campaign = Campaign(config, 'rerun', tmp_path / 'runs', tmp_path / 'bags', logs.append)
    observed = []
    with InProcessEvaluator('factory', time_limit=2.0, record_directory=campaign.bags_dir,
                            log=logs.append,
                            observer=lambda env, seed, run, origin: observed.append(
                                run.metrics['outcome'])) as evaluator:
        calls = silent_runner(evaluator, {1, 4})  # one in each generation
        result = campaign.run(evaluator)
    episodes = rows(result.run_dir / 'metrics_episodes.csv')
    assert len(calls) == 6 and calls[0] == calls[1]  # the first episode ran twice
    assert len(episodes) == 4
    assert 'controller_unresponsive' not in {row['outcome'] for row in episodes}
    assert 'controller_unresponsive' not in observed
    assert [row['harness_reruns'] for row in rows(result.run_dir / 'metrics_generations.csv')] \
        == ['1', '1']
    # Each generation's line gives its own and the run's, as its failures are the run's.
    lines = [line for line in logs if line.startswith('generation ')]
    assert 'harness re-runs 1 in this generation, 1 in the run' in lines[0], lines
    assert 'harness re-runs 1 in this generation, 2 in the run' in lines[1], lines
    assert any('a harness failure, not a result; running it again' in line for line in logs)
    assert 'Harness re-runs: 2 episodes' in result.report_path.read_text()
    report_result(result, logs.append)
    assert 'harness re-runs 2 (run again, not results)' in logs[-1], logs[-1]


def test_a_method_campaign_counts_its_harness_re_runs_too(tmp_path):
    """The default (screened) and every ask/tell method run through MethodCampaign: its
    console line, generation rows and report say how many episodes the harness ended."""
    from sessgan_evolver.method_campaign import MethodCampaign

    config = small_config(method='random', budget=2, population=2, record_failures=True)
    logs: list[str] = []
    campaign = MethodCampaign(config, 'rerun', tmp_path / 'runs', tmp_path / 'bags',
                              logs.append)
    with InProcessEvaluator('factory', time_limit=2.0, record_directory=campaign.bags_dir,
                            log=logs.append) as evaluator:
        calls = silent_runner(evaluator, {1})
        result = campaign.run(evaluator)
    assert len(calls) == 3 and calls[0] == calls[1]
    assert [row['harness_reruns'] for row in rows(result.run_dir / 'metrics_generations.csv')] \
        == ['1']
    assert any('harness re-runs 1 in this batch, 1 in the run' in line for line in logs), logs
    assert 'Harness re-runs: 1 episodes' in result.report_path.read_text()


def test_a_controller_silent_on_every_try_stops_the_campaign_with_a_resume_hint(
        tmp_path, monkeypatch, capsys):
    real = in_process.EpisodeRunner.run

    def always_silent(self, environment, seed, **options):
        result = real(self, environment, seed, **options)
        result.metrics['outcome'] = 'controller_unresponsive'
        result.metrics['detail'] = 'no cmd_vel within 2.0 s wall time'
        return result

    monkeypatch.setattr(in_process.EpisodeRunner, 'run', always_silent)
    status = campaign_cli.main([
        '--in-process', '--method', 'sessgan', '--scenario', 'factory', '--generations', '1',
        '--population', '2',
        '--maps-per-member', '1', '--time-limit', '2', '--harness-tries', '2', '--run', 'silent',
        '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags')])
    err = capsys.readouterr().err
    assert status == 1, err
    assert 'the controller under test was silent on every one of 2 tries' in err
    # The hint repeats the run's own options, so the resume runs as the run did.
    hint = next(line for line in err.splitlines() if 'continue later with: ' in line)
    assert '--in-process' in hint and '--run silent' in hint and hint.endswith('--resume')
    assert 'Traceback' not in err
    assert not (tmp_path / 'runs' / 'silent' / 'metrics_episodes.csv').exists()


def test_evaluate_and_compare_rerun_harness_outcomes_too(tmp_path):
    """They run their episodes through InProcessEvaluator.run_environment: the same rule."""
    from sessgan_core.token_map import load_example_map
    from sessgan_core.valid_tests import make_environment

    environment = make_environment(load_example_map('factory').cells, 'factory', 'example')
    observed = []
    with InProcessEvaluator('factory', time_limit=2.0, observer=lambda *args: observed.append(
            args[2].metrics['outcome'])) as evaluator:
        silent_runner(evaluator, {1, 2})
        run = evaluator.run_environment(environment, 1, 'fresh seed')
        assert run.metrics['outcome'] != 'controller_unresponsive'
        assert evaluator.harness_reruns == 2 and len(observed) == 1
        silent_runner(evaluator, None)
        with pytest.raises(HarnessFailureError, match='silent on every one of 3 tries'):
            evaluator.run_environment(environment, 1, 'fresh seed')


def test_a_lost_failure_bag_is_reported_and_the_campaign_goes_on(tmp_path, monkeypatch):
    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(in_process, 'write_trace_bag', no_space)
    logs: list[str] = []
    # Two sim seconds cannot cross a factory map: every valid test fails and is due a bag.
    campaign = Campaign(small_config(record_failures=True), 'full', tmp_path / 'runs',
                        tmp_path / 'bags', logs.append)
    with InProcessEvaluator('factory', time_limit=2.0, record_directory=campaign.bags_dir,
                            log=logs.append) as evaluator:
        result = campaign.run(evaluator)
    episodes = rows(result.run_dir / 'metrics_episodes.csv')
    lost = [row for row in episodes if row['bag_error']]
    assert lost, episodes
    assert all('No space left on device' in row['bag_error'] and row['bag_path'] == ''
               for row in lost)
    assert any('WARNING: failure bag LOST' in line for line in logs)
    assert any(f'WARNING: {len(lost)} failure bags lost' in line for line in logs)
    assert f'WARNING: {len(lost)} failure bags were lost' in result.report_path.read_text()
    assert not (tmp_path / 'bags' / 'full').exists() or not any(
        (tmp_path / 'bags' / 'full').iterdir())


def test_a_full_disk_leaves_no_half_written_bag(tmp_path, monkeypatch):
    """The real writer on ENOSPC midway: its staging directory goes, nothing is left."""
    from sessgan_sim import bag_recording

    real = bag_recording.write_map_server

    def full(*args, **kwargs):
        real(*args, **kwargs)  # some bytes are on disk already
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(bag_recording, 'write_map_server', full)
    logs: list[str] = []
    campaign = Campaign(small_config(record_failures=True), 'full', tmp_path / 'runs',
                        tmp_path / 'bags', logs.append)
    with InProcessEvaluator('factory', time_limit=2.0, record_directory=campaign.bags_dir,
                            log=logs.append) as evaluator:
        result = campaign.run(evaluator)
    assert any(row['bag_error'] for row in rows(result.run_dir / 'metrics_episodes.csv'))
    bags = tmp_path / 'bags' / 'full'
    assert not bags.exists() or list(bags.iterdir()) == []


def test_a_run_directory_that_cannot_be_written_stops_the_campaign_cleanly(
        tmp_path, monkeypatch, capsys):
    from sessgan_evolver.run_store import RunStore

    def no_space(self, kind, row):
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(RunStore, 'append_row', no_space)
    status = campaign_cli.main([
        '--in-process', '--method', 'sessgan', '--scenario', 'factory', '--generations', '1',
        '--population', '2',
        '--maps-per-member', '1', '--time-limit', '2', '--run', 'full',
        '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags')])
    err = capsys.readouterr().err
    assert status == 1, err
    assert 'No space left on device' in err
    hint = next(line for line in err.splitlines() if 'continue later with: ' in line)
    assert '--in-process' in hint and '--run full' in hint and hint.endswith('--resume')
    assert 'Traceback' not in err
