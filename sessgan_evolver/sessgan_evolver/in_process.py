"""The campaign's Evaluator without ROS: generator and simulator in this process.

:class:`InProcessEvaluator` samples members' maps with sessgan_gen's EnvironmentSampler (what
the generator node does) and runs every episode with an
:class:`~sessgan_evolver.episode_runner.EpisodeRunner` (the lockstep episode of a worker with
a built-in controller), one after the other. Campaigns (``campaign --in-process``), the
baselines and the fresh-seed evaluation all run their episodes through
:meth:`InProcessEvaluator.run_environment`, so they are measured with the same runner.

Maps without a certified route are simulated like the ROS workers do, unless
``simulate_invalid`` is off: then their result is the simulator's ``invalid_environment``
outcome with zero metrics (an invalid test teaches nothing about the controller, and every
method's budget still counts it as one episode).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from sessgan_core.environment import Environment
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import MissionSpec
from sessgan_evolver.bag_export import write_trace_bag
from sessgan_evolver.campaign import EpisodeJob
from sessgan_evolver.episode_runner import EpisodeRun, EpisodeRunner
from sessgan_evolver.faults import is_valid_failure
from sessgan_evolver.harness import DEFAULT_HARNESS_TRIES, HarnessRetries
from sessgan_gen.environment_sampler import EnvironmentSampler
from sessgan_sim.bag_recording import episode_bag_directory
from sessgan_sim.errors import BagWriteError
from sessgan_sim.metrics import EpisodeMetrics, Outcome, is_harness_outcome
from sessgan_sim.simulator_settings import SimulatorSettings, episode_config_record

EpisodeObserver = Callable[[Environment, int, EpisodeRun, str], None]
"""Called after every episode with (environment, simulator seed, run, origin label)."""

NOT_SIMULATED = 'not simulated: the map has no certified route (invalid test)'


def invalid_map_run(environment: Environment) -> EpisodeRun:
    """The result of a map without a certified route that is not simulated."""
    metrics = EpisodeMetrics(
        collisions=0, proximity_time=0.0, simulation_time=0.0, risk_score=0.0, feasible=False,
        min_clearance=0.0, distance_travelled=0.0, final_distance_to_goal=0.0, ticks=0,
        outcome=Outcome.INVALID_ENVIRONMENT, detail=NOT_SIMULATED).to_dict()
    metrics['wall_time'] = 0.0
    metrics['bag_path'] = ''
    metrics['bag_error'] = ''
    return EpisodeRun(metrics, None, 0.0)


class InProcessEvaluator:
    """Implements the campaign's Evaluator protocol in this process (module docstring).

    ``record_directory``: write a failure bag per controller failure there (like the workers
    with ``record_failures``); ``observer``: told about every episode (fault logs).
    """

    def __init__(self, scenario: str, controller: str = '', time_limit: float = 0.0,
                 record_directory: str | Path | None = None, bag_storage: str = 'mcap',
                 simulate_invalid: bool = True, settings: SimulatorSettings | None = None,
                 observer: EpisodeObserver | None = None,
                 mission: MissionSpec | None = None, fleet: FleetSpec | None = None,
                 harness_tries: int = DEFAULT_HARNESS_TRIES,
                 log: Callable[[str], None] | None = None,
                 size: tuple[int, int] | None = None) -> None:
        """``mission``: the stations every sampled map gets (None: plain episodes);
        ``fleet``: the robots under test every sampled map gets (None: one);
        ``harness_tries``: tries of an episode the harness ends (sessgan_evolver.harness);
        ``log``: where re-runs and lost bags are told (default: nowhere); ``size``: (height,
        width) of every sampled map in cells (None or a zero side: the checkpoint's training
        map's)."""
        self.size = size
        self.scenario = scenario
        self.mission = (mission or MissionSpec()).validate()
        self.fleet = (fleet or FleetSpec()).validate(self.mission.stations)
        self.runner = EpisodeRunner(scenario, controller, time_limit, settings)
        self.sampler = EnvironmentSampler()
        self.record_directory = Path(record_directory) if record_directory else None
        self.bag_storage = bag_storage
        self.simulate_invalid = simulate_invalid
        self.observer = observer
        self.episodes = 0
        """Episodes run so far (simulated or not)."""
        self.retries = HarnessRetries(harness_tries, log)
        self.log = log

    @property
    def harness_reruns(self) -> int:
        """Episodes run again because the harness ended them (never recorded)."""
        return self.retries.reruns

    @property
    def controller(self) -> str:
        return self.runner.controller_name

    def close(self) -> None:
        self.runner.close()

    def __enter__(self) -> InProcessEvaluator:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # --- the Evaluator protocol -------------------------------------------------------------

    def sample(self, weights: bytes, seeds: Sequence[int], generation: int,
               member: int) -> list[Environment]:
        return self.sampler.sample(seeds, weights, self.scenario, size=self.size,
                                   generation=generation, member=member, mission=self.mission,
                                   fleet=self.fleet)

    def evaluate(self, jobs: Sequence[EpisodeJob],
                 on_result: Callable[[EpisodeJob, dict], None]) -> None:
        for job in jobs:
            run = self.run_environment(job.environment, job.seed,
                                       f'generation {job.generation} member {job.member}')
            on_result(job, run.metrics)

    # --- one episode ------------------------------------------------------------------------

    def run_environment(self, environment: Environment, seed: int, origin: str = '',
                        keep_scans: bool = False) -> EpisodeRun:
        """Run one episode (with its trace), write its failure bag if asked, tell the
        observer. ``keep_scans`` keeps the scans in the trace even without a bag. An episode
        the harness ended is run again, never returned (HarnessFailureError after the last
        try); a bag that cannot be written (a full disk) is told to ``log`` and its reason is
        the metrics' ``bag_error``: the episode is still a result."""
        if not environment.feasible and not self.simulate_invalid:
            run = invalid_map_run(environment)
        else:
            directory = self.record_directory
            while True:
                run = self.runner.run(environment, seed, trace=True,
                                      keep_scans=keep_scans or directory is not None)
                if not is_harness_outcome(run.metrics['outcome']):
                    break
                self.retries.failed((environment.id, seed), environment.id,
                                    run.metrics['outcome'], run.metrics['detail'])
            self.retries.succeeded((environment.id, seed))
            if directory is not None and is_valid_failure(run.metrics) and run.trace is not None:
                try:
                    run.metrics['bag_path'] = str(self.write_bag(
                        episode_bag_directory(directory, environment.id), environment, seed,
                        run, origin))
                except (BagWriteError, OSError) as err:
                    # The writer leaves nothing half-written (bag_recording's staging).
                    run.metrics['bag_error'] = (f'cannot write the failure bag of '
                                                f'{environment.id!r} in {directory}: {err}')
                if not keep_scans:
                    run.trace.scans = None  # a campaign keeps no scans in memory
        self.episodes += 1
        if self.observer is not None:
            self.observer(environment, seed, run, origin)
        return run

    def write_bag(self, directory: Path, environment: Environment, seed: int, run: EpisodeRun,
                  origin: str = '') -> Path:
        """The episode's failure bag (``run`` must have been traced with its scans)."""
        assert run.trace is not None
        return write_trace_bag(directory, environment, run.trace, {
            **self.episode_facts(seed, environment), 'controller': self.controller,
            'metrics': {k: v for k, v in run.metrics.items() if k != 'bag_path'},
            'origin': origin,
        }, storage=self.bag_storage)

    def episode_facts(self, seed: int, environment: Environment | None = None) -> dict:
        """What a worker's failure bag says about its simulator (sessgan_sim.worker
        .failure_bags), so ``replay --resimulate`` rebuilds the same one."""
        config = self.runner.episode_config(seed, environment)
        return {'episode_seed': int(seed), 'robot': config.robot,
                'time_limit': config.time_limit, 'mode': 'lockstep', 'sim_time_origin': 0.0,
                'sim_time_origin_ns': 0, 'simulator': self.runner.settings.to_dict(),
                'episode_config': episode_config_record(config), 'in_process': True}
