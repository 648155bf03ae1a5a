"""Search methods that propose test maps directly: the baselines SESS-GAN is compared with.

Each method is an ask/tell object: :meth:`ask` returns a batch of :class:`Proposal` (a token
map and the simulator seed to run it with), :meth:`tell` receives their results. The driver
(sessgan_evolver.search) turns every proposal into an Environment with the same validity
certificate (``make_environment``), runs it with the same episode runner and counts it as
one episode of the budget. SESS-GAN itself (weight evolution) runs as the real Campaign.

* ``random``: the shipped (or a given) generator sampled with fresh seeds;
* ``cellular_automaton``: the BARN-style non-learned generator with fresh seeds;
* ``grid_ga``: a genetic algorithm over token maps (AmbieGen's approach: search the test
  space directly), initial maps from the cellular automaton, operators of map_operators;
* ``latent``: a genetic algorithm over the generator's noise inputs with the weights frozen
  (latent variable evolution, Volz et al. 2018), initial noise = fresh seeds' noise, so
  generation 0 is random sampling of the generator;
* ``screened``: children of failing tests in the generator's latent space and fresh samples,
  screened by cheap signals before they cost an episode (sessgan_evolver.screened_search).

Both genetic algorithms use the campaign's settings (population 12, 1 elite, tournaments of
3, crossover probability 0.5) and its fitness formula for one map per individual
(``member_fitness`` of the one episode, TPKL of the map relative to the mean of generation
0). Elites are not run again: in-process episodes are deterministic, so their result is
known. A test is the map with its environment seed (which places start and goal) and its
simulator seed (agents, sensor noise): a child inherits both from its first parent and
draws each afresh with probability ``seed_mutation``. Every random choice flows from the
method's seed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from sessgan_core.environment import Environment
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import MissionSpec
from sessgan_core.scenarios import get_scenario
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.cellular_automaton import (
    CellularAutomatonConfig,
    CellularAutomatonGenerator,
)
from sessgan_evolver.episode_runner import EpisodeTrace
from sessgan_evolver.errors import SearchMethodError
from sessgan_evolver.faults import FaultKey
from sessgan_evolver.fitness import FitnessConfig, member_fitness
from sessgan_evolver.map_operators import (
    NoiseMaps,
    crossover_noise,
    crossover_token_maps,
    mutate_noise,
    mutate_token_map,
)
from sessgan_gen.checkpoint import (
    checkpoint_training_map,
    default_checkpoint_path,
    load_checkpoint,
)
from sessgan_gen.environment_metrics import tile_pattern_kl
from sessgan_gen.environment_sampler import resolve_sample_size
from sessgan_gen.errors import SamplingRequestError
from sessgan_gen.model import GeneratorPyramid
from sessgan_gen.sampling import (
    sample_token_maps,
    sample_token_maps_from_noise,
    seed_noise_maps,
)
from sessgan_gen.track_cleanup import clean_generated_maps

SEED_BOUND = 2**32
"""Map and simulator seeds lie in [0, SEED_BOUND), like the campaign's."""


@dataclass(frozen=True)
class Proposal:
    """One test to run: a token map and a simulator seed."""

    cells: np.ndarray
    sim_seed: int
    map_seed: int = -1
    """The generator seed that made the map (-1: not a generator's sample)."""
    origin: str = ''
    """How it was made, for logs (e.g. 'generation 3 crossover 2x7 + paint')."""
    environment_seed: int | None = None
    """The Environment's seed (start and goal placement); None: the map seed (0 if none)."""
    environment: Environment | None = None
    """A plain episode's Environment the method built and certified itself (its own start
    and goal, e.g. another map's); None: the driver builds it from the seeds."""

    @property
    def resolved_environment_seed(self) -> int:
        if self.environment_seed is not None:
            return int(self.environment_seed)
        return max(int(self.map_seed), 0)

    def test_environment(self, scenario: str, environment_id: str, mission: MissionSpec,
                         fleet: FleetSpec, origin: tuple[float, float] = (0.0, 0.0),
                         generation: int = -1, member: int = -1) -> Environment:
        """The Environment this proposal runs as, with its map at ``origin``: the method's own
        for a plain episode (a screened child keeps its parent's start and goal), else drawn
        from the seeds (missions and fleets are drawn so for every method)."""
        if self.environment is not None and mission.stations == 0 and fleet.robots == 1:
            return replace(self.environment, id=environment_id, generation=generation,
                           member=member).moved_to(origin)
        return make_environment(self.cells, scenario, environment_id,
                                seed=self.resolved_environment_seed, generation=generation,
                                member=member, mission=mission, fleet=fleet, origin=origin)


@dataclass(frozen=True)
class Evaluated:
    """A proposal, its Environment and its episode metrics."""

    proposal: Proposal
    environment: Environment
    metrics: Mapping[str, Any]
    trace: EpisodeTrace | None = None
    """The episode's trace (where a failure happened), when the driver kept one."""
    fault_key: FaultKey | None = None
    """The fault key of a valid failure when the driver knows it without a trace (a campaign
    reads it from the failure bag of an episode that ran on a worker)."""


class SearchMethod(Protocol):
    """What the search driver needs from a method."""

    name: str

    def ask(self) -> list[Proposal]:
        """The next batch of tests (never empty)."""
        ...

    def tell(self, results: Sequence[Evaluated]) -> None:
        """The results of the last batch, in the order asked."""
        ...


def method_rng(seed: int, method: str) -> np.random.Generator:
    """The random generator of one method's search with ``seed``."""
    tag = int.from_bytes(method.encode()[:8].ljust(8, b'\0'), 'little')
    return np.random.default_rng(np.random.SeedSequence([int(seed), tag]))


def load_pyramid(scenario: str, checkpoint: str | bytes | None) -> GeneratorPyramid:
    """The generator to sample: ``checkpoint`` (a path or bytes) or the scenario's shipped."""
    return load_generator(scenario, checkpoint)[0]


def load_generator(scenario: str, checkpoint: str | bytes | None,
                   size: tuple[int, int] | None = None
                   ) -> tuple[GeneratorPyramid, tuple[int, int]]:
    """(generator, map size): ``size`` (height, width) as the sampler resolves it (None or a
    zero side: the checkpoint's training map's), so every method searches maps of the size
    the generator serves."""
    source = checkpoint or default_checkpoint_path(scenario)
    pyramid, metadata = load_checkpoint(source, scenario=scenario)
    try:
        return pyramid, resolve_sample_size(pyramid, metadata, size, scenario)
    except SamplingRequestError as err:
        raise SearchMethodError(str(err)) from err


class RandomSampling:
    """``random``: the generator with fresh seeds, ``batch`` maps per ask."""

    name = 'random'

    def __init__(self, scenario: str, seed: int, checkpoint: str | bytes | None = None,
                 batch: int = 12, size: tuple[int, int] | None = None) -> None:
        self.pyramid, self.size = load_generator(scenario, checkpoint, size)
        self.scenario = scenario
        self.rng = method_rng(seed, self.name)
        self.batch = batch

    def ask(self) -> list[Proposal]:
        seeds = self.rng.integers(0, SEED_BOUND, size=(self.batch, 2))
        # As the sampler serves them: the scenario's track_cleanup applied.
        maps = clean_generated_maps(
            sample_token_maps(self.pyramid, [int(s) for s in seeds[:, 0]], self.size),
            self.scenario)
        return [Proposal(cells, int(sim), int(map_seed), 'random sample')
                for cells, (map_seed, sim) in zip(maps, seeds)]

    def tell(self, results: Sequence[Evaluated]) -> None:
        """Random sampling learns nothing."""


class CellularAutomatonSampling:
    """``cellular_automaton``: the BARN-style generator with fresh seeds."""

    name = 'cellular_automaton'

    def __init__(self, scenario: str, seed: int, config: CellularAutomatonConfig | None = None,
                 batch: int = 12, checkpoint: str | bytes | None = None,
                 size: tuple[int, int] | None = None) -> None:
        """``checkpoint``, ``size``: maps of the size that generator serves (None: the
        shipped one's), or of ``size``."""
        self.generator = CellularAutomatonGenerator(
            scenario, config, load_generator(scenario, checkpoint, size)[1])
        self.rng = method_rng(seed, self.name)
        self.batch = batch

    def ask(self) -> list[Proposal]:
        seeds = self.rng.integers(0, SEED_BOUND, size=(self.batch, 2))
        maps = self.generator.maps([int(s) for s in seeds[:, 0]])
        return [Proposal(cells, int(sim), int(map_seed), 'cellular automaton')
                for cells, (map_seed, sim) in zip(maps, seeds)]

    def tell(self, results: Sequence[Evaluated]) -> None:
        """The cellular automaton learns nothing."""


# ---- genetic algorithms over test cases ------------------------------------------------------

Genotype = TypeVar('Genotype')


@dataclass(frozen=True)
class GAConfig:
    """Settings of the genetic algorithms over maps or noise (defaults: the campaign's)."""

    population: int = 12
    elite_count: int = 1
    tournament_size: int = 3
    crossover_probability: float = 0.5
    seed_mutation: float = 0.2
    """Probability that a child draws a fresh simulator seed (and, independently, a fresh
    environment seed) instead of its parent's."""
    noise_strength: float = 0.3
    """latent: s of ``mutate_noise`` (a child's noise keeps a correlation of 0.95)."""
    fitness: FitnessConfig = field(default_factory=FitnessConfig)

    def validate(self) -> None:
        if self.population < 2:
            raise SearchMethodError(f'population must be >= 2, got {self.population}')
        if not 0 <= self.elite_count < self.population:
            raise SearchMethodError(f'elite_count must lie in [0, population), got '
                                    f'{self.elite_count}')
        if self.tournament_size < 1:
            raise SearchMethodError(f'tournament_size must be >= 1, got {self.tournament_size}')
        for name in ('crossover_probability', 'seed_mutation', 'noise_strength'):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise SearchMethodError(f'{name} must lie in [0, 1], got {getattr(self, name)}')
        self.fitness.validate()


@dataclass
class Individual(Generic[Genotype]):
    genotype: Genotype
    sim_seed: int
    origin: str
    environment_seed: int
    fitness: float | None = None
    map_seed: int = -1


class MapSearchGA(Generic[Genotype]):
    """Generational GA with elitism over test cases; subclasses say what a genotype is."""

    name = ''

    def __init__(self, scenario: str, seed: int, config: GAConfig | None = None,
                 checkpoint: str | bytes | None = None) -> None:
        """``checkpoint``: the generator compared with (None: the shipped one); its training
        map is the TPKL reference of the fitness."""
        self.config = config or GAConfig()
        self.config.validate()
        self.spec = get_scenario(scenario)
        self.example = checkpoint_training_map(scenario, checkpoint)
        self.rng = method_rng(seed, self.name)
        self.generation = 0
        self.tpkl_reference: float | None = None
        self.population: list[Individual[Genotype]] = [
            self._first(index) for index in range(self.config.population)]
        self._pending: list[Individual[Genotype]] = []

    # -- what a subclass supplies --------------------------------------------------------

    def initial(self, index: int) -> tuple[Genotype, int]:
        """Generation 0's genotype ``index`` and its generator seed (-1 if none)."""
        raise NotImplementedError

    def mutate(self, genotype: Genotype) -> tuple[Genotype, str]:
        raise NotImplementedError

    def crossover(self, first: Genotype, second: Genotype) -> Genotype:
        raise NotImplementedError

    def express(self, genotypes: list[Genotype]) -> list[np.ndarray]:
        """The token maps of ``genotypes``."""
        raise NotImplementedError

    # -- ask / tell ----------------------------------------------------------------------

    def _fresh_seed(self) -> int:
        return int(self.rng.integers(0, SEED_BOUND))

    def _first(self, index: int) -> Individual[Genotype]:
        genotype, map_seed = self.initial(index)
        environment_seed = map_seed if map_seed >= 0 else self._fresh_seed()
        return Individual(genotype, self._fresh_seed(), 'generation 0', environment_seed,
                          map_seed=map_seed)

    def ask(self) -> list[Proposal]:
        self._pending = [member for member in self.population if member.fitness is None]
        maps = self.express([member.genotype for member in self._pending])
        return [Proposal(cells, member.sim_seed, member.map_seed,
                         f'generation {self.generation} {member.origin}',
                         member.environment_seed)
                for cells, member in zip(maps, self._pending)]

    def tell(self, results: Sequence[Evaluated]) -> None:
        if len(results) != len(self._pending):
            raise SearchMethodError(f'told {len(results)} results for {len(self._pending)} '
                                    'tests asked')
        tpkls = [tile_pattern_kl(self.example, [np.asarray(result.proposal.cells)])
                 for result in results]
        if self.tpkl_reference is None:
            finite = [t for t in tpkls if math.isfinite(t)]
            self.tpkl_reference = float(np.mean(finite)) if finite else 1.0
        for member, result, tpkl in zip(self._pending, results, tpkls):
            member.fitness = member_fitness([result.metrics], tpkl, self.tpkl_reference, None,
                                            self.config.fitness).fitness
        self._pending = []
        self._breed()

    def _breed(self) -> None:
        config = self.config
        fitnesses = [float(member.fitness) if member.fitness is not None else -math.inf
                     for member in self.population]
        ranking = sorted(range(len(self.population)), key=lambda i: (-fitnesses[i], i))
        children: list[Individual[Genotype]] = [self.population[i]
                                                for i in ranking[:config.elite_count]]
        while len(children) < config.population:
            first = self._tournament(fitnesses)
            parent = self.population[first]
            if self.rng.random() < config.crossover_probability:
                second = self._tournament(fitnesses)
                genotype = self.crossover(parent.genotype, self.population[second].genotype)
                made = f'crossover {first}x{second}'
            else:
                genotype = parent.genotype
                made = f'from {first}'
            genotype, edit = self.mutate(genotype)
            sim_seed = (self._fresh_seed() if self.rng.random() < config.seed_mutation
                        else parent.sim_seed)
            environment_seed = (self._fresh_seed() if self.rng.random() < config.seed_mutation
                                else parent.environment_seed)
            children.append(Individual(genotype, sim_seed, f'{made} + {edit}',
                                       environment_seed))
        self.population = children
        self.generation += 1

    def _tournament(self, fitnesses: list[float]) -> int:
        size = min(self.config.tournament_size, len(fitnesses))
        contestants = self.rng.choice(len(fitnesses), size=size, replace=False)
        return min((int(i) for i in contestants), key=lambda i: (-fitnesses[i], i))


class GridGA(MapSearchGA[np.ndarray]):
    """``grid_ga``: a GA over token maps (module docstring)."""

    name = 'grid_ga'

    def __init__(self, scenario: str, seed: int, config: GAConfig | None = None,
                 automaton: CellularAutomatonConfig | None = None,
                 checkpoint: str | bytes | None = None,
                 size: tuple[int, int] | None = None) -> None:
        self.automaton = CellularAutomatonGenerator(
            scenario, automaton, load_generator(scenario, checkpoint, size)[1])
        super().__init__(scenario, seed, config, checkpoint)

    def initial(self, index: int) -> tuple[np.ndarray, int]:
        seed = int(self.rng.integers(0, SEED_BOUND))
        return self.automaton.one(seed), seed

    def mutate(self, genotype: np.ndarray) -> tuple[np.ndarray, str]:
        return mutate_token_map(genotype, self.spec.num_tokens, self.rng, self.automaton.border)

    def crossover(self, first: np.ndarray, second: np.ndarray) -> np.ndarray:
        return crossover_token_maps(first, second, self.rng, self.automaton.border)

    def express(self, genotypes: list[np.ndarray]) -> list[np.ndarray]:
        return [np.asarray(genotype) for genotype in genotypes]


class LatentEvolution(MapSearchGA[NoiseMaps]):
    """``latent``: a GA over the generator's noise maps, weights frozen (module docstring)."""

    name = 'latent'

    def __init__(self, scenario: str, seed: int, config: GAConfig | None = None,
                 checkpoint: str | bytes | None = None,
                 size: tuple[int, int] | None = None) -> None:
        self.pyramid, self.size = load_generator(scenario, checkpoint, size)
        super().__init__(scenario, seed, config, checkpoint)

    def initial(self, index: int) -> tuple[NoiseMaps, int]:
        seed = int(self.rng.integers(0, SEED_BOUND))
        return seed_noise_maps(self.pyramid, seed, self.size), seed

    def mutate(self, genotype: NoiseMaps) -> tuple[NoiseMaps, str]:
        return mutate_noise(genotype, self.rng, self.config.noise_strength), 'noise'

    def crossover(self, first: NoiseMaps, second: NoiseMaps) -> NoiseMaps:
        return crossover_noise(first, second, self.rng)

    def express(self, genotypes: list[NoiseMaps]) -> list[np.ndarray]:
        return list(clean_generated_maps(
            sample_token_maps_from_noise(self.pyramid, genotypes), self.spec.name))


def _screened(scenario: str, seed: int, checkpoint: str | bytes | None, ga: GAConfig | None,
              size: tuple[int, int] | None, controller: str, effort: int,
              exploration: float) -> SearchMethod:
    # Imported here: sessgan_evolver.screened_search builds on this module's types.
    from sessgan_evolver.screened_search import ScreenedConfig, ScreenedSearch

    config = ScreenedConfig(effort=effort)
    if exploration:
        config = replace(config, exploration=exploration)
    return ScreenedSearch(scenario, seed, checkpoint, config, size, controller)


BaselineFactory = Callable[[str, int, 'str | bytes | None', 'GAConfig | None',
                            'tuple[int, int] | None', str, int, float], SearchMethod]
"""(scenario, search seed, generator checkpoint or None, GA settings or None, map size or
None: the generator's, controller under test or '', screening effort, exploration share or
0: the method's default) -> method."""

BASELINES: dict[str, BaselineFactory] = {
    'random': lambda scenario, seed, checkpoint, ga, size, *screening: RandomSampling(
        scenario, seed, checkpoint, size=size),
    'grid_ga': lambda scenario, seed, checkpoint, ga, size, *screening: GridGA(
        scenario, seed, ga, checkpoint=checkpoint, size=size),
    'cellular_automaton': lambda scenario, seed, checkpoint, ga, size, *screening:
        CellularAutomatonSampling(scenario, seed, checkpoint=checkpoint, size=size),
    'latent': lambda scenario, seed, checkpoint, ga, size, *screening: LatentEvolution(
        scenario, seed, ga, checkpoint, size),
    'screened': _screened,
}
"""Methods the search driver runs, by name (``sessgan`` runs as the real Campaign)."""

EXTERNAL_SCREENING_EFFORT = 3
"""The screened method's default effort (ScreenedConfig.effort) against a stack already
running (``--external``): its episode costs 10-60 s, against which three times the screen
(0.1-0.5 s a test) is a few per cent."""
IN_PROCESS_SCREENING_EFFORT = {True: 2, False: 1}
"""Its default with a built-in controller, by whether the scenario's episodes have dummy
agents. An episode costs 0.1-0.7 s there; effort 2 found more faults than 1 on six of the
eight robot x budget pairs measured (13 % fewer with the reference navigator on the factory,
within the seeds' spread), at a tenth to 29 % of the search's wall time; on the race track
(no agents) effort 3 found no more than 1 (README, *Screening effort*)."""


def check_exploration(exploration: float) -> None:
    """SearchMethodError unless ``exploration`` is a share of tests (0: the default)."""
    if not 0.0 <= exploration <= 1.0:
        raise SearchMethodError(f"exploration must lie in [0, 1] (0: the screened method's "
                                f'default), got {exploration}')


def screening_effort(requested: int, external: bool, scenario: str) -> int:
    """The screened method's effort: ``requested``, or by default (0) the defaults above."""
    if requested < 0:
        raise SearchMethodError(f'screening effort must be >= 0 (0: the default, '
                                f'{EXTERNAL_SCREENING_EFFORT} with external), got {requested}')
    if requested:
        return requested
    if external:
        return EXTERNAL_SCREENING_EFFORT
    return IN_PROCESS_SCREENING_EFFORT[get_scenario(scenario).dummy_agents > 0]


METHODS = ('sessgan', 'random', 'grid_ga', 'cellular_automaton', 'latent', 'screened')
"""Every method ``compare`` knows, in report order."""


def make_baseline(name: str, scenario: str, seed: int, checkpoint: str | bytes | None = None,
                  ga_config: GAConfig | None = None, size: tuple[int, int] | None = None,
                  controller: str = '', screening_effort: int = 1,
                  exploration: float = 0.0) -> SearchMethod:
    """A baseline by name (SearchMethodError lists the known ones); ``size``: (height, width)
    of its maps (None or a zero side: the generator's training map's); ``controller``: the
    one under test ('' for the scenario's or another stack), for a method that screens
    tests by its robot; ``screening_effort`` and ``exploration`` (0: its default): the
    screened method's (ScreenedConfig.effort and .exploration)."""
    try:
        factory = BASELINES[name]
    except KeyError as err:
        raise SearchMethodError(f'unknown search method {name!r}; known: '
                                f'{", ".join(METHODS)}') from err
    check_exploration(exploration)
    return factory(scenario, seed, checkpoint, ga_config, size, controller, screening_effort,
                   exploration)
