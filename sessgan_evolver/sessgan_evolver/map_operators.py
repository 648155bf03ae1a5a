"""Genetic operators on token maps (the grid GA baseline) and on generator noise (latent search).

Token maps (AmbieGen-style search in map space; every random choice from the ``rng`` given):

* ``mutate_token_map``: one edit, chosen uniformly among *paint* (a rectangle of 1-4 x 1-4
  cells set to one token), *scatter* (1-4 single cells set to other tokens) and *move* (a
  rectangle of 2-6 x 2-6 cells copied somewhere else);
* ``crossover_token_maps``: the first parent with a rectangle (each side a quarter to three
  quarters of the map's) taken from the second, the two-dimensional two-point crossover.

A fixed border (the example map's solid outer ring) is restored after either.

Noise maps (one float array per generator scale, standard normal):

* ``mutate_noise``: each scale, with probability ``scale_probability`` (at least one scale),
  becomes ``sqrt(1 - s^2) * z + s * e`` with fresh standard normal ``e``, so mutated noise is
  still standard normal (the generator sees inputs like those it was trained on) and keeps
  a correlation of ``sqrt(1 - s^2)`` with its parent;
* ``mutate_noise_region``: the same, only inside a rectangle given in fractions of the map
  (every chosen scale's noise covers the whole map at its own resolution), so the map
  changes around one place and stays the same away from it;
* ``crossover_noise``: each scale's noise taken whole from one parent or the other.
"""

from __future__ import annotations

import math

import numpy as np

from sessgan_evolver.errors import MapOperatorError

NoiseMaps = list[np.ndarray]


def _rectangle(rng: np.random.Generator, shape: tuple[int, int], low: int, high: int
               ) -> tuple[int, int, int, int]:
    """(row, col, height, width) of a random rectangle with sides in [low, high] cells that
    fits in ``shape``."""
    height = int(rng.integers(min(low, shape[0]), min(high, shape[0]) + 1))
    width = int(rng.integers(min(low, shape[1]), min(high, shape[1]) + 1))
    row = int(rng.integers(0, shape[0] - height + 1))
    col = int(rng.integers(0, shape[1] - width + 1))
    return row, col, height, width


def restore_border(cells: np.ndarray, border: int | None) -> np.ndarray:
    """``cells`` with its outer ring set to ``border`` (unchanged when None), in place."""
    if border is not None:
        cells[0, :] = cells[-1, :] = border
        cells[:, 0] = cells[:, -1] = border
    return cells


def mutate_token_map(cells: np.ndarray, num_tokens: int, rng: np.random.Generator,
                     border: int | None = None) -> tuple[np.ndarray, str]:
    """A mutated copy of ``cells`` and the name of the edit (module docstring)."""
    if num_tokens < 2:
        raise MapOperatorError(f'a token map needs at least 2 tokens, got {num_tokens}')
    child = np.array(cells, dtype=np.int64, copy=True)
    shape = (int(child.shape[0]), int(child.shape[1]))
    operation = ('paint', 'scatter', 'move')[int(rng.integers(0, 3))]
    if operation == 'paint':
        row, col, height, width = _rectangle(rng, shape, 1, 4)
        child[row:row + height, col:col + width] = int(rng.integers(0, num_tokens))
    elif operation == 'scatter':
        for _ in range(int(rng.integers(1, 5))):
            row, col = int(rng.integers(0, shape[0])), int(rng.integers(0, shape[1]))
            # Another token than the cell's: add 1..n-1 modulo n.
            child[row, col] = (child[row, col] + int(rng.integers(1, num_tokens))) % num_tokens
    else:
        row, col, height, width = _rectangle(rng, shape, 2, 6)
        block = child[row:row + height, col:col + width].copy()
        to_row = int(rng.integers(0, shape[0] - height + 1))
        to_col = int(rng.integers(0, shape[1] - width + 1))
        child[to_row:to_row + height, to_col:to_col + width] = block
    return restore_border(child, border), operation


def crossover_token_maps(first: np.ndarray, second: np.ndarray, rng: np.random.Generator,
                         border: int | None = None) -> np.ndarray:
    """``first`` with a random rectangle of ``second`` (module docstring)."""
    if np.shape(first) != np.shape(second):
        raise MapOperatorError(f'parents differ in shape: {np.shape(first)} vs '
                               f'{np.shape(second)}')
    child = np.array(first, dtype=np.int64, copy=True)
    shape = (int(child.shape[0]), int(child.shape[1]))
    low = max(1, min(shape) // 4)
    high = max(low, (3 * min(shape)) // 4)
    row, col, height, width = _rectangle(rng, shape, low, high)
    child[row:row + height, col:col + width] = np.asarray(second)[row:row + height,
                                                                 col:col + width]
    return restore_border(child, border)


def mutate_noise(noise: NoiseMaps, rng: np.random.Generator, strength: float,
                 scale_probability: float = 0.5,
                 scales: tuple[int, ...] | None = None) -> NoiseMaps:
    """A mutated copy of per-scale noise (module docstring); ``strength`` s in [0, 1].
    ``scales``: mutate exactly these scales (0 the coarsest) instead of drawing them."""
    if not 0.0 <= strength <= 1.0:
        raise MapOperatorError(f'noise mutation strength must lie in [0, 1], got {strength}')
    if not 0.0 <= scale_probability <= 1.0:
        raise MapOperatorError(f'scale probability must lie in [0, 1], got '
                               f'{scale_probability}')
    if not noise:
        raise MapOperatorError('no noise maps to mutate')
    if scales is not None:
        if not scales or any(not 0 <= scale < len(noise) for scale in scales):
            raise MapOperatorError(f'scales must name some of the {len(noise)} noise maps, '
                                   f'got {scales}')
        chosen = np.isin(np.arange(len(noise)), scales)
    else:
        chosen = rng.random(len(noise)) < scale_probability
        if not chosen.any():
            chosen[int(rng.integers(0, len(noise)))] = True
    keep = math.sqrt(1.0 - strength * strength)
    mutated = []
    for is_chosen, scale in zip(chosen, noise):
        values = np.asarray(scale, dtype=np.float32)
        if is_chosen:
            fresh = rng.standard_normal(values.shape).astype(np.float32)
            values = (keep * values + strength * fresh).astype(np.float32)
        else:
            values = values.copy()
        mutated.append(values)
    return mutated


def mutate_noise_region(noise: NoiseMaps, rng: np.random.Generator, strength: float,
                        region: tuple[float, float, float, float],
                        scales: tuple[int, ...]) -> NoiseMaps:
    """A copy of per-scale noise mutated like ``mutate_noise`` only inside ``region`` =
    (top, left, bottom, right) as fractions of the map's height and width, on ``scales``
    (each at least one noise cell)."""
    if not 0.0 <= strength <= 1.0:
        raise MapOperatorError(f'noise mutation strength must lie in [0, 1], got {strength}')
    top, left, bottom, right = region
    if not 0.0 <= top < bottom <= 1.0 or not 0.0 <= left < right <= 1.0:
        raise MapOperatorError(f'region must be (top, left, bottom, right) within [0, 1] with '
                               f'top < bottom and left < right, got {region}')
    if not scales or any(not 0 <= scale < len(noise) for scale in scales):
        raise MapOperatorError(f'scales must name some of the {len(noise)} noise maps, got '
                               f'{scales}')
    keep = math.sqrt(1.0 - strength * strength)
    mutated = [np.array(scale, dtype=np.float32, copy=True) for scale in noise]
    for scale in scales:
        values = mutated[scale]
        height, width = values.shape[-2:]
        rows = slice(min(int(top * height), height - 1), max(math.ceil(bottom * height),
                                                            int(top * height) + 1))
        cols = slice(min(int(left * width), width - 1), max(math.ceil(right * width),
                                                           int(left * width) + 1))
        window = values[..., rows, cols]
        fresh = rng.standard_normal(window.shape).astype(np.float32)
        values[..., rows, cols] = keep * window + strength * fresh
    return mutated


def crossover_noise(first: NoiseMaps, second: NoiseMaps, rng: np.random.Generator
                    ) -> NoiseMaps:
    """Each scale's noise taken whole from ``first`` or ``second`` with equal chance."""
    if [np.shape(a) for a in first] != [np.shape(b) for b in second]:
        raise MapOperatorError('parents have noise maps of different shapes')
    draws = rng.random(len(first))
    return [np.array(b if draw < 0.5 else a, dtype=np.float32, copy=True)
            for draw, a, b in zip(draws, first, second)]
