"""A non-learned map generator of a scenario's tokens: the BARN-style cellular automaton.

BARN (Perille et al., 2020) made its 300 navigation test maps with a cellular automaton: fill
the grid at random, then smooth it a few times with a birth/survival rule, with the fill and
the number of smoothing steps drawn per map. Here, per map (all draws from the map's seed):

1. every interior cell becomes an obstacle with probability ``fill`` ~ U(fill_range);
2. ``iterations`` ~ U{iteration_range} smoothing steps: a free cell becomes an obstacle when
   at least ``birth`` of its 8 neighbours are obstacles, an obstacle stays one when at least
   ``survival`` are (cells beyond the grid count as obstacles);
3. where the scenario has low obstacles (the drone area), steps 1-2 run again on the free
   cells with ``low_fill_range`` to place them;
4. if the scenario's example map has a solid border (its outer ring is one token), the border
   is restored.

Tokens come from the scenario: its first traversable free token (occupancy 0) is free space,
its first blocked token (occupancy 100) the obstacle, and its first low-obstacle token
(occupancy 50), if any, the low obstacle. Nothing is learned from the example map beyond the
border. Maps are checked by the same validity certificate as every other method's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sessgan_core.errors import SessganCoreError
from sessgan_core.scenarios import BLOCKED, FREE, LOW_OBSTACLE, Scenario, get_scenario
from sessgan_core.token_map import load_example_map
from sessgan_evolver.errors import CellularAutomatonError


@dataclass(frozen=True)
class CellularAutomatonConfig:
    """Parameters of the generator (module docstring); fractions in [0, 1]."""

    fill_range: tuple[float, float] = (0.30, 0.50)
    """The classic cave rule (B5/S4) needs about this much fill to leave structure: with
    BARN's lower fills it erases almost every obstacle of a 32x32 map."""
    iteration_range: tuple[int, int] = (1, 4)
    """Inclusive."""
    birth: int = 5
    survival: int = 4
    low_fill_range: tuple[float, float] = (0.25, 0.45)

    def validate(self) -> None:
        for name in ('fill_range', 'low_fill_range'):
            low, high = getattr(self, name)
            if not 0.0 <= low <= high <= 1.0:
                raise CellularAutomatonError(f'{name} must satisfy 0 <= low <= high <= 1, '
                                             f'got {(low, high)}')
        low, high = self.iteration_range
        if not 0 <= low <= high:
            raise CellularAutomatonError(f'iteration_range must satisfy 0 <= low <= high, '
                                         f'got {(low, high)}')
        for name in ('birth', 'survival'):
            if not 0 <= getattr(self, name) <= 8:
                raise CellularAutomatonError(f'{name} must lie in 0..8, got '
                                             f'{getattr(self, name)}')


def _token_with(spec: Scenario, occupancy: int, traversable: bool | None) -> int | None:
    for token, value in enumerate(spec.occupancy):
        if value != occupancy:
            continue
        if traversable is not None and (token in spec.traversable) != traversable:
            continue
        return token
    return None


def _obstacle_neighbours(obstacles: np.ndarray) -> np.ndarray:
    padded = np.pad(obstacles.astype(np.int8), 1, constant_values=1)
    height, width = obstacles.shape
    total = np.zeros(obstacles.shape, dtype=np.int8)
    for d_row in (-1, 0, 1):
        for d_col in (-1, 0, 1):
            if d_row or d_col:
                total += padded[1 + d_row:1 + d_row + height, 1 + d_col:1 + d_col + width]
    return total


def smooth(obstacles: np.ndarray, iterations: int, birth: int, survival: int) -> np.ndarray:
    """``iterations`` birth/survival steps on a bool obstacle grid (a new array)."""
    grid = np.asarray(obstacles, dtype=bool).copy()
    for _ in range(iterations):
        neighbours = _obstacle_neighbours(grid)
        grid = np.where(grid, neighbours >= survival, neighbours >= birth)
    return grid


class CellularAutomatonGenerator:
    """Token maps of a scenario from seeds (module docstring); map i depends only on
    seeds[i]."""

    def __init__(self, scenario: str, config: CellularAutomatonConfig | None = None,
                 size: tuple[int, int] | None = None) -> None:
        self.spec = get_scenario(scenario)
        self.config = config or CellularAutomatonConfig()
        self.config.validate()
        self.size = tuple(size) if size is not None else self.spec.default_size
        free = _token_with(self.spec, FREE, True)
        wall = _token_with(self.spec, BLOCKED, None)
        if free is None or wall is None:
            raise CellularAutomatonError(f'scenario {self.spec.name!r} has no free traversable '
                                         'token or no blocked token')
        self.free, self.wall = free, wall
        self.low = _token_with(self.spec, LOW_OBSTACLE, None)
        self.border = self._example_border()

    def _example_border(self) -> int | None:
        try:
            example = load_example_map(self.spec.name).cells
        except (OSError, SessganCoreError):  # a user scenario without an example: no border
            return None
        ring = np.concatenate([example[0], example[-1], example[:, 0], example[:, -1]])
        return int(ring[0]) if np.all(ring == ring[0]) else None

    def one(self, seed: int) -> np.ndarray:
        """The token map (height, width) of ``seed``."""
        config = self.config
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xCA]))
        height, width = self.size
        fill = rng.uniform(*config.fill_range)
        iterations = int(rng.integers(config.iteration_range[0], config.iteration_range[1] + 1))
        obstacles = smooth(rng.random((height, width)) < fill, iterations, config.birth,
                           config.survival)
        cells = np.where(obstacles, self.wall, self.free).astype(np.int64)
        if self.low is not None:
            low_fill = rng.uniform(*config.low_fill_range)
            low = smooth(rng.random((height, width)) < low_fill, iterations, config.birth,
                         config.survival)
            cells[low & ~obstacles] = self.low
        if self.border is not None:
            cells[0, :] = cells[-1, :] = self.border
            cells[:, 0] = cells[:, -1] = self.border
        return cells

    def maps(self, seeds: list[int]) -> np.ndarray:
        """Token maps (len(seeds), height, width), one per seed."""
        height, width = self.size
        if not seeds:
            return np.zeros((0, height, width), dtype=np.int64)
        return np.stack([self.one(seed) for seed in seeds])
