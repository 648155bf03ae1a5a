"""Episode outcomes and metrics, exactly as ARCHITECTURE.md defines them.

* collisions: contact *events*, i.e. no-contact -> contact transitions between the
  robot and walls, out-of-bounds barriers, low obstacles (ground robots) or agents,
  checked after every physics step.
* proximity_time: sim seconds with clearance (robot body to the nearest obstacle or
  agent) below the proximity distance while not in contact, sampled every control
  tick (each tick counts its whole period).
* simulation_time: sim seconds until the episode ended (or so far).
* risk_score = collisions * proximity_time / simulation_time (0 when no time passed).
"""

from __future__ import annotations

import enum
import math
from dataclasses import asdict, dataclass
from typing import Any


class Outcome(enum.StrEnum):
    """Why an episode ended."""

    GOAL_REACHED = 'goal_reached'
    COLLISION_LIMIT = 'collision_limit'
    TIMEOUT = 'timeout'
    STUCK = 'stuck'
    CONTROLLER_UNRESPONSIVE = 'controller_unresponsive'
    INVALID_ENVIRONMENT = 'invalid_environment'
    CANCELLED = 'cancelled'
    """Cut off by the evaluate client or by the simulator's shutdown: no test result."""


def risk_score(collisions: int, proximity_time: float, simulation_time: float) -> float:
    """The paper's risk: collisions x (proximity time / simulation time); 0 with no time."""
    if simulation_time <= 0:
        return 0.0
    return collisions * proximity_time / simulation_time


@dataclass(frozen=True)
class EpisodeMetrics:
    """The result of one episode (or of its part so far, with outcome None)."""

    collisions: int
    proximity_time: float
    """s"""
    simulation_time: float
    """s"""
    risk_score: float
    feasible: bool
    """Copied from the Environment: only failures in feasible maps are controller faults."""
    min_clearance: float
    """m, smallest clearance sampled at control ticks (0 when it touched something); capped
    at the clearance range when nothing ever came that close."""
    distance_travelled: float
    """m, path length of the robot's centre."""
    final_distance_to_goal: float
    """m, straight-line distance from the robot's centre to the goal at the end."""
    ticks: int
    """Control ticks simulated."""
    outcome: Outcome | None
    """None while the episode is running."""
    invalid_commands: int = 0
    """Commands with a NaN or infinite component, replaced by a stop."""
    detail: str = ''
    """Human-readable explanation of the outcome and of anything unusual."""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (outcome as its string value; infinities as None)."""
        data = asdict(self)
        data['outcome'] = self.outcome.value if self.outcome is not None else None
        for key, value in data.items():
            if isinstance(value, float) and not math.isfinite(value):
                data[key] = None
        return data


class MetricsRecorder:
    """Accumulates an episode's metrics step by step."""

    def __init__(self, clearance_range: float) -> None:
        self.collisions = 0
        self.proximity_time = 0.0
        self.min_clearance = clearance_range
        self.distance_travelled = 0.0
        self.ticks = 0
        self.invalid_commands = 0
        self._touching = False

    def record_contact(self, touching: bool) -> bool:
        """Record the contact state after a physics step; True when a new event began."""
        started = touching and not self._touching
        if started:
            self.collisions += 1
        self._touching = touching
        return started

    def record_motion(self, distance: float) -> None:
        """Add ``distance`` metres travelled by the robot's centre."""
        self.distance_travelled += distance

    def record_tick(self, period: float, clearance: float, touching: bool,
                    proximity_distance: float) -> None:
        """Close a control tick of ``period`` seconds with its clearance sample."""
        self.ticks += 1
        if touching:
            clearance = 0.0
        elif clearance < proximity_distance:
            self.proximity_time += period
        self.min_clearance = min(self.min_clearance, clearance)

    def snapshot(self, simulation_time: float, feasible: bool, distance_to_goal: float,
                 outcome: Outcome | None, detail: str) -> EpisodeMetrics:
        """The metrics so far."""
        return EpisodeMetrics(
            collisions=self.collisions,
            proximity_time=self.proximity_time,
            simulation_time=simulation_time,
            risk_score=risk_score(self.collisions, self.proximity_time, simulation_time),
            feasible=feasible,
            min_clearance=self.min_clearance,
            distance_travelled=self.distance_travelled,
            final_distance_to_goal=distance_to_goal,
            ticks=self.ticks,
            outcome=outcome,
            invalid_commands=self.invalid_commands,
            detail=detail,
        )
