"""The robot-under-test topics a simulator worker publishes, and the recording of them.

Names are relative (``-r __ns:=/w0`` moves them all). Every message is stamped with the sim
time of its tick in integer nanoseconds: the episode's time plus the worker's clock origin,
which only moves forward from one episode to the next (see SimulatorNode).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan, Range
from tf2_msgs.msg import TFMessage

from sessgan_core.environment import Pose2D
from sessgan_core.ros_conversion import occupancy_grid_msg
from sessgan_sim import cdr
from sessgan_sim import ros_messages as rm
from sessgan_sim.bag_recording import BagRecord

LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""map, tf_static and goal_pose: a reader that joins late still gets the latest message."""
SENSOR_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
ACK_TIMEOUT = Duration(seconds=1.0)

MESSAGE_TYPES = {
    'waypoints': 'nav_msgs/msg/Path',
    'scan': 'sensor_msgs/msg/LaserScan', 'odom': 'nav_msgs/msg/Odometry',
    'tf': 'tf2_msgs/msg/TFMessage', 'tf_static': 'tf2_msgs/msg/TFMessage',
    'clock': 'rosgraph_msgs/msg/Clock', 'map': 'nav_msgs/msg/OccupancyGrid',
    'goal_pose': 'geometry_msgs/msg/PoseStamped', 'range_down': 'sensor_msgs/msg/Range'}
"""ROS type name of every published topic (as failure bags record it)."""


def time_of(stamp_ns: int) -> Time:
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def stamp_of(stamp_ns: int) -> tuple[int, int]:
    return divmod(int(stamp_ns), 1_000_000_000)


@dataclass
class Recording:
    """Every message of an episode, in order, kept as messages (or already serialized bytes)
    until a bag is wanted."""

    entries: list = field(default_factory=list)

    def add(self, topic: str, msgtype: str, stamp_ns: int, message) -> None:
        self.entries.append((topic, msgtype, stamp_ns, message))

    def records(self):
        for topic, msgtype, stamp_ns, message in self.entries:
            data = message if isinstance(message, bytes) else serialize_message(message)
            yield BagRecord(topic, msgtype, stamp_ns, data)


class RobotTopics:
    """The publishers of the robot-under-test contract on ``node`` (a fleet robot's: on a
    node in its namespace, its frames named with ``frame_prefix``, e.g. 'r1/')."""

    def __init__(self, node, frame_prefix: str = '') -> None:
        self.node = node
        self.frame_prefix = frame_prefix
        self.publishers = {
            # Missions: every waypoint at once, latched like goal_pose.
            'waypoints': node.create_publisher(Path, 'waypoints', LATCHED_QOS),
            'scan': node.create_publisher(LaserScan, 'scan', SENSOR_QOS),
            'odom': node.create_publisher(Odometry, 'odom', SENSOR_QOS),
            'tf': node.create_publisher(TFMessage, 'tf', SENSOR_QOS),
            'tf_static': node.create_publisher(TFMessage, 'tf_static', LATCHED_QOS),
            'clock': node.create_publisher(Clock, 'clock', SENSOR_QOS),
            'map': node.create_publisher(OccupancyGrid, 'map', LATCHED_QOS),
            'goal_pose': node.create_publisher(PoseStamped, 'goal_pose', LATCHED_QOS),
            # Published only while the robot is a flyer (the one with a downward ranger).
            'range_down': node.create_publisher(Range, 'range_down', SENSOR_QOS),
        }
        self.names = {topic: node.resolve_topic_name(topic)
                      for topic in (*self.publishers, 'cmd_vel')}
        self._goal: tuple[Pose2D, int] | None = None  # (goal, stamp_ns) sent on goal_pose
        self._goal_readers_told = 0

    def publish(self, topic: str, message, stamp_ns: int, recording: Recording | None) -> None:
        self.publishers[topic].publish(message)
        if recording is not None:
            recording.add(self.names[topic], MESSAGE_TYPES[topic], stamp_ns, message)

    def readers(self, topic: str) -> int:
        """Readers matched to our writer of ``topic``."""
        return self.publishers[topic].get_subscription_count()

    # ---- an episode's messages ------------------------------------------------------------

    def publish_world(self, environment, ride_height: float, sensor_height: float,
                      stamp_ns: int, recording: Recording | None,
                      range_down: bool = False) -> None:
        """The episode's map and static transforms (both latched; ``range_down``: the robot
        has the downward range sensor, base_range_down), acknowledged by every reliable
        reader before this returns, as the goal is (:meth:`publish_goal`): a controller that
        plans on the map gets it before the first scan. Unacknowledged, a map delivered 66 ms
        late under load left the reference navigator standing for its first ticks, and the
        lockstep episode differed from its unloaded run."""
        stamp = time_of(stamp_ns)
        self.publish('map', occupancy_grid_msg(environment, stamp=stamp), stamp_ns, recording)
        self.publish('tf_static', rm.static_tf_msg(stamp, ride_height, sensor_height,
                                                   range_down, self.frame_prefix),
                     stamp_ns, recording)
        for name in ('map', 'tf_static'):
            self.publishers[name].wait_for_all_acked(ACK_TIMEOUT)

    def publish_goal(self, goal: Pose2D, stamp_ns: int, recording: Recording | None) -> None:
        """The goal on goal_pose (latched: a transient-local reader that joins later gets
        it), acknowledged by every reliable reader before this returns.

        The acknowledgement orders the goal before the episode's first scan in a controller
        that takes messages in arrival order (the built-in controllers' events executor): sim
        time no longer goes back at a new episode, so a scan handled before its episode's goal
        would be answered with the previous goal. A reader that does not acknowledge within a
        second (a stalled one) does not hold the episode up.
        """
        # Counted before it is sent: a reader that matches while the goal goes out or is
        # acknowledged may miss it (a volatile one), so it counts as new and gets it again.
        readers = self.readers('goal_pose')
        self.publish('goal_pose', rm.goal_msg(time_of(stamp_ns), goal.x, goal.y, goal.yaw),
                     stamp_ns, recording)
        self.publishers['goal_pose'].wait_for_all_acked(ACK_TIMEOUT)
        self._goal = (goal, stamp_ns)
        self._goal_readers_told = readers

    def forget_goal(self) -> None:
        """A new episode: nothing to resend until its goal is sent on goal_pose."""
        self._goal = None

    def publish_waypoints(self, waypoints, stamp_ns: int, recording: Recording | None) -> None:
        """Every waypoint of the episode's mission (stations, then home; a plain episode's
        goal alone) as a nav_msgs/Path in frame map, latched."""
        stamp = time_of(stamp_ns)
        path = Path()
        path.header.stamp = stamp
        path.header.frame_id = rm.MAP_FRAME
        path.poses = [rm.goal_msg(stamp, pose.x, pose.y, pose.yaw) for pose in waypoints]
        self.publish('waypoints', path, stamp_ns, recording)

    def republish_goal(self, force: bool = False) -> bool:
        """Send the episode's goal_pose again (not recorded) when a reader matched since it
        was last sent, or when ``force``: a volatile reader (Nav2's bt_navigator has one) that
        joins late gets no latched message. True when it was sent; never when the episode's
        goal did not go out on goal_pose."""
        if self._goal is None:
            return False
        goal, stamp_ns = self._goal
        readers = self.readers('goal_pose')
        if not force and readers <= self._goal_readers_told:
            self._goal_readers_told = min(self._goal_readers_told, readers)
            return False
        self.publishers['goal_pose'].publish(
            rm.goal_msg(time_of(stamp_ns), goal.x, goal.y, goal.yaw))
        self._goal_readers_told = readers
        return True

    def publish_tick(self, observation, stamp_ns: int, recording: Recording | None) -> None:
        """clock, odom, tf (when anyone listens or records), the flyer's range_down and scan
        of one tick; the messages of every tick are published serialized (sessgan_sim.cdr)."""
        stamp = stamp_of(stamp_ns)
        self.publish('clock', cdr.clock(stamp), stamp_ns, recording)
        pose = observation.pose
        altitude = observation.altitude
        twist = observation.twist
        prefix = self.frame_prefix
        odom = cdr.odometry(stamp, prefix + rm.ODOM_FRAME, prefix + rm.BASE_FOOTPRINT, pose.x,
                            pose.y, pose.yaw, twist.vx, twist.vy, twist.wz, z=altitude,
                            vz=observation.climb_rate)
        self.publish('odom', odom, stamp_ns, recording)
        if recording is not None or self.readers('tf') > 0:
            # Building tf costs more than the check; most controllers under test use odom.
            self.publish('tf', rm.dynamic_tf_msg(time_of(stamp_ns), pose.x, pose.y, pose.yaw,
                                                 altitude, prefix), stamp_ns, recording)
        ranger = observation.range_finder
        if ranger is not None and observation.range_down is not None:
            self.publish('range_down', cdr.range_reading(
                stamp, prefix + rm.RANGE_DOWN_FRAME, observation.range_down, ranger.field_of_view,
                ranger.min_range, ranger.max_range), stamp_ns, recording)
        lidar = observation.lidar
        self.publish('scan', cdr.laser_scan(
            stamp, prefix + rm.SCAN_FRAME, observation.scan, lidar.angle_min,
            lidar.angle_increment, lidar.range_min, lidar.range_max, lidar.scan_time),
            stamp_ns, recording)
