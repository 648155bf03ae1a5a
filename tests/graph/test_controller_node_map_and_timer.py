"""The controller node's map subscription and its timer mode: real nodes over DDS, in-process.

Map-aware controllers (every built-in one: the reference navigator plans on the map, the
paper's controllers their routes) subscribe ``map`` and get each map; a controller without
``set_map`` never subscribes it. In ``control_mode:=timer`` the node publishes at its own rate from
the latest scan and the odometry of that scan's tick, instead of once per scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest

rclpy = pytest.importorskip('rclpy')

import numpy as np  # noqa: E402
from nav_msgs.msg import OccupancyGrid  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from sessgan_controllers.controller_interface import VelocityCommand, parameter  # noqa: E402
from sessgan_controllers.controller_node import MAP_QOS, ControllerNode  # noqa: E402
from sessgan_controllers.registry import CONTROLLERS, ControllerSpec  # noqa: E402
from tests.graph.test_controller_node import goal_msg, harness, odom_msg, scan_msg  # noqa: E402,F401

pytestmark = pytest.mark.graph


def room_map(size: int = 12, resolution: float = 0.5) -> OccupancyGrid:
    """A walled square room as nav_msgs/OccupancyGrid."""
    cells = np.zeros((size, size), dtype=np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
    grid = OccupancyGrid()
    grid.header.frame_id = 'map'
    grid.info.resolution = resolution
    grid.info.width = grid.info.height = size
    grid.info.origin.orientation.w = 1.0
    grid.data.frombytes(cells.tobytes())
    return grid


def test_a_map_aware_controller_gets_the_map_and_plans_on_it(harness):  # noqa: F811
    run = harness('reference_navigator')
    maps = run.probe.create_publisher(OccupancyGrid, 'map', MAP_QOS)
    run.spin_until(lambda: maps.get_subscription_count() > 0)
    maps.publish(room_map())
    run.spin_until(lambda: run.node._map is not None)
    assert run.node._controller.costmap is not None
    run.odom.publish(odom_msg(1.0, 1.0))
    run.goal.publish(goal_msg(4.5, 4.5))
    run.spin_until(lambda: run.node._goal is not None and run.node._state is not None)
    command = run.tick(scan_msg())
    assert math.isfinite(command.linear.x) and math.isfinite(command.angular.z)
    assert run.node._controller.path is not None, 'no plan on the map'
    # A malformed map is refused with an error and the last good one stays.
    bad = room_map()
    bad.info.width = 7
    maps.publish(bad)
    for _ in range(25):
        run.executor.spin_once(timeout_sec=0.02)
    assert run.node._map is not None and run.node._map.occupancy.shape == (12, 12)


@dataclass
class CreepConfig:
    goal_tolerance: float = parameter(0.1, 'Distance in m to the goal that counts as reached.')

    def validate(self) -> None:
        """Nothing to check."""


class Creep:
    """A controller without set_map: it creeps forward."""

    def __init__(self, config: CreepConfig) -> None:
        self.config = config

    def compute_command(self, scan, state, goal) -> VelocityCommand:
        return VelocityCommand(0.1, 0.0, 0.0)

    def goal_reached(self, state, goal) -> bool:
        return goal.distance_from(state) <= self.config.goal_tolerance

    def reset(self) -> None:
        """Nothing kept."""


@pytest.fixture
def map_free_controller():
    """A registered controller that takes no map (every built-in one takes it)."""
    name = 'map_free_test_controller'
    CONTROLLERS[name] = ControllerSpec(name, CreepConfig, Creep, 'diff_drive', 'takes no map')
    yield name
    del CONTROLLERS[name]


def test_controllers_without_a_map_never_subscribe_it(harness, map_free_controller):  # noqa: F811
    run = harness(map_free_controller)
    namespace = run.node.get_namespace()
    for _ in range(20):
        run.executor.spin_once(timeout_sec=0.02)
    assert run.probe.count_subscribers(f'{namespace}/map') == 0


def test_timer_mode_publishes_at_its_rate_from_the_latest_scan(harness):  # noqa: F811
    run = harness('nearness_diagram', [Parameter('control_mode', value='timer'),
                                        Parameter('control_rate_hz', value=50.0)])
    for _ in range(20):
        run.executor.spin_once(timeout_sec=0.02)
    assert not run.commands, 'commanded before any scan'
    run.odom.publish(odom_msg())
    run.goal.publish(goal_msg(3.0, 0.0))
    run.spin_until(lambda: run.node._goal is not None and run.node._state is not None)
    run.scan.publish(scan_msg())
    run.spin_until(lambda: len(run.commands) >= 5)  # five commands from one scan
    assert all(command.linear.x > 0.0 for command in run.commands)


def test_timer_mode_reads_a_scan_from_the_pose_of_its_tick(harness):  # noqa: F811
    run = harness('nearness_diagram', [Parameter('control_mode', value='timer')])
    for second, x in ((1, 0.0), (2, 0.5), (3, 1.0)):
        odom = odom_msg(x, 0.0)
        odom.header.stamp.sec = second
        run.odom.publish(odom)
    run.spin_until(lambda: len(run.node._odom_history) == 3)
    scan = scan_msg()
    scan.header.stamp.sec = 2
    assert run.node._state_at(scan).x == pytest.approx(0.5)
    scan.header.stamp.sec = 9
    assert run.node._state_at(scan).x == pytest.approx(1.0)


def test_an_unknown_control_mode_is_refused():
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(ValueError, match='control_mode'):
            ControllerNode('nearness_diagram', context=context, parameter_overrides=[
                Parameter('control_mode', value='sometimes')])
    finally:
        rclpy.try_shutdown(context=context)
