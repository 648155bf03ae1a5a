"""The search driver: every method's episodes, at equal budget, through one episode runner.

:func:`run_search` runs a baseline (sessgan_evolver.search_methods) until ``budget`` episodes
have run; :func:`run_sessgan_search` runs SESS-GAN's real Campaign with as many generations
as the budget pays for. Both go through an
:class:`~sessgan_evolver.in_process.InProcessEvaluator` whose observer is an
:class:`EpisodeLog`, so every method's episodes are recorded the same way: the Environment,
the simulator seed, the metrics, the fault key of a valid failure and the wall time since
the search began.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sessgan_core.environment import Environment
from sessgan_evolver.campaign import Campaign, CampaignConfig
from sessgan_evolver.episode_runner import EpisodeRun
from sessgan_evolver.errors import SearchError
from sessgan_evolver.faults import FaultKey, FaultRule, is_valid_failure, key_of_failure
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.search_methods import Evaluated, SearchMethod


@dataclass
class EpisodeRecord:
    """One episode of a search."""

    index: int
    """0-based position in the search's episode order."""
    environment: Environment
    sim_seed: int
    metrics: dict[str, Any]
    fault: FaultKey | None
    """The fault key of a valid failure, else None."""
    elapsed: float
    """Wall seconds from the start of the search to the end of this episode."""
    origin: str
    cpu: float = 0.0
    """CPU seconds of this process from the start of the search to the end of this episode
    (on a shared machine less noisy than wall time)."""

    @property
    def valid_failure(self) -> bool:
        return is_valid_failure(self.metrics)


class EpisodeLog:
    """Records every episode an InProcessEvaluator runs (use it as the observer)."""

    def __init__(self, rule: FaultRule | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.rule = rule or FaultRule()
        self.clock = clock
        self.records: list[EpisodeRecord] = []
        self.restart_clock()

    def restart_clock(self) -> None:
        self.started = self.clock()
        self.cpu_started = time.process_time()

    def __call__(self, environment: Environment, seed: int, run: EpisodeRun,
                 origin: str) -> None:
        key = key_of_failure(environment, run.metrics, run.trace, self.rule)
        self.records.append(EpisodeRecord(
            len(self.records), environment, int(seed), dict(run.metrics), key,
            self.clock() - self.started, origin, time.process_time() - self.cpu_started))


def run_search(method: SearchMethod, evaluator: InProcessEvaluator, budget: int,
               run_label: str = '', origin: tuple[float, float] = (0.0, 0.0)) -> int:
    """Ask, run and tell until ``budget`` episodes have run (a last batch that would
    overrun is cut short and not told). Returns the episodes run. Each proposal is run on
    the Environment :meth:`Proposal.test_environment` gives, with the map at ``origin`` (the
    generator's training map's)."""
    if budget < 1:
        raise SearchError(f'the episode budget must be >= 1, got {budget}')
    label = run_label or method.name
    done = 0
    while done < budget:
        proposals = method.ask()
        if not proposals:
            raise SearchError(f'method {method.name!r} proposed no test')
        batch = proposals[:budget - done]
        results = []
        for proposal in batch:
            environment_id = f'{label}-e{done:05d}'
            environment = proposal.test_environment(evaluator.scenario, environment_id,
                                                    evaluator.mission, evaluator.fleet, origin)
            run = evaluator.run_environment(environment, proposal.sim_seed, proposal.origin)
            results.append(Evaluated(proposal, environment, run.metrics, run.trace))
            done += 1
        if len(batch) < len(proposals):
            break
        method.tell(results)
    return done


@dataclass(frozen=True)
class SessganSearch:
    """What a SESS-GAN search left: its run directory and the episodes it ran."""

    run_dir: Path
    generations: int
    episodes: int


def sessgan_config_for_budget(base: CampaignConfig, budget: int) -> CampaignConfig:
    """``base`` with the most generations ``budget`` episodes pay for (population x K
    episodes each; SearchError when not even one)."""
    per_generation = base.population * base.maps_per_member
    generations = budget // per_generation
    if generations < 1:
        raise SearchError(f'a budget of {budget} episodes pays for no SESS-GAN generation '
                          f'({base.population} members x {base.maps_per_member} maps = '
                          f'{per_generation} episodes each)')
    return dataclasses.replace(base, generations=generations, workers=1)


def run_sessgan_search(base: CampaignConfig, evaluator: InProcessEvaluator, budget: int,
                       runs_root: Path, run_name: str,
                       log: Callable[[str], None] = lambda _: None) -> SessganSearch:
    """SESS-GAN's Campaign, in process, for ``budget`` episodes (rounded down to whole
    generations)."""
    config = sessgan_config_for_budget(base, budget)
    before = evaluator.episodes
    campaign = Campaign(config, run_name, runs_root, runs_root / 'bags', log)
    result = campaign.run(evaluator)
    return SessganSearch(result.run_dir, config.generations, evaluator.episodes - before)
