"""A route-following controller written with rclpy, numpy and standard messages only.

It imports nothing from SESS-GAN: it plans its own route on the ``map`` topic (nav_msgs/
OccupancyGrid, transient local) and follows it, the way a simple planner-based stack would.
Planning: free cells are split into quarter cells; a quarter cell is usable when its centre
keeps ``robot_radius + margin`` from every occupied cell; breadth-first search from the robot
to the goal over usable quarter cells. Following: pure pursuit toward the route point
``lookahead`` metres ahead, turning in place when that point is far off the heading.
"""

import math
from collections import deque

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan

SPLIT = 4
ROBOT_RADIUS = 0.2
MARGIN = 0.1
LOOKAHEAD = 0.35
SPEED = 0.5


def plan(grid: OccupancyGrid, start, goal):
    """Route (list of (x, y)) from start to goal, or [] when none."""
    info = grid.info
    res, width, height = info.resolution, info.width, info.height
    ox, oy = info.origin.position.x, info.origin.position.y
    occupied = np.asarray(grid.data, dtype=np.int16).reshape(height, width) != 0
    rows, cols = np.nonzero(occupied)
    fine = res / SPLIT
    ys = oy + (np.arange(height * SPLIT) + 0.5) * fine
    xs = ox + (np.arange(width * SPLIT) + 0.5) * fine
    # Distance from each quarter-cell centre to the nearest occupied square or the border.
    gx = np.maximum.reduce([ox + cols[None, :] * res - xs[:, None],
                            xs[:, None] - ox - (cols[None, :] + 1) * res,
                            np.zeros((len(xs), len(cols)))])
    gy = np.maximum.reduce([oy + rows[None, :] * res - ys[:, None],
                            ys[:, None] - oy - (rows[None, :] + 1) * res,
                            np.zeros((len(ys), len(rows)))])
    clearance = np.full((len(ys), len(xs)), np.inf)
    for index in range(len(rows)):
        clearance = np.minimum(clearance, np.hypot(gy[:, index][:, None], gx[:, index][None, :]))
    border = np.minimum.outer(np.minimum(ys - oy, oy + height * res - ys),
                              np.minimum(xs - ox, ox + width * res - xs))
    usable = np.minimum(clearance, border) >= ROBOT_RADIUS + MARGIN

    def cell(point):
        return (int((point[1] - oy) / fine), int((point[0] - ox) / fine))

    source, target = cell(start), cell(goal)
    previous = {source: None}
    queue = deque([source])
    while queue:
        current = queue.popleft()
        if current == target:
            break
        r, c = current
        for nxt in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
            if (0 <= nxt[0] < len(ys) and 0 <= nxt[1] < len(xs) and usable[nxt]
                    and nxt not in previous):
                previous[nxt] = current
                queue.append(nxt)
    if target not in previous:
        return []
    route, current = [], target
    while current is not None:
        route.append((xs[current[1]], ys[current[0]]))
        current = previous[current]
    return route[::-1]


class RouteFollower(Node):

    def __init__(self) -> None:
        super().__init__('route_follower')
        self.grid = self.goal = self.pose = None
        self.route = []
        self.cmd_publisher = self.create_publisher(Twist, 'cmd_vel', 10)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(OccupancyGrid, 'map', self.on_map, latched)
        self.create_subscription(PoseStamped, 'goal_pose', self.on_goal, 10)
        self.create_subscription(Odometry, 'odom', self.on_odom, 10)
        self.create_subscription(LaserScan, 'scan', self.on_scan, 10)

    def on_map(self, msg: OccupancyGrid) -> None:
        self.grid, self.route = msg, []

    def on_goal(self, msg: PoseStamped) -> None:
        goal = (msg.pose.position.x, msg.pose.position.y)
        if goal != self.goal:
            self.goal, self.route = goal, []

    def on_odom(self, msg: Odometry) -> None:
        q = msg.pose.pose.orientation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, yaw)

    def on_scan(self, msg: LaserScan) -> None:
        cmd = Twist()
        if None not in (self.grid, self.goal, self.pose):
            x, y, yaw = self.pose
            if not self.route:
                self.route = plan(self.grid, (x, y), self.goal)
            # Drop route points behind the lookahead circle; steer at the first beyond it.
            while len(self.route) > 1 and math.hypot(self.route[0][0] - x,
                                                     self.route[0][1] - y) < LOOKAHEAD:
                self.route.pop(0)
            if self.route:
                tx, ty = self.route[0]
                error = math.atan2(ty - y, tx - x) - yaw
                error = math.atan2(math.sin(error), math.cos(error))
                cmd.angular.z = max(-1.5, min(1.5, 2.5 * error))
                if abs(error) < 0.6:
                    cmd.linear.x = SPEED * (1.0 - abs(error) / 0.6)
        self.cmd_publisher.publish(cmd)


def main() -> None:
    rclpy.init()
    node = RouteFollower()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
