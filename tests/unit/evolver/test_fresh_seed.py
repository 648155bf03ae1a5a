"""Fresh-seed evaluation: seeds disjoint from the campaigns, generators of a run, figures."""

from __future__ import annotations

import pytest
import torch

from sessgan_evolver.campaign import CampaignConfig
from sessgan_evolver.fresh_seed import (
    AutomatonSource,
    FreshSeedError,
    PyramidSource,
    SeedPlan,
    campaign_sources,
    check_disjoint,
    episode_rows,
    evaluate_source,
    fresh_seed_plan,
    summary_table,
    used_seeds,
)
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.search import run_sessgan_search

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


@pytest.fixture(scope='module')
def run_dir(tmp_path_factory):
    base = CampaignConfig(population=3, maps_per_member=1, seed=9, time_limit=1.0,
                          record_failures=False, seed_schedule='fixed')
    with InProcessEvaluator('factory', time_limit=1.0) as evaluator:
        return run_sessgan_search(base, evaluator, 6, tmp_path_factory.mktemp('runs'),
                                  'tiny').run_dir


def test_fresh_seeds_avoid_every_seed_a_run_used(run_dir):
    map_seeds, sim_seeds = used_seeds([run_dir])
    assert len(map_seeds) == 1 and len(sim_seeds) == 1  # fixed schedule, K = 1
    plan = fresh_seed_plan(5, 4, map_seeds, sim_seeds)
    assert plan == fresh_seed_plan(5, 4, map_seeds, sim_seeds) and plan.skipped == 0
    check_disjoint(plan, [run_dir])
    clash = fresh_seed_plan(5, 4, {plan.pairs[1][0]})
    assert clash.skipped == 1 and plan.pairs[1] not in clash.pairs and len(clash.pairs) == 4
    used = SeedPlan([(next(iter(map_seeds)), 1)], 0, 0, 0)
    with pytest.raises(FreshSeedError, match='used by the runs'):
        check_disjoint(used, [run_dir])
    with pytest.raises(FreshSeedError, match='config.json'):
        used_seeds([run_dir.parent / 'missing'])


def test_generators_of_a_campaigns_last_population(run_dir):
    best = campaign_sources(run_dir, 'best')
    final = campaign_sources(run_dir, 'final')
    assert len(best) == 1 and len(final) == 3
    assert best[0].label.startswith('tiny g1 m')
    assert campaign_sources(run_dir, '2')[0].label == 'tiny g1 m2'
    with pytest.raises(FreshSeedError, match='members 0..2'):
        campaign_sources(run_dir, '3')
    with pytest.raises(FreshSeedError, match="'best', 'final'"):
        campaign_sources(run_dir, 'worst')


def test_every_source_sees_the_same_seeds_and_the_figures_add_up(run_dir):
    plan = fresh_seed_plan(5, 3, *used_seeds([run_dir]))
    with InProcessEvaluator('factory', time_limit=2.0, simulate_invalid=False) as evaluator:
        shipped = evaluate_source(PyramidSource('shipped', 'factory'), plan, evaluator)
        again = evaluate_source(PyramidSource('again', 'factory'), plan, evaluator)
        automaton = evaluate_source(AutomatonSource('factory'), plan, evaluator)
    strip = ('generator', 'wall_time')
    assert [{k: v for k, v in row.items() if k not in strip} for row in episode_rows(shipped)] \
        == [{k: v for k, v in row.items() if k not in strip} for row in episode_rows(again)]
    assert [(r['map_seed'], r['sim_seed']) for r in episode_rows(automaton)] == plan.pairs
    summary = shipped.summary
    rows = episode_rows(shipped)
    valid = [row for row in rows if row['feasible']]
    assert summary.maps == 3 and summary.valid_maps == len(valid)
    assert summary.valid_failures == sum(row['valid_failure'] for row in rows)
    assert summary.failure_rate == pytest.approx(summary.valid_failures / len(valid))
    assert summary.distinct_faults == len({row['fault'] for row in rows if row['fault']})
    assert summary.tpkl > 0 and 0 < summary.uniqueness <= 100
    assert '| shipped | 3 |' in summary_table([summary])


def test_a_population_samples_its_members_in_turn(run_dir):
    from sessgan_evolver.fresh_seed import PopulationSource

    members = campaign_sources(run_dir, 'final')
    population = PopulationSource('final', members)
    maps = population.maps([11, 12, 13, 14])
    for index, seed in enumerate([11, 12, 13, 14]):
        assert (maps[index] == members[index % 3].maps([seed])[0]).all()
    assert population.maps([]).shape == (0, 32, 32)
    with pytest.raises(FreshSeedError):
        PopulationSource('none', [])


def test_fresh_maps_sit_at_the_generators_origin_and_run_the_same_episodes(run_dir):
    """A facility generator's maps sit at its training map's origin (evaluate and compare
    ran them at (0, 0)); moving the map frame changes no metric (beyond rounding: the
    physics works in map-frame coordinates)."""
    plan = fresh_seed_plan(5, 2, *used_seeds([run_dir]))
    seen = []
    with InProcessEvaluator('factory', time_limit=2.0, simulate_invalid=False) as evaluator:
        home = evaluate_source(PyramidSource('home', 'factory'), plan, evaluator)
        moved_source = PyramidSource('moved', 'factory')
        moved_source.origin = (-4.5, 7.25)
        run_environment = evaluator.run_environment

        def recording_run(environment, *rest):
            seen.append(environment)
            return run_environment(environment, *rest)

        evaluator.run_environment = recording_run
        moved = evaluate_source(moved_source, plan, evaluator)
    assert [environment.origin for environment in seen] == [(-4.5, 7.25)] * 2
    for before, after in zip(episode_rows(home), episode_rows(moved), strict=True):
        assert (before['outcome'], before['collisions']) == (after['outcome'],
                                                             after['collisions'])
        for name in ('risk_score', 'path_length', 'min_clearance'):
            assert after[name] == pytest.approx(before[name], rel=1e-9, abs=1e-12)
