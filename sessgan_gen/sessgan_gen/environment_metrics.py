"""Environment metrics of ARCHITECTURE.md: tile-pattern KL divergence and uniqueness.

Both work on integer grids of any small alphabet (token ids, or the common
free/low/blocked encoding of :func:`sessgan_core.token_map.to_common_encoding`
to compare scenarios). Every k x k window (stride 1) gets an exact integer
code: a positional number in base ``alphabet size`` while it fits 62 bits,
otherwise dense ranks built from the four corner windows of half the side,
relabelled at each step (lookup table or sort), so codes never collide. No
hashing: the counts are exact.

* **TPKL**: for k in ks, count every k x k window of the original and of the
  pooled generated maps; p = (count + eps) / ((N + eps) * (1 + eps)) with
  eps = 1e-7 and N the total number of windows on that side; the divergence
  KL(original || generated) sums p_o * ln(p_o / p_g) over the original's
  patterns (a pattern the generated maps lack has count 0). Report the mean
  over k.
* **Uniqueness**: for s in sizes, the percentage of distinct s x s patches
  (stride 1) among all s x s patches of the pooled generated maps
  (:func:`uniqueness_report`: NaN, not applicable, when no map holds an s x s patch).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import NamedTuple

import numpy as np

TPKL_EPSILON = 1e-7
DEFAULT_TPKL_SIZES = (2, 3, 4)
DEFAULT_UNIQUENESS_SIZES = (8, 16)
_CODE_LIMIT = 2 ** 62
_TABLE_LIMIT = 1 << 22
"""Codes below this are ranked with a lookup table instead of a sort."""


class UniquenessReport(NamedTuple):
    """Uniqueness per patch side (percent) and their mean (percent). A side larger than every
    map (no such patch) is NaN, not applicable, and so is the mean then: a mean over the
    sides that fit would not compare with the mean of maps that hold every side."""

    per_size: dict[int, float]
    mean: float


def _as_grid(grid: np.ndarray, what: str) -> np.ndarray:
    array = np.asarray(grid)
    if array.ndim != 2 or array.size == 0:
        raise ValueError(f'{what} must be a non-empty 2-D array, got shape {array.shape}')
    if not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f'{what} must hold integers (token ids), got dtype {array.dtype}')
    if array.min() < 0:
        raise ValueError(f'{what} holds negative values; token ids start at 0')
    return array.astype(np.int64, copy=False)


def _group_by_shape(grids: Iterable[np.ndarray]) -> list[np.ndarray]:
    """Stack grids of equal shape into (count, height, width) arrays, in first-seen order."""
    groups: dict[tuple[int, int], list[np.ndarray]] = {}
    for grid in grids:
        groups.setdefault(grid.shape, []).append(grid)
    return [np.stack(items) for items in groups.values()]


def _square_positional(stack: np.ndarray, side: int, base: int) -> np.ndarray:
    """Base-``base`` positional code of every side x side window of a (count, h, w) stack.

    The result is empty when the maps are smaller than the window.
    """
    count, height, width = stack.shape
    out_h, out_w = max(height - side + 1, 0), max(width - side + 1, 0)
    codes = np.zeros((count, out_h, out_w), dtype=np.int64)
    if codes.size == 0:
        return codes
    for row in range(side):
        for col in range(side):
            codes *= base
            codes += stack[:, row:row + out_h, col:col + out_w]
    return codes


def _dense_ranks(groups: list[np.ndarray]) -> tuple[list[np.ndarray], int]:
    """Replace values (>= 0) by their rank among all distinct values of all groups."""
    flat = np.concatenate([group.ravel() for group in groups])
    if flat.size == 0:
        inverse = flat.astype(np.int64)
        distinct = 1
    elif int(flat.max()) < _TABLE_LIMIT:
        # Small code space: a lookup table ranks in linear time, no sort.
        present = np.zeros(int(flat.max()) + 1, dtype=bool)
        present[flat] = True
        rank_of = np.cumsum(present, dtype=np.int64) - 1
        inverse = rank_of[flat]
        distinct = int(rank_of[-1]) + 1
    else:
        order = np.argsort(flat, kind='quicksort')
        ordered = flat[order]
        steps = np.empty(flat.size, dtype=np.int64)
        steps[0] = 0
        np.not_equal(ordered[1:], ordered[:-1], out=steps[1:])
        inverse = np.empty(flat.size, dtype=np.int64)
        inverse[order] = np.cumsum(steps)
        distinct = int(inverse[order[-1]]) + 1
    ranks = []
    start = 0
    for group in groups:
        ranks.append(inverse[start:start + group.size].reshape(group.shape))
        start += group.size
    return ranks, distinct


def _count_distinct(values: np.ndarray) -> int:
    """Number of distinct values (sorting; numpy 2's hash-based np.unique is slower here)."""
    if values.size == 0:
        return 0
    ordered = np.sort(values, kind='quicksort')
    return int(np.count_nonzero(ordered[1:] != ordered[:-1])) + 1


class _WindowCoder:
    """Exact codes of all s x s windows of groups of stacked maps, comparable across groups."""

    def __init__(self, groups: list[np.ndarray]) -> None:
        self.groups = groups
        self.base = max(2, max(int(group.max()) for group in groups) + 1)
        direct = 1
        while self.base ** ((direct + 1) ** 2) <= _CODE_LIMIT:
            direct += 1
        self.direct_side = direct
        """Largest side whose positional code fits in 62 bits."""
        self._ranked: dict[int, tuple[list[np.ndarray], int]] = {}
        self._horizontal: dict[int, tuple[list[np.ndarray], int]] = {}

    def codes(self, side: int) -> list[np.ndarray]:
        """Return per group an int64 array (count, h - side + 1, w - side + 1) of codes.

        Equal windows get equal codes; the array is empty for maps smaller than the window.
        """
        if side <= self.direct_side:
            return [_square_positional(group, side, self.base) for group in self.groups]
        if side in self._ranked:
            return self._ranked[side][0]
        # The final level needs no relabelling: pair codes are exact and comparable.
        return self._combine(side, relabel=False)[0]

    def sub_sizes(self, side: int) -> list[int]:
        """Window sides whose ranks :meth:`codes` computes to build ``side`` windows."""
        chain = []
        while side > self.direct_side:
            side = (side + 1) // 2
            chain.append(side)
        return chain

    def ranks(self, side: int) -> tuple[list[np.ndarray], int]:
        """Dense ranks of the side x side windows of every group, and how many ranks."""
        return self._ranks(side)

    def _ranks(self, side: int) -> tuple[list[np.ndarray], int]:
        """Dense ranks of the side x side windows of every group, and the number of ranks."""
        if side not in self._ranked:
            if side <= self.direct_side:
                self._ranked[side] = _dense_ranks(
                    [_square_positional(group, side, self.base) for group in self.groups])
            else:
                self._ranked[side] = self._combine(side, relabel=True)
        return self._ranked[side]

    def _combine(self, side: int, relabel: bool) -> tuple[list[np.ndarray], int]:
        """Codes of side x side windows from the ranks of their four corner sub-windows.

        The corner windows of side ceil(side / 2) cover the window exactly; they are
        paired horizontally, relabelled, then paired vertically (and relabelled again
        when ``relabel``).
        """
        half = (side + 1) // 2
        shift = side - half
        if side not in self._horizontal:
            sub, distinct = self._ranks(half)
            horizontal = []
            for group, codes in zip(self.groups, sub, strict=True):
                width = max(group.shape[2] - side + 1, 0)
                horizontal.append(codes[:, :, :width] * distinct
                                  + codes[:, :, shift:shift + width])
            self._horizontal[side] = _dense_ranks(horizontal)
        pairs, distinct_pairs = self._horizontal[side]
        vertical = []
        for group, codes in zip(self.groups, pairs, strict=True):
            height = max(group.shape[1] - side + 1, 0)
            vertical.append(codes[:, :height] * distinct_pairs + codes[:, shift:shift + height])
        if relabel:
            return _dense_ranks(vertical)
        return vertical, distinct_pairs * distinct_pairs


def _prepare(original: np.ndarray | None, generated: Sequence[np.ndarray]
             ) -> tuple[list[np.ndarray], int]:
    grids = [] if original is None else [_as_grid(original, 'original map')]
    for index, grid in enumerate(generated):
        grids.append(_as_grid(grid, f'generated map {index}'))
    if len(grids) == (0 if original is None else 1):
        raise ValueError('no generated maps given')
    return grids, (0 if original is None else 1)


def tile_pattern_kl_per_k(original_cells: np.ndarray, generated: Sequence[np.ndarray],
                          ks: Sequence[int] = DEFAULT_TPKL_SIZES) -> dict[int, float]:
    """KL(original || pooled generated) of k x k tile patterns for each k (nats)."""
    grids, _ = _prepare(original_cells, generated)
    original = grids[0]
    generated_groups = _group_by_shape(grids[1:])
    coder = _WindowCoder([original[None]] + generated_groups)
    result: dict[int, float] = {}
    for k in ks:
        if k < 1:
            raise ValueError(f'tile size must be >= 1, got {k}')
        if min(original.shape) < k:
            raise ValueError(f'original map {original.shape} is smaller than the {k}x{k} tile')
        codes = coder.codes(k)
        original_patterns, original_counts = np.unique(codes[0], return_counts=True)
        generated_codes = np.concatenate([item.ravel() for item in codes[1:]])
        if generated_codes.size == 0:
            raise ValueError(f'every generated map is smaller than the {k}x{k} tile')
        generated_codes.sort()
        # Count, for each pattern of the original, its occurrences among generated windows.
        left = np.searchsorted(generated_codes, original_patterns, side='left')
        right = np.searchsorted(generated_codes, original_patterns, side='right')
        generated_counts = right - left
        p_original = _probability(original_counts, int(codes[0].size))
        p_generated = _probability(generated_counts, int(generated_codes.size))
        result[int(k)] = float(np.sum(p_original * np.log(p_original / p_generated)))
    return result


def _probability(counts: np.ndarray, total: int) -> np.ndarray:
    return (counts.astype(np.float64) + TPKL_EPSILON) / (
        (total + TPKL_EPSILON) * (1.0 + TPKL_EPSILON))


def tile_pattern_kl(original_cells: np.ndarray, generated: Sequence[np.ndarray],
                    ks: Sequence[int] = DEFAULT_TPKL_SIZES) -> float:
    """TPKL: the mean over ``ks`` of :func:`tile_pattern_kl_per_k` (nats; 0 = same statistics)."""
    per_k = tile_pattern_kl_per_k(original_cells, generated, ks)
    return float(np.mean(list(per_k.values())))


def uniqueness(generated: Sequence[np.ndarray],
               sizes: Sequence[int] = DEFAULT_UNIQUENESS_SIZES) -> dict[int, float]:
    """Percentage (0..100) of distinct s x s patches among all s x s patches, per s."""
    grids, _ = _prepare(None, generated)
    coder = _WindowCoder(_group_by_shape(grids))
    for side in sizes:
        if side < 1:
            raise ValueError(f'patch size must be >= 1, got {side}')
    # Sizes that a larger requested size is built from get ranked anyway: their distinct
    # count comes with the ranks, no extra sort.
    ranked_sizes = {half for side in sizes for half in coder.sub_sizes(side)}
    result: dict[int, float] = {}
    for side in sorted(set(sizes)):
        if side in ranked_sizes:
            ranks, distinct = coder.ranks(side)
            total = sum(item.size for item in ranks)
        else:
            codes = np.concatenate([item.ravel() for item in coder.codes(side)])
            total = codes.size
            distinct = _count_distinct(codes)
        if total == 0:
            raise ValueError(f'every generated map is smaller than the {side}x{side} patch')
        result[int(side)] = 100.0 * distinct / total
    return {int(side): result[int(side)] for side in sizes}


def uniqueness_of_fitting_sizes(generated: Sequence[np.ndarray],
                                sizes: Sequence[int] = DEFAULT_UNIQUENESS_SIZES
                                ) -> dict[int, float]:
    """:func:`uniqueness` for the ``sizes`` that fit in at least one generated map: a small
    facility's maps (8 cells a side may be learned) hold no 16 x 16 patch, and a campaign's
    report must not fail on them. Empty when none fits."""
    largest = max((min(np.shape(cells)) for cells in generated), default=0)
    fitting = [side for side in sizes if side <= largest]
    return uniqueness(generated, fitting) if fitting else {}


def uniqueness_report(generated: Sequence[np.ndarray],
                      sizes: Sequence[int] = DEFAULT_UNIQUENESS_SIZES) -> UniquenessReport:
    """:func:`uniqueness` per size plus the mean over sizes (the paper's Table 1). A size
    larger than every generated map (12 x 12 maps hold no 16 x 16 patch) is NaN, and so is
    the mean then (:class:`UniquenessReport`), instead of a ValueError."""
    _prepare(None, generated)  # the maps are checked even when no size fits
    fitting = uniqueness_of_fitting_sizes(generated, sizes)
    per_size = {int(side): fitting.get(int(side), math.nan) for side in sizes}
    if not per_size:
        raise ValueError('no uniqueness patch size given')
    return UniquenessReport(per_size, float(math.fsum(per_size.values()) / len(per_size)))
