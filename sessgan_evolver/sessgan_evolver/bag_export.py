"""A failure bag of an in-process episode: the messages the simulator node would have recorded.

An :class:`~sessgan_evolver.episode_runner.EpisodeTrace` kept with its scans holds everything a
lockstep worker publishes: ``map``, ``tf_static`` and ``goal_pose`` at the start, then per
tick ``clock``, ``odom``, ``tf``, a flyer's ``range_down`` and ``scan``, and the controller's
``cmd_vel`` answer. They
are serialized without ROS (clock, odom and scan with sessgan_sim.cdr, the same bytes the node
publishes; the others with rosbags' Jazzy typestore) and written with
``sessgan_sim.bag_recording.write_episode_bag``, so the bag replays and re-simulates like a
worker's. episode.json also holds the trace summary (thinned trajectory, agent paths and
contact events), which the fault pictures read.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.fleet import fleet_to_json
from sessgan_core.quaternion import quaternion_from_yaw_pitch
from sessgan_evolver.episode_runner import EpisodeTrace
from sessgan_evolver.errors import BagExportError
from sessgan_sim import cdr
from sessgan_sim.bag_recording import BagRecord, jazzy_typestore, write_episode_bag
from sessgan_sim.frames import (
    BASE_FOOTPRINT,
    BASE_LINK,
    MAP_FRAME,
    ODOM_FRAME,
    RANGE_DOWN_FRAME,
    SCAN_FRAME,
)


def _nanoseconds(seconds: float) -> int:
    return int(round(seconds * 1e9))


class _Messages:
    """Builders of the messages not in sessgan_sim.cdr, as rosbags typestore objects."""

    def __init__(self) -> None:
        self.store = jazzy_typestore()
        self.types = self.store.types

    def serialize(self, message: Any) -> bytes:
        return bytes(self.store.serialize_cdr(message, message.__msgtype__))

    def time(self, seconds: float) -> Any:
        sec, nanosec = cdr.stamp(seconds)
        return self.types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)

    def header(self, seconds: float, frame: str) -> Any:
        return self.types['std_msgs/msg/Header'](stamp=self.time(seconds), frame_id=frame)

    def quaternion(self, yaw: float, pitch: float = 0.0) -> Any:
        x, y, z, w = quaternion_from_yaw_pitch(yaw, pitch)
        return self.types['geometry_msgs/msg/Quaternion'](x=x, y=y, z=z, w=w)

    def pose(self, x: float, y: float, yaw: float) -> Any:
        point = self.types['geometry_msgs/msg/Point'](x=float(x), y=float(y), z=0.0)
        return self.types['geometry_msgs/msg/Pose'](position=point,
                                                    orientation=self.quaternion(yaw))

    def transform(self, seconds: float, parent: str, child: str, x: float = 0.0,
                  y: float = 0.0, z: float = 0.0, yaw: float = 0.0, pitch: float = 0.0) -> Any:
        vector = self.types['geometry_msgs/msg/Vector3'](x=float(x), y=float(y), z=float(z))
        transform = self.types['geometry_msgs/msg/Transform'](
            translation=vector, rotation=self.quaternion(yaw, pitch))
        return self.types['geometry_msgs/msg/TransformStamped'](
            header=self.header(seconds, parent), child_frame_id=child, transform=transform)

    def tf(self, transforms: list[Any]) -> bytes:
        return self.serialize(self.types['tf2_msgs/msg/TFMessage'](transforms=transforms))

    def occupancy_grid(self, environment: Environment, seconds: float) -> bytes:
        occupancy = np.asarray(environment.occupancy, dtype=np.int8)
        info = self.types['nav_msgs/msg/MapMetaData'](
            map_load_time=self.time(seconds), resolution=float(environment.resolution),
            width=int(occupancy.shape[1]), height=int(occupancy.shape[0]),
            origin=self.pose(environment.origin[0], environment.origin[1], 0.0))
        return self.serialize(self.types['nav_msgs/msg/OccupancyGrid'](
            header=self.header(seconds, MAP_FRAME), info=info, data=occupancy.reshape(-1)))

    def goal_at(self, x: float, y: float, yaw: float, seconds: float) -> bytes:
        """A mission's later goal (the first is :meth:`goal`)."""
        return self.serialize(self.types['geometry_msgs/msg/PoseStamped'](
            header=self.header(seconds, MAP_FRAME), pose=self.pose(x, y, yaw)))

    def waypoints(self, waypoints: Sequence[Pose2D], seconds: float) -> bytes:
        """nav_msgs/Path of a mission's waypoints (the goal alone in a plain episode)."""
        header = self.header(seconds, MAP_FRAME)
        stamped = self.types['geometry_msgs/msg/PoseStamped']
        return self.serialize(self.types['nav_msgs/msg/Path'](header=header, poses=[
            stamped(header=header, pose=self.pose(pose.x, pose.y, pose.yaw))
            for pose in waypoints]))

    def twist(self, vx: float, vy: float, wz: float, vz: float = 0.0) -> bytes:
        vector = self.types['geometry_msgs/msg/Vector3']
        return self.serialize(self.types['geometry_msgs/msg/Twist'](
            linear=vector(x=float(vx), y=float(vy), z=float(vz)),
            angular=vector(x=0.0, y=0.0, z=float(wz))))


def trace_records(environment: Environment, trace: EpisodeTrace,
                  namespace: str = '') -> Iterator[BagRecord]:
    """The bag records of an episode, in publishing order (module docstring); with the
    mission's ``waypoints`` after the first goal, and each later ``goal_pose`` of a mission
    (``trace.goals``) before the tick it went out at. A fleet's robots each publish under
    r<i>/ with frames prefixed r<i>/ (as the simulator node does), in time order."""
    prefix = '/' + namespace.strip('/') if namespace.strip('/') else ''
    if not trace.fleet:
        yield from _robot_records(environment, trace, prefix, '', environment.waypoints)
        return
    robots = [(trace, environment.waypoints)]
    robots += [(other, (member.goal,)) for other, member in zip(trace.fleet, environment.fleet,
                                                                 strict=True)]
    yield from heapq.merge(*(
        _robot_records(environment, robot_trace, f'{prefix}/r{index}', f'r{index}/', waypoints)
        for index, (robot_trace, waypoints) in enumerate(robots)),
        key=lambda record: record.timestamp_ns)


def _robot_records(environment: Environment, trace: EpisodeTrace, prefix: str,
                   frames: str, waypoints: Sequence[Pose2D]) -> Iterator[BagRecord]:
    """One robot's records under topic ``prefix``, its frames prefixed ``frames``."""
    if trace.scans is None:
        raise BagExportError('the trace has no scans: run the episode with keep_scans=True')
    ticks = len(trace.times)
    if not (len(trace.poses) == len(trace.twists) == len(trace.scans) == ticks
            and len(trace.commands) == max(0, ticks - 1)):
        raise BagExportError(f'trace lengths differ: {ticks} times, {len(trace.poses)} poses, '
                             f'{len(trace.scans)} scans, {len(trace.commands)} commands')
    messages = _Messages()
    lidar = trace.lidar
    start = float(trace.times[0]) if ticks else 0.0
    start_ns = _nanoseconds(start)
    yield BagRecord(f'{prefix}/map', 'nav_msgs/msg/OccupancyGrid', start_ns,
                    messages.occupancy_grid(environment, start))
    odom, footprint, base, scan_frame, range_frame = (
        frames + name for name in (ODOM_FRAME, BASE_FOOTPRINT, BASE_LINK, SCAN_FRAME,
                                   RANGE_DOWN_FRAME))
    static = [messages.transform(start, footprint, base, z=trace.base_height),
              messages.transform(start, base, scan_frame,
                                 z=trace.sensor_height - trace.base_height)]
    ranger = trace.range_finder if trace.range_down is not None else {}
    if ranger:
        static.append(messages.transform(start, base, range_frame,
                                         z=-trace.base_height, pitch=math.pi / 2))
    yield BagRecord(f'{prefix}/tf_static', 'tf2_msgs/msg/TFMessage', start_ns,
                    messages.tf(static))
    first = waypoints[0]
    yield BagRecord(f'{prefix}/goal_pose', 'geometry_msgs/msg/PoseStamped', start_ns,
                    messages.goal_at(first.x, first.y, first.yaw, start))
    yield BagRecord(f'{prefix}/waypoints', 'nav_msgs/msg/Path', start_ns,
                    messages.waypoints(waypoints, start))
    later_goals = {row: (x, y, yaw) for row, x, y, yaw in trace.goals if row > 0}
    for tick in range(ticks):
        seconds = float(trace.times[tick])
        stamp, stamp_ns = cdr.stamp(seconds), _nanoseconds(seconds)
        if tick in later_goals:
            yield BagRecord(f'{prefix}/goal_pose', 'geometry_msgs/msg/PoseStamped', stamp_ns,
                            messages.goal_at(*later_goals[tick], seconds))
        x, y, yaw = (float(v) for v in trace.poses[tick])
        vx, vy, wz = (float(v) for v in trace.twists[tick])
        z, vz = ((float(v) for v in trace.vertical[tick]) if trace.vertical is not None
                 else (0.0, 0.0))
        yield BagRecord(f'{prefix}/clock', 'rosgraph_msgs/msg/Clock', stamp_ns,
                        cdr.clock(stamp))
        yield BagRecord(f'{prefix}/odom', 'nav_msgs/msg/Odometry', stamp_ns, cdr.odometry(
            stamp, odom, footprint, x, y, yaw, vx, vy, wz, z=z, vz=vz))
        yield BagRecord(f'{prefix}/tf', 'tf2_msgs/msg/TFMessage', stamp_ns, messages.tf([
            messages.transform(seconds, MAP_FRAME, odom),
            messages.transform(seconds, odom, footprint, x, y, z, yaw)]))
        if ranger and trace.range_down is not None:
            yield BagRecord(f'{prefix}/range_down', 'sensor_msgs/msg/Range', stamp_ns,
                            cdr.range_reading(stamp, range_frame,
                                              float(trace.range_down[tick]),
                                              ranger['field_of_view'], ranger['min_range'],
                                              ranger['max_range']))
        yield BagRecord(f'{prefix}/scan', 'sensor_msgs/msg/LaserScan', stamp_ns, cdr.laser_scan(
            stamp, scan_frame, trace.scans[tick], lidar['angle_min'], lidar['angle_increment'],
            lidar['range_min'], lidar['range_max'], lidar['scan_time']))
        if tick < len(trace.commands):
            yield BagRecord(f'{prefix}/cmd_vel', 'geometry_msgs/msg/Twist', stamp_ns,
                            messages.twist(*trace.commands[tick]))


def write_trace_bag(directory: str | Path, environment: Environment, trace: EpisodeTrace,
                    metadata: Mapping[str, Any], storage: str = 'mcap',
                    overwrite: bool = True) -> Path:
    """Write the episode as a failure bag directory (sessgan_sim.bag_recording layout);
    ``metadata`` goes into episode.json with the trace summary under 'trace'."""
    facts = dict(metadata)
    facts.setdefault('environment_id', environment.id)
    facts.setdefault('scenario', environment.scenario)
    facts.setdefault('seed', environment.seed)
    facts.setdefault('generation', environment.generation)
    facts.setdefault('member', environment.member)
    facts.setdefault('start', [environment.start.x, environment.start.y, environment.start.yaw])
    facts.setdefault('goal', [environment.goal.x, environment.goal.y, environment.goal.yaw])
    facts.setdefault('feasible', environment.feasible)
    facts.setdefault('route_length', environment.route_length)
    facts.setdefault('route_min_clearance', environment.route_min_clearance)
    facts.setdefault('stations', [[pose.x, pose.y, pose.yaw] for pose in environment.stations])
    facts.setdefault('dwell_time', environment.dwell_time)
    facts.setdefault('fleet', fleet_to_json(environment.fleet))
    facts.setdefault('namespace', '')
    facts['trace'] = trace.summary()
    return write_episode_bag(directory, trace_records(environment, trace), facts,
                             environment.occupancy, environment.resolution,
                             environment.origin, storage=storage, overwrite=overwrite)
