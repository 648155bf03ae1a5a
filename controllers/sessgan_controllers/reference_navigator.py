"""The reference navigator: a default Nav2 set-up in one ROS-free controller, for every robot.

What a user's stack typically is, so that a campaign against it shows what a test
generator finds in a competent planner-based navigator:

* **Global planner** (Nav2's planner_server with a costmap): the episode's map
  (:meth:`ReferenceNavigator.set_map`) is inflated into a costmap
  (:mod:`~sessgan_controllers.costmap`: lethal where the footprint touches, an
  expensive inscribed band of ``safety_margin``, then Nav2's exponential cost decay) and
  searched with A* (:mod:`~sessgan_controllers.path_planning`); the path is shortened
  and smoothed where that keeps clearance.
* **Obstacle layer**: what the scan sees that the map does not explain (dummy agents,
  other robots) is marked in the costmap and cleared again by ray tracing.
* **Replanning** (Nav2's default behaviour tree replans at 1 Hz): at most once per
  ``replan_interval`` steps, when there is no path yet, when the goal changed, when the
  robot strayed more than ``replan_deviation`` from the path, when a mark makes the path
  ahead lethal (within ``blocked_horizon``), and every ``replan_period`` steps while marks
  lie near the path (to go around an agent and come back once it is gone; such a plan
  replaces the path only when it is ``replan_improvement`` shorter).
* **Local controller** (:mod:`~sessgan_controllers.path_following`), chosen by ``robot``:

  - ``diff_drive``: Nav2's RotationShimController (turn in place while the carrot is more
    than ``rotate_start_angle`` off the heading) around Regulated Pure Pursuit: lookahead
    ``speed * lookahead_time`` clamped to [``lookahead_min``, ``lookahead_max``], speed
    limited by the path's curvature profile, the carrot arc's curvature, obstacle
    proximity and the approach to the goal;
  - ``car``: pure pursuit for the bicycle model (``wz = v * curvature``, curvature capped by
    the steering lock) with a curvature-based speed profile along the path that starts
    braking ``v^2 / (2 * deceleration)`` before each sharp turn;
  - ``flyer``: the same pursuit in 2-D with (vx, vy) towards the carrot, yaw turned along
    the motion. It starts landed: it first climbs in place to ``cruise_altitude`` and
    navigates only above ``takeoff_altitude`` (:mod:`~sessgan_controllers.altitude_control`),
    where low obstacles (50) lie below it and are passable for its planner; every command
    holds the cruise altitude (``linear.z``). Below the take-off altitude the scan is not
    marked: the low obstacles it sees there are on the map and will be below it.

  For every robot the speed is also limited so that it can stop (at ``deceleration``)
  ``stop_margin`` before the first point of the path ahead that an unexplained return
  blocks (closer than ``robot_radius + collision_margin + dynamic_margin``: it may move),
  so that it stops ``monitor_distance`` from the nearest unexplained return ahead of it
  (Nav2's collision monitor), and scaled down near any return ahead
  (``slowdown_distance``).
* **No path** (the goal is walled in, or an agent blocks the only passage): the robot
  stands still, keeps its marks clearing, and tries again every ``replan_interval``
  steps. Commands are always finite.

Robot-dependent parameters default to 0, meaning the preset of the chosen ``robot``
(:data:`ROBOT_PRESETS`, matched to sessgan_sim's robot models).

As a node: ``ros2 run sessgan_controllers reference_navigator --ros-args -p robot:=car
-p use_sim_time:=true`` (``diff_drive`` is the default) answers every scan of a lockstep
simulator; against a clocked one it runs on its own timer like Nav2's controller server:
``-p control_mode:=timer -p control_rate_hz:=20.0``, and under a namespace ``-r
/clock:=clock`` (the simulator publishes its clock in its namespace; a node's sim time comes
from ``/clock``). See :mod:`sessgan_controllers.controller_node`.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sessgan_controllers.altitude_control import AltitudeHold, with_climb
from sessgan_controllers.controller_interface import (
    STOP,
    Goal,
    MapData,
    RobotState,
    ScanData,
    VelocityCommand,
    parameter,
    wrap_angle,
)
from sessgan_controllers.costmap import FREE, LOW_OBSTACLE, Costmap, CostmapConfig
from sessgan_controllers.errors import InvalidConfigError
from sessgan_controllers.path_following import (
    CarLimits,
    DiffDriveLimits,
    HolonomicLimits,
    PathTracker,
    braking_speed,
    follow_car,
    follow_diff_drive,
    follow_holonomic,
    free_distance,
    nearest_gap_ahead,
    proximity_factor,
    speed_profile,
    swept_points,
    to_body,
)
from sessgan_controllers.path_planning import Path, PlannerConfig, PlanningError, plan_path
from sessgan_core.validation import require_non_negative, require_positive

ROBOTS = ('diff_drive', 'car', 'flyer')

ROBOT_PRESETS: dict[str, dict[str, float]] = {
    'diff_drive': dict(
        robot_radius=0.2, safety_margin=0.1, inflation_radius=0.5, cost_scaling_factor=6.0,
        planning_resolution=0.1, path_spacing=0.05, clearance_target=0.3,
        curvature_window=0.3, max_speed=0.7, max_angular_speed=1.8, lateral_acceleration=0.6,
        deceleration=0.8, min_speed=0.1, lookahead_min=0.3, lookahead_max=0.9,
        lookahead_time=1.5, slowdown_distance=0.5, goal_tolerance=0.15, mark_range=3.0,
        blocked_horizon=3.0, replan_deviation=0.5, monitor_distance=0.3, reaction_time=0.1),
    'car': dict(
        robot_radius=0.6, safety_margin=0.3, inflation_radius=2.0, cost_scaling_factor=1.5,
        planning_resolution=0.5, path_spacing=0.25, clearance_target=0.8,
        curvature_window=2.0, max_speed=12.0, max_angular_speed=0.0,
        lateral_acceleration=6.0, deceleration=6.0, min_speed=1.0, lookahead_min=2.0,
        lookahead_max=8.0, lookahead_time=0.6, slowdown_distance=0.3, goal_tolerance=0.5,
        mark_range=10.0, blocked_horizon=20.0, replan_deviation=2.0, monitor_distance=0.5,
        reaction_time=0.15),
    'flyer': dict(
        robot_radius=0.2, safety_margin=0.1, inflation_radius=0.5, cost_scaling_factor=6.0,
        planning_resolution=0.1, path_spacing=0.05, clearance_target=0.3,
        curvature_window=0.4, max_speed=1.2, max_angular_speed=1.5, lateral_acceleration=1.5,
        deceleration=1.5, min_speed=0.1, lookahead_min=0.4, lookahead_max=1.2,
        lookahead_time=0.8, slowdown_distance=0.5, goal_tolerance=0.15, mark_range=3.0,
        blocked_horizon=3.0, replan_deviation=0.5, monitor_distance=0.3, reaction_time=0.35),
}
"""Defaults per robot of the parameters that are 0 in :class:`ReferenceNavigatorConfig`."""

MARKS_NEAR_PATH = 'marks near the path'
"""The reason of a periodic replan (kept only if it shortens the path enough)."""


@dataclass
class ReferenceNavigatorConfig:
    """Parameters of :class:`ReferenceNavigator` (each becomes a ROS parameter). Fields that
    default to 0 take the chosen robot's value from :data:`ROBOT_PRESETS`."""

    robot: str = parameter(
        'diff_drive', "Robot driven: 'diff_drive' (rotation shim + regulated pure pursuit), "
        "'car' (bicycle pure pursuit, curvature speed profile) or 'flyer' (holonomic).")
    robot_radius: float = parameter(0.0, 'Footprint radius in m; 0: robot preset (0.2/0.6/0.2).')
    safety_margin: float = parameter(
        0.0, 'Clearance in m beyond the radius that paths avoid unless there is no other way '
        '(the inscribed band); 0: robot preset.')
    inflation_radius: float = parameter(
        0.0, 'Width in m of the band beyond the inscribed one where the cost decays; 0: preset.')
    cost_scaling_factor: float = parameter(
        0.0, 'Exponential decay rate in 1/m of the inflation cost; 0: robot preset.')
    cost_weight: float = parameter(
        3.0, 'Extra cost per metre at the inner edge of the inflation band (1 = double).')
    inscribed_penalty: float = parameter(
        1000.0, 'Extra cost per metre inside the inscribed band: so high that a path enters it '
        'only where no way round exists (or to leave it).')
    planning_resolution: float = parameter(
        0.0, 'Planning cell size in m (map cells are split into whole sub-cells); 0: preset.')
    path_spacing: float = parameter(0.0, 'Distance in m between path points; 0: preset.')
    clearance_target: float = parameter(
        0.0, 'Clearance in m beyond the radius that shortcuts and smoothing keep (or what the '
        'A* path had, if less); 0: robot preset.')
    curvature_window: float = parameter(
        0.0, 'Arc length in m over which path curvature is measured; 0: robot preset.')
    max_speed: float = parameter(0.0, 'Cruise speed in m/s; 0: robot preset (0.7/12/1.2).')
    max_angular_speed: float = parameter(
        0.0, 'Yaw-rate limit in rad/s (diff_drive: also caps speed on arcs; flyer: heading); '
        '0: robot preset.')
    lateral_acceleration: float = parameter(
        0.0, 'Lateral acceleration in m/s^2 allowed on curves (speed <= sqrt(a / curvature)); '
        '0: robot preset.')
    deceleration: float = parameter(
        0.0, 'Deceleration in m/s^2 planned for braking before turns, obstacles and the goal '
        '(below the robot limit); 0: robot preset.')
    min_speed: float = parameter(
        0.0, 'Speed floor in m/s of the curvature and proximity regulation (not of braking for '
        'an obstacle); 0: robot preset.')
    lookahead_min: float = parameter(0.0, 'Shortest lookahead in m; 0: robot preset.')
    lookahead_max: float = parameter(0.0, 'Longest lookahead in m; 0: robot preset.')
    lookahead_time: float = parameter(
        0.0, 'Lookahead in s of the current speed (clamped to min/max); 0: robot preset.')
    slowdown_distance: float = parameter(
        0.0, 'Gap in m between footprint and the nearest return ahead below which the speed '
        'scales down with the gap (Nav2 cost-regulated scaling); 0: robot preset.')
    min_speed_factor: float = parameter(
        0.3, 'Smallest factor of the proximity scaling (0..1).')
    stop_margin: float = parameter(
        0.15, 'Gap in m kept when braking for something the scan sees on the path.')
    collision_margin: float = parameter(
        0.05, 'Gap in m between footprint and obstacles that the motion towards the carrot must '
        'keep (RPP collision detection); a return the map does not explain closer than radius '
        '+ this + dynamic_margin to a path point blocks the path.')
    dynamic_margin: float = parameter(
        0.3, 'Extra gap in m kept from returns the map does not explain (they may move) when '
        'checking the path ahead.')
    reaction_time: float = parameter(
        0.0, "Seconds before a commanded slow-down takes hold (control period, the robot's "
        'response lag), allowed for when braking; 0: robot preset (0.1/0.15/0.35).')
    obstacle_speed: float = parameter(
        0.5, 'Speed in m/s at which returns the map does not explain may close in, allowed for '
        'when braking for them.')
    monitor_distance: float = parameter(
        0.0, 'Collision monitor: the speed is at most what stops the robot this far (m) from '
        'the nearest unexplained return ahead of it; 0: robot preset.')
    rotate_start_angle: float = parameter(
        0.785, 'diff_drive: heading error in rad to the carrot above which it turns in place.')
    rotate_stop_angle: float = parameter(
        0.25, 'diff_drive: heading error in rad at which a turn in place ends.')
    rotate_speed: float = parameter(1.5, 'diff_drive: yaw rate in rad/s of a turn in place.')
    angular_deceleration: float = parameter(
        3.0, 'diff_drive: yaw deceleration in rad/s^2 planned to stop a turn on the heading.')
    wheelbase: float = parameter(0.7, 'car: distance in m between the axles.')
    max_steering_angle: float = parameter(0.5, 'car: steering lock in rad.')
    yaw_gain: float = parameter(2.0, 'flyer: yaw rate in rad/s per rad of heading error.')
    mark_range: float = parameter(
        0.0, 'Unexplained returns within this distance in m are marked; 0: robot preset.')
    mark_lifetime: int = parameter(
        20, 'Scans a mark survives without a beam clearing it.')
    blocked_horizon: float = parameter(
        0.0, 'Path length in m ahead checked for blocking marks; 0: robot preset.')
    replan_deviation: float = parameter(
        0.0, 'Distance in m from the path that makes the robot replan; 0: robot preset.')
    replan_interval: int = parameter(10, 'Fewest steps between two plans.')
    replan_period: int = parameter(
        20, 'Steps between plans while scan marks lie near the path.')
    replan_improvement: float = parameter(
        0.1, 'A periodic replan replaces a path that is not blocked only when it is shorter '
        'by this fraction of what remains (0..1).')
    goal_tolerance: float = parameter(
        0.0, 'Distance in m to the goal at which the robot stops; 0: robot preset.')
    cruise_altitude: float = parameter(
        0.95, 'flyer: altitude in m (underside above the ground) it climbs to and holds.')
    takeoff_altitude: float = parameter(
        0.45, 'flyer: altitude in m below which it only climbs (above the 0.3 m low obstacles).')
    climb_gain: float = parameter(
        1.0, 'flyer: climb rate in m/s per m of altitude error (1/s).')
    max_climb_rate: float = parameter(
        1.0, 'flyer: largest climb or descent rate commanded in m/s.')

    def altitude_hold(self) -> AltitudeHold:
        """The flyer's altitude control these parameters ask for."""
        return AltitudeHold(cruise_altitude=self.cruise_altitude,
                            takeoff_altitude=self.takeoff_altitude, climb_gain=self.climb_gain,
                            max_climb_rate=self.max_climb_rate)

    def resolved(self) -> ReferenceNavigatorConfig:
        """This config with every 0 replaced by the robot preset (unknown robot: unchanged)."""
        preset = ROBOT_PRESETS.get(self.robot)
        if preset is None:
            return self
        changes: dict[str, Any] = {name: value for name, value in preset.items()
                                   if getattr(self, name) == 0.0}
        return dataclasses.replace(self, **changes)

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first parameter out of range."""
        if self.robot not in ROBOTS:
            raise InvalidConfigError(f'robot must be one of {", ".join(ROBOTS)}, got '
                                     f'{self.robot!r}')
        config = self.resolved()
        for name in ('robot_radius', 'inflation_radius', 'cost_scaling_factor',
                     'planning_resolution', 'path_spacing', 'curvature_window', 'max_speed',
                     'lateral_acceleration', 'deceleration', 'min_speed', 'lookahead_min',
                     'lookahead_max', 'slowdown_distance', 'goal_tolerance', 'mark_range',
                     'monitor_distance',
                     'blocked_horizon', 'replan_deviation', 'rotate_speed',
                     'angular_deceleration', 'wheelbase', 'max_steering_angle'):
            require_positive(name, getattr(config, name), InvalidConfigError)
        for name in ('safety_margin', 'cost_weight', 'inscribed_penalty', 'clearance_target',
                     'max_angular_speed', 'lookahead_time', 'min_speed_factor', 'stop_margin',
                     'collision_margin', 'dynamic_margin', 'reaction_time', 'obstacle_speed',
                     'rotate_start_angle',
                     'rotate_stop_angle',
                     'yaw_gain'):
            require_non_negative(name, getattr(config, name), InvalidConfigError)
        for name in ('mark_lifetime', 'replan_interval', 'replan_period'):
            value = getattr(config, name)
            if not (isinstance(value, int) and value >= 1):
                raise InvalidConfigError(f'{name} must be an integer >= 1, got {value!r}')
        if config.lookahead_min > config.lookahead_max:
            raise InvalidConfigError(f'lookahead_min {config.lookahead_min} exceeds '
                                     f'lookahead_max {config.lookahead_max}')
        if config.min_speed > config.max_speed:
            raise InvalidConfigError(f'min_speed {config.min_speed} exceeds max_speed '
                                     f'{config.max_speed}')
        if not 0.0 <= config.replan_improvement <= 1.0:
            raise InvalidConfigError(
                f'replan_improvement must be in [0, 1], got {config.replan_improvement}')
        if config.min_speed_factor > 1.0:
            raise InvalidConfigError(
                f'min_speed_factor must be in [0, 1], got {config.min_speed_factor}')
        if config.rotate_stop_angle > config.rotate_start_angle:
            raise InvalidConfigError(f'rotate_stop_angle {config.rotate_stop_angle} exceeds '
                                     f'rotate_start_angle {config.rotate_start_angle}')
        if config.max_steering_angle >= 0.5 * math.pi:
            raise InvalidConfigError(
                f'max_steering_angle must be below pi/2, got {config.max_steering_angle}')
        config.altitude_hold().validate()
        if config.robot != 'car' and config.max_angular_speed <= 0.0:
            raise InvalidConfigError(f'max_angular_speed must be positive for the '
                                     f'{config.robot}, got {config.max_angular_speed}')


class Mode(enum.Enum):
    """What the navigator did in a step."""

    NO_MAP = 'no_map'
    """No map yet: standing still."""
    NO_PATH = 'no_path'
    """No path to the goal: standing still until a plan succeeds."""
    ROTATE = 'rotate'
    """diff_drive turning in place towards the path (rotation shim)."""
    TAKEOFF = 'takeoff'
    """flyer climbing in place to its take-off altitude."""
    FOLLOW = 'follow'
    GOAL_REACHED = 'goal_reached'


@dataclass(frozen=True)
class NavigatorDecision:
    """What one step saw and decided (for tests, logs and benchmarks)."""

    mode: Mode
    command: VelocityCommand
    path: Path | None
    replanned: bool
    """A new plan was made (or tried) in this step."""
    speed_limits: dict[str, float]
    """The speed limits (m/s) of this step by cause: profile, proximity, obstacle."""
    detail: str = ''


class ReferenceNavigator:
    """The reference navigator; see the module docstring."""

    def __init__(self, config: ReferenceNavigatorConfig | None = None) -> None:
        config = config or ReferenceNavigatorConfig()
        config.validate()
        self.config = config
        self.settings = config.resolved()
        """The config with the robot preset filled in."""
        settings = self.settings
        self._costmap_config = CostmapConfig(
            robot_radius=settings.robot_radius, safety_margin=settings.safety_margin,
            inflation_radius=settings.inflation_radius,
            cost_scaling_factor=settings.cost_scaling_factor, cost_weight=settings.cost_weight,
            inscribed_penalty=settings.inscribed_penalty,
            resolution=settings.planning_resolution,
            passable_values=(FREE, LOW_OBSTACLE) if settings.robot == 'flyer' else (FREE,),
            mark_range=settings.mark_range, mark_lifetime=settings.mark_lifetime)
        self._planner_config = PlannerConfig(
            spacing=settings.path_spacing,
            wanted_clearance=settings.robot_radius + settings.clearance_target,
            smoothing_allowance=0.5 * settings.clearance_target,
            inscribed=settings.robot_radius + settings.safety_margin,
            curvature_window=settings.curvature_window,
            escape_radius=max(1.0, 3.0 * settings.robot_radius))
        self._diff_limits = DiffDriveLimits(
            max_angular_speed=settings.max_angular_speed,
            angular_deceleration=settings.angular_deceleration,
            lateral_acceleration=settings.lateral_acceleration,
            rotate_speed=settings.rotate_speed, rotate_start_angle=settings.rotate_start_angle,
            rotate_stop_angle=settings.rotate_stop_angle)
        self._car_limits = CarLimits(
            wheelbase=settings.wheelbase, max_steering_angle=settings.max_steering_angle,
            lateral_acceleration=settings.lateral_acceleration)
        self._holonomic_limits = HolonomicLimits(
            yaw_gain=settings.yaw_gain, max_yaw_rate=settings.max_angular_speed)
        self._altitude = settings.altitude_hold() if settings.robot == 'flyer' else None
        self.costmap: Costmap | None = None
        self.reset()

    # ----------------------------------------------------------------------------------------
    # The Controller protocol and its map extension

    def set_map(self, grid: MapData) -> None:
        """Plan on ``grid`` from now on: a new episode, so path and marks are dropped."""
        self.costmap = Costmap(grid, self._costmap_config)
        self.reset()

    def reset(self) -> None:
        """Forget the path, the scan marks and the rotation state (keep the map)."""
        self.path: Path | None = None
        self._tracker: PathTracker | None = None
        self._profile = np.zeros(0)
        self._planned_goal: tuple[float, float] | None = None
        self._steps = 0
        self._last_plan_step: int | None = None
        self._planned_with_marks = False
        self._rotating = False
        if self.costmap is not None:
            self.costmap.clear_marks()

    def goal_reached(self, state: RobotState, goal: Goal) -> bool:
        return goal.distance_from(state) <= self.settings.goal_tolerance

    def compute_command(self, scan: ScanData, state: RobotState, goal: Goal) -> VelocityCommand:
        return self.decide(scan, state, goal).command

    # ----------------------------------------------------------------------------------------
    # One step

    def decide(self, scan: ScanData, state: RobotState, goal: Goal) -> NavigatorDecision:
        """Run one step and return the full decision (a flyer takes off first, then holds
        its cruise altitude)."""
        if self.goal_reached(state, goal):
            return NavigatorDecision(Mode.GOAL_REACHED, STOP, self.path, False, {})
        if self.costmap is None:
            return NavigatorDecision(Mode.NO_MAP, STOP, None, False, {},
                                     'no map received yet')
        altitude = self._altitude
        if altitude is None:
            return self._decide_planar(scan, state, goal)
        climb = altitude.climb_rate(state.z)
        if not altitude.airborne(state.z):
            return NavigatorDecision(Mode.TAKEOFF, VelocityCommand(vz=climb), self.path, False,
                                     {}, f'taking off at {state.z:.2f} m')
        decision = self._decide_planar(scan, state, goal)
        return with_climb(decision, climb)

    def _decide_planar(self, scan: ScanData, state: RobotState,
                       goal: Goal) -> NavigatorDecision:
        """One step of the planar navigator (module docstring)."""
        costmap = self.costmap
        assert costmap is not None
        self._steps += 1
        costmap.update_marks(scan, state)
        deviation = self._tracker.update(state.x, state.y) if self._tracker else math.inf
        reason = self._replan_reason(state, goal, deviation)
        replanned = False
        detail = ''
        if reason and self._may_plan(reason):
            replanned = True
            detail = self._plan(state, goal, reason)
        if self.path is None or self._tracker is None:
            self._rotating = False
            return NavigatorDecision(Mode.NO_PATH, STOP, None, replanned, {},
                                     detail or 'no path')
        if replanned:
            self._tracker.update(state.x, state.y)
        return self._follow(scan, state, replanned, detail)

    def _replan_reason(self, state: RobotState, goal: Goal, deviation: float) -> str:
        if self.path is None:
            return 'no path'
        if self._planned_goal != (goal.x, goal.y):
            return 'new goal'
        if deviation > self.settings.replan_deviation:
            return f'{deviation:.2f} m off the path'
        assert self.costmap is not None and self._tracker is not None
        if self.costmap.marks or self._planned_with_marks:
            path, index = self.path, self._tracker.index
            arc = path.arc_length
            end = int(np.searchsorted(arc, arc[index] + self.settings.blocked_horizon, 'right'))
            ahead = path.points[index:max(end, index + 1)]
            clearance = self.costmap.clearance_at(ahead)
            if np.any(clearance < self.settings.robot_radius):
                return 'path blocked'
            near = np.any(clearance < self.costmap.config.max_distance)
            if near or self._planned_with_marks:
                if self._steps - (self._last_plan_step or 0) >= self.settings.replan_period:
                    return MARKS_NEAR_PATH
        return ''

    def _may_plan(self, reason: str) -> bool:
        if reason in ('no path', 'new goal') and self._planned_goal is None:
            return True
        if self._last_plan_step is None:
            return True
        return self._steps - self._last_plan_step >= self.settings.replan_interval

    def _plan(self, state: RobotState, goal: Goal, reason: str) -> str:
        assert self.costmap is not None
        self._last_plan_step = self._steps
        self._planned_goal = (goal.x, goal.y)
        try:
            path = plan_path(self.costmap, (state.x, state.y), (goal.x, goal.y),
                             self._planner_config)
        except PlanningError as err:
            self.path, self._tracker = None, None
            return f'replanning ({reason}) failed: {err}'
        settings = self.settings
        if reason == MARKS_NEAR_PATH and self.path is not None and self._tracker is not None:
            # Hysteresis: an agent moving about the path must not flip the robot between two
            # ways of similar length (each flip a turn on the spot).
            remaining = self._tracker.remaining
            if path.length > (1.0 - settings.replan_improvement) * remaining:
                self._planned_with_marks = bool(self.costmap.marks)
                return f'kept the path ({reason}): a new one would be {path.length:.2f} m'
        self.path = path
        self._tracker = PathTracker(path, search_distance=2.0 * settings.lookahead_max)
        self._profile = speed_profile(
            path, settings.max_speed, settings.lateral_acceleration, settings.deceleration,
            end_speed=settings.min_speed,
            max_curvature_speed=(settings.max_angular_speed if settings.robot == 'diff_drive'
                                 else math.inf))
        self._planned_with_marks = bool(self.costmap.marks)
        self._rotating = False
        return f'planned ({reason}): {path.length:.2f} m'

    def _follow(self, scan: ScanData, state: RobotState, replanned: bool,
                detail: str) -> NavigatorDecision:
        settings = self.settings
        tracker = self._tracker
        path = self.path
        assert tracker is not None and path is not None and self.costmap is not None
        index = tracker.index
        speed = max(0.0, state.speed)
        lookahead = min(settings.lookahead_max,
                        max(settings.lookahead_min, speed * settings.lookahead_time))
        carrot = tracker.carrot(lookahead)
        # The profile a little ahead: the robot takes a moment to slow down.
        window = int(np.searchsorted(
            path.arc_length, tracker.travelled + (settings.reaction_time + 0.2) * speed,
            side='right'))
        profile = float(self._profile[index:max(window, index + 1)].min())
        carrot_x, carrot_y = to_body(state, carrot)
        direction = math.atan2(carrot_y, carrot_x)
        proximity = settings.max_speed * proximity_factor(
            scan, settings.robot_radius, direction, settings.slowdown_distance,
            settings.min_speed_factor)
        dynamic = self.costmap.unexplained_points(scan, state, settings.blocked_horizon)
        free = free_distance(path, index, settings.blocked_horizon, dynamic,
                             settings.robot_radius + settings.collision_margin
                             + settings.dynamic_margin)
        obstacle = braking_speed(free, settings.deceleration, settings.stop_margin,
                                 settings.reaction_time, settings.obstacle_speed)
        monitor = braking_speed(
            nearest_gap_ahead(dynamic, state, direction, settings.robot_radius),
            settings.deceleration, settings.monitor_distance, settings.reaction_time,
            settings.obstacle_speed)
        regulated = max(settings.min_speed, min(profile, proximity))
        target = min(regulated, obstacle, monitor, settings.max_speed)
        limits = {'profile': profile, 'proximity': proximity, 'obstacle': obstacle,
                  'monitor': monitor}
        command, mode = self._command_towards(state, carrot, target)
        # Like RPP's collision detection: the motion up to the carrot must keep clearance; a
        # nearer carrot bends the motion back to the path, a turn in place is always safe for
        # a round robot.
        if mode is Mode.FOLLOW and settings.robot != 'car':
            reach = math.hypot(carrot_x, carrot_y)
            for share in (0.5, 0.25):
                if self._motion_clear(state, command, max(reach, speed)):
                    break
                reach = share * lookahead
                command, mode = self._command_towards(state, tracker.carrot(reach), target)
            else:
                if not self._motion_clear(state, command, max(reach, speed)):
                    command, mode = self._recover(state, tracker)
                    detail = detail or 'motion towards the path blocked: turning to the path'
        if not command.is_finite():
            return NavigatorDecision(Mode.NO_PATH, STOP, path, replanned, limits,
                                     'non-finite command: stopping')
        return NavigatorDecision(mode, command, path, replanned, limits, detail)

    def _command_towards(self, state: RobotState, carrot: np.ndarray,
                         speed: float) -> tuple[VelocityCommand, Mode]:
        robot = self.settings.robot
        if robot == 'diff_drive':
            command, self._rotating = follow_diff_drive(
                state, carrot, speed, self._diff_limits, self._rotating)
            return command, Mode.ROTATE if self._rotating else Mode.FOLLOW
        if robot == 'car':
            return follow_car(state, carrot, speed, self._car_limits), Mode.FOLLOW
        return follow_holonomic(state, carrot, speed, self._holonomic_limits), Mode.FOLLOW

    def _motion_clear(self, state: RobotState, command: VelocityCommand, length: float,
                      margin: float | None = None) -> bool:
        """Whether ``command`` keeps the footprint ``margin`` (default ``collision_margin``)
        off every obstacle of the costmap over ``length`` metres; where the robot is closer
        than that already, whether it loses no more than half the margin (and never touches)."""
        assert self.costmap is not None
        settings = self.settings
        if math.hypot(command.vx, command.vy) < 1e-6:
            return True
        margin = settings.collision_margin if margin is None else margin
        points = swept_points(state, command, length, 0.5 * self.costmap.resolution)
        clearance = self.costmap.clearance_at(points)
        radius = settings.robot_radius
        needed = max(radius + 0.2 * margin,
                     min(radius + margin, float(clearance[0]) - 0.5 * margin))
        return bool(clearance[1:].min() >= needed - 1e-6)

    def _recover(self, state: RobotState, tracker: PathTracker) -> tuple[VelocityCommand, Mode]:
        """No safe motion towards the path ahead: a diff_drive turns in place to the path's
        heading, then creeps along it; a flyer creeps straight back onto the path's nearest
        point; each stops where even that would touch."""
        settings = self.settings
        creep_target = tracker.carrot(0.5 * settings.lookahead_min)
        if settings.robot == 'diff_drive':
            error = wrap_angle(tracker.path.heading(tracker.index) - state.yaw)
            if abs(error) > settings.rotate_stop_angle:
                rate = math.copysign(min(settings.rotate_speed, 0.5 + abs(error)), error)
                return VelocityCommand(0.0, 0.0, rate), Mode.ROTATE
            command, _ = follow_diff_drive(state, creep_target, settings.min_speed,
                                           self._diff_limits, rotating=False)
        else:
            creep_target = tracker.path.points[tracker.index]
            command = follow_holonomic(state, creep_target, settings.min_speed,
                                       self._holonomic_limits)
        if not self._motion_clear(state, command, 0.1, margin=0.0):
            return STOP, Mode.FOLLOW
        return command, Mode.FOLLOW
