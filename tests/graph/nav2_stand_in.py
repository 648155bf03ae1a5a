"""A stand-in for a Nav2 stack, written with rclpy and standard interfaces only.

It behaves as Nav2 does where the simulator's contract is concerned (Nav2 itself cannot be
installed on this project's machines):

* a controller on a 20 Hz timer on sim time (like controller_server's control loop), reading
  the latest scan, odom and tf (the robot's pose is map->odom->base_footprint from ``tf``, as
  Nav2's costmaps look it up) and publishing Twist, or TwistStamped with ``--stamped``;
* goals on ``goal_pose`` (volatile, like bt_navigator's subscription) and, with ``--action``,
  on a ``navigate_to_pose`` action server (nav2_msgs/action/NavigateToPose) that succeeds when
  the goal is reached and aborts or cancels like bt_navigator;
* with ``--forward-goal-pose`` (and ``--action``), a goal on ``goal_pose`` becomes a goal of its
  own navigate_to_pose server, as bt_navigator does, so the server's status topic shows it;
* with ``--abort-after N``, after N commands it gives up on its navigate_to_pose goal (aborted,
  as bt_navigator when planning and its recoveries failed), stops the robot and sends nothing;
* with ``--costmaps``, the ClearEntireCostmap services of Nav2's two costmaps
  (``global_costmap/clear_entirely_global_costmap`` and ``local_costmap/...``);
  ``--reset-delay S`` makes them answer after S wall seconds.

``--fall-silent-after N`` and ``--wait-after N`` stop the robot after N commands and then
send nothing, for good (a stack whose controller died) or for ``--wait-for`` sim seconds
(Nav2's Wait recovery: behavior_server stops the robot, waits, and no node publishes cmd_vel).

It logs what a test checks: every goal with the sim time it arrived at, every costmap reset,
a line for each backward jump of sim time (tf2 clears its buffer on one) and the number of
commands sent by a sim time every 20 commands. Policy: turn
toward the goal, drive when facing it, slow down near obstacles ahead.

Like Nav2's nodes it reads ``/clock`` (through use_sim_time) and ``/tf``, absolute names: under
a worker's namespace start it as Nav2 is started, with ``-r /clock:=clock -r /tf:=tf``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import rclpy
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.clock import Clock, ClockChange, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

CONTROL_PERIOD = 0.05
"""Sim seconds between commands: controller_server's default controller_frequency, 20 Hz."""
COMMAND_LOG_EVERY = 20
"""A log line every this many commands: how a test sees the loop's rate on sim time."""
NAVIGATION_PERIOD = 0.05
"""Wall seconds between checks of a navigate_to_pose goal."""
GOAL_TOLERANCE = 0.25
"""Metres: Nav2's default xy_goal_tolerance."""


def yaw_of(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def compose(a: tuple[float, float, float], b: tuple[float, float, float]):
    """Pose b given in frame a, expressed in a's parent."""
    ax, ay, ayaw = a
    bx, by, byaw = b
    return (ax + math.cos(ayaw) * bx - math.sin(ayaw) * by,
            ay + math.sin(ayaw) * bx + math.cos(ayaw) * by, ayaw + byaw)


class Nav2StandIn(Node):

    def __init__(self, options) -> None:
        super().__init__('nav2_stand_in')
        self.options = options
        self.scan: LaserScan | None = None
        self.odom: Odometry | None = None
        self.transforms: dict[tuple[str, str], tuple[float, float, float]] = {}
        self.goal: tuple[float, float] | None = None
        self.goal_handle = None
        self.navigation_done = Future()
        self.commands_sent = 0
        self.giving_up = False
        """Set by --abort-after: the navigate_to_pose goal is to be aborted."""
        self.waiting_until = 0.0
        """Sim time until which it sends nothing (--wait-after)."""
        command_type = TwistStamped if options.stamped else Twist
        self.cmd_publisher = self.create_publisher(command_type, 'cmd_vel', 10)
        self.create_subscription(LaserScan, 'scan', self.on_scan, 10)
        self.create_subscription(Odometry, 'odom', self.on_odom, 10)
        # Absolute like tf2_ros' listener; a namespaced stack remaps it (-r /tf:=tf).
        self.create_subscription(TFMessage, '/tf', self.on_tf, 10)
        self.create_subscription(PoseStamped, 'goal_pose', self.on_goal_pose, 10)
        self.create_timer(CONTROL_PERIOD, self.control)
        self.create_timer(NAVIGATION_PERIOD, self.update_navigation,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=True), post_callback=self.on_jump)
        if options.action:
            from nav2_msgs.action import NavigateToPose

            self.action_server = ActionServer(
                self, NavigateToPose, 'navigate_to_pose', execute_callback=self.navigate,
                goal_callback=self.on_navigate_goal,
                cancel_callback=lambda _: CancelResponse.ACCEPT)
            self.self_client = ActionClient(self, NavigateToPose, 'navigate_to_pose')
        if options.costmaps:
            from nav2_msgs.srv import ClearEntireCostmap

            for costmap in ('global', 'local'):
                self.create_service(
                    ClearEntireCostmap, f'{costmap}_costmap/clear_entirely_{costmap}_costmap',
                    lambda request, response, costmap=costmap: self.clear(costmap, response),
                    )
        self.get_logger().info('stand-in ready')

    # ---- inputs ------------------------------------------------------------------------------

    def on_scan(self, msg: LaserScan) -> None:
        self.scan = msg

    def on_odom(self, msg: Odometry) -> None:
        self.odom = msg

    def on_tf(self, msg: TFMessage) -> None:
        for transform in msg.transforms:
            t = transform.transform
            self.transforms[(transform.header.frame_id, transform.child_frame_id)] = (
                t.translation.x, t.translation.y, yaw_of(t.rotation))

    def on_goal_pose(self, msg: PoseStamped) -> None:
        if self.options.forward_goal_pose:
            from nav2_msgs.action import NavigateToPose

            self.get_logger().info('goal_pose forwarded to navigate_to_pose')
            self.self_client.send_goal_async(NavigateToPose.Goal(pose=msg))
        else:
            self.set_goal(msg, 'goal_pose')

    def set_goal(self, msg: PoseStamped, source: str) -> None:
        self.goal = (msg.pose.position.x, msg.pose.position.y)
        now = self.get_clock().now().nanoseconds / 1e9
        self.get_logger().info(
            f'goal from {source}: ({self.goal[0]:.2f}, {self.goal[1]:.2f}) frame '
            f'{msg.header.frame_id!r} stamp {msg.header.stamp.sec}.{msg.header.stamp.nanosec:09d}'
            f' at sim time {now:.3f}')

    def on_jump(self, jump) -> None:
        if jump.clock_change == ClockChange.ROS_TIME_ACTIVATED:
            return
        if jump.delta.nanoseconds < 0:
            self.get_logger().warning(
                f'sim time jumped back by {-jump.delta.nanoseconds / 1e9:.3f} s '
                '(tf2 would clear its buffer)')

    def pose(self):
        """map -> base_footprint from tf, as Nav2 looks the robot up."""
        map_odom = self.transforms.get(('map', 'odom'))
        odom_base = self.transforms.get(('odom', 'base_footprint'))
        if map_odom is None or odom_base is None:
            return None
        return compose(map_odom, odom_base)

    # ---- the 20 Hz control loop --------------------------------------------------------------

    def control(self) -> None:
        fall_silent_after = self.options.fall_silent_after
        if self.options.silent or 0 < fall_silent_after <= self.commands_sent:
            return
        if 0 < self.options.abort_after <= self.commands_sent:
            return  # gave up: no goal, so controller_server sends nothing
        now = self.get_clock().now().nanoseconds / 1e9
        if now < self.waiting_until:
            return
        linear = angular = 0.0
        pose = self.pose()
        if self.goal is not None and pose is not None and self.scan is not None:
            x, y, yaw = pose
            distance = math.hypot(self.goal[0] - x, self.goal[1] - y)
            if distance > GOAL_TOLERANCE:
                heading = math.atan2(self.goal[1] - y, self.goal[0] - x)
                error = math.atan2(math.sin(heading - yaw), math.cos(heading - yaw))
                scan = self.scan
                ahead = [r for i, r in enumerate(scan.ranges)
                         if abs(scan.angle_min + i * scan.angle_increment) < 0.3
                         and math.isfinite(r)]
                clearance = min(ahead, default=scan.range_max)
                angular = max(-1.5, min(1.5, 2.0 * error))
                if abs(error) < 0.5:
                    linear = max(0.0, min(0.5, 0.6 * (clearance - 0.3)))
        if self.commands_sent + 1 == fall_silent_after:
            linear = angular = 0.0  # its last command: a stop
            self.get_logger().info('falling silent')
        if self.commands_sent + 1 == self.options.abort_after:
            linear = angular = 0.0  # controller_server stops the robot when its goal ends
            self.giving_up = True
            self.get_logger().info('giving up on the goal')
        if self.commands_sent + 1 == self.options.wait_after:
            # Nav2's Wait recovery: behavior_server stops the robot, then sends nothing.
            linear = angular = 0.0
            self.waiting_until = now + self.options.wait_for
            self.get_logger().info(f'waiting {self.options.wait_for:g} sim s at {now:.2f}')
        if self.options.stamped:
            command = TwistStamped()
            command.header.stamp = self.get_clock().now().to_msg()
            command.header.frame_id = 'base_footprint'
            twist = command.twist
        else:
            command = twist = Twist()
        twist.linear.x = linear
        twist.angular.z = angular
        self.cmd_publisher.publish(command)
        self.commands_sent += 1
        if self.commands_sent % COMMAND_LOG_EVERY == 0:
            now = self.get_clock().now().nanoseconds / 1e9
            self.get_logger().info(f'{self.commands_sent} commands sent by sim time {now:.3f}')

    # ---- Nav2's servers ----------------------------------------------------------------------

    def clear(self, costmap: str, response):
        if self.options.reset_delay > 0:
            time.sleep(self.options.reset_delay)
        self.get_logger().info(f'cleared the {costmap} costmap')
        return response

    def on_navigate_goal(self, goal_request) -> GoalResponse:
        if self.options.reject_goals:
            self.get_logger().info('rejecting a navigate_to_pose goal')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    async def navigate(self, goal_handle):
        """Runs until the 20 Hz control loop ends the goal (reached, cancelled, preempted):
        awaiting keeps the single-threaded executor free for the loop."""
        from nav2_msgs.action import NavigateToPose

        previous, self.goal_handle = self.goal_handle, goal_handle
        if previous is not None and previous.is_active and not previous.is_cancel_requested:
            previous.abort()  # preempted, as bt_navigator does
            self.navigation_done.set_result(None)
        self.navigation_done = Future()
        self.set_goal(goal_handle.request.pose, 'navigate_to_pose')
        await self.navigation_done
        return NavigateToPose.Result()

    def update_navigation(self) -> None:
        """On a wall-clock timer, like bt_navigator's tree (it answers a cancel also when sim
        time stands still): end the navigate_to_pose goal or send its feedback."""
        from nav2_msgs.action import NavigateToPose

        pose = self.pose()
        goal_handle = self.goal_handle
        if goal_handle is None or not goal_handle.is_active or self.navigation_done.done():
            return
        if goal_handle.is_cancel_requested:
            self.goal = None
            goal_handle.canceled()
            self.get_logger().info('navigate_to_pose goal canceled')
        elif self.giving_up:
            self.goal = None
            goal_handle.abort()
            self.get_logger().info('navigate_to_pose goal aborted')
        elif pose is not None and self.goal is not None and math.hypot(
                self.goal[0] - pose[0], self.goal[1] - pose[1]) <= GOAL_TOLERANCE:
            goal_handle.succeed()
            self.get_logger().info('navigate_to_pose goal succeeded')
        else:
            feedback = NavigateToPose.Feedback()
            if pose is not None and self.goal is not None:
                feedback.current_pose.header.frame_id = 'map'
                feedback.current_pose.pose.position.x, feedback.current_pose.pose.position.y = (
                    pose[0], pose[1])
                feedback.distance_remaining = float(math.hypot(self.goal[0] - pose[0],
                                                               self.goal[1] - pose[1]))
            goal_handle.publish_feedback(feedback)
            return
        self.navigation_done.set_result(None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--stamped', action='store_true', help='publish TwistStamped')
    parser.add_argument('--action', action='store_true', help='serve navigate_to_pose')
    parser.add_argument('--costmaps', action='store_true', help='serve the costmap resets')
    parser.add_argument('--reset-delay', type=float, default=0.0,
                        help='wall seconds before a reset is answered')
    parser.add_argument('--reject-goals', action='store_true',
                        help='reject navigate_to_pose goals')
    parser.add_argument('--forward-goal-pose', action='store_true',
                        help='make a goal_pose a goal of its own navigate_to_pose server, as '
                             'bt_navigator does (needs --action)')
    parser.add_argument('--abort-after', type=int, default=0, metavar='N',
                        help='after N commands (the last a stop) abort the navigate_to_pose '
                             'goal and send nothing: a stack that gave up')
    parser.add_argument('--silent', action='store_true', help='never publish a command')
    parser.add_argument('--fall-silent-after', type=int, default=0, metavar='N',
                        help='publish N commands, the last a stop, then none (a stack whose '
                             'controller died)')
    parser.add_argument('--wait-after', type=int, default=0, metavar='N',
                        help='after N commands (the last a stop) send nothing for --wait-for '
                             "sim s, then go on: Nav2's Wait recovery")
    parser.add_argument('--wait-for', type=float, default=5.0, metavar='S',
                        help="sim seconds of --wait-after (Nav2's default BT waits 5 s)")
    args = rclpy.utilities.remove_ros_args(sys.argv)[1:]
    options = parser.parse_args(args)
    if options.forward_goal_pose and not options.action:
        parser.error('--forward-goal-pose needs --action (the server it forwards to)')
    rclpy.init(args=sys.argv)
    node = Nav2StandIn(options)
    # One thread with rclpy's events executor, as the built-in controllers spin: at 80 ticks
    # per wall second (clocked mode, real-time factor 4) the multi-threaded executor fell
    # behind on a 2-core machine and handled seconds-old clock, tf and scan messages.
    executor = EventsExecutor(context=node.context)
    executor.add_node(node)
    try:
        while rclpy.ok(context=node.context):
            executor.spin_once(timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
