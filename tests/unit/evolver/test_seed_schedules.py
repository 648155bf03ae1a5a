"""Seed schedules of a campaign: fixed, per-generation and rotating (elites selected on the
mean of all their evaluations), resumable."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sessgan_evolver.campaign import Campaign, CampaignConfig, CampaignError
from sessgan_evolver.genome import Genome
from sessgan_evolver.in_process import InProcessEvaluator

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


class Interrupted(Exception):
    pass


class InterruptedEvaluator(InProcessEvaluator):
    def __init__(self, generation: int) -> None:
        super().__init__('factory', time_limit=2.0)
        self.stop_at = generation

    def evaluate(self, jobs, on_result):
        if jobs and jobs[0].generation == self.stop_at:
            raise Interrupted()
        super().evaluate(jobs, on_result)


def config(**overrides) -> CampaignConfig:
    values = dict(generations=4, population=3, maps_per_member=1, seed=2, time_limit=2.0,
                  record_failures=False, seed_schedule='rotating', seed_pool=2)
    values.update(overrides)
    return CampaignConfig(**values)


def test_which_seeds_each_schedule_uses():
    rotating = config(maps_per_member=2, seed_pool=4)
    seeds = [rotating.generation_seeds(g) for g in range(3)]
    pool = seeds[0][0] + seeds[1][0]
    assert len(set(pool)) == 4 and seeds[2] == seeds[0]
    assert seeds[0][0] != seeds[0][1]  # map and simulator seeds are different streams
    fixed = config(seed_schedule='fixed')
    assert fixed.generation_seeds(0) == fixed.generation_seeds(5)
    per_generation = config(seed_schedule='per-generation')
    assert per_generation.generation_seeds(0) != per_generation.generation_seeds(1)
    assert config(seed_pool=0).resolved_seed_pool() == 4
    with pytest.raises(CampaignError, match='seed schedule'):
        config(seed_schedule='sometimes').validate()
    with pytest.raises(CampaignError, match='seed pool'):
        config(maps_per_member=3, seed_pool=2).validate()


@pytest.fixture(scope='module')
def straight(tmp_path_factory) -> Campaign:
    """An uninterrupted rotating campaign (config()), run once for the tests that read it."""
    root = tmp_path_factory.mktemp('straight')
    campaign = Campaign(config(), 'straight', root / 'runs', root / 'bags', log=lambda _: None)
    with InProcessEvaluator('factory', time_limit=2.0) as evaluator:
        campaign.run(evaluator)
    return campaign


def test_rotating_elites_are_selected_on_all_their_evaluations(straight):
    store = straight.store
    rows = store.read_rows('member')
    history: dict[str, list[float]] = {}
    repeated = 0
    for generation in range(4):
        population = store.load_checkpoint(generation)['algorithm']['population']
        for member, plain in enumerate(population):
            row = next(r for r in rows if r['generation'] == generation and
                       r['member'] == member)
            fitnesses = history.setdefault(Genome.from_plain(plain).digest(), [])
            fitnesses.append(row['fitness'])
            assert row['evaluations'] == len(fitnesses)
            assert row['selection_fitness'] == pytest.approx(np.mean(fitnesses))
            repeated += len(fitnesses) > 1
    assert repeated >= 3  # the elite of every generation after the first


def test_a_resumed_rotating_campaign_gives_the_uninterrupted_results(straight, tmp_path):
    with pytest.raises(Interrupted):
        Campaign(config(), 'killed', tmp_path / 'runs', tmp_path / 'bags',
                 log=lambda _: None).run(InterruptedEvaluator(3))
    resumed = Campaign(config(), 'killed', tmp_path / 'runs', tmp_path / 'bags',
                       log=lambda _: None)
    with InProcessEvaluator('factory', time_limit=2.0) as evaluator:
        resumed.run(evaluator, resume=True)

    def members(store):
        return [{k: v for k, v in row.items() if k != 'wall_time'}
                for row in store.read_rows('member')]

    assert members(resumed.store) == members(straight.store)
