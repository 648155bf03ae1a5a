"""Synthetic scans for the controller tests: ray casting on small grids and discs, no simulator."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import pytest

from sessgan_controllers.controller_interface import RobotState, ScanData

ScanFactory = Callable[..., ScanData]


def cast_scan(
    pose: RobotState,
    grid: Sequence[str] = (),
    resolution: float = 0.5,
    discs: Sequence[tuple[float, float, float]] = (),
    beams: int = 360,
    range_max: float = 8.0,
    step: float = 0.01,
) -> ScanData:
    """A 360-degree scan from ``pose``.

    ``grid`` rows are strings of '.' (free) and '#' (wall), the first string the
    top row (highest y); cell (row, col) of the bottom-up grid covers
    [col * resolution, (col + 1) * resolution) in x. ``discs`` are (x, y, radius).
    Beams that hit nothing within ``range_max`` read inf.
    """
    angles = -math.pi + (2.0 * math.pi / beams) * np.arange(beams)
    world = angles + pose.yaw
    distances = np.arange(step, range_max, step)
    xs = pose.x + np.cos(world)[:, None] * distances[None, :]
    ys = pose.y + np.sin(world)[:, None] * distances[None, :]
    hit = np.zeros(xs.shape, dtype=bool)
    if grid:
        walls = np.array([[char == '#' for char in row] for row in reversed(grid)])
        rows = np.floor(ys / resolution).astype(int)
        cols = np.floor(xs / resolution).astype(int)
        inside = (rows >= 0) & (rows < walls.shape[0]) & (cols >= 0) & (cols < walls.shape[1])
        hit |= ~inside
        hit[inside] |= walls[rows[inside], cols[inside]]
    for x, y, radius in discs:
        hit |= np.hypot(xs - x, ys - y) <= radius
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
    ranges = np.where(first >= 0, distances[np.maximum(first, 0)], np.inf)
    return ScanData(ranges=ranges, angle_min=-math.pi, angle_increment=2.0 * math.pi / beams,
                    range_min=0.05, range_max=range_max)


@pytest.fixture
def scan_factory() -> ScanFactory:
    return cast_scan
