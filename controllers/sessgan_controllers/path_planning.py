"""Global planning on a :class:`~sessgan_controllers.costmap.Costmap`: A*, smoothing, paths.

* :func:`astar`: 8-connected A* over the costmap's cells. Moving into a cell costs the
  step's length (1 or sqrt 2 cells) times ``1 + penalty`` of the cell; lethal cells
  (penalty inf) are never entered, and a diagonal step needs both cells beside it
  passable (no corner cutting). The octile distance is the heuristic (admissible:
  every step costs at least its length), so the path is cost-optimal.
* :func:`plan_path`: start and goal positions in metres to a smooth :class:`Path`: A*
  from the start's cell (or the nearest passable cell when the robot stands in a
  lethal one) to the goal's, then shortcuts that keep clearance (a straight segment
  replaces a run of the path when every point of it keeps at least the smaller of
  ``wanted_clearance`` and the least clearance of the run it replaces), resampling
  at ``spacing`` and a few rounds of Nav2's simple smoother, each point moved only
  where it keeps that clearance less ``smoothing_allowance`` (rounding a corner
  brings the path nearer to what it bends around), never less than the inscribed
  radius or than the point had.
* :class:`Path`: points with arc length, heading and curvature.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from sessgan_controllers.costmap import Costmap
from sessgan_controllers.errors import PlanningError

SQRT2 = math.sqrt(2.0)

Cell = tuple[int, int]


@dataclass(frozen=True)
class Path:
    """A path in the map frame, points ``spacing`` metres apart (the last may be closer)."""

    points: np.ndarray
    """N x 2 positions in m, the first at the start, the last at the goal."""
    arc_length: np.ndarray
    """Distance in m along the path from the first point to each point."""
    curvature: np.ndarray
    """Signed curvature in 1/m at each point (positive: turning left)."""

    @classmethod
    def from_points(cls, points: np.ndarray, curvature_window: float = 0.0) -> Path:
        """A path through ``points``; curvature from the heading change over about
        ``curvature_window`` metres (0: neighbouring points)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        steps = np.hypot(*np.diff(points, axis=0).T) if len(points) > 1 else np.zeros(0)
        arc = np.concatenate(([0.0], np.cumsum(steps)))
        return cls(points, arc, _curvature(points, arc, curvature_window))

    @property
    def length(self) -> float:
        return float(self.arc_length[-1])

    def __len__(self) -> int:
        return len(self.points)

    def heading(self, index: int) -> float:
        """Direction of travel in rad at point ``index`` (of the last step at the end)."""
        points = self.points
        if len(points) < 2:
            return 0.0
        index = min(max(index, 0), len(points) - 2)
        dx, dy = points[index + 1] - points[index]
        return math.atan2(dy, dx)

    def point_at(self, distance: float) -> np.ndarray:
        """The point ``distance`` metres along the path (clamped to its ends)."""
        arc = self.arc_length
        if distance <= 0.0 or len(arc) == 1:
            return self.points[0].copy()
        if distance >= arc[-1]:
            return self.points[-1].copy()
        index = int(np.searchsorted(arc, distance, side='right'))
        span = arc[index] - arc[index - 1]
        share = (distance - arc[index - 1]) / span if span > 0 else 0.0
        return self.points[index - 1] + share * (self.points[index] - self.points[index - 1])


def _curvature(points: np.ndarray, arc: np.ndarray, window: float) -> np.ndarray:
    """Heading change over about ``window`` metres of arc around each point, per metre.

    Headings are those of the steps between points, each taken at its step's middle (exact
    for a polyline through points of a circle)."""
    count = len(points)
    if count < 3:
        return np.zeros(count)
    steps = np.diff(points, axis=0)
    headings = np.unwrap(np.arctan2(steps[:, 1], steps[:, 0]))
    middles = 0.5 * (arc[:-1] + arc[1:])
    spacing = max(float(arc[-1]) / (count - 1), 1e-9)
    half = max(1, int(round(0.5 * window / spacing)))
    index = np.arange(count)
    first = np.clip(index - half, 0, count - 2)
    last = np.clip(index + half - 1, 0, count - 2)
    last = np.maximum(last, np.minimum(first + 1, count - 2))
    first = np.minimum(first, np.maximum(last - 1, 0))
    span = middles[last] - middles[first]
    turn = headings[last] - headings[first]
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(span > 1e-9, turn / span, 0.0)


# ------------------------------------------------------------------------------------------
# A*


def astar(penalty: np.ndarray, start: Cell, goal: Cell) -> list[Cell] | None:
    """Cheapest 8-connected path of cells from ``start`` to ``goal`` (both included).

    ``penalty`` is the extra cost per unit length of each cell (inf: impassable); see the
    module docstring. None when the goal cannot be reached; [start] when start is the goal.
    Raises ValueError when an end lies outside the grid or on an impassable cell.
    """
    cost = np.asarray(penalty, dtype=float)
    if cost.ndim != 2:
        raise ValueError(f'penalty must be a 2-D array, got shape {cost.shape}')
    height, width = cost.shape
    for name, (row, col) in (('start', start), ('goal', goal)):
        if not (0 <= row < height and 0 <= col < width):
            raise ValueError(f'{name} cell {(row, col)} lies outside the {width}x{height} grid')
        if not math.isfinite(cost[row, col]):
            raise ValueError(f'{name} cell {(row, col)} is impassable')
    if tuple(start) == tuple(goal):
        return [(int(start[0]), int(start[1]))]
    stride = width + 2
    padded = np.pad(cost, 1, mode='constant', constant_values=np.inf)
    step_cost = (1.0 + padded).ravel().tolist()  # inf stays inf
    passable = np.isfinite(padded).ravel().tolist()
    size = len(step_cost)
    start_index = (start[0] + 1) * stride + start[1] + 1
    goal_index = (goal[0] + 1) * stride + goal[1] + 1
    goal_row, goal_col = goal[0] + 1, goal[1] + 1
    # (offset, length, side offsets that must be passable for a diagonal)
    moves = [(1, 1.0, 0, 0), (-1, 1.0, 0, 0), (stride, 1.0, 0, 0), (-stride, 1.0, 0, 0),
             (stride + 1, SQRT2, stride, 1), (stride - 1, SQRT2, stride, -1),
             (-stride + 1, SQRT2, -stride, 1), (-stride - 1, SQRT2, -stride, -1)]
    best = [math.inf] * size
    parent = [-1] * size
    closed = bytearray(size)
    best[start_index] = 0.0
    diagonal_saving = SQRT2 - 2.0
    heap = [(0.0, start_index)]
    push, pop = heapq.heappush, heapq.heappop
    while heap:
        _, current = pop(heap)
        if closed[current]:
            continue
        if current == goal_index:
            break
        closed[current] = 1
        cost_here = best[current]
        for offset, length, side_a, side_b in moves:
            neighbour = current + offset
            if closed[neighbour] or not passable[neighbour]:
                continue
            if side_a and not (passable[current + side_a] and passable[current + side_b]):
                continue
            candidate = cost_here + length * step_cost[neighbour]
            if candidate < best[neighbour]:
                best[neighbour] = candidate
                parent[neighbour] = current
                row, col = divmod(neighbour, stride)
                d_row, d_col = abs(row - goal_row), abs(col - goal_col)
                # Octile distance: diagonal steps first, then straight ones.
                heuristic = d_row + d_col + diagonal_saving * min(d_row, d_col)
                push(heap, (candidate + heuristic, neighbour))
    if parent[goal_index] < 0:
        return None
    path = [goal_index]
    while path[-1] != start_index:
        path.append(parent[path[-1]])
    path.reverse()
    return [((index // stride) - 1, (index % stride) - 1) for index in path]


# ------------------------------------------------------------------------------------------
# From positions to a smooth path


@dataclass(frozen=True)
class PlannerConfig:
    """How :func:`plan_path` turns an A* path into a smooth one. Lengths in metres."""

    spacing: float
    """Distance between the points of the final path."""
    wanted_clearance: float
    """Shortcuts and smoothing never bring the path closer than this to an obstacle, nor
    closer than the A* path already was."""
    smoothing_allowance: float = 0.0
    """Clearance smoothing may give up below the shortcuts' (never below ``inscribed``)."""
    inscribed: float = 0.0
    """Clearance (m) smoothing never goes below, unless a point had less already."""
    smoothing_iterations: int = 60
    smooth_weight: float = 0.3
    data_weight: float = 0.15
    curvature_window: float = 0.3
    """Curvature is the heading change over about this arc length."""
    escape_radius: float = 1.0
    """How far from a lethal start or goal cell the nearest passable cell is looked for."""


def nearest_passable_cell(costmap: Costmap, x: float, y: float, radius: float) -> Cell | None:
    """The passable cell nearest to (x, y) within ``radius`` metres, or None."""
    row, col = costmap.cell_of(x, y)
    reach = int(math.ceil(radius / costmap.resolution))
    height, width = costmap.shape
    top, bottom = max(0, row - reach), min(height, row + reach + 1)
    left, right = max(0, col - reach), min(width, col + reach + 1)
    if top >= bottom or left >= right:
        return None
    window = np.isfinite(costmap.penalty[top:bottom, left:right])
    if not window.any():
        return None
    rows, cols = np.nonzero(window)
    rows, cols = rows + top, cols + left
    centres = costmap.centres(rows, cols)
    distance = np.hypot(centres[:, 0] - x, centres[:, 1] - y)
    best = int(np.argmin(distance))
    if distance[best] > radius:
        return None
    return int(rows[best]), int(cols[best])


def plan_path(costmap: Costmap, start: tuple[float, float], goal: tuple[float, float],
              config: PlannerConfig) -> Path:
    """A smooth path from ``start`` to ``goal`` (map-frame metres); PlanningError if none."""
    start_cell = nearest_passable_cell(costmap, start[0], start[1], config.escape_radius)
    if start_cell is None:
        raise PlanningError(f'no passable cell within {config.escape_radius:.2f} m of the robot '
                            f'at ({start[0]:.2f}, {start[1]:.2f})')
    goal_cell = nearest_passable_cell(costmap, goal[0], goal[1], config.escape_radius)
    if goal_cell is None:
        raise PlanningError(f'no passable cell within {config.escape_radius:.2f} m of the goal '
                            f'at ({goal[0]:.2f}, {goal[1]:.2f})')
    cells = astar(costmap.penalty, start_cell, goal_cell)
    if cells is None:
        raise PlanningError(f'no path from ({start[0]:.2f}, {start[1]:.2f}) to the goal at '
                            f'({goal[0]:.2f}, {goal[1]:.2f})')
    rows = np.array([cell[0] for cell in cells])
    cols = np.array([cell[1] for cell in cells])
    points = costmap.centres(rows, cols)
    points = np.vstack((np.asarray(start, dtype=float), points, np.asarray(goal, dtype=float)))
    points = _drop_repeats(points)
    points = shortcut(costmap, points, config.wanted_clearance, config.spacing)
    points = resample(points, config.spacing)
    points = smooth(costmap, points, config)
    return Path.from_points(points, config.curvature_window)


def _drop_repeats(points: np.ndarray) -> np.ndarray:
    if len(points) < 2:
        return points
    steps = np.hypot(*np.diff(points, axis=0).T)
    keep = np.concatenate(([True], steps > 1e-9))
    return points[keep]


def _segment_clearance(costmap: Costmap, a: np.ndarray, b: np.ndarray, step: float) -> float:
    length = float(np.hypot(*(b - a)))
    count = max(2, int(math.ceil(length / step)) + 1)
    share = np.linspace(0.0, 1.0, count)[:, None]
    return float(costmap.clearance_at(a + share * (b - a)).min())


def shortcut(costmap: Costmap, points: np.ndarray, wanted_clearance: float,
             step: float) -> np.ndarray:
    """Greedy shortcuts: from each kept point, the farthest later point reachable in a straight
    line that keeps min(``wanted_clearance``, least clearance of the skipped run)."""
    if len(points) < 3:
        return points
    clearance = costmap.clearance_at(points)
    check_step = min(step, 0.5 * costmap.resolution)
    kept = [0]
    anchor = 0
    last = len(points) - 1
    while anchor < last:
        reach = anchor + 1
        run_min = min(clearance[anchor], clearance[anchor + 1])
        candidate = anchor + 2
        while candidate <= last:
            run_min = min(run_min, clearance[candidate])
            needed = min(wanted_clearance, run_min) - 1e-6
            if _segment_clearance(costmap, points[anchor], points[candidate],
                                  check_step) < needed:
                break
            reach = candidate
            candidate += 1
        kept.append(reach)
        anchor = reach
    return points[kept]


def resample(points: np.ndarray, spacing: float) -> np.ndarray:
    """Points along the polyline every ``spacing`` metres, both ends kept."""
    if len(points) < 2:
        return points.copy()
    steps = np.hypot(*np.diff(points, axis=0).T)
    arc = np.concatenate(([0.0], np.cumsum(steps)))
    total = float(arc[-1])
    if total <= 0.0:
        return points[:1].copy()
    count = max(2, int(math.ceil(total / spacing)) + 1)
    samples = np.linspace(0.0, total, count)
    return np.stack((np.interp(samples, arc, points[:, 0]),
                     np.interp(samples, arc, points[:, 1])), axis=1)


def smooth(costmap: Costmap, points: np.ndarray, config: PlannerConfig) -> np.ndarray:
    """Nav2's simple smoother (gradient steps towards the neighbours' midpoint, held to the
    original path by ``data_weight``); ends fixed; a point moves only where it keeps the
    clearance the module docstring states."""
    if len(points) < 3 or config.smoothing_iterations <= 0:
        return points
    original = points.copy()
    smoothed = points.copy()
    before = costmap.clearance_at(points)
    floor = np.maximum(config.inscribed, np.minimum(before, config.wanted_clearance)
                       - config.smoothing_allowance)
    floor = np.minimum(before, floor) - 1e-6
    for _ in range(config.smoothing_iterations):
        inner = smoothed[1:-1]
        moved = (inner + config.data_weight * (original[1:-1] - inner)
                 + config.smooth_weight * (smoothed[:-2] + smoothed[2:] - 2.0 * inner))
        allowed = costmap.clearance_at(moved) >= floor[1:-1]
        smoothed[1:-1] = np.where(allowed[:, None], moved, inner)
    return smoothed
