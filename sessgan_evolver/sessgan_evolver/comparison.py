"""Every search method side by side at equal episode budget: the ``compare`` report.

For one scenario and controller, each method (sessgan_evolver.search_methods.METHODS) runs
once per search seed with the same episode budget, through the same in-process runner and
validity certificate (maps without a certified route are not simulated and still cost one
episode, for every method). Per run:

* **distinct faults** (sessgan_evolver.faults) among its valid failures, each re-run
  ``repeats`` times; *confirmed* when every re-run shows the same fault (``confirm_limit``
  > 0 checks only the first that many faults of a run and says so);
* **confirmed distinct faults per 1,000 episodes**;
* **episodes and wall time to the first confirmed failure**: the episode index of the first
  valid failure whose fault was confirmed, and the search's wall seconds at that episode
  plus that fault's confirmation re-runs (CPU seconds beside it);
* **fresh-seed failure rate of the final generator** (sessgan_evolver.fresh_seed): SESS-GAN's
  fittest member of its last generation; ``random`` and ``latent`` (weights frozen) leave
  the generator they sampled; ``screened`` leaves its archive (children of the failing tests
  it kept, sessgan_evolver.screened_search.ArchiveSource; the generator when it found no
  fault); ``cellular_automaton`` is its own generator;
  ``grid_ga`` leaves none. Every generator is evaluated on the same fresh seed pairs,
  disjoint from all seeds of all runs, once per distinct generator;
* **TPKL and uniqueness of the failing maps**: of the maps of its distinct faults (first
  occurrence each), to the example map;
* **fault situations per 1,000 episodes**: its confirmed distinct faults grouped where they
  have the same kind and coarse cell on maps that differ in fewer than 10 % (and, stricter,
  25 %) of their cells (sessgan_evolver.faults.same_situation): a local variant of a failing
  map is a new distinct fault but the same situation.

Figures are reported per method as mean ± sample standard deviation over the search seeds,
with every seed's value in runs.csv; a figure of the final generator counts each distinct
generator once (``random``, ``latent`` and ``cellular_automaton`` leave the same one on every
seed: one measurement, n=1, no spread). compare.png draws the mean as a bar, each
measurement as a dot and their min–max as whiskers (inside the quantity's possible range).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sessgan_core.errors import InvalidFleetError, InvalidMissionError
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import DEFAULT_DWELL_TIME, MissionSpec
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import occupancy_to_tokens
from sessgan_evolver.campaign import SEED_SCHEDULES, CampaignConfig, check_controller
from sessgan_evolver.errors import CompareError, SearchMethodError
from sessgan_evolver.fault_picture import FaultScene, scene_from_run, write_scene_grid
from sessgan_evolver.fault_records import confirm_faults
from sessgan_evolver.fault_tally import OriginFigures, origin_family, origin_rows
from sessgan_evolver.faults import (
    SITUATION_CELLS,
    STRICT_SITUATION_CELLS,
    FaultEntry,
    FaultRule,
    SituationArchive,
    group_faults,
)
from sessgan_evolver.fitness import FitnessConfig
from sessgan_evolver.fresh_seed import (
    AutomatonSource,
    FreshSeedSummary,
    MapSource,
    PyramidSource,
    campaign_sources,
    evaluate_source,
    fresh_seed_plan,
    summary_rows,
    summary_table,
    write_csv,
)
from sessgan_evolver.in_process import EpisodeObserver, InProcessEvaluator
from sessgan_evolver.screened_search import ArchiveSource, ScreenedSearch
from sessgan_evolver.search import EpisodeLog, EpisodeRecord, run_search, run_sessgan_search
from sessgan_evolver.search_methods import (
    METHODS,
    GAConfig,
    check_exploration,
    make_baseline,
    screening_effort,
)
from sessgan_evolver.worker_episodes import external_record_subdirectory, worker_evaluator
from sessgan_gen.checkpoint import checkpoint_metadata, checkpoint_training_map, map_origin
from sessgan_gen.environment_metrics import tile_pattern_kl, uniqueness_report
from sessgan_sim.episode import check_time_limit
from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.metrics import navigation_columns


@dataclass(frozen=True)
class CompareConfig:
    """What ``compare`` runs; the CLI fills it from its arguments."""

    scenario: str = 'factory'
    """Scenario. (default: factory)"""
    controller: str = ''
    """Built-in controller under test. (default: scenario's)"""
    methods: tuple[str, ...] = METHODS
    """Methods to compare. (default: all)"""
    search_seeds: tuple[int, ...] = (0, 1, 2)
    """One run of each method per seed (at least 3 for a spread). (default: 0,1,2)"""
    budget: int = 360
    """Episodes per run (SESS-GAN: whole generations of population x K). (default: 360)"""
    screening_effort: int = 0
    """The screened method's work per test: candidate maps and simulator seeds screened,
    times its defaults. (default: 0: 2 where the episodes have agents, else 1; 3 with
    --external)"""
    exploration: float = 0.0
    """The screened method's least share of tests that are fresh samples of the generator,
    the rest children of failing tests; 1: fresh samples only. (default: 0: 0.2)"""
    fresh_episodes: int = 30
    """Fresh seed pairs per final generator. (default: 30)"""
    repeats: int = 3
    """Re-runs per distinct fault to confirm it. (default: 3)"""
    confirm_limit: int = 0
    """Confirm only the first this many distinct faults of each run. (default: 0: all)"""
    max_fault_records: int = 3
    """Confirmed faults per run kept as a bag and a picture (-1: every one; a bag of a
    60 s factory episode is about 2 MB). (default: 3)"""
    time_limit: float = 0.0
    """Episode time limit, sim seconds. (default: scenario's)"""
    evaluation_seed: int = 1000
    """Seed of the fresh seed pairs. (default: 1000)"""
    checkpoint: str = ''
    """Pre-trained generator (SESS-GAN's start, random's and latent's). (default: the
    scenario's shipped one)"""
    seed_schedule: str = 'per-generation'
    """SESS-GAN's seed schedule. (default: per-generation)"""
    population: int = 12
    """SESS-GAN's members and the GAs' individuals per generation. (default: 12)"""
    maps_per_member: int = 3
    """SESS-GAN's K. (default: 3)"""
    coarse_cells: int = 4
    """Fault rule: coarse cell side, map cells. (default: 4)"""
    context_cells: int = 2
    """Fault rule: context around the coarse cell, map cells. (default: 2)"""
    mission_stations: int = 0
    """Pick-up -> place missions: stations drawn before home on every map of every method,
    each leg certified (0..16); 0: plain start -> goal episodes. (default: 0)"""
    station_dwell_time: float = DEFAULT_DWELL_TIME
    """Sim seconds the robot stands still at each mission station. (default: 2.0)"""
    robots: int = 1
    """Robots under test on every map of every method (a fleet episode: robots r1, r2,
    ... drawn beside the map's own start and goal, each route certified), 1..8; 1: one
    robot. (default: 1)"""
    external: bool = False
    """Run every episode (and every confirming re-run) on the evaluate action servers
    already running, e.g. your own stack under /w0, /w1 (as campaign --external), instead of
    in process; --controller then only names it. Their failure bags (in <their
    bags_root>/external/<output folder name>/<method-seed>) are copied over ROS into
    <output-dir>/worker_bags/<method>-seed<n>/, so the workers may run on other machines.
    (default: False)"""
    adaptive_rtf: bool = False
    """With --external, clocked simulators: run an episode that ended overloaded (the
    stack could not keep pace with sim time) again at half the real-time factor, halved again
    on each overloaded try (down to 1/16). (default: False)"""
    width: int = 0
    """Width of every method's maps in cells (by default the size of
    the map the generator learned). (default: 0: the generator's)"""
    height: int = 0
    """Height of every method's maps in cells. (default: 0: the generator's)"""

    def validate(self) -> None:
        get_scenario(self.scenario)
        try:
            self.mission()
        except InvalidMissionError as err:
            raise CompareError(str(err)) from err
        try:
            self.fleet()
        except InvalidFleetError as err:
            raise CompareError(str(err)) from err
        if self.adaptive_rtf and not self.external:
            raise CompareError('adaptive_rtf needs external: in process, episodes run in '
                               'lockstep')
        unknown = [m for m in self.methods if m not in METHODS]
        if unknown or not self.methods:
            raise CompareError(f'unknown or no methods {unknown}; known: {", ".join(METHODS)}')
        if not self.search_seeds or len(set(self.search_seeds)) != len(self.search_seeds):
            raise CompareError(f'search seeds must be distinct and not empty, got '
                               f'{self.search_seeds}')
        for name in ('budget', 'fresh_episodes', 'population', 'maps_per_member'):
            if getattr(self, name) < 1:
                raise CompareError(f'{name} must be >= 1, got {getattr(self, name)}')
        for name in ('repeats', 'confirm_limit', 'screening_effort'):
            if getattr(self, name) < 0:
                raise CompareError(f'{name} must be >= 0, got {getattr(self, name)}')
        try:
            check_exploration(self.exploration)
        except SearchMethodError as err:
            raise CompareError(str(err)) from err
        if self.seed_schedule not in SEED_SCHEDULES:
            raise CompareError(f'seed schedule must be one of {SEED_SCHEDULES}')
        if 'sessgan' in self.methods and self.budget < self.population * self.maps_per_member:
            raise CompareError(f'a budget of {self.budget} pays for no SESS-GAN generation of '
                               f'{self.population} x {self.maps_per_member} episodes')
        if self.max_fault_records < -1:
            raise CompareError(f'max_fault_records must be >= -1 (-1: every one), got '
                               f'{self.max_fault_records}')
        for name, value in (('search_seeds', min(self.search_seeds)),
                            ('evaluation_seed', self.evaluation_seed)):
            if value < 0:
                raise CompareError(f'{name} must be >= 0, got {value}')
        try:
            check_time_limit(self.time_limit, 'time_limit')
        except InvalidConfigError as err:
            raise CompareError(str(err)) from err
        check_controller(self.scenario, self.controller)
        if self.checkpoint and not Path(self.checkpoint).is_file():
            raise CompareError(f'checkpoint {self.checkpoint!r} does not exist')
        if 'sessgan' in self.methods:
            self.campaign_config(self.search_seeds[0]).validate()
        self.rule().validate()
        if self.width < 0 or self.height < 0:
            raise CompareError(f'width and height must be >= 0 (0: the generator map size), '
                               f'got {self.width}x{self.height}')

    def map_size(self) -> tuple[int, int] | None:
        """(height, width) asked for; None: the generator's own."""
        return (self.height, self.width) if self.height or self.width else None

    def rule(self) -> FaultRule:
        return FaultRule(self.coarse_cells, self.context_cells)

    def mission(self) -> MissionSpec:
        """The mission every map gets (validated: InvalidMissionError names the option)."""
        return MissionSpec(self.mission_stations, self.station_dwell_time).validate()

    def fleet(self) -> FleetSpec:
        """The robots every map gets (validated: InvalidFleetError names the option)."""
        return FleetSpec(self.robots).validate(self.mission_stations)

    def campaign_config(self, seed: int) -> CampaignConfig:
        return CampaignConfig(
            scenario=self.scenario, population=self.population,
            maps_per_member=self.maps_per_member, seed=seed, checkpoint=self.checkpoint,
            controller=self.controller, time_limit=self.time_limit,
            seed_schedule=self.seed_schedule, record_failures=False,
            mission_stations=self.mission_stations, station_dwell_time=self.station_dwell_time,
            robots=self.robots, width=self.width, height=self.height,
            fitness=FitnessConfig())

    def ga_config(self) -> GAConfig:
        return GAConfig(population=self.population)

    def controller_label(self) -> str:
        if self.external:
            return self.controller or 'external'
        return self.controller or get_scenario(self.scenario).controller


def open_evaluator(config: CompareConfig, output: Path, label: str,
                   observer: EpisodeObserver | None = None,
                   log: Callable[[str], None] = print) -> AbstractContextManager[Any]:
    """Where ``compare`` runs its episodes: in process, or with ``external`` on the graph's
    workers (sessgan_evolver.worker_episodes; their bags under <their bags_root>/external/
    <output folder name>/<label>).
    Maps without a certified route are not simulated."""
    if config.external:
        return worker_evaluator(config.scenario, external_record_subdirectory(output, label),
                                output / 'logs' / label, config.controller,
                                config.time_limit, config.mission(), config.fleet(),
                                simulate_invalid=False, observer=observer, log=log,
                                size=config.map_size(), adaptive_rtf=config.adaptive_rtf,
                                collect_into=output / 'worker_bags' / label)
    return InProcessEvaluator(config.scenario, config.controller, config.time_limit,
                              simulate_invalid=False, observer=observer,
                              mission=config.mission(), fleet=config.fleet(), log=log,
                              size=config.map_size())


@dataclass
class RunFigures:
    """One method's run with one search seed."""

    method: str
    search_seed: int
    episodes: int
    valid_maps: int
    valid_failures: int
    distinct_faults: int
    checked_faults: int
    """Distinct faults re-run (all unless confirm_limit)."""
    confirmed_faults: int
    exact_faults: int
    """Checked faults whose every re-run reproduced the metrics exactly."""
    confirmed_per_1000: float
    """Confirmed distinct faults per 1,000 episodes (of the checked ones)."""
    distinct_per_1000: float
    first_confirmed_episode: int | None
    """1-based episode of the first valid failure with a confirmed fault."""
    first_confirmed_wall: float | None
    first_confirmed_cpu: float | None
    search_wall: float
    search_cpu: float
    generator: str
    """The final generator's label ('' for none)."""
    fresh_failure_rate: float | None = None
    fresh_valid_fraction: float | None = None
    failing_tpkl: float | None = None
    failing_uniqueness: float | None = None
    fault_records: list[str] = field(default_factory=list)
    cheap_wall: float = 0.0
    """Wall seconds the method spent on cheap work (screening, surrogate; within
    search_wall)."""
    situations_per_1000: float = 0.0
    """Fault situations of the confirmed faults (maps < 10 % of cells apart: one) per 1,000
    episodes."""
    strict_situations_per_1000: float = 0.0
    """The same with maps < 25 % of cells apart one situation."""

    def row(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        data['fault_records'] = ';'.join(self.fault_records)
        return data


@dataclass
class MethodRun:
    """What a run leaves for the report."""

    figures: RunFigures
    records: list[EpisodeRecord]
    faults: list[FaultEntry]
    source: MapSource | None
    source_key: str


@dataclass
class Comparison:
    config: CompareConfig
    runs: list[MethodRun]
    fresh: dict[str, FreshSeedSummary]
    """Fresh-seed summaries by generator key."""
    report_path: Path
    wall_time: float


def _example_tokens(records: Sequence[EpisodeRecord], faults: Sequence[FaultEntry],
                    scenario: str) -> list[np.ndarray]:
    spec = get_scenario(scenario)
    return [occupancy_to_tokens(records[entry.first].environment.occupancy, spec)
            for entry in faults]


def run_method(config: CompareConfig, method: str, seed: int, output: Path,
               log: Callable[[str], None]) -> MethodRun:
    """One search run, its faults confirmed and recorded."""
    rule = config.rule()
    episode_log = EpisodeLog(rule)
    label = f'{method}-seed{seed}'
    with open_evaluator(config, output, label, episode_log, log) as evaluator:
        episode_log.restart_clock()
        source: MapSource | None
        cheap_wall = 0.0
        if method == 'sessgan':
            search = run_sessgan_search(config.campaign_config(seed), evaluator, config.budget,
                                        output / 'runs', label, log)
            source = campaign_sources(search.run_dir, 'best')[0]
            source_key = f'sessgan:{source.label}'
        else:
            searcher = make_baseline(method, config.scenario, seed, config.checkpoint or None,
                                     config.ga_config(), config.map_size(),
                                     '' if config.external else config.controller,
                                     screening_effort(config.screening_effort,
                                                      config.external, config.scenario),
                                     config.exploration)
            origin = map_origin(checkpoint_metadata(config.scenario, config.checkpoint or None))
            run_search(searcher, evaluator, config.budget, label, origin)
            cheap_wall = float(getattr(searcher, 'cheap_wall_time', 0.0))
            source, source_key = _final_source(config, method)
            if isinstance(searcher, ScreenedSearch) and searcher.parents:
                source = ArchiveSource(searcher, f'screened archive ({label})', origin)
                source_key = f'screened:{label}'
        search_wall = time.perf_counter() - episode_log.started
        search_cpu = time.process_time() - episode_log.cpu_started
        records = episode_log.records
        faults = group_faults([record.fault for record in records])
        checked = faults[:config.confirm_limit] if config.confirm_limit else faults
        written = confirm_faults(checked, records, evaluator, rule, config.repeats,
                                 output / 'faults' / label, config.max_fault_records,
                                 {'method': method, 'search_seed': seed})
    confirmed = [entry for entry in checked
                 if entry.confirmation is not None and entry.confirmation.confirmed]
    exact = [entry for entry in checked if entry.confirmation is not None
             and entry.confirmation.exact == entry.confirmation.repeats]
    first = min(confirmed, key=lambda entry: entry.first, default=None)
    episodes = len(records)
    per_1000 = 1000.0 / episodes if episodes else 0.0
    tokens = _example_tokens(records, faults, config.scenario)
    example = checkpoint_training_map(config.scenario, config.checkpoint or None)
    figures = RunFigures(
        method=method, search_seed=seed, episodes=episodes,
        valid_maps=sum(bool(r.metrics.get('feasible')) for r in records),
        valid_failures=sum(r.valid_failure for r in records), distinct_faults=len(faults),
        checked_faults=len(checked), confirmed_faults=len(confirmed),
        exact_faults=len(exact),
        confirmed_per_1000=per_1000 * len(confirmed), distinct_per_1000=per_1000 * len(faults),
        first_confirmed_episode=None if first is None else first.first + 1,
        first_confirmed_wall=None if first is None else
        records[first.first].elapsed + first.confirmation.wall_time,  # type: ignore[union-attr]
        first_confirmed_cpu=None if first is None else records[first.first].cpu,
        search_wall=search_wall, search_cpu=search_cpu,
        generator=source.label if source is not None else '',
        failing_tpkl=tile_pattern_kl(example, tokens) if tokens else None,
        failing_uniqueness=uniqueness_report(tokens).mean if tokens else None,
        fault_records=[str(path) for path in written], cheap_wall=cheap_wall,
        situations_per_1000=per_1000 * fault_situations(confirmed, records),
        strict_situations_per_1000=per_1000 * fault_situations(confirmed, records,
                                                               STRICT_SITUATION_CELLS))
    log(f'{label}: {episodes} episodes, {figures.valid_failures} valid failures, '
        f'{len(faults)} distinct faults, {len(confirmed)}/{len(checked)} confirmed, '
        f'{search_wall:.0f} s')
    return MethodRun(figures, records, faults, source, source_key)


def fault_situations(faults: Sequence[FaultEntry], records: Sequence[EpisodeRecord],
                     share: float = SITUATION_CELLS) -> int:
    """How many fault situations ``faults`` (in the order found) make: faults of one kind in
    one coarse cell on maps that differ in fewer than ``share`` of their cells are one."""
    situations = SituationArchive(share)
    for entry in faults:
        situations.add(entry.key, records[entry.first].environment.occupancy)
    return len(situations)


def figures_by_origin(runs: Sequence[MethodRun]) -> dict[str, OriginFigures]:
    """Every origin family of ``runs``' episodes (pooled over the runs), with what it gave:
    confirmed faults only, situations by fault_situations's rule in the order found."""
    table: dict[str, OriginFigures] = {}
    for run in runs:
        for record in run.records:
            table.setdefault(origin_family(record.origin), OriginFigures()).episodes += 1
        situations = SituationArchive(SITUATION_CELLS)
        for entry in run.faults:
            if entry.confirmation is None or not entry.confirmation.confirmed:
                continue
            record = run.records[entry.first]
            row = table[origin_family(record.origin)]
            row.faults += 1
            row.situations += situations.add(entry.key, record.environment.occupancy)
    return table


def origin_table(config: CompareConfig, runs: Sequence[MethodRun]) -> str:
    """Markdown: per method and origin of its episodes (fresh samples, children by each
    operator, ...), pooled over the search seeds, the share of episodes that showed a new
    confirmed distinct fault and a new fault situation: where a method's faults come from."""
    lines = ['| method | episodes from | episodes | new confirmed distinct fault | new fault '
             'situation |', '|---|---|---:|---:|---:|']
    for method in config.methods:
        mine = [run for run in runs if run.figures.method == method]
        lines += origin_rows(figures_by_origin(mine), f'{method} | ')
    return '\n'.join(lines)


def _final_source(config: CompareConfig, method: str) -> tuple[MapSource | None, str]:
    label = 'shipped generator' if not config.checkpoint else config.checkpoint
    base = PyramidSource(label, config.scenario, config.checkpoint or None, config.map_size())
    if method in ('random', 'latent', 'screened'):
        return base, 'pyramid:base'
    if method == 'cellular_automaton':
        return (AutomatonSource(config.scenario, reference=base.reference, size=base.size,
                                origin=base.origin), 'cellular_automaton')
    return None, ''


def generator_users(runs: Sequence[MethodRun], source_key: str) -> str:
    """Which runs left the generator ``source_key``, for the console: ' (left by random,
    latent: one evaluation for their 4 runs)'; '' for a generator of one run."""
    users = [run for run in runs if run.source_key == source_key]
    if len(users) < 2:
        return ''
    methods = ', '.join(dict.fromkeys(run.figures.method for run in users))
    return f' (left by {methods}: one evaluation for their {len(users)} runs)'


def fresh_seed_figures(config: CompareConfig, runs: list[MethodRun], output: Path,
                       log: Callable[[str], None]) -> dict[str, FreshSeedSummary]:
    """Evaluate every distinct final generator on one plan of fresh seeds."""
    used_maps = {int(r.environment.seed) for run in runs for r in run.records}
    used_sims = {int(r.sim_seed) for run in runs for r in run.records}
    plan = fresh_seed_plan(config.evaluation_seed, config.fresh_episodes, used_maps, used_sims)
    summaries: dict[str, FreshSeedSummary] = {}
    with open_evaluator(config, output, 'fresh', log=log) as evaluator:
        for run in runs:
            if run.source is None or run.source_key in summaries:
                continue
            result = evaluate_source(run.source, plan, evaluator, config.rule())
            summaries[run.source_key] = result.summary
            rate = result.summary.failure_rate
            log(f'fresh seeds, {run.source.label}{generator_users(runs, run.source_key)}: '
                f'failure rate {"none" if rate is None else f"{rate:.3f}"}, '
                f'{result.summary.valid_maps} valid maps')
    for run in runs:
        summary = summaries.get(run.source_key)
        if summary is not None:
            run.figures.fresh_failure_rate = summary.failure_rate
            run.figures.fresh_valid_fraction = summary.valid_fraction
    write_csv(output / 'fresh_seed.csv', summary_rows(list(summaries.values())))
    (output / 'fresh_seed_plan.txt').write_text(
        f'{len(plan.pairs)} fresh (map seed, simulator seed) pairs from evaluation seed '
        f'{config.evaluation_seed}; {plan.skipped} drawn seeds skipped because a run used '
        f'them; excluded {plan.excluded_map_seeds} map and {plan.excluded_sim_seeds} '
        f'simulator seeds of the runs\n' + '\n'.join(f'{m} {s}' for m, s in plan.pairs) + '\n')
    return summaries


# ---- aggregation and report ---------------------------------------------------------------

REPORTED = (
    ('confirmed_per_1000', 'confirmed distinct faults / 1,000 episodes', '{:.1f}'),
    ('distinct_per_1000', 'distinct faults / 1,000 episodes', '{:.1f}'),
    ('first_confirmed_episode', 'episodes to first confirmed failure', '{:.0f}'),
    ('first_confirmed_wall', 'wall s to first confirmed failure', '{:.1f}'),
    ('fresh_failure_rate', 'fresh-seed failure rate of the final generator', '{:.3f}'),
    ('failing_tpkl', 'TPKL of failing maps', '{:.3f}'),
    ('failing_uniqueness', 'uniqueness of failing maps (%)', '{:.1f}'),
)
"""(RunFigures field, label, format) of the report's table and figure."""

PER_GENERATOR = frozenset({'fresh_failure_rate', 'fresh_valid_fraction'})
"""RunFigures fields that measure a run's final generator, evaluated once per distinct
generator (fresh_seed_figures): runs that leave the same one (random, latent and
cellular_automaton on every seed) share one measurement, counted once."""


def method_values(runs: Sequence[MethodRun], method: str, key: str) -> list[float | None]:
    """``method``'s measurements of the RunFigures field ``key``: one per run, or for a
    figure of the final generator (PER_GENERATOR) one per distinct generator its runs left."""
    chosen = [run for run in runs if run.figures.method == method]
    if key not in PER_GENERATOR:
        return [getattr(run.figures, key) for run in chosen]
    by_generator: dict[str, float | None] = {}
    for run in chosen:
        by_generator.setdefault(run.source_key or f'none:{run.figures.search_seed}',
                                getattr(run.figures, key))
    return list(by_generator.values())


def spread(values: Sequence[float | None]) -> tuple[float | None, float | None, int]:
    """(mean, sample std or None for fewer than 2 values, count) of the non-None values."""
    present = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    if not present:
        return None, None, 0
    std = float(np.std(present, ddof=1)) if len(present) > 1 else None
    return float(np.mean(present)), std, len(present)


def format_spread(values: Sequence[float | None], number_format: str, runs: int = 0) -> str:
    """Mean ± sample std of ``values``; ``runs``: how many runs they come from, when more
    than the measurements (one shared generator: '0.167 (n=1)', no spread)."""
    mean, std, count = spread(values)
    if mean is None:
        return 'none'
    text = number_format.format(mean)
    if std is not None:
        text += ' ± ' + number_format.format(std)
    if count < len(values):
        text += f' ({count}/{len(values)} runs)'
    elif count < runs:
        text += f' (n={count})'
    return text


def method_table(config: CompareConfig, runs: Sequence[MethodRun]) -> str:
    methods = [m for m in config.methods if any(r.figures.method == m for r in runs)]
    lines = ['| | ' + ' | '.join(methods) + ' |', '|---|' + '---:|' * len(methods)]
    run_count = {m: sum(r.figures.method == m for r in runs) for m in methods}
    rows = list(REPORTED) + [('episodes', 'episodes per run', '{:.0f}'),
                             ('valid_failures', 'valid failures (episodes)', '{:.1f}'),
                             ('distinct_faults', 'distinct faults', '{:.1f}'),
                             ('confirmed_faults', 'confirmed distinct faults', '{:.1f}'),
                             ('situations_per_1000', 'fault situations / 1,000 episodes '
                              '(maps < 10 % apart: one)', '{:.1f}'),
                             ('strict_situations_per_1000', 'fault situations / 1,000 '
                              'episodes (maps < 25 % apart: one)', '{:.1f}'),
                             ('search_wall', 'search wall s', '{:.0f}'),
                             ('cheap_wall', 'cheap work wall s (within search)', '{:.1f}'),
                             ('search_cpu', 'search CPU s', '{:.0f}')]
    for key, label, number_format in rows:
        cells = [format_spread(method_values(runs, m, key), number_format, run_count[m])
                 for m in methods]
        lines.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines)


def comparison_figure(config: CompareConfig, runs: Sequence[MethodRun]) -> Any:
    """compare.png's matplotlib figure: per reported figure and method, the mean as a bar,
    every measurement as a dot and, from two on, their min–max as whiskers (never outside
    what the quantity can take, unlike mean ± std of a few seeds)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    methods = [m for m in config.methods if any(r.figures.method == m for r in runs)]
    figure, axes = plt.subplots(2, 4, figsize=(16, 7.5), layout='constrained')
    colours = plt.rcParams['axes.prop_cycle'].by_key()['color']
    for axis, (key, label, _) in zip(axes.flat, REPORTED):
        for index, method in enumerate(methods):
            values = method_values(runs, method, key)
            runs_of_method = sum(r.figures.method == method for r in runs)
            mean, _, count = spread(values)
            colour = colours[index % len(colours)]
            present = [float(v) for v in values if v is not None and math.isfinite(float(v))]
            if mean is not None:
                axis.bar(index, mean, color=colour, alpha=0.6)
            if mean is not None and count > 1:
                axis.errorbar(index, mean, yerr=[[mean - min(present)], [max(present) - mean]],
                              fmt='none', ecolor='black', capsize=4)
            axis.plot([index] * len(present), present, 'o', color='black', markersize=3)
            if count < len(values):
                axis.text(index, 0, f'{count}/{len(values)}', ha='center', va='bottom',
                          fontsize='x-small')
            elif 0 < count < runs_of_method:
                axis.text(index, 0, f'n={count}', ha='center', va='bottom',
                          fontsize='x-small')
        axis.set_xticks(range(len(methods)), methods, rotation=30, fontsize='small')
        axis.set_title(label + (' (dots: generators)' if key in PER_GENERATOR else ''),
                       fontsize='small')
        axis.grid(axis='y', alpha=0.3)
    axes.flat[-1].set_axis_off()
    axes.flat[-1].text(0.0, 0.5, _settings_text(config), fontsize='small', va='center',
                       transform=axes.flat[-1].transAxes)
    figure.suptitle(f'Fault finding on {config.scenario} against '
                    f'{config.controller_label()} over search seeds '
                    f'{list(config.search_seeds)}\nbars: mean; dots: each run (each distinct '
                    'final generator for the fresh-seed rate; n=1: one generator shared by '
                    'every seed); whiskers: min–max')
    return figure


def plot_comparison(config: CompareConfig, runs: Sequence[MethodRun], path: Path) -> Path:
    import matplotlib.pyplot as plt

    figure = comparison_figure(config, runs)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


GA_METHODS = ('grid_ga', 'latent')
"""Baselines whose GA runs with ``population`` (CompareConfig.ga_config)."""


def _settings_text(config: CompareConfig) -> str:
    """The chart's caption: the settings, those of a method only when it was run."""
    ga_methods = [m for m in config.methods if m in GA_METHODS]
    return (f'budget {config.budget} episodes per run\n'
            f'{len(config.search_seeds)} search seeds\n'
            f'{config.repeats} re-runs per distinct fault'
            + (f' (first {config.confirm_limit} per run)' if config.confirm_limit else '')
            + f'\n{config.fresh_episodes} fresh seed pairs per generator\n'
            + (f'SESS-GAN: {config.population} x {config.maps_per_member}, '
               f'{config.seed_schedule} seeds\n' if 'sessgan' in config.methods else '')
            + (f'GA population {config.population} ({", ".join(ga_methods)})\n'
               if ga_methods else '')
            + f'fault cells {config.coarse_cells} (+{config.context_cells} context)')


def example_scenes(config: CompareConfig, runs: Sequence[MethodRun], per_method: int = 4,
                   output: Path | None = None) -> list[tuple[str, list[FaultScene]]]:
    """Up to ``per_method`` confirmed distinct faults per method (seeds in turn), re-run
    with a trace for the picture."""
    rows = []
    with open_evaluator(config, output or Path('.'), 'scenes') as evaluator:
        for method in config.methods:
            method_runs = [r for r in runs if r.figures.method == method]
            if not method_runs:
                continue
            queues = [[e for e in r.faults if e.confirmation and e.confirmation.confirmed]
                      for r in method_runs]
            picked: list[tuple[MethodRun, FaultEntry]] = []
            while len(picked) < per_method and any(queues):
                for run, queue in zip(method_runs, queues):
                    if queue and len(picked) < per_method:
                        picked.append((run, queue.pop(0)))
            scenes = []
            for run, entry in picked:
                record = run.records[entry.first]
                episode = evaluator.runner.run(record.environment, record.sim_seed, trace=True)
                if episode.trace is None:
                    continue  # an external stack that did not fail again: nothing to draw
                scene = scene_from_run(record.environment, episode.trace, episode.metrics,
                                       entry.key, config.rule())
                scene.caption = (f'seed {run.figures.search_seed}: '
                                 f'{entry.key.kind.replace("_", " ")}')
                scenes.append(scene)
            rows.append((method, scenes))
    return rows


GENERATOR_NOTES = {
    'sessgan': 'SESS-GAN runs whole generations of population x K episodes; its final '
               "generator is its last generation's fittest member, one per seed",
    'random': 'random leaves the generator it sampled (weights frozen: the same on every seed)',
    'latent': 'latent leaves the generator whose noise it evolved (weights frozen: the same on '
              'every seed)',
    'screened': 'screened its archive (children of its failing tests, start and goal kept; '
                'the generator when it kept none)',
    'cellular_automaton': 'cellular_automaton its automaton (the same on every seed)',
    'grid_ga': 'grid_ga leaves none',
}
"""What each method leaves for the fresh-seed evaluation, for the report."""


def write_report(config: CompareConfig, runs: Sequence[MethodRun],
                 fresh: dict[str, FreshSeedSummary], output: Path, command: str,
                 wall_time: float) -> Path:
    plot_comparison(config, runs, output / 'compare.png')
    write_scene_grid(example_scenes(config, runs, output=output), output / 'failing_maps.png')
    write_csv(output / 'runs.csv', [run.figures.row() for run in runs])
    write_csv(output / 'faults.csv', [
        {'method': run.figures.method, 'search_seed': run.figures.search_seed,
         'fault': entry.key.label, 'kind': entry.key.kind, 'first_episode': entry.first + 1,
         'occurrences': len(entry.occurrences),
         'environment_id': run.records[entry.first].environment.id,
         'sim_seed': run.records[entry.first].sim_seed,
         'outcome': run.records[entry.first].metrics.get('outcome'),
         'fault_collisions': run.records[entry.first].metrics.get('fault_collisions'),
         'repeats': entry.confirmation.repeats if entry.confirmation else '',
         'reproduced': entry.confirmation.reproduced if entry.confirmation else '',
         'exact': entry.confirmation.exact if entry.confirmation else ''}
        for run in runs for entry in run.faults])
    write_csv(output / 'episodes.csv', [
        {'method': run.figures.method, 'search_seed': run.figures.search_seed,
         'episode': record.index + 1, 'environment_id': record.environment.id,
         'map_seed': record.environment.seed, 'sim_seed': record.sim_seed,
         'feasible': record.metrics.get('feasible'), 'outcome': record.metrics.get('outcome'),
         'fault_collisions': record.metrics.get('fault_collisions'),
         'collisions': record.metrics.get('collisions'),
         'risk_score': record.metrics.get('risk_score'),
         'fault_risk_score': record.metrics.get('fault_risk_score'),
         **navigation_columns(record.metrics),
         'valid_failure': record.valid_failure,
         'fault': record.fault.label if record.fault else '', 'elapsed': record.elapsed,
         'cpu': record.cpu, 'origin': record.origin}
        for run in runs for record in run.records])
    controller = config.controller_label()
    lines = [
        f'# Fault finding: {config.scenario}, {controller}', '',
        f'Command: `{command}`', '',
        f'{len(config.search_seeds)} search seeds {list(config.search_seeds)}, '
        f'{config.budget} episodes per run, '
        + ('on the external workers (one episode at a time), ' if config.external
           else 'in process (lockstep, one core), ') +
        f'{wall_time / 60:.1f} min in all. Mean ± sample std over the seeds; '
        '`(k/n runs)`: only k of n runs had a value; `(n=k)`: k measurements only, because '
        'runs left the same final generator, evaluated once on fresh seeds. The chart: bars '
        'the mean, dots the measurements, whiskers their min–max.', '',
        method_table(config, runs), '',
        '![comparison](compare.png)', '',
        '## Example failing maps (confirmed distinct faults)', '',
        '![failing maps](failing_maps.png)', '',
        '## Where the faults come from', '',
        'Per origin of the episodes, pooled over the search seeds: the share of episodes '
        'that were the first to show a confirmed distinct fault, and a new fault situation '
        f'(< {SITUATION_CELLS:.0%} of cells apart: one).', '',
        origin_table(config, runs), '',
        '## Fresh-seed evaluation of the final generators', '',
        summary_table(list(fresh.values())) if fresh else 'No method left a generator.', '',
        '## How it is counted', '',
        f'* Distinct faults: same kind, same {config.coarse_cells}x{config.coarse_cells}-cell '
        f'coarse cell of the first fault event, same map within {config.context_cells} cells '
        'around it (sessgan_evolver.faults). Confirmed: all '
        f'{config.repeats} re-runs show the same fault'
        + (f'; only the first {config.confirm_limit} faults of each run were re-run'
           if config.confirm_limit else '') + '.',
        '* Every map goes through the same validity certificate; maps without a certified '
        'route are not simulated and still cost one episode.',
        '* Final generators: ' + '; '.join(GENERATOR_NOTES[m] for m in config.methods
                                             if m in GENERATOR_NOTES) + '.',
        '* Files: runs.csv (every run), faults.csv (every distinct fault), episodes.csv '
        '(every episode), fresh_seed.csv, faults/<method>-seed<s>/ (bags and pictures of '
        'confirmed faults)' + (', runs/ (SESS-GAN campaigns)' if 'sessgan' in config.methods
                               else '') + '.',
    ]
    path = output / 'report.md'
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def run_comparison(config: CompareConfig, output: str | Path, command: str = '',
                   log: Callable[[str], None] = print) -> Comparison:
    """Run every method on every seed, evaluate the final generators, write the report."""
    config.validate()
    output = Path(output)
    if (output / 'report.md').exists():
        raise CompareError(f'{output} holds a comparison already: choose another --output')
    output.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    runs = []
    for seed in config.search_seeds:
        for method in config.methods:
            runs.append(run_method(config, method, seed, output, log))
    fresh = fresh_seed_figures(config, runs, output, log)
    wall = time.perf_counter() - started
    report = write_report(config, runs, fresh, output, command, wall)
    return Comparison(config, runs, fresh, report, wall)
