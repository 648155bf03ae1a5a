"""Episodes of a built-in controller on the simulator core, in this process, without ROS.

The episode the ROS graph runs in lockstep mode, minus the messages: every control tick the
controller core (from sessgan_controllers' registry) turns the observation into the command
applied during the next tick, as a controller node answering every scan does; a controller
that plans on the map gets the environment's map first, as the node gets the ``map`` topic,
and drives the robot a campaign gives it (the scenario's where it can, else its own: the
tricycle of tricycle_nearness_diagram). The simulator
settings are a simulator worker's (sessgan_sim.simulator_settings.SimulatorSettings; by
default the node's defaults: the scenario's robot, agents and time limit), and the
controller sees its inputs exactly as the node decodes them from the messages
(:func:`node_inputs`: the scan's geometry in float32 as LaserScan carries it, the yaw read
back from the odometry quaternion, STOP once the controller says the goal is reached), so an
in-process episode is, bit for bit, the lockstep episode of a worker running the same
controller node: its failure bags re-simulate to the same result
(``ros2 run sessgan_evolver replay <bag> --resimulate``).

Deterministic: the same environment, seed and settings give the same metrics and trace
(every random choice of the episode derives from the seed; the controllers keep no state
between episodes).

A trace (optional) keeps what a picture or a bag of the episode needs: per tick the robot's
pose and velocity, the command, the agents' positions (and the scans for a bag), and the
episode's contact events as sessgan_sim attributes them (static, robot into agent, agent
into robot).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import numpy as np

from sessgan_controllers.controller_interface import (
    STOP,
    Controller,
    Goal,
    MapAwareController,
    MapData,
    RobotState,
    ScanData,
)
from sessgan_controllers.errors import UnknownControllerError
from sessgan_controllers.registry import ControllerSpec, get_controller
from sessgan_core.environment import Environment
from sessgan_core.quaternion import quaternion_from_yaw, yaw_from_quaternion
from sessgan_core.scenarios import get_scenario
from sessgan_core.validation import require_non_negative
from sessgan_evolver.errors import EpisodeRunnerError
from sessgan_sim.episode import Episode, EpisodeConfig, Observation, TickProfile
from sessgan_sim.errors import EpisodeError
from sessgan_sim.metrics import ContactEvent
from sessgan_sim.robots import create_robot
from sessgan_sim.simulator_settings import SimulatorSettings


def _float32(value: float) -> float:
    return float(np.float32(value))


def node_inputs(observation: Observation) -> tuple[ScanData, RobotState]:
    """The controller's inputs as its node decodes them from the simulator's messages.

    LaserScan carries angle_min, angle_increment, range_min and range_max as float32 and
    Odometry the heading as a quaternion; the controllers' own ``observed()`` passes the
    float64 values through, which is a different (if tiny) input, and a controller's path
    through a cluttered map amplifies any difference within seconds.
    """
    lidar, pose, twist = observation.lidar, observation.pose, observation.twist
    scan = ScanData(np.asarray(observation.scan, dtype=float), _float32(lidar.angle_min),
                    _float32(lidar.angle_increment), _float32(lidar.range_min),
                    _float32(lidar.range_max))
    # The odometry carries the yaw as a quaternion; the node reads it back from it.
    yaw = yaw_from_quaternion(*quaternion_from_yaw(pose.yaw))
    return scan, RobotState(float(pose.x), float(pose.y), yaw, float(twist.vx),
                            float(twist.vy), float(twist.wz), float(observation.altitude),
                            float(observation.climb_rate))


@dataclass
class EpisodeTrace:
    """What happened during an episode, tick by tick (row 0: the state at reset)."""

    times: np.ndarray
    """(n,) sim seconds."""
    poses: np.ndarray
    """(n, 3) robot x, y (m) and yaw (rad) in the map frame."""
    twists: np.ndarray
    """(n, 3) body-frame vx, vy (m/s) and wz (rad/s)."""
    commands: np.ndarray
    """(n - 1, 4) the command applied after row i's observation: vx, vy, wz, vz."""
    agents: np.ndarray
    """(n, agents, 2) agent centres, metres."""
    contacts: list[ContactEvent] = field(default_factory=list)
    """The episode's contact events (sessgan_sim.metrics), in order."""
    scans: np.ndarray | None = None
    """(n, beams) float32 ranges in metres when kept (bags), else None."""
    lidar: dict[str, float] = field(default_factory=dict)
    """angle_min, angle_increment, range_min, range_max, scan_time of the scans."""
    goals: list[tuple[int, float, float, float]] = field(default_factory=list)
    """(row, x, y, yaw) of every goal that went out, the first at row 0: a mission's next
    waypoint goes out before row i's tick is published."""
    robot_radius: float = 0.0
    """m, the robot's footprint circle."""
    agent_radius: float = 0.0
    """m"""
    base_height: float = 0.0
    """m, the robot body's centre above the ground (base_link)."""
    sensor_height: float = 0.0
    """m, the scan plane above the ground (base_scan)."""
    vertical: np.ndarray | None = None
    """(n, 2) a flyer's altitude (m) and climb rate (m/s); None for ground robots."""
    range_down: np.ndarray | None = None
    """(n,) a flyer's downward range readings in metres; None without the sensor."""
    range_finder: dict[str, float] = field(default_factory=dict)
    """field_of_view, min_range, max_range of the downward range sensor."""
    fleet: list[EpisodeTrace] = field(default_factory=list)
    """A fleet episode's robots r1, r2, ... (each with its own poses, scans, commands,
    contacts and goals; their agents are r0's); empty for one robot under test."""

    def summary(self, max_points: int = 400) -> dict[str, Any]:
        """Plain data for episode.json: the trajectory and agent paths thinned to at most
        ``max_points`` rows, the contact events and the geometry."""
        step = max(1, math.ceil(len(self.times) / max_points))
        rows = list(range(0, len(self.times), step))
        if rows and rows[-1] != len(self.times) - 1:
            rows.append(len(self.times) - 1)
        summary = {
            'times': [round(float(t), 4) for t in self.times[rows]],
            'robot': np.round(self.poses[rows], 4).tolist(),
            'agents': np.round(self.agents[rows], 4).tolist(),
            'contacts': [contact.to_dict() for contact in self.contacts],
            'robot_radius': self.robot_radius,
            'agent_radius': self.agent_radius,
        }
        if self.fleet:
            summary['fleet'] = [np.round(other.poses[rows], 4).tolist() for other in self.fleet]
        return summary


@dataclass
class EpisodeRun:
    """One episode's result."""

    metrics: dict[str, Any]
    """EpisodeMetrics as a dict (outcome as a string), plus ``wall_time`` (s) and
    ``bag_path`` ('' unless a bag was written), the fields the campaign stores."""
    trace: EpisodeTrace | None
    wall_time: float
    """Wall seconds of reset and ticks."""


def settings_for_controller(scenario: str, controller: ControllerSpec,
                            settings: SimulatorSettings | None = None) -> SimulatorSettings:
    """``settings`` (default: the defaults) with the robot the campaign's simulators host for
    ``controller`` (campaign_cli): its own where it cannot drive the scenario's (the tricycle
    of tricycle_nearness_diagram)."""
    settings = settings or SimulatorSettings()
    default = get_scenario(scenario).robot
    robot = controller.robot_in(default)
    if not settings.robot and robot != default:
        settings = dataclasses.replace(settings, robot=robot)
    return settings


class EpisodeRunner:
    """Owns one simulator (a pybullet client) and runs episodes one at a time.

    ``controller``: a name of sessgan_controllers' registry ('' = the scenario's);
    ``time_limit``: sim seconds (0 = the settings', else each episode's own as a worker
    gives it); ``settings``: the simulator worker's settings each episode's config is built
    from (default: the node's defaults; only lockstep makes sense in process); ``clock``:
    times each run's ``wall_time`` and the parts of its ticks (:attr:`profile`), e.g.
    ``time.thread_time`` for CPU time.
    """

    def __init__(self, scenario: str, controller: str = '', time_limit: float = 0.0,
                 settings: SimulatorSettings | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        spec = get_scenario(scenario)
        self.scenario = spec.name
        self.controller_name = controller or spec.controller
        try:
            self.controller_spec = get_controller(self.controller_name)
        except UnknownControllerError as err:
            raise EpisodeRunnerError(str(err)) from err
        require_non_negative('time limit (0: the scenario default)', time_limit,
                             EpisodeRunnerError, unit=' s')
        self.settings = settings_for_controller(spec.name, self.controller_spec, settings)
        if self.settings.mode != 'lockstep':
            raise EpisodeRunnerError('in-process episodes are lockstep episodes; the settings '
                                     f'ask for {self.settings.mode!r}')
        self.time_limit = float(time_limit) or float(self.settings.time_limit)
        """Sim seconds of every episode; 0: each episode's own, by the rule a worker applies
        (the scenario's, raised for a long route and a mission: EpisodeConfig.time_limit_for)."""
        config = self.episode_config(0)
        config.validate()
        self.robot = str(config.robot)
        if not self.controller_spec.drives(self.robot):
            raise EpisodeRunnerError(f'controller {self.controller_name!r} does not drive the '
                                     f'{self.robot} robot of the {self.scenario} scenario')
        self._clock = clock
        self._episode: Episode | None = None

    # --- resources --------------------------------------------------------------------------

    def open(self) -> EpisodeRunner:
        if self._episode is None:
            self._episode = Episode(clock=self._clock).open()
        return self

    def close(self) -> None:
        if self._episode is not None:
            self._episode.close()
            self._episode = None

    def __enter__(self) -> EpisodeRunner:
        return self.open()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    @property
    def profile(self) -> TickProfile:
        """Where the last episode spent its time (reset, physics, sensors, metrics, the
        controllers' decisions; the rest of a run is the trace's), in ``clock`` seconds."""
        return self._episode.profile if self._episode is not None else TickProfile()

    # --- episodes ---------------------------------------------------------------------------

    def episode_config(self, seed: int, environment: Environment | None = None
                       ) -> EpisodeConfig:
        """The config of an episode with simulator seed ``seed`` (as a worker builds it for an
        evaluate goal with this runner's time limit), scenario defaults filled in; with
        ``environment``, its time limit as a worker gives it."""
        config = self.settings.episode_config(time_limit=self.time_limit, seed=int(seed))
        if environment is not None and config.time_limit is None:
            top_speed = create_robot(str(config.robot or get_scenario(self.scenario).robot),
                                     config.robot_params).top_speed
            config = dataclasses.replace(
                config, time_limit=config.time_limit_for(environment, top_speed))
        return config.resolved(get_scenario(self.scenario))

    def make_controller(self, environment: Environment) -> Controller:
        """A fresh controller for an episode in ``environment``, set up as its node would be:
        told which robot it drives (a controller of several), given the map as the ``map``
        topic carries it (a controller that plans on one), reset for the new goal."""
        spec = self.controller_spec
        controller = spec.make(robot=self.robot) if spec.robots else spec.make()
        if isinstance(controller, MapAwareController):
            # OccupancyGrid carries the resolution as float32.
            controller.set_map(MapData(np.asarray(environment.occupancy, dtype=np.int8),
                                       _float32(environment.resolution),
                                       (float(environment.origin[0]),
                                        float(environment.origin[1]))))
        controller.reset()
        return controller

    def run(self, environment: Environment, seed: int, trace: bool = False,
            keep_scans: bool = False) -> EpisodeRun:
        """Run one episode of ``environment`` with simulator seed ``seed``.

        ``trace``: also return an :class:`EpisodeTrace`; ``keep_scans``: with the scans
        (needed for a bag; about 1.4 KB a tick).
        """
        if environment.scenario != self.scenario:
            raise EpisodeRunnerError(f'environment {environment.id!r} is a '
                                     f'{environment.scenario} map; this runner tests the '
                                     f'{self.scenario} scenario')
        self.open()
        episode = self._episode
        assert episode is not None
        # A fleet's robots each get a controller of their own, as each gets its own node.
        controllers = [self.make_controller(environment) for _ in range(environment.robots)]
        started = self._clock()
        episode.reset(environment, self.episode_config(seed, environment))
        observations = episode.observations()
        goals = [Goal(each.goal.x, each.goal.y) for each in observations]
        recorders = ([_TraceRecorder(episode, each, keep_scans, index)
                      for index, each in enumerate(observations)] if trace else [])
        goal_reached = [False] * len(observations)
        clock = self._clock
        while not episode.done:
            deciding = clock()
            commands = []
            for index, (controller, each) in enumerate(zip(controllers, observations)):
                if (each.goal.x, each.goal.y) != (goals[index].x, goals[index].y):
                    # A mission's next waypoint: as the controller node takes a new goal_pose.
                    goals[index] = Goal(each.goal.x, each.goal.y)
                    goal_reached[index] = False
                    controller.reset()
                scan, state = node_inputs(each)
                # As the controller node: STOP from the first tick the controller says the
                # goal is reached, and for a non-finite command.
                goal_reached[index] = (goal_reached[index]
                                       or controller.goal_reached(state, goals[index]))
                command = (STOP if goal_reached[index]
                           else controller.compute_command(scan, state, goals[index]))
                commands.append((command if command.is_finite() else STOP).values())
            episode.profile.controller += clock() - deciding
            observations = [result.observation for result in episode.step_fleet(commands)]
            for recorder, each, values in zip(recorders, observations, commands):
                recorder.add(each, values)
        wall_time = self._clock() - started
        result = episode.metrics()
        metrics = result.to_dict()
        metrics['wall_time'] = wall_time
        metrics['bag_path'] = ''
        metrics['bag_error'] = ''
        episode_trace = None
        if recorders:
            traces = [recorder.finish(list(episode.robot_metrics(index).contacts))
                      for index, recorder in enumerate(recorders)]
            episode_trace, episode_trace.fleet = traces[0], traces[1:]
        return EpisodeRun(metrics, episode_trace, wall_time)


class _TraceRecorder:
    """Collects an EpisodeTrace while an episode runs."""

    def __init__(self, episode: Episode, observation: Observation, keep_scans: bool,
                 robot: int = 0) -> None:
        self.episode = episode
        self.keep_scans = keep_scans
        self.times: list[float] = []
        self.poses: list[tuple[float, float, float]] = []
        self.twists: list[tuple[float, float, float]] = []
        self.commands: list[tuple[float, float, float, float]] = []
        self.vertical: list[tuple[float, float]] = []
        self.range_down: list[float] = []
        self.range_finder = observation.range_finder
        self.agents: list[np.ndarray] = []
        self.scans: list[np.ndarray] = []
        try:
            body = episode.robots[robot]
            self.robot_radius = float(body.footprint_radius)
            self.base_height = float(body.ride_height)
            self.sensor_height = float(body.sensor_height)
        except EpisodeError:  # an episode that could not start has no robot
            self.robot_radius = self.base_height = self.sensor_height = 0.0
        self.agent_radius = float(episode.agents.config.radius)
        self.goals: list[tuple[int, float, float, float]] = []
        self._observe(observation)

    def _observe(self, observation: Observation) -> None:
        pose, twist = observation.pose, observation.twist
        goal = observation.goal
        if not self.goals or self.goals[-1][1:] != (goal.x, goal.y, goal.yaw):
            self.goals.append((len(self.times), float(goal.x), float(goal.y), float(goal.yaw)))
        self.times.append(float(observation.time))
        self.poses.append((float(pose.x), float(pose.y), float(pose.yaw)))
        self.twists.append((float(twist.vx), float(twist.vy), float(twist.wz)))
        self.vertical.append((float(observation.altitude), float(observation.climb_rate)))
        if observation.range_down is not None:
            self.range_down.append(float(observation.range_down))
        self.agents.append(np.array(self.episode.agents.positions, dtype=float).reshape(-1, 2))
        if self.keep_scans:
            self.scans.append(np.array(observation.scan, dtype=np.float32))

    def add(self, observation: Observation,
            command: tuple[float, float, float, float]) -> None:
        self.commands.append(command)
        self._observe(observation)

    def finish(self, contacts: list[ContactEvent]) -> EpisodeTrace:
        lidar = self.episode.lidar_info
        agent_count = max((len(a) for a in self.agents), default=0)
        agents = np.zeros((len(self.agents), agent_count, 2))
        for row, positions in enumerate(self.agents):
            agents[row, :len(positions)] = positions
        return EpisodeTrace(
            times=np.array(self.times), poses=np.array(self.poses).reshape(-1, 3),
            twists=np.array(self.twists).reshape(-1, 3),
            commands=np.array(self.commands).reshape(-1, 4), agents=agents,
            contacts=contacts,
            scans=np.stack(self.scans) if self.keep_scans and self.scans else None,
            lidar={'angle_min': float(lidar.angle_min),
                   'angle_increment': float(lidar.angle_increment),
                   'range_min': float(lidar.range_min), 'range_max': float(lidar.range_max),
                   'scan_time': float(lidar.scan_time)},
            robot_radius=self.robot_radius, agent_radius=self.agent_radius,
            base_height=self.base_height, sensor_height=self.sensor_height,
            vertical=np.array(self.vertical).reshape(-1, 2) if self.range_finder else None,
            range_down=np.array(self.range_down) if self.range_finder else None,
            range_finder=({'field_of_view': self.range_finder.field_of_view,
                           'min_range': self.range_finder.min_range,
                           'max_range': self.range_finder.max_range}
                          if self.range_finder else {}),
            goals=self.goals)
