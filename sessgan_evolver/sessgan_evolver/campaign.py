"""The SESS-GAN campaign loop, independent of ROS: sample, simulate, score, evolve, record.

The loop talks to the outside world through an :class:`Evaluator` (the campaign node provides
one over the generator service and the simulator workers' ``evaluate`` actions), so the loop
itself is plain Python: it owns the genetic algorithm, the run directory and the report.

Order of one generation (what makes ``--resume`` exact, see run_store): checkpoint g ->
sample every member's K maps from seeds shared by the generation -> run every episode ->
episode and member rows -> tell -> generation row -> checkpoint g+1.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from sessgan_controllers.errors import UnknownControllerError
from sessgan_controllers.registry import get_controller
from sessgan_core.environment import Environment
from sessgan_core.errors import InvalidFleetError, InvalidMissionError
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import DEFAULT_DWELL_TIME, MissionSpec
from sessgan_core.progress import ProgressPrinter, format_duration
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import occupancy_to_tokens
from sessgan_evolver import __version__
from sessgan_evolver.algorithm import GeneticAlgorithm, GeneticAlgorithmConfig
from sessgan_evolver.errors import CampaignError, SearchMethodError
from sessgan_evolver.fault_tally import FaultTally, FaultTracker, fault_label
from sessgan_evolver.fitness import (
    FitnessConfig,
    generation_summary,
    map_diversity,
    member_fitness,
    tpkl_reference_from,
)
from sessgan_evolver.genome import Genome
from sessgan_evolver.genome_operators import OperatorConfig
from sessgan_evolver.harness import DEFAULT_HARNESS_TRIES, check_harness_tries
from sessgan_evolver.report import report_generations, write_report
from sessgan_evolver.run_store import RunStore
from sessgan_evolver.search_methods import METHODS, check_exploration, screening_effort
from sessgan_evolver.seeding import SeedStream, shared_seeds
from sessgan_gen.checkpoint import (
    checkpoint_bytes,
    default_checkpoint_path,
    incomplete_warning,
    load_checkpoint,
    training_map,
)
from sessgan_gen.environment_metrics import (
    tile_pattern_kl,
    tile_pattern_kl_per_k,
    uniqueness_of_fitting_sizes,
)
from sessgan_gen.environment_sampler import resolve_sample_size
from sessgan_gen.errors import SamplingRequestError
from sessgan_sim.bag_recording import BagStorage
from sessgan_sim.episode import check_time_limit
from sessgan_sim.errors import InvalidConfigError

SEED_SCHEDULES = ('fixed', 'per-generation', 'rotating')

SESSGAN_METHOD = 'sessgan'
"""The paper's weight evolution (this module's Campaign); every other method of
search_methods.METHODS runs as a sessgan_evolver.method_campaign.MethodCampaign."""
DEFAULT_METHOD = 'screened'
"""What the ``campaign`` command (and ``./sessgan demo``) runs without --method: the best
measured. A CampaignConfig built in code defaults to sessgan, the Campaign class's method."""

FEW_VALID_TESTS = 0.25
"""A first generation with fewer valid tests than this share gets a loud warning."""

EPISODE_TIMEOUT_SECONDS_PER_CELL = 5e-5
"""Wall seconds per map cell added to the default episode timeout for building the world: a
simulator built a 4096 x 4096 map (16.8 M cells) in 262 s, 16 us a cell (a 1024 x 1024 map
with 10 % walls: 21 us); more than twice that covers a busy host."""
EPISODE_TIMEOUT_SECONDS_PER_CELL_AND_SIM_SECOND = 1e-5
"""Wall seconds per map cell and sim second of time limit added for stepping: the 1024 x 1024
map took 5.6 wall s per sim second (5.3 us a cell); about twice that."""
MAX_EPISODE_TIMEOUT = 7 * 86400.0
"""Wall seconds: the longest --episode-timeout accepted (a week; 0 derives it)."""


def check_episode_timeout(seconds: float) -> float:
    """``seconds`` (an ``--episode-timeout``) when it is one, else CampaignError naming it."""
    if not (math.isfinite(seconds) and 0.0 <= seconds <= MAX_EPISODE_TIMEOUT):
        raise CampaignError(f'episode_timeout must lie in [0, {MAX_EPISODE_TIMEOUT:.0f}] wall '
                            f'seconds (0: derived from the time limit), got {seconds}')
    return seconds


def check_controller(scenario: str, controller: str) -> None:
    """CampaignError unless ``controller`` ('' = the scenario's) is a built-in controller that
    drives the scenario's robot (or a robot of its own that the simulators then host)."""
    name = controller or get_scenario(scenario).controller
    try:
        spec = get_controller(name)
    except UnknownControllerError as err:
        raise CampaignError(str(err)) from err
    robot = spec.robot_in(get_scenario(scenario).robot)
    if not spec.drives(robot):
        raise CampaignError(f'controller {name!r} does not drive the {robot} robot of the '
                            f'{scenario} scenario')


@dataclass(frozen=True)
class CampaignConfig:
    """What a campaign does; the CLI fills it from its arguments (defaults in brackets)."""

    scenario: str = 'factory'
    """[factory] Scenario: factory, racetrack or drone."""
    method: str = SESSGAN_METHOD
    """Search method: sessgan (the paper's evolution of generator weights) or an ask/tell
    method of compare (random, latent, grid_ga, cellular_automaton, ...), each run through
    the same workers, budget, failure bags and metrics."""
    budget: int = 0
    """[0: generations x population x maps per member] Episodes of the robot under test
    (the budget); sessgan runs the whole generations it pays for."""
    screening_effort: int = 0
    """[0: 2 where the episodes have agents, else 1; 3 with --external] The screened
    method's work per test: candidate maps and simulator seeds screened, times its defaults
    (milliseconds each; worth more where an episode of the robot under test costs seconds)."""
    exploration: float = 0.0
    """[0: 0.2] The screened method's least share of tests that are fresh samples of the
    generator (the rest are children of failing tests, near them in the generator's latent
    space); 1: fresh samples only, fewer faults but more different ones (README, *How much
    it finds*)."""
    generations: int = 30
    """[30] Generations to evaluate (generation 0 is the mutated pre-trained generator)."""
    population: int = 12
    """[12] Members (generator copies) per generation."""
    maps_per_member: int = 3
    """[3] K: maps each member samples from the generation's shared seeds."""
    workers: int = 2
    """[2] Simulator workers (/w0, /w1, ...) to start, each with its own controller (none with
    --external: it uses every worker already running)."""
    seed: int = 0
    """[0] The campaign seed; every random choice derives from it."""
    checkpoint: str = ''
    """[scenario's shipped] Pre-trained generator checkpoint to evolve."""
    controller: str = ''
    """[scenario's] Built-in controller to test (ignored with --external)."""
    time_limit: float = 0.0
    """[scenario's] Episode time limit in sim seconds."""
    episode_timeout: float = 0.0
    """[max(30, 2 x time limit), plus 50 us + 10 us x time limit per map cell] Wall seconds
    before an episode is retried elsewhere."""
    harness_tries: int = DEFAULT_HARNESS_TRIES
    """[3] Tries of an episode the test harness ends (a silent controller, a dead process, a
    cancelled episode): each is run again, never recorded; an episode the harness ends on
    every try stops the run (1..20)."""
    adaptive_rtf: bool = False
    """[False] Clocked mode: run an episode that ended overloaded (the stack could not keep
    pace with sim time) again at half the simulator's real-time factor, halved again for
    each overloaded try (down to 1/16)."""
    bag_storage: str = 'mcap'
    """[mcap] Failure bag storage: mcap or sqlite3."""
    seed_schedule: str = 'per-generation'
    """[per-generation] Map and simulator seeds: 'per-generation' draws new shared seeds each
    generation (fitness then also varies with the maps drawn; on fresh seeds its generators
    fail at least as often as the others', see README); 'fixed' uses the same K seeds in every
    generation (a member's fitness is comparable across generations, but the search learns
    those K maps: the worst on fresh seeds); 'rotating' takes K consecutive seeds of a pool
    of --seed-pool in turn, and a member evaluated in earlier generations (an unchanged
    elite) is selected on the mean fitness of all its evaluations, so one lucky draw does not
    keep it."""
    seed_pool: int = 0
    """[0: 4 x maps per member] Rotating schedule: the number of seeds in the pool."""
    record_failures: bool = True
    """[True] Write every failure episode as a bag under bags/<run>/."""
    mode: str = 'lockstep'
    """[lockstep] Stepping mode of the simulators this campaign starts: lockstep or clocked."""
    external: bool = False
    """[False] Start no simulators or controllers: use every evaluate action server already
    running (e.g. your own stack under /w0, /w1)."""
    in_process: bool = False
    """[False] No ROS graph: sample and run every episode in this process with the built-in
    controller (lockstep, one episode at a time; workers and mode are ignored)."""
    elite_count: int = 1
    """[1] Members kept unchanged each generation."""
    tournament_size: int = 3
    """[3] Tournament size of parent selection."""
    crossover_probability: float = 0.5
    """[0.5] Probability that a child has two parents."""
    mutation_scale: float = 0.02
    """[0.02] Gaussian mutation sigma relative to each tensor's spread."""
    mutation_probability: float = 0.5
    """[0.5] Probability that a tensor is mutated."""
    mission_stations: int = 0
    """[0] Pick-up -> place missions: stations drawn before home on every map, each leg
    certified (0..16); 0: plain start -> goal episodes."""
    station_dwell_time: float = DEFAULT_DWELL_TIME
    """[2.0] Sim seconds the robot stands still at each mission station (loading)."""
    robots: int = 1
    """[1] Robots under test on every map (a fleet episode: robots r1, r2, ... drawn beside
    the map's own start and goal, each route certified), 1..8; 1: one robot."""
    width: int = 0
    """[0: the checkpoint's] Width of every map in cells; by default the generator serves
    maps of the size of the map it learned (your facility's)."""
    height: int = 0
    """[0: the checkpoint's] Height of every map in cells."""
    fitness: FitnessConfig = field(default_factory=FitnessConfig)

    def validate(self) -> None:
        get_scenario(self.scenario)
        if self.method not in METHODS:
            raise CampaignError(f'method must be one of {", ".join(METHODS)}, got '
                                f'{self.method!r}')
        if self.budget < 0:
            raise CampaignError(f'budget must be >= 0 (0: generations x population x maps '
                                f'per member), got {self.budget}')
        try:
            screening_effort(self.screening_effort, self.external, self.scenario)
            check_exploration(self.exploration)
        except SearchMethodError as err:
            raise CampaignError(str(err)) from err
        if self.exploration and self.method != 'screened':
            raise CampaignError(f'exploration is a setting of the screened method, not of '
                                f'{self.method}')
        if (self.method == SESSGAN_METHOD and self.budget
                and self.budget < self.population * self.maps_per_member):
            raise CampaignError(f'a budget of {self.budget} episodes pays for no sessgan '
                                f'generation ({self.population} members x '
                                f'{self.maps_per_member} maps)')
        if self.width < 0 or self.height < 0:
            raise CampaignError(f'width and height must be >= 0 (0: the checkpoint map size), got '
                                f'{self.width}x{self.height}')
        try:
            self.mission()
        except InvalidMissionError as err:
            raise CampaignError(str(err)) from err
        try:
            self.fleet()
        except InvalidFleetError as err:
            raise CampaignError(str(err)) from err
        for name in ('generations', 'population', 'maps_per_member', 'workers'):
            if getattr(self, name) < 1:
                raise CampaignError(f'{name} must be >= 1, got {getattr(self, name)}')
        try:
            check_time_limit(self.time_limit, 'time_limit')
        except InvalidConfigError as err:
            raise CampaignError(str(err)) from err
        check_episode_timeout(self.episode_timeout)
        check_harness_tries(self.harness_tries)
        if not self.external:
            check_controller(self.scenario, self.controller)
        if self.seed_schedule not in SEED_SCHEDULES:
            raise CampaignError(f'seed schedule must be one of {", ".join(SEED_SCHEDULES)}, '
                                f'got {self.seed_schedule!r}')
        if self.seed_pool < 0 or (self.seed_pool and self.seed_pool < self.maps_per_member):
            raise CampaignError(f'seed pool must be 0 (default) or at least maps_per_member '
                                f'({self.maps_per_member}), got {self.seed_pool}')
        if self.bag_storage not in set(BagStorage):
            raise CampaignError(f'bag storage must be one of {[s.value for s in BagStorage]}, '
                                f'got {self.bag_storage!r}')
        if self.mode not in ('lockstep', 'clocked'):
            raise CampaignError(f'mode must be lockstep or clocked, got {self.mode!r}')
        if self.in_process and self.adaptive_rtf:
            raise CampaignError('adaptive_rtf re-runs clocked episodes slower; in_process '
                                'episodes run in lockstep')
        if self.in_process and self.external:
            raise CampaignError('in_process runs a built-in controller itself; it cannot use '
                                'external workers')
        self.algorithm_config().validate()
        self.fitness.validate()

    def algorithm_config(self) -> GeneticAlgorithmConfig:
        operators = dataclasses.replace(
            OperatorConfig(), mutation_scale=self.mutation_scale,
            mutation_probability=self.mutation_probability)
        return GeneticAlgorithmConfig(
            population_size=self.population, elite_count=min(self.elite_count, self.population),
            tournament_size=min(self.tournament_size, self.population),
            crossover_probability=self.crossover_probability, seed=self.seed,
            operators=operators)

    def resolved_budget(self) -> int:
        """Episodes of the robot under test the campaign may run."""
        return self.budget or self.generations * self.population * self.maps_per_member

    def with_budget_generations(self) -> CampaignConfig:
        """sessgan: this config with as many whole generations as ``budget`` pays for
        (unchanged without a budget)."""
        if not self.budget or self.method != SESSGAN_METHOD:
            return self
        return dataclasses.replace(
            self, generations=self.budget // (self.population * self.maps_per_member))

    def resolved_seed_pool(self) -> int:
        return self.seed_pool or 4 * self.maps_per_member

    def generation_seeds(self, generation: int) -> tuple[list[int], list[int]]:
        """(map seeds, simulator seeds) every member of ``generation`` is evaluated on."""
        count = self.maps_per_member
        if self.seed_schedule == 'rotating':
            pool = self.resolved_seed_pool()
            maps = shared_seeds(self.seed, 0, pool)
            sims = shared_seeds(self.seed, 0, pool, SeedStream.SIMULATION)
            picks = [(generation * count + k) % pool for k in range(count)]
            return [maps[i] for i in picks], [sims[i] for i in picks]
        seed_generation = 0 if self.seed_schedule == 'fixed' else generation
        return (shared_seeds(self.seed, seed_generation, count),
                shared_seeds(self.seed, seed_generation, count, SeedStream.SIMULATION))

    def mission(self) -> MissionSpec:
        """The mission every map gets (validated: InvalidMissionError names the option)."""
        return MissionSpec(self.mission_stations, self.station_dwell_time).validate()

    def fleet(self) -> FleetSpec:
        """The robots every map gets (validated: InvalidFleetError names the option)."""
        return FleetSpec(self.robots).validate(self.mission_stations)

    def resolved_time_limit(self) -> float:
        return self.time_limit or get_scenario(self.scenario).time_limit

    def episode_timeout_for(self, cells: int) -> float:
        """Wall seconds an episode on a map of ``cells`` cells may take before it is retried
        on another worker: ``episode_timeout`` if set, else twice the time limit (a clocked
        simulator runs at real time; at least 30 s) plus the world's build and stepping time,
        which grow with the map (:data:`EPISODE_TIMEOUT_SECONDS_PER_CELL`,
        :data:`EPISODE_TIMEOUT_SECONDS_PER_CELL_AND_SIM_SECOND`); a fleet's robots each add
        their share of stepping."""
        if self.episode_timeout:
            return self.episode_timeout
        # A mission's legs each take up to a plain episode's time, plus the dwells.
        time_limit = (self.resolved_time_limit() * (self.mission_stations + 1)
                      + self.mission_stations * self.station_dwell_time)
        per_cell = (EPISODE_TIMEOUT_SECONDS_PER_CELL
                    + EPISODE_TIMEOUT_SECONDS_PER_CELL_AND_SIM_SECOND * time_limit)
        return (max(30.0, 2.0 * time_limit)
                + per_cell * max(0, int(cells)) * max(1, int(self.robots)))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class EpisodeJob:
    """One episode to run: a member's k-th map of a generation."""

    generation: int
    member: int
    index: int
    environment: Environment
    seed: int
    """Simulator seed (sensor noise, dummy agents), shared by the generation's members."""

    @property
    def key(self) -> tuple[int, int]:
        return (self.member, self.index)


class Evaluator(Protocol):
    """How the loop reaches the generator and the simulators."""

    @property
    def harness_reruns(self) -> int:
        """Episodes run again so far because the test harness, not the controller, ended
        them (sessgan_evolver.harness): never results, shown so a user sees the harness
        struggled."""

    def sample(self, weights: bytes, seeds: Sequence[int], generation: int,
               member: int) -> list[Environment]:
        """Environments of a member's weights (checkpoint bytes), one per seed."""

    def evaluate(self, jobs: Sequence[EpisodeJob],
                 on_result: Callable[[EpisodeJob, dict], None]) -> None:
        """Run every job (in parallel where possible), calling ``on_result(job, metrics)``
        as each finishes; metrics is a dict of EpisodeMetrics fields (``bag_error``: why
        the failure bag of a failure was lost, '' if none was). An episode the harness ended
        is run again, not passed on (HarnessFailureError when it never gets a result)."""


@dataclass
class CampaignResult:
    run_dir: Path
    bags_dir: Path
    report_path: Path
    generations: list[dict]
    wall_time: float


class Campaign:
    """One run: ``runs/<run>/`` and ``bags/<run>/``, resumable."""

    def __init__(self, config: CampaignConfig, run_name: str, runs_root: Path, bags_root: Path,
                 log: Callable[[str], None] = print,
                 invocation: Mapping[str, Any] | None = None) -> None:
        """``invocation``: how the campaign was started (command line, run and bag roots),
        kept in config.json beside the config. Bad settings or an unreadable checkpoint raise
        before anything is written."""
        config.validate()
        if config.method != SESSGAN_METHOD:
            raise CampaignError(f'method {config.method!r} runs as a MethodCampaign '
                                '(sessgan_evolver.method_campaign), not as the weight evolution')
        config = config.with_budget_generations()
        self.config = config
        self.invocation = dict(invocation or {})
        scenario = get_scenario(config.scenario)
        self.scenario = scenario
        checkpoint = config.checkpoint or str(default_checkpoint_path(scenario.name))
        self.pyramid, self.metadata = load_checkpoint(checkpoint, scenario=scenario.name)
        if warning := incomplete_warning(self.metadata, f'checkpoint {checkpoint}'):
            log(f'WARNING: {warning}')
        # TPKL (fitness penalty, report) is measured against the map the generator learned.
        self.example = training_map(self.metadata)
        try:
            self.size = resolve_sample_size(self.pyramid, self.metadata,
                                            (config.height, config.width), scenario.name)
        except SamplingRequestError as err:
            raise CampaignError(str(err)) from err
        self.template = {k: v.clone() for k, v in self.pyramid.state_dict().items()}
        self.store = RunStore(runs_root, run_name)  # creates the run directory
        self.bags_dir = Path(bags_root).resolve() / run_name
        self.log = log

    def weights_of(self, genome: Genome) -> bytes:
        """Checkpoint bytes of a member: the pre-trained pyramid with the genome's tensors."""
        self.pyramid.load_state_dict(genome.to_state_dict(self.template))
        return checkpoint_bytes(self.pyramid, self.metadata)

    def start(self, resume: bool) -> tuple[GeneticAlgorithm, float | None,
                                          dict[str, list[float]]]:
        """The algorithm to continue with, the TPKL reference (None before generation 0) and
        the fitness history of the current population's genomes (digest -> fitnesses)."""
        self.store.write_config(self.config.to_dict(), self.config.seed, __version__,
                                invocation=self.invocation)
        point = self.store.resume() if resume else None
        if resume and point is None:
            self.log(f'nothing to resume in {self.store.run_dir}: starting at generation 0')
        if point is not None:
            for line in point.set_aside:
                self.log(f'{line}: going back to an earlier generation')
            self.log(f'resuming {self.store.run_dir} at generation {point.generation}')
            algorithm = GeneticAlgorithm.from_state_dict(point.checkpoint['algorithm'])
            extra = point.checkpoint['extra']
            history = {str(k): [float(f) for f in v]
                       for k, v in (extra.get('fitness_history') or {}).items()}
            return algorithm, extra.get('tpkl_reference'), history
        if self.store.latest_checkpoint() is not None:
            raise CampaignError(
                f'run {self.store.run_name!r} exists already: pass --resume to continue it, '
                f'or choose another --run name')
        initial = Genome.from_state_dict(self.template)
        return GeneticAlgorithm(self.config.algorithm_config(), initial), None, {}

    def run(self, evaluator: Evaluator, resume: bool = False) -> CampaignResult:
        config = self.config
        wall_start = time.monotonic()
        algorithm, tpkl_reference, history = self.start(resume)
        sample_generations = set(report_generations(config.generations - 1))
        progress = ProgressPrinter()
        last_tokens: list[list[np.ndarray]] = []
        first_generation = algorithm.generation
        tracker = FaultTracker()
        tracker.attach(evaluator)
        tally = FaultTally.from_rows(self.store.read_rows('episode'), self.store.situations_path)
        while algorithm.generation < config.generations:
            generation = algorithm.generation
            self.store.save_checkpoint(generation, algorithm.state_dict(),
                                       {'tpkl_reference': tpkl_reference,
                                        'fitness_history': history})
            genomes = algorithm.ask()
            map_seeds, sim_seeds = config.generation_seeds(generation)
            jobs, token_maps = [], []
            for member, genome in enumerate(genomes):
                environments = evaluator.sample(self.weights_of(genome), map_seeds,
                                                generation, member)
                self.check_size(environments)
                token_maps.append([occupancy_to_tokens(env.occupancy, self.scenario)
                                   for env in environments])
                jobs += [EpisodeJob(generation, member, k, env, sim_seeds[k])
                         for k, env in enumerate(environments)]
            tpkls = [tile_pattern_kl(self.example, maps) for maps in token_maps]
            if tpkl_reference is None:
                tpkl_reference = tpkl_reference_from(tpkls)
            if generation in sample_generations:
                self.save_sample_maps(generation, token_maps)

            results, harness_reruns, lost_bags = run_episodes(
                evaluator, jobs, progress, f'generation {generation}/{config.generations - 1}',
                self.log)
            missing = [job.key for job in jobs if job.key not in results]
            if missing:
                raise CampaignError(f'generation {generation}: no result for episodes {missing}')

            fitnesses, selection = [], []
            for member in range(len(genomes)):
                episodes = [results[(member, k)] for k in range(config.maps_per_member)]
                for job in jobs[member * config.maps_per_member:(member + 1) *
                                config.maps_per_member]:
                    key = tracker.key_of(job.environment, results[job.key])
                    fault = fault_label(results[job.key], key)
                    new_situation = tally.add(fault, key, job.environment)
                    self.store.append_episode({
                        'generation': generation, 'member': member, 'map': job.index,
                        'environment_id': job.environment.id, 'map_seed': job.environment.seed,
                        'sim_seed': job.seed, **results[job.key], 'fault': fault,
                        'situation': new_situation})
                breakdown = member_fitness(
                    episodes, tpkls[member], tpkl_reference,
                    map_diversity(token_maps[member]), config.fitness)
                evaluations = history.setdefault(genomes[member].digest(), [])
                evaluations.append(breakdown.fitness)
                # Rotating seeds: an unchanged genome is selected on all its evaluations.
                selection.append(float(np.mean(evaluations))
                                 if config.seed_schedule == 'rotating' else breakdown.fitness)
                self.store.append_member({'generation': generation, 'member': member,
                                          **breakdown.as_row(),
                                          'selection_fitness': selection[-1],
                                          'evaluations': len(evaluations)})
                fitnesses.append(breakdown)
            algorithm.tell(selection)
            # Only genomes that can come back (elites, unchanged) keep their history.
            survivors = {genome.digest() for genome in algorithm.ask()}
            history = {digest: values for digest, values in history.items()
                       if digest in survivors}
            tally.save_situations(self.store.situations_path)
            summary = {**generation_summary(generation, fitnesses), **tally.columns(),
                       'harness_reruns': harness_reruns, 'lost_bags': lost_bags}
            self.store.append_generation(summary)
            elapsed = time.monotonic() - wall_start
            done = generation + 1
            per_generation = elapsed / (done - first_generation)
            self.log(
                f'generation {generation}: {tally.line()} | fault risk '
                f'{fmt(summary["mean_fault_risk_score"])}, risk '
                f'{fmt(summary["mean_risk_score"])}, collisions '
                f'{fmt(summary["mean_collisions"])}, feasible '
                f'{summary["feasible_fraction"]:.0%}, TPKL {fmt(summary["mean_tpkl"])}, best '
                f'fitness {summary["best_fitness"]:.3f} | {done}/{config.generations} '
                f'generations, {60 / per_generation:.1f}/min, elapsed '
                f'{format_duration(elapsed)}, ETA '
                f'{format_duration(per_generation * (config.generations - done))}'
                + harness_note(self.store, 'generation'))
            if generation == first_generation and summary['feasible_fraction'] < FEW_VALID_TESTS:
                self.log(f'WARNING: only {summary["feasible_fraction"]:.0%} of the maps of '
                         f'generation {generation} are valid tests (hold a route): episodes '
                         'on the others find no fault. Check the map the generator learned '
                         '(mostly wall? passages too narrow for the robot?)')
            if done < config.generations:
                self.store.save_checkpoint(done, algorithm.state_dict(),
                                           {'tpkl_reference': tpkl_reference,
                                            'fitness_history': history})
            last_tokens = token_maps
        report_path = self.write_report(last_tokens)
        return CampaignResult(self.store.run_dir, self.bags_dir, report_path,
                              self.store.read_rows('generation'),
                              time.monotonic() - wall_start)

    def has_bags(self) -> bool:
        """Whether the campaign's bag folder exists and holds a bag."""
        return self.bags_dir.is_dir() and any(self.bags_dir.iterdir())

    def check_size(self, environments: Sequence[Environment]) -> None:
        """CampaignError unless every map is of the size this campaign asks for (a generator
        node started elsewhere, or an evaluator built without the size, would serve others)."""
        for environment in environments:
            if tuple(environment.occupancy.shape) != self.size:
                height, width = self.size
                raise CampaignError(
                    f'the generator served {environment.id} at {environment.occupancy.shape[0]}'
                    f'x{environment.occupancy.shape[1]} cells; the campaign asks for '
                    f'{height}x{width} (height x width)')

    # -- report ---------------------------------------------------------------------------

    def sample_maps_path(self, generation: int) -> Path:
        return self.store.run_dir / 'sample_maps' / f'generation_{generation:04d}.npy'

    def save_sample_maps(self, generation: int, token_maps: list[list[np.ndarray]]) -> None:
        path = self.sample_maps_path(generation)
        path.parent.mkdir(parents=True, exist_ok=True)
        # The first map of up to four members: enough for the report's figure.
        np.save(path, np.stack([maps[0] for maps in token_maps[:4]]))

    def write_report(self, last_population: list[list[np.ndarray]]) -> Path:
        maps_by_generation = {}
        for generation in report_generations(self.config.generations - 1):
            path = self.sample_maps_path(generation)
            if path.exists():
                maps_by_generation[generation] = list(np.load(path))
        tpkl_table, uniqueness_table = {}, {}
        for member, maps in enumerate(last_population):
            per_k = tile_pattern_kl_per_k(self.example, maps)
            tpkl_table[f'member {member}'] = {**{f'k={k}': v for k, v in per_k.items()},
                                              'mean': float(np.mean(list(per_k.values())))}
        pooled = [m for maps in last_population for m in maps]
        if pooled and (unique := uniqueness_of_fitting_sizes(pooled)):
            uniqueness_table['last population'] = {
                **{f'{s}x{s}': v for s, v in unique.items()},
                'mean': float(np.mean(list(unique.values())))}
        # Only point to the bag folder when a failure was recorded into it.
        notes = ([f'Failure bags: `{self.bags_dir}` (replay one with '
                  '`ros2 run sessgan_evolver replay <bag>`, re-simulate with `--resimulate`).']
                 if self.has_bags() else
                 ['No failure bag was written (no failure was found, or failures were not '
                  'recorded).'])
        notes += harness_notes(self.store)
        return write_report(self.store.run_dir, maps_by_generation, tpkl_table, uniqueness_table,
                            title=f'SESS-GAN campaign {self.store.run_name} '
                                  f'({self.config.scenario})',
                            token_names=self.scenario.token_names, notes=notes)


def run_episodes(evaluator: Evaluator, jobs: Sequence[EpisodeJob], progress: ProgressPrinter,
                 label: str, log: Callable[[str], None]
                 ) -> tuple[dict[tuple[int, int], dict], int, int]:
    """Every job's metrics by its key (with a progress bar, and a lost failure bag warned of
    as it comes), the episodes the harness ended and ran again, and the failure bags lost."""
    results: dict[tuple[int, int], dict] = {}
    progress.start(label, len(jobs))

    def on_result(job: EpisodeJob, metrics: dict) -> None:
        results[job.key] = metrics
        if metrics.get('bag_error'):
            log(f'WARNING: failure bag LOST for episode {job.environment.id}: '
                f'{metrics["bag_error"]} (its metrics are recorded; bag_error in '
                'metrics_episodes.csv)')
        progress.update(len(results), f'collisions in these episodes '
                        f'{sum(m["collisions"] for m in results.values())}')

    reruns_before = evaluator.harness_reruns
    evaluator.evaluate(jobs, on_result)
    lost_bags = sum(bool(metrics.get('bag_error')) for metrics in results.values())
    return results, evaluator.harness_reruns - reruns_before, lost_bags


def harness_notes(store: RunStore) -> list[str]:
    """A report's lines on the harness re-runs and lost failure bags of a whole run."""
    generations = store.read_rows('generation')
    reruns = sum(int(row.get('harness_reruns') or 0) for row in generations)
    lost = [row for row in store.read_rows('episode') if row.get('bag_error')]
    notes = []
    if reruns:
        notes.append(f'Harness re-runs: {reruns} episodes were ended by the test harness '
                     '(a silent or overloaded stack, a dead process, a cancelled episode), '
                     'not by the controller, and run again; none of them is a result (the '
                     '`harness_reruns` column of metrics_generations.csv says when, the '
                     "campaign's log why).")
    if lost:
        notes.append(f'**WARNING: {len(lost)} failure bags were lost** (their metrics are '
                     'recorded; see the `bag_error` column of metrics_episodes.csv): '
                     + '; '.join(f'{row.get("environment_id")}: {row.get("bag_error")}'
                                 for row in lost[:5])
                     + ('; ...' if len(lost) > 5 else ''))
    return notes


def harness_note(store: RunStore, step: str) -> str:
    """The console line's note of what went wrong around the episodes of the last ``step``
    ('batch', 'generation'), with the run's totals ('' when nothing); ``store`` holds that
    step's row."""
    rows = store.read_rows('generation')
    reruns, lost = (int(rows[-1].get(column) or 0) for column in ('harness_reruns', 'lost_bags'))
    parts = []
    if reruns:
        parts.append(f'harness re-runs {reruns} in this {step}, '
                     f'{sum(int(row.get("harness_reruns") or 0) for row in rows)} in the run '
                     '(episodes the harness, not the controller, ended: run again)')
    if lost:
        parts.append(f'WARNING: {lost} failure bags lost in this {step}, '
                     f'{sum(int(row.get("lost_bags") or 0) for row in rows)} in the run')
    return ''.join(f' | {part}' for part in parts)


def fmt(value: float | None) -> str:
    return 'n/a' if value is None else f'{value:.3f}'
