"""Footprint-aware free space, start and goal selection, feasibility and shortest paths.

Used by the generator, the simulator and the evolver, so everything here is
deterministic (no random numbers) and fast: the evolver builds thousands of
environments per generation.

Conventions:

* Cells are ``(row, col)`` in OccupancyGrid order (row 0 = lowest y).
* **Footprint inflation**: the robot's centre may stand on a cell when no
  blocked cell *square* comes closer than the robot's radius to the cell's
  centre, and the grid's outside counts as blocked. Measuring to the nearest
  point of a blocked square (not to its centre) is what keeps the car (radius
  0.6 m in 1 m cells) out of track cells that touch the kerb, while the ground
  robot and the drone (0.2 m in 0.5 m cells) still fit a one-cell gap.
* **Connectivity**: 4-connected moves only. A diagonal move between two
  blocked diagonal neighbours would cut a corner the footprint cannot pass, and
  forbidding diagonals altogether is the simple safe rule.
* **Start and goal**: the largest 4-connected region of the inflated free
  space (ties: the region whose first cell in row-major order comes first);
  a double sweep of breadth-first searches picks two cells far apart by
  geodesic distance: A = the cell farthest from the region's first cell in
  row-major order, B = the cell farthest from A (ties: smallest row, then col).
  Start = A, goal = B. On a closed circuit this puts the goal about half a lap
  from the start.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from sessgan_gen.environment import Environment, Pose2D
from sessgan_gen.scenarios import Scenario
from sessgan_gen.token_map import ScenarioLike, check_cells, resolve_scenario, tokens_to_occupancy

Cell = tuple[int, int]
"""A grid cell (row, col)."""

HEADING_LOOKAHEAD = 3
"""Path cells ahead (behind, for the goal) used to point the start (goal) yaw along the route."""

OPEN_CELL_WINDOW = 5
"""Side in cells of the window counting passable cells to find the most open cell."""


class Route(NamedTuple):
    """A start, a goal and the 4-connected shortest path between them (both included)."""

    start: Cell
    goal: Cell
    path: list[Cell]


class Regions(NamedTuple):
    """4-connected regions of a free mask."""

    labels: np.ndarray
    """int32 array, region index of each free cell, -1 elsewhere; regions numbered in
    row-major order of their first cell."""
    sizes: list[int]
    """Number of cells of each region."""


def passable_mask(cells: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Cells the robot may occupy (its tokens in ``scenario.traversable``), as a bool array."""
    spec = resolve_scenario(scenario)
    array = check_cells(cells, spec)
    table = np.zeros(spec.num_tokens, dtype=bool)
    table[list(spec.traversable)] = True
    return table[array]


def occupancy_passable_mask(occupancy: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Passable cells of an OccupancyGrid array (e.g. an Environment's) for a scenario's robot.

    A cell is passable when its value is the occupancy of one of the scenario's
    traversable tokens (free 0; also low obstacle 50 for the drone). Unknown (-1)
    and any other value are not passable.
    """
    spec = resolve_scenario(scenario)
    allowed = sorted({spec.occupancy[token] for token in spec.traversable})
    return np.isin(np.asarray(occupancy), allowed)


@lru_cache(maxsize=64)
def _footprint_offsets(radius_cells: float) -> tuple[tuple[int, int], ...]:
    """Return the precomputed disc kernel of :func:`inflate`.

    Offsets (dr, dc), other than (0, 0), of the cells whose square lies closer than
    ``radius_cells`` to a cell centre.
    """
    reach = int(math.ceil(radius_cells + 0.5))
    offsets = []
    for d_row in range(-reach, reach + 1):
        for d_col in range(-reach, reach + 1):
            if d_row == 0 and d_col == 0:
                continue
            gap = math.hypot(max(abs(d_row) - 0.5, 0.0), max(abs(d_col) - 0.5, 0.0))
            if gap < radius_cells:
                offsets.append((d_row, d_col))
    return tuple(offsets)


def inflate(passable: np.ndarray, radius_cells: float) -> np.ndarray:
    """Cells where a disc of ``radius_cells`` (in cells) centred on the cell touches nothing.

    A cell is free for the footprint when it is passable and no blocked cell's
    square, nor the outside of the grid, lies closer than ``radius_cells`` to its
    centre. Returns a new bool array of the same shape.
    """
    mask = np.asarray(passable, dtype=bool)
    if mask.ndim != 2:
        raise ValueError(f'passable mask must be 2-D, got shape {mask.shape}')
    if not math.isfinite(radius_cells) or radius_cells < 0:
        raise ValueError(f'radius must be a finite number of cells >= 0, got {radius_cells}')
    offsets = _footprint_offsets(round(float(radius_cells), 9))
    blocked = ~mask
    if not offsets:
        return mask.copy()
    reach = max(max(abs(d_row), abs(d_col)) for d_row, d_col in offsets)
    height, width = mask.shape
    padded = np.pad(blocked, reach, mode='constant', constant_values=True)
    out = blocked.copy()
    for d_row, d_col in offsets:
        out |= padded[reach + d_row:reach + d_row + height, reach + d_col:reach + d_col + width]
    return ~out


def footprint_free_mask(cells: np.ndarray, scenario: ScenarioLike) -> np.ndarray:
    """Cells where the scenario's robot centre may stand: passable cells, inflated."""
    spec = resolve_scenario(scenario)
    return inflate(passable_mask(cells, spec), spec.robot_radius / spec.cell_size)


# --- breadth-first search on a padded flat grid ------------------------------------------------
#
# Pure Python on a flat bytearray with a one-cell blocked border: no bounds checks, and
# faster than numpy for the few thousand cells of a map (numpy's per-call overhead
# dominates a frontier search whose depth is the map's geodesic diameter).


class _FlatGrid(NamedTuple):
    open_cells: bytearray
    stride: int
    height: int
    width: int


def _flat_grid(free: np.ndarray) -> _FlatGrid:
    mask = np.asarray(free, dtype=bool)
    if mask.ndim != 2:
        raise ValueError(f'free mask must be 2-D, got shape {mask.shape}')
    padded = np.pad(mask, 1, mode='constant', constant_values=False)
    return _FlatGrid(bytearray(padded.astype(np.uint8).tobytes()), padded.shape[1],
                     mask.shape[0], mask.shape[1])


def _to_flat(grid: _FlatGrid, cell: Cell) -> int:
    return (cell[0] + 1) * grid.stride + cell[1] + 1


def _to_cell(grid: _FlatGrid, index: int) -> Cell:
    row, col = divmod(index, grid.stride)
    return (row - 1, col - 1)


def _bfs(grid: _FlatGrid, start: int, dist: list[int]) -> list[int]:
    """Fill ``dist`` (pre-set to -1) from ``start``; return the visit order."""
    open_cells = grid.open_cells
    stride = grid.stride
    dist[start] = 0
    queue = [start]
    append = queue.append
    head = 0
    while head < len(queue):
        current = queue[head]
        head += 1
        step = dist[current] + 1
        for neighbour in (current - stride, current - 1, current + 1, current + stride):
            if open_cells[neighbour] and dist[neighbour] < 0:
                dist[neighbour] = step
                append(neighbour)
    return queue


def _farthest(order: list[int], dist: list[int]) -> int:
    """The visited cell at the largest distance; ties go to the smallest flat index."""
    best = order[-1]
    far = dist[best]
    for index in reversed(order):
        if dist[index] != far:
            break
        best = min(best, index)
    return best


def _walk_back(grid: _FlatGrid, dist: list[int], goal: int) -> list[int]:
    """Path from the BFS source to ``goal`` following decreasing distances."""
    stride = grid.stride
    path = [goal]
    current = goal
    while dist[current] > 0:
        want = dist[current] - 1
        for neighbour in (current - stride, current - 1, current + 1, current + stride):
            if dist[neighbour] == want:
                current = neighbour
                break
        path.append(current)
    path.reverse()
    return path


def _regions(grid: _FlatGrid) -> tuple[list[int], list[list[int]], list[int]]:
    """Label every free cell of a flat grid.

    Returns (labels, visit order per region, distance from each region's first cell);
    labels are -1 outside free space.
    """
    size = len(grid.open_cells)
    dist = [-1] * size
    labels = [-1] * size
    orders: list[list[int]] = []
    open_cells = grid.open_cells
    index = open_cells.find(1)
    while index >= 0:
        if dist[index] < 0:
            order = _bfs(grid, index, dist)
            label = len(orders)
            for member in order:
                labels[member] = label
            orders.append(order)
        index = open_cells.find(1, index + 1)
    return labels, orders, dist


def reachable_regions(free: np.ndarray) -> Regions:
    """The 4-connected regions of a free mask (e.g. :func:`footprint_free_mask`)."""
    grid = _flat_grid(free)
    labels, orders, _ = _regions(grid)
    stride = grid.stride
    label_array = np.asarray(labels, dtype=np.int32).reshape(-1, stride)[1:-1, 1:-1]
    return Regions(np.ascontiguousarray(label_array), [len(order) for order in orders])


def _route_in_free(free: np.ndarray) -> Route | None:
    grid = _flat_grid(free)
    _, orders, dist_from_first = _regions(grid)
    if not orders:
        return None
    largest = max(range(len(orders)), key=lambda label: (len(orders[label]), -label))
    order = orders[largest]
    if len(order) < 2:
        return None
    start = _farthest(order, dist_from_first)
    dist = [-1] * len(grid.open_cells)
    order_from_start = _bfs(grid, start, dist)
    goal = _farthest(order_from_start, dist)
    path = [_to_cell(grid, index) for index in _walk_back(grid, dist, goal)]
    return Route(_to_cell(grid, start), _to_cell(grid, goal), path)


MIN_ROUTE_FRACTION = 0.5
"""A feasible map's route is at least this fraction of the grid's shorter side long."""


def min_route_cells(shape: tuple[int, ...]) -> int:
    """Fewest route steps (cells) of a feasible map of ``shape`` (height, width)."""
    return max(2, int(MIN_ROUTE_FRACTION * min(shape[0], shape[1])))


def plan_route(cells: np.ndarray, scenario: ScenarioLike) -> Route | None:
    """Start, goal and shortest path as the module docstring describes.

    None when the footprint fits nowhere (no region of at least two cells).
    """
    return _route_in_free(footprint_free_mask(cells, scenario))


def choose_start_goal(cells: np.ndarray, scenario: ScenarioLike) -> tuple[Cell, Cell] | None:
    """Deterministic (start, goal) cells far apart in the largest footprint-free region."""
    route = plan_route(cells, scenario)
    return None if route is None else (route.start, route.goal)


def _check_cell(free: np.ndarray, cell: Cell, label: str) -> None:
    row, col = cell
    if not (0 <= row < free.shape[0] and 0 <= col < free.shape[1]):
        raise ValueError(f'{label} cell {cell} lies outside the {free.shape[1]}x'
                         f'{free.shape[0]} grid')


def shortest_path_in_free(free: np.ndarray, start: Cell, goal: Cell) -> list[Cell]:
    """4-connected shortest path from ``start`` to ``goal`` inside a free mask.

    Both ends are included; [] when either end is not free or no path exists.
    """
    mask = np.asarray(free, dtype=bool)
    _check_cell(mask, start, 'start')
    _check_cell(mask, goal, 'goal')
    if not (mask[start] and mask[goal]):
        return []
    grid = _flat_grid(mask)
    dist = [-1] * len(grid.open_cells)
    _bfs(grid, _to_flat(grid, start), dist)
    target = _to_flat(grid, goal)
    if dist[target] < 0:
        return []
    return [_to_cell(grid, index) for index in _walk_back(grid, dist, target)]


def shortest_path(cells: np.ndarray, scenario: ScenarioLike, start_rc: Cell,
                  goal_rc: Cell) -> list[Cell]:
    """Shortest footprint-safe 4-connected path of cells from start to goal ([] if none)."""
    return shortest_path_in_free(footprint_free_mask(cells, scenario), start_rc, goal_rc)


def is_feasible(cells: np.ndarray, scenario: ScenarioLike, start_rc: Cell,
                goal_rc: Cell) -> bool:
    """True when the robot's footprint can travel from ``start_rc`` to ``goal_rc``."""
    return bool(shortest_path(cells, scenario, start_rc, goal_rc))


def environment_is_feasible(environment: Environment) -> bool:
    """Feasibility of an Environment from its occupancy grid, start and goal poses."""
    spec = resolve_scenario(environment.scenario)
    passable = occupancy_passable_mask(environment.occupancy, spec)
    free = inflate(passable, spec.robot_radius / environment.resolution)
    start = environment.cell_of(environment.start.x, environment.start.y)
    goal = environment.cell_of(environment.goal.x, environment.goal.y)
    height, width = free.shape
    for row, col in (start, goal):
        if not (0 <= row < height and 0 <= col < width):
            return False
    return bool(shortest_path_in_free(free, start, goal))


def _box_sums(mask: np.ndarray, side: int) -> np.ndarray:
    """Number of True cells in the side x side window centred on each cell (side odd)."""
    half = side // 2
    padded = np.pad(mask.astype(np.int32), half)
    summed = np.pad(padded.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    height, width = mask.shape
    return (summed[side:side + height, side:side + width] - summed[:height, side:side + width]
            - summed[side:side + height, :width] + summed[:height, :width])


def most_open_cell(cells: np.ndarray, scenario: ScenarioLike) -> Cell:
    """Return the most open cell, the fallback pose of maps without a feasible route.

    Footprint-free cells come first, then passable ones; among those, the most passable
    cells in the OPEN_CELL_WINDOW square, then in the 3 x 3 square; ties go to the
    smallest (row, col).
    """
    spec = resolve_scenario(scenario)
    passable = passable_mask(cells, spec)
    free = inflate(passable, spec.robot_radius / spec.cell_size)
    wide = _box_sums(passable, OPEN_CELL_WINDOW)
    near = _box_sums(passable, 3)
    # Each term outweighs all the later ones: near <= 9 < 10, 10 * wide + near < 1000.
    score = free * 100_000 + passable * 10_000 + wide * 10 + near
    row, col = np.unravel_index(int(np.argmax(score)), score.shape)
    return (int(row), int(col))


def _heading(path: list[Cell], at_start: bool) -> float:
    """Yaw in radians along the first (or last) HEADING_LOOKAHEAD steps of a path."""
    if len(path) < 2:
        return 0.0
    steps = min(HEADING_LOOKAHEAD, len(path) - 1)
    if at_start:
        (row_a, col_a), (row_b, col_b) = path[0], path[steps]
    else:
        (row_a, col_a), (row_b, col_b) = path[-1 - steps], path[-1]
    return math.atan2(row_b - row_a, col_b - col_a)


def make_environment(cells: np.ndarray, scenario_name: ScenarioLike, env_id: str,
                     seed: int = 0, generation: int = -1, member: int = -1) -> Environment:
    """Build the Environment of a token map: occupancy, start, goal and feasibility.

    Resolution is the scenario's cell size (metres per cell) and the origin (0, 0),
    so cell (row, col) spans x in [col*res, (col+1)*res). Start and goal sit at cell
    centres chosen by :func:`plan_route`; their yaw points along the route's first
    and last steps. ``feasible`` is True when the route has at least
    :func:`min_route_cells` steps. Without any route (the footprint fits nowhere),
    ``feasible`` is False and start and goal both sit at :func:`most_open_cell`, yaw 0.
    ``extra['path_length_m']`` holds the route length in metres (0 when infeasible).
    """
    spec: Scenario = resolve_scenario(scenario_name)
    array = check_cells(cells, spec)
    occupancy = tokens_to_occupancy(array, spec)
    route = plan_route(array, spec)
    resolution = spec.cell_size

    def centre(cell: Cell, yaw: float) -> Pose2D:
        return Pose2D((cell[1] + 0.5) * resolution, (cell[0] + 0.5) * resolution, yaw)

    if route is None:
        cell = most_open_cell(array, spec)
        start = goal = centre(cell, 0.0)
        feasible = False
        length = 0.0
    else:
        start = centre(route.start, _heading(route.path, at_start=True))
        goal = centre(route.goal, _heading(route.path, at_start=False))
        length = (len(route.path) - 1) * resolution
        # A start next to its goal tests nothing: a map only counts as feasible if its
        # route crosses a fair part of it.
        feasible = len(route.path) - 1 >= min_route_cells(array.shape)
    return Environment(
        id=env_id, scenario=spec.name, occupancy=occupancy, resolution=resolution,
        start=start, goal=goal, origin=(0.0, 0.0), seed=seed, generation=generation,
        member=member, feasible=feasible, extra={'path_length_m': length})
