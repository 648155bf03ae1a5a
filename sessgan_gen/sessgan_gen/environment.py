"""The Environment: one test map with a start and a goal, independent of ROS.

Grids are stored in nav_msgs/OccupancyGrid order: ``occupancy[row, col]`` with
row 0 at the map origin (lowest y) and col 0 at the lowest x. Cell (row, col)
covers x in [origin_x + col*res, origin_x + (col+1)*res), likewise for y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sessgan_gen.errors import InvalidEnvironmentError
from sessgan_gen.scenarios import OCCUPANCY_VALUES, get_scenario

MAX_CELLS_PER_SIDE = 4096
"""Grids larger than this per side are rejected as absurd (memory and build time)."""


@dataclass(frozen=True)
class Pose2D:
    """A planar pose in the map frame: metres and radians."""

    x: float
    y: float
    yaw: float = 0.0


@dataclass
class Environment:
    """One environment to evaluate; the core twin of sessgan_interfaces/Environment."""

    id: str
    scenario: str
    occupancy: np.ndarray
    """int8 array (height, width) of OccupancyGrid values 0 / 50 / 100."""
    resolution: float
    """Metres per cell."""
    start: Pose2D
    goal: Pose2D
    origin: tuple[float, float] = (0.0, 0.0)
    """Map-frame position (x, y) of the outer corner of cell (0, 0)."""
    seed: int = 0
    generation: int = -1
    member: int = -1
    feasible: bool = True
    """A valid test: start and goal joined by a certified route (sessgan_gen.route_certificate)."""
    route_length: float = 0.0
    """m, length of the certified route (0 when not a valid test or not known)."""
    route_min_clearance: float = 0.0
    """m, bottleneck clearance of the route: the tightest passage between start and goal."""
    extra: dict = field(default_factory=dict)

    @property
    def height(self) -> int:
        return int(self.occupancy.shape[0])

    @property
    def width(self) -> int:
        return int(self.occupancy.shape[1])

    def cell_center(self, row: int, col: int) -> tuple[float, float]:
        """Map-frame centre (x, y) in metres of cell (row, col)."""
        return (self.origin[0] + (col + 0.5) * self.resolution,
                self.origin[1] + (row + 0.5) * self.resolution)

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """Cell (row, col) containing map-frame point (x, y); may be outside the grid."""
        return (int(math.floor((y - self.origin[1]) / self.resolution)),
                int(math.floor((x - self.origin[0]) / self.resolution)))

    def validate(self) -> None:
        """Raise InvalidEnvironmentError naming the first thing that is wrong."""
        get_scenario(self.scenario)  # raises UnknownScenarioError
        grid = self.occupancy
        if not isinstance(grid, np.ndarray) or grid.ndim != 2:
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: occupancy must be a 2-D array, '
                f'got shape {getattr(grid, "shape", None)}')
        height, width = grid.shape
        if not (1 <= height <= MAX_CELLS_PER_SIDE and 1 <= width <= MAX_CELLS_PER_SIDE):
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: grid {width}x{height} cells is outside '
                f'1..{MAX_CELLS_PER_SIDE} per side')
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: resolution must be a positive finite number of '
                f'metres per cell, got {self.resolution}')
        if not all(math.isfinite(v) for v in self.origin):
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: origin {self.origin} is not finite')
        bad = ~np.isin(grid, OCCUPANCY_VALUES)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise InvalidEnvironmentError(
                f'environment {self.id!r}: cell ({row}, {col}) has occupancy {grid[row, col]}; '
                f'expected one of {OCCUPANCY_VALUES}')
        for label, pose in (('start', self.start), ('goal', self.goal)):
            if not all(math.isfinite(v) for v in (pose.x, pose.y, pose.yaw)):
                raise InvalidEnvironmentError(
                    f'environment {self.id!r}: {label} {pose} is not finite')
            row, col = self.cell_of(pose.x, pose.y)
            if not (0 <= row < height and 0 <= col < width):
                raise InvalidEnvironmentError(
                    f'environment {self.id!r}: {label} ({pose.x:.2f}, {pose.y:.2f}) m lies '
                    f'outside '
                    f'the {width}x{height} grid')
