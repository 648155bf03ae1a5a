"""A Nav2-style costmap of a known map for a circular robot: inflation and a scan overlay.

The map (:class:`~sessgan_controllers.controller_interface.MapData`) is refined to the planning
resolution (each map cell split into ``factor x factor`` cells, so thin walls stay
exact) and every cell gets its **clearance**: the distance in metres from the
cell's centre to the nearest blocked cell *square* (walls, out of bounds, cells
whose value the robot may not cross, unknown cells, and the grid's outside),
capped at :attr:`CostmapConfig.max_distance`. From the clearance ``d``, a cell's
**penalty** (the extra cost per metre travelled through it, as Nav2's inflation
layer grades cells):

* ``d < robot_radius``: lethal (``inf``): the footprint would touch an obstacle;
* ``robot_radius <= d < inscribed``: ``inscribed_penalty``, where ``inscribed =
  robot_radius + safety_margin``; passable but avoided whenever any other way exists,
  so a robot that starts (or is pushed) that close to a wall can still leave;
* ``inscribed <= d < max_distance``: ``cost_weight * exp(-cost_scaling_factor * (d -
  inscribed))``, Nav2's exponential decay: paths keep off walls where there is room;
* farther: 0.

The **scan overlay** marks what the scan sees that the map does not explain (another
robot, a dummy agent): a return farther than ``explained_distance`` from any mapped
obstacle marks its cell. Marks are cleared the way Nav2's obstacle layer clears
them, by ray tracing: a beam that reaches past a marked cell shows the cell empty.
A mark that no beam clears (hidden behind something) expires after
``mark_lifetime`` scans. Marks count as blocked cells in the clearance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from sessgan_controllers.controller_interface import MapData, RobotState, ScanData

FREE = 0
LOW_OBSTACLE = 50
BLOCKED = 100
UNKNOWN = -1


@dataclass(frozen=True)
class CostmapConfig:
    """How a map becomes costs. Lengths in metres."""

    robot_radius: float
    """Radius of the circular footprint."""
    safety_margin: float
    """Clearance beyond the radius below which cells cost ``inscribed_penalty``."""
    inflation_radius: float
    """Width of the zone beyond ``robot_radius + safety_margin`` over which the cost decays."""
    cost_scaling_factor: float
    """Exponential decay rate of the cost in 1/m."""
    cost_weight: float
    """Penalty at the inner edge of the decaying zone (extra cost per metre, 1 = double)."""
    inscribed_penalty: float
    """Penalty of cells closer than ``robot_radius + safety_margin`` to an obstacle."""
    resolution: float
    """Wanted planning resolution in m; the map's cells are split into whole sub-cells."""
    passable_values: tuple[int, ...] = (FREE,)
    """Occupancy values the robot may cross (a flyer also crosses low obstacles, 50)."""
    mark_range: float = 3.0
    """Returns farther than this from the robot are not marked."""
    mark_lifetime: int = 20
    """Scans a mark survives without being cleared by a beam."""

    @property
    def inscribed_radius(self) -> float:
        return self.robot_radius + self.safety_margin

    @property
    def max_distance(self) -> float:
        """Clearances are exact up to here and capped at it."""
        return self.robot_radius + self.safety_margin + self.inflation_radius


@lru_cache(maxsize=16)
def _gap_groups(reach: int, resolution: float, max_distance: float
                ) -> tuple[tuple[float, tuple[tuple[int, int], ...]], ...]:
    """Cell offsets within ``reach`` grouped by the distance (m) from a cell's centre to the
    nearest point of the offset cell's square, nearest first, only those below the cap."""
    groups: dict[float, list[tuple[int, int]]] = {}
    for d_row in range(-reach, reach + 1):
        for d_col in range(-reach, reach + 1):
            if d_row == 0 and d_col == 0:
                continue
            gap = math.hypot(max(abs(d_row) - 0.5, 0.0), max(abs(d_col) - 0.5, 0.0)) * resolution
            if gap < max_distance:
                groups.setdefault(round(gap, 12), []).append((d_row, d_col))
    return tuple((gap, tuple(offsets)) for gap, offsets in sorted(groups.items()))


@lru_cache(maxsize=16)
def _gap_kernel(reach: int, resolution: float) -> np.ndarray:
    """(2 reach + 1)^2 distances from the centre cell's centre to each cell's square."""
    offsets = np.abs(np.arange(-reach, reach + 1, dtype=float))
    gaps = np.maximum(offsets - 0.5, 0.0)
    kernel = np.hypot(gaps[:, None], gaps[None, :]) * resolution
    kernel[reach, reach] = 0.0
    kernel.flags.writeable = False
    return kernel


def clearance_field(blocked: np.ndarray, resolution: float, max_distance: float) -> np.ndarray:
    """Distance in m from each cell's centre to the nearest blocked cell's square or the grid's
    outside, capped at ``max_distance``; 0 on blocked cells."""
    mask = np.asarray(blocked, dtype=bool)
    reach = int(math.ceil(max_distance / resolution + 0.5))
    height, width = mask.shape
    padded = np.pad(mask, reach, mode='constant', constant_values=True)
    distance = np.where(mask, 0.0, max_distance)
    for gap, offsets in _gap_groups(reach, float(resolution), float(max_distance)):
        near = np.zeros_like(mask)
        for d_row, d_col in offsets:
            near |= padded[reach + d_row:reach + d_row + height,
                           reach + d_col:reach + d_col + width]
        np.minimum(distance, np.where(near, gap, max_distance), out=distance)
    return distance


class Costmap:
    """Clearance and penalty of every planning cell; see the module docstring."""

    def __init__(self, grid: MapData, config: CostmapConfig) -> None:
        grid.validate()
        self.config = config
        occupancy = np.asarray(grid.occupancy)
        self.map_shape = occupancy.shape
        self.factor = max(1, int(round(grid.resolution / config.resolution)))
        self.resolution = grid.resolution / self.factor
        self.origin = (float(grid.origin[0]), float(grid.origin[1]))
        blocked = ~np.isin(occupancy, config.passable_values)
        self.blocked = np.repeat(np.repeat(blocked, self.factor, axis=0), self.factor, axis=1)
        self.shape = self.blocked.shape
        self.static_clearance = clearance_field(self.blocked, self.resolution,
                                                config.max_distance)
        self._reach = int(math.ceil(config.max_distance / self.resolution + 0.5))
        self.marks: dict[tuple[int, int], int] = {}
        """Marked cell -> scans since it was last seen."""
        self._clearance: np.ndarray | None = None
        self._penalty: np.ndarray | None = None

    # ----------------------------------------------------------------------------------------
    # Geometry

    def cells_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the cells holding map-frame ``points`` (N x 2, metres)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        cols = np.floor((points[:, 0] - self.origin[0]) / self.resolution).astype(int)
        rows = np.floor((points[:, 1] - self.origin[1]) / self.resolution).astype(int)
        return rows, cols

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        return (int(math.floor((y - self.origin[1]) / self.resolution)),
                int(math.floor((x - self.origin[0]) / self.resolution)))

    def centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Map-frame centres (N x 2, metres) of cells."""
        return np.stack((self.origin[0] + (np.asarray(cols) + 0.5) * self.resolution,
                         self.origin[1] + (np.asarray(rows) + 0.5) * self.resolution), axis=1)

    def inside(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return (rows >= 0) & (rows < self.shape[0]) & (cols >= 0) & (cols < self.shape[1])

    # ----------------------------------------------------------------------------------------
    # Clearance and penalty

    @property
    def clearance(self) -> np.ndarray:
        """Clearance (m) of every cell, map and scan marks together."""
        if self._clearance is None:
            clearance = self.static_clearance.copy()
            if self.marks:
                self._add_marks(clearance)
            self._clearance = clearance
        return self._clearance

    @property
    def penalty(self) -> np.ndarray:
        """Extra cost per metre of every cell (inf: lethal)."""
        if self._penalty is None:
            self._penalty = self.penalty_of(self.clearance)
        return self._penalty

    def penalty_of(self, clearance: np.ndarray) -> np.ndarray:
        config = self.config
        inscribed = config.inscribed_radius
        decay = config.cost_weight * np.exp(
            -config.cost_scaling_factor * np.maximum(clearance - inscribed, 0.0))
        penalty = np.where(clearance < inscribed, config.inscribed_penalty, decay)
        penalty = np.where(clearance >= config.max_distance, 0.0, penalty)
        return np.where(clearance < config.robot_radius, np.inf, penalty)

    def _add_marks(self, clearance: np.ndarray) -> None:
        reach = self._reach
        kernel = _gap_kernel(reach, float(self.resolution))
        height, width = self.shape
        for row, col in self.marks:
            top, bottom = max(0, row - reach), min(height, row + reach + 1)
            left, right = max(0, col - reach), min(width, col + reach + 1)
            window = kernel[top - row + reach:bottom - row + reach,
                            left - col + reach:right - col + reach]
            np.minimum(clearance[top:bottom, left:right], window,
                       out=clearance[top:bottom, left:right])

    def clearance_at(self, points: np.ndarray, static: bool = False) -> np.ndarray:
        """Clearance (m) at map-frame ``points`` (N x 2), bilinear between cell centres; 0
        outside the grid."""
        field = self.static_clearance if static else self.clearance
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        u = (points[:, 0] - self.origin[0]) / self.resolution - 0.5
        v = (points[:, 1] - self.origin[1]) / self.resolution - 0.5
        height, width = self.shape
        outside = (u < -0.5) | (v < -0.5) | (u > width - 0.5) | (v > height - 0.5)
        # The calls a tick makes are many and small: ufuncs instead of np.clip's wrapper and
        # one flat take per corner instead of 2-D fancy indexing (the same values).
        u = np.minimum(np.maximum(u, 0.0), width - 1.0)
        v = np.minimum(np.maximum(v, 0.0), height - 1.0)
        col0 = np.minimum(np.floor(u).astype(int), width - 2) if width > 1 else np.zeros(
            len(u), dtype=int)
        row0 = np.minimum(np.floor(v).astype(int), height - 2) if height > 1 else np.zeros(
            len(v), dtype=int)
        col1 = np.minimum(col0 + 1, width - 1)
        row1 = np.minimum(row0 + 1, height - 1)
        fu, fv = u - col0, v - row0
        flat = field.ravel()
        top, bottom = row0 * width, row1 * width
        value = ((1 - fu) * (1 - fv) * flat.take(top + col0)
                 + fu * (1 - fv) * flat.take(top + col1)
                 + (1 - fu) * fv * flat.take(bottom + col0) + fu * fv * flat.take(bottom + col1))
        return np.where(outside, 0.0, value)

    # ----------------------------------------------------------------------------------------
    # The scan overlay

    @property
    def explained_distance(self) -> float:
        """A return this close to a mapped obstacle is the map's, not a new obstacle."""
        return 0.75 * self.resolution + 0.03

    def unexplained_points(self, scan: ScanData, state: RobotState,
                           max_range: float = math.inf) -> np.ndarray:
        """Map-frame returns (N x 2) within ``max_range`` that no mapped obstacle explains."""
        angles, ranges = scan.points()
        near = ranges <= max_range
        angles, ranges = angles[near], ranges[near]
        heading = angles + state.yaw
        points = np.stack((state.x + ranges * np.cos(heading),
                           state.y + ranges * np.sin(heading)), axis=1)
        if not len(points):
            return points
        static = self.clearance_at(points, static=True)
        rows, cols = self.cells_of(points)
        return points[(static > self.explained_distance) & self.inside(rows, cols)]

    def update_marks(self, scan: ScanData, state: RobotState) -> bool:
        """Age, clear (ray tracing) and add marks from one scan; True when the marks changed."""
        config = self.config
        changed = False
        if self.marks:
            changed = self._clear_marks(scan, state)
        points = self.unexplained_points(scan, state, config.mark_range)
        rows, cols = self.cells_of(points)
        for row, col in zip(rows.tolist(), cols.tolist(), strict=True):
            if (row, col) not in self.marks:
                changed = True
            self.marks[(row, col)] = 0
        if changed:
            self._clearance = None
            self._penalty = None
        return changed

    def _clear_marks(self, scan: ScanData, state: RobotState) -> bool:
        cells = list(self.marks)
        rows = np.array([cell[0] for cell in cells])
        cols = np.array([cell[1] for cell in cells])
        centres = self.centres(rows, cols)
        dx, dy = centres[:, 0] - state.x, centres[:, 1] - state.y
        distance = np.hypot(dx, dy)
        bearing = np.arctan2(dy, dx) - state.yaw
        count = len(scan.ranges)
        cleared = np.zeros(len(cells), dtype=bool)
        if count and scan.angle_increment != 0.0:
            index = np.round(((bearing - scan.angle_min) / scan.angle_increment)).astype(int)
            if scan.field_of_view() >= 2.0 * math.pi - 1e-6:
                index %= count
            seen = (index >= 0) & (index < count)
            ranges = np.asarray(scan.ranges, dtype=float)[np.clip(index, 0, count - 1)]
            # No return (+inf or beyond range_max) sees free space up to range_max; a reading
            # below range_min (-inf) sees nothing.
            reach = np.where(np.isnan(ranges) | (ranges < scan.range_min), -np.inf,
                             np.minimum(np.where(np.isinf(ranges), scan.range_max, ranges),
                                        scan.range_max))
            cleared = seen & (distance < scan.range_max) & (reach > distance + self.resolution)
        changed = bool(cleared.any())
        lifetime = self.config.mark_lifetime
        for cell, gone in zip(cells, cleared.tolist(), strict=True):
            age = self.marks[cell] + 1
            if gone or age > lifetime:
                del self.marks[cell]
                changed = True
            else:
                self.marks[cell] = age
        return changed

    def clear_marks(self) -> None:
        """Forget every mark."""
        if self.marks:
            self.marks.clear()
            self._clearance = None
            self._penalty = None
