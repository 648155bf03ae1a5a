"""Track realism: how much a race-track map looks like a track a driver could race on.

A car test needs a continuous road of the example's width with turns, not a maze of
fragments. These measures compare generated race tracks with the example map; they read
only a bool mask of track cells and the certified start-to-goal route, so they hold for any
scenario's map (the racetrack is the one they are made for).

Definitions (lengths in cells inside, metres in the results):

* **Clearance** of a track cell: distance from its centre to the nearest point of a
  non-track cell square; the outside of the grid is non-track (as in
  :mod:`sessgan_core.route_certificate`). A straight of width w has clearance w / 2 on its
  centre line.
* **Inscribed discs**: every track cell q is the centre of a disc of radius clearance(q)
  that lies inside the track. The **local width** at a route point is the diameter of the
  largest inscribed disc that contains it (2 x the clearance of the centre line beside it),
  so a route that hugs the inside of a bend still measures the whole road's width.
* **Route corridor**: the union of the inscribed discs that contain a route point: the
  road the route drives along, never across a barrier. ``route_corridor_fraction`` is the
  share of all track cells on it.
* **Lap**: a return route from the goal back to the start that avoids the corridor of the
  route's middle (beyond one local width of either end), through the route certificate's
  free space (sub-cells with the route's clearance). When one exists the track is a
  circuit through start and goal; ``lap_corridor_fraction`` is the share of track cells on
  the corridor of the route or of the return (equal to the route's share when there is no
  return). A closed ring measures about 1, a ring with a long spur less.
* **Dead ends**: end points of the track's skeleton (Zhang-Suen thinning) after pruning
  every skeleton branch that ends within ``spur_length`` skeleton steps (default: the
  median local width of the track): a dead end is a spur longer than the road is wide, so
  bumps and the forks thinning leaves at square ends are not counted. A straight fragment
  has two, a T junction's stub one, a closed ring none.
* **Route curvature**: the route (pulled taut) resampled every ``curvature_step_m``,
  smoothed by a moving average over ``smoothing_m``, heading change per metre between
  consecutive samples (absolute, rad/m). The taut route is a polygon of chords on wide
  bends, so its median curvature may be 0 on a round bend: compare means (total turn per
  metre) and upper percentiles (the sharp turns).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sessgan_core.environment import Environment
from sessgan_core.grid_search import flat_grid, label_regions
from sessgan_core.token_map import resolve_scenario
from sessgan_core.valid_tests import (
    certify_environment,
    occupancy_passable_mask,
    shortest_path_in_free,
)

DEFAULT_CURVATURE_STEP_M = 0.5
"""Spacing in metres of the resampled route whose heading changes give the curvature."""

DEFAULT_SMOOTHING_M = 4.0
"""Moving-average window in metres over the route before headings are taken: a car's path
through a corner, not the taut route's kinks (about the example track's width)."""

_CHUNK_ELEMENTS = 4_000_000
"""Largest distance matrix built at once (float64 elements)."""


@dataclass(frozen=True)
class TrackRealism:
    """The track-realism measures of one map (see the module docstring)."""

    track_cells: int
    """Number of track (passable) cells."""
    fragments: int
    """4-connected components of track cells."""
    route_component_fraction: float
    """Share of track cells in the component that holds the route (0 without a route)."""
    route_corridor_fraction: float
    """Share of track cells on the route's corridor (0 without a route)."""
    lap_corridor_fraction: float
    """Share of track cells on the corridor of the route or its return (see ``closed_lap``)."""
    closed_lap: bool
    """Whether a return route from goal to start exists beside the route (a circuit)."""
    dead_ends: int
    """End points of the pruned track skeleton."""
    route_widths: np.ndarray
    """m, local track width at route points spaced one cell apart (empty without a route)."""
    route_curvatures: np.ndarray
    """rad/m, absolute heading change per metre along the smoothed route (may be empty)."""


_BAND = 8
"""Columns each side that track_clearance's first pass looks at (wider roads: a second)."""


def track_clearance(track: np.ndarray) -> np.ndarray:
    """Clearance in cells of every cell centre to the nearest non-track cell square.

    Exact Euclidean distance (separable: rows, then columns); the outside of the grid is
    non-track; 0 on non-track cells.
    """
    mask = np.asarray(track, dtype=bool)
    if mask.ndim != 2:
        raise ValueError(f'track mask must be 2-D, got shape {mask.shape}')
    blocked = np.pad(~mask, 1, constant_values=True)
    height, width = blocked.shape
    rows = np.arange(height, dtype=np.float64)[:, None]
    # Row distance to the nearest blocked cell of the same column, above and below.
    above = np.where(blocked, rows, -np.inf)
    above = np.maximum.accumulate(above, axis=0)
    below = np.where(blocked, rows, np.inf)
    below = np.minimum.accumulate(below[::-1], axis=0)[::-1]
    row_gap = np.minimum(rows - above, below - rows)
    along_rows = np.maximum(row_gap - 0.5, 0.0) ** 2
    # squared[r, c] = min over c' of (|c - c'| - 0.5)^2 + along_rows[r, c'], first over the
    # columns within _BAND of c; columns farther away add at least (_BAND + 0.5)^2, so the
    # band's minimum is exact wherever it is no larger, and the rest is taken over all.
    band = min(_BAND, width - 1)
    padded = np.pad(along_rows, ((0, 0), (band, band)), constant_values=np.inf)
    squared = along_rows.copy()
    for offset in range(1, band + 1):
        step = (offset - 0.5) ** 2
        np.minimum(squared, padded[:, band - offset:band - offset + width] + step, out=squared)
        np.minimum(squared, padded[:, band + offset:band + offset + width] + step, out=squared)
    far_rows = np.nonzero((squared > (band + 0.5) ** 2).any(axis=1))[0]
    if len(far_rows):
        columns = np.arange(width, dtype=np.float64)
        across = np.maximum(np.abs(columns[:, None] - columns[None, :]) - 0.5, 0.0) ** 2
        chunk = max(1, _CHUNK_ELEMENTS // (width * width))
        for first in range(0, len(far_rows), chunk):
            chosen = far_rows[first:first + chunk]
            squared[chosen] = (along_rows[chosen][:, None, :] + across[None, :, :]).min(axis=2)
    clearance = np.sqrt(squared)[1:-1, 1:-1]
    clearance[~mask] = 0.0
    return clearance


_NEIGHBOURS = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
"""The 8 neighbours in circular order (P2..P9 of Zhang and Suen)."""


def _neighbour_codes(image: np.ndarray) -> np.ndarray:
    """(h, w) uint8: each pixel's 8 neighbours as bits, P2 the lowest (outside = 0)."""
    height, width = image.shape
    padded = np.zeros((height + 2, width + 2), dtype=np.uint8)
    padded[1:-1, 1:-1] = image
    codes = np.zeros((height, width), dtype=np.uint8)
    for bit, (d_row, d_col) in enumerate(_NEIGHBOURS):
        codes |= padded[1 + d_row:1 + d_row + height, 1 + d_col:1 + d_col + width] << bit
    return codes


def _code_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per neighbour code: removable in Zhang-Suen's first and second sub-iteration, and
    whether a skeleton pixel with these neighbours ends a branch."""
    bits = (np.arange(256)[:, None] >> np.arange(8)[None, :]) & 1
    p2, p3, p4, p5, p6, p7, p8, p9 = bits.T
    count = bits.sum(axis=1)
    # 0 -> 1 transitions around the circular neighbourhood.
    transitions = ((bits == 0) & (np.roll(bits, -1, axis=1) == 1)).sum(axis=1)
    thinnable = (count >= 2) & (count <= 6) & (transitions == 1)
    first = thinnable & (p2 * p4 * p6 == 0) & (p4 * p6 * p8 == 0)
    second = thinnable & (p2 * p4 * p8 == 0) & (p2 * p6 * p8 == 0)
    end = (count <= 2) & (transitions <= 1)
    return first, second, end


_THIN_FIRST, _THIN_SECOND, _END_POINT = _code_tables()


def skeleton(track: np.ndarray) -> np.ndarray:
    """Zhang-Suen thinning of a bool mask: an 8-connected one-cell-wide centre line."""
    image = np.asarray(track, dtype=bool).copy()
    while True:
        changed = False
        for removable in (_THIN_FIRST, _THIN_SECOND):
            remove = image & removable[_neighbour_codes(image)]
            if remove.any():
                image[remove] = False
                changed = True
        if not changed:
            return image


def skeleton_end_points(skeleton_mask: np.ndarray) -> np.ndarray:
    """Bool mask of skeleton pixels that end a branch: one neighbour, or two that touch each
    other (a single run of neighbours around the pixel, at most two long), or none."""
    image = np.asarray(skeleton_mask, dtype=bool)
    return image & _END_POINT[_neighbour_codes(image)]


def prune_spurs(skeleton_mask: np.ndarray, spur_length: int) -> np.ndarray:
    """The skeleton with ``spur_length`` rounds of end-point removal: branches that end within
    that many steps vanish, longer ones lose their last ``spur_length`` pixels; closed loops
    stay whole."""
    image = np.asarray(skeleton_mask, dtype=bool).copy()
    for _ in range(max(0, int(spur_length))):
        ends = skeleton_end_points(image)
        if not ends.any():
            break
        image &= ~ends
    return image


def count_dead_ends(track: np.ndarray, spur_length: int | None = None,
                    clearance: np.ndarray | None = None) -> int:
    """Dead ends of a track mask: end points of its skeleton pruned by ``spur_length`` cells
    (None: the median local width, 2 x clearance on the skeleton, at least 2)."""
    thin = skeleton(track)
    if spur_length is None:
        if clearance is None:
            clearance = track_clearance(track)
        widths = 2.0 * clearance[thin]
        spur_length = max(2, int(round(float(np.median(widths))))) if len(widths) else 2
    return int(skeleton_end_points(prune_spurs(thin, spur_length)).sum())


def resample_polyline(points: np.ndarray, step: float) -> np.ndarray:
    """Points every ``step`` along a polyline (first and last included); (n, 2) in, (m, 2)
    out."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(points) < 2:
        return points.copy()
    segment = np.hypot(*np.diff(points, axis=0).T)
    along = np.concatenate([[0.0], np.cumsum(segment)])
    total = float(along[-1])
    if total <= 0.0:
        return points[:1].copy()
    count = max(2, int(math.ceil(total / step)) + 1)
    at = np.linspace(0.0, total, count)
    return np.column_stack([np.interp(at, along, points[:, 0]),
                            np.interp(at, along, points[:, 1])])


def route_curvatures(points_m: np.ndarray, step_m: float = DEFAULT_CURVATURE_STEP_M,
                     smoothing_m: float = DEFAULT_SMOOTHING_M) -> np.ndarray:
    """Absolute heading change per metre (rad/m) along a route given by its corners in
    metres: resampled every ``step_m``, smoothed by a moving average over ``smoothing_m``."""
    samples = resample_polyline(points_m, step_m)
    window = max(1, int(round(smoothing_m / step_m)))
    if len(samples) < window + 2:
        return np.zeros(0)
    if window > 1:
        kernel = np.ones(window) / window
        samples = np.column_stack([np.convolve(samples[:, 0], kernel, mode='valid'),
                                   np.convolve(samples[:, 1], kernel, mode='valid')])
    steps = np.diff(samples, axis=0)
    lengths = np.hypot(steps[:, 0], steps[:, 1])
    moving = lengths > 1e-9
    steps, lengths = steps[moving], lengths[moving]
    if len(steps) < 2:
        return np.zeros(0)
    headings = np.arctan2(steps[:, 1], steps[:, 0])
    turn = np.angle(np.exp(1j * np.diff(headings)))
    return np.abs(turn) / (0.5 * (lengths[1:] + lengths[:-1]))


def _disc_hits(centres: np.ndarray, radii: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Bool (len(centres), len(points)): whether each point lies in each centre's disc."""
    hits = np.zeros((len(centres), len(points)), dtype=bool)
    if not len(centres) or not len(points):
        return hits
    chunk = max(1, _CHUNK_ELEMENTS // len(points))
    for first in range(0, len(centres), chunk):
        block = centres[first:first + chunk]
        squared = ((block[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
        hits[first:first + chunk] = squared <= (radii[first:first + chunk, None] + 1e-9) ** 2
    return hits


def paint_discs(shape: tuple[int, ...], rows: np.ndarray, cols: np.ndarray,
                 radii: np.ndarray) -> np.ndarray:
    """Bool mask of the cells whose centres lie in at least one disc (centre = a cell centre,
    radius in cells, rounded to 1e-6); one shifted comparison per offset for all discs at
    once (the largest squared radius reaching from each centre)."""
    height, width = shape
    covered = np.zeros(shape, dtype=bool)
    keys = np.round(np.asarray(radii, dtype=np.float64), 6)
    if not len(keys):
        return covered
    reach = int(math.floor(float(keys.max()) + 1e-9))
    # Squared radius (with the tolerance) of the disc centred on each cell, -1 elsewhere.
    reaches = np.full((height + 2 * reach, width + 2 * reach), -1.0)
    np.maximum.at(reaches, (rows + reach, cols + reach), keys * keys + 1e-9)
    top = float(keys.max())
    farthest = top * top + 1e-9
    for d_row in range(-reach, reach + 1):
        for d_col in range(-reach, reach + 1):
            if d_row * d_row + d_col * d_col > farthest:
                continue  # beyond every disc
            reaching = reaches[reach - d_row:reach - d_row + height,
                               reach - d_col:reach - d_col + width]
            covered |= reaching >= d_row * d_row + d_col * d_col
    return covered


class _Discs:
    """The inscribed discs of a track: centres (x, y) in cells and radii in cells."""

    def __init__(self, track: np.ndarray, clearance: np.ndarray) -> None:
        rows, cols = np.nonzero(track)
        self.shape = track.shape
        self.rows, self.cols = rows, cols
        self.centres = np.column_stack([cols + 0.5, rows + 0.5]).astype(np.float64)
        self.radii = clearance[rows, cols].astype(np.float64)

    def corridor(self, points: np.ndarray) -> np.ndarray:
        """Bool per track cell (row-major order): on the union of the discs that contain one
        of ``points`` (cells)."""
        touching = _disc_hits(self.centres, self.radii, points).any(axis=1)
        covered = paint_discs(self.shape, self.rows[touching], self.cols[touching],
                               self.radii[touching])
        return covered[self.rows, self.cols]

    def widths(self, points: np.ndarray) -> np.ndarray:
        """Diameter in cells of the largest disc containing each point (0 if none)."""
        hits = _disc_hits(self.centres, self.radii, points)
        return 2.0 * np.where(hits, self.radii[:, None], 0.0).max(axis=0, initial=0.0)


def measure_track(track: np.ndarray, route_points: np.ndarray | None, cell_size: float = 1.0,
                  route_clearance: float = 0.0, spur_length: int | None = None,
                  curvature_step_m: float = DEFAULT_CURVATURE_STEP_M,
                  smoothing_m: float = DEFAULT_SMOOTHING_M,
                  route_free: np.ndarray | None = None) -> TrackRealism:
    """The track-realism measures of a bool track mask (row 0 = lowest y).

    ``route_points``: (n, 2) map-frame (x, y) corners of the start-to-goal route in cells
    from the grid's corner (cell (row, col) spans x in [col, col + 1)), or None when the map
    has no route. ``cell_size``: metres per cell. Where the lap's return route may run:
    ``route_free``, a bool mask of k x k sub-cells per cell (the route certificate's free
    space), or else the track cells whose clearance is at least ``route_clearance`` cells.
    """
    mask = np.asarray(track, dtype=bool)
    clearance = track_clearance(mask)
    track_cells = int(mask.sum())
    dead_ends = count_dead_ends(mask, spur_length, clearance)
    labels, sizes = label_regions(flat_grid(mask))
    fragments = len(sizes)
    empty = np.zeros(0)
    route = None if route_points is None else np.asarray(route_points, dtype=np.float64)
    if route is None or len(route) == 0 or track_cells == 0:
        return TrackRealism(track_cells, fragments, 0.0, 0.0, 0.0, False, dead_ends, empty,
                            empty)
    if route_free is None:
        route_free = mask & (clearance >= route_clearance - 1e-9)
    route_free = np.asarray(route_free, dtype=bool)
    subdivision = route_free.shape[0] // mask.shape[0]
    if subdivision < 1 or route_free.shape != (mask.shape[0] * subdivision,
                                               mask.shape[1] * subdivision):
        raise ValueError(f'route_free of shape {route_free.shape} does not split the '
                         f'{mask.shape} track into equal sub-cells')
    discs = _Discs(mask, clearance)
    dense = resample_polyline(route, 0.5)
    on_route = discs.corridor(dense)
    stride = mask.shape[1] + 2
    start_row, start_col = _cell_of(route[0], mask.shape)
    component = labels[(start_row + 1) * stride + start_col + 1]
    route_component = int(sizes[component]) if component >= 0 else 0
    per_cell = resample_polyline(route, 1.0)
    widths = discs.widths(per_cell)
    lap = on_route
    closed = False
    back = _return_route(discs, dense, widths, route_free, subdivision)
    if back is not None:
        closed = True
        lap = on_route | discs.corridor(back)
    curvatures = route_curvatures(route * cell_size, curvature_step_m, smoothing_m)
    return TrackRealism(
        track_cells, fragments, route_component / track_cells,
        float(on_route.sum()) / track_cells, float(lap.sum()) / track_cells, closed, dead_ends,
        widths * cell_size, curvatures)


def _cell_of(point: np.ndarray, shape: tuple[int, ...], scale: int = 1) -> tuple[int, int]:
    row = min(max(int(math.floor(point[1] * scale)), 0), shape[0] - 1)
    col = min(max(int(math.floor(point[0] * scale)), 0), shape[1] - 1)
    return row, col


def _return_route(discs: _Discs, dense: np.ndarray, widths: np.ndarray, free: np.ndarray,
                  subdivision: int) -> np.ndarray | None:
    """Points (x, y) in cells of a route from the goal back to the start through ``free``
    sub-cells that avoids the corridor of the route's middle (the discs touching the route
    farther than one local width from either end, less those touching its ends), or None."""
    if len(dense) < 3:
        return None
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(dense, axis=0).T))])
    end_width = float(max(widths[0], widths[-1], 1.0)) if len(widths) else 1.0
    in_middle = (along > end_width) & (along < along[-1] - end_width)
    if not in_middle.any():
        return None
    barrier = discs.corridor(dense[in_middle]) & ~discs.corridor(dense[~in_middle])
    blocked = np.zeros(discs.shape, dtype=bool)
    blocked[discs.rows[barrier], discs.cols[barrier]] = True
    if subdivision > 1:
        blocked = np.repeat(np.repeat(blocked, subdivision, axis=0), subdivision, axis=1)
    path = shortest_path_in_free(free & ~blocked, _cell_of(dense[-1], free.shape, subdivision),
                                 _cell_of(dense[0], free.shape, subdivision))
    if not path:
        return None
    return np.array([((col + 0.5) / subdivision, (row + 0.5) / subdivision)
                     for row, col in path], dtype=np.float64)


def measure_environment(environment: Environment, spur_length: int | None = None,
                        curvature_step_m: float = DEFAULT_CURVATURE_STEP_M,
                        smoothing_m: float = DEFAULT_SMOOTHING_M) -> TrackRealism:
    """The track-realism measures of an Environment, on its own certified start-to-goal
    route (:func:`sessgan_core.valid_tests.certify_environment`; no route measures when it is
    not a valid test). Track = the cells its scenario's robot may occupy."""
    spec = resolve_scenario(environment.scenario)
    track = occupancy_passable_mask(environment.occupancy, spec)
    certificate = certify_environment(environment) if environment.feasible else None
    route = None
    route_free = None
    if certificate is not None:
        origin = np.asarray(environment.origin, dtype=np.float64)
        route = (certificate.points - origin) / environment.resolution
        route_free = (certificate.grid.clearance
                      >= certificate.required_clearance - 1e-9)
    return measure_track(track, route, environment.resolution, 0.0, spur_length,
                         curvature_step_m, smoothing_m, route_free)
