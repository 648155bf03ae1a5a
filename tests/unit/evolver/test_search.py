"""The search driver at equal budget, SESS-GAN's campaign as a search, the episode log."""

from __future__ import annotations

import pytest
import torch

from sessgan_evolver.campaign import CampaignConfig
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.search import (
    EpisodeLog,
    SearchError,
    run_search,
    run_sessgan_search,
    sessgan_config_for_budget,
)
from sessgan_evolver.search_methods import CellularAutomatonSampling, GAConfig, GridGA

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


class Counting:
    """Wraps a method and counts what it was told."""

    def __init__(self, method):
        self.method, self.name, self.told = method, method.name, []

    def ask(self):
        return self.method.ask()

    def tell(self, results):
        self.told.append(len(results))
        self.method.tell(results)


def test_a_search_stops_at_its_budget_and_logs_every_episode():
    log = EpisodeLog()
    method = Counting(GridGA('factory', 0, GAConfig(population=3)))
    with InProcessEvaluator('factory', time_limit=1.0, simulate_invalid=False,
                            observer=log) as evaluator:
        assert run_search(method, evaluator, budget=4) == 4
    # 3 in generation 0, then 1 of the 2 children of generation 1 (the elite is not re-run):
    # the cut batch is not told.
    assert method.told == [3]
    assert [record.index for record in log.records] == [0, 1, 2, 3]
    assert [record.environment.id for record in log.records][:2] == ['grid_ga-e00000',
                                                                     'grid_ga-e00001']
    assert all(r.elapsed >= 0 and r.origin.startswith('generation') for r in log.records)
    elapsed = [r.elapsed for r in log.records]
    assert elapsed == sorted(elapsed)
    for record in log.records:
        assert (record.fault is not None) == record.valid_failure
    with pytest.raises(SearchError, match='budget'):
        run_search(CellularAutomatonSampling('factory', 0), evaluator, 0)


def test_sessgan_runs_the_real_campaign_for_whole_generations(tmp_path):
    base = CampaignConfig(population=2, maps_per_member=2, seed=4, time_limit=1.0,
                          record_failures=False)
    assert sessgan_config_for_budget(base, 9).generations == 2
    with pytest.raises(SearchError, match='no SESS-GAN generation'):
        sessgan_config_for_budget(base, 3)
    log = EpisodeLog()
    with InProcessEvaluator('factory', time_limit=1.0, observer=log) as evaluator:
        search = run_sessgan_search(base, evaluator, 9, tmp_path, 'sessgan-test')
    assert search.generations == 2 and search.episodes == 8 == len(log.records)
    assert (search.run_dir / 'metrics_episodes.csv').exists()
    assert log.records[0].origin == 'generation 0 member 0'
    assert log.records[-1].environment.id.startswith('factory-g001-m01-')


def test_a_search_draws_the_evaluators_fleet_and_runs_a_methods_own_environment():
    from sessgan_core.fleet import FleetSpec
    from sessgan_evolver.screened_search import ScreenedConfig, ScreenedSearch
    from sessgan_evolver.search_methods import RandomSampling

    log = EpisodeLog()
    with InProcessEvaluator('factory', time_limit=0.5, simulate_invalid=False,
                            observer=log, fleet=FleetSpec(2)) as evaluator:
        run_search(RandomSampling('factory', 0, batch=3), evaluator, budget=3)
    feasible = [r.environment for r in log.records if r.environment.feasible]
    assert feasible and all(environment.robots == 2 for environment in feasible)
    # A method that builds its Environments (the screened search) has them run as built.
    method = ScreenedSearch('factory', 1, config=ScreenedConfig(batch=2, reference_maps=2))
    log = EpisodeLog()
    with InProcessEvaluator('factory', time_limit=0.5, simulate_invalid=False,
                            observer=log) as evaluator:
        proposals = method.ask()
        method.ask = lambda: proposals  # type: ignore[method-assign]
        run_search(method, evaluator, budget=2)
    for proposal, record in zip(proposals, log.records):
        assert proposal.environment is not None
        assert record.environment.id == f'screened-e0000{record.index}'
        assert record.environment.start == proposal.environment.start
        assert (record.environment.occupancy == proposal.environment.occupancy).all()


def test_a_search_runs_its_maps_at_the_generators_origin():
    from sessgan_evolver.screened_search import ScreenedConfig, ScreenedSearch
    from sessgan_evolver.search_methods import RandomSampling

    origin = (-4.5, 7.25)
    for method in (RandomSampling('factory', 0, batch=2),
                   ScreenedSearch('factory', 1, config=ScreenedConfig(batch=2,
                                                                      reference_maps=2))):
        log = EpisodeLog()
        with InProcessEvaluator('factory', time_limit=0.5, simulate_invalid=False,
                                observer=log) as evaluator:
            proposals = method.ask()
            method.ask = lambda: proposals  # type: ignore[method-assign]
            run_search(method, evaluator, budget=2, origin=origin)
        assert [record.environment.origin for record in log.records] == [origin] * 2
        for proposal, record in zip(proposals, log.records):
            if proposal.environment is not None:  # its own start, in the moved frame
                assert record.environment.start.x == \
                    pytest.approx(proposal.environment.start.x + origin[0])
