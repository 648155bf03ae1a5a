"""``screened``: search near failing tests in the generator's latent space, screened cheaply.

What fails is a test: a map *with its start and goal*. In the pilot (factory,
Nearness-Diagram, 9-10 % of fresh tests fail) a failing test fails again 54 % of the time
with a new simulator seed, but 12-14 % after the smallest change of its generator noise or
of its environment seed: either re-draws start and goal, and the failure is gone. Keeping
the start and goal and changing the map only in detail, a child fails 41-45 % of the time,
and where the map changed around the fault place the failure is a new distinct fault
(sessgan_evolver.faults keys it by the map around it). So:

* **Novelty is by fault situation** (sessgan_evolver.faults.same_situation, the rule the
  fault-finding benchmark counts by): a failure is new only when no known fault has its kind
  and coarse cell on a map within 10 % of its cells. A local variant of a failing map that
  fails at the same place is a new distinct fault by the exact-context rule, but the same
  situation: it earns no credit and makes no parent.
* **Parents**: every test that showed a new fault situation, with its start and goal. A
  child slot goes by Thompson sampling on the record (new situations / tests) of each parent's
  children and of fresh samples, so productive lineages get more budget and fresh samples
  get more where they find more. A parent whose last ``retire_after`` children showed no new
  situation is retired once its record falls to fresh samples' (posterior means): where
  fresh samples rarely fail (the race track with the reference navigator: 1-3 %), a lineage
  stays worth its children longer.
* **Operators** (:class:`Operator`), also by Thompson sampling on their record in this
  run: the parent's noise mutated only around its fault place (``local``), or on the two
  finest scales everywhere (mildly or strongly), the parent's start and goal kept
  (re-certified on the child's map) with its simulator seed; ``RELOCATE`` (the same map,
  new start and goal) is available.
* **Exploration**: at least ``exploration`` of all tests are fresh samples of the generator
  (the best of ``fresh_candidates`` by the screen), so new regions keep being found.
* **Screen** (cheap work, timed in ``cheap_wall_time``): each candidate's route is certified
  (the certificate every test gets); candidates without one, children that keep the map
  unchanged around a fault place that a test with their start, goal and simulator seed
  showed (the parent's, a sibling's: they would most likely show that fault again) and maps
  less realistic than the generator's own (single-map TPKL above ``tpkl_quantile`` of fresh
  samples: the realism constraint) are dropped; the rest are ranked by a surrogate of
  P(valid failure) over route-local features (sessgan_evolver.screening.OnlineLogistic,
  refitted on this run's episodes; route length until it has seen ``surrogate_warmup``
  episodes and some failures) times a novelty factor that halves for every known fault
  along the route: known places (same coarse cell, same surrounding map) or known
  situations (same coarse cell, map within 10 %), whichever are more.
* **Agents** (where the episodes have dummy agents): a third of Nearness-Diagram's factory
  failures are drives into an agent, and whether one happens depends on where the agents
  walk, which the simulator seed decides. Each kept candidate tries ``agent_seeds``
  simulator seeds (its own first: a fresh sample's drawn one, a child's parent's) and runs
  the one whose agents come closest to the robot on its way: the patrols the episode will
  spawn (sessgan_sim.episode.PatrolPlanner, exactly), the robot on the shortest way its
  body fits at the average speed it drove in this run's episodes
  (screening.closest_encounter; a forecast, not a simulation). The closest encounter is a
  surrogate feature too. On 600 fresh factory maps (tests/benchmarks/bench_agent_seed_pick.py,
  2026-12-07) the pick of 16 made Nearness-Diagram fail 14.0 % of them where the drawn seed
  failed 9.2 %, the tricycle 13.7 % against 12.2 %; it also makes agents drive into the robot
  (no fault) on 11-12 % of maps against 2 %. (A mission or fleet campaign draws each test's
  stations or robots itself, so there the picked seed is as good as a drawn one.)

Proposals carry the Environment the screen certified, so the robot under test runs exactly
the start and goal that were screened. Every random choice flows from the method's seed;
the budget is only the robot under test's episodes (the driver counts proposals).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sessgan_controllers.errors import UnknownControllerError
from sessgan_controllers.registry import get_controller
from sessgan_core.environment import Environment
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import tokens_to_occupancy
from sessgan_evolver.episode_runner import settings_for_controller
from sessgan_evolver.errors import FaultError, SearchMethodError
from sessgan_evolver.faults import (
    FAULT_KIND_OF_CONTACT,
    FaultKey,
    FaultRule,
    SituationArchive,
    is_valid_failure,
    key_of_failure,
    place_context,
)
from sessgan_evolver.map_operators import NoiseMaps, mutate_noise, mutate_noise_region
from sessgan_evolver.screening import (
    FEATURE_NAMES,
    CertifiedCandidate,
    FaultArchive,
    OnlineLogistic,
    Pose,
    certify_candidate,
    certify_route,
    closest_encounter,
    environment_of,
    reactive_path,
    route_coarse_cells,
    route_features,
)
from sessgan_evolver.search_methods import (
    SEED_BOUND,
    Evaluated,
    Proposal,
    load_generator,
    method_rng,
)
from sessgan_gen.checkpoint import checkpoint_training_map
from sessgan_gen.environment_metrics import tile_pattern_kl
from sessgan_gen.sampling import sample_token_maps_from_noise, seed_noise_maps
from sessgan_gen.track_cleanup import clean_generated_maps
from sessgan_sim.episode import PatrolPlanner
from sessgan_sim.episode_config import EpisodeConfig
from sessgan_sim.metrics import ContactKind
from sessgan_sim.robots import create_robot
from sessgan_sim.simulator_settings import SimulatorSettings


@dataclass(frozen=True)
class Operator:
    """How a child is made from a parent test."""

    name: str
    strength: float = 0.0
    """``mutate_noise`` strength; 0: the parent's map unchanged."""
    scales: tuple[int, ...] | None = None
    """Noise scales to mutate (0 the coarsest, -1 the finest); None: drawn, each with
    probability 0.5 (the finest alone for a local operator)."""
    keep_route: bool = True
    """Keep the parent's start and goal (re-certified on the child's map); else draw them
    from a new environment seed."""
    new_sim_seed: bool = False
    """Draw a new simulator seed (agents, sensor noise) instead of the parent's."""
    local: bool = False
    """Mutate the noise only around the parent's fault place (its coarse cell and context,
    ``mutate_noise_region``), so the map changes there and stays the same elsewhere."""

    def validate(self) -> None:
        if not 0.0 <= self.strength <= 1.0:
            raise SearchMethodError(f'operator {self.name}: strength must lie in [0, 1], got '
                                    f'{self.strength}')
        if self.strength == 0.0 and self.keep_route and not self.new_sim_seed:
            raise SearchMethodError(f'operator {self.name} would repeat its parent exactly')


RELOCATE = Operator('relocate', keep_route=False, new_sim_seed=True)
"""The same map with a new start, goal and simulator seed."""

DEFAULT_OPERATORS = (
    Operator('local_0.8', 0.8, local=True),
    Operator('two_finest_0.4', 0.4, scales=(-2, -1)),
    Operator('two_finest_0.9', 0.9, scales=(-2, -1)),
)
"""Chosen by ``tests/benchmarks/bench_child_tests.py`` (factory, Nearness-Diagram, pilot seeds
21 and 22, 37 and 40 failing parents, 2 children each): per child run, a new fault
situation in 6-13 % (around the fault place), 10-15 % (two finest scales at 0.4) and
10-23 % (at 0.7-0.9, the map changed in 12-16 % of its cells) against 3-4 % for the finest
scale alone (near-duplicates of the parent's situation) and 12-13 % for a fresh sample."""


@dataclass(frozen=True)
class ScreenedConfig:
    """Settings of the ``screened`` search (module docstring)."""

    batch: int = 6
    """Tests per ask (the method learns after every batch)."""
    exploration: float = 0.2
    """Least share of all tests that are fresh samples of the generator."""
    fresh_candidates: int = 3
    """Fresh samples screened per exploration test."""
    child_candidates: int = 3
    """Candidates screened per child test."""
    operators: tuple[Operator, ...] = DEFAULT_OPERATORS
    tpkl_quantile: float = 0.95
    """Candidates whose single-map TPKL exceeds this quantile of fresh samples' are dropped."""
    reference_maps: int = 32
    """Fresh samples that set the TPKL limit."""
    surrogate_warmup: int = 24
    """Episodes before the surrogate ranks candidates (route length before)."""
    retries: int = 4
    """Extra candidates drawn for a test whose candidates were all dropped."""
    agent_seeds: int = 8
    """Simulator seeds tried per candidate where the episodes have dummy agents: the one whose
    agents come closest to the robot on its way (screening.closest_encounter) is run; the
    first tried is a fresh sample's drawn seed or a child's parent's (1: that one)."""
    retire_after: int = 3
    """A parent whose last this many children showed no new fault situation gets no more
    once its record is no better than fresh samples'."""
    rule: FaultRule = field(default_factory=FaultRule)
    """How fault places are keyed (the archive's novelty)."""
    effort: int = 1
    """Screening work per test: ``fresh_candidates``, ``child_candidates`` and
    ``agent_seeds`` are each tried this many times over. A candidate or a seed costs
    milliseconds; an episode of a real stack costs seconds, so there more is nearly free
    (the defaults: ``search_methods.screening_effort``)."""

    def validate(self) -> None:
        for name in ('batch', 'fresh_candidates', 'child_candidates', 'reference_maps',
                     'retire_after', 'agent_seeds', 'effort'):
            if getattr(self, name) < 1:
                raise SearchMethodError(f'{name} must be >= 1, got {getattr(self, name)}')
        for name in ('surrogate_warmup', 'retries'):
            if getattr(self, name) < 0:
                raise SearchMethodError(f'{name} must be >= 0, got {getattr(self, name)}')
        if not 0.0 < self.exploration <= 1.0:
            raise SearchMethodError(f'exploration must lie in (0, 1], got {self.exploration}')
        if not 0.0 < self.tpkl_quantile <= 1.0:
            raise SearchMethodError(f'tpkl_quantile must lie in (0, 1], got '
                                    f'{self.tpkl_quantile}')
        if not self.operators:
            raise SearchMethodError('no operator to make children with')
        names = [operator.name for operator in self.operators]
        if len(set(names)) != len(names):
            raise SearchMethodError(f'operator names must be distinct, got {names}')
        for operator in self.operators:
            operator.validate()
        self.rule.validate()


@dataclass
class Test:
    """A test the method made: its generator noise, map, seeds, route and lineage."""

    noise: NoiseMaps
    cells: np.ndarray
    map_seed: int
    environment_seed: int
    sim_seed: int
    origin: str
    parent: int | None = None
    """Index into ``ScreenedSearch.parents`` (None: a fresh sample)."""
    operator: str = ''
    route: tuple[Pose, Pose] | None = None
    """Start and goal to keep (a child's of its parent); None: drawn from the seed."""
    features: np.ndarray | None = None
    environment: Environment | None = None
    encounter: float = math.inf
    """m, the closest encounter forecast for its simulator seed (inf: no agents)."""
    seed_options: list[int] = field(default_factory=list)
    """Simulator seeds its agents' encounter may be forecast for (its own first), drawn when
    the screen keeps it; forecast only while it could still be the one run (``_best``)."""


@dataclass
class Parent:
    """A test that showed a new fault situation, and its children's record."""

    test: Test
    key: FaultKey
    route: tuple[Pose, Pose]
    """The start and goal it failed with."""
    children: int = 0
    new_faults: int = 0
    """Children that showed a new fault situation."""
    barren: int = 0
    """Children since its last child with a new fault situation."""

    def credit(self, new: bool) -> None:
        self.children += 1
        self.new_faults += new
        self.barren = 0 if new else self.barren + 1


@dataclass
class Record:
    """Trials and successes (a child with a new fault situation) of a parent or operator."""

    trials: int = 0
    successes: int = 0

    @property
    def mean(self) -> float:
        """Posterior mean success rate (uniform prior)."""
        return (1 + self.successes) / (2 + self.trials)

    def draw(self, rng: np.random.Generator) -> float:
        return float(rng.beta(1 + self.successes, 1 + self.trials - self.successes))


SPEED_PRIOR = 0.7
"""Share of the robot's top speed assumed for its average speed before the run has measured
it (Nearness-Diagram's factory episodes: about 0.75)."""
SPEED_SAMPLES = 3
"""Episodes that reached their goal before their measured speed replaces the prior."""
ENCOUNTER_CAP = 10.0
"""m: a closest encounter further than this (or none) is this far for the surrogate."""


@dataclass
class RobotSpeed:
    """The robot under test's average speed (m/s) on its way to a goal, learnt from the run's
    own episodes that reached it (distance travelled / simulation time)."""

    prior: float
    total: float = 0.0
    samples: int = 0

    def add(self, metrics: Mapping[str, Any]) -> None:
        if metrics.get('outcome') != 'goal_reached':
            return
        distance = float(metrics.get('distance_travelled') or 0.0)
        duration = float(metrics.get('simulation_time') or 0.0)
        if distance > 0 and duration > 0:
            self.total += distance / duration
            self.samples += 1

    @property
    def value(self) -> float:
        return self.total / self.samples if self.samples >= SPEED_SAMPLES else self.prior


class ScreenedSearch:
    """``screened``: the module docstring's search, ask/tell."""

    name = 'screened'

    def __init__(self, scenario: str, seed: int, checkpoint: str | bytes | None = None,
                 config: ScreenedConfig | None = None,
                 size: tuple[int, int] | None = None, controller: str = '') -> None:
        """``controller``: the built-in controller under test ('' or another stack's: the
        scenario's robot), whose robot the simulators host; with the defaults' agents it sets
        the episodes whose agents the screen forecasts."""
        self.config = config or ScreenedConfig()
        self.config.validate()
        self.spec = get_scenario(scenario)
        self.episode_config = _episode_config(self.spec.name, controller)
        robot = create_robot(str(self.episode_config.robot), self.episode_config.robot_params)
        self.robot_speed = RobotSpeed(SPEED_PRIOR * robot.top_speed)
        self.pyramid, self.size = load_generator(scenario, checkpoint, size)
        # Realism is measured against the map the generator learned.
        self.example = checkpoint_training_map(scenario, checkpoint)
        self.rng = method_rng(seed, self.name)
        self.archive = FaultArchive(self.config.rule)
        self.situations = SituationArchive()
        self.surrogate = OnlineLogistic(len(FEATURE_NAMES) + 2)
        self.parents: list[Parent] = []
        self.route_faults: dict[tuple[tuple[Pose, Pose], int], set[tuple[int, int, str]]] = {}
        """Fault places (coarse row, col, context) shown by the tests of each start, goal and
        simulator seed: a child that keeps one of them would most likely show it again."""
        self.operators = {operator.name: operator for operator in self.config.operators}
        self.operator_records = {name: Record() for name in self.operators}
        self.fresh_record = Record()
        """Fresh samples run and those that showed a new fault situation."""
        self.asked = 0
        self.fresh_asked = 0
        self.told = 0
        self.screened = 0
        """Candidates certified and scored (proposed or not)."""
        self.cheap_wall_time = 0.0
        """Wall seconds spent screening and learning (never in the robot under test)."""
        self._pending: list[Test] = []
        started = time.perf_counter()
        reference = self.express([seed_noise_maps(self.pyramid, self._seed(), self.size)
                                   for _ in range(self.config.reference_maps)])
        self.tpkl_limit = float(np.quantile([self._tpkl(cells) for cells in reference],
                                            self.config.tpkl_quantile))
        self.cheap_wall_time += time.perf_counter() - started

    # ---- ask ---------------------------------------------------------------------------

    def ask(self) -> list[Proposal]:
        started = time.perf_counter()
        self._pending = []
        for _ in range(self.config.batch):
            explore = (not self.parents or self.fresh_asked
                       < self.config.exploration * (self.asked + 1))
            test = (None if explore else self._child_test()) or self._fresh_test()
            self.fresh_asked += test.parent is None
            self.asked += 1
            self._pending.append(test)
        self.cheap_wall_time += time.perf_counter() - started
        return [Proposal(test.cells, test.sim_seed, test.map_seed, test.origin,
                         test.environment_seed, test.environment) for test in self._pending]

    def _seed(self) -> int:
        return int(self.rng.integers(0, SEED_BOUND))

    def express(self, noises: Sequence[NoiseMaps]) -> list[np.ndarray]:
        """The cleaned token map (height x width cells) the generator makes of each noise."""
        return list(clean_generated_maps(sample_token_maps_from_noise(self.pyramid, noises),
                                         self.spec.name))

    def _tpkl(self, cells: np.ndarray) -> float:
        value = tile_pattern_kl(self.example, [np.asarray(cells)])
        return value if math.isfinite(value) else math.inf

    def _fresh_test(self) -> Test:
        def draw(count: int) -> list[Test]:
            seeds = [self._seed() for _ in range(count)]
            noises = [seed_noise_maps(self.pyramid, seed, self.size) for seed in seeds]
            return [Test(noise, cells, seed, seed, self._seed(), 'fresh sample')
                    for noise, cells, seed in zip(noises, self.express(noises), seeds)]
        # A generator whose samples all fail the screen: run the last like random does.
        return (self._screen(draw, self.config.fresh_candidates * self.config.effort)
                or draw(1)[0])

    def _pick_parent(self) -> int | None:
        """Thompson sampling over the parents not retired and fresh samples (None: a fresh
        sample)."""
        records = self._parent_records()
        live = self._live_parents(records)
        if not live:
            return None
        draws = [records[index].draw(self.rng) for index in live]
        if self.fresh_record.draw(self.rng) > max(draws):
            return None
        return live[int(np.argmax(draws))]

    def _live_parents(self, records: list[Record] | None = None) -> list[int]:
        """Indices of the parents not retired (the module docstring), given their records
        (default: computed)."""
        records = self._parent_records() if records is None else records
        fresh = self.fresh_record.mean
        return [index for index, (parent, record) in enumerate(zip(self.parents, records))
                if parent.barren < self.config.retire_after or record.mean > fresh]

    def _child_test(self) -> Test | None:
        index = self._pick_parent()
        if index is None:
            return None
        parent = self.parents[index]
        names = list(self.operators)
        operator = self.operators[names[int(np.argmax(
            [self.operator_records[name].draw(self.rng) for name in names]))]]

        def draw(count: int) -> list[Test]:
            base = parent.test
            noises = [self.mutate(parent, operator) for _ in range(count)]
            maps = self.express(noises) if operator.strength > 0 else [base.cells] * count
            children = []
            for noise, cells in zip(noises, maps):
                environment_seed = (base.environment_seed if operator.keep_route
                                    else self._seed())
                sim_seed = self._seed() if operator.new_sim_seed else base.sim_seed
                children.append(Test(
                    noise, cells, base.map_seed if operator.strength == 0 else -1,
                    environment_seed, sim_seed,
                    f'child of {parent.key.label} by {operator.name}', index, operator.name,
                    parent.route if operator.keep_route else None))
            return children
        test = self._screen(draw, self.config.child_candidates * self.config.effort)
        if test is None:
            # No child worth an episode: a failed trial of the parent and the operator, and
            # the slot goes to a fresh sample.
            parent.credit(False)
            self.operator_records[operator.name].trials += 1
        return test

    def mutate(self, parent: Parent, operator: Operator,
               rng: np.random.Generator | None = None) -> NoiseMaps:
        """A child of ``parent``'s noise by ``operator`` (its noise itself at strength 0;
        a local operator changes only the noise around the parent's fault cell), drawn from
        ``rng`` (default: the search's own stream)."""
        rng = self.rng if rng is None else rng
        noise = parent.test.noise
        if operator.strength == 0:
            return noise
        scales = None if operator.scales is None else tuple(
            scale % len(noise) for scale in operator.scales)
        if not operator.local:
            return mutate_noise(noise, rng, operator.strength, scales=scales)
        rule = self.config.rule
        height, width = np.shape(parent.test.cells)
        side = rule.coarse_cells
        region = (max(0.0, (parent.key.row * side - rule.context_cells) / height),
                  max(0.0, (parent.key.col * side - rule.context_cells) / width),
                  min(1.0, ((parent.key.row + 1) * side + rule.context_cells) / height),
                  min(1.0, ((parent.key.col + 1) * side + rule.context_cells) / width))
        return mutate_noise_region(noise, rng, operator.strength, region,
                                   scales or (len(noise) - 1,))

    def _parent_records(self) -> list[Record]:
        return [Record(parent.children, parent.new_faults) for parent in self.parents]

    def _screen(self, draw: Callable[[int], list[Test]], count: int) -> Test | None:
        """The best of ``count`` candidates from ``draw`` (more when all are dropped; None
        when every retry is dropped too)."""
        candidates: list[tuple[Test, CertifiedCandidate]] = []
        for attempt in range(1 + self.config.retries):
            kept = []
            for test in draw(count if attempt == 0 else 1):
                self.screened += 1
                occupancy = tokens_to_occupancy(test.cells, self.spec)
                # The cheap checks first: most of a candidate's cost is its certificate.
                if self._tpkl(test.cells) > self.tpkl_limit \
                        or self._repeats_lineage(test, occupancy):
                    continue
                certified = (certify_candidate(occupancy, self.spec, test.environment_seed)
                             if test.route is None else
                             certify_route(occupancy, self.spec, *test.route))
                if certified.feasible:
                    test.features = route_features(certified, self.spec)
                    test.environment = environment_of(certified, self.spec, self.name,
                                                      test.environment_seed)
                    self._draw_sim_seeds(test)
                    kept.append((test, certified))
            candidates += kept
            if candidates:
                break
        else:
            return None
        return self._best(candidates)

    def _best(self, candidates: list[tuple[Test, CertifiedCandidate]]) -> Test:
        """The highest-scoring candidate (the first of equals), run with its picked simulator
        seed. The pick (most of the screen's cost) moves a score only through the surrogate's
        encounter feature, so never above the score at encounter 0 or at ``ENCOUNTER_CAP``:
        candidates are picked in order of that bound until none left could beat the best,
        which chooses what picking every candidate would."""
        novelty = [self._novelty(certified) for _, certified in candidates]
        bounds = [self._score(test, value, bound=True)
                  for (test, _), value in zip(candidates, novelty)]
        scores: dict[int, float] = {}
        for index in sorted(range(len(candidates)), key=lambda index: -bounds[index]):
            # A relative margin, so a float's rounding cannot skip a better candidate.
            if scores and max(scores.values()) > bounds[index] * (1 + 1e-9):
                break
            test, certified = candidates[index]
            self.pick_sim_seed(test, certified)
            scores[index] = self._score(test, novelty[index])
        return candidates[max(scores, key=lambda index: (scores[index], -index))][0]

    def _repeats_lineage(self, test: Test, occupancy: np.ndarray) -> bool:
        """Whether a child keeps its parent's start, goal and simulator seed and the map
        around a fault place that a test with them showed (the parent's own, or a sibling's
        or an ancestor's): the robot would most likely drive there as before and show that
        fault again."""
        if test.parent is None or test.route is None:
            return False
        places = self.route_faults.get((test.route, test.sim_seed), ())
        return any(place_context(occupancy, row, col, self.config.rule) == context
                   for row, col, context in places)

    def _novelty(self, certified: CertifiedCandidate) -> float:
        """Halved for every known fault along the route (the module docstring)."""
        cells = route_coarse_cells(certified, self.config.rule)
        return 0.5 ** max(self.archive.known_places_on(certified, cells),
                          self.situations.known_on(certified.occupancy, cells))

    def _score(self, test: Test, novelty: float, bound: bool = False) -> float:
        """``novelty`` times P(failure) by the surrogate (route length before it is
        trained); ``bound``: the most any simulator seed's encounter could make it."""
        assert test.features is not None
        if self.told < self.config.surrogate_warmup or not self.surrogate.trained:
            # Longer routes expose more (the screening pilot): rank by length in metres.
            return novelty * float(test.features[0])
        rows = ([self._row(test, 0.0), self._row(test, ENCOUNTER_CAP)] if bound
                else [self._row(test)])
        return novelty * float(self.surrogate.predict(np.stack(rows)).max())

    def _draw_sim_seeds(self, test: Test) -> None:
        """The simulator seeds, of ``agent_seeds`` (its own first), whose agents'
        encounter the pick may forecast; none without agents."""
        if int(self.episode_config.dummy_agents or 0) > 0:
            tries = self.config.agent_seeds * self.config.effort
            test.seed_options = [test.sim_seed] + [self._seed() for _ in range(tries - 1)]

    def pick_sim_seed(self, test: Test, certified: CertifiedCandidate) -> None:
        """Run ``test`` with the simulator seed, of its ``seed_options``, whose agents come
        closest to the robot on its way; remember that encounter."""
        if not test.seed_options:
            return
        assert test.environment is not None
        certificate = certified.placement.certificate
        assert certificate is not None
        # The certificate's grid is the map's clearance at the search's origin, (0, 0).
        planner = PatrolPlanner(test.environment, self.episode_config, certificate.grid)
        path = reactive_path(certified, self.spec)
        encounters = [closest_encounter(path, planner.patrols(seed), self.robot_speed.value,
                                        self.episode_config.agents.speed)
                      for seed in test.seed_options]
        best = int(np.argmin(encounters))
        test.sim_seed, test.encounter = test.seed_options[best], encounters[best]

    @staticmethod
    def _row(test: Test, encounter: float | None = None) -> np.ndarray:
        """The surrogate's features of ``test`` (with ``encounter`` instead of its own)."""
        assert test.features is not None
        encounter = test.encounter if encounter is None else encounter
        return np.append(test.features, [min(encounter, ENCOUNTER_CAP),
                                         float(test.parent is not None)])

    # ---- tell --------------------------------------------------------------------------

    def tell(self, results: Sequence[Evaluated]) -> None:
        if len(results) != len(self._pending):
            raise SearchMethodError(f'told {len(results)} results for {len(self._pending)} '
                                    'tests asked')
        started = time.perf_counter()
        for test, result in zip(self._pending, results):
            self.told += 1
            self.robot_speed.add(result.metrics)
            failed = is_valid_failure(result.metrics)
            if test.features is not None:
                self.surrogate.add(self._row(test), failed)
            key = self._fault_key(result) if failed else None
            # The start and goal the search certified: a mission's or a fleet's episode draws
            # its own from the seeds (a mission's goal is home, its start), on which no
            # child's route could be certified.
            route = _route_of(test.environment or result.environment)
            if key is not None:
                self.archive.add(key)
                self.route_faults.setdefault((route, test.sim_seed), set()).add(
                    (key.row, key.col, key.context))
            new = key is not None and self.situations.add(key, result.environment.occupancy)
            if test.parent is None:
                self.fresh_record.trials += 1
                self.fresh_record.successes += new
            else:
                self.parents[test.parent].credit(new)
                record = self.operator_records[test.operator]
                record.trials += 1
                record.successes += new
            if new:
                assert key is not None
                self.parents.append(Parent(test, key, route))
        self._pending = []
        self.surrogate.fit()
        self.cheap_wall_time += time.perf_counter() - started

    def _fault_key(self, result: Evaluated) -> FaultKey | None:
        """The key the driver knows (read from a failure bag), else the trace's; None for a
        valid failure that neither places (it then makes no parent and earns no credit)."""
        if result.fault_key is not None or result.trace is None:
            return result.fault_key
        try:
            return key_of_failure(result.environment, result.metrics, result.trace,
                                  self.config.rule)
        except FaultError as err:
            raise SearchMethodError(f'the screened search keys failures by their episode '
                                    f'trace: {err}') from err


def _episode_config(scenario: str, controller: str) -> EpisodeConfig:
    """The episode config (its seed aside) of a simulator with the default settings hosting
    ``controller``'s robot; another stack's (not a built-in controller) gets the scenario's."""
    try:
        settings = settings_for_controller(
            scenario, get_controller(controller or get_scenario(scenario).controller))
    except UnknownControllerError:
        settings = SimulatorSettings()
    return settings.episode_config(seed=0).resolved(get_scenario(scenario))


def _route_of(environment: Environment) -> tuple[Pose, Pose]:
    """(start, goal) of an environment as (x, y, yaw) each, in the search's frame (the map
    at (0, 0); a driver runs it where the generator's training map lies)."""
    at_zero = environment.moved_to((0.0, 0.0))
    start, goal = at_zero.start, at_zero.goal
    return (start.x, start.y, start.yaw), (goal.x, goal.y, goal.yaw)


AGENT_FAULT = FAULT_KIND_OF_CONTACT[ContactKind.ROBOT_INTO_AGENT.value]
"""The fault kind of a drive into an agent."""
ARCHIVE_TRIES = 8
"""Children an archive test draws before it falls back to its parent's own map."""
ARCHIVE_STREAM = 20
"""Mixed into each map seed, so an archive's random draws are its own, not those a generator
or the search makes from the same number."""


class ArchiveSource:
    """A finished screened search's archive as a generator of tests, for fresh-seed
    evaluation (sessgan_evolver.fresh_seed): what a user takes home besides the faults.

    Map seed ``m`` alone picks one of the search's parents (tests that showed a new fault
    situation) and makes a child of it with the operator that earned the most new situations
    in the run (posterior mean), the parent's start and goal kept and re-certified, as the
    search made children; after ``ARCHIVE_TRIES`` children without a certified route the test
    is the parent's own map. The simulator seed is the evaluation's (fresh), so an archived
    failure shows again only where it is a property of the test, not of one agent draw: the
    parents drawn are those whose fault the map made (a wall, a dead end), not a drive into an
    agent, which depended on where that episode's agents walked (all parents when every fault
    was one)."""

    def __init__(self, search: ScreenedSearch, label: str,
                 origin: tuple[float, float] = (0.0, 0.0)) -> None:
        """``origin``: where its maps sit in the map frame (the generator's training map's
        origin); the search itself works at (0, 0)."""
        if not search.parents:
            raise SearchMethodError('the screened search has no archive: it found no fault')
        self.search = search
        self.label = label
        self.reference = search.example
        self.origin = origin
        records = search.operator_records
        self.operator = search.operators[max(records, key=lambda name: records[name].mean)]
        self.parents = [parent for parent in search.parents
                        if parent.key.kind != AGENT_FAULT] or search.parents

    def maps(self, seeds: Sequence[int]) -> np.ndarray:
        return np.stack([cells for cells, _ in self.environments(seeds)])

    def environments(self, seeds: Sequence[int]) -> list[tuple[np.ndarray, Environment]]:
        """(token map, Environment) of each map seed (the class docstring)."""
        search, spec = self.search, self.search.spec
        made = []
        for seed in seeds:
            rng = np.random.default_rng([int(seed), ARCHIVE_STREAM])
            parent = self.parents[int(rng.integers(len(self.parents)))]
            cells, certified = parent.test.cells, None
            for _ in range(ARCHIVE_TRIES):
                child = search.express([search.mutate(parent, self.operator, rng)])[0]
                candidate = certify_route(tokens_to_occupancy(child, spec), spec,
                                          *parent.route)
                if candidate.feasible:
                    cells, certified = child, candidate
                    break
            if certified is None:
                certified = certify_route(tokens_to_occupancy(cells, spec), spec,
                                          *parent.route)
            made.append((np.asarray(cells), environment_of(certified, spec, 'archive',
                                                           int(seed))))
        return made
