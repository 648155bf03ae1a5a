"""Valid tests: start and goal poses with room around them and a certified route between them.

A map only tests a controller when a competent robot could cross it safely. This module
decides that, deterministically from the map and the environment seed:

* **Clearance** of a point: distance in metres from it to the nearest blocked cell *square*
  (the grid's outside counts as blocked). It is computed on a certificate grid that splits
  every map cell into ``subdivision`` x ``subdivision`` sub-cells (0.125 m for the 0.5 m cells
  of the factory and the drone area, 0.33 m on the race track): at cell-centre resolution
  a 1 m corridor would have 0.25 m of clearance everywhere and look closed to a 0.2 m robot.
* **Start and goal** are sub-cell centres whose clearance is at least ``robot_radius +
  clearance_margin``. The start is drawn from the seed among them; the goal among those that
  are far along the route from it: at least :func:`min_route_steps` (half the map's shorter
  side) and at least half the farthest such cell; for a scenario with a
  ``goal_track_fraction`` (the race track: 0.5), also at least that fraction of the track's
  length, the longest route between two such cells of the start's region
  (:func:`track_length_steps`). Both yaws point along the route.
* **Route certificate**: a 4-connected shortest path from start to goal through sub-cells
  whose clearance is at least ``robot_radius + route_margin`` (Nav2's inscribed radius plus an
  inflation margin). A map is a *valid test* (``feasible``) only when it exists. The
  certificate records the route's length (of the path pulled taut inside that free space)
  and its *bottleneck clearance*: the largest clearance ``c`` such that start and goal stay
  connected through sub-cells of clearance >= ``c`` (the tightest passage every route from
  start to goal must go through).

Everything is pure numpy / Python and fast enough to run on every generated map.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from sessgan_core.grid_search import (
    FlatGrid,
    bfs,
    flat_grid,
    label_regions,
    steps_of,
    to_cell,
    to_flat,
    unvisited,
    walk_back,
)
from sessgan_core.scenarios import Scenario

Cell = tuple[int, int]
"""A certificate-grid cell (row, col); row 0 at the map origin (lowest y)."""

START_TRIES = 8
"""Starts drawn before a map is declared to have no far-apart pair of clear cells."""

HEADING_LOOKAHEAD_M = 1.0
"""Route distance ahead of the start (behind the goal) that the yaws point along."""


class Rejection:
    """Why a map is not a valid test (the values of ``Placement.rejection``)."""

    NO_CLEAR_CELL = 'no_clear_cell'
    """No point has the clearance start and goal need."""
    NO_FAR_GOAL = 'no_far_goal'
    """Clear points exist, but no two of them are far enough apart on a certified route."""


class CertificateGrid(NamedTuple):
    """The clearance field of a map on its certificate grid."""

    clearance: np.ndarray
    """float array (height * subdivision, width * subdivision), metres, capped at ``cap``."""
    subdivision: int
    """Certificate cells per map cell and axis."""
    cell_size: float
    """Metres per certificate cell."""
    origin: tuple[float, float]
    """Map-frame (x, y) of the outer corner of certificate cell (0, 0)."""
    cap: float
    """Clearances at least this large are stored as ``cap``."""

    def centre(self, cell: Cell) -> tuple[float, float]:
        """Map-frame (x, y) in metres of a certificate cell's centre."""
        return (self.origin[0] + (cell[1] + 0.5) * self.cell_size,
                self.origin[1] + (cell[0] + 0.5) * self.cell_size)

    def cell_of(self, x: float, y: float) -> Cell:
        """Certificate cell containing map-frame point (x, y) (may lie outside the grid)."""
        return (int(math.floor((y - self.origin[1]) / self.cell_size)),
                int(math.floor((x - self.origin[0]) / self.cell_size)))


class RouteCertificate(NamedTuple):
    """A certified route from start to goal."""

    path: list[Cell]
    """4-connected certificate cells from start to goal, both included."""
    points: np.ndarray
    """float array (n, 2): map-frame (x, y) of the taut route's corners, start to goal."""
    length: float
    """m, length of the taut route."""
    bottleneck_clearance: float
    """m, the tightest clearance any route from start to goal must pass (see the module)."""
    required_clearance: float
    """m, the clearance the route keeps at least: robot radius + route margin."""
    grid: CertificateGrid
    """The clearance field the route was certified on (``path`` indexes it)."""


class Placement(NamedTuple):
    """Start, goal and certificate of one map, or why there are none."""

    start: tuple[float, float, float] | None
    """(x, y, yaw) in metres and radians; None when rejected."""
    goal: tuple[float, float, float] | None
    certificate: RouteCertificate | None
    start_clearance: float
    goal_clearance: float
    rejection: str
    """'' for a valid test, else a :class:`Rejection` value."""


def certificate_subdivision(spec: Scenario) -> int:
    """Certificate cells per map cell and axis: sub-cells at most two thirds of the robot's
    radius (0.125 m for the 0.2 m robots in 0.5 m cells, 0.33 m for the car), at most 4."""
    return int(min(4, max(1, math.ceil(spec.cell_size / (spec.robot_radius * 2 / 3)))))


def clearance_field(blocked: np.ndarray, resolution: float, subdivision: int,
                    cap: float, origin: tuple[float, float] = (0.0, 0.0)) -> CertificateGrid:
    """Clearance of every certificate-cell centre to the nearest blocked map-cell square.

    ``blocked`` is a bool array (height, width) of map cells; the outside of the grid counts
    as blocked. Distances are exact (point to square) up to ``cap`` metres.
    """
    blocked = np.asarray(blocked, dtype=bool)
    if blocked.ndim != 2:
        raise ValueError(f'blocked mask must be 2-D, got shape {blocked.shape}')
    if subdivision < 1:
        raise ValueError(f'subdivision must be >= 1, got {subdivision}')
    height, width = blocked.shape
    reach = int(math.ceil(cap / resolution)) + 1
    padded = np.pad(blocked, reach, mode='constant', constant_values=True)
    clearance = np.full((height * subdivision, width * subdivision), cap, dtype=np.float64)
    # Sub-cell centres sit at fractions (k + 0.5) / subdivision of their map cell. For one
    # fraction pair, the gap to a map cell square offset by (d_row, d_col) is the same for
    # every map cell: each sub-cell's clearance is the least gap of the offsets whose map
    # cell is blocked, one numpy reduction per fraction pair over every offset's shifted
    # mask (a minimum per pair and offset cost 3x as much in call overhead on small maps).
    fractions = (np.arange(subdivision) + 0.5) / subdivision
    offsets = [(d_row, d_col) for d_row in range(-reach, reach + 1)
               for d_col in range(-reach, reach + 1)]
    shifted = np.stack([padded[reach + d_row:reach + d_row + height,
                               reach + d_col:reach + d_col + width]
                        for d_row, d_col in offsets])
    for sub_row, frac_row in enumerate(fractions):
        for sub_col, frac_col in enumerate(fractions):
            gaps = np.array([
                # Distance along each axis from a point at `frac` inside cell 0 to cell d.
                math.hypot(max(d_row - frac_row, frac_row - d_row - 1.0, 0.0),
                           max(d_col - frac_col, frac_col - d_col - 1.0, 0.0)) * resolution
                for d_row, d_col in offsets])
            near = np.flatnonzero(gaps < cap)
            clearance[sub_row::subdivision, sub_col::subdivision] = np.where(
                shifted[near], gaps[near, None, None], cap).min(axis=0, initial=cap)
    return CertificateGrid(clearance, subdivision, resolution / subdivision, origin, cap)


def required_clearances(spec: Scenario) -> tuple[float, float]:
    """(start/goal clearance, route clearance) in metres for a scenario's robot."""
    return (spec.robot_radius + spec.clearance_margin, spec.robot_radius + spec.route_margin)


def map_clearance(occupancy: np.ndarray, resolution: float, origin: tuple[float, float],
                  spec: Scenario) -> CertificateGrid:
    """The clearance field of an OccupancyGrid array for a scenario's robot.

    Cells the robot may not occupy (not one of the scenario's traversable occupancy values,
    unknown included) are blocked. Clearances are exact up to 1 m beyond what the start needs.
    """
    allowed = sorted({spec.occupancy[token] for token in spec.traversable})
    blocked = ~np.isin(np.asarray(occupancy), allowed)
    cap = required_clearances(spec)[0] + 1.0
    return clearance_field(blocked, resolution, certificate_subdivision(spec), cap, origin)


def min_route_steps(shape: tuple[int, int], subdivision: int) -> int:
    """Fewest certificate-grid steps between start and goal: half the map's shorter side."""
    return max(2, int(0.5 * min(shape[0], shape[1]))) * subdivision


def track_length_steps(flat: FlatGrid, region: np.ndarray | list[int],
                       candidates: np.ndarray) -> int:
    """The track's length in grid steps: the longest shortest route between two
    ``candidates`` (flat indices) of one 4-connected ``region`` (its flat indices), by a
    double sweep: the candidate farthest from the region's first cell, then the candidate
    farthest from that one. Exact on tree-shaped tracks and on a single loop (half the
    lap), at most the longest route otherwise; 0 when the region holds no candidate."""
    inside = candidates[np.isin(candidates, np.asarray(region))]
    if not len(inside):
        return 0
    dist = unvisited(flat)
    bfs(flat, int(region[0]), dist)
    end = int(inside[int(np.argmax(steps_of(dist)[inside]))])
    dist = unvisited(flat)
    bfs(flat, end, dist)
    return int(steps_of(dist)[inside].max())


def _yaw_along(points: list[tuple[float, float]]) -> float:
    (x0, y0), (x1, y1) = points[0], points[-1]
    return math.atan2(y1 - y0, x1 - x0) if (x0, y0) != (x1, y1) else 0.0


def _line_is_free(free: np.ndarray, a: Cell, b: Cell) -> bool:
    """Whether the segment between two cell centres crosses only free cells (sampled every
    quarter cell)."""
    steps = max(1, int(4 * max(abs(b[0] - a[0]), abs(b[1] - a[1]))))
    t = np.linspace(0.0, 1.0, steps + 1)
    rows = np.floor(a[0] + 0.5 + t * (b[0] - a[0])).astype(int)
    cols = np.floor(a[1] + 0.5 + t * (b[1] - a[1])).astype(int)
    return bool(free[rows, cols].all())


def taut_corners(free: np.ndarray, path: list[Cell]) -> list[Cell]:
    """Corners of ``path`` pulled taut inside ``free`` (greedy line of sight)."""
    if len(path) <= 2:
        return list(path)
    corners = [path[0]]
    anchor = 0
    for index in range(2, len(path)):
        if not _line_is_free(free, path[anchor], path[index]):
            anchor = index - 1
            corners.append(path[anchor])
    corners.append(path[-1])
    return corners


def bottleneck_clearance(clearance: np.ndarray, start: Cell, goal: Cell, floor: float) -> float:
    """The largest c such that start and goal connect through cells of clearance >= c
    (4-connected, cells below ``floor`` never entered); 0 when they do not connect.

    A bisection over the field's own values (a few dozen distinct ones) with one region
    labelling a step: connecting at c implies connecting at every lower value.
    """
    field = np.asarray(clearance, dtype=np.float64)
    at_start, at_goal = float(field[start]), float(field[goal])
    if start == goal:
        return at_start if at_start >= floor else -1.0
    if at_start < floor or at_goal < floor:
        return 0.0
    levels = np.unique(field[(field >= floor) & (field <= min(at_start, at_goal))])
    stride = field.shape[1] + 2
    ends = ((start[0] + 1) * stride + start[1] + 1, (goal[0] + 1) * stride + goal[1] + 1)

    def connected(level: float) -> bool:
        labels = label_regions(flat_grid(field >= level)).labels
        return bool(labels[ends[0]] == labels[ends[1]])

    if not connected(float(levels[0])):
        return 0.0
    low, high = 0, len(levels) - 1  # connected at levels[low]; find the highest such
    while low < high:
        middle = (low + high + 1) // 2
        if connected(float(levels[middle])):
            low = middle
        else:
            high = middle - 1
    return float(levels[low])


def certify(grid: CertificateGrid, start: Cell, goal: Cell,
            required_clearance: float) -> RouteCertificate | None:
    """The certified route between two certificate cells, None when there is none."""
    free = grid.clearance >= required_clearance - 1e-9
    flat = flat_grid(free)
    height, width = free.shape
    for row, col in (start, goal):
        if not (0 <= row < height and 0 <= col < width) or not free[row, col]:
            return None
    dist = unvisited(flat)
    target = to_flat(flat, goal)
    bfs(flat, to_flat(flat, start), dist, target)
    if dist[target] < 0:
        return None
    path = [to_cell(flat, index) for index in walk_back(flat, dist, target)]
    return _certificate(grid, free, path, required_clearance)


def _certificate(grid: CertificateGrid, free: np.ndarray, path: list[Cell],
                 required_clearance: float) -> RouteCertificate:
    corners = taut_corners(free, path)
    points = np.array([grid.centre(cell) for cell in corners], dtype=np.float64)
    length = float(np.hypot(*np.diff(points, axis=0).T).sum()) if len(points) > 1 else 0.0
    bottleneck = bottleneck_clearance(grid.clearance, path[0], path[-1], required_clearance)
    return RouteCertificate(path, points, length, bottleneck, required_clearance, grid)


def place_start_goal(occupancy: np.ndarray, resolution: float, origin: tuple[float, float],
                     spec: Scenario, seed: int) -> Placement:
    """Draw a start and a goal for a map from ``seed`` and certify the route between them
    (the rules are in the module docstring). Deterministic per (map, seed)."""
    grid = map_clearance(occupancy, resolution, origin, spec)
    place_need, route_need = required_clearances(spec)
    clearance = grid.clearance
    placeable = clearance >= place_need - 1e-9
    routable = clearance >= route_need - 1e-9
    if not placeable.any():
        return Placement(None, None, None, 0.0, 0.0, Rejection.NO_CLEAR_CELL)
    flat = flat_grid(routable)
    labels, region_sizes = label_regions(flat)
    min_steps = min_route_steps(np.asarray(occupancy).shape, grid.subdivision)
    rows, cols = np.nonzero(placeable)
    candidates = (rows + 1) * flat.stride + cols + 1
    # Only regions large enough to hold a route of min_steps can give a valid pair.
    starts = candidates[region_sizes[labels[candidates]] > min_steps]
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(0x5E55,)))
    track_lengths: dict[int, int] = {}
    for _ in range(START_TRIES if len(starts) else 0):
        start = int(starts[rng.integers(len(starts))])
        dist = unvisited(flat)
        bfs(flat, start, dist)
        steps = steps_of(dist)[candidates]
        farthest_steps = int(steps.max())
        need = max(min_steps, 0.5 * farthest_steps)
        if spec.goal_track_fraction > 0:
            region = int(labels[start])
            if region not in track_lengths:
                track_lengths[region] = track_length_steps(
                    flat, np.flatnonzero(labels == region), candidates)
            need = max(need, spec.goal_track_fraction * track_lengths[region])
        goals = candidates[steps >= need]
        if not len(goals):
            continue
        goal = int(goals[rng.integers(len(goals))])
        path = [to_cell(flat, index) for index in walk_back(flat, dist, goal)]
        certificate = _certificate(grid, routable, path, route_need)
        lookahead = max(1, min(len(path) - 1, round(HEADING_LOOKAHEAD_M / grid.cell_size)))
        start_xy = grid.centre(path[0])
        goal_xy = grid.centre(path[-1])
        start_yaw = _yaw_along([start_xy, grid.centre(path[lookahead])])
        goal_yaw = _yaw_along([grid.centre(path[-1 - lookahead]), goal_xy])
        return Placement((*start_xy, start_yaw), (*goal_xy, goal_yaw), certificate,
                         float(clearance[path[0]]), float(clearance[path[-1]]), '')
    return Placement(None, None, None, 0.0, 0.0, Rejection.NO_FAR_GOAL)
