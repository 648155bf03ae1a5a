"""The node shared by the built-in controllers: the robot-under-test topic contract.

Subscribes ``scan`` (sensor_msgs/LaserScan), ``odom`` (nav_msgs/Odometry) and
``goal_pose`` (geometry_msgs/PoseStamped); publishes ``cmd_vel``
(geometry_msgs/Twist, or TwistStamped with ``use_stamped_cmd_vel``). Topic
names are relative, so a namespace (``-r __ns:=/w0``) moves them all.

One command is published per received scan, computed from that scan, the
odometry of the same tick (same stamp, or newer) and the goal: a lockstep
simulator that publishes a tick's odom, then its scan, and waits for
``cmd_vel`` gets exactly one answer per tick, whatever order the executor
hands the messages over in. A scan waits for its odometry and for a goal
(sim time going back starts a new episode: the old goal and pose are
dropped). Once the goal is reached the command is zero. Every
message on ``goal_pose`` is a new goal (as for Nav2's bt_navigator), even at
the same position: a new episode may reuse a goal. The one exception is the
goal in force sent again with its own (non-zero) stamp: the simulator resends
it for readers that joined late, and taking it as new would reset the
controller at a moment set by wall-clock timing.

The goal is read in its own frame; the simulator's map->odom transform is
the identity (perfect localisation), so map and odom coordinates agree.

Controllers that plan on a map (a ``set_map`` method, see
:class:`~sessgan_controllers.controller_interface.MapAwareController`) also subscribe ``map``
(nav_msgs/OccupancyGrid, reliable and transient local, depth 1, as the simulator
publishes it) and get every map that arrives; the others never subscribe it.

``control_mode`` chooses when commands are published:

* ``scan`` (default): one command per scan, as above; for a lockstep simulator.
* ``timer``: a command every ``1 / control_rate_hz`` seconds of the node's clock (sim
  time with ``use_sim_time``), computed from the latest scan, the odometry of that scan's
  tick (the scan is read from where the robot was when it was taken: pairing it with a
  newer pose would shift every return by the distance driven since) and the goal, the
  way Nav2's controller_server runs (20 Hz by default); for a clocked simulator. Scans
  are not answered one by one.

Every built-in controller runs through :func:`main`, one entry point for all of them: the
executable's name (``ros2 run sessgan_controllers nearness_diagram``) is the registry name of
the controller it runs (:mod:`sessgan_controllers.registry`). Parameters: the fields of the
controller's config plus ``use_stamped_cmd_vel``, ``base_frame_id``, ``control_mode`` and
``control_rate_hz``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import rclpy
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from sensor_msgs.msg import LaserScan

from sessgan_controllers.controller_interface import (
    STOP,
    Goal,
    MapData,
    RobotState,
    VelocityCommand,
    accepts_map,
    config_help,
)
from sessgan_controllers.messages import (
    goal_from_pose,
    map_from_msg,
    odom_from_cdr,
    scan_from_msg,
    twist_from_command,
    twist_stamped_from_command,
)
from sessgan_controllers.registry import ControllerSpec, get_controller
from sessgan_core.node_help import exit_if_help

GOAL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
"""Matches reliable publishers, volatile or transient-local (a latched goal from a
transient-local publisher that started earlier is not replayed to a volatile reader)."""

MAP_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1,
    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""As the simulator publishes ``map``: a controller started later still gets the last map."""

CONTROL_MODES = ('scan', 'timer')

ODOM_HISTORY = 20
"""Timer mode: odometry messages kept to find the one of the latest scan's tick."""

CMD_VEL_QOS_DEPTH = 10
SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                        reliability=ReliabilityPolicy.RELIABLE)
"""Reliable: a lockstep simulator starts publishing once it has matched our scan reader, and
only a reliable reader still gets what was sent before it matched the simulator in turn (a
lost first tick would stall the episode until the startup timeout)."""


def _nanoseconds(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class ControllerNode(Node):
    """A registered controller core wrapped in the topic contract."""

    controller_name = ''
    """Registry name of the controller, unless given to the constructor (a subclass may set
    it)."""

    def __init__(self, controller_name: str = '', **kwargs: Any) -> None:
        """``controller_name``: registry name (also the node's default name); ``kwargs`` go to
        rclpy's Node (context, namespace, parameter_overrides, ...)."""
        spec = get_controller(controller_name or self.controller_name)
        super().__init__(spec.name, **kwargs)
        self._spec: ControllerSpec = spec
        self._config = self._declare_config(spec.config_type)
        self._controller = spec.make(self._config)
        self._stamped = bool(self.declare_parameter(
            'use_stamped_cmd_vel', False, ParameterDescriptor(
                description='Publish geometry_msgs/TwistStamped on cmd_vel instead of Twist.',
                read_only=True)).value)
        self._base_frame = str(self.declare_parameter(
            'base_frame_id', 'base_footprint', ParameterDescriptor(
                description='frame_id of TwistStamped commands.', read_only=True)).value)
        self._control_mode = str(self.declare_parameter(
            'control_mode', 'scan', ParameterDescriptor(
                description="'scan': one command per scan (lockstep); 'timer': a command every "
                            '1 / control_rate_hz s of the node clock from the latest scan '
                            '(clocked simulation, like Nav2).', read_only=True)).value)
        control_rate = self.declare_parameter(
            'control_rate_hz', 20.0, ParameterDescriptor(
                description="Commands per second of the node clock in 'timer' mode.",
                read_only=True)).value
        if self._control_mode not in CONTROL_MODES:
            raise ValueError(f'control_mode must be one of {", ".join(CONTROL_MODES)}, got '
                             f'{self._control_mode!r}')
        if not (isinstance(control_rate, (int, float)) and math.isfinite(control_rate)
                and control_rate > 0.0):
            raise ValueError(f'control_rate_hz must be a positive number, got {control_rate!r}')
        self._timer_mode = self._control_mode == 'timer'
        self._latest_scan: LaserScan | None = None
        self._odom_history: deque[tuple[int, RobotState]] = deque(maxlen=ODOM_HISTORY)
        self._map: MapData | None = None
        self._state: RobotState | None = None
        self._odom_stamp: int | None = None
        self._waiting_scan: tuple[int, LaserScan] | None = None
        self._last_scan_stamp: int | None = None
        self._goal_since_last_scan = False
        self._goal: Goal | None = None
        self._goal_stamp: int | None = None
        self._goal_reached = False
        self._warned_no_odom = False
        self._warned_frames: set[str] = set()
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._cmd_vel = self.create_publisher(
            TwistStamped if self._stamped else Twist, 'cmd_vel', CMD_VEL_QOS_DEPTH)
        self.create_subscription(LaserScan, 'scan', self._on_scan, SENSOR_QOS)
        self.create_subscription(Odometry, 'odom', self._on_odom, SENSOR_QOS, raw=True)
        self.create_subscription(PoseStamped, 'goal_pose', self._on_goal, GOAL_QOS)
        if accepts_map(self._controller):
            self.create_subscription(OccupancyGrid, 'map', self._on_map, MAP_QOS)
        if self._timer_mode:
            self.create_timer(1.0 / float(control_rate), self._on_timer)

    # ----------------------------------------------------------------------------------------
    # Parameters: one per config field, validated as a whole before they are applied.

    def _declare_config(self, config_type: type) -> Any:
        help_texts = config_help(config_type)
        values = {}
        for item in dataclasses.fields(config_type):
            default = item.default
            parameter = self.declare_parameter(
                item.name, default, ParameterDescriptor(description=help_texts[item.name]))
            values[item.name] = parameter.value
        config = config_type(**values)
        config.validate()
        return config

    def _config_with(self, parameters: list[Parameter]) -> Any:
        names = {item.name for item in dataclasses.fields(self._spec.config_type)}
        changes = {p.name: p.value for p in parameters if p.name in names}
        if not changes:
            return None
        return dataclasses.replace(self._config, **changes)

    def _validate_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        try:
            config = self._config_with(parameters)
            if config is not None:
                config.validate()
        except (TypeError, ValueError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        config = self._config_with(parameters)
        if config is not None:
            self._config = config
            self._controller = self._spec.make(config)
            if self._map is not None and accepts_map(self._controller):
                self._controller.set_map(self._map)
            self.get_logger().info(f'Parameters updated: {config}')

    # ----------------------------------------------------------------------------------------
    # Topics

    def _on_odom(self, data: bytes) -> None:
        self._odom_stamp, self._state = odom_from_cdr(data)
        if self._timer_mode:
            self._odom_history.append((self._odom_stamp, self._state))
        else:
            self._answer_if_ready()

    def _on_map(self, msg: OccupancyGrid) -> None:
        try:
            grid = map_from_msg(msg)
            self._controller.set_map(grid)
        except ValueError as err:
            self.get_logger().error(f'Ignoring an unusable map: {err}')
            return
        self._map = grid
        self.get_logger().info(
            f'New map: {grid.occupancy.shape[1]}x{grid.occupancy.shape[0]} cells of '
            f'{grid.resolution:g} m')

    def _on_timer(self) -> None:
        """Timer mode: a command from the latest scan, odometry and goal."""
        if self._latest_scan is None:
            return
        command = self._command_for(self._latest_scan, self._state_at(self._latest_scan))
        if self._stamped:
            stamp = self.get_clock().now().to_msg()
            self._cmd_vel.publish(twist_stamped_from_command(command, stamp, self._base_frame))
        else:
            self._cmd_vel.publish(twist_from_command(command))

    def _on_scan(self, msg: LaserScan) -> None:
        stamp = _nanoseconds(msg.header.stamp)
        if self._last_scan_stamp is not None and stamp < self._last_scan_stamp:
            # Sim time went back: a new episode. Odometry newer than this scan, and a goal
            # that came before the previous episode's last scan, belong to the old episode.
            if self._odom_stamp is not None and self._odom_stamp > stamp:
                self._state, self._odom_stamp = None, None
            # Only odometry that came after the jump back belongs to the new episode.
            history = list(self._odom_history)
            newest_old = max((index for index, (odom_stamp, _) in enumerate(history)
                              if odom_stamp > stamp), default=-1)
            self._odom_history = deque(history[newest_old + 1:], maxlen=ODOM_HISTORY)
            if not self._goal_since_last_scan:
                self._goal = None
        self._last_scan_stamp = stamp
        self._goal_since_last_scan = False
        if self._timer_mode:
            self._latest_scan = msg
            return
        # A newer scan replaces one still waiting: answer only the latest tick.
        self._waiting_scan = (stamp, msg)
        self._answer_if_ready()

    def _answer_if_ready(self) -> None:
        """Answer the waiting scan once its tick's odometry and a goal are known.

        The executor may hand us a scan before the odom or the goal published just ahead of
        it; answering then, with a stale pose or no goal, would make the command (and so a
        lockstep episode) depend on callback order instead of on the robot's state.
        """
        if self._waiting_scan is None or self._goal is None or self._odom_stamp is None:
            return
        stamp, msg = self._waiting_scan
        if self._odom_stamp >= stamp:
            self._answer(msg)

    def _on_goal(self, msg: PoseStamped) -> None:
        goal = goal_from_pose(msg)
        if not (math.isfinite(goal.x) and math.isfinite(goal.y)):
            self.get_logger().warning(f'Ignoring a goal that is not finite: ({goal.x}, {goal.y})')
            return
        stamp = _nanoseconds(msg.header.stamp)
        if stamp and (goal, stamp) == (self._goal, self._goal_stamp):
            # The same stamped goal again: a simulator's resend for readers that joined late
            # (or a slow first answer), not a new goal. Resetting here would make the episode
            # depend on wall-clock timing (a planner's path and state dropped mid-run).
            return
        frame = msg.header.frame_id
        if frame not in ('', 'map', 'odom') and frame not in self._warned_frames:
            self._warned_frames.add(frame)
            self.get_logger().warning(
                f'Goal in frame {frame!r}: read as map coordinates (map = odom here)')
        self._goal, self._goal_stamp = goal, stamp
        self._goal_since_last_scan = True
        self._goal_reached = False
        self._controller.reset()
        self.get_logger().info(
            f'New goal ({goal.x:.2f}, {goal.y:.2f}) in frame {msg.header.frame_id!r}')
        if not self._timer_mode:
            self._answer_if_ready()

    def _answer(self, msg: LaserScan) -> None:
        self._waiting_scan = None
        command = self._command_for(msg)
        if self._stamped:
            frame = self._base_frame
            self._cmd_vel.publish(twist_stamped_from_command(command, msg.header.stamp, frame))
        else:
            self._cmd_vel.publish(twist_from_command(command))

    def _state_at(self, msg: LaserScan) -> RobotState | None:
        """The odometry of the scan's tick: the newest not newer than the scan (the latest
        state when all are newer)."""
        stamp = _nanoseconds(msg.header.stamp)
        for odom_stamp, state in reversed(self._odom_history):
            if odom_stamp <= stamp:
                return state
        return self._state

    def _command_for(self, msg: LaserScan, state: RobotState | None = None) -> VelocityCommand:
        """The command for scan ``msg`` seen from ``state`` (default: the latest odometry)."""
        state = state if state is not None else self._state
        if self._goal is None or self._goal_reached:
            return STOP
        if state is None:
            if not self._warned_no_odom:
                self.get_logger().warning('Scan received before any odometry: standing still')
                self._warned_no_odom = True
            return STOP
        if self._controller.goal_reached(state, self._goal):
            self._goal_reached = True
            self.get_logger().info(f'Goal reached at ({state.x:.2f}, {state.y:.2f})')
            return STOP
        command = self._controller.compute_command(scan_from_msg(msg), state, self._goal)
        if not command.is_finite():
            self.get_logger().error(
                f'Controller produced a non-finite command {command}; stopping')
            return STOP
        return command


def spin(node: Node) -> None:
    """Spin ``node`` until shutdown, with rclpy's events executor where it exists.

    In lockstep every tick costs the controller three callbacks (clock, odom, scan); the events
    executor dispatches them from a C++ queue at about half the CPU time of the default
    executor, which in a simulator's lockstep loop is a third of all the time per tick
    (tests/benchmarks/bench_simulator_node.py). Its ``spin()`` delivered no callbacks in
    rclpy 7.1.6 and kept signals from being handled, so it is driven by ``spin_once``.
    """
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # an rclpy without it
        rclpy.spin(node)
        return
    executor = EventsExecutor(context=node.context)
    executor.add_node(node)
    try:
        while rclpy.ok(context=node.context):
            executor.spin_once(timeout_sec=0.5)
    finally:
        executor.shutdown()


def run(controller_name: str, args: Sequence[str] | None = None) -> None:
    """Spin the node of controller ``controller_name`` until shutdown, with Jazzy's shutdown
    idiom.

    Unusable parameters end the process with a one-line error and exit status 1.
    """
    rclpy.init(args=args)
    node = None
    failure = ''
    try:
        node = ControllerNode(controller_name)
        spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ValueError, ParameterException) as err:
        failure = f'cannot start {controller_name}: {err}'
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if failure:
        rclpy.logging.get_logger(controller_name).fatal(failure)
        sys.exit(1)


def main(args: Sequence[str] | None = None) -> None:
    """Entry point of every built-in controller executable: the executable's name is the
    controller's registry name."""
    name = Path(sys.argv[0]).name
    try:
        spec = get_controller(name)
    except KeyError as err:
        print(f'{name}: {err}', file=sys.stderr)
        sys.exit(2)
    robots = (f'the robots {", ".join(spec.robots)} (its robot parameter)' if spec.robots
              else f'the {spec.robot} robot')
    exit_if_help(f'sessgan_controllers {name}', f'{spec.description} For {robots}.\n\n'
                 'Subscribes scan, odom and goal_pose (and map, if it plans on one); publishes '
                 'cmd_vel (Twist, or TwistStamped with use_stamped_cmd_vel): one per scan, or '
                 'with control_mode:=timer every 1 / control_rate_hz s of its clock. Run it '
                 'with use_sim_time:=true beside a simulator worker in the same namespace (in '
                 'timer mode also -r /clock:=clock).',
                 lambda: ControllerNode(name), args)
    run(name, args)


if __name__ == '__main__':
    main()
