"""Conversion between the core Environment and ROS messages (nodes only: imports messages)."""

from __future__ import annotations

import numpy as np
from geometry_msgs.msg import Pose
from nav_msgs.msg import OccupancyGrid

from sessgan_core.environment import Environment, FleetRobot, Pose2D, check_grid_size
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_core.quaternion import quaternion_from_yaw, yaw_from_quaternion
from sessgan_core.validation import require_positive
from sessgan_interfaces.msg import Environment as EnvironmentMsg


def pose_to_msg(pose: Pose2D) -> Pose:
    msg = Pose()
    msg.position.x = float(pose.x)
    msg.position.y = float(pose.y)
    q = msg.orientation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(pose.yaw)
    return msg


def pose_from_msg(msg: Pose) -> Pose2D:
    q = msg.orientation
    return Pose2D(float(msg.position.x), float(msg.position.y),
                  yaw_from_quaternion(q.x, q.y, q.z, q.w))


def occupancy_grid_msg(environment: Environment, frame_id: str = 'map',
                       stamp=None) -> OccupancyGrid:
    """The environment's map as a nav_msgs/OccupancyGrid (row-major, row 0 at the origin)."""
    grid = OccupancyGrid()
    grid.header.frame_id = frame_id
    if stamp is not None:
        grid.header.stamp = stamp
    grid.info.resolution = float(environment.resolution)
    grid.info.width = environment.width
    grid.info.height = environment.height
    grid.info.origin.position.x = float(environment.origin[0])
    grid.info.origin.position.y = float(environment.origin[1])
    grid.info.origin.orientation.w = 1.0
    # array('b') assignment from bytes is far faster than a list of ints.
    grid.data.frombytes(np.ascontiguousarray(environment.occupancy, dtype=np.int8).tobytes())
    return grid


def occupancy_from_grid_msg(grid: OccupancyGrid) -> tuple[np.ndarray, float, tuple[float, float]]:
    """(occupancy array, resolution, origin) of a grid; InvalidEnvironmentError if malformed."""
    width, height = int(grid.info.width), int(grid.info.height)
    resolution = float(grid.info.resolution)
    try:
        check_grid_size(width, height)  # before anything is built from the data
    except InvalidEnvironmentError as err:
        raise InvalidEnvironmentError(f'occupancy grid: {err}') from err
    if len(grid.data) != width * height:
        raise InvalidEnvironmentError(
            f'occupancy grid data has {len(grid.data)} cells but info says '
            f'{width}x{height} = {width * height}')
    require_positive('occupancy grid resolution', resolution, InvalidEnvironmentError, ' m')
    q = grid.info.origin.orientation
    if abs(q.z) > 1e-6 or abs(q.x) > 1e-6 or abs(q.y) > 1e-6:
        raise InvalidEnvironmentError('rotated occupancy grid origins are not supported')
    occupancy = np.frombuffer(bytes(grid.data), dtype=np.int8).reshape(height, width).copy()
    origin = (float(grid.info.origin.position.x), float(grid.info.origin.position.y))
    return occupancy, resolution, origin


def environment_to_msg(environment: Environment, stamp=None) -> EnvironmentMsg:
    msg = EnvironmentMsg()
    msg.id = environment.id
    msg.scenario = environment.scenario
    msg.seed = int(environment.seed) & 0xFFFFFFFFFFFFFFFF
    msg.generation = int(environment.generation)
    msg.member = int(environment.member)
    msg.map = occupancy_grid_msg(environment, stamp=stamp)
    msg.start = pose_to_msg(environment.start)
    msg.goal = pose_to_msg(environment.goal)
    msg.feasible = bool(environment.feasible)
    msg.route_length = float(environment.route_length)
    msg.route_min_clearance = float(environment.route_min_clearance)
    msg.stations = [pose_to_msg(station) for station in environment.stations]
    msg.dwell_time = float(environment.dwell_time)
    msg.fleet_starts = [pose_to_msg(robot.start) for robot in environment.fleet]
    msg.fleet_goals = [pose_to_msg(robot.goal) for robot in environment.fleet]
    msg.fleet_route_lengths = [float(robot.route_length) for robot in environment.fleet]
    return msg


def fleet_from_msg(msg: EnvironmentMsg) -> tuple[FleetRobot, ...]:
    """Robots r1, r2, ... of a message's three parallel fleet arrays; InvalidEnvironmentError
    when their lengths differ (one entry per robot in each)."""
    lengths = (len(msg.fleet_starts), len(msg.fleet_goals), len(msg.fleet_route_lengths))
    if len(set(lengths)) != 1:
        raise InvalidEnvironmentError(
            f'environment {msg.id!r}: fleet_starts, fleet_goals and fleet_route_lengths must '
            f'have one entry per fleet robot each, got {lengths[0]}, {lengths[1]} and '
            f'{lengths[2]}')
    return tuple(FleetRobot(pose_from_msg(start), pose_from_msg(goal), float(length))
                 for start, goal, length in zip(msg.fleet_starts, msg.fleet_goals,
                                                msg.fleet_route_lengths))


def environment_from_msg(msg: EnvironmentMsg) -> Environment:
    """Core Environment of a message; raises InvalidEnvironmentError naming what is wrong."""
    occupancy, resolution, origin = occupancy_from_grid_msg(msg.map)
    environment = Environment(
        id=msg.id, scenario=msg.scenario, occupancy=occupancy, resolution=resolution,
        origin=origin, start=pose_from_msg(msg.start), goal=pose_from_msg(msg.goal),
        seed=int(msg.seed), generation=int(msg.generation), member=int(msg.member),
        feasible=bool(msg.feasible), route_length=float(msg.route_length),
        route_min_clearance=float(msg.route_min_clearance),
        stations=tuple(pose_from_msg(station) for station in msg.stations),
        dwell_time=float(msg.dwell_time), fleet=fleet_from_msg(msg))
    environment.validate()
    return environment
