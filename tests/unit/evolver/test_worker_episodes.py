"""The external workers' evaluator without ROS: a fake job runner stands in for the evaluate
action servers, a real in-process runner writes the failure bags a worker would."""

from __future__ import annotations

import numpy as np
import pytest

from sessgan_core.valid_tests import make_environment
from sessgan_evolver.compare_cli import parse_args
from sessgan_evolver.errors import ExternalWorkerError
from sessgan_evolver.faults import FaultRule, key_of_failure
from sessgan_evolver.in_process import NOT_SIMULATED, InProcessEvaluator
from sessgan_evolver.worker_episodes import WorkerEvaluator
from sessgan_gen.environment_sampler import EnvironmentSampler

pytestmark = pytest.mark.unit


class BagWritingWorkers:
    """Runs each job in process with failure bags on, like a worker with record_directory,
    and hands back what a worker's metrics message carries (no contacts, no trace)."""

    def __init__(self, record_directory) -> None:
        self.local = InProcessEvaluator('factory', '', 40.0, record_directory=record_directory)
        self.ids: list[str] = []

    def __call__(self, jobs, on_result) -> None:
        for job in jobs:
            self.ids.append(job.environment.id)
            run = self.local.run_environment(job.environment, job.seed)
            on_result(job, {k: v for k, v in run.metrics.items() if k != 'contacts'})


def test_a_workers_failure_gets_its_trace_and_key_from_its_bag_and_reruns_keep_their_own(
        tmp_path):
    workers = BagWritingWorkers(tmp_path)
    seen = []
    evaluator = WorkerEvaluator('factory', workers, tmp_path,
                                observer=lambda env, seed, run, origin: seen.append(origin))
    # Map seed 36 at 40 s: Nearness-Diagram drives into a wall (see test_method_campaign).
    (environment,) = EnvironmentSampler().sample([36], None, 'factory')
    run = evaluator.run_environment(environment, 7, 'search')
    expected = workers.local.runner.run(environment, 7, trace=True)
    key = key_of_failure(environment, expected.metrics, expected.trace, FaultRule())
    assert key is not None and key.kind == 'collision_static'
    assert key_of_failure(environment, run.metrics, run.trace, FaultRule()) == key
    assert run.metrics['contacts'] == expected.metrics['contacts']
    again = evaluator.runner.run(environment, 7, trace=True)
    assert key_of_failure(environment, again.metrics, again.trace, FaultRule()) == key
    assert workers.ids == [environment.id, f'{environment.id}-rerun1']
    assert (tmp_path / environment.id).is_dir() and (tmp_path / workers.ids[1]).is_dir()
    assert (evaluator.episodes, seen) == (1, ['search'])  # a re-run is no search episode
    workers.local.close()


def test_maps_without_a_route_are_not_simulated_and_a_failure_without_a_bag_is_an_error(
        tmp_path):
    told = []

    def no_bags(jobs, on_result):
        for job in jobs:
            told.append(job.environment.id)
            on_result(job, {'outcome': 'timeout', 'feasible': True, 'fault_collisions': 0,
                            'bag_path': ''})

    evaluator = WorkerEvaluator('factory', no_bags, tmp_path, simulate_invalid=False)
    walled = np.ones((32, 32), dtype=np.int64)
    invalid = make_environment(walled, 'factory', 'walled', seed=1)
    assert not invalid.feasible
    run = evaluator.run_environment(invalid, 3)
    assert (run.metrics['detail'], told) == (NOT_SIMULATED, [])
    (valid,) = [env for env in EnvironmentSampler().sample([36], None, 'factory')]
    with pytest.raises(ExternalWorkerError, match='not readable here'):
        evaluator.run_environment(valid, 3)


def test_compare_takes_external_as_a_flag():
    assert parse_args(['--external']).external is True
    assert parse_args([]).external is False
    assert parse_args(['--no-external']).external is False
