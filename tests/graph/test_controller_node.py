"""The controller nodes' topic contract: real nodes over DDS, in this process.

The nodes are thin, so this checks the adapter: one cmd_vel per scan, zero without a
goal or odometry, Twist or TwistStamped, the goal logic and parameter validation.
The nodes run in this process with a context of their own (marked ``graph``: they talk
over DDS); it needs rclpy and the standard messages but no built workspace.
"""

from __future__ import annotations

import math
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped, Twist, TwistStamped  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import LaserScan  # noqa: E402

from sessgan_controllers.controller_node import GOAL_QOS, ControllerNode  # noqa: E402

pytestmark = pytest.mark.graph


def scan_msg(range_value: float = math.inf) -> LaserScan:
    msg = LaserScan()
    msg.header.frame_id = 'base_scan'
    msg.angle_min = -math.pi
    msg.angle_increment = 2.0 * math.pi / 360
    msg.angle_max = msg.angle_min + 359 * msg.angle_increment
    msg.range_min = 0.12
    msg.range_max = 10.0
    msg.ranges = [range_value] * 360
    return msg


def odom_msg(x: float = 0.0, y: float = 0.0, yaw: float = 0.0) -> Odometry:
    msg = Odometry()
    msg.header.frame_id = 'odom'
    msg.child_frame_id = 'base_footprint'
    msg.pose.pose.position.x = x
    msg.pose.pose.position.y = y
    msg.pose.pose.orientation.z = math.sin(yaw / 2.0)
    msg.pose.pose.orientation.w = math.cos(yaw / 2.0)
    return msg


def goal_msg(x: float, y: float) -> PoseStamped:
    msg = PoseStamped()
    msg.header.frame_id = 'map'
    msg.pose.position.x = x
    msg.pose.position.y = y
    msg.pose.orientation.w = 1.0
    return msg


class Harness:
    """A controller node and a probe node playing the simulator, sharing one executor."""

    def __init__(self, controller: str, namespace: str, parameters: list[Parameter] = ()) -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = ControllerNode(controller, context=self.context, namespace=namespace,
                                   parameter_overrides=list(parameters))
        self.probe = rclpy.create_node('probe', namespace=namespace, context=self.context)
        stamped = self.node.get_parameter('use_stamped_cmd_vel').value
        self.commands: list = []
        self.probe.create_subscription(TwistStamped if stamped else Twist, 'cmd_vel',
                                       self.commands.append, 10)
        self.scan = self.probe.create_publisher(LaserScan, 'scan', 10)
        self.odom = self.probe.create_publisher(Odometry, 'odom', 10)
        self.goal = self.probe.create_publisher(PoseStamped, 'goal_pose', GOAL_QOS)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.spin_until(lambda: self.scan.get_subscription_count() > 0
                        and self.goal.get_subscription_count() > 0
                        and self.probe.count_publishers('cmd_vel') > 0)

    def spin_until(self, predicate, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            assert time.monotonic() < deadline, 'timed out waiting for the graph'
            self.executor.spin_once(timeout_sec=0.02)

    def tick(self, scan: LaserScan | None = None) -> object:
        """Publish a scan like a lockstep simulator and return the one command it answers."""
        count = len(self.commands)
        self.scan.publish(scan or scan_msg())
        self.spin_until(lambda: len(self.commands) > count)
        return self.commands[-1]

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def harness(request):
    created = []

    def make(controller='nearness_diagram', parameters=()):
        item = Harness(controller, f'/ctl_test_{len(created)}_{id(created) % 10000}', parameters)
        created.append(item)
        return item

    yield make
    for item in created:
        item.close()


def test_scan_waits_for_a_goal_then_drives_to_the_goal(harness):
    run = harness()
    run.scan.publish(scan_msg())  # no goal, no odometry: no answer yet
    run.spin_until(lambda: run.node._waiting_scan is not None)
    assert not run.commands
    run.odom.publish(odom_msg())
    run.goal.publish(goal_msg(3.0, 0.0))
    run.spin_until(lambda: run.commands)  # the waiting scan is answered with the goal
    command = run.commands[-1]
    assert command.linear.x > 0.0 and abs(command.angular.z) < 1e-6
    # At the goal it stops, and keeps answering every scan with zero.
    run.odom.publish(odom_msg(2.95, 0.0))
    run.spin_until(lambda: run.node._state.x > 2.9)
    assert run.tick().linear.x == 0.0
    assert run.tick().linear.x == 0.0
    # Every goal message is a new goal, even at a position used before.
    run.odom.publish(odom_msg(0.0, 0.0))
    run.goal.publish(goal_msg(3.0, 0.0))
    run.spin_until(lambda: not run.node._goal_reached)
    assert run.tick().linear.x > 0.0


def test_a_resent_goal_is_not_a_new_goal(harness):
    run = harness('reference_navigator')
    goal = goal_msg(3.0, 0.0)
    goal.header.stamp.sec = 5
    run.odom.publish(odom_msg(2.95, 0.0))
    run.goal.publish(goal)
    run.spin_until(lambda: run.node._goal is not None and run.node._state is not None)
    assert run.tick().linear.x == 0.0 and run.node._goal_reached
    # The simulator resends the goal (same stamp) for a reader that joined late: the goal in
    # force, so the navigator keeps its state instead of being reset as for a new goal.
    run.node._controller.path = 'kept'
    run.goal.publish(goal)
    deadline = time.monotonic() + 0.5
    while time.monotonic() < deadline:
        run.executor.spin_once(timeout_sec=0.02)
    assert run.node._goal_reached and run.node._controller.path == 'kept'
    # The same place with a new stamp is a new goal.
    goal.header.stamp.sec = 6
    run.goal.publish(goal)
    run.spin_until(lambda: not run.node._goal_reached)
    assert run.node._controller.path is None


@pytest.mark.parametrize('controller', ['velocity_projection', 'race_controller'])
def test_stamped_commands(harness, controller):
    run = harness(controller, [Parameter('use_stamped_cmd_vel', value=True)])
    odom = odom_msg()
    odom.header.stamp.sec = 42  # the odometry of the scan's tick
    if controller == 'velocity_projection':
        odom.pose.pose.position.z = 0.9  # airborne, a little below its cruise altitude
    run.odom.publish(odom)
    run.goal.publish(goal_msg(0.0, 5.0))
    run.spin_until(lambda: run.node._goal is not None and run.node._state is not None)
    scan = scan_msg()
    scan.header.stamp.sec = 42
    command = run.tick(scan)
    assert isinstance(command, TwistStamped)
    assert command.header.stamp.sec == 42
    assert command.header.frame_id == 'base_footprint'
    assert command.twist.angular.z > 0.0  # the goal is to the left
    if controller == 'velocity_projection':  # and it climbs back to its cruise altitude
        assert command.twist.linear.z == pytest.approx(0.05)


def test_scan_waits_for_the_odometry_of_its_tick(harness):
    run = harness()
    run.odom.publish(odom_msg())
    run.goal.publish(goal_msg(0.0, 5.0))
    run.spin_until(lambda: run.node._goal is not None and run.node._state is not None)
    scan = scan_msg()
    scan.header.stamp.sec = 7
    run.scan.publish(scan)
    run.spin_until(lambda: run.node._waiting_scan is not None)
    assert not run.commands, 'answered with the odometry of an older tick'
    odom = odom_msg()
    odom.header.stamp.sec = 7
    run.odom.publish(odom)
    run.spin_until(lambda: run.commands)
    assert len(run.commands) == 1


def test_parameters_are_declared_and_validated(harness):
    run = harness(parameters=[Parameter('max_linear_speed', value=0.3)])
    assert run.node.get_parameter('max_linear_speed').value == pytest.approx(0.3)
    assert run.node.get_parameter('use_sim_time').value is False
    rejected = run.node.set_parameters([Parameter('security_distance', value=-1.0)])[0]
    assert not rejected.successful and 'security_distance' in rejected.reason
    accepted = run.node.set_parameters([Parameter('max_linear_speed', value=0.6)])[0]
    assert accepted.successful
    assert run.node._controller.config.max_linear_speed == pytest.approx(0.6)


def test_new_episode_drops_the_old_goal_and_pose(harness):
    run = harness()
    old = odom_msg()
    old.header.stamp.sec = 10
    run.odom.publish(old)
    run.goal.publish(goal_msg(3.0, 0.0))
    run.spin_until(lambda: run.node._goal is not None and run.node._state is not None)
    scan = scan_msg()
    scan.header.stamp.sec = 10
    run.tick(scan)
    count = len(run.commands)
    run.scan.publish(scan_msg())  # sim time back at 0: a new episode began
    run.spin_until(lambda: run.node._waiting_scan is not None
                   and run.node._waiting_scan[0] == 0)
    assert run.node._goal is None and run.node._state is None
    run.odom.publish(odom_msg())
    run.spin_until(lambda: run.node._state is not None)
    assert len(run.commands) == count, 'answered before the new episode had its goal'
    run.goal.publish(goal_msg(0.0, 3.0))
    run.spin_until(lambda: len(run.commands) > count)
