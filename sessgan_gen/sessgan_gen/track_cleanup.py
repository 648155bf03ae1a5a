"""A structural post-process of generated race tracks that keeps the learned geometry.

The racetrack generator draws road of the example's width and bends, but as a maze: many
detached pieces, specks of road and of barrier, and dead-end spurs. A car test needs one
continuous road. :func:`clean_track` turns a generated map into one by deleting and filling
only (it draws no new road beyond one-cell gaps between pieces, so widths and bends stay
the generator's), in this order:

1. fill holes of off-track cells up to ``max_island_cells`` (specks of barrier in the road);
2. fill one-cell gaps between two different track pieces (``bridge_gaps``), then keep the
   largest track piece (4-connected) and remove the rest;
3. remove dead-end spurs: the track's skeleton loses every branch that ends within
   ``max_spur_cells`` skeleton steps (:func:`sessgan_gen.track_realism.prune_spurs`), the
   branches that stay regrow their tips through the pruned pixels, and track cells covered
   only by the inscribed discs of removed skeleton cells (radius + 1 cell) are removed;
4. steps 1 and 2 again (a spur's removal may leave a speck or a hole);
5. keep the largest circuit (``keep_circuit``, :func:`keep_circuit`): the largest
   biconnected block of the skeleton's 8-neighbour graph, when its centre line is at least
   ``min_circuit_sides`` times the map's shorter side long. A block is a network of loops
   in which every two points lie on a common loop, so a car can drive from any point to
   any other and back another way; the road of the rest (dead ends of any length, roads
   that join two circuits) is removed as in step 3, and where the circuit's road is
   narrower than ``min_circuit_width`` (a pinch the car's certified lane cannot pass) it is
   widened to that width around the centre line: the only road this step draws. Then
   fill specks and keep the largest piece again (no bridging: a removed road must not be
   joined back). A track without such a circuit keeps the result of step 4.

Deterministic: a pure function of the map, so maps stay deterministic per seed.
"""

from __future__ import annotations

import numpy as np

from sessgan_core.scenarios import Scenario, TrackCleanup, get_scenario
from sessgan_core.valid_tests import reachable_regions
from sessgan_gen.track_realism import (
    paint_discs,
    prune_spurs,
    skeleton,
    skeleton_end_points,
    track_clearance,
)


def fill_islands(track: np.ndarray, max_cells: int) -> np.ndarray:
    """The track with every off-track hole (4-connected, not touching the map's edge) of at
    most ``max_cells`` cells filled."""
    mask = np.asarray(track, dtype=bool).copy()
    if max_cells <= 0 or mask.all():
        return mask
    labels, sizes = reachable_regions(~mask)
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    small = np.array([size <= max_cells for size in sizes], dtype=bool)
    small[edge[edge >= 0]] = False
    inside = labels >= 0
    fill = np.zeros_like(mask)
    fill[inside] = small[labels[inside]]
    return mask | fill


_OPPOSITE_PAIRS = (((1, 0), (-1, 0)), ((0, 1), (0, -1)), ((1, 1), (-1, -1)), ((1, -1), (-1, 1)))


def bridge_gaps(track: np.ndarray) -> np.ndarray:
    """The track with every off-track cell filled whose opposite neighbours (across or
    diagonally) are track cells of two different 4-connected pieces."""
    mask = np.asarray(track, dtype=bool)
    labels, sizes = reachable_regions(mask)
    if len(sizes) < 2:
        return mask.copy()
    padded = np.pad(labels, 1, constant_values=-1)
    height, width = mask.shape
    fill = np.zeros_like(mask)
    for (row_a, col_a), (row_b, col_b) in _OPPOSITE_PAIRS:
        first = padded[1 + row_a:1 + row_a + height, 1 + col_a:1 + col_a + width]
        second = padded[1 + row_b:1 + row_b + height, 1 + col_b:1 + col_b + width]
        fill |= (first >= 0) & (second >= 0) & (first != second)
    return mask | (fill & ~mask)


def largest_piece(track: np.ndarray) -> np.ndarray:
    """The largest 4-connected piece of track (ties: the first in row-major order)."""
    mask = np.asarray(track, dtype=bool)
    labels, sizes = reachable_regions(mask)
    if not sizes:
        return mask.copy()
    return labels == int(np.argmax(sizes))


def _dilate8(mask: np.ndarray) -> np.ndarray:
    padded = np.pad(mask, 1)
    height, width = mask.shape
    out = mask.copy()
    for d_row in (-1, 0, 1):
        for d_col in (-1, 0, 1):
            out |= padded[1 + d_row:1 + d_row + height, 1 + d_col:1 + d_col + width]
    return out


def remove_spurs(track: np.ndarray, max_spur_cells: int) -> np.ndarray:
    """The track without the dead-end spurs whose skeleton ends within ``max_spur_cells``
    steps of the rest (see the module docstring)."""
    mask = np.asarray(track, dtype=bool)
    if max_spur_cells <= 0 or not mask.any():
        return mask.copy()
    thin = skeleton(mask)
    kept = prune_spurs(thin, max_spur_cells)
    # Long dead ends were shortened by max_spur_cells: grow their tips back through the
    # pixels the pruning took (never back along what it kept, into a pruned side spur).
    pruned = thin & ~kept
    grown = skeleton_end_points(kept)
    for _ in range(max_spur_cells):
        grown = (_dilate8(grown) & pruned) | grown
    kept |= grown
    removed = thin & ~kept
    if not removed.any():
        return mask.copy()
    clearance = track_clearance(mask)
    rows, cols = np.nonzero(removed)
    cut = paint_discs(mask.shape, rows, cols, clearance[rows, cols] + 1.0)
    rows, cols = np.nonzero(kept)
    keep = paint_discs(mask.shape, rows, cols, clearance[rows, cols] + 1.0)
    return mask & ~(cut & ~keep)


MIN_LOOP_PIXELS = 8
"""Pixels of the shortest skeleton loop that encloses a cell (the ring around one cell)."""


def largest_loop_block(skeleton_mask: np.ndarray) -> np.ndarray:
    """Bool mask of the pixels of the largest biconnected block (most pixels; ties: the first
    found) of a skeleton's 8-neighbour graph that holds a loop around at least one cell
    (``MIN_LOOP_PIXELS`` or more: smaller blocks are the triangles and diamonds of 8-adjacent
    pixels at junctions); all False when there is none. Tarjan's algorithm, iterative."""
    thin = np.asarray(skeleton_mask, dtype=bool)
    rows, cols = np.nonzero(thin)
    height, width = thin.shape
    index = np.full((height + 2, width + 2), -1, dtype=np.int64)
    index[rows + 1, cols + 1] = np.arange(len(rows))
    # Each pixel's skeleton neighbours, row-major around it, gathered for all pixels at once.
    around = np.stack([index[rows + 1 + d_row, cols + 1 + d_col]
                       for d_row in (-1, 0, 1) for d_col in (-1, 0, 1) if d_row or d_col], axis=1)
    neighbours = [[other for other in row if other >= 0] for row in around.tolist()]
    order = [-1] * len(rows)
    low = [0] * len(rows)
    counter = 0
    best: set[int] = set()
    for root in range(len(rows)):
        if order[root] >= 0:
            continue
        order[root] = low[root] = counter
        counter += 1
        stack = [(root, -1, iter(neighbours[root]))]
        edges: list[tuple[int, int]] = []
        while stack:
            node, parent, pending = stack[-1]
            descended = False
            for other in pending:
                if order[other] < 0:
                    edges.append((node, other))
                    order[other] = low[other] = counter
                    counter += 1
                    stack.append((other, node, iter(neighbours[other])))
                    descended = True
                    break
                if other != parent and order[other] < order[node]:
                    edges.append((node, other))
                    low[node] = min(low[node], order[other])
            if descended:
                continue
            stack.pop()
            if not stack:
                continue
            above = stack[-1][0]
            low[above] = min(low[above], low[node])
            if low[node] >= order[above]:
                block: set[int] = set()
                while True:
                    edge = edges.pop()
                    block.update(edge)
                    if edge == (above, node):
                        break
                if len(block) >= MIN_LOOP_PIXELS and len(block) > len(best):
                    best = block
    out = np.zeros_like(thin)
    chosen = np.array(sorted(best), dtype=np.int64)
    out[rows[chosen], cols[chosen]] = True
    return out


def keep_circuit(track: np.ndarray, min_circuit_cells: float, min_width: float = 0.0
                 ) -> np.ndarray:
    """The track reduced to its largest circuit (step 5 of the module docstring); the track
    unchanged when its skeleton has no biconnected block of at least ``min_circuit_cells``
    pixels."""
    mask = np.asarray(track, dtype=bool)
    thin = skeleton(mask)
    circuit = largest_loop_block(thin)
    if circuit.sum() < max(MIN_LOOP_PIXELS, min_circuit_cells):
        return mask.copy()
    clearance = track_clearance(mask)
    radius = 0.5 * min_width
    rows, cols = np.nonzero(circuit)
    narrow = clearance[rows, cols] < radius
    widened = mask | paint_discs(mask.shape, rows[narrow], cols[narrow],
                                 np.full(int(narrow.sum()), radius))
    keep = paint_discs(mask.shape, rows, cols, np.maximum(clearance[rows, cols], radius) + 1.0)
    rows, cols = np.nonzero(thin & ~circuit)
    cut = paint_discs(mask.shape, rows, cols, clearance[rows, cols] + 1.0)
    return widened & ~(cut & ~keep)


def clean_track(track: np.ndarray, cleanup: TrackCleanup) -> np.ndarray:
    """The track mask after the post-process of the module docstring."""
    mask = fill_islands(track, cleanup.max_island_cells)
    if cleanup.bridge_gaps:
        mask = bridge_gaps(mask)
    if cleanup.keep_main_piece:
        mask = largest_piece(mask)
    if cleanup.max_spur_cells > 0:
        mask = fill_islands(remove_spurs(mask, cleanup.max_spur_cells),
                            cleanup.max_island_cells)
        if cleanup.keep_main_piece:
            mask = largest_piece(mask)
    if cleanup.keep_circuit:
        mask = keep_circuit(mask, cleanup.min_circuit_sides * min(mask.shape),
                            cleanup.min_circuit_width)
        mask = fill_islands(mask, cleanup.max_island_cells)
        if cleanup.keep_main_piece:
            mask = largest_piece(mask)
    return mask


def clean_token_map(cells: np.ndarray, spec: Scenario) -> np.ndarray:
    """A token map after the scenario's ``track_cleanup`` (a copy; unchanged when it has
    none): removed track becomes the off-track token, filled holes the track token."""
    array = np.asarray(cells)
    cleanup = spec.track_cleanup
    if cleanup is None:
        return array.copy()
    track_id = spec.token_id(cleanup.track_token)
    off_id = spec.token_id(cleanup.off_track_token)
    track = array == track_id
    cleaned = clean_track(track, cleanup)
    out = array.copy()
    out[track & ~cleaned] = off_id
    out[cleaned & ~track] = track_id
    return out


def clean_generated_maps(maps: np.ndarray, scenario: str) -> np.ndarray:
    """Generated token maps (n, height, width) after the scenario's ``track_cleanup``, as the
    sampler serves them (the same array when the scenario has none)."""
    spec = get_scenario(scenario)
    if spec.track_cleanup is None or not len(maps):
        return maps
    return np.stack([clean_token_map(cells, spec) for cells in maps])
