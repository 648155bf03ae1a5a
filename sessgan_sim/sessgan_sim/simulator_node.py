"""sessgan_sim simulator node: a pybullet robot that looks like a real one to its controller.

Topics (relative, so ``-r __ns:=/w0`` namespaces a worker): publishes ``scan``, ``odom``, ``tf``,
``tf_static``, ``clock``, ``map`` and ``goal_pose``; subscribes ``cmd_vel`` (Twist, or
TwistStamped with ``use_stamped_cmd_vel``) and, in free mode, ``environment``
(nav_msgs/OccupancyGrid). Serves the ``evaluate`` action (sessgan_interfaces/EvaluateEnvironment).

Stepping modes: ``lockstep`` publishes a tick's data and waits for the controller's answer before
advancing; ``clocked`` advances ``/clock`` at ``real_time_factor`` and uses the latest command.
A controller silent for ``controller_timeout`` wall seconds ends the episode as
``controller_unresponsive``.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import rclpy
from geometry_msgs.msg import PoseStamped, Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan
from tf2_msgs.msg import TFMessage

from sessgan_gen.environment import Environment
from sessgan_gen.errors import SessganGenError
from sessgan_gen.navigation import make_environment
from sessgan_gen.ros_conversion import (
    environment_from_msg,
    occupancy_from_grid_msg,
    occupancy_grid_msg,
)
from sessgan_gen.scenarios import get_scenario
from sessgan_gen.token_map import occupancy_to_tokens
from sessgan_interfaces.action import EvaluateEnvironment
from sessgan_interfaces.msg import EpisodeMetrics as EpisodeMetricsMsg
from sessgan_sim import cdr
from sessgan_sim import ros_messages as rm
from sessgan_sim.bag_recording import BagRecord, BagWriteError, write_episode_bag
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.errors import SessganSimError
from sessgan_sim.metrics import Outcome, is_controller_failure
from sessgan_sim.sensors import LidarConfig

LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
SENSOR_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
"""cmd_vel: matches reliable and best-effort controllers; see CommandReceiver."""



class CommandReceiver:
    """Takes ``cmd_vel`` messages straight from a wait set, without an executor.

    Lockstep waits for one command per tick; an executor's Python overhead per wake-up costs
    more than the whole round trip, and the subscription's node is spun by nobody else. The
    reader is best effort: reliability's acknowledgements cost a fifth of a lockstep tick. An
    episode starts only once this reader has matched the controller's writer (a best-effort
    reader drops what comes before; wait_for_controller). A command lost on one host (none in
    bench_lockstep_under_load.py) would end the episode controller_unresponsive after the
    timeout, never hang it or shift later commands.
    """

    def __init__(self, node, msg_type, topic: str) -> None:
        self.subscription = node.create_subscription(msg_type, topic, lambda _: None,
                                                     COMMAND_QOS)
        self.context = node.context
        # A wait on a shut-down context never returns (seen with rclpy 7.1.6): shutdown (a
        # SIGTERM, say) wakes the waiting episode instead, as rclpy's executors wake theirs.
        self.shutdown = node.create_guard_condition(lambda: None)
        self.context.on_shutdown(self.shutdown.trigger)
        self.wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, 0, self.context.handle)

    def take(self):
        """The oldest received command, or None."""
        taken = self.subscription.handle.take_message(self.subscription.msg_type, False)
        return None if taken is None else taken[0]

    def take_all(self) -> list:
        commands = []
        while (command := self.take()) is not None:
            commands.append(command)
        return commands

    def wait(self, timeout: float) -> bool:
        """Block until a command is ready or ``timeout`` seconds pass; False once ROS is shut
        down (no command will come)."""
        if not self.context.ok():
            return False
        self.wait_set.clear_entities()
        self.wait_set.add_subscription(self.subscription.handle)
        self.wait_set.add_guard_condition(self.shutdown.handle)
        self.wait_set.wait(max(0, int(timeout * 1e9)))
        return self.context.ok()


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


class SimulatorNode(Node):

    def __init__(self) -> None:
        super().__init__('sessgan_sim')
        self.declare_parameter('mode', 'lockstep')            # lockstep | clocked
        self.declare_parameter('real_time_factor', 1.0)       # clocked mode: sim s per wall s
        self.declare_parameter('controller_timeout', 2.0)     # wall s without a command
        self.declare_parameter('controller_startup_timeout', 15.0)  # wall s for the first one
        self.declare_parameter('use_stamped_cmd_vel', False)
        self.declare_parameter('scenario', 'factory')         # free mode and defaults
        self.declare_parameter('robot', '')                   # empty: the scenario's robot
        self.declare_parameter('time_limit', 0.0)             # sim s; 0: the scenario's
        self.declare_parameter('control_rate', 20.0)          # Hz of scan/odom/commands
        self.declare_parameter('lidar_beams', 360)
        self.declare_parameter('lidar_fov_deg', 360.0)
        self.declare_parameter('lidar_range_max', 10.0)
        self.declare_parameter('lidar_noise_std', 0.01)       # m
        self.declare_parameter('dummy_agents', -1)            # -1: the scenario's
        self.declare_parameter('free_mode', False)            # run an episode per `environment`
        self.declare_parameter('seed', 0)                     # free mode episodes
        self.declare_parameter('record_directory', '')        # free mode failure bags
        self.declare_parameter('bag_storage', 'mcap')         # mcap | sqlite3

        self.busy = threading.Lock()
        self.episode = Episode().open()  # one pybullet world, rebuilt for every episode
        self.callback_group = ReentrantCallbackGroup()
        self.scan_publisher = self.create_publisher(LaserScan, 'scan', SENSOR_QOS)
        self.odom_publisher = self.create_publisher(Odometry, 'odom', SENSOR_QOS)
        self.tf_publisher = self.create_publisher(TFMessage, 'tf', SENSOR_QOS)
        self.tf_static_publisher = self.create_publisher(TFMessage, 'tf_static', LATCHED_QOS)
        self.clock_publisher = self.create_publisher(Clock, 'clock', SENSOR_QOS)
        self.map_publisher = self.create_publisher(OccupancyGrid, 'map', LATCHED_QOS)
        self.goal_publisher = self.create_publisher(PoseStamped, 'goal_pose', LATCHED_QOS)
        self.topics = {name: self.resolve_topic_name(name) for name in (
            'scan', 'odom', 'tf', 'tf_static', 'clock', 'map', 'goal_pose', 'cmd_vel')}

        stamped = bool(self.get_parameter('use_stamped_cmd_vel').value)
        self.command_type = TwistStamped if stamped else Twist
        self.command_node = rclpy.create_node(
            self.get_name() + '_cmd_vel', namespace=self.get_namespace(), context=self.context)
        self.commands = CommandReceiver(self.command_node, self.command_type, 'cmd_vel')

        self.action_server = ActionServer(
            self, EvaluateEnvironment, 'evaluate', execute_callback=self.execute,
            goal_callback=self.on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=self.callback_group)
        if self.get_parameter('free_mode').value:
            self.free_seed = int(self.get_parameter('seed').value)
            self.create_subscription(OccupancyGrid, 'environment', self.on_free_map, LATCHED_QOS,
                                     callback_group=self.callback_group)
        self.get_logger().info(
            f'simulator ready: {self.get_parameter("mode").value} mode, action '
            f'{self.resolve_topic_name("evaluate")}')

    # ---- entry points ----------------------------------------------------------------------

    def on_goal(self, goal_request) -> GoalResponse:
        if self.busy.locked():
            self.get_logger().warning('rejecting an evaluate goal: an episode is running')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def execute(self, goal_handle):
        request = goal_handle.request
        result = EvaluateEnvironment.Result()
        with self.busy:
            if not self.context.ok():  # shut down while waiting: the world is closed
                return result
            try:
                environment = environment_from_msg(request.environment)
            except (SessganGenError, SessganSimError, ValueError) as err:
                result.metrics = invalid_metrics(request.environment.id, str(err))
                self.get_logger().warning(f'invalid environment {request.environment.id!r}: {err}')
                goal_handle.succeed()
                return result
            result.metrics = self.run_episode(
                environment, robot=request.robot, time_limit=request.time_limit,
                seed=request.seed, record_directory=request.record_directory,
                controller=request.controller, goal_handle=goal_handle)
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        else:
            goal_handle.succeed()
        return result

    def on_free_map(self, grid: OccupancyGrid) -> None:
        scenario = self.get_parameter('scenario').value
        try:
            occupancy, _, _ = occupancy_from_grid_msg(grid)
            cells = occupancy_to_tokens(occupancy, get_scenario(scenario))
            environment = make_environment(cells, scenario, f'free-{self.free_seed}',
                                           seed=self.free_seed)
        except (SessganGenError, ValueError) as err:
            self.get_logger().error(f'ignoring the map on environment: {err}')
            return
        if not self.busy.acquire(blocking=False):
            self.get_logger().warning('ignoring a map on environment: an episode is running')
            return
        try:
            if not self.context.ok():  # shutting down: the world is closed
                return
            self.free_seed += 1
            metrics = self.run_episode(
                environment, robot='', time_limit=0.0, seed=environment.seed,
                record_directory=self.get_parameter('record_directory').value,
                controller='external', goal_handle=None)
            self.get_logger().info(
                f'free-mode episode {environment.id}: {metrics.outcome}, '
                f'collisions {metrics.collisions}, risk {metrics.risk_score:.3f}')
        finally:
            self.busy.release()

    # ---- the episode loop ------------------------------------------------------------------

    def episode_config(self, robot: str, time_limit: float, seed: int) -> EpisodeConfig:
        """Parameters and goal fields as a core config; None fields take scenario defaults."""
        param = self.get_parameter
        rate = float(param('control_rate').value)
        agents = int(param('dummy_agents').value)
        config = EpisodeConfig(
            robot=robot or param('robot').value or None,
            control_rate_hz=rate,
            time_limit=time_limit or float(param('time_limit').value) or None,
            lidar=LidarConfig(
                beams=int(param('lidar_beams').value),
                field_of_view=math.radians(float(param('lidar_fov_deg').value)),
                range_max=float(param('lidar_range_max').value),
                noise_std=float(param('lidar_noise_std').value), rate_hz=rate),
            dummy_agents=None if agents < 0 else agents,
            seed=int(seed),
        )
        config.validate()
        return config

    def run_episode(self, environment: Environment, robot: str, time_limit: float, seed: int,
                    record_directory: str, controller: str, goal_handle) -> EpisodeMetricsMsg:
        wall_start = time.monotonic()
        recording = Recording() if record_directory else None
        try:
            config = self.episode_config(robot, time_limit, seed)
        except (SessganSimError, ValueError) as err:
            return invalid_metrics(environment.id, str(err))
        episode = self.episode
        observation = episode.reset(environment, config)
        config = episode.config  # resolved: scenario defaults filled in
        startup_timeout = float(self.get_parameter('controller_startup_timeout').value)
        if episode.done:
            metrics = episode.metrics()
        elif not self.wait_for_controller(startup_timeout):
            episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                          f'no controller subscribed to scan and published cmd_vel within '
                          f'{startup_timeout:.1f} s wall time')
            metrics = episode.metrics()
        else:
            self.publish_episode_start(environment, episode, observation, recording)
            loop_start = time.monotonic()
            metrics = self.step_loop(episode, observation, recording, goal_handle)
            self.log_timing(environment.id, metrics, episode.profile,
                            time.monotonic() - loop_start)
        message = metrics_msg(environment.id, metrics, time.monotonic() - wall_start)
        if recording is not None and is_controller_failure(metrics):
            message.bag_path = self.write_bag(
                record_directory, environment, config, metrics, recording, seed, controller)
        return message

    def log_timing(self, environment_id: str, metrics, profile, loop_seconds: float) -> None:
        """One line per episode: where the wall time of a tick goes (benchmarks parse it)."""
        ticks = max(1, profile.ticks)
        per_tick = {'physics': profile.physics / ticks, 'sensors': profile.sensors / ticks,
                    'metrics': profile.metrics / ticks}
        per_tick['messaging'] = max(0.0, loop_seconds / ticks - sum(per_tick.values()))
        factor = metrics.simulation_time / loop_seconds if loop_seconds > 0 else 0.0
        self.get_logger().info(
            f'episode {environment_id}: {metrics.outcome.value} after '
            f'{metrics.simulation_time:.2f} sim s in {loop_seconds:.2f} wall s '
            f'(x{factor:.1f} real time); per tick ms: ' +
            ' '.join(f'{name}={value * 1e3:.3f}' for name, value in per_tick.items()))

    def publish_episode_start(self, environment, episode, observation, recording) -> None:
        stamp = rm.time_msg(observation.time)
        self.publish(self.map_publisher, 'map', 'nav_msgs/msg/OccupancyGrid',
                     occupancy_grid_msg(environment, stamp=stamp), observation.time, recording)
        self.publish(self.tf_static_publisher, 'tf_static', 'tf2_msgs/msg/TFMessage',
                     rm.static_tf_msg(stamp, episode.robot.ride_height,
                                      episode.robot.sensor_height),
                     observation.time, recording)
        goal = environment.goal
        self.publish(self.goal_publisher, 'goal_pose', 'geometry_msgs/msg/PoseStamped',
                     rm.goal_msg(stamp, goal.x, goal.y, goal.yaw), observation.time, recording)

    def wait_for_controller(self, timeout: float) -> bool:
        """Wait until a controller reads our scan and publishes cmd_vel, with every endpoint of
        the tick's topics that discovery shows matched to ours.

        Only matched endpoints exchange messages: a tick published before the controller's odom
        reader matched our writer, or an answer sent before our best-effort cmd_vel reader
        matched its writer, would be lost and stall the episode until the startup timeout. A
        tick is never published twice (a repeated one would earn a second answer and shift
        every later command by a tick). An endpoint that never matches (incompatible QoS) holds
        the start up for at most a second.
        """
        deadline = time.monotonic() + timeout
        settle_deadline = None
        waited = False
        while True:
            commands = self.commands.subscription.get_publisher_count()
            if self.scan_publisher.get_subscription_count() > 0 and commands > 0:
                complete = commands >= self.command_node.count_publishers(
                    self.topics['cmd_vel']) and all(
                    publisher.get_subscription_count() >= self.count_subscribers(
                        self.topics[name]) for name, publisher in (
                        ('clock', self.clock_publisher), ('odom', self.odom_publisher),
                        ('scan', self.scan_publisher)))
                now = time.monotonic()
                settle_deadline = settle_deadline or now + 1.0
                if complete or now >= settle_deadline:
                    if waited:  # just matched: let the controller's side catch up too
                        time.sleep(0.1)
                    return True
            if time.monotonic() > deadline:
                return False
            waited = True
            time.sleep(0.01)

    def republish_goal(self, episode, observation) -> None:
        """Resend the goal to a controller whose volatile goal_pose reader (Nav2's is) joined
        after the first one; not recorded twice."""
        goal = episode.environment.goal
        self.goal_publisher.publish(
            rm.goal_msg(rm.time_msg(observation.time), goal.x, goal.y, goal.yaw))

    def publish(self, publisher, topic: str, msgtype: str, message, sim_time: float,
                recording: Recording | None) -> None:
        publisher.publish(message)
        if recording is not None:
            recording.add(self.topics[topic], msgtype, int(round(sim_time * 1e9)), message)

    def publish_tick(self, episode, observation, recording) -> None:
        """clock, odom, tf (when anyone listens or records) and scan of one tick; the
        messages of every tick are published serialized (sessgan_sim.cdr)."""
        t = observation.time
        stamp = cdr.stamp(t)
        self.publish(self.clock_publisher, 'clock', 'rosgraph_msgs/msg/Clock', cdr.clock(stamp),
                     t, recording)
        pose = observation.pose
        odom = cdr.odometry(stamp, rm.ODOM_FRAME, rm.BASE_FOOTPRINT, pose.x, pose.y, pose.yaw,
                            *observation.twist)
        self.publish(self.odom_publisher, 'odom', 'nav_msgs/msg/Odometry', odom, t, recording)
        if recording is not None or self.tf_publisher.get_subscription_count() > 0:
            # Building tf costs more than the check; most controllers under test use odom.
            self.publish(self.tf_publisher, 'tf', 'tf2_msgs/msg/TFMessage', rm.dynamic_tf_msg(
                rm.time_msg(t), pose.x, pose.y, pose.yaw), t, recording)
        lidar = observation.lidar
        self.publish(self.scan_publisher, 'scan', 'sensor_msgs/msg/LaserScan', cdr.laser_scan(
            stamp, rm.SCAN_FRAME, observation.scan, lidar.angle_min, lidar.angle_increment,
            lidar.range_min, lidar.range_max, lidar.scan_time), t, recording)

    def wait_for_command(self, deadline: float, republish) -> object | None:
        """The next command received before the wall-clock ``deadline``, else None."""
        next_republish = time.monotonic() + 1.0
        while True:
            command = self.commands.take()
            if command is not None:
                return command
            now = time.monotonic()
            if now >= deadline:
                return None
            if republish is not None and now >= next_republish:
                republish()  # covers a controller that matched our publishers only now
                next_republish = now + 1.0
            if not self.commands.wait(min(deadline, next_republish) - now):
                return None

    def step_loop(self, episode, observation, recording, goal_handle):
        lockstep = self.get_parameter('mode').value != 'clocked'
        rtf = max(1e-3, float(self.get_parameter('real_time_factor').value))
        timeout = float(self.get_parameter('controller_timeout').value)
        startup_timeout = float(self.get_parameter('controller_startup_timeout').value)
        dt = 1.0 / episode.config.control_rate_hz
        feedback_every = max(1, int(round(0.25 / dt)))
        command = None
        last_command_wall = time.monotonic()
        wall_origin = time.monotonic()
        first = True
        ticks = 0
        self.commands.take_all()  # stale answers of an earlier episode
        while not episode.done:
            if goal_handle is not None and goal_handle.is_cancel_requested:
                episode.abort(Outcome.TIMEOUT, 'cancelled by the evaluate client')
                break
            if not self.context.ok():  # shutting down (SIGTERM): end at once, no more ticks
                episode.abort(Outcome.CONTROLLER_UNRESPONSIVE, 'the simulator was shut down')
                break
            self.publish_tick(episode, observation, recording)
            if lockstep:
                limit = startup_timeout if first else timeout
                received = self.wait_for_command(
                    time.monotonic() + limit,
                    (lambda: self.republish_goal(episode, observation)) if first else None)
                if received is None:
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                                  f'no cmd_vel within {limit:.1f} s wall time')
                    break
                command = received
            else:
                tick_deadline = wall_origin + (observation.time + dt) / rtf
                while (remaining := tick_deadline - time.monotonic()) > 0:
                    if not self.commands.wait(remaining):
                        break
                    received = self.commands.take_all()
                    if received:
                        command = received[-1]
                        last_command_wall = time.monotonic()
                limit = startup_timeout if command is None else timeout
                if time.monotonic() - last_command_wall > limit:
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                                  f'no cmd_vel within {limit:.1f} s wall time')
                    break
            first = False
            values = rm.twist_values(command) if command is not None else (0.0, 0.0, 0.0)
            if recording is not None and command is not None:
                recording.add(self.topics['cmd_vel'], 'geometry_msgs/msg/' +
                              self.command_type.__name__, int(round(observation.time * 1e9)),
                              command)
            observation = episode.step(values).observation
            ticks += 1
            if goal_handle is not None and ticks % feedback_every == 0:
                so_far = episode.metrics()
                feedback = EvaluateEnvironment.Feedback()
                feedback.sim_time = observation.time
                feedback.collisions = so_far.collisions
                feedback.distance_to_goal = so_far.final_distance_to_goal
                goal_handle.publish_feedback(feedback)
        if not lockstep:
            # The final state, so subscribers and bags see where the robot ended. Not in
            # lockstep: its answer could arrive during the next episode.
            self.publish_tick(episode, observation, recording)
        return episode.metrics()

    def write_bag(self, record_directory, environment, config, metrics, recording, seed,
                  controller) -> str:
        directory = Path(record_directory) / environment.id
        metadata = {
            'environment_id': environment.id, 'scenario': environment.scenario,
            'seed': environment.seed, 'episode_seed': int(seed),
            'generation': environment.generation, 'member': environment.member,
            'controller': controller, 'metrics': metrics.to_dict(),
            'robot': config.robot, 'time_limit': config.time_limit,
            'start': [environment.start.x, environment.start.y, environment.start.yaw],
            'goal': [environment.goal.x, environment.goal.y, environment.goal.yaw],
            'feasible': environment.feasible, 'route_length': environment.route_length,
            'route_min_clearance': environment.route_min_clearance,
            'namespace': self.get_namespace(),
        }
        try:
            path = write_episode_bag(
                directory, recording.records(), metadata, environment.occupancy,
                environment.resolution, environment.origin,
                storage=self.get_parameter('bag_storage').value, overwrite=True)
        except (BagWriteError, OSError, ValueError) as err:
            self.get_logger().error(f'cannot write the failure bag {directory}: {err}')
            return ''
        self.get_logger().info(f'failure bag written: {path}')
        return str(path)


def metrics_msg(environment_id: str, metrics, wall_time: float) -> EpisodeMetricsMsg:
    msg = EpisodeMetricsMsg()
    msg.environment_id = environment_id
    msg.outcome = metrics.outcome.value if metrics.outcome else ''
    msg.detail = metrics.detail
    msg.collisions = int(metrics.collisions)
    msg.proximity_time = float(metrics.proximity_time)
    msg.simulation_time = float(metrics.simulation_time)
    msg.risk_score = float(metrics.risk_score)
    msg.feasible = bool(metrics.feasible)
    msg.min_clearance = float(metrics.min_clearance)
    msg.distance_travelled = float(metrics.distance_travelled)
    msg.final_distance_to_goal = float(metrics.final_distance_to_goal)
    msg.ticks = int(metrics.ticks)
    msg.wall_time = float(wall_time)
    msg.fault_collisions = int(metrics.fault_collisions)
    msg.static_collisions = int(metrics.static_collisions)
    msg.robot_into_agent_collisions = int(metrics.robot_into_agent_collisions)
    msg.agent_into_robot_collisions = int(metrics.agent_into_robot_collisions)
    msg.fault_risk_score = float(metrics.fault_risk_score)
    msg.invalid_commands = int(metrics.invalid_commands)
    return msg


def invalid_metrics(environment_id: str, detail: str) -> EpisodeMetricsMsg:
    msg = EpisodeMetricsMsg()
    msg.environment_id = environment_id
    msg.outcome = EpisodeMetricsMsg.OUTCOME_INVALID_ENVIRONMENT
    msg.detail = detail
    return msg


def main(args=None) -> None:
    rclpy.init(args=args)
    node = None
    executor = MultiThreadedExecutor(num_threads=2)
    try:
        node = SimulatorNode()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            # A running episode ends at its next tick once ROS is shut down; closing its world
            # and nodes under it would crash the process instead of letting it exit. A goal
            # still waiting for the lock finds ROS shut down and returns at once.
            idle = node.busy.acquire(timeout=5.0)
            node.episode.close()
            node.command_node.destroy_node()
            node.destroy_node()
            if idle:
                node.busy.release()
        rclpy.try_shutdown()
