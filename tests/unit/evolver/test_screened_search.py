"""The screened search: ask/tell, determinism, exploration share, archive novelty, the
surrogate, route features, and a budget counted in episodes of the robot under test only."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from sessgan_core.fleet import FleetSpec
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import tokens_to_occupancy
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.episode_runner import EpisodeTrace
from sessgan_evolver.faults import (
    FaultEvent,
    FaultKey,
    FaultRule,
    SituationArchive,
    fault_key,
    same_situation,
)
from sessgan_evolver.fresh_seed import EnvironmentSource, SeedPlan, evaluate_source
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.screened_search import (
    AGENT_FAULT,
    RELOCATE,
    ArchiveSource,
    Operator,
    Record,
    ScreenedConfig,
    ScreenedSearch,
)
from sessgan_evolver.screened_search import (
    Test as ScreenedTest,
)
from sessgan_evolver.screening import (
    FEATURE_NAMES,
    CertifiedCandidate,
    FaultArchive,
    OnlineLogistic,
    certify_candidate,
    certify_route,
    route_coarse_cells,
    route_features,
)
from sessgan_evolver.search import EpisodeLog, run_search
from sessgan_evolver.search_methods import (
    BASELINES,
    METHODS,
    Evaluated,
    SearchMethodError,
    make_baseline,
    screening_effort,
)

pytestmark = pytest.mark.unit
torch.set_num_threads(1)

SMALL = ScreenedConfig(batch=4, reference_maps=4, surrogate_warmup=4)


def ended_at(x: float, y: float) -> EpisodeTrace:
    """A two-row trace of a robot that ended at (x, y) (where a stuck failure is keyed)."""
    poses = np.array([[x, y, 0.0], [x, y, 0.0]])
    return EpisodeTrace(times=np.array([0.0, 0.05]), poses=poses, twists=np.zeros((2, 3)),
                        commands=np.zeros((1, 4)), agents=np.zeros((2, 0, 2)))


def oracle_results(proposals, fails=lambda environment: environment.route_length > 14.0):
    """Episodes without simulation: a map fails (stuck at its goal) when ``fails`` says so."""
    results = []
    for index, proposal in enumerate(proposals):
        environment = proposal.environment or make_environment(
            proposal.cells, 'factory', f'e{index}', seed=proposal.resolved_environment_seed)
        failed = environment.feasible and fails(environment)
        results.append(Evaluated(proposal, environment, {
            'feasible': environment.feasible, 'collisions': 0, 'fault_collisions': 0,
            'outcome': 'stuck' if failed else 'goal_reached'},
            ended_at(environment.goal.x, environment.goal.y)))
    return results


def test_screened_is_registered_for_compare_and_the_campaign():
    assert 'screened' in METHODS and 'screened' in BASELINES
    assert make_baseline('screened', 'factory', 0).name == 'screened'


def test_the_screening_effort_multiplies_candidates_and_simulator_seeds(monkeypatch):
    """Effort e screens e times each test's candidates and tries e times each kept
    candidate's simulator seeds; by default 1 in process and 3 for a stack already running
    (--external), whose episodes cost seconds where a candidate costs milliseconds."""
    import sessgan_evolver.screened_search as screened_module

    tried: list[int] = []
    forecast = screened_module.closest_encounter
    monkeypatch.setattr(screened_module, 'closest_encounter',
                        lambda *args: tried.append(1) or forecast(*args))
    for effort in (1, 3):
        tried.clear()
        search = ScreenedSearch('factory', 3, config=dataclasses.replace(SMALL, effort=effort))
        search.ask()
        assert search.screened == SMALL.batch * SMALL.fresh_candidates * effort
        per_candidate = SMALL.agent_seeds * effort
        assert len(tried) % per_candidate == 0 and len(tried) >= SMALL.batch * per_candidate
    defaults = [screening_effort(0, external, scenario) for external in (False, True)
                for scenario in ('factory', 'drone', 'racetrack')]
    assert defaults == [2, 2, 1, 3, 3, 3]  # in process: 2 where the episodes have agents
    assert screening_effort(2, True, 'racetrack') == 2
    assert make_baseline('screened', 'factory', 0, screening_effort=2).config.effort == 2
    with pytest.raises(SearchMethodError, match='screening effort must be >= 0'):
        screening_effort(-1, False, 'factory')
    with pytest.raises(SearchMethodError, match='effort must be >= 1'):
        ScreenedConfig(effort=0).validate()


def test_ask_tell_contract():
    search = ScreenedSearch('factory', 3, config=SMALL)
    proposals = search.ask()
    assert len(proposals) == 4
    # No failure yet: every test is a fresh sample, each the best of its screened candidates.
    assert all(p.origin == 'fresh sample' for p in proposals)
    assert search.screened >= 4 * SMALL.fresh_candidates
    with pytest.raises(SearchMethodError, match='told 3 results for 4'):
        search.tell(oracle_results(proposals)[:3])
    search.tell(oracle_results(proposals))
    assert search.told == 4 and len(search.surrogate.labels) == 4
    with pytest.raises(SearchMethodError, match='exploration'):
        ScreenedConfig(exploration=0.0).validate()
    with pytest.raises(SearchMethodError, match='no operator'):
        ScreenedConfig(operators=()).validate()
    with pytest.raises(SearchMethodError, match='repeat its parent'):
        ScreenedConfig(operators=(Operator('same'),)).validate()


def run_with_oracle(seed: int, batches: int, config: ScreenedConfig = SMALL):
    search = ScreenedSearch('factory', seed, config=config)
    asked = []
    for _ in range(batches):
        proposals = search.ask()
        asked.append(proposals)
        search.tell(oracle_results(proposals))
    return search, asked


def test_same_seed_same_proposals_and_results():
    first, first_asked = run_with_oracle(5, 4)
    again, again_asked = run_with_oracle(5, 4)
    other, other_asked = run_with_oracle(6, 1)
    flat = [p for batch in first_asked for p in batch]
    flat_again = [p for batch in again_asked for p in batch]
    assert [(p.sim_seed, p.environment_seed, p.origin) for p in flat] == \
        [(p.sim_seed, p.environment_seed, p.origin) for p in flat_again]
    assert all(np.array_equal(a.cells, b.cells) for a, b in zip(flat, flat_again))
    assert first.archive.keys == again.archive.keys
    assert [p.sim_seed for p in other_asked[0]] != [p.sim_seed for p in first_asked[0]]


def test_same_seed_same_episodes_through_the_driver():
    def episodes(seed):
        log = EpisodeLog()
        with InProcessEvaluator('factory', time_limit=2.0, simulate_invalid=False,
                                observer=log) as evaluator:
            run_search(ScreenedSearch('factory', seed, config=SMALL), evaluator, budget=6)
        return [(r.environment.seed, r.sim_seed, r.metrics['outcome'], r.metrics['ticks'],
                 r.fault) for r in log.records]
    assert episodes(2) == episodes(2)


def test_children_of_failures_get_the_budget_and_exploration_keeps_its_share():
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25)
    # Every feasible map fails, each at its goal: parents from the first batch on.
    search, asked = run_with_oracle(1, 6, config)
    flat = [p for batch in asked for p in batch]
    fresh = sum(p.origin == 'fresh sample' for p in flat)
    assert fresh >= 0.25 * len(flat)
    children = sum(p.origin.startswith('child of') for p in flat)
    assert children and children + fresh == len(flat)
    # Every child is a trial of its operator (and so is a child slot whose candidates were
    # all dropped before an episode: it went to a fresh sample).
    assert sum(r.trials for r in search.operator_records.values()) >= children
    half, asked = run_with_oracle(1, 6, ScreenedConfig(batch=4, reference_maps=4,
                                                        exploration=0.5))
    flat = [p for batch in asked for p in batch]
    assert sum(p.origin == 'fresh sample' for p in flat) >= 0.5 * len(flat)


def test_exploration_one_runs_fresh_samples_only_and_is_a_campaign_setting():
    """--exploration 1 (campaign, compare): every test a screened fresh sample, though
    failing tests were there to make children of; 0 keeps the method's default."""
    search, asked = run_with_oracle(1, 4, ScreenedConfig(batch=4, reference_maps=4,
                                                         exploration=1.0))
    assert search.parents
    assert all(p.origin == 'fresh sample' for batch in asked for p in batch)
    assert make_baseline('screened', 'factory', 0, exploration=1.0).config.exploration == 1.0
    assert make_baseline('screened', 'factory', 0).config.exploration == \
        ScreenedConfig().exploration
    for wrong in (-0.1, 1.5, float('nan')):
        with pytest.raises(SearchMethodError, match='exploration must lie in'):
            make_baseline('screened', 'factory', 0, exploration=wrong)


def test_relocated_children_keep_the_map_and_draw_new_seeds():
    config = ScreenedConfig(batch=4, reference_maps=4, operators=(RELOCATE,),
                            exploration=0.25)
    search, asked = run_with_oracle(4, 3, config)
    children = [p for batch in asked for p in batch if p.origin.startswith('child')]
    assert children and all(RELOCATE.name in p.origin for p in children)
    parents = [parent.test for parent in search.parents]
    for child in children:
        # Its parent (a failing test; children that fail are parents too) had this map
        # with other seeds.
        assert any(np.array_equal(t.cells, child.cells)
                   and t.environment_seed != child.environment_seed
                   and t.sim_seed != child.sim_seed for t in parents)


def test_mutated_children_keep_their_parents_start_and_goal_on_a_changed_map():
    # One simulator seed a test: the child keeps its parent's (else the one whose agents
    # come closest, tests/unit/evolver/test_agent_encounters.py).
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25, agent_seeds=1,
                            operators=(Operator('fine', 0.5, scales=(2,)),))
    search, asked = run_with_oracle(2, 3, config)
    children = [p for batch in asked for p in batch if p.origin.startswith('child')]
    assert children
    for child in children:
        assert child.environment is not None and child.environment.feasible
        start, goal = child.environment.start, child.environment.goal
        parent = next(parent for parent in search.parents
                      if parent.route[0][:2] == (start.x, start.y)
                      and parent.route[1][:2] == (goal.x, goal.y))
        assert not np.array_equal(parent.test.cells, child.cells)
        assert child.sim_seed == parent.test.sim_seed
        # The route is certified on the child's own map, by the placement's rules.
        assert child.environment.route_length > 0
        assert child.environment.extra['start_clearance'] >= 0.45


def factory_candidate(seed: int = 0) -> CertifiedCandidate:
    from sessgan_core.token_map import tokens_to_occupancy
    from sessgan_evolver.search_methods import load_pyramid
    from sessgan_gen.sampling import sample_token_maps

    spec = get_scenario('factory')
    cells = sample_token_maps(load_pyramid('factory', None), [seed])[0]
    candidate = certify_candidate(tokens_to_occupancy(cells, spec), spec, seed)
    assert candidate.feasible
    return candidate


def test_archive_knows_a_fault_place_only_with_the_same_surroundings():
    rule = FaultRule()
    candidate = factory_candidate()
    environment = make_environment_of(candidate)
    row, col = sorted(route_coarse_cells(candidate, rule))[0]
    # The key sessgan_evolver.faults gives a stuck robot in the middle of that coarse cell.
    size = get_scenario('factory').cell_size * rule.coarse_cells
    key = fault_key(environment, FaultEvent('stuck', (col + 0.5) * size, (row + 0.5) * size,
                                            1.0), rule)
    archive = FaultArchive(rule)
    assert archive.known_places_on(candidate) == 0
    assert archive.add(key) and not archive.add(key)
    assert archive.known_places_on(candidate) == 1
    # Change one map cell next to the place: the same spot is another situation now.
    changed = candidate.occupancy.copy()
    r, c = row * rule.coarse_cells, col * rule.coarse_cells
    changed[r, c] = 100 if changed[r, c] == 0 else 0
    assert archive.known_places_on(CertifiedCandidate(changed, candidate.placement)) == 0
    # A key elsewhere on the map does not count.
    far = FaultArchive(rule)
    far.add(FaultKey('stuck', row + 100, col, key.context))
    assert far.known_places_on(candidate) == 0


def make_environment_of(candidate: CertifiedCandidate):
    from sessgan_core.environment import Environment, Pose2D

    placement = candidate.placement
    assert placement.start is not None and placement.goal is not None
    return Environment(id='x', scenario='factory', occupancy=candidate.occupancy,
                       resolution=get_scenario('factory').cell_size,
                       start=Pose2D(*placement.start), goal=Pose2D(*placement.goal))


def test_the_screen_halves_a_candidate_per_known_fault_place_on_its_route():
    search = ScreenedSearch('factory', 0, config=SMALL)
    candidate = factory_candidate(3)
    test = search._fresh_test()
    test.features = route_features(candidate, search.spec)
    plain = search._score(test, search._novelty(candidate))
    rule = search.config.rule
    for row, col in sorted(route_coarse_cells(candidate, rule))[:2]:
        from sessgan_evolver.faults import place_context
        search.archive.add(FaultKey('stuck', row, col,
                                    place_context(candidate.occupancy, row, col, rule)))
    assert search._score(test, search._novelty(candidate)) == pytest.approx(plain / 4)


def test_route_features_of_a_corridor_match_its_geometry():
    spec = get_scenario('factory')
    occupancy = np.full((20, 20), 100, dtype=np.int8)
    occupancy[8:12, 1:19] = 0  # a straight corridor 2 m wide and 9 m long
    candidate = certify_candidate(occupancy, spec, 0)
    assert candidate.feasible
    features = dict(zip(FEATURE_NAMES, route_features(candidate, spec)))
    points = candidate.placement.certificate.points
    assert features['route_length'] == pytest.approx(
        float(np.hypot(*(points[-1] - points[0]))), rel=1e-6)
    assert features['detour_ratio'] == pytest.approx(1.0, abs=0.02)
    assert features['sharpest_turn'] < 0.2
    # 2 m wide: nothing on the route is more than 1 m from a wall, nothing tight.
    assert 0.45 <= features['bottleneck_clearance'] <= features['mean_clearance'] <= 1.0
    assert features['tight_share'] == 0.0 and features['tight_passages'] == 0
    # A 1 m block in the corridor: one tight passage beside it, a bend, a lower bottleneck.
    occupancy[8:10, 9:11] = 100
    blocked = dict(zip(FEATURE_NAMES, route_features(certify_candidate(occupancy, spec, 0),
                                                      spec)))
    assert blocked['tight_passages'] == 1 and 0 < blocked['tight_share'] < 1
    assert blocked['turns'] >= 1 and blocked['turning_angle'] > 0
    assert blocked['bottleneck_clearance'] < features['bottleneck_clearance']


def test_the_surrogate_learns_a_toy_rule():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((300, 3))
    y = x[:, 0] + 0.5 * x[:, 1] + 0.3 * rng.standard_normal(300) > 1.0
    model = OnlineLogistic(3)
    assert np.allclose(model.predict(x[:2]), 0.5)
    for row, label in zip(x[:200], y[:200]):
        model.add(row, bool(label))
    model.fit()
    p = model.predict(x[200:])
    positives, negatives = p[y[200:]], p[~y[200:]]
    auc = float(np.mean(positives[:, None] > negatives[None, :]))
    assert auc > 0.9
    assert model.weights[1] > model.weights[2] > abs(model.weights[3])


def test_the_surrogate_fit_does_not_diverge_where_plain_newton_steps_do():
    # A race-track search's own episodes (reference navigator, 270 rows of FEATURE_NAMES and
    # the child flag): undamped Newton steps overshot from the 258th row on (intercept -1314,
    # then a singular Hessian that stopped the search).
    data = np.load(Path(__file__).parent / 'data' / 'diverging_surrogate.npz')
    x, y = data['x'].astype(np.float64), data['y']
    for rows in (258, 264, 270):
        model = OnlineLogistic(x.shape[1])
        for row, label in zip(x[:rows], y[:rows]):
            model.add(row, bool(label))
        model.fit()
        assert np.all(np.isfinite(model.weights)) and abs(model.weights[0]) < 20
        p = model.predict(x[:rows])
        # The fit explains the labels better than the base rate does.
        rate = y[:rows].mean()
        log_loss = -np.mean(np.where(y[:rows], np.log(p), np.log(1 - p)))
        assert log_loss < -(rate * np.log(rate) + (1 - rate) * np.log(1 - rate))


def test_the_budget_is_episodes_of_the_robot_under_test_only():
    search = ScreenedSearch('factory', 8, config=SMALL)
    with InProcessEvaluator('factory', time_limit=1.0, simulate_invalid=False) as evaluator:
        assert run_search(search, evaluator, budget=7) == 7
        assert evaluator.episodes == 7
    # Screening certified more maps than were run, and its time is on its own clock.
    assert search.screened > 7 and search.cheap_wall_time > 0


def test_a_fresh_test_is_the_environment_make_environment_gives_its_seed():
    # The screen certifies exactly what every other method's episode gets, so a fresh
    # sample of the screened search is a random sample's test, only chosen.
    search = ScreenedSearch('factory', 9, config=SMALL)
    for proposal in search.ask():
        assert proposal.origin == 'fresh sample' and proposal.environment is not None
        drawn = make_environment(proposal.cells, 'factory', proposal.environment.id,
                                 seed=proposal.resolved_environment_seed)
        assert drawn.start == proposal.environment.start
        assert drawn.goal == proposal.environment.goal
        assert drawn.route_length == proposal.environment.route_length
        assert drawn.route_min_clearance == proposal.environment.route_min_clearance
        assert drawn.extra == proposal.environment.extra and drawn.feasible
        assert (drawn.occupancy == proposal.environment.occupancy).all()



def test_situations_group_faults_at_one_place_on_nearly_the_same_map():
    occupancy = np.zeros((20, 20), dtype=np.int8)
    key = FaultKey('stuck', 1, 2, 'a')
    archive = SituationArchive()
    assert archive.add(key, occupancy) and len(archive) == 1
    near = occupancy.copy()
    near.flat[:39] = 100  # 9.75 % of the cells differ: the same situation
    # Another context digest (a new fault by the exact rule) on a nearly equal map: no news.
    assert same_situation(FaultKey('stuck', 1, 2, 'b'), near, key, occupancy)
    assert not archive.add(FaultKey('stuck', 1, 2, 'b'), near)
    far = occupancy.copy()
    far.flat[:40] = 100  # 10 %: another situation
    assert not same_situation(key, far, key, occupancy)
    assert archive.add(FaultKey('stuck', 1, 3, 'a'), occupancy)  # another coarse cell
    assert archive.add(FaultKey('timeout', 1, 2, 'a'), occupancy)  # another kind
    assert len(archive) == 3
    assert archive.known_on(near, {(1, 2)}) == 2 and archive.known_on(far, {(1, 2)}) == 0
    assert archive.known_on(occupancy, {(0, 0)}) == 0


def failing_at(proposals, where):
    """Every test fails, stuck at ``where(environment)`` (a point in metres)."""
    results = []
    for proposal in proposals:
        environment = proposal.environment
        assert environment is not None and environment.feasible
        results.append(Evaluated(proposal, environment, {
            'feasible': True, 'collisions': 0, 'fault_collisions': 0, 'outcome': 'stuck'},
            ended_at(*where(environment))))
    return results


def at_goal(environment):
    return environment.goal.x, environment.goal.y


def with_parents(config: ScreenedConfig) -> ScreenedSearch:
    """A search whose first batch all failed (each fresh test a parent)."""
    search = ScreenedSearch('factory', 1, config=config)
    search.tell(failing_at(search.ask(), at_goal))
    assert search.parents
    return search


def test_a_near_duplicate_failure_earns_no_credit_and_a_failure_at_a_new_place_does():
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25,
                            operators=(Operator('local', 0.8, local=True),))
    search = with_parents(config)
    record = search.operator_records['local']
    proposals = search.ask()
    children = [(proposal, search.parents[test.parent])
                for proposal, test in zip(proposals, search._pending) if test.parent is not None]
    assert children
    for proposal, parent in children:
        # Its parent's start and goal on a map changed only around the parent's fault.
        assert proposal.environment.goal == parent.test.environment.goal
        assert np.mean(proposal.environment.occupancy
                       != parent.test.environment.occupancy) < 0.1
    faults = len(search.archive.keys)
    search.tell(failing_at(proposals, at_goal))
    # Each child failed where its parent did: a new distinct fault by the exact rule (the map
    # around the place changed) but the same situation, so no credit.
    assert len(search.archive.keys) >= faults + len(children)
    assert record.trials >= len(children) and record.successes == 0
    assert all(parent.new_faults == 0 and parent.barren >= 1 for _, parent in children)
    assert not any(parent.test.parent is not None for parent in search.parents)
    # Children failing at their start, in another coarse cell than the goal: new, credited.
    proposals = search.ask()
    size = search.spec.cell_size * config.rule.coarse_cells

    def cell(pose):
        return int(pose.x // size), int(pose.y // size)
    moved = [search.parents[test.parent] for proposal, test in zip(proposals, search._pending)
             if test.parent is not None
             and cell(proposal.environment.start) != cell(proposal.environment.goal)]
    assert moved
    search.tell(failing_at(proposals, lambda e: (e.start.x, e.start.y)))
    assert record.successes >= 1
    assert any(parent.new_faults >= 1 and parent.barren == 0 for parent in moved)
    assert any(parent.test.parent is not None for parent in search.parents)


def test_a_parent_whose_children_repeat_known_situations_is_retired():
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25, retire_after=2)
    search = with_parents(config)
    # Fresh samples that show a new situation half the time.
    search.fresh_record = Record(20, 10)
    first = search.parents[0]
    first.credit(False)
    assert first.barren == 1 and 0 in search._live_parents()
    for parent in search.parents:
        parent.credit(False)
        parent.credit(False)
    # Every parent retired: each slot is a fresh sample.
    assert search._live_parents() == []
    assert search._pick_parent() is None and search._child_test() is None
    assert all(p.origin == 'fresh sample' for p in search.ask())
    # A new situation revives a parent's streak: only it is picked.
    first.credit(True)
    first.credit(False)
    assert first.barren == 1 and search._live_parents() == [0]


def test_a_barren_parent_lives_on_while_its_record_beats_fresh_samples():
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25, retire_after=2)
    search = with_parents(config)
    for parent in search.parents:
        parent.credit(True)
        parent.credit(False)
        parent.credit(False)
    # 1 new situation in 3 children (posterior mean 0.4) against fresh samples' 1 in 48
    # (0.04): the barren streak alone does not retire them.
    search.fresh_record = Record(48, 1)
    assert search._live_parents() == list(range(len(search.parents)))
    search.fresh_record = Record(48, 24)
    assert search._live_parents() == []


def test_fresh_samples_compete_with_parents_for_child_slots():
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25)
    search = with_parents(config)
    for parent in search.parents:
        for _ in range(2):
            parent.credit(False)
    parents = len(search.parents)
    # Fresh samples that always show a new situation take the slots; ones that never do
    # leave them to the parents.
    search.fresh_record = Record(200, 200)
    assert all(search._pick_parent() is None for _ in range(20))
    search.fresh_record = Record(200, 0)
    assert all(search._pick_parent() in range(parents) for _ in range(20))


def test_the_archive_makes_children_of_its_failing_tests_with_their_start_and_goal():
    with pytest.raises(SearchMethodError, match='no archive'):
        ArchiveSource(ScreenedSearch('factory', 1, config=SMALL), 'empty')
    search = with_parents(SMALL)
    source = ArchiveSource(search, 'archive')
    assert isinstance(source, EnvironmentSource) and source.reference is search.example
    made = source.environments([11, 12, 13, 11])
    goals = {(p.test.environment.goal.x, p.test.environment.goal.y): p for p in search.parents}
    for cells, environment in made:
        # Every test is a certified child of a parent, with that parent's start and goal.
        parent = goals[(environment.goal.x, environment.goal.y)]
        assert environment.feasible
        assert environment.start == parent.test.environment.start
        assert np.array_equal(environment.occupancy,
                              tokens_to_occupancy(cells, search.spec))
    # A map seed alone decides its test.
    assert np.array_equal(made[0][0], made[3][0]) and made[0][1].start == made[3][1].start
    assert np.array_equal(source.maps([11, 12]), np.stack([made[0][0], made[1][0]]))
    # Mutated, not a copy of the parents' maps (all four would be copies only by chance).
    assert any(not any(np.array_equal(cells, p.test.cells) for p in search.parents)
               for cells, _ in made)


def test_the_archive_draws_the_parents_whose_fault_the_map_made():
    search = with_parents(SMALL)
    assert len(search.parents) >= 2
    agent = search.parents[0]
    agent.key = dataclasses.replace(agent.key, kind=AGENT_FAULT)
    goal = agent.test.environment.goal
    # A drive into an agent depended on where that episode's agents walked: the archive runs
    # fresh simulator seeds, so it draws the other parents.
    made = ArchiveSource(search, 'archive').environments(range(30))
    assert all(environment.goal != goal for _, environment in made)
    # Where every fault was one, it draws them all.
    for parent in search.parents:
        parent.key = dataclasses.replace(parent.key, kind=AGENT_FAULT)
    made = ArchiveSource(search, 'archive').environments(range(30))
    assert any(environment.goal == goal for _, environment in made)


def test_fresh_seed_evaluation_runs_an_archive_s_tests_as_made():
    search = with_parents(SMALL)
    source = ArchiveSource(search, 'archive')
    plan = SeedPlan([(21, 5), (22, 6)], 0, 0, 0)
    with InProcessEvaluator('factory', time_limit=2.0) as evaluator:
        result = evaluate_source(source, plan, evaluator)
    expected = source.environments([21, 22])
    assert [record.environment.start for record in result.records] == \
        [environment.start for _, environment in expected]
    assert [record.environment.id for record in result.records] == ['fresh-0000-s21',
                                                                     'fresh-0001-s22']
    assert [record.sim_seed for record in result.records] == [5, 6]
    assert result.summary.generator == 'archive' and result.summary.valid_maps == 2


def test_a_child_that_keeps_a_sibling_s_fault_place_is_not_run():
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25,
                            operators=(Operator('local', 0.8, local=True),))
    search = with_parents(config)
    proposals = search.ask()
    children = [(proposal, test) for proposal, test in zip(proposals, search._pending)
                if test.parent is not None]
    assert children
    # The children fail at their start, away from their parents' fault (the goal).
    search.tell(failing_at(proposals, lambda e: (e.start.x, e.start.y)))
    rule = search.config.rule
    changed_maps = 0
    for proposal, child in children:
        parent = search.parents[child.parent]
        sibling = ScreenedTest(child.noise, child.cells, -1, parent.test.environment_seed,
                               child.sim_seed, 'child', child.parent, 'local',
                               parent.route)
        # A sibling on this child's map keeps the map around the child's failing place: run
        # again with the same start, goal and simulator seed it would most likely repeat it.
        occupancy = proposal.environment.occupancy
        candidate = certify_route(occupancy, search.spec, *parent.route)
        assert candidate.feasible and search._repeats_lineage(sibling, occupancy)
        # The same map changed in one cell around that place is worth running.
        size = search.spec.cell_size * rule.coarse_cells
        row = int(proposal.environment.start.y // size) * rule.coarse_cells
        col = int(proposal.environment.start.x // size) * rule.coarse_cells
        window = occupancy[max(row - rule.context_cells, 0):row + rule.coarse_cells
                           + rule.context_cells,
                           max(col - rule.context_cells, 0):col + rule.coarse_cells
                           + rule.context_cells]
        walls = np.argwhere(window == 100)
        if not len(walls):
            continue
        changed = occupancy.copy()
        r, c = walls[0] + (max(row - rule.context_cells, 0), max(col - rule.context_cells, 0))
        changed[r, c] = 0  # a wall cell opened: the route stays certified
        candidate = certify_route(changed, search.spec, *parent.route)
        assert candidate.feasible and not search._repeats_lineage(sibling, changed)
        changed_maps += 1
        # With another simulator seed the robot meets other agents: no prediction.
        sibling.sim_seed += 1
        assert not search._repeats_lineage(sibling, occupancy)
    assert changed_maps


def test_children_keep_their_parents_start_and_goal_when_the_map_runs_elsewhere():
    # A facility generator's maps run at its training map's origin; the search works at (0, 0).
    origin = (-12.5, 4.0)
    config = ScreenedConfig(batch=4, reference_maps=4, exploration=0.25)
    search = ScreenedSearch('factory', 1, config=config)
    proposals = search.ask()
    results = []
    for proposal in proposals:
        moved = proposal.environment.moved_to(origin)
        results.append(Evaluated(proposal, moved, {
            'feasible': True, 'collisions': 0, 'fault_collisions': 0, 'outcome': 'stuck'},
            ended_at(moved.goal.x, moved.goal.y)))
    search.tell(results)
    assert [parent.route for parent in search.parents] == [
        ((p.environment.start.x, p.environment.start.y, p.environment.start.yaw),
         (p.environment.goal.x, p.environment.goal.y, p.environment.goal.yaw))
        for p in proposals]
    children = [p for p in search.ask() if p.origin.startswith('child')]
    assert children
    starts = {parent.route[0] for parent in search.parents}
    for child in children:
        start = child.environment.start
        assert (start.x, start.y, start.yaw) in starts and child.environment.origin == (0, 0)


def test_a_mission_s_failures_make_children_and_an_archive_that_runs_missions():
    from sessgan_core.missions import MissionSpec

    # A mission's episode draws its own stations and ends at home, its start: the search's
    # parents keep the start and goal it certified, so their children certify (they never
    # did on home -> home), and the archive's fresh-seed evaluation draws missions too (it
    # stopped with "an infeasible candidate has no environment to run").
    mission = MissionSpec(stations=2)
    search = ScreenedSearch('factory', 1, config=SMALL)
    proposals = search.ask()
    results = []
    for index, proposal in enumerate(proposals):
        environment = proposal.test_environment('factory', f'm{index}', mission, FleetSpec())
        home, start = environment.goal, environment.start
        assert environment.stations and (home.x, home.y) == (start.x, start.y)
        results.append(Evaluated(proposal, environment, {
            'feasible': True, 'collisions': 0, 'fault_collisions': 0, 'outcome': 'stuck'},
            ended_at(environment.start.x + 1.0, environment.start.y)))
    search.tell(results)
    assert [parent.route[1][:2] for parent in search.parents] == [
        (p.environment.goal.x, p.environment.goal.y) for p in proposals]
    assert any(p.origin.startswith('child') for p in search.ask())

    source = ArchiveSource(search, 'archive')
    with InProcessEvaluator('factory', time_limit=1.0, mission=mission) as evaluator:
        result = evaluate_source(source, SeedPlan([(21, 5), (22, 6)], 0, 0, 0), evaluator)
    assert all(record.environment.stations for record in result.records)
