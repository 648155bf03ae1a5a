"""One episode of the robot under test in one Environment, without ROS.

The simulator node wraps this core: it turns parameters into an
:class:`EpisodeConfig`, calls :meth:`Episode.reset` with each Environment,
publishes each :class:`Observation` and feeds every received command to
:meth:`Episode.step`, one control tick at a time::

    with Episode() as episode:
        observation = episode.reset(environment, EpisodeConfig(seed=7))
        done = episode.done
        while not done:
            observation, done, outcome = episode.step(controller(observation))
        print(episode.metrics())

An episode ends on goal reached, collision limit, time limit, no progress toward
the goal (stuck) or :meth:`Episode.abort` (e.g. a silent controller). An Environment with
mission stations is driven leg by leg (sessgan_sim.mission): the goal of the observation is
the waypoint in force, the next one once the robot has dwelt at a station, and the goal is
reached when the last waypoint (home) is. An Environment with a fleet holds several robots
under test, each driving its own start -> goal in the same world and seeing the others:
:meth:`Episode.step_fleet` takes a command per robot and returns an observation per robot; a
robot that ended (goal reached, stuck, ...) stands still while the others go on, and the
episode is done when every robot is. An
environment that cannot be simulated (invalid grid, unknown scenario or robot,
start footprint overlapping an obstacle) ends the episode at reset with outcome
``invalid_environment`` and a detail saying why. A command with a NaN or
infinite component is replaced by a stop and counted; the episode goes on.
Every random choice (lidar noise, agents) derives from ``config.seed``: the same
seed, environment and commands give identical observations and metrics.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from time import perf_counter
from types import TracebackType
from typing import NamedTuple

import numpy as np
import pybullet as p

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.errors import SessganCoreError
from sessgan_core.route_certificate import CertificateGrid, map_clearance, required_clearances
from sessgan_core.scenarios import get_scenario
from sessgan_sim.agents import DummyAgents, KeepClear, PatrolPath, PatrolSpace
from sessgan_sim.contacts import ContactClassifier
from sessgan_sim.episode_config import (  # noqa: F401 (also imported from here)
    MAX_TIME_LIMIT,
    ROUTE_TIME_FACTOR,
    EpisodeConfig,
    check_time_limit,
)
from sessgan_sim.errors import EpisodeError, InvalidConfigError, UnknownRobotError
from sessgan_sim.metrics import (
    STANDING_SPEED,
    ContactKind,
    EpisodeMetrics,
    MetricsRecorder,
    Outcome,
    fleet_metrics,
    is_harness_outcome,
)
from sessgan_sim.mission import MissionEvent, MissionTracker, failed_leg
from sessgan_sim.progress import ProgressField, ProgressMonitor, progress_field
from sessgan_sim.robots import STOP, BodyCommand, FlyerRobot, Robot, create_robot
from sessgan_sim.sensors import (
    ClearanceSensor,
    Lidar,
    LidarInfo,
    RangeFinder,
    RangeFinderConfig,
    RayCaster,
    Twist2D,
    contact_partners,
    read_odometry,
)
from sessgan_sim.world import ObstacleKind, World, WorldLayout

AGENT_WAIT_DISTANCE = 1.0
"""m between bodies within which a robot waiting for an agent is not counted stuck."""

AGENT_BUMP_LIMIT = 3
"""Times agents may drive into a robot under test before the episode ends as
collision_limit (with the collision limit on): a blind agent whose patrol runs through a
robot waiting for it would ram it until the time limit, a timeout the robot is not to blame
for. A fault collision before it still makes the episode a failure."""

START_OVERLAP_TOLERANCE = 1e-4
"""m: a start footprint penetrating an obstacle deeper than this is invalid."""

@dataclass(frozen=True)
class Observation:
    """What the robot senses after a tick (or at reset)."""

    time: float
    """Sim seconds since the episode's start."""
    scan: np.ndarray
    """float32 ranges in metres (read-only), REP 117 (+inf: no return)."""
    scan_updated: bool
    """True when the lidar took this scan at this tick (its rate may be below the control
    rate); False repeats the previous scan."""
    lidar: LidarInfo
    pose: Pose2D
    """Odometry pose in the odom (= map) frame."""
    twist: Twist2D
    """Body-frame velocity."""
    goal: Pose2D
    """The waypoint in force (the goal of a plain episode)."""
    in_contact: bool
    altitude: float = 0.0
    """m, the body's underside above the ground (odometry's z; 0 for ground robots)."""
    climb_rate: float = 0.0
    """m/s, up positive."""
    range_down: float | None = None
    """m, the downward range sensor's reading (REP 117 infinities); None without one."""
    range_finder: RangeFinderConfig | None = None
    """The downward range sensor's geometry; None for robots without one."""


class StepResult(NamedTuple):
    observation: Observation
    done: bool
    outcome: Outcome | None


@dataclass
class TickProfile:
    """Seconds (of the episode's clock) spent per part of the ticks of the current episode."""

    ticks: int = 0
    physics: float = 0.0
    """Agents, robot dynamics, pybullet steps, contact checks."""
    sensors: float = 0.0
    """Lidar and clearance."""
    metrics: float = 0.0
    """Metric bookkeeping, termination checks and the Observation."""
    reset: float = 0.0
    """The episode's reset: world build, progress fields, agents, first scan (not in
    :attr:`total`)."""
    controller: float = 0.0
    """The controllers' decisions, where their runner times them (sessgan_evolver's
    EpisodeRunner; 0 otherwise; not in :attr:`total`)."""

    @property
    def total(self) -> float:
        return self.physics + self.sensors + self.metrics


def _as_command(command: BodyCommand | Sequence[float]) -> BodyCommand:
    if isinstance(command, BodyCommand):
        return command
    values = tuple(command)
    if len(values) not in (3, 4):
        raise EpisodeError(f'a command is (vx, vy, wz) or (vx, vy, wz, vz), got {values!r}')
    return BodyCommand(*(float(value) for value in values))


@dataclass
class _RobotUnderTest:
    """What every robot under test of an episode has after reset, valid or not."""

    environment: Environment
    config: EpisodeConfig
    recorder: MetricsRecorder
    lidar_info: LidarInfo
    scan: np.ndarray
    start: Pose2D
    """This robot's start (the environment's, or its fleet entry's)."""
    waypoints: tuple[Pose2D, ...]
    """This robot's goals in order (a mission's stations then home; else its goal)."""
    index: int = 0
    """r0, r1, ... in a fleet."""
    outcome: Outcome | None = None
    detail: str = ''
    ticks: int = 0
    """Control ticks this robot was simulated (until its outcome)."""
    touching: bool = False
    scan_updated: bool = False
    """Whether its lidar took ``scan`` at the last tick."""
    mission: MissionTracker | None = None
    """The legs so far (None until the environment was found valid)."""
    live: _RobotSimulation | None = None
    """Its simulation (None when the environment could not be built)."""


@dataclass
class _RobotSimulation:
    """The simulation of an episode whose environment could be built."""

    robot: Robot
    lidar: Lidar
    clearance: ClearanceSensor
    range_finder: RangeFinder | None
    contacts: ContactClassifier
    progress: ProgressMonitor
    """The stuck rule, on the current leg's ProgressField."""
    time_limit: float
    proximity_distance: float
    goal_tolerance: float
    next_scan_time: float = 0.0
    velocity: tuple[float, float] = (0.0, 0.0)
    """m/s, map-frame velocity of the robot's centre over the last physics step."""


class Episode:
    """Runs episodes in a World it owns (one pybullet client), one at a time.

    ``clock`` times the parts of each tick in :attr:`profile` (wall clock by default;
    ``time.thread_time`` measures this thread's CPU time instead).
    """

    def __init__(self, clock: Callable[[], float] = perf_counter) -> None:
        self._clock = clock
        self._world = World()
        self._agents = DummyAgents()
        self._records: list[_RobotUnderTest] = []
        """One per robot under test (r0 first); [] before the first reset."""
        self._latest: list[Observation] = []
        """Every robot's latest observation (r0's alone when the episode could not start)."""
        self.profile = TickProfile()

    # --- resource handling ----------------------------------------------------------------

    def open(self) -> Episode:
        self._world.open()
        return self

    def close(self) -> None:
        self._world.close()
        self._records = []

    def __enter__(self) -> Episode:
        return self.open()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    # --- read-only state ------------------------------------------------------------------

    @property
    def _record(self) -> _RobotUnderTest | None:
        """Robot r0's record (the only robot's outside fleets)."""
        return self._records[0] if self._records else None

    @property
    def _live(self) -> _RobotSimulation | None:
        """Robot r0's simulation."""
        return self._records[0].live if self._records else None

    @property
    def done(self) -> bool:
        """Whether the episode ended: every robot under test has its outcome."""
        return bool(self._records) and all(record.outcome is not None
                                           for record in self._records)

    @property
    def outcome(self) -> Outcome | None:
        """The episode's outcome (a fleet's: see :meth:`metrics`); None while it runs."""
        if not self.done:
            return None
        return self._fleet_outcome()[0]

    @property
    def time(self) -> float:
        """Sim seconds since the episode's start."""
        records = self._records
        if not records:
            return 0.0
        return max(record.ticks for record in records) * records[0].config.control_period

    @property
    def config(self) -> EpisodeConfig:
        """The episode's config, with the scenario's defaults filled in when it is known."""
        return self._require_record().config

    @property
    def environment(self) -> Environment:
        return self._require_record().environment

    @property
    def robot(self) -> Robot:
        """The robot under test (r0 in a fleet; its sensor height places the base_scan
        frame)."""
        return self._require_live().robot

    @property
    def robots(self) -> list[Robot]:
        """Every robot under test, r0 first."""
        self._require_live()
        return [record.live.robot for record in self._records if record.live is not None]

    @property
    def robot_count(self) -> int:
        """Robots under test of the current episode (1 outside fleets)."""
        return len(self._records)

    @property
    def layout(self) -> WorldLayout:
        return self._world.layout

    @property
    def agents(self) -> DummyAgents:
        return self._agents

    @property
    def lidar_info(self) -> LidarInfo:
        return self._require_record().lidar_info

    # --- the episode ----------------------------------------------------------------------

    def reset(self, environment: Environment, config: EpisodeConfig | None = None) -> Observation:
        """Start an episode in ``environment``; return the first observation (robot r0's;
        :meth:`observations` has every robot's).

        Raises InvalidConfigError for an unusable config. An environment that cannot be
        simulated does not raise: the episode is done at once with outcome
        invalid_environment (see :attr:`done` and :meth:`metrics`).
        """
        started = self._clock()
        try:
            return self._reset(environment, config)
        finally:
            self.profile.reset = self._clock() - started

    def _reset(self, environment: Environment, config: EpisodeConfig | None) -> Observation:
        config = config or EpisodeConfig()
        config.validate()
        self._world.open()
        self._agents = DummyAgents(config.agents)
        self.profile = TickProfile()
        scan = np.full(config.lidar.beams, np.inf, dtype=np.float32)
        scan.flags.writeable = False
        record = _RobotUnderTest(environment, config, MetricsRecorder(math.inf),
                                 config.lidar.info, scan, start=environment.start, waypoints=())
        self._records = [record]

        try:
            environment.validate()
            record.waypoints = environment.waypoints
            given = config
            config = record.config = config.resolved(get_scenario(environment.scenario))
            robot = create_robot(str(config.robot), config.robot_params)
            if isinstance(robot, FlyerRobot) and robot.top >= config.world.wall_height:
                raise InvalidConfigError(
                    f'the flyer reaches {robot.top:.2f} m (max_altitude + height): walls '
                    f'must be taller, but world wall_height is {config.world.wall_height} m')
            if environment.fleet and RayCaster(config.lidar.caster) is not RayCaster.ANALYTIC:
                raise InvalidConfigError(
                    'a fleet episode needs the analytic lidar caster (lidar caster '
                    f'{config.lidar.caster!r} does not see the other robots)')
            config = record.config = dataclasses.replace(
                config, time_limit=given.time_limit_for(environment, robot.top_speed))
            robots = [robot, *(create_robot(str(config.robot), config.robot_params)
                               for _ in environment.fleet)]
        except (SessganCoreError, UnknownRobotError) as err:
            self._end(record, Outcome.INVALID_ENVIRONMENT, str(err))
            self._latest = [self._blank_observation(record)]
            return self._latest[0]
        clearance_range = float(config.clearance_range or 0.0)
        self._records = records = [record] + [
            _RobotUnderTest(environment, config, MetricsRecorder(clearance_range, index),
                    config.lidar.info, scan, start=member.start, waypoints=(member.goal,),
                    index=index)
            for index, member in enumerate(environment.fleet, start=1)]
        record.recorder = MetricsRecorder(clearance_range)

        client = self._world.client
        layout = self._world.build(environment, config.physics_timestep, config.world)
        for each, body in zip(records, robots, strict=True):
            body.spawn(client, each.start,
                       body.start_altitude(self._support_height(each.start, body, layout)))
        for each, body in zip(records, robots, strict=True):
            overlap = self._start_overlap(environment, each, body, layout)
            if overlap is not None:
                for other in records:
                    self._end(other, Outcome.INVALID_ENVIRONMENT, overlap)
                self._latest = [self._blank_observation(record)]
                return self._latest[0]

        # A third stream for the range finder leaves the first two as they were before it;
        # robots r1, r2, ... draw from streams spawned after those three.
        streams = np.random.SeedSequence(config.seed)
        noise_seed, agent_seed, range_seed = streams.spawn(3)
        fleet_seeds = streams.spawn(2 * len(environment.fleet))
        spec = get_scenario(environment.scenario)
        grid = map_clearance(environment.occupancy, environment.resolution,
                             environment.origin, spec)
        route_need = required_clearances(spec)[1]
        keep_clear: list[KeepClear] = []
        for each, body in zip(records, robots, strict=True):
            waypoints = each.waypoints
            feasible = environment.feasible
            each.live = _RobotSimulation(
                robot=body, lidar=Lidar(config.lidar, np.random.default_rng(
                    noise_seed if each.index == 0 else fleet_seeds[2 * each.index - 2])),
                clearance=ClearanceSensor(client, body, layout, clearance_range),
                range_finder=None,
                contacts=ContactClassifier(each.recorder, self._agents, self._robot_at),
                progress=ProgressMonitor([
                    progress_field(grid, leg_start, leg_goal, feasible, body.footprint_radius,
                                   route_need)
                    for leg_start, leg_goal in zip((each.start, *waypoints), waypoints)],
                    config.stuck_timeout),
                time_limit=float(config.time_limit or 0.0),
                proximity_distance=float(config.proximity_distance or 0.0),
                goal_tolerance=float(config.goal_tolerance or 0.0),
                next_scan_time=record.lidar_info.scan_time)
            keep_clear += robot_keep_clear(each.index, each.start, waypoints,
                                           each.live.progress.legs, body, config, route_need)
        self._agents.spawn(client, environment, robot, int(config.dummy_agents or 0),
                           np.random.default_rng(agent_seed), keep_clear=keep_clear)
        for each in records:
            live = each.live
            assert live is not None
            others = [other for other in robots if other is not live.robot]
            live.lidar.attach(client, live.robot, layout, self._agents, others)
            live.clearance.set_agent_heights(self._agents.centre_height, config.agents.height)
            live.clearance.set_fleet(others)
            if live.robot.flies:
                live.range_finder = RangeFinder(config.range_finder, np.random.default_rng(
                    range_seed if each.index == 0 else fleet_seeds[2 * each.index - 1]))
                live.range_finder.attach(live.robot, layout)
            each.mission = MissionTracker(each.waypoints, environment.dwell_time,
                                          live.goal_tolerance)
            live.progress.start_leg(0, *live.robot.position)
            each.scan = live.lidar.scan()
        self._latest = [self._observation(each, scan_updated=True) for each in records]
        return self._latest[0]

    def observations(self) -> list[Observation]:
        """Every robot's latest observation (r0 first): of the last reset or step (r0's
        blank one when the episode could not start)."""
        self._require_record()
        return list(self._latest)

    def step(self, command: BodyCommand | Sequence[float]) -> StepResult:
        """Apply ``command`` (body-frame vx, vy, wz, and the flyer's climb rate vz, 0 when
        left out) for one control tick; return the result. A fleet steps with
        :meth:`step_fleet`."""
        if len(self._records) > 1:
            raise EpisodeError(f'a fleet episode of {len(self._records)} robots steps with '
                               f'step_fleet(), a command per robot')
        return self.step_fleet((command,))[0]

    def step_fleet(self, commands: Sequence[BodyCommand | Sequence[float]]
                   ) -> list[StepResult]:
        """Apply a command per robot under test (r0 first) for one control tick; return a
        result per robot: its observation, whether the episode is done and the robot's own
        outcome. A robot that already ended stands still whatever it is sent."""
        records = self._records
        record = self._require_record()
        if self.done:
            raise EpisodeError(f'the episode is over ({self.outcome}); call reset()')
        self._require_live()
        if len(commands) != len(records):
            raise EpisodeError(f'{len(records)} robot(s) under test, got {len(commands)} '
                               f'command(s)')
        config = record.config
        running = [each for each in records if each.outcome is None]
        lives = [each.live for each in running]
        robots = [live.robot for live in lives if live is not None]
        applied = []
        for each in running:
            command = _as_command(commands[each.index])
            if not (math.isfinite(command.vx) and math.isfinite(command.vy)
                    and math.isfinite(command.wz) and math.isfinite(command.vz)):
                each.recorder.invalid_commands += 1
                command = STOP
            applied.append(command)
        stopped = [each.live.robot for each in records
                   if each.outcome is not None and each.live is not None]
        client = self._world.client
        dt = config.physics_timestep
        goals = [self._goal(each) for each in running]
        tolerance = float(config.goal_tolerance or 0.0)
        count = len(running)
        reached = [False] * count
        touching = [False] * count
        travelled = [0.0] * count
        clock = self._clock
        started = clock()

        # The hot loop: bound methods and locals keep Python's overhead per step low.
        advance_agents, step_simulation, hypot = self._agents.advance, p.stepSimulation, math.hypot
        before = [body.position for body in robots]
        positions = before + [body.position for body in stopped]
        velocities = [live.velocity for live in lives if live is not None]
        step_time = record.ticks * config.control_period
        for _ in range(config.physics_steps_per_tick):
            advance_agents(dt, positions)
            for body, command in zip(robots, applied):
                body.apply(command, dt)
            for body in stopped:  # an ended robot holds still where it is
                body.apply(STOP, dt)
            step_simulation(physicsClientId=client)
            for body in stopped:
                body.sync()
            step_time += dt
            for index, body in enumerate(robots):
                body.sync()
                x, y = body.position
                x_before, y_before = before[index]
                previous = velocities[index]
                velocities[index] = ((x - x_before) / dt, (y - y_before) / dt)
                partners = contact_partners(client, body.body_id)
                if partners:
                    touching[index] = True
                    live = lives[index]
                    assert live is not None
                    live.contacts.record(partners, step_time, x, y,
                                         (previous, velocities[index]))
                else:
                    touching[index] = False
                travelled[index] += hypot(x - x_before, y - y_before)
                goal = goals[index]
                if hypot(x - goal.x, y - goal.y) <= tolerance:
                    reached[index] = True
                before[index] = (x, y)
            positions = before + [body.position for body in stopped] if stopped else before
        for index, each in enumerate(running):
            live = lives[index]
            assert live is not None
            live.velocity = velocities[index]
            each.recorder.record_motion(travelled[index])
            each.touching = touching[index]
            each.ticks += 1
        now = self.time
        physics_done = clock()

        agents = self._agents
        clearances = []
        for each in records:
            each.scan_updated = False
        for each in running:
            live = each.live
            assert live is not None
            if now >= live.next_scan_time - 1e-9:
                each.scan = live.lidar.scan()
                live.next_scan_time += record.lidar_info.scan_time
                if live.next_scan_time <= now:  # lidar faster than control: scan every tick
                    live.next_scan_time = now + config.control_period
                each.scan_updated = True
            clearances.append(live.clearance.measure(agents.body_ids, agents.positions,
                                                     agents.config.radius))
        sensors_done = clock()

        for index, each in enumerate(running):
            live = each.live
            assert live is not None
            each.recorder.record_tick(config.control_period, clearances[index],
                                      touching[index], live.proximity_distance)
            x, y = live.robot.position
            goal = goals[index]
            self._check_end(each, live, reached[index], now, hypot(x - goal.x, y - goal.y))
        done = self.done
        results = [StepResult(self._observation(each, each.scan_updated), done, each.outcome)
                   for each in records]
        # Standard navigation metrics: one O(1) update per robot, from the odometry twist just
        # read for the observation (sessgan_sim.metrics.NavigationAccumulator).
        for index, each in enumerate(running):
            twist = results[each.index].observation.twist
            each.recorder.navigation.add(config.control_period,
                                         0.0 if touching[index] else clearances[index],
                                         twist.vx, twist.vy, twist.wz)
        self._latest = [result.observation for result in results]
        finished = clock()
        profile = self.profile
        profile.ticks += 1
        profile.physics += physics_done - started
        profile.sensors += sensors_done - physics_done
        profile.metrics += finished - sensors_done
        return results

    def driving(self) -> list[int]:
        """The robots under test that have no outcome yet (r0 is 0)."""
        return [record.index for record in self._records if record.outcome is None]

    def await_first_command(self, index: int) -> None:
        """Robot ``index``'s stack has sent no command in this episode yet (clocked mode: sim
        time runs on): the next tick is not judged, so the robot's stuck rule and time limit
        start with its first command. A robot that never moved is no test result; the wall
        clock bounds the wait (the simulator's controller_startup_timeout)."""
        self._require_record()
        record = self._records[index]
        live = record.live
        if live is not None and record.outcome is None:
            live.progress.hold(self.time + record.config.control_period)
            live.time_limit += record.config.control_period

    def abort(self, outcome: Outcome | str, detail: str = '') -> None:
        """End the running episode from outside (e.g. controller_unresponsive), for every
        robot that has not ended yet.

        No-op when the episode already ended: its first outcome stands.
        """
        self._require_record()
        for record in self._records:
            if record.outcome is None:
                self._end(record, Outcome(outcome), detail)

    def metrics(self) -> EpisodeMetrics:
        """The episode's metrics (so far, with outcome None, while it runs). A fleet's add up
        its robots' (sessgan_sim.metrics.fleet_metrics): its outcome is the first failing
        robot's (goal_reached when all reached theirs), the detail names each robot's."""
        self._require_record()
        records = self._records
        if len(records) == 1:
            return self.robot_metrics(0)
        robots = [self.robot_metrics(index) for index in range(len(records))]
        outcome, failed = self._fleet_outcome() if self.done else (None, -1)
        if outcome is not None and is_harness_outcome(outcome) and failed >= 0:
            # No result: say why once, naming the robot (an abort ends every robot with the
            # detail of the one that fell silent; listed per robot, r0 read unresponsive).
            detail = robots[failed].detail
            if not detail.startswith('robot r'):
                detail = f'robot r{failed}: {detail}'
        else:
            detail = '; '.join(
                f'r{index}: {metrics.outcome.value if metrics.outcome else "running"}'
                + (f' ({metrics.detail})' if metrics.detail else '')
                for index, metrics in enumerate(robots))
        return fleet_metrics(robots, outcome, detail, failed)

    def robot_metrics(self, index: int) -> EpisodeMetrics:
        """Robot ``index``'s own metrics (r0: the only robot's outside fleets)."""
        self._require_record()
        record = self._records[index]
        detail = record.detail
        invalid = record.recorder.invalid_commands
        if invalid:
            note = (f'{invalid} command(s) with NaN or infinite components were replaced by '
                    f'a stop')
            detail = f'{detail}; {note}' if detail else note
        snapshot = record.recorder.snapshot(
            simulation_time=record.ticks * record.config.control_period,
            feasible=bool(record.environment.feasible),
            distance_to_goal=self._distance_to_goal(record), outcome=record.outcome,
            detail=detail, route_length=self._route_length(record))
        mission = record.mission
        if mission is None:
            return snapshot
        failed = failed_leg(mission, record.outcome,
                            (event.time for event in snapshot.contacts if event.fault))
        if failed >= 0 and mission.legs > 1:
            note = f'failed on {mission.describe_leg(failed)}'
            detail = f'{snapshot.detail}; {note}' if snapshot.detail else note
        return dataclasses.replace(
            snapshot, detail=detail, legs=mission.legs, legs_completed=mission.legs_completed,
            leg_times=mission.leg_times, failed_leg=failed)

    # --- internals ------------------------------------------------------------------------

    @staticmethod
    def _route_length(record: _RobotUnderTest) -> float:
        """m, the certified route of this robot (r0: the environment's, else its fleet
        entry's); 0 without one."""
        environment = record.environment
        if record.index == 0:
            return float(environment.route_length or 0.0)
        return float(environment.fleet[record.index - 1].route_length or 0.0)

    def _fleet_outcome(self) -> tuple[Outcome | None, int]:
        """The episode's outcome and the index of the robot it comes from (-1: every robot
        reached its goal without a fault): the earliest-ending robot that did not reach its
        goal, else the earliest-ending one with a fault collision (then the goal's outcome):
        an episode where a robot timed out does not read goal_reached."""
        records = self._records
        failing = ([record for record in records if record.outcome is not Outcome.GOAL_REACHED]
                   or [record for record in records if record.recorder.fault_collisions])
        if not failing:
            return (records[0].outcome, -1) if records else (None, -1)
        first = min(failing, key=lambda record: (record.ticks, record.index))
        return first.outcome, (first.index if len(records) > 1 else -1)

    def _require_record(self) -> _RobotUnderTest:
        if not self._records:
            raise EpisodeError('no episode yet: call reset(environment, config) first')
        return self._records[0]

    def _require_live(self) -> _RobotSimulation:
        live = self._records[0].live if self._records else None
        if live is None:
            raise EpisodeError('no running simulation: reset() has not built a valid episode')
        return live

    @staticmethod
    def _end(record: _RobotUnderTest, outcome: Outcome, detail: str) -> None:
        record.outcome = outcome
        record.detail = detail

    @staticmethod
    def _goal(record: _RobotUnderTest) -> Pose2D:
        """The robot's waypoint in force: its goal in a plain episode."""
        if record.mission is not None:
            return record.mission.goal
        return record.waypoints[-1] if record.waypoints else record.environment.goal

    def _check_end(self, record: _RobotUnderTest, live: _RobotSimulation, reached: bool,
                   now: float, distance: float) -> None:
        config = record.config
        recorder = record.recorder
        mission = record.mission
        if mission is None:  # reset() sets it whenever it builds a simulation
            raise EpisodeError('no mission: reset() has not built a valid episode')
        if config.collision_limit and recorder.collisions >= config.collision_limit:
            self._end(record, Outcome.COLLISION_LIMIT,
                      f'{recorder.collisions} collisions reached the limit of '
                      f'{config.collision_limit} at {now:.2f} s')
            return
        bumps = sum(event.kind is ContactKind.AGENT_INTO_ROBOT for event in recorder.contacts)
        if config.collision_limit and bumps >= AGENT_BUMP_LIMIT:
            self._end(record, Outcome.COLLISION_LIMIT,
                      f'agents drove into the robot {bumps} times by {now:.2f} s (the limit '
                      f'for agents): the test, not the robot, ends it')
            return
        event = mission.update(now, reached, distance, math.hypot(*live.velocity),
                               config.control_period)
        if event is MissionEvent.COMPLETE:
            if mission.legs > 1:
                self._end(record, Outcome.GOAL_REACHED,
                          f'completed the mission: reached home, the last of {mission.legs} '
                          f'waypoints, within {live.goal_tolerance:.2f} m at {now:.2f} s')
            else:
                self._end(record, Outcome.GOAL_REACHED,
                          f'reached the goal within {live.goal_tolerance:.2f} m at {now:.2f} s')
            return
        progress = live.progress
        if event is MissionEvent.NEXT_LEG:
            progress.start_leg(mission.leg, *live.robot.position)
        if event is not MissionEvent.NONE:
            progress.hold(now)  # arriving and setting off are progress
        if now >= live.time_limit - 1e-9:
            blocking = self._robots_nearby(live)
            self._end(record, Outcome.TIMEOUT,
                      f'time limit of {live.time_limit:.2f} s reached, '
                      f'{self._distance_to_goal(record):.2f} m from the goal' + (
                          f'; robot(s) {", ".join(f"r{index}" for index in blocking)} within '
                          f'{AGENT_WAIT_DISTANCE:.1f} m (waiting for each other?)'
                          if blocking else ''))
        elif mission.dwelling and distance <= live.goal_tolerance:
            progress.hold(now)  # dwelling at a station is not being stuck
        elif progress.stuck_timeout > 0 and progress.stuck(
                now, *live.robot.position,
                lambda: self._agent_nearby(live)):  # an agent or a robot in the way
            # A robot circling or oscillating is stuck too, but not "stopped": say which.
            speed = math.hypot(*live.velocity)
            where = f'{self._distance_to_goal(record):.2f} m from it at {now:.2f} s'
            self._end(record, Outcome.STUCK,
                      f'no progress toward the goal and no new ground for '
                      f'{config.stuck_timeout:.2f} s; ' + (
                          f'stopped {where}' if speed <= STANDING_SPEED
                          else f'{where}, moving at {speed:.2f} m/s'))

    def _robot_at(self, body_id: int) -> tuple[int, tuple[float, float]] | None:
        """Index and position of the robot under test whose body is ``body_id``; None for any
        other."""
        for record in self._records:
            if record.live is not None and record.live.robot.body_id == body_id:
                return record.index, record.live.robot.position
        return None

    def _agent_nearby(self, live: _RobotSimulation) -> bool:
        """Whether an agent's body, or another robot under test, is within
        AGENT_WAIT_DISTANCE of the robot's body."""
        agents = self._agents
        robot = live.robot
        x, y = robot.position
        if self._robots_nearby(live):
            return True
        if not agents.body_ids:
            return False
        gaps = (np.hypot(agents.positions[:, 0] - x, agents.positions[:, 1] - y)
                - agents.config.radius - robot.footprint_radius)
        return bool((gaps < AGENT_WAIT_DISTANCE).any())

    def _robots_nearby(self, live: _RobotSimulation) -> list[int]:
        """The other robots under test within AGENT_WAIT_DISTANCE of the robot's body."""
        robot = live.robot
        x, y = robot.position
        nearby = []
        for record in self._records:
            other = record.live.robot if record.live is not None else robot
            if other is not robot:
                gap = (math.hypot(other.position[0] - x, other.position[1] - y)
                       - other.footprint_radius - robot.footprint_radius)
                if gap < AGENT_WAIT_DISTANCE:
                    nearby.append(record.index)
        return nearby

    def _distance_to_goal(self, record: _RobotUnderTest) -> float:
        goal = self._goal(record)
        if record.live is not None:
            x, y = record.live.robot.position
        else:
            x, y = record.start.x, record.start.y
        try:
            distance = math.hypot(x - goal.x, y - goal.y)
        except TypeError:  # an invalid environment may hold anything
            return math.inf
        return distance if math.isfinite(distance) else math.inf

    def _start_overlap(self, environment: Environment, record: _RobotUnderTest, robot: Robot,
                       layout: WorldLayout) -> str | None:
        """Why the robot's footprint at its start overlaps an obstacle, or None."""
        x, y = robot.position
        client = self._world.client
        for other in layout.obstacles_near(x, y, robot.footprint_radius):
            for point in p.getClosestPoints(robot.body_id, other, 0.0, physicsClientId=client):
                if point[8] < -START_OVERLAP_TOLERANCE:
                    kind = layout.kind_of(other)
                    name = kind.value.replace('_', ' ') if kind else 'obstacle'
                    start = record.start
                    row, col = environment.cell_of(x, y)
                    inside = (' (start inside it)'
                              if int(environment.occupancy[row, col]) not in robot.passable_values
                              else '')
                    who = f"robot r{record.index}'s" if environment.fleet else 'the'
                    return (f'environment {environment.id!r}: {who} {robot.name} footprint at '
                            f'the start ({start.x:.2f}, {start.y:.2f}) m overlaps a {name} by '
                            f'{-point[8]:.3f} m{inside}')
        return None

    def _observation(self, record: _RobotUnderTest, scan_updated: bool) -> Observation:
        live = record.live
        assert live is not None
        robot = live.robot
        odometry = read_odometry(robot)
        range_finder = live.range_finder
        time = record.ticks * record.config.control_period
        if range_finder is None:
            return Observation(
                time=time, scan=record.scan, scan_updated=scan_updated,
                lidar=record.lidar_info, pose=odometry.pose, twist=odometry.twist,
                goal=self._goal(record), in_contact=record.touching)
        return Observation(
            time=time, scan=record.scan, scan_updated=scan_updated,
            lidar=record.lidar_info, pose=odometry.pose, twist=odometry.twist,
            goal=self._goal(record), in_contact=record.touching,
            altitude=robot.altitude, climb_rate=robot.state.vz,
            range_down=range_finder.measure(), range_finder=range_finder.config)

    @staticmethod
    def _support_height(start: Pose2D, robot: Robot, layout: WorldLayout) -> float:
        """Height (m) of the tallest low obstacle under the robot's footprint at ``start``
        (0 on bare ground): a flyer starts landed on it."""
        x, y, radius = float(start.x), float(start.y), robot.footprint_radius
        support = 0.0
        for box in layout.obstacles:
            if box.kind is not ObstacleKind.LOW_OBSTACLE:
                continue
            dx = max(box.x_min - x, 0.0, x - box.x_max)
            dy = max(box.y_min - y, 0.0, y - box.y_max)
            if dx * dx + dy * dy < radius * radius:
                support = max(support, box.height)
        return support

    @staticmethod
    def _blank_observation(record: _RobotUnderTest) -> Observation:
        """The observation of an episode that could not start: no returns, at the start."""
        environment = record.environment
        try:
            start, goal = environment.start, environment.goal
            pose = Pose2D(float(start.x), float(start.y), float(start.yaw))
            goal = Pose2D(float(goal.x), float(goal.y), float(goal.yaw))
        except (TypeError, ValueError, AttributeError):
            pose = goal = Pose2D(0.0, 0.0, 0.0)
        return Observation(time=0.0, scan=record.scan, scan_updated=False,
                           lidar=record.lidar_info, pose=pose, twist=Twist2D(0.0, 0.0, 0.0),
                           goal=goal, in_contact=False)


def leg_keep_clear(goal: Pose2D, robot: Robot, config: EpisodeConfig, progress: ProgressField,
                   route_need: float) -> list[KeepClear]:
    """Discs where agents may neither start nor end a patrol leg: around a leg's goal, and
    on its certified route's narrow passages (where the robot could not pass an agent
    standing there; a patrol may cross those, not run along them)."""
    agents = config.agents
    discs = [KeepClear(goal.x, goal.y, agents.min_start_distance)]
    # Narrow: the robot on the route could not pass an agent standing beside it; the
    # passage's free space lies within its clearance (below narrow_below) of the route.
    narrow_below = agents.radius + route_need
    reach = agents.radius + robot.footprint_radius
    grid = progress.grid
    step = max(1, len(progress.route) // 400)  # bound the disc count on long routes
    for row, col in progress.route[::step]:
        if grid.clearance[row, col] < narrow_below:
            x, y = grid.centre((row, col))
            discs.append(KeepClear(x, y, reach, narrow_below))
    return discs


def robot_keep_clear(index: int, start: Pose2D, waypoints: Sequence[Pose2D],
                     legs: Sequence[ProgressField], robot: Robot, config: EpisodeConfig,
                     route_need: float) -> list[KeepClear]:
    """The keep-clear discs of robot under test ``index`` (0: r0) for its legs to
    ``waypoints``; agents also start away from every other robot's start, as from r0's."""
    discs = [disc for goal, progress in zip(waypoints, legs, strict=True)
             for disc in leg_keep_clear(goal, robot, config, progress, route_need)]
    if index > 0:
        discs.append(KeepClear(start.x, start.y, config.agents.min_start_distance))
    return discs


class PatrolPlanner:
    """The patrols the dummy agents of an episode of a valid ``environment`` walk (what
    Episode.reset spawns) for any simulator seed, computed without a simulation: a screen
    predicts from them where agents will meet the robot. ``config``: the episode's, but for
    its seed; ``grid``: the environment's map_clearance, when the caller has it."""

    def __init__(self, environment: Environment, config: EpisodeConfig,
                 grid: CertificateGrid | None = None) -> None:
        spec = get_scenario(environment.scenario)
        self.environment = environment
        self.config = config = config.resolved(spec)
        self.count = int(config.dummy_agents or 0)
        robot = create_robot(str(config.robot), config.robot_params)
        keep_clear: list[KeepClear] = []
        self.space: PatrolSpace | None = None
        if self.count == 0:
            return
        if grid is None:
            grid = map_clearance(environment.occupancy, environment.resolution,
                                 environment.origin, spec)
        route_need = required_clearances(spec)[1]
        robots = [(0, environment.start, environment.waypoints),
                  *((index, member.start, (member.goal,))
                    for index, member in enumerate(environment.fleet, start=1))]
        for index, start, waypoints in robots:
            legs = [progress_field(grid, leg_start, leg_goal, environment.feasible,
                                   robot.footprint_radius, route_need)
                    for leg_start, leg_goal in zip((start, *waypoints), waypoints)]
            keep_clear += robot_keep_clear(index, start, waypoints, legs, robot, config,
                                           route_need)
        self.space = PatrolSpace(environment, robot.passable_values, config.agents, keep_clear)

    def patrols(self, seed: int) -> list[PatrolPath]:
        """The patrols of an episode with simulator seed ``seed``."""
        if self.space is None:
            return []
        # The agents' stream of Episode.reset: the second of three spawned from the seed.
        agent_seed = np.random.SeedSequence(int(seed)).spawn(3)[1]
        return self.space.patrols(self.count, np.random.default_rng(agent_seed))
