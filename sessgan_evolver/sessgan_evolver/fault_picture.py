"""A picture of one fault that a user reads at a glance (PNG, matplotlib Agg).

The map (free white, low obstacles grey, walls black), the certified route from start to
goal (the taut route of the route certificate, dashed blue), the robot's trajectory (orange,
start circle, end square), the agents' paths (thin purple, their last positions as discs),
every contact the robot caused (red x; agents driving into it: grey x) with the first fault
event circled, and the coarse cell that keys the fault (red frame). A fleet episode's other
robots r1, r2, ... show their start (circle), goal (star) and certified route (dashed), each
in its own colour and labelled; the robot under test is then labelled r0.

:func:`scene_from_bag` reads all of it from a failure bag: the map from ``/map``, the
trajectory from ``/odom``, contacts from episode.json's metrics, agents from its trace (a
worker's bag has no trace: it shows map, route, trajectory and contacts).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

from sessgan_evolver.errors import FaultPictureError

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402
from matplotlib.colors import BoundaryNorm, ListedColormap  # noqa: E402

from sessgan_core.environment import Environment, Pose2D  # noqa: E402
from sessgan_core.fleet import fleet_from_json  # noqa: E402
from sessgan_core.route_certificate import RouteCertificate  # noqa: E402
from sessgan_core.valid_tests import (  # noqa: E402
    certify_environment,
    certify_fleet,
    certify_mission,
)
from sessgan_evolver.bag_reading import iter_bag_messages, read_episode_json  # noqa: E402
from sessgan_evolver.episode_runner import EpisodeTrace  # noqa: E402
from sessgan_evolver.faults import FaultKey, FaultRule, failing_robot  # noqa: E402
from sessgan_sim.bag_recording import jazzy_typestore  # noqa: E402

FIGURE_DPI = 120
_MAP_COLOURS = ListedColormap(['#ffffff', '#9e9e9e', '#202020'])
_MAP_NORM = BoundaryNorm([-0.5, 25, 75, 100.5], 3)


@dataclass
class FaultScene:
    """Everything one picture shows; positions in metres (map frame)."""

    scenario: str
    occupancy: np.ndarray
    resolution: float
    origin: tuple[float, float]
    start: tuple[float, float]
    goal: tuple[float, float]
    trajectory: np.ndarray
    """(n, 2) robot centre."""
    agents: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 2)))
    """(n, agents, 2) agent centres."""
    contacts: list[dict[str, Any]] = field(default_factory=list)
    """Contact events (sessgan_sim.metrics.ContactEvent.to_dict): x, y, kind, time, fault."""
    route: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    """(n, 2) corners of the certified route, start to goal (empty: no certificate)."""
    fault: FaultKey | None = None
    rule: FaultRule = field(default_factory=FaultRule)
    title: str = ''
    fault_place: tuple[float, float] | None = None
    """The first fault event's position (a contact, or where the robot ended)."""
    caption: str = ''
    """A short title for small pictures (default: the fault's kind)."""
    stations: list[tuple[float, float]] = field(default_factory=list)
    """A mission's stations, in visiting order (``goal`` is then home)."""
    fleet: list[FleetMember] = field(default_factory=list)
    """A fleet episode's robots r1, r2, ... (empty: one robot under test)."""


@dataclass
class FleetMember:
    """One more robot of a fleet episode, as drawn: start, goal, certified route, path."""

    start: tuple[float, float]
    goal: tuple[float, float]
    route: np.ndarray
    """(n, 2) corners of its certified route (empty: none)."""
    trajectory: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    """(n, 2) where it drove (empty: not known)."""


FLEET_COLOURS = ('#e377c2', '#8c564b', '#bcbd22', '#9467bd', '#393b79', '#637939', '#843c39')
"""Robots r1..r7 (apart from the route, trajectory, start, agent and contact colours)."""


def _corners(route: RouteCertificate | None) -> np.ndarray:
    if route is None:
        return np.zeros((0, 2))
    return np.asarray(route.points, dtype=float).reshape(-1, 2)


def fleet_members(environment: Environment, trajectories: Sequence[np.ndarray] = ()
                  ) -> list[FleetMember]:
    """Robots r1, r2, ... of a fleet environment with their certified routes (each among the
    other robots parked on their goals, sessgan_core.fleet) and, when given, where they
    drove (``trajectories``, r1 first)."""
    if not environment.fleet:
        return []
    routes = certify_fleet(environment)[1:]
    paths = list(trajectories) + [np.zeros((0, 2))] * (len(routes) - len(trajectories))
    return [FleetMember((robot.start.x, robot.start.y), (robot.goal.x, robot.goal.y),
                        _corners(route), np.asarray(path, dtype=float).reshape(-1, 2))
            for robot, route, path in zip(environment.fleet, routes, paths)]


def certified_route(environment: Environment) -> np.ndarray:
    """Corners (n, 2) of the taut certified route of an environment's own start and goal
    (sessgan_core.valid_tests.certify_environment), through every leg of a mission, among the
    other robots of a fleet; empty when there is none (or a leg has none)."""
    if environment.fleet:
        return _corners(certify_fleet(environment)[0])
    legs = (certify_mission(environment) if environment.stations
            else [certify_environment(environment)])
    if not legs or any(leg is None for leg in legs):
        return np.zeros((0, 2))
    return np.concatenate([np.asarray(leg.points, dtype=float).reshape(-1, 2)
                           for leg in legs if leg is not None])


def fault_place(contacts: Sequence[dict[str, Any]], trajectory: np.ndarray
                ) -> tuple[float, float] | None:
    """The first contact the robot caused, else where it ended."""
    for contact in contacts:
        if contact.get('fault', True):
            return float(contact['x']), float(contact['y'])
    if len(trajectory):
        return float(trajectory[-1][0]), float(trajectory[-1][1])
    return None


def fleet_fault_robot(contacts: Sequence[dict[str, Any]], metrics: dict[str, Any],
                      robots: int) -> int | None:
    """Which robot of a fleet showed the fault (None for one robot): the first contact a
    robot caused, else the robot the episode's outcome comes from (``failed_leg``)."""
    if robots < 2:
        return None
    for contact in contacts:
        if contact.get('fault', True):
            return int(contact.get('robot') or 0)
    failed = failing_robot(metrics, robots)
    return failed if 0 <= failed < robots else 0


def scene_from_run(environment: Environment, trace: EpisodeTrace, metrics: dict[str, Any],
                   fault: FaultKey | None = None, rule: FaultRule | None = None,
                   title: str = '') -> FaultScene:
    """The scene of an in-process episode."""
    start = (environment.start.x, environment.start.y)
    goal = (environment.goal.x, environment.goal.y)
    contacts = sorted((contact.to_dict() for robot in (trace, *trace.fleet)
                       for contact in robot.contacts), key=lambda contact: contact['time'])
    paths = [np.asarray(robot.poses)[:, :2] for robot in (trace, *trace.fleet)]
    robot = fleet_fault_robot(contacts, metrics, len(paths))
    return FaultScene(
        environment.scenario, np.asarray(environment.occupancy), environment.resolution,
        environment.origin, start, goal, paths[0], np.asarray(trace.agents), contacts,
        certified_route(environment), fault, rule or FaultRule(),
        title or default_title(metrics, fault, robot=robot),
        fault_place(contacts, paths[robot or 0]),
        stations=[(pose.x, pose.y) for pose in environment.stations],
        fleet=fleet_members(environment, paths[1:]))


def default_title(metrics: dict[str, Any], fault: FaultKey | None,
                  controller: str = '', robot: int | None = None) -> str:
    """'<kind> | <controller> | <outcome>, N fault collisions, fault risk R'; ``robot``: the
    fleet's robot that showed the fault, named first ('r1: collision agent | ...')."""
    risk = metrics.get('fault_risk_score')
    parts = [('' if robot is None else f'r{robot}: ')
             + (fault.kind.replace('_', ' ') if fault else str(metrics.get('outcome')))]
    if controller:
        parts.append(controller)
    parts.append(f'{metrics.get("outcome")}, {metrics.get("fault_collisions")} fault '
                 f'collisions' + (f', fault risk {risk:.2f}' if isinstance(risk, (int, float))
                                  else ''))
    return ' | '.join(parts)


def scene_from_bag(bag: str | Path) -> FaultScene:
    """The scene of a failure bag (module docstring)."""
    bag = Path(bag)
    episode = read_episode_json(bag) or {}
    store = jazzy_typestore()
    occupancy = resolution = origin = None
    odometry: dict[str, list[tuple[float, float]]] = {}
    """Positions by odom topic: a fleet's robots each publish their own."""
    for message in iter_bag_messages(bag):
        name = message.topic.rsplit('/', 1)[-1]
        if name == 'map' and occupancy is None:
            grid: Any = store.deserialize_cdr(message.data, message.msgtype)
            occupancy = np.asarray(grid.data, dtype=np.int8).reshape(grid.info.height,
                                                                     grid.info.width)
            resolution = float(grid.info.resolution)
            origin = (float(grid.info.origin.position.x), float(grid.info.origin.position.y))
        elif name == 'odom':
            odom: Any = store.deserialize_cdr(message.data, message.msgtype)
            odometry.setdefault(message.topic, []).append(
                (odom.pose.pose.position.x, odom.pose.pose.position.y))
    if occupancy is None or resolution is None or origin is None:
        raise FaultPictureError(f'bag {bag} has no map message')
    fleet = fleet_from_json(episode.get('fleet'))
    robots = [[] if not fleet else next(
        (path for topic, path in odometry.items() if topic.endswith(f'/r{index}/odom')), [])
        for index in range(len(fleet) + 1)]
    trajectory = robots[0] if fleet else next(iter(odometry.values()), [])
    scenario = str(episode.get('scenario') or 'factory')
    start = tuple(episode.get('start') or (*(trajectory[0] if trajectory else (0.0, 0.0)),
                                            0.0))
    goal = tuple(episode.get('goal') or (0.0, 0.0, 0.0))
    environment = Environment(str(episode.get('environment_id', bag.name)), scenario,
                              occupancy, resolution, Pose2D(*start[:3]), Pose2D(*goal[:3]),
                              origin, stations=tuple(Pose2D(*station[:3])
                                                     for station in episode.get('stations', ())),
                              fleet=fleet)
    trace = episode.get('trace') or {}
    if not trajectory and trace.get('robot'):
        trajectory = [tuple(row[:2]) for row in trace['robot']]
    metrics = episode.get('metrics') or {}
    contacts = list(metrics.get('contacts') or trace.get('contacts') or [])
    fault_data = episode.get('fault')
    fault = FaultKey(**fault_data) if isinstance(fault_data, dict) else None
    rule_data = episode.get('fault_rule')
    rule = FaultRule(**rule_data) if isinstance(rule_data, dict) else FaultRule()
    path = np.asarray(trajectory, dtype=float).reshape(-1, 2)
    robot = fleet_fault_robot(contacts, metrics, len(robots) if fleet else 1)
    failing = path if not robot else np.asarray(robots[robot], dtype=float).reshape(-1, 2)
    return FaultScene(
        scenario, occupancy, resolution, origin, (float(start[0]), float(start[1])),
        (float(goal[0]), float(goal[1])), path,
        np.asarray(trace.get('agents') or np.zeros((0, 0, 2)), dtype=float), contacts,
        certified_route(environment), fault, rule,
        default_title(metrics, fault, str(episode.get('controller', '')), robot),
        fault_place(contacts, failing),
        stations=[(pose.x, pose.y) for pose in environment.stations],
        fleet=fleet_members(environment, [np.asarray(path, dtype=float) for path in robots[1:]]))


def draw_scene(axis: Any, scene: FaultScene, legend: bool = True, compact: bool = False
               ) -> None:
    """Draw ``scene`` into a matplotlib axis."""
    height, width = scene.occupancy.shape
    left, bottom = scene.origin
    extent = (left, left + width * scene.resolution, bottom, bottom + height * scene.resolution)
    axis.imshow(np.asarray(scene.occupancy, dtype=float), cmap=_MAP_COLOURS, norm=_MAP_NORM,
                origin='lower', extent=extent, interpolation='nearest')
    if len(scene.route):
        axis.plot(scene.route[:, 0], scene.route[:, 1], '--', color='#1f77b4', linewidth=1.4,
                  label='certified route')
    agents = scene.agents
    if agents.ndim == 3 and agents.shape[0] and agents.shape[1]:
        for index in range(agents.shape[1]):
            axis.plot(agents[:, index, 0], agents[:, index, 1], '-', color='#8e44ad',
                      linewidth=0.8, alpha=0.7, label='agent paths' if index == 0 else None)
            axis.plot(agents[-1, index, 0], agents[-1, index, 1], 'o', color='#8e44ad',
                      markersize=5 if compact else 7, alpha=0.8)
    if len(scene.trajectory):
        axis.plot(scene.trajectory[:, 0], scene.trajectory[:, 1], '-', color='#ff7f0e',
                  linewidth=1.6, label='robot trajectory')
        axis.plot(*scene.trajectory[-1], 's', color='#ff7f0e', markersize=6)
    axis.plot(*scene.start, 'o', color='#2ca02c', markersize=8, markeredgecolor='black',
              label='start')
    if scene.fleet:
        axis.annotate('r0', scene.start, textcoords='offset points', xytext=(5, 5), fontsize=8)
    for number, member in enumerate(scene.fleet, 1):
        colour = FLEET_COLOURS[(number - 1) % len(FLEET_COLOURS)]
        if len(member.route):
            axis.plot(member.route[:, 0], member.route[:, 1], '--', color=colour,
                      linewidth=1.2)
        if len(member.trajectory):
            axis.plot(member.trajectory[:, 0], member.trajectory[:, 1], '-', color=colour,
                      linewidth=1.6)
            axis.plot(*member.trajectory[-1], 's', color=colour, markersize=6)
        axis.plot(*member.start, 'o', color=colour, markersize=7, markeredgecolor='black',
                  label=f'robot r{number}')
        axis.plot(*member.goal, '*', color=colour, markersize=11, markeredgecolor='black')
        for place in (member.start, member.goal):
            axis.annotate(f'r{number}', place, textcoords='offset points', xytext=(5, 5),
                          fontsize=8)
    axis.plot(*scene.goal, '*', color='#2ca02c', markersize=13, markeredgecolor='black',
              label='home' if scene.stations else 'goal')
    for number, station in enumerate(scene.stations, 1):
        axis.plot(*station, 'D', color='#17becf', markersize=8, markeredgecolor='black',
                  label='stations' if number == 1 else None)
        axis.annotate(str(number), station, textcoords='offset points', xytext=(5, 5),
                      fontsize=8)
    caused = [(c['x'], c['y']) for c in scene.contacts if c.get('fault', True)]
    suffered = [(c['x'], c['y']) for c in scene.contacts if not c.get('fault', True)]
    if caused:
        points = np.array(caused)
        axis.plot(points[:, 0], points[:, 1], 'x', color='#d62728', markersize=8,
                  markeredgewidth=2, label='contacts it caused')
    if suffered:
        points = np.array(suffered)
        axis.plot(points[:, 0], points[:, 1], 'x', color='#7f7f7f', markersize=8,
                  markeredgewidth=2, label='agent drove into it')
    if scene.fault_place is not None:
        axis.plot(*scene.fault_place, 'o', markersize=16, markerfacecolor='none',
                  markeredgecolor='#d62728', markeredgewidth=2, label='first fault')
        side = scene.rule.coarse_cells * scene.resolution
        row = np.floor((scene.fault_place[1] - bottom) / side)
        col = np.floor((scene.fault_place[0] - left) / side)
        axis.add_patch(plt.Rectangle((left + col * side, bottom + row * side), side, side,
                                     fill=False, edgecolor='#d62728', linewidth=1.2,
                                     linestyle=':'))
    axis.set_xlim(extent[0], extent[1])
    axis.set_ylim(extent[2], extent[3])
    axis.set_aspect('equal')
    if compact:
        axis.set_xticks([])
        axis.set_yticks([])
    else:
        axis.set_xlabel('x (m)')
        axis.set_ylabel('y (m)')
    if compact:
        caption = scene.caption or (scene.fault.kind.replace('_', ' ') if scene.fault
                                    else scene.title.split(' | ')[0])
        axis.set_title(caption, fontsize='small')
    else:
        axis.set_title(scene.title)
    if legend:
        axis.legend(loc='upper left', bbox_to_anchor=(1.01, 1.0), fontsize='small')


ZOOM_ABOVE = 30.0
"""m: maps wider than this get a second panel zoomed on the first fault."""
ZOOM_SIDE = 20.0
"""m: side of the zoomed panel."""


def write_scene_png(scene: FaultScene, path: str | Path) -> Path:
    """One fault as a PNG (with a zoom on the fault for maps wider than ZOOM_ABOVE)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    side = max(scene.occupancy.shape) * scene.resolution
    if side > ZOOM_ABOVE and scene.fault_place is not None:
        figure, (whole, zoom) = plt.subplots(1, 2, figsize=(14.5, 6.6))
        draw_scene(whole, scene, legend=False)
        draw_scene(zoom, scene)
        x, y = scene.fault_place
        zoom.set_xlim(x - ZOOM_SIDE / 2, x + ZOOM_SIDE / 2)
        zoom.set_ylim(y - ZOOM_SIDE / 2, y + ZOOM_SIDE / 2)
        zoom.set_title(f'{ZOOM_SIDE:.0f} m around the first fault')
        whole.add_patch(plt.Rectangle((x - ZOOM_SIDE / 2, y - ZOOM_SIDE / 2), ZOOM_SIDE,
                                      ZOOM_SIDE, fill=False, edgecolor='#ff7f0e',
                                      linewidth=1.0))
    else:
        figure, axis = plt.subplots(figsize=(8.2, 6.0))
        draw_scene(axis, scene)
    figure.tight_layout()
    figure.savefig(path, dpi=FIGURE_DPI)
    plt.close(figure)
    return path


def scene_grid_figure(rows: Sequence[tuple[str, Sequence[FaultScene]]], columns: int = 4
                      ) -> Any:
    """Small pictures, one row per label (e.g. per method), up to ``columns`` each: the
    matplotlib figure. Constrained layout keeps every row's titles clear of the row above
    (tight_layout let equal-aspect maps overlap them)."""
    if not rows:
        raise FaultPictureError('no scenes to draw')
    figure, axes = plt.subplots(len(rows), columns, figsize=(3.0 * columns, 3.4 * len(rows)),
                                squeeze=False, layout='constrained')
    for row, (label, scenes) in enumerate(rows):
        for column in range(columns):
            axis = axes[row][column]
            if column < len(scenes):
                draw_scene(axis, scenes[column], legend=False, compact=True)
            elif column == 0:  # keep the axis for the row's label
                axis.set_xticks([])
                axis.set_yticks([])
                for spine in axis.spines.values():
                    spine.set_visible(False)
                axis.text(0.5, 0.5, 'no valid failure', ha='center', va='center',
                          transform=axis.transAxes)
            else:
                axis.set_axis_off()
            if column == 0:
                axis.set_ylabel(label, fontsize='large')
    handles, labels = [], []
    for axis in axes.flat:
        for handle, text in zip(*axis.get_legend_handles_labels()):
            if text not in labels:
                handles.append(handle)
                labels.append(text)
    if handles:
        figure.legend(handles, labels, loc='outside lower center', ncol=min(len(labels), 7),
                      fontsize='small')
    return figure


def write_scene_grid(rows: Sequence[tuple[str, Sequence[FaultScene]]], path: str | Path,
                     columns: int = 4) -> Path:
    """scene_grid_figure as a PNG."""
    figure = scene_grid_figure(rows, columns)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=FIGURE_DPI)
    plt.close(figure)
    return path
