"""A controller written the way any user would: rclpy and standard messages only.

It imports nothing from SESS-GAN, proving that any stack plugs into the simulator through the
topic contract (scan, odom, goal_pose in; cmd_vel out). Policy: turn toward the goal, drive
forward when facing it, slow down near obstacles ahead. ``--nan`` sends NaN velocities instead
(a broken controller), ``--silent`` never answers, ``--blind`` drives straight ahead whatever
the scan says (a faulty controller that must fail a valid test), ``--mute-first-scan`` leaves
the first scan it gets unanswered and then drives as usual (a controller that missed one tick,
as a starved process does: its episode ends controller_unresponsive, the next ones do not),
``--alternate`` is blind in every other episode (the first, third, ...: a fault that shows now
and then; an episode begins where the odometry's stamp goes back or its position jumps, to the
next episode's start), ``--stall`` drives as usual but sleeps 0.2 s wall time after every
20th scan (a process the scheduler leaves out now and then: against a clocked simulator its
commands come late in sim time, the episode ends overloaded), ``--late-start-alternate``
drives as usual but sends no command until 5 s wall time after every other new goal (the
first, third, ...; a goal is new when its stamp is: an injected start-up delay, a stack slow to
plan; the simulator does not judge the wait for a stack's first command, so at 4x real
time such an episode still reaches its goal).
"""

import math
import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from sensor_msgs.msg import LaserScan


class GoToGoal(Node):

    def __init__(self, behaviour: str) -> None:
        super().__init__('external_controller')
        self.behaviour = behaviour
        self.goal = None
        self.pose = None
        self.scans = 0
        self.episodes = 0
        self.last_stamp = None
        self.goal_stamp = None
        self.goals = 0
        self.delayed_goal = 0
        self.start_after = 0.0
        self.cmd_publisher = self.create_publisher(Twist, 'cmd_vel', 10)
        self.create_subscription(PoseStamped, 'goal_pose', self.on_goal, 10)
        self.create_subscription(Odometry, 'odom', self.on_odom, 10)
        self.create_subscription(LaserScan, 'scan', self.on_scan, 10)

    def on_goal(self, msg: PoseStamped) -> None:
        self.goal = (msg.pose.position.x, msg.pose.position.y)
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        if stamp != self.goal_stamp:  # a goal sent again to a late reader keeps its stamp
            self.goal_stamp = stamp
            self.goals += 1

    def on_odom(self, msg: Odometry) -> None:
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        position = (msg.pose.pose.position.x, msg.pose.pose.position.y)
        if (self.last_stamp is None or stamp <= self.last_stamp or self.pose is None
                or math.dist(position, self.pose[:2]) > 0.5):
            self.episodes += 1
        self.last_stamp = stamp
        q = msg.pose.pose.orientation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, yaw)

    def on_scan(self, msg: LaserScan) -> None:
        self.scans += 1
        if self.behaviour == 'late-start-alternate':
            if self.goal is None:
                return  # no command before the first goal: the delay comes first
            if self.goals % 2 == 1:
                if self.delayed_goal != self.goals:
                    self.delayed_goal = self.goals
                    self.start_after = time.monotonic() + 5.0
                if time.monotonic() < self.start_after:
                    return
        if self.behaviour == 'silent' or (self.behaviour == 'mute-first-scan'
                                          and self.scans == 1):
            return
        cmd = Twist()
        if self.behaviour == 'nan':
            cmd.linear.x = float('nan')
            cmd.angular.z = float('inf')
        elif self.behaviour == 'blind' or (self.behaviour == 'alternate'
                                            and self.episodes % 2 == 1):
            cmd.linear.x = 0.5
        elif self.goal is not None and self.pose is not None:
            x, y, yaw = self.pose
            heading = math.atan2(self.goal[1] - y, self.goal[0] - x)
            error = math.atan2(math.sin(heading - yaw), math.cos(heading - yaw))
            ahead = [r for i, r in enumerate(msg.ranges)
                     if abs(msg.angle_min + i * msg.angle_increment) < 0.3 and math.isfinite(r)]
            clearance = min(ahead, default=msg.range_max)
            cmd.angular.z = max(-1.5, min(1.5, 2.0 * error))
            if abs(error) < 0.5:
                cmd.linear.x = max(0.0, min(0.4, 0.5 * (clearance - 0.3)))
        self.cmd_publisher.publish(cmd)
        if self.behaviour == 'stall' and self.scans % 20 == 0:
            time.sleep(0.2)


def main() -> None:
    behaviour = next((flag[2:] for flag in ('--nan', '--silent', '--blind', '--mute-first-scan',
                                                  '--alternate', '--stall',
                                                  '--late-start-alternate')
                      if flag in sys.argv), 'go')
    rclpy.init(args=sys.argv)
    node = GoToGoal(behaviour)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
