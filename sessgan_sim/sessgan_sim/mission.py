"""Following a mission's waypoints the way Nav2's waypoint follower does, without ROS.

An episode's waypoints are the Environment's stations and then its goal (home); a plain
start -> goal episode is the mission of one leg. The robot is given one waypoint at a time.
A leg ends when the robot's centre comes within the goal tolerance of its waypoint; at a
station the robot then dwells (loading): once it has stood still (slower than
``STANDING_SPEED``) inside the tolerance for ``dwell_time`` sim seconds without a break, the
next leg starts and its waypoint goes out. Reaching the last waypoint completes the mission.

Per leg the tracker records when it started, when its waypoint was reached and when the
robot left (the dwell's end); :func:`failed_leg` says which leg an episode failed on.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from sessgan_core.environment import Pose2D
from sessgan_core.validation import require_non_negative
from sessgan_sim.errors import EpisodeError
from sessgan_sim.metrics import FAILURE_OUTCOMES, STANDING_SPEED, Outcome


class MissionEvent(enum.StrEnum):
    """What one tick did to the mission."""

    NONE = 'none'
    ARRIVED = 'arrived'
    """A station's waypoint was reached: the dwell begins."""
    NEXT_LEG = 'next_leg'
    """The dwell is over: the next leg's waypoint is the goal now."""
    COMPLETE = 'complete'
    """The last waypoint was reached."""


@dataclass
class LegRecord:
    """One leg of a mission, as far as it got. Times in sim seconds since the episode's start."""

    goal: Pose2D
    started: float
    reached: float | None = None
    departed: float | None = None
    """When the dwell ended and the next leg started (None for the last leg)."""

    @property
    def time(self) -> float | None:
        """Sim seconds from the leg's start to reaching its waypoint (None: not reached)."""
        return None if self.reached is None else self.reached - self.started


class MissionTracker:
    """The waypoint in force and the record of every leg started so far."""

    def __init__(self, waypoints: Sequence[Pose2D], dwell_time: float, tolerance: float,
                 start_time: float = 0.0) -> None:
        if not waypoints:
            raise EpisodeError('a mission needs at least one waypoint (the goal)')
        require_non_negative('dwell time', dwell_time, EpisodeError, ' s')
        self.waypoints = tuple(waypoints)
        self.dwell_time = float(dwell_time)
        self.tolerance = float(tolerance)
        self.records = [LegRecord(self.waypoints[0], start_time)]
        self.dwelling = False
        self.complete = False
        self._still = 0.0
        """Sim seconds the robot has stood still at the station without a break."""

    @property
    def legs(self) -> int:
        return len(self.waypoints)

    @property
    def leg(self) -> int:
        """0-based index of the leg in progress (the last one once complete)."""
        return len(self.records) - 1

    @property
    def goal(self) -> Pose2D:
        """The waypoint in force: the current leg's."""
        return self.records[-1].goal

    @property
    def legs_completed(self) -> int:
        """Legs done: a station's once the robot has dwelt there, the last once reached (a
        robot that reached a station and failed before its dwell ended failed that leg)."""
        return (sum(1 for record in self.records if record.departed is not None)
                + int(self.complete))

    @property
    def leg_times(self) -> tuple[float, ...]:
        """Sim seconds from each leg's start to its waypoint, of every leg whose waypoint was
        reached, in order."""
        return tuple(record.time for record in self.records if record.time is not None)

    def update(self, now: float, reached: bool, distance: float, speed: float,
               period: float) -> MissionEvent:
        """Close a control tick of ``period`` s ending at ``now``: ``reached`` when the robot
        came within the tolerance of the current waypoint during it, ``distance`` (m) to the
        waypoint and ``speed`` (m/s) at its end."""
        if self.complete:
            return MissionEvent.NONE
        record = self.records[-1]
        if not self.dwelling:
            if not reached:
                return MissionEvent.NONE
            record.reached = now
            if self.leg == self.legs - 1:
                self.complete = True
                return MissionEvent.COMPLETE
            if self.dwell_time <= 0:
                self._next_leg(now)
                return MissionEvent.NEXT_LEG
            self.dwelling, self._still = True, 0.0
            return MissionEvent.ARRIVED
        standing = distance <= self.tolerance and speed <= STANDING_SPEED
        self._still = self._still + period if standing else 0.0
        if self._still >= self.dwell_time - 1e-9:
            self._next_leg(now)
            return MissionEvent.NEXT_LEG
        return MissionEvent.NONE

    def leg_at(self, time: float) -> int:
        """The leg in progress at sim ``time`` s (a dwell belongs to the leg it ends)."""
        for index in range(len(self.records) - 1, 0, -1):
            if time >= self.records[index].started:
                return index
        return 0

    def describe_leg(self, leg: int) -> str:
        """'leg 2 of 3 (to station 2)' or 'leg 3 of 3 (home)'."""
        target = 'home' if leg == self.legs - 1 else f'to station {leg + 1}'
        return f'leg {leg + 1} of {self.legs} ({target})'

    def _next_leg(self, now: float) -> None:
        self.records[-1].departed = now
        self.records.append(LegRecord(self.waypoints[len(self.records)], now))
        self.dwelling, self._still = False, 0.0


def failed_leg(tracker: MissionTracker, outcome: Outcome | None,
               fault_contact_times: Iterable[float]) -> int:
    """The 0-based leg an episode failed on: that of its first fault collision, else the leg
    in progress when it ended without reaching its last waypoint (timeout, stuck, collision
    limit, a silent controller); -1 when no leg failed (also while it runs, and for
    episodes without a test result)."""
    times = sorted(fault_contact_times)
    if times:
        return tracker.leg_at(times[0])
    if outcome is not None and (outcome in FAILURE_OUTCOMES or outcome in (
            Outcome.COLLISION_LIMIT, Outcome.CONTROLLER_UNRESPONSIVE)):
        return tracker.leg
    return -1
