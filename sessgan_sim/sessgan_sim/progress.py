"""Progress toward the goal and the stuck rule of one robot under test.

An episode ends as stuck when, for ``stuck_timeout`` sim seconds, the robot has neither come
closer to its goal than ever before on this leg (measured on a ProgressField of the certificate
grid) nor reached new ground (a NEW_GROUND_CELL square it has not been on during this leg),
unless it waits for something that blocks its way (the episode says what) or dwells at a
station. New ground counts because a planner may choose a way of its own: a longer one that
costs less, one around an agent, a gap the certificate does not use. A robot driving that way
is not stuck; one that stands, turns on the spot or goes to and fro over the same ground is.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from sessgan_core.environment import Pose2D
from sessgan_core.grid_search import descend, distance_field
from sessgan_core.route_certificate import CertificateGrid


class ProgressField(NamedTuple):
    """Distance to the goal in certificate-grid steps that the stuck rule measures progress on.

    Exact inside the certified route's space (clearance >= radius + route margin: where a
    stack with an inflation margin drives, so a detour the route needs counts as progress),
    extended a few steps into the band around it where a robot cutting a corner or touching
    a wall may be, but never through a gap the certificate does not use; inf elsewhere. In a
    map without a certified route it is the distance through any space the footprint fits.
    """

    grid: CertificateGrid
    steps: np.ndarray
    route: list[tuple[int, int]]
    """The certified route's cells from start to goal ([] without one)."""

    def distance(self, x: float, y: float) -> float:
        """Distance (m) from (``x``, ``y``) to the goal along the field; inf (never progress)
        where the field does not reach."""
        row, col = self.grid.cell_of(x, y)
        steps = self.steps
        if 0 <= row < steps.shape[0] and 0 <= col < steps.shape[1]:
            return float(steps[row, col]) * self.grid.cell_size
        return math.inf


def progress_field(grid: CertificateGrid, leg_start: Pose2D, leg_goal: Pose2D, feasible: bool,
                   footprint_radius: float, route_need: float) -> ProgressField:
    """The ProgressField of one leg (a plain episode's one leg: start to goal) for a robot of
    ``footprint_radius`` (m); ``route_need``: the clearance (m) the certified route keeps."""
    goal = grid.cell_of(leg_goal.x, leg_goal.y)
    start = grid.cell_of(leg_start.x, leg_start.y)
    clearance = grid.clearance
    # Diagonal steps: a diagonal gap the robot passes must not look like a detour.
    steps = distance_field(clearance >= route_need - 1e-9, goal, diagonal=True)
    route = descend(steps, start) if feasible else []
    if not route:
        return ProgressField(grid, distance_field(
            clearance >= footprint_radius * 0.75, goal, diagonal=True), [])
    band = (clearance > 0.0) & ~np.isfinite(steps)
    for _ in range(int(math.ceil(route_need / grid.cell_size)) + 1):
        padded = np.pad(steps, 1, constant_values=np.inf)
        nearest = np.minimum.reduce([padded[:-2, 1:-1], padded[2:, 1:-1],
                                     padded[1:-1, :-2], padded[1:-1, 2:]]) + 1.0
        steps = np.where(band, np.minimum(steps, nearest), steps)
    return ProgressField(grid, steps, route)


NEW_GROUND_CELL = 0.5
"""m, the side of the squares of new ground: the movement Nav2's progress checker asks for
(``required_movement_radius``, 0.5 m), which, unlike ours, a robot going to and fro meets."""


class ProgressMonitor:
    """The stuck rule of one robot: the best distance to the current leg's goal so far, the
    ground covered on this leg, and when the robot last got closer or onto new ground.
    ``stuck_timeout`` <= 0 disables the rule."""

    def __init__(self, legs: Sequence[ProgressField], stuck_timeout: float) -> None:
        self.legs = list(legs)
        """Every leg's ProgressField, in order (a plain episode's one)."""
        self.field = self.legs[0]
        """The current leg's."""
        self.stuck_timeout = stuck_timeout
        self.best = math.inf
        """m, the least distance to the current leg's goal so far."""
        self.covered: set[tuple[int, int]] = set()
        """The NEW_GROUND_CELL squares the robot has been on during this leg."""
        self.last_progress_time = 0.0

    def start_leg(self, leg: int, x: float, y: float) -> None:
        """Measure progress on leg ``leg`` from the robot at (``x``, ``y``) m on."""
        self.field = self.legs[leg]
        self.best = self.field.distance(x, y)
        self.covered = {self._square(x, y)}

    @staticmethod
    def _square(x: float, y: float) -> tuple[int, int]:
        return math.floor(x / NEW_GROUND_CELL), math.floor(y / NEW_GROUND_CELL)

    def hold(self, now: float) -> None:
        """Count sim time ``now`` as progress (arriving, setting off, dwelling)."""
        self.last_progress_time = now

    def stuck(self, now: float, x: float, y: float, waiting: Callable[[], bool]) -> bool:
        """Whether the robot at (``x``, ``y``) m is stuck at sim time ``now``: neither a new
        least distance nor new ground for stuck_timeout seconds. ``waiting()`` (asked only
        without progress) says whether something blocks its way; waiting is not being stuck
        (the time limit still bounds the wait)."""
        if self.stuck_timeout <= 0:
            return False
        distance = self.field.distance(x, y)
        square = self._square(x, y)
        if distance < self.best or square not in self.covered:
            self.best = min(self.best, distance)
            self.covered.add(square)
            self.last_progress_time = now
            return False
        if waiting():
            self.last_progress_time = now
            return False
        return now - self.last_progress_time >= self.stuck_timeout - 1e-9
