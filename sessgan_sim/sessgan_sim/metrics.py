"""Episode outcomes and metrics, exactly as ARCHITECTURE.md defines them.

* collisions: contact *events* between the robot and walls, out-of-bounds barriers, low
  obstacles (ground robots) or agents, checked after every physics step. One physical contact
  counts once: an event with a partner (static obstacles together, each agent on its own)
  begins when the robot touches it after at least ``CONTACT_DEBOUNCE`` seconds out of contact
  with it, so sliding along a wall, or a contact flickering on and off, is one event.
* Each event is attributed (:class:`ContactKind`): the robot against a static obstacle, the
  robot moving into an agent (its velocity toward the agent above ``STANDING_SPEED`` at the
  event's start, and at least 1 / ``FASTER_PARTNER`` of the agent's toward it), or an agent
  driving into a robot that stood still, moved away, or closed in less than half as fast as
  the agent (or shoving it into a wall or another agent), which is not the controller's
  fault.
  ``fault_collisions`` counts the first two.
* In a fleet episode (several robots under test), a contact between two of them is the fault
  of the one that moved into the other (``robot_into_robot``, by the same approach-speed rule;
  both when both did) and not of the one standing or moving away (``robot_hit_by_robot``).
  Each robot has its own metrics; the episode's (:func:`fleet_metrics`) add them up.
* proximity_time: sim seconds with clearance (robot body to the nearest obstacle or
  agent) below the proximity distance while not in contact, sampled every control
  tick (each tick counts its whole period).
* simulation_time: sim seconds until the episode ended (or so far).
* risk_score = collisions * proximity_time / simulation_time (0 when no time passed), the
  paper's formula; fault_risk_score is the same with fault collisions.
* A *controller failure* (:func:`is_controller_failure`) happens only in a valid test
  (feasible map): a fault collision, or the goal not reached (timeout, stuck).
* Standard navigation metrics (:class:`NavigationAccumulator`, the list Nav2's benchmark
  discussions ask for): success, time to goal, path length (``distance_travelled``) and its
  ratio to the certified route's length, the mean of the per-tick clearance (its minimum is
  ``min_clearance``), integrated jerk (linear and angular) and mean speed.
"""

from __future__ import annotations

import enum
import math
from dataclasses import asdict, dataclass, field
from typing import Any, NamedTuple

CONTACT_DEBOUNCE = 0.5
"""s out of contact with a partner before touching it again counts as a new event."""

STANDING_SPEED = 0.05
"""m/s: a robot approaching an agent slower than this at contact did not drive into it."""

FASTER_PARTNER = 2.0
"""Nor did a robot whose agent closed in more than this many times as fast as it did: a
blind agent ramming a robot that was braking, creeping or passing across its way (the
robot's share of the closing speed under a third)."""


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
    HARNESS_ERROR = 'harness_error'
    """The simulator could not run the episode for a reason of its own (its parameters, the
    goal's options), not of the map: no test result."""
    OVERLOADED = 'overloaded'
    """Clocked mode: the stack's commands came too late in sim time to drive the robot (a
    busy machine; sessgan_sim.command_pace): no test result."""


FAILURE_OUTCOMES = frozenset({Outcome.TIMEOUT, Outcome.STUCK})
"""Outcomes that fail a valid test even without a collision: the goal was not reached."""

HARNESS_OUTCOMES = frozenset({Outcome.CONTROLLER_UNRESPONSIVE, Outcome.CANCELLED,
                              Outcome.HARNESS_ERROR, Outcome.OVERLOADED})
"""Outcomes that say the test harness failed, not the controller under test: a controller
that sent nothing in time (under load its process may just not have been scheduled), an
episode cut off, a simulator that could not run it, a stack that could not keep pace with
sim time in clocked mode. Such an episode is no result: campaigns,
evaluate and compare run it again (sessgan_evolver.harness) and never record it, and it is
no controller failure (no failure bag). A dead simulator or controller process is the other
harness failure; it has no outcome, the campaign sees the process die."""


def is_harness_outcome(outcome: object) -> bool:
    """True when ``outcome`` (an Outcome or its string) is one of HARNESS_OUTCOMES."""
    return str(outcome) in HARNESS_OUTCOMES


class ContactKind(enum.StrEnum):
    """Who caused a contact event."""

    STATIC = 'static'
    """The robot touched a wall, barrier or low obstacle: its fault."""
    ROBOT_INTO_AGENT = 'robot_into_agent'
    """The robot moved into an agent: its fault."""
    AGENT_INTO_ROBOT = 'agent_into_robot'
    """An agent drove into the robot standing still or moving away, or shoved it into
    something else (within CONTACT_DEBOUNCE of driving into it): not its fault."""
    ROBOT_INTO_ROBOT = 'robot_into_robot'
    """Fleets: the robot moved into another robot under test: its fault."""
    ROBOT_HIT_BY_ROBOT = 'robot_hit_by_robot'
    """Fleets: another robot under test drove into the robot standing still or moving away
    (or shoved it into something): not its fault."""


NOT_FAULT_KINDS = frozenset({ContactKind.AGENT_INTO_ROBOT, ContactKind.ROBOT_HIT_BY_ROBOT})


class ContactEvent(NamedTuple):
    """One debounced contact event."""

    time: float
    """s since the episode's start."""
    x: float
    """m, robot centre in the map frame when the event began."""
    y: float
    kind: ContactKind
    agent: int
    """Index of the agent touched; -1: no agent was touched, but a static obstacle (an
    agent_into_robot event with -1: an agent shoved the robot into it) or another robot under
    test (``other_robot``)."""
    robot: int = 0
    """Fleets: index of the robot under test the event belongs to (r0, r1, ...)."""
    other_robot: int = -1
    """Fleets: index of the other robot under test touched; -1 for none."""

    @property
    def fault(self) -> bool:
        """Whether the robot under test caused it."""
        return self.kind not in NOT_FAULT_KINDS

    def to_dict(self) -> dict[str, Any]:
        data = {'time': self.time, 'x': self.x, 'y': self.y, 'kind': self.kind.value,
                'agent': self.agent, 'fault': self.fault, 'robot': self.robot,
                'other_robot': self.other_robot}
        # Shoved into a wall: the kind names the shover and agent is -1 (the wall was touched),
        # which reads like a bug in episode.json without a word.
        if self.agent < 0 and self.other_robot < 0 and self.kind in NOT_FAULT_KINDS:
            data['note'] = ('shoved into a static obstacle by '
                            + ('an agent' if self.kind is ContactKind.AGENT_INTO_ROBOT
                               else 'another robot under test'))
        return data


def risk_score(collisions: int, proximity_time: float, simulation_time: float) -> float:
    """The paper's risk: collisions x (proximity time / simulation time); 0 with no time."""
    if simulation_time <= 0:
        return 0.0
    return collisions * proximity_time / simulation_time


@dataclass(frozen=True)
class EpisodeMetrics:
    """The result of one episode (or of its part so far, with outcome None)."""

    collisions: int
    """Contact events of every kind (the paper's count)."""
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
    """m, straight-line distance from the robot's centre to the goal at the end (a mission's
    waypoint in force)."""
    ticks: int
    """Control ticks simulated."""
    outcome: Outcome | None
    """None while the episode is running."""
    invalid_commands: int = 0
    """Commands with a NaN or infinite component, replaced by a stop."""
    detail: str = ''
    """Human-readable explanation of the outcome and of anything unusual."""
    fault_collisions: int = 0
    """Contact events the robot under test caused (static + robot_into_agent)."""
    static_collisions: int = 0
    robot_into_agent_collisions: int = 0
    agent_into_robot_collisions: int = 0
    """Agents driving into the robot: recorded, not its fault."""
    robot_into_robot_collisions: int = 0
    """Fleets: robots under test moving into another one (faults)."""
    robot_hit_by_robot_collisions: int = 0
    """Fleets: robots under test hit by another one: not their fault."""
    fault_risk_score: float = 0.0
    """fault_collisions x proximity_time / simulation_time."""
    contacts: tuple[ContactEvent, ...] = field(default=())
    """Every contact event, in order."""
    legs: int = 1
    """Legs of the episode's mission (1: a plain start -> goal episode)."""
    legs_completed: int = 0
    """Legs whose waypoint was reached (sessgan_sim.mission)."""
    leg_times: tuple[float, ...] = ()
    """s from each completed leg's start to reaching its waypoint, in order."""
    failed_leg: int = -1
    """0-based leg the episode failed on (sessgan_sim.mission.failed_leg); -1: none."""
    success: bool = False
    """The goal (a mission's last waypoint) was reached without a fault collision."""
    time_to_goal: float = math.nan
    """s until the goal was reached; NaN (None in JSON) when it was not."""
    path_length_ratio: float = math.nan
    """distance_travelled / the certified route's length (NaN without a route)."""
    mean_clearance: float = math.nan
    """m, mean of the per-tick clearance samples (0 in contact; NaN without a tick)."""
    linear_jerk: float = 0.0
    """m/s^2, integrated jerk of the body-frame linear velocity (NavigationAccumulator)."""
    angular_jerk: float = 0.0
    """rad/s^2, integrated jerk of the yaw rate."""
    mean_speed: float = 0.0
    """m/s, distance_travelled / simulation_time (0 when no time passed)."""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (outcome as its string value; infinities as None)."""
        data = asdict(self)
        data['outcome'] = self.outcome.value if self.outcome is not None else None
        data['contacts'] = [event.to_dict() for event in self.contacts]
        data['leg_times'] = list(self.leg_times)
        for key, value in data.items():
            if isinstance(value, float) and not math.isfinite(value):
                data[key] = None
        return data


def is_controller_failure(metrics: Any) -> bool:
    """A fault of the controller under test: in a valid test (feasible map) that the harness
    did not cut short (HARNESS_OUTCOMES), a contact it caused, or the goal not reached
    (timeout, stuck). Works on EpisodeMetrics and on
    anything with the same fields (messages, rows)."""
    if not metrics.feasible or is_harness_outcome(metrics.outcome):
        return False
    return metrics.fault_collisions > 0 or str(metrics.outcome) in FAILURE_OUTCOMES


class NavigationAccumulator:
    """The per-tick part of the standard navigation metrics: O(1) work and memory a tick.

    Every control tick adds the tick's clearance sample and the robot's body-frame velocity
    (vx, vy, wz) at its end. Accelerations are the velocity differences over a tick divided by
    its period, jerks the acceleration differences over a tick divided by it; integrated jerk
    is the integral of the jerk's magnitude over time, sum |j| * period = sum |delta a|: the
    total variation of the acceleration (linear: of the (ax, ay) vector, in m/s^2; angular: of
    the yaw acceleration, in rad/s^2). The robot starts at rest, so the first tick's velocity
    is measured against zero.
    """

    __slots__ = ('clearance_sum', 'samples', 'linear_jerk', 'angular_jerk', '_velocity',
                 '_acceleration')

    def __init__(self) -> None:
        self.clearance_sum = 0.0
        self.samples = 0
        self.linear_jerk = 0.0
        self.angular_jerk = 0.0
        self._velocity = (0.0, 0.0, 0.0)
        self._acceleration: tuple[float, float, float] | None = None

    def add(self, period: float, clearance: float, vx: float, vy: float, wz: float) -> None:
        """Close a tick of ``period`` s with its clearance (m; 0 in contact) and velocity."""
        self.clearance_sum += clearance
        self.samples += 1
        last = self._velocity
        acceleration = ((vx - last[0]) / period, (vy - last[1]) / period,
                        (wz - last[2]) / period)
        self._velocity = (vx, vy, wz)
        previous = self._acceleration
        self._acceleration = acceleration
        if previous is not None:
            self.linear_jerk += math.hypot(acceleration[0] - previous[0],
                                           acceleration[1] - previous[1])
            self.angular_jerk += abs(acceleration[2] - previous[2])

    @property
    def mean_clearance(self) -> float:
        return self.clearance_sum / self.samples if self.samples else math.nan


def navigation_figures(navigation: NavigationAccumulator, outcome: Outcome | None,
                       fault_collisions: int, simulation_time: float, distance: float,
                       route_length: float) -> dict[str, Any]:
    """EpisodeMetrics' standard navigation fields from an episode's accumulator and totals."""
    reached = outcome is Outcome.GOAL_REACHED
    return {
        'success': reached and fault_collisions == 0,
        'time_to_goal': simulation_time if reached else math.nan,
        'path_length_ratio': distance / route_length if route_length > 0 else math.nan,
        'mean_clearance': navigation.mean_clearance,
        'linear_jerk': navigation.linear_jerk,
        'angular_jerk': navigation.angular_jerk,
        'mean_speed': distance / simulation_time if simulation_time > 0 else 0.0,
    }


NAVIGATION_COLUMNS = ('success', 'time_to_goal', 'path_length', 'path_length_ratio',
                      'min_clearance', 'mean_clearance', 'linear_jerk', 'angular_jerk',
                      'mean_speed')
"""The standard navigation metrics as CSV columns (path_length: distance_travelled)."""


def navigation_columns(metrics: Any) -> dict[str, Any]:
    """NAVIGATION_COLUMNS of an EpisodeMetrics dict (to_dict's; a missing field is '')."""
    values = {name: metrics.get(name, '') for name in NAVIGATION_COLUMNS}
    values['path_length'] = metrics.get('distance_travelled', '')
    return values


class MetricsRecorder:
    """Accumulates an episode's metrics step by step."""

    def __init__(self, clearance_range: float, robot: int = 0) -> None:
        self.navigation = NavigationAccumulator()
        """Standard navigation metrics (added by the episode once a tick)."""
        self.robot = robot
        """Index of the robot under test whose metrics these are (fleets)."""
        self.proximity_time = 0.0
        self.min_clearance = clearance_range
        self.distance_travelled = 0.0
        self.ticks = 0
        self.invalid_commands = 0
        self.contacts: list[ContactEvent] = []
        self._last_touch: dict[tuple[str, int], float] = {}
        """Last time (s) each partner was touched: ('agent', -1) = static obstacles,
        ('agent', i) = agent i, ('robot', j) = robot under test j."""

    @property
    def collisions(self) -> int:
        return len(self.contacts)

    @property
    def fault_collisions(self) -> int:
        return sum(1 for event in self.contacts if event.fault)

    def record_contact(self, time: float, partner: int, kind: ContactKind, x: float,
                       y: float, other_robot: int = -1) -> bool:
        """Record that the robot touches ``partner`` (-1 static, else an agent index) or
        robot under test ``other_robot`` at ``time`` s; True when this begins a new event
        (see CONTACT_DEBOUNCE)."""
        key = ('robot', other_robot) if other_robot >= 0 else ('agent', partner)
        last = self._last_touch.get(key)
        self._last_touch[key] = time
        if last is not None and time - last <= CONTACT_DEBOUNCE + 1e-9:
            return False
        self.contacts.append(ContactEvent(time, x, y, kind, partner, self.robot, other_robot))
        return True

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
                 outcome: Outcome | None, detail: str,
                 route_length: float = 0.0) -> EpisodeMetrics:
        """The metrics so far (``route_length``: m, the certified route's, for the path
        length ratio; 0 without one)."""
        kinds = [event.kind for event in self.contacts]
        faults = self.fault_collisions
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
            fault_collisions=faults,
            static_collisions=kinds.count(ContactKind.STATIC),
            robot_into_agent_collisions=kinds.count(ContactKind.ROBOT_INTO_AGENT),
            agent_into_robot_collisions=kinds.count(ContactKind.AGENT_INTO_ROBOT),
            robot_into_robot_collisions=kinds.count(ContactKind.ROBOT_INTO_ROBOT),
            robot_hit_by_robot_collisions=kinds.count(ContactKind.ROBOT_HIT_BY_ROBOT),
            fault_risk_score=risk_score(faults, self.proximity_time, simulation_time),
            contacts=tuple(self.contacts),
            **navigation_figures(self.navigation, outcome, faults, simulation_time,
                                 self.distance_travelled, route_length),
        )


def fleet_metrics(robots: list[EpisodeMetrics], outcome: Outcome | None, detail: str,
                  failed_robot: int = -1) -> EpisodeMetrics:
    """The metrics of a fleet episode from its robots' (r0 first): counts, proximity time and
    distance added up, the risks computed from those sums over the episode's time (the
    longest robot's), min_clearance the smallest, final_distance_to_goal the largest, the
    contacts of every robot in time order; a leg per robot (legs_completed: the robots that
    reached their goals, failed_leg: ``failed_robot``); ``outcome`` and ``detail`` the
    fleet's."""
    simulation_time = max(robot.simulation_time for robot in robots)
    ticks = sum(robot.ticks for robot in robots)
    proximity = sum(robot.proximity_time for robot in robots)
    collisions = sum(robot.collisions for robot in robots)
    faults = sum(robot.fault_collisions for robot in robots)
    summed = {name: sum(getattr(robot, name) for robot in robots) for name in (
        'static_collisions', 'robot_into_agent_collisions', 'agent_into_robot_collisions',
        'robot_into_robot_collisions', 'robot_hit_by_robot_collisions', 'invalid_commands',
        'distance_travelled')}
    return EpisodeMetrics(
        collisions=collisions, proximity_time=proximity, simulation_time=simulation_time,
        risk_score=risk_score(collisions, proximity, simulation_time),
        feasible=all(robot.feasible for robot in robots),
        min_clearance=min(robot.min_clearance for robot in robots),
        final_distance_to_goal=max(robot.final_distance_to_goal for robot in robots),
        ticks=max(robot.ticks for robot in robots), outcome=outcome, detail=detail,
        fault_collisions=faults,
        fault_risk_score=risk_score(faults, proximity, simulation_time),
        contacts=tuple(sorted((event for robot in robots for event in robot.contacts),
                              key=lambda event: (event.time, event.robot))),
        legs=len(robots), legs_completed=sum(robot.legs_completed for robot in robots),
        leg_times=tuple(time for robot in robots for time in robot.leg_times),
        failed_leg=failed_robot,
        # Navigation figures: every robot succeeded, the last arrival, the robots' means
        # (clearance weighted by their ticks), jerks added up.
        success=all(robot.success for robot in robots),
        time_to_goal=(max(robot.time_to_goal for robot in robots)
                      if all(robot.success or robot.outcome is Outcome.GOAL_REACHED
                             for robot in robots) else math.nan),
        path_length_ratio=sum(robot.path_length_ratio for robot in robots) / len(robots),
        mean_clearance=(sum(robot.mean_clearance * robot.ticks for robot in robots) / ticks
                        if ticks else math.nan),
        linear_jerk=sum(robot.linear_jerk for robot in robots),
        angular_jerk=sum(robot.angular_jerk for robot in robots),
        mean_speed=sum(robot.mean_speed for robot in robots) / len(robots),
        **summed)
