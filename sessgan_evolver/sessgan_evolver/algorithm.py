"""The genetic algorithm over generator genomes, with an ask/tell interface.

The algorithm knows nothing about maps or simulation (that is the problem, see
``fitness``): ``ask()`` hands out the genomes of the current generation, the caller
evaluates them anywhere (workers, out of order) and reports fitnesses with ``tell()`` or
member by member with ``tell_one()``. Fitness is maximised.

The whole state (generation index, population, fitnesses told so far, lineage, the numpy
random state) is plain data returned by ``state_dict()``; ``from_state_dict()`` restores an
algorithm that continues exactly as the original would have.

One generation step (``tell``):
  1. rank members by fitness (ties: lower member index first);
  2. the ``elite_count`` best are copied unchanged to the next generation;
  3. every other child: a parent by tournament (``tournament_size`` distinct members, the
     fittest wins); with probability ``crossover_probability`` a second parent by another
     tournament and a tensor-wise crossover; then Gaussian mutation (``genome_operators``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from sessgan_evolver.errors import AlgorithmStateError, GenomeError
from sessgan_evolver.genome import Genome
from sessgan_evolver.genome_operators import OperatorConfig, crossover, mutate

STATE_FORMAT = 'sessgan_evolver.genetic_algorithm/1'
"""Tag of ``state_dict()`` payloads; other payloads are rejected."""


@dataclass(frozen=True)
class GeneticAlgorithmConfig:
    """Parameters of the genetic algorithm (defaults in brackets)."""

    population_size: int = 12
    """[12] Members per generation."""
    elite_count: int = 1
    """[1] Best members copied unchanged into the next generation (and re-evaluated there
    on that generation's maps)."""
    tournament_size: int = 3
    """[3] Distinct members drawn per tournament; the fittest is selected as a parent."""
    crossover_probability: float = 0.5
    """[0.5] Probability that a child has two parents (tensor-wise crossover) rather than
    being a mutated copy of one."""
    keep_original: bool = True
    """[True] Member 0 of generation 0 is the pre-trained genome unmutated (a baseline
    that elitism keeps while nothing beats it)."""
    seed: int = 0
    """[0] Seed of every random choice of the algorithm (selection, crossover, noise)."""
    operators: OperatorConfig = field(default_factory=OperatorConfig)
    """Crossover and mutation parameters."""

    def validate(self) -> None:
        """Raise AlgorithmStateError naming the first invalid field."""
        if self.population_size < 1:
            raise AlgorithmStateError(
                f'population_size must be >= 1, got {self.population_size}')
        if not 0 <= self.elite_count <= self.population_size:
            raise AlgorithmStateError(f'elite_count must lie in [0, population_size='
                                      f'{self.population_size}], got {self.elite_count}')
        if self.tournament_size < 1:
            raise AlgorithmStateError(
                f'tournament_size must be >= 1, got {self.tournament_size}')
        if not 0.0 <= self.crossover_probability <= 1.0:
            raise AlgorithmStateError(f'crossover_probability must lie in [0, 1], got '
                                      f'{self.crossover_probability}')
        if self.seed < 0:
            raise AlgorithmStateError(f'seed must be >= 0, got {self.seed}')
        try:
            self.operators.validate()
        except GenomeError as err:
            raise AlgorithmStateError(f'invalid operator config: {err}') from err

    def to_dict(self) -> dict[str, Any]:
        """Plain data (nested dicts), e.g. for config.json and checkpoints."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GeneticAlgorithmConfig:
        """Inverse of ``to_dict``; unknown keys are an error."""
        values = dict(data)
        try:
            operators = OperatorConfig(**values.pop('operators', {}))
            return cls(operators=operators, **values)
        except TypeError as err:
            raise AlgorithmStateError(f'invalid genetic algorithm config: {err}') from err


@dataclass(frozen=True)
class MemberOrigin:
    """How a member of the current generation was made (for logs and the report)."""

    kind: str
    """'original' (pre-trained, unmutated), 'initial' (mutated pre-trained), 'elite'
    (copied unchanged) or 'offspring' (selection, optional crossover, mutation)."""
    parents: tuple[int, ...] = ()
    """Member indices in the previous generation (empty in generation 0)."""

    def to_dict(self) -> dict[str, Any]:
        return {'kind': self.kind, 'parents': list(self.parents)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MemberOrigin:
        return cls(kind=str(data['kind']), parents=tuple(int(p) for p in data['parents']))


@dataclass(frozen=True)
class GenerationResult:
    """The outcome of one evaluated generation, returned when it is complete."""

    generation: int
    fitnesses: tuple[float, ...]
    ranking: tuple[int, ...]
    """Member indices, fittest first."""
    elite_members: tuple[int, ...]
    """Members copied unchanged into the next generation."""

    @property
    def best_member(self) -> int:
        return self.ranking[0]

    @property
    def best_fitness(self) -> float:
        return self.fitnesses[self.ranking[0]]

    @property
    def mean_fitness(self) -> float:
        """Mean over members with a finite fitness (NaN if none)."""
        finite = [f for f in self.fitnesses if math.isfinite(f)]
        return float(np.mean(finite)) if finite else math.nan


@dataclass(frozen=True)
class BestMember:
    """The fittest member seen so far (on its own generation's maps)."""

    generation: int
    member: int
    fitness: float
    genome: Genome


class GeneticAlgorithm:
    """Ask/tell genetic algorithm over genomes; see the module docstring."""

    def __init__(self, config: GeneticAlgorithmConfig, initial_genome: Genome) -> None:
        """Generation 0: ``population_size`` copies of ``initial_genome`` (the pre-trained
        generator), each mutated, except member 0 when ``config.keep_original``."""
        config.validate()
        self._config = config
        self._rng = np.random.default_rng(config.seed)
        population: list[Genome] = []
        origins: list[MemberOrigin] = []
        for member in range(config.population_size):
            if member == 0 and config.keep_original:
                population.append(initial_genome.clone())
                origins.append(MemberOrigin('original'))
            else:
                population.append(mutate(initial_genome, config.operators, self._rng))
                origins.append(MemberOrigin('initial'))
        self._generation = 0
        self._population = population
        self._origins = origins
        self._fitnesses: list[float | None] = [None] * config.population_size
        self._best: BestMember | None = None
        self._history: list[dict[str, float | int]] = []

    # -- read access ----------------------------------------------------------------------

    @property
    def config(self) -> GeneticAlgorithmConfig:
        return self._config

    @property
    def generation(self) -> int:
        """Index of the generation ``ask()`` returns (0-based)."""
        return self._generation

    @property
    def population_size(self) -> int:
        return self._config.population_size

    @property
    def origins(self) -> list[MemberOrigin]:
        return list(self._origins)

    @property
    def fitnesses(self) -> list[float | None]:
        """Fitnesses told so far for the current generation (None: not yet told)."""
        return list(self._fitnesses)

    @property
    def best(self) -> BestMember | None:
        """The fittest member told so far over all generations (None before the first)."""
        return self._best

    @property
    def history(self) -> list[dict[str, float | int]]:
        """One entry per completed generation: generation, best_member, best_fitness,
        mean_fitness."""
        return [dict(entry) for entry in self._history]

    def pending_members(self) -> list[int]:
        """Members of the current generation whose fitness has not been told yet."""
        return [i for i, f in enumerate(self._fitnesses) if f is None]

    # -- ask / tell -----------------------------------------------------------------------

    def ask(self) -> list[Genome]:
        """The genomes of the current generation, member order. Calling it again before
        the generation is complete returns the same genomes. Treat them as read-only."""
        return list(self._population)

    def tell(self, fitnesses: Sequence[float]) -> GenerationResult:
        """Report the fitness of every member (member order) and breed the next generation.

        Values must not be NaN or +inf; -inf marks a member that could not be evaluated
        (it ranks last). Raises AlgorithmStateError if some members were already told
        with ``tell_one`` (mixing the two within one generation is ambiguous).
        """
        if len(fitnesses) != self.population_size:
            raise AlgorithmStateError(f'tell expects {self.population_size} fitnesses, '
                                      f'got {len(fitnesses)}')
        if any(f is not None for f in self._fitnesses):
            raise AlgorithmStateError(
                f'generation {self._generation} already has fitnesses told with tell_one; '
                'finish it with tell_one')
        values = [_checked_fitness(i, f) for i, f in enumerate(fitnesses)]
        self._fitnesses = list(values)
        return self._advance(values)

    def tell_one(self, member: int, fitness: float) -> GenerationResult | None:
        """Report one member's fitness, in any order. Returns the GenerationResult when
        this completes the generation (which then advances), else None."""
        if not 0 <= member < self.population_size:
            raise AlgorithmStateError(f'member {member} is outside 0..'
                                      f'{self.population_size - 1}')
        if self._fitnesses[member] is not None:
            raise AlgorithmStateError(f'member {member} of generation {self._generation} '
                                      'was already told')
        self._fitnesses[member] = _checked_fitness(member, fitness)
        if self.pending_members():
            return None
        return self._advance([float(f) for f in self._fitnesses if f is not None])

    # -- the generation step --------------------------------------------------------------

    def _advance(self, fitnesses: list[float]) -> GenerationResult:
        config = self._config
        ranking = sorted(range(self.population_size), key=lambda i: (-fitnesses[i], i))
        elites = tuple(ranking[:config.elite_count])
        result = GenerationResult(self._generation, tuple(fitnesses), tuple(ranking), elites)
        if self._best is None or result.best_fitness > self._best.fitness:
            self._best = BestMember(self._generation, result.best_member,
                                    result.best_fitness,
                                    self._population[result.best_member].clone())
        self._history.append({'generation': self._generation,
                              'best_member': result.best_member,
                              'best_fitness': result.best_fitness,
                              'mean_fitness': result.mean_fitness})

        population = [self._population[i].clone() for i in elites]
        origins = [MemberOrigin('elite', (i,)) for i in elites]
        while len(population) < self.population_size:
            first = self._tournament(fitnesses)
            if self._rng.random() < config.crossover_probability:
                second = self._tournament(fitnesses)
                child = crossover(self._population[first], self._population[second],
                                  config.operators, self._rng)
                parents: tuple[int, ...] = (first, second)
            else:
                child = self._population[first]
                parents = (first,)
            population.append(mutate(child, config.operators, self._rng))
            origins.append(MemberOrigin('offspring', parents))

        self._generation += 1
        self._population = population
        self._origins = origins
        self._fitnesses = [None] * self.population_size
        return result

    def _tournament(self, fitnesses: list[float]) -> int:
        size = min(self._config.tournament_size, self.population_size)
        contestants = self._rng.choice(self.population_size, size=size, replace=False)
        return min((int(i) for i in contestants), key=lambda i: (-fitnesses[i], i))

    # -- state ----------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """The complete state as plain data (dicts, lists, numbers, strings, tensors), so
        ``torch.load(..., weights_only=True)`` can read a checkpoint of it."""
        best = None
        if self._best is not None:
            best = {'generation': self._best.generation, 'member': self._best.member,
                    'fitness': self._best.fitness, 'genome': self._best.genome.to_plain()}
        return {
            'format': STATE_FORMAT,
            'config': self._config.to_dict(),
            'generation': self._generation,
            'population': [genome.to_plain() for genome in self._population],
            'origins': [origin.to_dict() for origin in self._origins],
            'fitnesses': list(self._fitnesses),
            'rng_state': _plain_rng_state(self._rng),
            'best': best,
            'history': self.history,
        }

    @classmethod
    def from_state_dict(cls, state: dict[str, Any]) -> GeneticAlgorithm:
        """Restore an algorithm from ``state_dict()`` output; it continues identically."""
        if not isinstance(state, dict) or state.get('format') != STATE_FORMAT:
            raise AlgorithmStateError(f'not a genetic algorithm state (expected format '
                                      f'{STATE_FORMAT!r})')
        try:
            config = GeneticAlgorithmConfig.from_dict(state['config'])
            config.validate()
            population = [Genome.from_plain(g) for g in state['population']]
            origins = [MemberOrigin.from_dict(o) for o in state['origins']]
            fitnesses = [None if f is None else float(f) for f in state['fitnesses']]
            rng = _rng_from_plain(state['rng_state'])
            best_state = state['best']
            best = None if best_state is None else BestMember(
                int(best_state['generation']), int(best_state['member']),
                float(best_state['fitness']), Genome.from_plain(best_state['genome']))
            generation = int(state['generation'])
            history = [dict(entry) for entry in state['history']]
        except (KeyError, TypeError, ValueError) as err:
            raise AlgorithmStateError(f'incomplete or invalid algorithm state: {err!r}') from err
        sizes = {len(population), len(origins), len(fitnesses)}
        if sizes != {config.population_size}:
            raise AlgorithmStateError(f'state holds {sorted(sizes)} members; the config '
                                      f'says {config.population_size}')
        for genome in population[1:]:
            population[0].check_compatible(genome)
        algorithm = cls.__new__(cls)
        algorithm._config = config
        algorithm._rng = rng
        algorithm._generation = generation
        algorithm._population = population
        algorithm._origins = origins
        algorithm._fitnesses = fitnesses
        algorithm._best = best
        algorithm._history = history
        return algorithm


def _checked_fitness(member: int, fitness: float) -> float:
    value = float(fitness)
    if math.isnan(value) or value == math.inf:
        raise AlgorithmStateError(f'member {member}: fitness {fitness} is not allowed '
                                  '(use -inf for a member that could not be evaluated)')
    return value


def _plain_rng_state(rng: np.random.Generator) -> dict[str, Any]:
    """The bit generator's state as nested dicts of ints and strings."""
    return _to_plain(rng.bit_generator.state)


def _to_plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _to_plain(v) for k, v in value.items()}
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, np.ndarray):
        return [int(v) for v in value.tolist()]
    return value


def _rng_from_plain(state: dict[str, Any]) -> np.random.Generator:
    name = state.get('bit_generator')
    bit_generator_class = getattr(np.random, str(name), None)
    if bit_generator_class is None or not isinstance(bit_generator_class, type):
        raise AlgorithmStateError(f'unknown numpy bit generator {name!r} in the state')
    bit_generator = bit_generator_class()
    bit_generator.state = state
    return np.random.Generator(bit_generator)
