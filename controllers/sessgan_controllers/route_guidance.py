"""Route guidance for the paper's local controllers: a route on the map and a waypoint on it.

The paper's robots run local obstacle-avoidance methods (Nearness-Diagram, velocity
projection, follow-the-gap). Steering for the goal itself, a purely reactive method gets
trapped in the dead ends of a factory map or takes the wrong branch of a race track: a
failure in almost every generated map, and none of the faults the paper reports. So, as ND
was deployed behind a global planner (Player's ``nd`` driver behind its ``wavefront``
planner), each controller here steers for a **waypoint** on a route planned on the
episode's map (the ``map`` topic):

* the route: A* on the map inflated for the robot's radius
  (:mod:`~sessgan_controllers.costmap` and :mod:`~sessgan_controllers.path_planning`, the
  reference navigator's planner), keeping ``route_clearance`` beyond the radius where the
  map allows; planned at the first step towards a goal and again when the robot strays
  more than ``replan_deviation`` from it. The map only: moving agents are left to the local
  method, where its flaws lie;
* the waypoint: the route point ``waypoint_distance`` metres of route beyond the point
  nearest to the robot (the goal itself on the route's last stretch).

Without a map, or when no route exists, the waypoint is the goal: the controller is purely
reactive again. Lengths are metres.
"""

from __future__ import annotations

from dataclasses import dataclass

from sessgan_controllers.controller_interface import (
    Goal,
    MapData,
    RobotState,
    StatelessController,
    parameter,
)
from sessgan_controllers.costmap import FREE, Costmap, CostmapConfig
from sessgan_controllers.errors import InvalidConfigError
from sessgan_controllers.path_following import PathTracker
from sessgan_controllers.path_planning import PlannerConfig, PlanningError, plan_path
from sessgan_core.validation import require_non_negative, require_positive


@dataclass(frozen=True)
class RouteGuidanceConfig:
    """How a controller's route is planned and where its waypoint lies. Lengths in metres."""

    robot_radius: float
    """Footprint radius: cells closer to an obstacle are never on the route."""
    route_clearance: float
    """Clearance beyond the radius that the route keeps where the map has room for it."""
    waypoint_distance: float
    """Route length from the robot's nearest route point to its waypoint."""
    replan_deviation: float
    """Distance from the route beyond which it is planned again from where the robot is."""
    planning_resolution: float
    """Planning cell size (map cells are split into whole sub-cells)."""
    passable_values: tuple[int, ...] = (FREE,)
    """Map values the robot may cross (a flyer also crosses low obstacles, 50)."""
    enabled: bool = True
    """False: no route, the waypoint is always the goal."""

    def validate(self) -> None:
        """Raise ValueError naming the first unusable value."""
        for name in ('robot_radius', 'waypoint_distance', 'replan_deviation',
                     'planning_resolution'):
            require_positive(name, getattr(self, name))
        require_non_negative('route_clearance', self.route_clearance)


ROUTE_PARAMETER_HELP = {
    'use_map': 'Steer for a waypoint on a route planned on the map topic (true) or for the goal '
               'itself (false: purely reactive, trapped by dead ends, the wrong branch at forks).',
    'waypoint_distance': 'Route length in m from the nearest route point to the waypoint '
                         'steered for.',
    'route_clearance': "Clearance in m beyond the footprint radius (a car's half-width) that "
                       'the route keeps where the map has room.',
    'replan_deviation': 'Distance in m from the route beyond which the route is planned again.',
    'planning_resolution': 'Route planning cell size in m.',
}


def route_parameter(name: str, default: float) -> float:
    """A route-guidance field with another default than :class:`RouteGuidanceParameters`'
    (re-declared in a subclass, it keeps its place and its help)."""
    return parameter(default, ROUTE_PARAMETER_HELP[name])


@dataclass
class RouteGuidanceParameters:
    """The route-guidance parameters of a route-guided controller's config, declared once:
    a config inherits them (each becomes a ROS parameter) and re-declares a default with
    :func:`route_parameter` where its robot needs another."""

    use_map: bool = parameter(True, ROUTE_PARAMETER_HELP['use_map'])
    waypoint_distance: float = route_parameter('waypoint_distance', 1.5)
    route_clearance: float = route_parameter('route_clearance', 0.1)
    replan_deviation: float = route_parameter('replan_deviation', 1.0)
    planning_resolution: float = route_parameter('planning_resolution', 0.1)

    def validate_route_parameters(self) -> None:
        """Raise InvalidConfigError naming the first route parameter out of range."""
        for name in ('waypoint_distance', 'replan_deviation', 'planning_resolution'):
            require_positive(name, getattr(self, name), InvalidConfigError)
        require_non_negative('route_clearance', self.route_clearance, InvalidConfigError)

    def route_guidance_for(self, robot_radius: float,
                           passable_values: tuple[int, ...] = (FREE,)) -> RouteGuidanceConfig:
        """The route guidance these parameters ask for, for a footprint of ``robot_radius``
        metres that may cross ``passable_values``."""
        return RouteGuidanceConfig(
            robot_radius=robot_radius, route_clearance=self.route_clearance,
            waypoint_distance=self.waypoint_distance, replan_deviation=self.replan_deviation,
            planning_resolution=self.planning_resolution, passable_values=passable_values,
            enabled=bool(self.use_map))


@dataclass(frozen=True)
class Waypoint:
    """Where the local method steers this step."""

    target: Goal
    """The waypoint (the goal itself when it is the last one or there is no route)."""
    is_goal: bool
    """True when ``target`` is the episode's goal (arrive there; do not just pass)."""


class RouteGuide:
    """A route on the episode's map and the waypoint ahead on it; see the module docstring."""

    def __init__(self, config: RouteGuidanceConfig) -> None:
        config.validate()
        self.config = config
        self._costmap_config = CostmapConfig(
            robot_radius=config.robot_radius, safety_margin=config.route_clearance,
            inflation_radius=2.0 * config.robot_radius + config.route_clearance,
            cost_scaling_factor=3.0 / max(config.robot_radius, 1e-3), cost_weight=3.0,
            inscribed_penalty=1000.0, resolution=config.planning_resolution,
            passable_values=config.passable_values)
        self._planner_config = PlannerConfig(
            spacing=0.5 * config.planning_resolution,
            wanted_clearance=config.robot_radius + config.route_clearance,
            inscribed=config.robot_radius + config.route_clearance,
            escape_radius=max(1.0, 3.0 * config.robot_radius))
        self.costmap: Costmap | None = None
        self.reset()

    def set_map(self, grid: MapData) -> None:
        """Plan on ``grid`` from now on (a new episode: the old route is dropped)."""
        self.costmap = Costmap(grid, self._costmap_config) if self.config.enabled else None
        self.reset()

    def reset(self) -> None:
        """Drop the route (keep the map)."""
        self._tracker: PathTracker | None = None
        self._planned_goal: tuple[float, float] | None = None
        self.plans = 0
        """Routes planned since the last reset."""

    @property
    def route(self):
        """The current route (:class:`~sessgan_controllers.path_planning.Path`) or None."""
        return self._tracker.path if self._tracker is not None else None

    def waypoint(self, state: RobotState, goal: Goal) -> Waypoint:
        """The waypoint for the robot at ``state`` heading for ``goal``."""
        if self.costmap is None:
            return Waypoint(goal, True)
        tracker = self._tracker
        if self._planned_goal != (goal.x, goal.y):
            tracker = self._plan(state, goal)
        elif tracker is not None and \
                tracker.update(state.x, state.y) > self.config.replan_deviation:
            tracker = self._plan(state, goal)
        if tracker is None:
            return Waypoint(goal, True)
        distance = self.config.waypoint_distance
        if tracker.remaining <= distance:
            return Waypoint(goal, True)
        x, y = tracker.carrot(distance)
        return Waypoint(Goal(float(x), float(y)), False)

    def _plan(self, state: RobotState, goal: Goal) -> PathTracker | None:
        self._planned_goal = (goal.x, goal.y)
        self.plans += 1
        assert self.costmap is not None
        try:
            path = plan_path(self.costmap, (state.x, state.y), (goal.x, goal.y),
                             self._planner_config)
        except PlanningError:
            self._tracker = None
            return None
        self._tracker = PathTracker(path, search_distance=2.0 * self.config.waypoint_distance)
        self._tracker.update(state.x, state.y)
        return self._tracker


class RouteGuidedController(StatelessController):
    """Base of the paper's controllers: ``decide`` steers for ``self.guide``'s waypoint.

    The route is the only state kept between steps; a new goal (:meth:`reset`) or a new map
    (:meth:`set_map`) drops it.
    """

    guide: RouteGuide

    def set_map(self, grid: MapData) -> None:
        """Plan routes on ``grid`` from now on (see :mod:`route_guidance`)."""
        self.guide.set_map(grid)

    def reset(self) -> None:
        self.guide.reset()
