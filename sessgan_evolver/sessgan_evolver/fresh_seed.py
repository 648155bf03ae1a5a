"""Fresh-seed evaluation: does a generator make failing maps for noise it never saw?

A campaign optimises its members on the seeds of its schedule, so their risk on those seeds
says little about new maps. Here a generator (the shipped checkpoint, a campaign's best
member or whole last population, a user's checkpoint, or the non-learned cellular automaton)
samples N maps from seeds that no given campaign used, and each map is run once with a
simulator seed that no campaign used either:

* map seeds come from stream FRESH_MAPS and simulator seeds from FRESH_SIMULATION of the
  evaluation seed (sessgan_evolver.seeding); any seed that appears among the map or simulator
  seeds of an excluded run's episodes (metrics.jsonl) is skipped, and how many were skipped
  is reported;
* every source sees the same seed pairs, so generators are compared on common random numbers.

Per source: valid maps (certified route), valid failures (controller failures,
sessgan_evolver.faults), failure rate = valid failures / valid maps, mean fault collisions,
risk (the paper's) and fault risk over valid maps, TPKL of all its maps to the example map,
their uniqueness (None, not applicable, for a patch side larger than the maps), the distinct
faults among them, and the episodes the test harness ended and ran again (harness re-runs:
never results, sessgan_evolver.harness).
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from sessgan_core.environment import Environment
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.cellular_automaton import CellularAutomatonGenerator
from sessgan_evolver.errors import FreshSeedError, RunStoreError
from sessgan_evolver.faults import FaultEntry, FaultRule, group_faults
from sessgan_evolver.genome import Genome
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.run_store import RunStore
from sessgan_evolver.search import EpisodeLog, EpisodeRecord
from sessgan_evolver.seeding import SeedStream, shared_seeds
from sessgan_gen.checkpoint import (
    checkpoint_bytes,
    default_checkpoint_path,
    load_checkpoint,
    map_origin,
    training_map,
)
from sessgan_gen.environment_metrics import (
    DEFAULT_UNIQUENESS_SIZES,
    tile_pattern_kl,
    uniqueness_report,
)
from sessgan_gen.environment_sampler import resolve_sample_size
from sessgan_gen.errors import SamplingRequestError
from sessgan_gen.sampling import sample_token_maps
from sessgan_gen.track_cleanup import clean_generated_maps
from sessgan_sim.metrics import NAVIGATION_COLUMNS, navigation_columns


class MapSource(Protocol):
    """Something that turns seeds into token maps."""

    label: str
    reference: np.ndarray
    """The token map its TPKL is measured against: the map the generator learned."""
    origin: tuple[float, float]
    """Map-frame position of its maps' cell (0, 0): the generator's training map's
    (sessgan_gen.checkpoint.map_origin), so episodes and bags overlay that map."""

    def maps(self, seeds: Sequence[int]) -> np.ndarray:
        """Token maps (len(seeds), height, width), map i from seeds[i] alone."""
        ...


@runtime_checkable
class EnvironmentSource(Protocol):
    """A source that makes whole tests (map, start and goal) from seeds, not only maps (the
    screened search's archive keeps the start and goal its failures had)."""

    label: str
    reference: np.ndarray
    origin: tuple[float, float]

    def maps(self, seeds: Sequence[int]) -> np.ndarray: ...

    def environments(self, seeds: Sequence[int]) -> list[tuple[np.ndarray, Environment]]:
        """(token map, Environment) of each seed, from that seed alone."""
        ...


class PyramidSource:
    """A generator checkpoint (a path, checkpoint bytes, or None for the shipped one)."""

    def __init__(self, label: str, scenario: str, checkpoint: str | Path | bytes | None = None,
                 size: tuple[int, int] | None = None) -> None:
        """``size``: (height, width) of its maps; None or a zero side: the map it learned."""
        self.label = label
        self.scenario = scenario
        source = checkpoint or default_checkpoint_path(scenario)
        self.pyramid, self.metadata = load_checkpoint(source, scenario=scenario)
        self.reference = training_map(self.metadata)
        self.origin = map_origin(self.metadata)
        try:
            self.size = resolve_sample_size(self.pyramid, self.metadata, size, scenario)
        except SamplingRequestError as err:
            raise FreshSeedError(f'{label}: {err}') from err

    def maps(self, seeds: Sequence[int]) -> np.ndarray:
        """The maps the generator node would serve for ``seeds`` (the scenario's
        track_cleanup applied, as the sampler does)."""
        return clean_generated_maps(
            sample_token_maps(self.pyramid, [int(s) for s in seeds], self.size), self.scenario)


class PopulationSource:
    """A population as one generator: map i comes from member i mod n (a member drawn in
    turn), so N fresh maps cost N episodes whatever the population's size."""

    def __init__(self, label: str, members: Sequence[PyramidSource]) -> None:
        if not members:
            raise FreshSeedError('a population needs at least one member')
        self.label = label
        self.members = list(members)
        self.reference = self.members[0].reference
        self.origin = self.members[0].origin

    def maps(self, seeds: Sequence[int]) -> np.ndarray:
        count = len(self.members)
        if not seeds:
            return self.members[0].maps([])
        rows = [self.members[index % count].maps([seed])[0] for index, seed in enumerate(seeds)]
        return np.stack(rows)


class AutomatonSource:
    """The BARN-style cellular automaton (sessgan_evolver.cellular_automaton)."""

    def __init__(self, scenario: str, label: str = 'cellular automaton',
                 reference: np.ndarray | None = None,
                 size: tuple[int, int] | None = None,
                 origin: tuple[float, float] = (0.0, 0.0)) -> None:
        """``reference``: the map its TPKL is measured against (default: the scenario's
        example map); give the training map of the generators it is compared with, their
        map ``size`` (height, width; default the scenario's) and map ``origin``."""
        self.label = label
        self.generator = CellularAutomatonGenerator(scenario, size=size)
        self.reference = (load_example_map(scenario).cells if reference is None
                          else np.asarray(reference))
        self.origin = origin

    def maps(self, seeds: Sequence[int]) -> np.ndarray:
        return self.generator.maps([int(s) for s in seeds])


# ---- campaigns -------------------------------------------------------------------------------


def open_run(run_dir: str | Path) -> RunStore:
    run_dir = Path(run_dir)
    if not (run_dir / 'config.json').is_file():
        raise FreshSeedError(f'{run_dir} is not a campaign run (it has no config.json)')
    return RunStore(run_dir.parent, run_dir.name)


def used_seeds(run_dirs: Iterable[str | Path]) -> tuple[set[int], set[int]]:
    """(map seeds, simulator seeds) of every episode the runs recorded."""
    map_seeds: set[int] = set()
    sim_seeds: set[int] = set()
    for run_dir in run_dirs:
        store = open_run(run_dir)
        try:
            rows = store.read_rows('episode')
        except RunStoreError as err:
            raise FreshSeedError(f'cannot read the episodes of {run_dir}: {err}') from err
        for row in rows:
            if row.get('map_seed') is not None:
                map_seeds.add(int(row['map_seed']))
            if row.get('sim_seed') is not None:
                sim_seeds.add(int(row['sim_seed']))
    return map_seeds, sim_seeds


@dataclass(frozen=True)
class SeedPlan:
    """The fresh (map seed, simulator seed) pairs of an evaluation."""

    pairs: list[tuple[int, int]]
    skipped: int
    """Seeds drawn but skipped because an excluded run used them."""
    excluded_map_seeds: int
    excluded_sim_seeds: int


def fresh_seed_plan(evaluation_seed: int, count: int, exclude_maps: Collection[int] = (),
                    exclude_sims: Collection[int] = ()) -> SeedPlan:
    """``count`` seed pairs from the evaluation seed, disjoint from the excluded seeds."""
    if count < 1:
        raise FreshSeedError(f'the number of fresh maps must be >= 1, got {count}')
    exclude_maps, exclude_sims = set(exclude_maps), set(exclude_sims)
    pairs: list[tuple[int, int]] = []
    skipped = 0
    batch = 0
    while len(pairs) < count:
        # Further draws (another 'generation' of the stream) in the unlikely case of clashes.
        map_seeds = shared_seeds(evaluation_seed, batch, count, SeedStream.FRESH_MAPS)
        sim_seeds = shared_seeds(evaluation_seed, batch, count, SeedStream.FRESH_SIMULATION)
        for map_seed, sim_seed in zip(map_seeds, sim_seeds):
            if map_seed in exclude_maps or sim_seed in exclude_sims:
                skipped += 1
            elif len(pairs) < count:
                pairs.append((map_seed, sim_seed))
        batch += 1
    return SeedPlan(pairs, skipped, len(exclude_maps), len(exclude_sims))


def check_disjoint(plan: SeedPlan, run_dirs: Iterable[str | Path]) -> None:
    """FreshSeedError if any seed of ``plan`` was used by one of the runs."""
    map_seeds, sim_seeds = used_seeds(run_dirs)
    clashes = [pair for pair in plan.pairs if pair[0] in map_seeds or pair[1] in sim_seeds]
    if clashes:
        raise FreshSeedError(f'{len(clashes)} seed pairs were used by the runs, e.g. '
                             f'{clashes[0]}')


def last_evaluated_generation(store: RunStore) -> int:
    """The last generation with member rows (its population is the run's final one)."""
    generations = [int(row['generation']) for row in store.read_rows('member')]
    if not generations:
        raise FreshSeedError(f'run {store.run_dir} has no evaluated generation yet')
    return max(generations)


def campaign_sources(run_dir: str | Path, member: str = 'best',
                     size: tuple[int, int] | None = None) -> list[PyramidSource]:
    """Generators of a campaign's last evaluated population: ``member`` is 'best' (the
    fittest member of that generation), 'final' (every member) or a member index; their maps
    are of ``size`` (height, width), by default of the campaign's."""
    store = open_run(run_dir)
    config = store.read_config()['config']
    scenario = str(config['scenario'])
    method = str(config.get('method') or 'sessgan')
    if method != 'sessgan':
        checkpoint = config.get('checkpoint')
        sampled = f'--checkpoint {checkpoint}' if checkpoint else '--shipped'
        raise FreshSeedError(
            f'run {store.run_dir} is a {method} campaign: it evolves no generator weights to '
            f'evaluate; evaluate the generator it sampled ({sampled}) and pass the run as '
            '--exclude-run so its seeds are not reused')
    generation = last_evaluated_generation(store)
    rows = [row for row in store.read_rows('member') if int(row['generation']) == generation]
    state = store.load_checkpoint(generation)['algorithm']
    genomes = [Genome.from_plain(plain) for plain in state['population']]
    if member == 'best':
        fitness_key = 'selection_fitness' if 'selection_fitness' in rows[0] else 'fitness'
        best = max(rows, key=lambda row: (row[fitness_key] if row[fitness_key] is not None
                                          else -math.inf, -int(row['member'])))
        chosen = [int(best['member'])]
    elif member == 'final':
        chosen = list(range(len(genomes)))
    else:
        try:
            chosen = [int(member)]
        except ValueError as err:
            raise FreshSeedError(f"member must be 'best', 'final' or an index, got "
                                 f'{member!r}') from err
        if not 0 <= chosen[0] < len(genomes):
            raise FreshSeedError(f'run {store.run_dir} has members 0..{len(genomes) - 1}, not '
                                 f'{chosen[0]}')
    base = config.get('checkpoint') or default_checkpoint_path(scenario)
    pyramid, metadata = load_checkpoint(base, scenario=scenario)
    template = {key: value.clone() for key, value in pyramid.state_dict().items()}
    sources = []
    for index in chosen:
        pyramid.load_state_dict(genomes[index].to_state_dict(template))
        weights = checkpoint_bytes(pyramid, metadata)
        sources.append(PyramidSource(
            f'{store.run_name} g{generation} m{index}', scenario, weights,
            size or (int(config.get('height', 0)), int(config.get('width', 0)))))
    return sources


# ---- evaluation ------------------------------------------------------------------------------


@dataclass
class FreshSeedSummary:
    """One generator's figures (module docstring)."""

    generator: str
    maps: int
    valid_maps: int
    valid_fraction: float
    valid_failures: int
    failure_rate: float | None
    """Valid failures / valid maps (None without a valid map)."""
    mean_fault_collisions: float | None
    """Contacts the robot caused, mean over valid maps."""
    mean_collisions: float | None
    """Every contact event, mean over valid maps."""
    mean_risk: float | None
    """The paper's risk score, mean over valid maps."""
    mean_fault_risk: float | None
    """Fault risk score, mean over valid maps."""
    tpkl: float
    """Of all its maps to the map its generator learned (``MapSource.reference``), nats."""
    uniqueness: float | None
    """Mean of the 8x8 and 16x16 uniqueness of all its maps, percent; None (not applicable)
    when its maps are smaller than 16 cells a side (no 16x16 patch)."""
    distinct_faults: int
    wall_time: float
    """Wall seconds of its episodes."""
    uniqueness_8x8: float | None = None
    """8x8 uniqueness of all its maps, percent (None: the maps hold no 8x8 patch)."""
    uniqueness_16x16: float | None = None
    """16x16 uniqueness of all its maps, percent (None: the maps hold no 16x16 patch)."""
    harness_reruns: int = 0
    """Its episodes the test harness ended (a silent controller, a dead process) and ran
    again: never results (sessgan_evolver.harness). ``evaluate`` adds those of the re-runs
    that confirm its faults."""


@dataclass
class FreshSeedResult:
    summary: FreshSeedSummary
    records: list[EpisodeRecord]
    faults: list[FaultEntry] = field(default_factory=list)
    harness_reruns: list[int] = field(default_factory=list)
    """Harness re-runs of each record's episode (records' order; empty: not counted)."""


def _optional(value: float) -> float | None:
    """A figure that may be NaN (not applicable) as None."""
    return None if math.isnan(value) else float(value)


def harness_reruns_of(evaluator: object) -> int:
    """The evaluator's harness re-runs so far (0 for one that does not count them)."""
    return int(getattr(evaluator, 'harness_reruns', 0) or 0)


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def evaluate_source(source: MapSource, plan: SeedPlan, evaluator: InProcessEvaluator,
                    rule: FaultRule | None = None,
                    progress: Callable[[int, int], None] | None = None) -> FreshSeedResult:
    """Run every fresh seed pair of ``plan`` on ``source``'s maps."""
    log = EpisodeLog(rule)
    observer, evaluator.observer = evaluator.observer, log
    harness_reruns: list[int] = []
    started = time.perf_counter()
    try:
        map_seeds = [map_seed for map_seed, _ in plan.pairs]
        plain = not evaluator.mission.stations and evaluator.fleet.robots == 1
        if isinstance(source, EnvironmentSource) and plain:
            tests = source.environments(map_seeds)
            maps = [cells for cells, _ in tests]
            environments = [replace(environment, id=f'fresh-{index:04d}-s{map_seed}')
                            .moved_to(source.origin)
                            for index, (map_seed, (_, environment))
                            in enumerate(zip(map_seeds, tests))]
        else:
            maps = list(source.maps(map_seeds))
            environments = [make_environment(cells, evaluator.scenario,
                                             f'fresh-{index:04d}-s{map_seed}', seed=map_seed,
                                             mission=evaluator.mission, fleet=evaluator.fleet,
                                             origin=source.origin)
                            for index, (map_seed, cells) in enumerate(zip(map_seeds, maps))]
        for index, ((_, sim_seed), environment) in enumerate(zip(plan.pairs, environments)):
            reruns_before = harness_reruns_of(evaluator)
            evaluator.run_environment(environment, sim_seed, source.label)
            harness_reruns.append(harness_reruns_of(evaluator) - reruns_before)
            if progress is not None:
                progress(index + 1, len(plan.pairs))
    finally:
        evaluator.observer = observer
    wall = time.perf_counter() - started
    records = log.records
    valid = [record for record in records if record.metrics.get('feasible')]
    failures = [record for record in valid if record.valid_failure]
    example = source.reference
    token_maps = [np.asarray(m) for m in maps]
    faults = group_faults([record.fault for record in records])
    unique = uniqueness_report(token_maps, DEFAULT_UNIQUENESS_SIZES)
    summary = FreshSeedSummary(
        generator=source.label, maps=len(records), valid_maps=len(valid),
        valid_fraction=len(valid) / len(records) if records else 0.0,
        valid_failures=len(failures),
        failure_rate=len(failures) / len(valid) if valid else None,
        mean_fault_collisions=_mean([float(r.metrics['fault_collisions']) for r in valid]),
        mean_collisions=_mean([float(r.metrics['collisions']) for r in valid]),
        mean_risk=_mean([float(r.metrics['risk_score']) for r in valid]),
        mean_fault_risk=_mean([float(r.metrics['fault_risk_score']) for r in valid]),
        tpkl=tile_pattern_kl(example, token_maps),
        uniqueness=_optional(unique.mean), distinct_faults=len(faults), wall_time=wall,
        uniqueness_8x8=_optional(unique.per_size[8]),
        uniqueness_16x16=_optional(unique.per_size[16]),
        harness_reruns=sum(harness_reruns))
    return FreshSeedResult(summary, records, faults, harness_reruns)


EPISODE_COLUMNS = ('generator', 'index', 'environment_id', 'map_seed', 'sim_seed', 'feasible',
                   'route_length', 'route_min_clearance', 'outcome', 'detail',
                   'fault_collisions',
                   'collisions', 'proximity_time', 'simulation_time', 'risk_score',
                   'fault_risk_score', *NAVIGATION_COLUMNS, 'invalid_commands',
                   'valid_failure', 'fault', 'harness_reruns', 'wall_time')


def episode_rows(result: FreshSeedResult) -> list[dict[str, Any]]:
    """Per-map rows of one generator (EPISODE_COLUMNS): ``invalid_commands`` counts the
    commands with a NaN or infinite component that the simulator replaced by a stop;
    ``harness_reruns`` the tries of the episode the harness ended before its result."""
    rows = []
    reruns: Sequence[int | None] = result.harness_reruns
    if len(reruns) != len(result.records):  # not counted per episode: left empty
        reruns = [None] * len(result.records)
    for record, harness_reruns in zip(result.records, reruns):
        metrics = record.metrics
        rows.append({
            'generator': result.summary.generator, 'index': record.index,
            'environment_id': record.environment.id, 'map_seed': record.environment.seed,
            'sim_seed': record.sim_seed, 'feasible': bool(metrics.get('feasible')),
            'route_length': record.environment.route_length,
            'route_min_clearance': record.environment.route_min_clearance,
            'outcome': metrics.get('outcome'),
            # Why it ended, or why its map is no valid test (a fleet's names the robot).
            'detail': metrics.get('detail'),
            'fault_collisions': metrics.get('fault_collisions'),
            'collisions': metrics.get('collisions'),
            'proximity_time': metrics.get('proximity_time'),
            'simulation_time': metrics.get('simulation_time'),
            'risk_score': metrics.get('risk_score'),
            'fault_risk_score': metrics.get('fault_risk_score'),
            **navigation_columns(metrics),
            'invalid_commands': metrics.get('invalid_commands'),
            'valid_failure': record.valid_failure,
            'fault': record.fault.label if record.fault else '',
            'harness_reruns': harness_reruns,
            'wall_time': metrics.get('wall_time')})
    return rows


def write_csv(path: str | Path, rows: Sequence[Mapping[str, Any]],
              columns: Sequence[str] | None = None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = list(columns or (rows[0].keys() if rows else []))
    with path.open('w', newline='', encoding='utf-8') as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction='ignore',
                                lineterminator='\n')
        writer.writeheader()
        for row in rows:
            writer.writerow({key: '' if row.get(key) is None else row.get(key)
                             for key in columns})
    return path


def _format(value: Any, digits: int = 3) -> str:
    if value is None:
        return '–'
    if isinstance(value, float):
        return f'{value:.{digits}f}'
    return str(value)


def summary_table(summaries: Sequence[FreshSeedSummary]) -> str:
    """The summaries as a GitHub markdown table."""
    lines = ['| generator | maps | valid | valid failures | failure rate | fault collisions | '
             'risk | fault risk | TPKL | uniqueness (%) | distinct faults |',
             '|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|']
    for s in summaries:
        lines.append(
            f'| {s.generator} | {s.maps} | {s.valid_maps} ({s.valid_fraction:.0%}) | '
            f'{s.valid_failures} | {_format(s.failure_rate)} | '
            f'{_format(s.mean_fault_collisions, 2)} | {_format(s.mean_risk)} | '
            f'{_format(s.mean_fault_risk)} | {s.tpkl:.3f} | '
            f'{"n/a" if s.uniqueness is None else f"{s.uniqueness:.2f}"} | '
            f'{s.distinct_faults} |')
    return '\n'.join(lines)


def summary_rows(summaries: Sequence[FreshSeedSummary]) -> list[dict[str, Any]]:
    return [asdict(summary) for summary in summaries]
