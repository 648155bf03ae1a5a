"""A campaign with an ask/tell search method (``campaign --method random|latent|...``).

The methods of sessgan_evolver.search_methods propose token maps in this process (cheap
work); every proposal becomes an Environment with the validity certificate
(``make_environment``) and one episode of the robot under test, run by the same
:class:`~sessgan_evolver.campaign.Evaluator` as the weight evolution's (the ROS workers or
the in-process runner), with the same failure bags. The budget is the campaign's episodes;
a last batch that would overrun is cut short and not told. Each asked batch is one
'generation' of the run directory: its episode rows, then its generation row (the same
summary as the weight evolution's), so the report and the metrics CSV/JSONL read like any
campaign's; ``evaluate --exclude-run`` keeps its seeds out of a fresh-seed evaluation
(``evaluate --run`` refuses it: it evolves no generator weights).

Each batch's generation row also says how long its cheap work took (``cheap_wall_time``:
asking, certificates, TPKL, telling; wall seconds) beside its episodes
(``episodes_wall_time``).

**Resume is exact, by replay**: a method's state is its seed and everything it was told, so
``--resume`` builds the method afresh, asks again batch by batch and tells it the recorded
results of every complete batch (checking that it proposes the recorded maps, by seeds and
digest), drops the rows of the batch that was cut off, and goes on from there.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sessgan_core.environment import Environment
from sessgan_core.progress import ProgressPrinter, format_duration
from sessgan_core.scenarios import get_scenario
from sessgan_evolver import __version__
from sessgan_evolver.campaign import (
    FEW_VALID_TESTS,
    SESSGAN_METHOD,
    CampaignConfig,
    CampaignResult,
    EpisodeJob,
    Evaluator,
    fmt,
    harness_note,
    harness_notes,
    run_episodes,
)
from sessgan_evolver.errors import CampaignError, FaultError, SearchMethodError
from sessgan_evolver.fault_tally import (
    FaultTally,
    FaultTracker,
    fault_label,
    key_from_label,
    map_digest,
)
from sessgan_evolver.faults import FaultRule
from sessgan_evolver.fitness import generation_summary, member_fitness
from sessgan_evolver.report import report_generations, write_report
from sessgan_evolver.run_store import RunStore
from sessgan_evolver.search_methods import (
    Evaluated,
    GAConfig,
    Proposal,
    SearchMethod,
    make_baseline,
    screening_effort,
)
from sessgan_gen.checkpoint import (
    checkpoint_metadata,
    incomplete_warning,
    map_origin,
    training_map,
)
from sessgan_gen.environment_metrics import (
    tile_pattern_kl,
    tile_pattern_kl_per_k,
    uniqueness_of_fitting_sizes,
)
from sessgan_gen.errors import SessganGenError

SAMPLE_MAPS_PER_BATCH = 4
"""Maps of each batch kept for the report's figure."""


def method_of(config: CampaignConfig) -> SearchMethod:
    """The configured ask/tell method, seeded with the campaign seed; the genetic
    algorithms take the campaign's population, elitism, tournament, crossover and fitness."""
    ga = GAConfig(population=config.population,
                  elite_count=min(config.elite_count, max(config.population - 1, 0)),
                  tournament_size=config.tournament_size,
                  crossover_probability=config.crossover_probability,
                  fitness=config.fitness)
    try:
        return make_baseline(config.method, config.scenario, config.seed,
                             config.checkpoint or None, ga, (config.height, config.width),
                             '' if config.external else config.controller,
                             screening_effort(config.screening_effort, config.external,
                                              config.scenario), config.exploration)
    except SearchMethodError as err:
        raise CampaignError(f'method {config.method}: {err}') from err


class MethodCampaign:
    """One run of an ask/tell method: ``runs/<run>/`` and ``bags/<run>/``, resumable."""

    def __init__(self, config: CampaignConfig, run_name: str, runs_root: Path, bags_root: Path,
                 log: Callable[[str], None] = print,
                 invocation: Mapping[str, Any] | None = None) -> None:
        """Bad settings or an unreadable checkpoint raise before anything is written."""
        config.validate()
        if config.method == SESSGAN_METHOD:
            raise CampaignError('sessgan runs as sessgan_evolver.campaign.Campaign')
        self.config = config
        self.invocation = dict(invocation or {})
        self.scenario = get_scenario(config.scenario)
        self.method = method_of(config)
        # The maps' TPKL reference and origin are the generator's training map's (the
        # shipped checkpoint's, the example map at (0, 0), for a method that needs none).
        try:
            metadata = checkpoint_metadata(self.scenario.name, config.checkpoint or None)
            self.example = training_map(metadata)
            self.origin = map_origin(metadata)
        except SessganGenError as err:
            raise CampaignError(f'checkpoint {config.checkpoint}: {err}') from err
        if config.checkpoint and (warning := incomplete_warning(
                metadata, f'checkpoint {config.checkpoint}')):
            log(f'WARNING: {warning}')
        self.store = RunStore(runs_root, run_name)
        self.bags_dir = Path(bags_root).resolve() / run_name
        self.log = log

    def environment_of(self, proposal: Proposal, environment_id: str, batch: int,
                       member: int) -> Environment:
        return proposal.test_environment(self.scenario.name, environment_id,
                                         self.config.mission(), self.config.fleet(),
                                         self.origin, batch, member)

    # -- resume ---------------------------------------------------------------------------

    def replay(self) -> tuple[int, float | None]:
        """Tell the method every complete batch recorded (module docstring); returns the
        next batch and the TPKL reference."""
        generations = sorted(self.store.read_rows('generation'),
                             key=lambda row: int(row['generation']))
        complete = len(generations)
        if [int(row['generation']) for row in generations] != list(range(complete)):
            raise CampaignError(f'{self.store.run_dir}: the generation rows are not batches '
                                f'0..{complete - 1}; it cannot be resumed')
        self.store.truncate_metrics(complete)
        rows = self.store.read_rows('episode')
        for batch in range(complete):
            proposals = self.method.ask()
            recorded = sorted((row for row in rows if int(row['generation']) == batch),
                              key=lambda row: int(row['member']))
            if not recorded or len(recorded) > len(proposals):
                raise CampaignError(f'batch {batch}: {len(recorded)} episodes recorded, the '
                                    f'method proposes {len(proposals)}; cannot resume exactly')
            results = []
            for member, (proposal, row) in enumerate(zip(proposals, recorded)):
                if (int(row['map_seed']) != proposal.resolved_environment_seed
                        or int(row['sim_seed']) != proposal.sim_seed
                        or row.get('map_digest') != map_digest(proposal.cells)):
                    raise CampaignError(
                        f'batch {batch} episode {member}: the method proposes another map '
                        f'than the one recorded ({row["environment_id"]}); the run was made '
                        'by other software or settings and cannot be resumed exactly')
                environment = self.environment_of(proposal, str(row['environment_id']), batch,
                                                  member)
                try:
                    key = key_from_label(str(row.get('fault') or ''), environment.occupancy,
                                         FaultRule())
                except FaultError as err:
                    raise CampaignError(f'batch {batch} episode {member}: {err}; cannot resume '
                                        'exactly') from err
                results.append(Evaluated(proposal, environment, row, fault_key=key))
            if len(recorded) == len(proposals):
                self.method.tell(results)
        return complete, generations[0].get('tpkl_reference') if generations else None

    def start(self, resume: bool) -> tuple[int, float | None]:
        self.store.write_config(self.config.to_dict(), self.config.seed, __version__,
                                invocation=self.invocation)
        recorded = bool(self.store.read_rows())
        if recorded and not resume:
            raise CampaignError(
                f'run {self.store.run_name!r} exists already: pass --resume to continue it, '
                f'or choose another --run name')
        if not recorded:
            if resume:
                self.log(f'nothing to resume in {self.store.run_dir}: starting at batch 0')
            return 0, None
        batch, reference = self.replay()
        self.log(f'resuming {self.store.run_dir} at batch {batch} (method {self.config.method} '
                 f'told the {batch} batches recorded)')
        return batch, reference

    # -- the loop -------------------------------------------------------------------------

    def run(self, evaluator: Evaluator, resume: bool = False) -> CampaignResult:
        config = self.config
        wall_start = time.monotonic()
        batch, tpkl_reference = self.start(resume)
        budget = config.resolved_budget()
        tracker = FaultTracker()
        tracker.attach(evaluator)
        tally = FaultTally.from_rows(self.store.read_rows('episode'), self.store.situations_path)
        first_episode = tally.episodes
        progress = ProgressPrinter()
        last_maps: list[np.ndarray] = []
        cheap_total = 0.0
        while tally.episodes < budget:
            cheap_start = time.perf_counter()
            proposals = self.method.ask()
            if not proposals:
                raise CampaignError(f'method {config.method!r} proposed no test')
            cut = proposals[:budget - tally.episodes]
            environments = [
                self.environment_of(proposal, f'b{batch:04d}-e{tally.episodes + member:05d}',
                                    batch, member)
                for member, proposal in enumerate(cut)]
            jobs = [EpisodeJob(batch, member, 0, environment, proposal.sim_seed)
                    for member, (proposal, environment) in enumerate(zip(cut, environments))]
            tpkls = [tile_pattern_kl(self.example, [np.asarray(p.cells)]) for p in cut]
            if tpkl_reference is None:
                finite = [t for t in tpkls if math.isfinite(t)]
                tpkl_reference = float(np.mean(finite)) if finite else None
            self.save_sample_maps(batch, [np.asarray(p.cells) for p in cut])
            cheap = time.perf_counter() - cheap_start
            episodes_start = time.perf_counter()
            results, harness_reruns, lost_bags = run_episodes(evaluator, jobs, progress,
                                                              f'batch {batch}', self.log)
            episodes_wall = time.perf_counter() - episodes_start
            missing = [job.key for job in jobs if job.key not in results]
            if missing:
                raise CampaignError(f'batch {batch}: no result for episodes {missing}')
            told, breakdowns = [], []
            for job, proposal, tpkl in zip(jobs, cut, tpkls):
                metrics = results[job.key]
                key = tracker.key_of(job.environment, metrics)
                fault = fault_label(metrics, key)
                new_situation = tally.add(fault, key, job.environment)
                self.store.append_episode({
                    'generation': batch, 'member': job.member, 'map': 0,
                    'episode': tally.episodes, 'environment_id': job.environment.id,
                    'map_seed': job.environment.seed, 'sim_seed': job.seed,
                    'map_digest': map_digest(proposal.cells), 'origin': proposal.origin,
                    'tpkl': tpkl, **metrics, 'fault': fault, 'situation': new_situation})
                told.append(Evaluated(proposal, job.environment, metrics, fault_key=key))
                breakdowns.append(member_fitness([metrics], tpkl, tpkl_reference, None,
                                                 config.fitness))
            tell_start = time.perf_counter()
            if len(cut) == len(proposals):
                self.method.tell(told)
            cheap += time.perf_counter() - tell_start
            cheap_total += cheap
            tally.save_situations(self.store.situations_path)
            summary = {**generation_summary(batch, breakdowns), **tally.columns(),
                       'harness_reruns': harness_reruns, 'lost_bags': lost_bags,
                       'cheap_wall_time': cheap, 'episodes_wall_time': episodes_wall}
            self.store.append_generation(summary)
            elapsed = time.monotonic() - wall_start
            per_episode = elapsed / max(tally.episodes - first_episode, 1)
            self.log(
                f'batch {batch}: {tally.line()} | fault risk '
                f'{fmt(summary["mean_fault_risk_score"])}, risk '
                f'{fmt(summary["mean_risk_score"])}, feasible {summary["feasible_fraction"]:.0%}'
                f', TPKL {fmt(summary["mean_tpkl"])} | {tally.episodes}/{budget} episodes, '
                f'cheap work {cheap_total / max(elapsed, 1e-9):.0%} of the wall time, '
                f'elapsed {format_duration(elapsed)}, ETA '
                f'{format_duration(per_episode * (budget - tally.episodes))}'
                + harness_note(self.store, 'batch'))
            if tally.episodes - len(cut) == first_episode and \
                    summary['feasible_fraction'] < FEW_VALID_TESTS:
                self.log(f'WARNING: only {summary["feasible_fraction"]:.0%} of the maps of '
                         f'batch {batch} are valid tests (hold a route): episodes on the '
                         'others find no fault. Check the map the generator learned (mostly '
                         'wall? passages too narrow for the robot?)')
            last_maps = [np.asarray(p.cells) for p in cut]
            batch += 1
        report_path = self.write_report(batch - 1, last_maps)
        return CampaignResult(self.store.run_dir, self.bags_dir, report_path,
                              self.store.read_rows('generation'),
                              time.monotonic() - wall_start)

    # -- report ---------------------------------------------------------------------------

    def sample_maps_path(self, batch: int) -> Path:
        return self.store.run_dir / 'sample_maps' / f'generation_{batch:04d}.npy'

    def save_sample_maps(self, batch: int, maps: Sequence[np.ndarray]) -> None:
        path = self.sample_maps_path(batch)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.save(path, np.stack(list(maps[:SAMPLE_MAPS_PER_BATCH])))

    def write_report(self, last_batch: int, last_maps: Sequence[np.ndarray]) -> Path:
        maps_by_batch = {}
        for batch in report_generations(max(last_batch, 0)):
            path = self.sample_maps_path(batch)
            if path.exists():
                maps_by_batch[batch] = list(np.load(path))
        if not last_maps and last_batch in maps_by_batch:
            last_maps = maps_by_batch[last_batch]  # a resumed run with nothing left to do
        tpkl_table, uniqueness_table = {}, {}
        for index, cells in enumerate(last_maps[:SAMPLE_MAPS_PER_BATCH]):
            per_k = tile_pattern_kl_per_k(self.example, [cells])
            tpkl_table[f'map {index}'] = {**{f'k={k}': v for k, v in per_k.items()},
                                          'mean': float(np.mean(list(per_k.values())))}
        if last_maps and (unique := uniqueness_of_fitting_sizes(list(last_maps))):
            uniqueness_table['last batch'] = {**{f'{s}x{s}': v for s, v in unique.items()},
                                              'mean': float(np.mean(list(unique.values())))}
        notes = [f'Method `{self.config.method}` (sessgan_evolver.search_methods): each '
                 "'generation' is one batch the method asked for; the maps of the last batch "
                 'are in the TPKL and uniqueness tables.']
        # Only point to the bag folder when a failure was recorded into it.
        notes.append(f'Failure bags: `{self.bags_dir}` (replay one with '
                     '`ros2 run sessgan_evolver replay <bag>`, re-simulate with '
                     '`--resimulate`).'
                     if self.bags_dir.is_dir() and any(self.bags_dir.iterdir()) else
                     'No failure bag was written (no failure was found, or failures were not '
                     'recorded).')
        notes += harness_notes(self.store)
        return write_report(self.store.run_dir, maps_by_batch, tpkl_table, uniqueness_table,
                            title=f'{self.config.method} campaign {self.store.run_name} '
                                  f'({self.config.scenario})',
                            token_names=self.scenario.token_names, notes=notes)
