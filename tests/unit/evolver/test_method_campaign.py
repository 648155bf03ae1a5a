"""campaign --method: ask/tell methods through the campaign's Evaluator, budget, run files,
fault counting and exact resume by replay; fault keys read from failure bags."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from sessgan_evolver.campaign import (
    DEFAULT_METHOD,
    SESSGAN_METHOD,
    Campaign,
    CampaignConfig,
    CampaignError,
)
from sessgan_evolver.campaign_cli import (
    campaign_parser,
    config_from_args,
    make_campaign,
    plan_of,
    report_result,
    resume_command,
)
from sessgan_evolver.campaign_cli import main as campaign_main
from sessgan_evolver.episode_runner import EpisodeRun, EpisodeTrace
from sessgan_evolver.errors import FaultError, FreshSeedError
from sessgan_evolver.fault_tally import (
    UNPLACED,
    FaultTally,
    FaultTracker,
    fault_label,
    key_from_bag,
    key_from_label,
    origin_family,
)
from sessgan_evolver.faults import FaultKey, FaultRule, key_of_failure, place_context
from sessgan_evolver.fresh_seed import campaign_sources, used_seeds
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.method_campaign import MethodCampaign, method_of
from sessgan_evolver.report import FAULT_KIND_MEANINGS
from sessgan_evolver.run_store import RunStore

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


class Interrupted(Exception):
    pass


class ScriptedEvaluator:
    """Runs no simulator: an episode fails (a wall contact where the robot starts) when its
    map seed is even, so the test knows every outcome; traced like the in-process evaluator
    (it has an ``observer``)."""

    harness_reruns = 0

    def __init__(self, interrupt_after: int | None = None) -> None:
        self.observer = None
        self.interrupt_after = interrupt_after
        self.episodes = 0

    def evaluate(self, jobs, on_result):
        for job in jobs:
            if self.episodes == self.interrupt_after:
                raise Interrupted()
            self.episodes += 1
            environment = job.environment
            fails = environment.seed % 2 == 0 and environment.feasible
            x, y = environment.start.x, environment.start.y
            metrics = {
                'outcome': 'collision_limit' if fails else 'goal_reached',
                'feasible': environment.feasible, 'collisions': int(fails),
                'fault_collisions': int(fails), 'proximity_time': 1.0,
                'simulation_time': 10.0, 'risk_score': 0.1 * fails,
                # A speed with many digits: the screened search learns the robot's from it,
                # so a resumed run must be told exactly what the first was.
                'distance_travelled': environment.route_length / 3,
                'fault_risk_score': 0.1 * fails,
                'contacts': [{'kind': 'static', 'x': x, 'y': y, 'time': 1.0}] if fails else []}
            trace = EpisodeTrace(times=np.array([0.0]), poses=np.array([[x, y, 0.0]]),
                                 twists=np.zeros((1, 3)), commands=np.zeros((0, 4)),
                                 agents=np.zeros((1, 0, 2)))
            if self.observer is not None:
                self.observer(environment, job.seed, EpisodeRun(metrics, trace, 0.0), '')
            on_result(job, metrics)


def method_config(**values) -> CampaignConfig:
    return CampaignConfig(**{'method': 'latent', 'budget': 8, 'population': 3, 'seed': 3,
                             **values})


def episode_rows(run_dir) -> list[dict]:
    return [row for row in RunStore(run_dir.parent, run_dir.name).read_rows('episode')]


def test_a_method_campaign_spends_its_budget_and_counts_the_faults(tmp_path):
    campaign = MethodCampaign(method_config(), 'run', tmp_path / 'runs', tmp_path / 'bags',
                              log=lambda _: None)
    result = campaign.run(ScriptedEvaluator())
    rows = episode_rows(result.run_dir)
    assert len(rows) == 8  # batches of 3, 2, 2 and 1 (cut short): the budget, not more
    assert [row['episode'] for row in rows] == list(range(1, 9))
    failing = [row for row in rows if row['map_seed'] % 2 == 0 and row['feasible']]
    assert failing, 'the scripted evaluator should have failed some episodes'
    assert {row['fault'] for row in failing} - {''} and '' not in {r['fault'] for r in failing}
    assert all(row['fault'] == '' for row in rows if row not in failing)
    last = result.generations[-1]
    assert last['episodes_so_far'] == 8
    assert last['valid_failures_so_far'] == len(failing)
    assert last['distinct_faults_so_far'] == len({row['fault'] for row in failing})
    assert all(row['cheap_wall_time'] > 0 and row['episodes_wall_time'] >= 0
               for row in result.generations)
    config = json.loads((result.run_dir / 'config.json').read_text())['config']
    assert (config['method'], config['budget']) == ('latent', 8)
    report = result.report_path.read_text()
    assert report.index('## Faults found') < report.index('## Summary')
    assert f'**{len(failing)} valid failures and ' in report
    # Numbered from 1, its id (and bag) from 0: the report names both.
    assert (f"first valid failure: episode {failing[0]['episode']} "
            f"(`{failing[0]['environment_id']}`)") in report
    assert '| mean fault risk score |' in report
    assert (result.report_path.parent / 'faults_found.png').stat().st_size > 0
    # What kind of failures: a row per kind, its failures and distinct faults.
    kinds = {row['fault'].rpartition('-r')[0] for row in failing}
    for kind in kinds:
        labels = {row['fault'] for row in failing if row['fault'].startswith(kind + '-r')}
        count = sum(row['fault'].startswith(kind + '-r') for row in failing)
        assert f'| `{kind}` | {FAULT_KIND_MEANINGS[kind]} | {count} | {len(labels)} |' \
            in report, report
    # Where they come from: a row per origin of the episodes, the distinct faults all in one.
    origins = [origin_family(row['origin']) for row in rows]
    assert 'Where they come from' in report
    found = 0
    for origin in set(origins):
        line = next(line for line in report.splitlines()
                    if line.startswith(f'| {origin} | {origins.count(origin)} | '))
        found += int(line.split('(')[1].split(')')[0])
    assert found == last['distinct_faults_so_far']


def test_an_interrupted_method_campaign_resumes_with_identical_rows(tmp_path):
    straight = MethodCampaign(method_config(), 'straight', tmp_path / 'runs',
                              tmp_path / 'bags', log=lambda _: None).run(ScriptedEvaluator())
    killed = MethodCampaign(method_config(), 'killed', tmp_path / 'runs', tmp_path / 'bags',
                            log=lambda _: None)
    with pytest.raises(Interrupted):
        killed.run(ScriptedEvaluator(interrupt_after=5))  # inside the third batch
    assert len(episode_rows(killed.store.run_dir)) == 5
    # As if killed between the second batch's episode rows and its generation row: those
    # rows are dropped and the batch run again.
    path = killed.store.metrics_jsonl_path
    lines = path.read_text().splitlines()
    assert json.loads(lines[-1])['kind'] == 'generation'
    path.write_text('\n'.join(lines[:-1]) + '\n')
    with pytest.raises(CampaignError, match='pass --resume'):
        MethodCampaign(method_config(), 'killed', tmp_path / 'runs', tmp_path / 'bags',
                       log=lambda _: None).run(ScriptedEvaluator())
    logged: list[str] = []
    resumed = MethodCampaign(method_config(), 'killed', tmp_path / 'runs', tmp_path / 'bags',
                             log=logged.append).run(ScriptedEvaluator(), resume=True)
    assert any('resuming' in line and 'batch 1' in line for line in logged), logged
    assert episode_rows(resumed.run_dir) == episode_rows(straight.run_dir)
    timing = {'cheap_wall_time', 'episodes_wall_time'}
    assert [{k: v for k, v in row.items() if k not in timing} for row in resumed.generations] \
        == [{k: v for k, v in row.items() if k not in timing} for row in straight.generations]


def test_evaluate_refuses_a_method_run_as_a_generator_but_excludes_its_seeds(tmp_path):
    result = MethodCampaign(method_config(), 'run', tmp_path / 'runs', tmp_path / 'bags',
                            log=lambda _: None).run(ScriptedEvaluator())
    with pytest.raises(FreshSeedError, match=r'latent campaign: it evolves no generator.*'
                       r'sampled \(--shipped\)'):
        campaign_sources(result.run_dir)
    map_seeds, sim_seeds = used_seeds([result.run_dir])
    rows = episode_rows(result.run_dir)
    assert map_seeds == {row['map_seed'] for row in rows}
    assert sim_seeds == {row['sim_seed'] for row in rows}


def test_resume_refuses_a_run_whose_maps_the_method_does_not_propose(tmp_path):
    campaign = MethodCampaign(method_config(), 'run', tmp_path / 'runs', tmp_path / 'bags',
                              log=lambda _: None)
    campaign.run(ScriptedEvaluator())
    path = campaign.store.metrics_jsonl_path
    lines = path.read_text().splitlines()
    first = json.loads(lines[0])
    first['map_digest'] = '0' * 16
    path.write_text('\n'.join([json.dumps(first), *lines[1:]]) + '\n')
    with pytest.raises(CampaignError, match='another map than the one recorded'):
        MethodCampaign(method_config(), 'run', tmp_path / 'runs', tmp_path / 'bags',
                       log=lambda _: None).run(ScriptedEvaluator(), resume=True)


def test_methods_are_validated_and_each_runs_as_its_own_campaign(tmp_path):
    with pytest.raises(CampaignError, match='method must be one of'):
        CampaignConfig(method='hill_climbing').validate()
    with pytest.raises(CampaignError, match='budget must be >= 0'):
        CampaignConfig(budget=-1).validate()
    with pytest.raises(CampaignError, match='screening effort must be >= 0'):
        CampaignConfig(screening_effort=-1).validate()
    with pytest.raises(CampaignError, match='pays for no sessgan generation'):
        CampaignConfig(budget=5, population=3, maps_per_member=2).validate()
    with pytest.raises(CampaignError, match='exploration must lie in'):
        CampaignConfig(method='screened', exploration=2.0).validate()
    with pytest.raises(CampaignError, match='setting of the screened method, not of random'):
        CampaignConfig(method='random', exploration=1.0).validate()
    with pytest.raises(CampaignError, match='MethodCampaign'):
        Campaign(method_config(), 'a', tmp_path, tmp_path)
    with pytest.raises(CampaignError, match='sessgan runs as'):
        MethodCampaign(CampaignConfig(), 'b', tmp_path, tmp_path)
    with pytest.raises(CampaignError, match='population must be >= 2'):
        MethodCampaign(method_config(population=1), 'c', tmp_path, tmp_path)
    assert CampaignConfig(budget=14, population=3, maps_per_member=2) \
        .with_budget_generations().generations == 2
    assert CampaignConfig(generations=4, population=3, maps_per_member=2) \
        .resolved_budget() == 24
    assert method_config(budget=0, generations=2).resolved_budget() == 2 * 3 * 3


def test_the_command_defaults_to_the_default_method_and_records_the_chosen_one(tmp_path):
    assert config_from_args(campaign_parser().parse_args([])).method == DEFAULT_METHOD
    assert CampaignConfig().method == SESSGAN_METHOD
    config = config_from_args(campaign_parser().parse_args(['--method', 'random',
                                                            '--budget', '5']))
    assert (config.method, config.budget) == ('random', 5)
    assert isinstance(make_campaign(config, 'r', tmp_path, tmp_path, print, {}),
                      MethodCampaign)
    # The screened method screens twice as much where agents walk (the factory), three times
    # for a stack already running, once on the race track.
    for arguments, effort in (([], 2), (['--external'], 3), (['--screening-effort', '4'], 4),
                              (['--scenario', 'racetrack'], 1)):
        screened = config_from_args(campaign_parser().parse_args(['--method', 'screened',
                                                                  *arguments]))
        assert method_of(screened).config.effort == effort
        assert f'screening effort {effort}' in plan_of(screened)  # the run's first log line
    sessgan = config_from_args(campaign_parser().parse_args(['--method', 'sessgan']))
    assert isinstance(make_campaign(sessgan, 's', tmp_path, tmp_path, print, {}), Campaign)


def test_resuming_takes_the_run_s_own_options_and_other_settings_are_refused_first(
        tmp_path, capsys):
    """The hint a stopped campaign prints repeats its options (an --external run resumed
    without --external would start simulators of its own), and a resume with other settings
    is refused before any process starts, naming the command that made the run."""
    assert resume_command(['--external', '--budget', '40', '--run', 'c40'], 'c40') == \
        'ros2 run sessgan_evolver campaign --external --budget 40 --run c40 --resume'
    assert resume_command(['--seed', '3', '--resume'], 'factory-seed3') == \
        'ros2 run sessgan_evolver campaign --seed 3 --resume --run factory-seed3'
    runs = tmp_path / 'runs'
    arguments = ['--method', 'random', '--budget', '3', '--in-process', '--run', 'r',
                 '--runs-root', str(runs), '--bags-root', str(tmp_path / 'bags')]
    made = make_campaign(config_from_args(campaign_parser().parse_args(arguments)), 'r', runs,
                         tmp_path / 'bags', print, {'command_line': ['campaign', *arguments]})
    made.store.write_config(made.config.to_dict(), made.config.seed,
                            invocation={'command_line': ['campaign', *arguments]})
    status = campaign_main(['--method', 'random', '--budget', '5', '--in-process', '--run', 'r',
                            '--runs-root', str(runs), '--bags-root', str(tmp_path / 'bags'),
                            '--resume'])
    err = capsys.readouterr().err
    assert status == 2, err
    assert 'config.budget: 3 -> 5' in err and '--budget 3' in err and 'Traceback' not in err
    assert not (runs / 'r' / 'metrics.jsonl').exists()


def test_the_last_line_leads_with_failures_and_faults(tmp_path, capsys):
    result = MethodCampaign(method_config(method='random', budget=5), 'run', tmp_path / 'runs',
                            tmp_path / 'bags', log=lambda _: None).run(ScriptedEvaluator())
    logged: list[str] = []
    report_result(result, logged.append)
    last = result.generations[-1]
    assert logged[0].split(': ', 1)[1].startswith(
        f'{last["valid_failures_so_far"]} valid failures')
    assert logged[0].index('fault risk') < logged[0].index('; risk')


def test_fault_tally_counts_failures_faults_and_unplaced_ones():
    tally = FaultTally.from_rows([{'fault': ''}, {'fault': 'a'}, {'fault': UNPLACED},
                                  {'fault': 'a'}, {'fault': 'b'}, {}])
    assert (tally.episodes, tally.valid_failures, tally.distinct_faults, tally.unplaced) == \
        (6, 4, 2, 1)
    assert tally.faults == {'a': 2, 'b': 5}
    assert tally.first_failure == 2
    assert tally.line().startswith('4 valid failures (0.667/episode), 2 distinct faults '
                                   '(0.333/episode) + 1 unplaced in 6 episodes')


def test_fault_situations_group_variants_of_a_failing_map_and_survive_a_resume(tmp_path):
    """Two failures at one place on maps 2 % apart are two distinct faults (the map around
    the place differs) but one situation; a map 50 % apart is another situation. A resumed
    tally compares against the situations its kept rows found, not a dropped row's."""
    rule = FaultRule()

    def environment(identifier, occupancy):
        return type('E', (), {'id': identifier, 'occupancy': occupancy})()

    first = np.zeros((32, 32), dtype=np.int8)
    variant = first.copy()
    variant[1, 1:21] = 100  # 20 cells: 2 % of the map, beside the fault place
    other = first.copy()
    other[2:18, :] = 100
    keys = [FaultKey('collision_static', 0, 0, place_context(occupancy, 0, 0, rule))
            for occupancy in (first, variant, other)]
    assert keys[0] != keys[1]
    tally = FaultTally()
    found = [tally.add(key.label, key, environment(f'e{index}', occupancy))
             for index, (key, occupancy) in enumerate(zip(keys, (first, variant, other)))]
    assert found == [True, False, True]
    assert (tally.distinct_faults, tally.fault_situations) == (3, 2)
    assert '3 distinct faults (1.000/episode), 2 fault situations in 3 episodes' in tally.line()
    tally.save_situations(tmp_path / 'situations.npz')
    rows = [{'fault': key.label, 'environment_id': f'e{index}', 'situation': new}
            for index, (key, new) in enumerate(zip(keys, found))]
    resumed = FaultTally.from_rows(rows, tmp_path / 'situations.npz')
    assert resumed.fault_situations == 2
    assert resumed.add(keys[1].label, keys[1], environment('e3', variant)) is False
    # The row that found the second situation was dropped (its batch runs again).
    resumed = FaultTally.from_rows(rows[:2], tmp_path / 'situations.npz')
    assert (resumed.fault_situations, resumed.situation_ids) == (1, ['e0'])
    assert resumed.add(keys[2].label, keys[2], environment('e2', other)) is True
    # A run recorded before situations were counted says nothing about them.
    assert 'situation' not in FaultTally.from_rows([{'fault': 'a'}]).line()


def test_a_failure_without_trace_or_bag_is_unplaced_and_a_success_has_no_fault(tmp_path):
    tracker = FaultTracker()
    environment = object.__new__(type('E', (), {'id': 'x'}))
    for metrics, label in (({'feasible': True, 'outcome': 'goal_reached',
                             'fault_collisions': 0}, ''),
                           ({'feasible': True, 'outcome': 'timeout', 'fault_collisions': 0,
                             'bag_path': ''}, UNPLACED)):
        assert fault_label(metrics, tracker.key_of(environment, metrics)) == label


@pytest.mark.parametrize(('time_limit', 'seeds', 'kinds'), [
    (3.0, [2, 3], {'timeout'}), (40.0, [11, 36], {'collision_static'})])
def test_the_fault_key_of_a_failure_bag_is_the_key_of_its_trace(tmp_path, time_limit, seeds,
                                                                kinds):
    """A ROS worker's result carries no contact places: the campaign reads them from the
    failure bag. Keys from bags equal keys from the traces of the same episodes (timeouts:
    where the robot ended; map seeds 11 and 36 at 40 s: Nearness-Diagram's contacts with a
    wall. Map seed 1 gave a drive into an agent until the agent rules of 2026-11-28; with
    simulator seed 7 none of the first 79 maps does now.)"""
    from sessgan_gen.environment_sampler import EnvironmentSampler

    rule = FaultRule()
    found = set()
    with InProcessEvaluator('factory', '', time_limit, record_directory=tmp_path) as evaluator:
        for environment in EnvironmentSampler().sample(seeds, None, 'factory'):
            run = evaluator.run_environment(environment, 7)
            key = key_of_failure(environment, run.metrics, run.trace, rule)
            assert key is not None
            assert key_from_bag(environment, run.metrics['bag_path'], rule) == key
            found.add(key.kind)
            tracker = FaultTracker(rule)  # as the campaign over ROS: no trace, the bag
            assert tracker.key_of(environment, run.metrics) == key
    assert found == kinds


def test_the_screened_search_learns_from_a_campaign_s_faults_and_resumes_exactly(tmp_path):
    """A campaign tells the search each failure's fault key (from the trace in process, from
    the failure bag over ROS; here the scripted trace), so the search makes children of its
    failing tests; a resumed run rebuilds the keys from the recorded labels."""
    config = method_config(method='screened', budget=14)
    straight = MethodCampaign(config, 'straight', tmp_path / 'runs', tmp_path / 'bags',
                              log=lambda _: None).run(ScriptedEvaluator())
    rows = episode_rows(straight.run_dir)
    assert len(rows) == 14 and any(row['fault'] for row in rows)
    assert any(str(row['origin']).startswith('child of') for row in rows)
    killed = MethodCampaign(config, 'killed', tmp_path / 'runs', tmp_path / 'bags',
                            log=lambda _: None)
    with pytest.raises(Interrupted):
        killed.run(ScriptedEvaluator(interrupt_after=9))
    resumed = MethodCampaign(config, 'killed', tmp_path / 'runs', tmp_path / 'bags',
                             log=lambda _: None).run(ScriptedEvaluator(), resume=True)
    assert episode_rows(resumed.run_dir) == rows


def test_a_fault_label_names_its_key_on_its_map():
    occupancy = np.zeros((32, 32), dtype=np.int8)
    occupancy[10:12, 4:20] = 1
    rule = FaultRule()
    key = FaultKey('collision_static', 2, 3, place_context(occupancy, 2, 3, rule))
    assert key_from_label(key.label, occupancy, rule) == key
    assert key_from_label('', occupancy, rule) is None
    assert key_from_label(UNPLACED, occupancy, rule) is None
    moved = occupancy.copy()
    moved[9, 12] = 1  # the map around the place differs: not this label's fault
    with pytest.raises(FaultError, match='does not match'):
        key_from_label(key.label, moved, rule)
    with pytest.raises(FaultError, match='not a fault label'):
        key_from_label('stuck', occupancy, rule)


def test_a_campaign_runs_the_start_and_goal_the_method_certified(tmp_path, monkeypatch):
    """A screened child keeps its failing parent's start and goal: the campaign must run
    that Environment, not draw a new start and goal from the seed (it did, so the default
    campaign's children were not the tests the search screened), at the generator's origin."""
    from sessgan_core.token_map import load_example_map
    from sessgan_core.valid_tests import make_environment
    from sessgan_evolver.search_methods import Proposal

    cells = load_example_map('factory').cells
    own = make_environment(cells, 'factory', 'own', seed=7)
    drawn = make_environment(cells, 'factory', 'drawn', seed=3)
    assert own.feasible and (own.start, own.goal) != (drawn.start, drawn.goal)
    campaign = MethodCampaign(method_config(), 'run', tmp_path / 'runs', tmp_path / 'bags',
                              log=lambda _: None)
    proposal = Proposal(cells, sim_seed=1, map_seed=3, environment=own)
    for origin in ((0.0, 0.0), (-4.5, -1.6)):
        monkeypatch.setattr(campaign, 'origin', origin)
        episode = campaign.environment_of(proposal, 'b0000-e00000', 0, 0)
        assert (episode.id, episode.generation, episode.member) == ('b0000-e00000', 0, 0)
        assert episode.origin == origin
        assert (episode.start.x - own.start.x, episode.start.y - own.start.y,
                episode.goal.x - own.goal.x, episode.goal.y - own.goal.y) == \
            pytest.approx((origin[0], origin[1], origin[0], origin[1]))
    # Without the method's own Environment, the start and goal come from the seed.
    episode = campaign.environment_of(Proposal(cells, sim_seed=1, map_seed=3), 'e', 0, 0)
    assert (episode.start.x, episode.start.y) == \
        pytest.approx((drawn.start.x - 4.5, drawn.start.y - 1.6))
