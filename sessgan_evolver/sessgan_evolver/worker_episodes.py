"""Episodes on the ``evaluate`` action servers already running: ``compare`` and ``evaluate``
with --external, against your own stack under /w0, /w1, ... (as ``campaign --external``).

:class:`WorkerEvaluator` offers what those commands use of the
:class:`~sessgan_evolver.in_process.InProcessEvaluator` (``run_environment`` with its
observer, ``runner.run`` for the re-runs that confirm a fault and draw it, ``sample`` and
``evaluate`` for a sessgan campaign), with every episode run by the robot under test in its
own process through the campaign's :class:`~sessgan_evolver.ros_evaluator.RosEvaluator`. In
process the trace comes from the runner; here it comes from the worker's failure bag
(sessgan_evolver.fault_tally.trace_from_bag). Only a valid failure has a bag, and only a
valid failure needs a trace (its fault key, its picture), so the workers must write their
bags where this process reads them: the goal names a subdirectory of each worker's
``bags_root`` (:func:`external_record_subdirectory`), which must be on this machine (or a
shared disk); the result's ``bag_path`` says where. A re-run gets an environment id of its
own, so its bag does not replace the one of the episode it repeats.

Episodes run one at a time (a search asks for one result before its next test), except a
sessgan generation, which goes to every worker in parallel.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sessgan_core.environment import MAX_ROBOTS, Environment
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import MissionSpec
from sessgan_evolver.campaign import CampaignConfig, EpisodeJob
from sessgan_evolver.episode_runner import EpisodeRun
from sessgan_evolver.errors import BagReadError, ExternalWorkerError, HarnessFailureError
from sessgan_evolver.fault_tally import trace_from_bag
from sessgan_evolver.faults import is_valid_failure
from sessgan_evolver.in_process import EpisodeObserver, invalid_map_run
from sessgan_gen.environment_sampler import EnvironmentSampler
from sessgan_sim.bag_recording import check_record_subdirectory

JobRunner = Callable[[Sequence[EpisodeJob], Callable[[EpisodeJob, dict], None]], None]
"""Runs jobs on the workers, telling each result: RosEvaluator.evaluate."""

WORKER_WAIT = 120.0
"""Wall seconds to wait for the first evaluate action server."""


class WorkerEvaluator:
    """The in-process evaluator's surface over the graph's workers (module docstring)."""

    def __init__(self, scenario: str, run_jobs: JobRunner, record_directory: str,
                 controller: str = 'external', simulate_invalid: bool = True,
                 observer: EpisodeObserver | None = None, mission: MissionSpec | None = None,
                 fleet: FleetSpec | None = None,
                 count_harness_reruns: Callable[[], int] = lambda: 0,
                 size: tuple[int, int] | None = None) -> None:
        self.scenario = scenario
        self.size = size
        """(height, width) of sampled maps (None: the checkpoint's training map's)."""
        self.run_jobs = run_jobs
        self.count_harness_reruns = count_harness_reruns
        self.record_directory = record_directory
        """Relative to each worker's bags_root."""
        self.controller = controller
        self.simulate_invalid = simulate_invalid
        self.observer = observer
        self.mission = (mission or MissionSpec()).validate()
        self.fleet = (fleet or FleetSpec()).validate(self.mission.stations)
        self.sampler = EnvironmentSampler()
        self.episodes = 0
        """Episodes run so far (simulated or not), re-runs excluded."""
        self.reruns = 0

    @property
    def harness_reruns(self) -> int:
        """Episodes the workers ran again after a harness outcome (never results)."""
        return self.count_harness_reruns()

    @property
    def runner(self) -> WorkerEvaluator:
        """Re-runs (``runner.run``) go to the workers too."""
        return self

    def close(self) -> None:
        """Nothing of its own to release (the ROS node belongs to worker_evaluator)."""

    def __enter__(self) -> WorkerEvaluator:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- the campaign's Evaluator protocol ------------------------------------------------

    def sample(self, weights: bytes, seeds: Sequence[int], generation: int,
               member: int) -> list[Environment]:
        return self.sampler.sample(seeds, weights, self.scenario, size=self.size,
                                   generation=generation, member=member, mission=self.mission,
                                   fleet=self.fleet)

    def evaluate(self, jobs: Sequence[EpisodeJob],
                 on_result: Callable[[EpisodeJob, dict], None]) -> None:
        """Every job on the workers in parallel (maps without a certified route are not
        simulated unless ``simulate_invalid``)."""
        def told(job: EpisodeJob, metrics: dict) -> None:
            run = self.with_trace(job.environment, metrics)
            self.finish(job.environment, job.seed, run,
                        f'generation {job.generation} member {job.member}')
            on_result(job, run.metrics)

        runnable = []
        for job in jobs:
            if job.environment.feasible or self.simulate_invalid:
                runnable.append(job)
            else:
                told(job, invalid_map_run(job.environment).metrics)
        if runnable:
            self.run_jobs(runnable, told)

    # --- one episode ----------------------------------------------------------------------

    def run_environment(self, environment: Environment, seed: int, origin: str = '',
                        keep_scans: bool = False) -> EpisodeRun:
        """Run one episode on a worker (its trace from its failure bag), tell the observer.
        ``keep_scans`` is accepted for the in-process surface: a worker's bag has them."""
        if not environment.feasible and not self.simulate_invalid:
            run = invalid_map_run(environment)
        else:
            run = self.episode(environment, seed)
        self.finish(environment, seed, run, origin)
        return run

    def run(self, environment: Environment, seed: int, trace: bool = False,
            keep_scans: bool = False) -> EpisodeRun:
        """A re-run (``runner.run``), recorded under an environment id of its own."""
        self.reruns += 1
        rerun = dataclasses.replace(environment, id=f'{environment.id}-rerun{self.reruns}')
        return self.episode(rerun, seed)

    def episode(self, environment: Environment, seed: int) -> EpisodeRun:
        results: list[dict] = []
        self.run_jobs([EpisodeJob(-1, 0, 0, environment, int(seed))],
                      lambda job, metrics: results.append(metrics))
        if len(results) != 1:
            raise ExternalWorkerError(f'episode {environment.id}: the workers told '
                                      f'{len(results)} results')
        return self.with_trace(environment, results[0])

    def with_trace(self, environment: Environment, metrics: dict[str, Any]) -> EpisodeRun:
        """The run of a worker's result: a valid failure's trace and contacts from its
        failure bag."""
        metrics = dict(metrics)
        trace = None
        if is_valid_failure(metrics):
            bag = str(metrics.get('bag_path') or '')
            if not bag or not Path(bag).is_dir():
                raise ExternalWorkerError(
                    f'episode {environment.id} failed, but its failure bag '
                    f'{bag or "(none written)"} is not readable here: the workers must write '
                    'their bags where this process reads them (<their bags_root>/'
                    f'{self.record_directory}); run them on this machine, with recording on')
            try:
                trace, recorded = trace_from_bag(bag)
            except BagReadError as err:
                raise ExternalWorkerError(f'episode {environment.id}: {err}') from err
            metrics['contacts'] = list(recorded.get('contacts') or [])
        return EpisodeRun(metrics, trace, float(metrics.get('wall_time') or 0.0))

    def finish(self, environment: Environment, seed: int, run: EpisodeRun,
               origin: str) -> None:
        self.episodes += 1
        if self.observer is not None:
            self.observer(environment, seed, run, origin)


def external_record_subdirectory(output: Path, label: str = '') -> str:
    """Where the workers put this command's failure bags, relative to their bags_root:
    ``external/<output folder's name>[/<label>]``, made a safe name (BagWriteError if not)."""
    safe = re.sub(r'[^A-Za-z0-9._-]', '_', Path(output).resolve().name).lstrip('._-') or 'run'
    return check_record_subdirectory('/'.join(['external', safe] + ([label] if label else [])))


SILENT_STACK = 'no controller subscribed to'
"""What a simulator's controller_unresponsive detail says when no stack took its scans."""


def fleet_stack_hint(count_subscribers: Callable[[str], int], workers: Sequence[str],
                     robots: int) -> str:
    """A one-robot episode no controller answered, while controllers are subscribed to the
    scans of fleet robots (``<worker namespace>/r0/scan``, ``r1/scan``, ...: a fleet stack
    under the worker): the hint to pass ``--robots``; '' otherwise. ``count_subscribers``:
    the node's (a graph query, no waiting); ``workers``: their evaluate action names."""
    if robots != 1:
        return ''
    found: dict[str, int] = {}
    for worker in workers:
        namespace = worker.rsplit('/', 1)[0]
        fleet = 0
        while fleet < MAX_ROBOTS and count_subscribers(f'{namespace}/r{fleet}/scan') > 0:
            fleet += 1
        if fleet:
            found[namespace] = fleet
    if not found:
        return ''
    where = ', '.join(f'{namespace}/r0..r{count - 1}' if count > 1 else f'{namespace}/r0'
                      for namespace, count in found.items())
    count = max(found.values())
    return (f'. Controllers are subscribed to the scans of fleet robots under {where}: a '
            f'fleet stack, while this evaluation runs one robot; pass --robots {count}')


@contextmanager
def worker_evaluator(scenario: str, record_directory: str, log_directory: Path,
                     controller: str = '',
                     time_limit: float = 0.0, mission: MissionSpec | None = None,
                     fleet: FleetSpec | None = None, simulate_invalid: bool = True,
                     observer: EpisodeObserver | None = None,
                     log: Callable[[str], None] = print,
                     wait: float = WORKER_WAIT,
                     size: tuple[int, int] | None = None,
                     adaptive_rtf: bool = False,
                     collect_into: Path | None = None) -> Iterator[WorkerEvaluator]:
    """A WorkerEvaluator on every evaluate action server of the domain (after at least one
    answers within ``wait`` seconds), their failure bags in ``record_directory`` under their
    bags_root and, with ``collect_into``, copied there over ROS (verified:
    sessgan_evolver.bag_collection), so workers on other machines serve too; its ROS node is
    shut down on exit. Nothing is started: the simulators and the stack under test are
    yours. ``adaptive_rtf``: re-run an overloaded episode slower
    (CampaignConfig.adaptive_rtf)."""
    import rclpy

    from sessgan_core.ros_spin import init_rclpy
    from sessgan_evolver.process_supervisor import ProcessSupervisor
    from sessgan_evolver.ros_evaluator import RosEvaluator

    mission = (mission or MissionSpec()).validate()
    fleet = (fleet or FleetSpec()).validate(mission.stations)
    config = CampaignConfig(scenario=scenario, time_limit=time_limit, external=True,
                            mission_stations=mission.stations,
                            station_dwell_time=mission.dwell_time, robots=fleet.robots,
                            record_failures=True, adaptive_rtf=adaptive_rtf)
    config.validate()
    record_directory = check_record_subdirectory(record_directory)
    label = controller or 'external'
    # No rclpy signal handlers: SIGINT is the command's (run_command), so the context stays up
    # for the clean-up instead of being shut down under a running evaluation.
    init_rclpy(['--ros-args'])
    node = rclpy.create_node('sessgan_evolver_external')
    try:
        # No process is started: the supervisor only gives the evaluator its log folder.
        supervisor = ProcessSupervisor(log_directory)
        ros = RosEvaluator(node, config, Path(record_directory), label, supervisor, log)
        ros.collect_into = None if collect_into is None else Path(collect_into).resolve()
        ros.wait_for_workers(1, timeout=wait)
        log(f'external workers: {", ".join(ros.discover_workers())} in ROS_DOMAIN_ID '
            f'{os.environ.get("ROS_DOMAIN_ID", "0")}; failure bags in <their bags_root>/'
            f'{record_directory}')
        try:
            yield WorkerEvaluator(scenario, ros.evaluate, record_directory, label,
                                  simulate_invalid, observer, mission, fleet,
                                  lambda: ros.harness_reruns, size)
        except HarnessFailureError as err:
            hint = (fleet_stack_hint(node.count_subscribers, sorted(ros.clients), fleet.robots)
                    if SILENT_STACK in str(err) else '')
            if hint:
                raise HarnessFailureError(f'{err}{hint}') from err
            raise
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
