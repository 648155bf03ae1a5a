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
reached when the last waypoint (home) is. An
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
import numbers
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from time import perf_counter
from types import TracebackType
from typing import NamedTuple

import numpy as np
import pybullet as p

from sessgan_gen.environment import Environment, Pose2D
from sessgan_gen.errors import SessganGenError
from sessgan_gen.grid_search import descend, distance_field
from sessgan_gen.route_certificate import CertificateGrid, map_clearance, required_clearances
from sessgan_gen.scenarios import Scenario, get_scenario
from sessgan_sim.agents import AgentConfig, DummyAgents
from sessgan_sim.errors import EpisodeError, InvalidConfigError, UnknownRobotError
from sessgan_sim.metrics import (
    CONTACT_DEBOUNCE,
    STANDING_SPEED,
    ContactKind,
    EpisodeMetrics,
    MetricsRecorder,
    Outcome,
)
from sessgan_sim.mission import MissionEvent, MissionTracker, failed_leg
from sessgan_sim.robots import STOP, FlyerRobot, Robot, VelocityCommand, create_robot
from sessgan_sim.sensors import (
    ClearanceSensor,
    Lidar,
    LidarConfig,
    LidarInfo,
    RangeFinder,
    RangeFinderConfig,
    Twist2D,
    contact_partners,
    read_odometry,
)
from sessgan_sim.world import ObstacleKind, World, WorldLayout, WorldStyle

AGENT_WAIT_DISTANCE = 1.0
"""m between bodies within which a robot waiting for an agent is not counted stuck."""

ROUTE_TIME_FACTOR = 4.0
"""Default time limits allow driving the certified route at a quarter of the top speed."""

START_OVERLAP_TOLERANCE = 1e-4
"""m: a start footprint penetrating an obstacle deeper than this is invalid."""


@dataclass(frozen=True)
class EpisodeConfig:
    """Everything an episode needs besides the Environment. None = the scenario's default.

    Units: seconds, metres, hertz.
    """

    robot: str | None = None
    """Robot model from the registry (sessgan_sim.robots); None: the scenario's robot."""
    robot_params: Mapping[str, float] = field(default_factory=dict)
    """Overrides of the robot model's parameters, e.g. {'max_linear_speed': 0.5}."""
    control_rate_hz: float = 20.0
    """Control ticks per sim second: one command per tick."""
    physics_rate_hz: float = 100.0
    """Physics steps per sim second, rounded to a whole number of steps per tick. 100 Hz
    keeps a car at 12 m/s moving 12 cm per step, well inside any barrier's 1 m cell."""
    time_limit: float | None = None
    """Sim seconds before the episode ends with outcome timeout. None: the scenario's limit,
    raised to ROUTE_TIME_FACTOR x the certified route's length / the robot's top speed, so a
    valid test always leaves time to drive its route."""
    proximity_distance: float | None = None
    """Clearance below which time counts as proximity time."""
    clearance_range: float | None = None
    """Farthest clearance measured, at least the proximity distance: min_clearance is capped
    here. None: the proximity distance (the cheapest query)."""
    lidar: LidarConfig = field(default_factory=LidarConfig)
    range_finder: RangeFinderConfig = field(default_factory=RangeFinderConfig)
    """The downward range sensor; only a flying robot has one."""
    dummy_agents: int | None = None
    """Number of moving dummy agents."""
    agents: AgentConfig = field(default_factory=AgentConfig)
    stuck_timeout: float = 10.0
    """Sim seconds without progress toward the goal (a new minimum of the geodesic distance
    on the grid) before the episode ends with outcome stuck; <= 0 disables it."""
    goal_tolerance: float | None = None
    """Distance of the robot's centre to the goal that counts as reached; None: one cell of
    the scenario."""
    collision_limit: int = 10
    """Collisions that end the episode (outcome collision_limit); 0 disables it."""
    seed: int = 0
    """Seed of every random choice of the episode."""
    world: WorldStyle = field(default_factory=WorldStyle)

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first unusable value."""
        for name in ('control_rate_hz', 'physics_rate_hz'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InvalidConfigError(f'episode config: {name} must be > 0, got {value!r}')
        for name in ('time_limit', 'proximity_distance', 'goal_tolerance', 'clearance_range'):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise InvalidConfigError(f'episode config: {name} must be > 0 or None, '
                                         f'got {value!r}')
        if self.physics_rate_hz < self.control_rate_hz:
            raise InvalidConfigError(
                f'episode config: physics_rate_hz ({self.physics_rate_hz}) must be at least '
                f'control_rate_hz ({self.control_rate_hz})')
        if not math.isfinite(self.stuck_timeout):
            raise InvalidConfigError(f'episode config: stuck_timeout must be finite, got '
                                     f'{self.stuck_timeout}')
        counts = (('collision_limit', self.collision_limit), ('seed', self.seed),
                  ('dummy_agents', 0 if self.dummy_agents is None else self.dummy_agents))
        for name, count in counts:
            if not (isinstance(count, numbers.Integral) and count >= 0):
                raise InvalidConfigError(f'episode config: {name} must be an integer >= 0, '
                                         f'got {count!r}')
        self.lidar.validate()
        self.range_finder.validate()
        self.agents.validate()
        self.world.validate()

    def resolved(self, scenario: Scenario) -> EpisodeConfig:
        """This config with every None replaced by the scenario's default."""
        proximity = (self.proximity_distance if self.proximity_distance is not None
                     else scenario.proximity_distance)
        return dataclasses.replace(
            self,
            robot=self.robot if self.robot is not None else scenario.robot,
            time_limit=self.time_limit if self.time_limit is not None else scenario.time_limit,
            proximity_distance=proximity,
            clearance_range=max(self.clearance_range or proximity, proximity),
            dummy_agents=(self.dummy_agents if self.dummy_agents is not None
                          else scenario.dummy_agents),
            goal_tolerance=(self.goal_tolerance if self.goal_tolerance is not None
                            else scenario.cell_size),
        )

    @property
    def control_period(self) -> float:
        """Sim seconds per control tick."""
        return 1.0 / self.control_rate_hz

    @property
    def physics_steps_per_tick(self) -> int:
        return max(1, round(self.physics_rate_hz / self.control_rate_hz))

    @property
    def physics_timestep(self) -> float:
        """Sim seconds per physics step (the tick divided into whole steps)."""
        return self.control_period / self.physics_steps_per_tick


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

    @property
    def total(self) -> float:
        return self.physics + self.sensors + self.metrics


def _as_command(command: VelocityCommand | Sequence[float]) -> VelocityCommand:
    if isinstance(command, VelocityCommand):
        return command
    values = tuple(command)
    if len(values) not in (3, 4):
        raise EpisodeError(f'a command is (vx, vy, wz) or (vx, vy, wz, vz), got {values!r}')
    return VelocityCommand(*(float(value) for value in values))


@dataclass
class _Record:
    """What every episode has after reset, valid or not."""

    environment: Environment
    config: EpisodeConfig
    recorder: MetricsRecorder
    lidar_info: LidarInfo
    scan: np.ndarray
    outcome: Outcome | None = None
    detail: str = ''
    ticks: int = 0
    touching: bool = False
    mission: MissionTracker | None = None
    """The legs so far (None until the environment was found valid)."""


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


@dataclass
class _Live:
    """The simulation of an episode whose environment could be built."""

    robot: Robot
    lidar: Lidar
    clearance: ClearanceSensor
    range_finder: RangeFinder | None
    progress: ProgressField
    """The current leg's."""
    time_limit: float
    proximity_distance: float
    goal_tolerance: float
    best_progress: float = math.inf
    last_progress_time: float = 0.0
    next_scan_time: float = 0.0
    velocity: tuple[float, float] = (0.0, 0.0)
    """m/s, map-frame velocity of the robot's centre over the last physics step."""
    leg_progress: list[ProgressField] = field(default_factory=list)
    """Every leg's ProgressField, in order (a plain episode's one)."""


class Episode:
    """Runs episodes in a World it owns (one pybullet client), one at a time.

    ``clock`` times the parts of each tick in :attr:`profile` (wall clock by default;
    ``time.thread_time`` measures this thread's CPU time instead).
    """

    def __init__(self, clock: Callable[[], float] = perf_counter) -> None:
        self._clock = clock
        self._world = World()
        self._agents = DummyAgents()
        self._pushed_by: int | None = None
        """The agent that last drove into the robot, until ``_pushed_until`` (sim s)."""
        self._pushed_until = -math.inf
        self._record: _Record | None = None
        self._live: _Live | None = None
        self.profile = TickProfile()

    # --- resource handling ----------------------------------------------------------------

    def open(self) -> Episode:
        self._world.open()
        return self

    def close(self) -> None:
        self._world.close()
        self._record = None
        self._live = None

    def __enter__(self) -> Episode:
        return self.open()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    # --- read-only state ------------------------------------------------------------------

    @property
    def done(self) -> bool:
        return self._record is not None and self._record.outcome is not None

    @property
    def outcome(self) -> Outcome | None:
        return self._record.outcome if self._record else None

    @property
    def time(self) -> float:
        """Sim seconds since the episode's start."""
        record = self._record
        return record.ticks * record.config.control_period if record else 0.0

    @property
    def config(self) -> EpisodeConfig:
        """The episode's config, with the scenario's defaults filled in when it is known."""
        return self._require_record().config

    @property
    def environment(self) -> Environment:
        return self._require_record().environment

    @property
    def robot(self) -> Robot:
        """The robot under test (its sensor height places the base_scan frame)."""
        return self._require_live().robot

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
        """Start an episode in ``environment``; return the first observation.

        Raises InvalidConfigError for an unusable config. An environment that cannot be
        simulated does not raise: the episode is done at once with outcome
        invalid_environment (see :attr:`done` and :meth:`metrics`).
        """
        config = config or EpisodeConfig()
        config.validate()
        self._world.open()
        self._live = None
        self._agents = DummyAgents(config.agents)
        self._pushed_by, self._pushed_until = None, -math.inf
        self.profile = TickProfile()
        scan = np.full(config.lidar.beams, np.inf, dtype=np.float32)
        scan.flags.writeable = False
        record = _Record(environment, config, MetricsRecorder(math.inf), config.lidar.info, scan)
        self._record = record

        try:
            environment.validate()
            scenario_limit = config.time_limit is None
            config = record.config = config.resolved(get_scenario(environment.scenario))
            robot = create_robot(str(config.robot), config.robot_params)
            if isinstance(robot, FlyerRobot) and robot.top >= config.world.wall_height:
                raise InvalidConfigError(
                    f'the flyer reaches {robot.top:.2f} m (max_altitude + height): walls '
                    f'must be taller, but world wall_height is {config.world.wall_height} m')
            if scenario_limit and environment.route_length > 0:
                route_time = ROUTE_TIME_FACTOR * environment.route_length / robot.top_speed
                config = dataclasses.replace(
                    config, time_limit=max(float(config.time_limit or 0.0), route_time))
            if scenario_limit and environment.stations:
                # A mission gets the scenario's limit per leg (at least the route's time, as
                # above), and time for every dwell.
                per_leg = get_scenario(environment.scenario).time_limit * environment.legs
                config = dataclasses.replace(config, time_limit=max(
                    per_leg, float(config.time_limit or 0.0))
                    + len(environment.stations) * environment.dwell_time)
            record.config = config
        except (SessganGenError, UnknownRobotError) as err:
            self._end(Outcome.INVALID_ENVIRONMENT, str(err))
            return self._blank_observation()
        clearance_range = float(config.clearance_range or 0.0)
        record.recorder = MetricsRecorder(clearance_range)

        client = self._world.client
        layout = self._world.build(environment, config.physics_timestep, config.world)
        robot.spawn(client, environment.start,
                    robot.start_altitude(self._support_height(environment, robot, layout)))
        overlap = self._start_overlap(environment, robot, layout)
        if overlap is not None:
            self._end(Outcome.INVALID_ENVIRONMENT, overlap)
            return self._blank_observation()

        # A third stream for the range finder leaves the first two as they were before it.
        noise_seed, agent_seed, range_seed = np.random.SeedSequence(config.seed).spawn(3)
        spec = get_scenario(environment.scenario)
        grid = map_clearance(environment.occupancy, environment.resolution,
                             environment.origin, spec)
        route_need = required_clearances(spec)[1]
        waypoints = environment.waypoints
        leg_progress = [
            self._progress_field(grid, leg_start, leg_goal, environment.feasible, robot,
                                 route_need)
            for leg_start, leg_goal in zip((environment.start, *waypoints), waypoints)]
        keep_clear = [disc for leg_goal, progress in zip(waypoints, leg_progress)
                      for disc in self._agent_keep_clear(leg_goal, robot, config, progress,
                                                         route_need)]
        progress = leg_progress[0]
        self._agents.spawn(client, environment, robot, int(config.dummy_agents or 0),
                           np.random.default_rng(agent_seed), keep_clear=keep_clear)
        lidar = Lidar(config.lidar, np.random.default_rng(noise_seed))
        lidar.attach(client, robot, layout, self._agents)
        clearance = ClearanceSensor(client, robot, layout, clearance_range)
        clearance.set_agent_heights(self._agents.centre_height, config.agents.height)
        range_finder = None
        if robot.flies:
            range_finder = RangeFinder(config.range_finder, np.random.default_rng(range_seed))
            range_finder.attach(robot, layout)
        live = _Live(
            robot=robot, lidar=lidar, clearance=clearance, range_finder=range_finder,
            progress=progress,
            time_limit=float(config.time_limit or 0.0),
            proximity_distance=float(config.proximity_distance or 0.0),
            goal_tolerance=float(config.goal_tolerance or 0.0),
            next_scan_time=record.lidar_info.scan_time)
        self._live = live
        live.leg_progress = leg_progress
        record.mission = MissionTracker(waypoints, environment.dwell_time, live.goal_tolerance)
        live.best_progress = self._progress_distance(record, live)
        record.scan = lidar.scan()
        return self._observation(record, live, scan_updated=True)

    def step(self, command: VelocityCommand | Sequence[float]) -> StepResult:
        """Apply ``command`` (body-frame vx, vy, wz, and the flyer's climb rate vz, 0 when
        left out) for one control tick; return the result."""
        record = self._require_record()
        if record.outcome is not None:
            raise EpisodeError(f'the episode is over ({record.outcome.value}); call reset()')
        live = self._require_live()
        command = _as_command(command)
        if not (math.isfinite(command.vx) and math.isfinite(command.vy)
                and math.isfinite(command.wz) and math.isfinite(command.vz)):
            record.recorder.invalid_commands += 1
            command = STOP
        config, robot, recorder = record.config, live.robot, record.recorder
        client = self._world.client
        body = robot.body_id
        dt = config.physics_timestep
        goal = self._goal(record)
        tolerance = live.goal_tolerance
        reached = touching = False
        clock = self._clock
        started = clock()

        # The hot loop: bound methods and locals keep Python's overhead per step low.
        advance_agents, apply, sync = self._agents.advance, robot.apply, robot.sync
        step_simulation, hypot = p.stepSimulation, math.hypot
        x, y = robot.position
        velocity = live.velocity
        step_time = record.ticks * config.control_period
        travelled = 0.0
        for _ in range(config.physics_steps_per_tick):
            advance_agents(dt, (x, y))
            x_before, y_before = x, y
            apply(command, dt)
            step_simulation(physicsClientId=client)
            sync()
            step_time += dt
            x, y = robot.position
            previous, velocity = velocity, ((x - x_before) / dt, (y - y_before) / dt)
            partners = contact_partners(client, body)
            touching = bool(partners)
            if touching:
                self._record_contacts(recorder, partners, step_time, x, y, (previous, velocity))
            travelled += hypot(x - x_before, y - y_before)
            if hypot(x - goal.x, y - goal.y) <= tolerance:
                reached = True
        live.velocity = velocity
        recorder.record_motion(travelled)
        record.touching = touching
        record.ticks += 1
        now = self.time
        physics_done = clock()

        scan_updated = now >= live.next_scan_time - 1e-9
        if scan_updated:
            record.scan = live.lidar.scan()
            live.next_scan_time += record.lidar_info.scan_time
            if live.next_scan_time <= now:  # lidar faster than control: scan every tick
                live.next_scan_time = now + config.control_period
        agents = self._agents
        clearance = live.clearance.measure(agents.body_ids, agents.positions,
                                           agents.config.radius)
        sensors_done = clock()

        recorder.record_tick(config.control_period, clearance, touching,
                             live.proximity_distance)
        self._check_end(record, live, reached, now, hypot(x - goal.x, y - goal.y))
        observation = self._observation(record, live, scan_updated)
        finished = clock()
        profile = self.profile
        profile.ticks += 1
        profile.physics += physics_done - started
        profile.sensors += sensors_done - physics_done
        profile.metrics += finished - sensors_done
        return StepResult(observation, record.outcome is not None, record.outcome)

    def abort(self, outcome: Outcome | str, detail: str = '') -> None:
        """End the running episode from outside (e.g. controller_unresponsive).

        No-op when the episode already ended: its first outcome stands.
        """
        record = self._require_record()
        if record.outcome is None:
            self._end(Outcome(outcome), detail)

    def metrics(self) -> EpisodeMetrics:
        """The episode's metrics (so far, with outcome None, while it runs)."""
        record = self._require_record()
        detail = record.detail
        invalid = record.recorder.invalid_commands
        if invalid:
            note = (f'{invalid} command(s) with NaN or infinite components were replaced by '
                    f'a stop')
            detail = f'{detail}; {note}' if detail else note
        snapshot = record.recorder.snapshot(
            simulation_time=self.time, feasible=bool(record.environment.feasible),
            distance_to_goal=self._distance_to_goal(record), outcome=record.outcome,
            detail=detail)
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

    def _require_record(self) -> _Record:
        if self._record is None:
            raise EpisodeError('no episode yet: call reset(environment, config) first')
        return self._record

    def _require_live(self) -> _Live:
        if self._live is None:
            raise EpisodeError('no running simulation: reset() has not built a valid episode')
        return self._live

    def _end(self, outcome: Outcome, detail: str) -> None:
        record = self._require_record()
        record.outcome = outcome
        record.detail = detail

    def _goal(self, record: _Record) -> Pose2D:
        """The waypoint in force: the environment's goal in a plain episode."""
        return record.mission.goal if record.mission is not None else record.environment.goal

    def _check_end(self, record: _Record, live: _Live, reached: bool, now: float,
                   distance: float) -> None:
        config = record.config
        recorder = record.recorder
        mission = record.mission
        if mission is None:  # reset() sets it whenever it builds a simulation
            raise EpisodeError('no mission: reset() has not built a valid episode')
        if config.collision_limit and recorder.collisions >= config.collision_limit:
            self._end(Outcome.COLLISION_LIMIT,
                      f'{recorder.collisions} collisions reached the limit of '
                      f'{config.collision_limit} at {now:.2f} s')
            return
        event = mission.update(now, reached, distance, math.hypot(*live.velocity),
                               config.control_period)
        if event is MissionEvent.COMPLETE:
            if mission.legs > 1:
                self._end(Outcome.GOAL_REACHED,
                          f'completed the mission: reached home, the last of {mission.legs} '
                          f'waypoints, within {live.goal_tolerance:.2f} m at {now:.2f} s')
            else:
                self._end(Outcome.GOAL_REACHED,
                          f'reached the goal within {live.goal_tolerance:.2f} m at {now:.2f} s')
            return
        if event is MissionEvent.NEXT_LEG:
            live.progress = live.leg_progress[mission.leg]
            live.best_progress = self._progress_distance(record, live)
        if event is not MissionEvent.NONE:
            live.last_progress_time = now  # arriving and setting off are progress
        if now >= live.time_limit - 1e-9:
            self._end(Outcome.TIMEOUT, f'time limit of {live.time_limit:.2f} s reached, '
                                       f'{self._distance_to_goal(record):.2f} m from the goal')
        elif mission.dwelling and distance <= live.goal_tolerance:
            live.last_progress_time = now  # dwelling at a station is not being stuck
        elif config.stuck_timeout > 0:
            progress = self._progress_distance(record, live)
            if progress < live.best_progress:
                live.best_progress = progress
                live.last_progress_time = now
            elif self._agent_nearby(live):
                # Waiting for an agent that blocks the way is not stuck (the time limit
                # still bounds the wait).
                live.last_progress_time = now
            elif now - live.last_progress_time >= config.stuck_timeout - 1e-9:
                self._end(Outcome.STUCK,
                          f'no progress toward the goal for {config.stuck_timeout:.2f} s; '
                          f'stopped {self._distance_to_goal(record):.2f} m from it at '
                          f'{now:.2f} s')

    def _record_contacts(self, recorder: MetricsRecorder, partners: set[int], time: float,
                         x: float, y: float,
                         velocities: tuple[tuple[float, float], ...]) -> None:
        """Record one physics step's contacts, attributing each (see sessgan_sim.metrics).

        While an agent drives into the robot (and CONTACT_DEBOUNCE after), whatever else the
        robot touches is that agent's doing too: it was shoved."""
        agents = self._agents
        touches_static = False
        for body in partners:
            agent = agents.index_of(body)
            if agent is None:
                touches_static = True
                continue
            dx, dy = agents.positions[agent, 0] - x, agents.positions[agent, 1] - y
            distance = math.hypot(dx, dy) or 1e-9
            # The robot drove into the agent if, just before or during the contact step, it
            # moved toward it faster than a standing robot would.
            approach = max((vx * dx + vy * dy) / distance for vx, vy in velocities)
            pushed = self._pushed_by is not None and time <= self._pushed_until
            if approach > STANDING_SPEED and not pushed:
                kind = ContactKind.ROBOT_INTO_AGENT
            else:
                kind = ContactKind.AGENT_INTO_ROBOT
                self._pushed_by, self._pushed_until = agent, time + CONTACT_DEBOUNCE
            recorder.record_contact(time, agent, kind, x, y)
        if touches_static:
            # Shoved into a wall by an agent: the agent's doing (its index names it).
            if self._pushed_by is not None and time <= self._pushed_until:
                recorder.record_contact(time, -1, ContactKind.AGENT_INTO_ROBOT, x, y)
            else:
                recorder.record_contact(time, -1, ContactKind.STATIC, x, y)

    @staticmethod
    def _progress_field(grid: CertificateGrid, leg_start: Pose2D, leg_goal: Pose2D,
                        feasible: bool, robot: Robot, route_need: float) -> ProgressField:
        """The ProgressField of one leg (a plain episode's one leg: start to goal)."""
        goal = grid.cell_of(leg_goal.x, leg_goal.y)
        start = grid.cell_of(leg_start.x, leg_start.y)
        clearance = grid.clearance
        # Diagonal steps: a diagonal gap the robot passes must not look like a detour.
        steps = distance_field(clearance >= route_need - 1e-9, goal, diagonal=True)
        route = descend(steps, start) if feasible else []
        if not route:
            return ProgressField(grid, distance_field(
                clearance >= robot.footprint_radius * 0.75, goal, diagonal=True), [])
        band = (clearance > 0.0) & ~np.isfinite(steps)
        for _ in range(int(math.ceil(route_need / grid.cell_size)) + 1):
            padded = np.pad(steps, 1, constant_values=np.inf)
            nearest = np.minimum.reduce([padded[:-2, 1:-1], padded[2:, 1:-1],
                                         padded[1:-1, :-2], padded[1:-1, 2:]]) + 1.0
            steps = np.where(band, np.minimum(steps, nearest), steps)
        return ProgressField(grid, steps, route)

    @staticmethod
    def _agent_keep_clear(goal: Pose2D, robot: Robot, config: EpisodeConfig,
                          progress: ProgressField, route_need: float
                          ) -> list[tuple[float, float, float]]:
        """Discs (x, y, radius) where agents may neither start nor end a patrol leg: around
        a leg's goal, and on its certified route's narrow passages (where the robot could not
        pass an agent standing there)."""
        agents = config.agents
        discs = [(goal.x, goal.y, agents.min_start_distance)]
        # Narrow: the robot on the route could not pass an agent standing beside it.
        narrow_below = agents.radius + route_need
        reach = agents.radius + robot.footprint_radius
        grid = progress.grid
        step = max(1, len(progress.route) // 400)  # bound the disc count on long routes
        for row, col in progress.route[::step]:
            if grid.clearance[row, col] < narrow_below:
                x, y = grid.centre((row, col))
                discs.append((x, y, reach))
        return discs

    def _agent_nearby(self, live: _Live) -> bool:
        """Whether an agent's body is within AGENT_WAIT_DISTANCE of the robot's body."""
        agents = self._agents
        if not agents.body_ids:
            return False
        x, y = live.robot.position
        gaps = (np.hypot(agents.positions[:, 0] - x, agents.positions[:, 1] - y)
                - agents.config.radius - live.robot.footprint_radius)
        return bool((gaps < AGENT_WAIT_DISTANCE).any())

    def _progress_distance(self, record: _Record, live: _Live) -> float:
        """Distance (m) from the robot to the goal along its ProgressField; inf (never
        progress) where the field does not reach."""
        progress = live.progress
        x, y = live.robot.position
        row, col = progress.grid.cell_of(x, y)
        steps = progress.steps
        if 0 <= row < steps.shape[0] and 0 <= col < steps.shape[1]:
            return float(steps[row, col]) * progress.grid.cell_size
        return math.inf

    def _distance_to_goal(self, record: _Record) -> float:
        environment = record.environment
        goal = self._goal(record)
        if self._live is not None:
            x, y = self._live.robot.position
        else:
            x, y = environment.start.x, environment.start.y
        try:
            distance = math.hypot(x - goal.x, y - goal.y)
        except TypeError:  # an invalid environment may hold anything
            return math.inf
        return distance if math.isfinite(distance) else math.inf

    def _start_overlap(self, environment: Environment, robot: Robot,
                       layout: WorldLayout) -> str | None:
        """Why the robot's footprint at the start overlaps an obstacle, or None."""
        x, y = robot.position
        client = self._world.client
        for other in layout.obstacles_near(x, y, robot.footprint_radius):
            for point in p.getClosestPoints(robot.body_id, other, 0.0, physicsClientId=client):
                if point[8] < -START_OVERLAP_TOLERANCE:
                    kind = layout.kind_of(other)
                    name = kind.value.replace('_', ' ') if kind else 'obstacle'
                    start = environment.start
                    row, col = environment.cell_of(x, y)
                    inside = (' (start inside it)'
                              if int(environment.occupancy[row, col]) not in robot.passable_values
                              else '')
                    return (f'environment {environment.id!r}: the {robot.name} footprint at the '
                            f'start ({start.x:.2f}, {start.y:.2f}) m overlaps a {name} by '
                            f'{-point[8]:.3f} m{inside}')
        return None

    def _observation(self, record: _Record, live: _Live, scan_updated: bool) -> Observation:
        robot = live.robot
        odometry = read_odometry(robot)
        range_finder = live.range_finder
        if range_finder is None:
            return Observation(
                time=self.time, scan=record.scan, scan_updated=scan_updated,
                lidar=record.lidar_info, pose=odometry.pose, twist=odometry.twist,
                goal=self._goal(record), in_contact=record.touching)
        return Observation(
            time=self.time, scan=record.scan, scan_updated=scan_updated,
            lidar=record.lidar_info, pose=odometry.pose, twist=odometry.twist,
            goal=self._goal(record), in_contact=record.touching,
            altitude=robot.altitude, climb_rate=robot.state.vz,
            range_down=range_finder.measure(), range_finder=range_finder.config)

    @staticmethod
    def _support_height(environment: Environment, robot: Robot, layout: WorldLayout) -> float:
        """Height (m) of the tallest low obstacle under the robot's footprint at the start
        (0 on bare ground): a flyer starts landed on it."""
        start = environment.start
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

    def _blank_observation(self) -> Observation:
        """The observation of an episode that could not start: no returns, at the start."""
        record = self._require_record()
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
