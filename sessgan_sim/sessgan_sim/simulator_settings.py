"""Every setting of a simulator worker, validated in one place, without ROS.

The simulator node declares one ROS parameter per field of :class:`SimulatorSettings` (same
name, same default, the field's docstring as its description), turns the parameter values into
settings with :meth:`SimulatorSettings.from_values` (which names the parameter at fault) and
builds each episode's :class:`~sessgan_sim.episode_config.EpisodeConfig` with
:meth:`SimulatorSettings.episode_config`. Failure bags record :meth:`SimulatorSettings.to_dict`
and the resolved episode config (:func:`episode_config_record`), so ``replay --resimulate``
rebuilds the same simulator (:func:`resimulation_settings`).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, get_type_hints

from sessgan_core.errors import InvalidFleetError, InvalidMissionError, SessganCoreError
from sessgan_core.fleet import FleetSpec
from sessgan_core.json_data import to_json_data
from sessgan_core.missions import DEFAULT_DWELL_TIME, MissionSpec
from sessgan_core.scenarios import get_scenario
from sessgan_core.validation import require_non_negative, require_positive
from sessgan_sim.agents import AGENT_BEHAVIOURS, AgentConfig
from sessgan_sim.bag_recording import BagStorage, check_record_subdirectory
from sessgan_sim.command_pace import PaceRule
from sessgan_sim.episode_config import EpisodeConfig, check_time_limit
from sessgan_sim.errors import BagWriteError, InvalidConfigError, SessganSimError
from sessgan_sim.robots import create_robot, get_robot_class
from sessgan_sim.sensors import LidarConfig


class StepMode(StrEnum):
    """How the simulator advances time."""

    LOCKSTEP = 'lockstep'
    """Publish a tick's data, wait for the controller's answer, then advance (one command per
    tick; for controllers that answer every scan)."""
    CLOCKED = 'clocked'
    """Advance /clock at ``real_time_factor`` and apply the latest command (for stacks with
    their own timers, like Nav2)."""


class GoalInterface(StrEnum):
    """How each episode's goal reaches the stack under test."""

    GOAL_POSE = 'goal_pose'
    """geometry_msgs/PoseStamped on ``goal_pose`` (reliable, transient local, depth 1)."""
    NAVIGATE_TO_POSE = 'navigate_to_pose'
    """A nav2_msgs/action/NavigateToPose goal on the ``navigate_to_pose`` action server."""
    BOTH = 'both'
    """The topic and the action goal."""

    @property
    def uses_topic(self) -> bool:
        return self in (GoalInterface.GOAL_POSE, GoalInterface.BOTH)

    @property
    def uses_action(self) -> bool:
        return self in (GoalInterface.NAVIGATE_TO_POSE, GoalInterface.BOTH)


STRUCTURAL_SETTINGS = frozenset({'use_stamped_cmd_vel', 'free_mode', 'sim_time_origin',
                                 'bags_root'})
"""Settings fixed at start-up: the cmd_vel type, the free-mode subscription and the clock's
starting point cannot change while the node runs; nor can the bags root (no client may move
where the simulator writes)."""

EPISODE_SETTINGS = frozenset({
    'robot', 'robot_params', 'time_limit', 'control_rate', 'physics_rate', 'lidar_beams',
    'lidar_fov_deg', 'lidar_range_min', 'lidar_range_max', 'lidar_rate', 'lidar_noise_std',
    'dummy_agents', 'agent_speed', 'agent_behaviour', 'stuck_timeout', 'collision_limit',
    'goal_tolerance'})
"""Settings that shape an episode's simulation (its EpisodeConfig); the others say how the
node steps, talks to the stack under test and records."""


@dataclass(frozen=True)
class SimulatorSettings:
    """The simulator node's parameters (ROS parameters of the same names). Units: seconds,
    metres, hertz, degrees where the name says so."""

    mode: str = StepMode.LOCKSTEP.value
    """Stepping mode: lockstep (wait for the controller's answer to every tick) or clocked
    (advance /clock at real_time_factor, use the latest command; for Nav2)."""
    real_time_factor: float = 1.0
    """Clocked mode: sim seconds per wall second."""
    controller_timeout: float = 2.0
    """Wall seconds without a cmd_vel that end an episode as controller_unresponsive (in
    clocked mode after a stop command: at least the stuck window, stuck_timeout sim s)."""
    controller_startup_timeout: float = 15.0
    """Wall seconds allowed for the first cmd_vel (and for a controller to appear)."""
    expected_command_period: float = 0.0
    """Clocked mode: the stack's command period in sim seconds (0.05 for a 20 Hz controller),
    against which late commands are measured; 0: the median of its first 10 gaps."""
    overload_gap_factor: float = 3.0
    """Clocked mode: a gap between commands longer than this many command periods is late."""
    overload_late_share: float = 0.1
    """Clocked mode: an episode whose late gaps cover more than this share of its sim time
    (or with one gap over 40 periods) ends as overloaded, a harness outcome that is run
    again; 1: never."""
    use_stamped_cmd_vel: bool = False
    """Read geometry_msgs/TwistStamped on cmd_vel instead of Twist (fixed at start-up)."""
    goal_interface: str = GoalInterface.GOAL_POSE.value
    """How the goal is sent: goal_pose (topic), navigate_to_pose (NavigateToPose action goal)
    or both."""
    reset_costmaps: bool = False
    """Before each episode call Nav2's ClearEntireCostmap services
    global_costmap/clear_entirely_global_costmap and local_costmap/clear_entirely_local_costmap."""
    stack_timeout: float = 5.0
    """Wall seconds each reset call, and the NavigateToPose goal's acceptance, may take; past it
    the episode ends as controller_unresponsive with the reason in its detail."""
    sim_time_origin: float = 0.0
    """Sim time of the first episode's first tick; every later episode starts one control
    period after the previous one ended, so /clock never goes back (fixed at start-up)."""
    scenario: str = 'factory'
    """Scenario of free-mode maps (the evaluate action names its own)."""
    robot: str = ''
    """Robot model (diff_drive, car, flyer); empty: each scenario's robot."""
    robot_params: str = ''
    """Overrides of the robot model's parameters, 'name=value,name=value' (e.g.
    'max_linear_speed=0.5'); empty: the model's defaults."""
    time_limit: float = 0.0
    """Sim seconds per episode; 0: the scenario's."""
    control_rate: float = 20.0
    """Hz of scan, odom and commands (control ticks per sim second)."""
    physics_rate: float = 100.0
    """Hz of physics steps (at least the control rate)."""
    lidar_beams: int = 360
    """Beams per scan."""
    lidar_fov_deg: float = 360.0
    """Field of view in degrees, centred on the robot's heading."""
    lidar_range_min: float = 0.12
    """Shortest range reported, metres."""
    lidar_range_max: float = 10.0
    """Longest range reported, metres."""
    lidar_rate: float = 0.0
    """Scans per sim second; 0: the control rate."""
    lidar_noise_std: float = 0.01
    """Standard deviation of the range noise, metres."""
    dummy_agents: int = -1
    """Moving dummy agents; -1: the scenario's."""
    agent_speed: float = 0.5
    """Speed of the dummy agents, m/s."""
    agent_behaviour: str = 'blind'
    """'blind' agents drive on whatever is ahead; 'cautious' ones wait while the robot or
    another agent is within 0.5 m ahead (an AGV with a safety scanner)."""
    stuck_timeout: float = 30.0
    """Sim seconds neither closer to the goal nor onto new ground that end an episode as stuck;
    0 disables. Room for a stack's recoveries after its progress checker gives up (Nav2's:
    10 s); until 2026-11-28 it was 10."""
    collision_limit: int = 10
    """Collisions that end an episode (collision_limit); 0 disables."""
    goal_tolerance: float = 0.0
    """m between the robot's centre and the goal that count as reached (heading not judged,
    the robot need not stop); 0: one map cell of the scenario (0.5 m in the factory)."""
    free_mode: bool = False
    """Run an episode for every map on the environment topic (fixed at start-up)."""
    seed: int = 0
    """Seed of the first free-mode episode (each later one uses the next)."""
    mission_stations: int = 0
    """Free mode: mission stations (pick-up, place, ...) drawn before home on every map;
    0: plain start -> goal episodes. The evaluate action's environments bring their own."""
    station_dwell_time: float = DEFAULT_DWELL_TIME
    """Free mode: sim seconds the robot stands still at each station (loading)."""
    robots: int = 1
    """Free mode: robots under test on every map (a fleet episode: r1, r2, ... drawn beside
    the map's own start and goal); 1: one robot. The evaluate action's environments bring
    their own fleet."""
    bags_root: str = 'bags'
    """Directory under which every failure bag is written; relative: to the simulator's
    working directory (fixed at start-up). An evaluate goal's record_directory, and
    record_directory below, name a subdirectory of it."""
    record_directory: str = ''
    """Free mode: subdirectory of bags_root for failure bags (e.g. 'free'); empty: none."""
    bag_storage: str = BagStorage.MCAP.value
    """Failure bag storage: mcap or sqlite3."""

    # ---- construction -----------------------------------------------------------------------

    @classmethod
    def from_values(cls, values: Mapping[str, Any]) -> SimulatorSettings:
        """Settings from parameter values (defaults for missing names), validated.

        InvalidConfigError names the parameter at fault: an unknown name, a value of the wrong
        type or out of range.
        """
        known = {item.name: item for item in dataclasses.fields(cls)}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise InvalidConfigError(f'unknown simulator parameter(s) {unknown}; known: '
                                     f'{sorted(known)}')
        hints = get_type_hints(cls)
        converted = {name: _converted(name, hints[name], value)
                     for name, value in values.items()}
        settings = cls(**converted)
        settings.validate()
        return settings

    @classmethod
    def field_types(cls) -> dict[str, type]:
        """Python type (bool, int, float or str) of each setting."""
        return dict(get_type_hints(cls))

    # ---- validation -------------------------------------------------------------------------

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first parameter that cannot work."""
        _one_of('mode', self.mode, StepMode)
        _one_of('goal_interface', self.goal_interface, GoalInterface)
        _one_of('bag_storage', self.bag_storage, BagStorage)
        for name in ('real_time_factor', 'controller_timeout', 'controller_startup_timeout',
                     'stack_timeout', 'control_rate', 'physics_rate', 'lidar_range_max',
                     'agent_speed'):
            _positive(name, getattr(self, name))
        for name in ('sim_time_origin', 'time_limit', 'lidar_rate', 'lidar_noise_std',
                     'lidar_range_min', 'stuck_timeout', 'goal_tolerance'):
            _not_negative(name, getattr(self, name))
        self.pace_rule()
        check_time_limit(self.time_limit, "parameter 'time_limit'")
        for name in ('collision_limit', 'seed'):
            if getattr(self, name) < 0:
                raise InvalidConfigError(f'parameter {name!r} must be >= 0, got '
                                         f'{getattr(self, name)}')
        if not self.bags_root:
            raise InvalidConfigError("parameter 'bags_root' must name a directory, got ''")
        if self.record_directory:
            try:
                check_record_subdirectory(self.record_directory)
            except BagWriteError as err:
                raise InvalidConfigError(f"parameter 'record_directory': {err}") from err
        if self.agent_behaviour not in AGENT_BEHAVIOURS:
            raise InvalidConfigError(f"parameter 'agent_behaviour' must be one of "
                                     f"{', '.join(AGENT_BEHAVIOURS)}; got "
                                     f'{self.agent_behaviour!r}')
        try:
            self.mission()
        except InvalidMissionError as err:
            raise InvalidConfigError(f'parameter {err}') from err
        try:
            self.fleet()
        except InvalidFleetError as err:
            raise InvalidConfigError(f'parameter {err}') from err
        if self.dummy_agents < -1:
            raise InvalidConfigError(f"parameter 'dummy_agents' must be >= 0, or -1 for the "
                                     f"scenario's, got {self.dummy_agents}")
        if not 1 <= self.lidar_beams <= 16384:
            raise InvalidConfigError(f"parameter 'lidar_beams' must be in 1..16384, got "
                                     f'{self.lidar_beams}')
        if not 0 < self.lidar_fov_deg <= 360:
            raise InvalidConfigError(f"parameter 'lidar_fov_deg' must be in (0, 360], got "
                                     f'{self.lidar_fov_deg}')
        if self.lidar_range_max <= self.lidar_range_min:
            raise InvalidConfigError(
                f"parameter 'lidar_range_max' ({self.lidar_range_max}) must exceed "
                f"'lidar_range_min' ({self.lidar_range_min})")
        if self.physics_rate < self.control_rate:
            raise InvalidConfigError(
                f"parameter 'physics_rate' ({self.physics_rate}) must be at least "
                f"'control_rate' ({self.control_rate})")
        try:
            get_scenario(self.scenario)
        except SessganCoreError as err:
            raise InvalidConfigError(f"parameter 'scenario': {err}") from err
        overrides = self.robot_param_values()
        if self.robot:
            try:
                get_robot_class(self.robot)
                create_robot(self.robot, overrides)
            except SessganSimError as err:
                raise InvalidConfigError(f"parameter 'robot'/'robot_params': {err}") from err
        try:
            self.episode_config().validate()
        except SessganSimError as err:  # anything the checks above let through
            raise InvalidConfigError(f'simulator parameters: {err}') from err

    def robot_param_values(self) -> dict[str, float]:
        """``robot_params`` as {name: value}; InvalidConfigError for a malformed entry."""
        values: dict[str, float] = {}
        for entry in filter(None, (part.strip() for part in self.robot_params.split(','))):
            name, separator, text = entry.partition('=')
            name = name.strip()
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not separator or not name or not math.isfinite(value):
                raise InvalidConfigError(
                    f"parameter 'robot_params': {entry!r} is not name=number (expected e.g. "
                    "'max_linear_speed=0.5,max_angular_speed=1.5')")
            if name in values:
                raise InvalidConfigError(f"parameter 'robot_params' sets {name!r} twice")
            values[name] = value
        return values

    # ---- use --------------------------------------------------------------------------------

    def mission(self) -> MissionSpec:
        """The free-mode mission, validated (InvalidMissionError names the parameter)."""
        return MissionSpec(self.mission_stations, self.station_dwell_time).validate()

    def fleet(self) -> FleetSpec:
        """The free-mode fleet, validated (InvalidFleetError names the parameter)."""
        return FleetSpec(self.robots).validate(self.mission_stations)

    def pace_rule(self) -> PaceRule:
        """Clocked mode's rule for a stack that could not keep pace, validated
        (InvalidConfigError names the parameter)."""
        return PaceRule(expected_period=self.expected_command_period,
                        gap_factor=self.overload_gap_factor,
                        late_share=self.overload_late_share).validate()

    @property
    def step_mode(self) -> StepMode:
        return StepMode(self.mode)

    @property
    def goal_via(self) -> GoalInterface:
        return GoalInterface(self.goal_interface)

    def episode_config(self, robot: str = '', time_limit: float = 0.0,
                       seed: int = 0) -> EpisodeConfig:
        """The core config of one episode; ``robot`` and ``time_limit`` (an evaluate goal's)
        override the settings' when given. None fields take the scenario's defaults."""
        return EpisodeConfig(
            robot=robot or self.robot or None,
            robot_params=self.robot_param_values(),
            control_rate_hz=float(self.control_rate),
            physics_rate_hz=float(self.physics_rate),
            time_limit=float(time_limit or self.time_limit) or None,
            lidar=LidarConfig(
                beams=int(self.lidar_beams), field_of_view=math.radians(self.lidar_fov_deg),
                range_min=float(self.lidar_range_min), range_max=float(self.lidar_range_max),
                rate_hz=float(self.lidar_rate or self.control_rate),
                noise_std=float(self.lidar_noise_std)),
            dummy_agents=None if self.dummy_agents < 0 else int(self.dummy_agents),
            agents=AgentConfig(speed=float(self.agent_speed), behaviour=self.agent_behaviour),
            stuck_timeout=float(self.stuck_timeout),
            collision_limit=int(self.collision_limit),
            goal_tolerance=float(self.goal_tolerance) or None,
            seed=int(seed),
        )

    def to_dict(self) -> dict[str, Any]:
        """Every setting by parameter name (what episode.json records)."""
        return dataclasses.asdict(self)

    def changed_from_defaults(self) -> dict[str, Any]:
        """The settings that differ from the defaults, by parameter name."""
        defaults = SimulatorSettings()
        return {name: value for name, value in self.to_dict().items()
                if getattr(defaults, name) != value}


def episode_config_record(config: EpisodeConfig) -> dict[str, Any]:
    """A resolved episode config as JSON data, with the robot model's complete parameters
    (defaults and overrides) under ``robot_params``."""
    record = to_json_data(dataclasses.asdict(config))
    if config.robot:
        try:
            params = create_robot(config.robot, config.robot_params).params
        except SessganSimError:
            params = None  # an invalid robot ends the episode as invalid_environment
        if params is not None:
            record['robot_params'] = to_json_data(dataclasses.asdict(params))
    return record


def resimulation_settings(episode: Mapping[str, Any]) -> tuple[SimulatorSettings, list[str]]:
    """The settings that rebuild the simulator an episode.json was recorded with, and notes
    for the user (what cannot be exact).

    The recorded settings are taken as they were, except what only concerns the recording
    worker (free mode, its bags root and record directory); the clock starts at the recorded
    origin.
    InvalidConfigError when the recorded settings are unusable, or when they no longer give
    the recorded episode config (a bag of another software version).
    """
    notes: list[str] = []
    recorded = episode.get('simulator')
    if not isinstance(recorded, Mapping):
        notes.append('episode.json records no simulator settings (an older bag): '
                     're-simulating with the default simulator')
        recorded = {}
    values = {name: value for name, value in recorded.items()
              if name not in ('free_mode', 'bags_root', 'record_directory')}
    values['sim_time_origin'] = float(episode.get('sim_time_origin', 0.0) or 0.0)
    settings = SimulatorSettings.from_values(values)
    if settings.step_mode is StepMode.CLOCKED:
        notes.append('recorded in clocked mode: commands depend on wall-clock timing, so the '
                     're-simulation can differ from the recording')
    expected = episode.get('episode_config')
    if isinstance(expected, Mapping):
        scenario = get_scenario(str(episode.get('scenario', settings.scenario)))
        rebuilt = settings.episode_config(
            robot=str(episode.get('robot') or ''),
            time_limit=float(episode.get('time_limit') or 0.0),
            seed=int(episode.get('episode_seed', 0))).resolved(scenario)
        differing = sorted(key for key, value in episode_config_record(rebuilt).items()
                           if expected.get(key) != value)
        if differing:
            raise InvalidConfigError(
                f'the recorded episode config differs in {differing} from what these settings '
                'build now (a bag of another software version?): an exact re-simulation is '
                'not possible')
    return settings, notes


# ---- conversion helpers ---------------------------------------------------------------------


def _converted(name: str, kind: type, value: Any) -> Any:
    """``value`` as the setting's type; InvalidConfigError naming the parameter otherwise."""
    if kind is bool:
        if isinstance(value, bool):
            return value
        expected = 'true or false'
    elif kind is int:
        if isinstance(value, numbers.Integral) and not isinstance(value, bool):
            return int(value)
        expected = 'an integer'
    elif kind is float:
        if isinstance(value, numbers.Real) and not isinstance(value, bool):
            if math.isfinite(value):
                return float(value)
            expected = 'a finite number'
        else:
            expected = 'a number'
    else:
        if isinstance(value, str):
            return value
        expected = 'a string'
    raise InvalidConfigError(f'parameter {name!r} must be {expected}, got {value!r}')


def _one_of(name: str, value: str, choices: type[StrEnum]) -> None:
    allowed = [choice.value for choice in choices]
    if value not in allowed:
        raise InvalidConfigError(f'parameter {name!r} must be one of {", ".join(allowed)}; '
                                 f'got {value!r}')


def _positive(name: str, value: float) -> None:
    require_positive(f'parameter {name!r}', value, InvalidConfigError)


def _not_negative(name: str, value: float) -> None:
    require_non_negative(f'parameter {name!r}', value, InvalidConfigError)
