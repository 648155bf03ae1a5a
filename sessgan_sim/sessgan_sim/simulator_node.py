"""sessgan_sim simulator node: a pybullet robot that looks like a real one to its controller.

Topics (relative, so ``-r __ns:=/w0`` namespaces a worker): publishes ``scan``, ``odom``, ``tf``,
``tf_static``, ``clock``, ``map``, ``goal_pose`` and ``waypoints`` (a mission's waypoints at
once; ``goal_pose`` carries the one in force, the next once the robot dwelt at a station);
subscribes ``cmd_vel`` (Twist, or
TwistStamped with ``use_stamped_cmd_vel``) and, in free mode, ``environment``
(nav_msgs/OccupancyGrid). Serves the ``evaluate`` action (sessgan_interfaces/EvaluateEnvironment)
and the ``bags`` service (sessgan_interfaces/WorkerBags: its failure bags, for a campaign on
another host to collect, and what the worker is: sessgan_sim.bag_serving).

Stepping modes: ``lockstep`` publishes a tick's data and waits for the controller's answer before
advancing; ``clocked`` advances ``/clock`` at ``real_time_factor`` and uses the latest command.
A controller silent for ``controller_timeout`` wall seconds ends the episode as
``controller_unresponsive``. Sim time only moves forward: the first episode starts at
``sim_time_origin``, every later one a control period after the previous one ended (failure
bags record each episode's origin), so a long-running stack can live through any number of
episodes. Every parameter is a field of
:class:`sessgan_sim.simulator_settings.SimulatorSettings`, validated there as a whole.

The node composes the parts in ``sessgan_sim.worker``: it receives work (evaluate goals, free
mode maps), runs one episode at a time and answers with its metrics.

Failure bags go only under ``bags_root`` (fixed at start-up): a goal's ``record_directory``
must be a relative subdirectory of it (sessgan_sim.bag_recording.record_directory_under); a
goal naming anything else (an absolute path, '..') is answered ``harness_error`` with the
reason (the client's fault, never a test result), and no episode runs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import threading
import time
from pathlib import Path

import rclpy
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node

from sessgan_core.config_cli import field_docs
from sessgan_core.environment import Environment
from sessgan_core.errors import SessganCoreError
from sessgan_core.node_help import exit_if_help
from sessgan_core.ros_conversion import environment_from_msg, occupancy_from_grid_msg
from sessgan_core.ros_spin import exit_process, run_node
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import occupancy_to_tokens
from sessgan_core.valid_tests import make_environment
from sessgan_interfaces.action import EvaluateEnvironment
from sessgan_interfaces.msg import EpisodeMetrics as EpisodeMetricsMsg
from sessgan_interfaces.srv import WorkerBags
from sessgan_sim import __version__
from sessgan_sim.bag_recording import record_directory_under
from sessgan_sim.bag_serving import BagServer
from sessgan_sim.command_pace import PaceFigures, check_real_time_factor_scale
from sessgan_sim.episode import Episode, check_time_limit
from sessgan_sim.errors import (
    BagServeError,
    BagWriteError,
    InvalidConfigError,
    SessganSimError,
)
from sessgan_sim.metrics import Outcome, is_controller_failure
from sessgan_sim.simulator_settings import STRUCTURAL_SETTINGS, SimulatorSettings
from sessgan_sim.worker.commands import CommandReceiver
from sessgan_sim.worker.failure_bags import EpisodeFacts, remove_partial_bags, write_failure_bag
from sessgan_sim.worker.nav2_stack import Nav2Stack
from sessgan_sim.worker.stepping import EpisodeClock, EpisodeStepper, RobotChannel
from sessgan_sim.worker.topics import LATCHED_QOS, Recording, RobotTopics


class SimulatorNode(Node):
    """Parameters, the evaluate action and free mode around one Episode at a time."""

    def __init__(self) -> None:
        super().__init__('sessgan_sim')
        self.settings = self.declare_settings()
        self.add_on_set_parameters_callback(self.check_parameters)
        self.add_post_set_parameters_callback(self.apply_parameters)

        self.busy = threading.Lock()
        self.episode = Episode().open()  # one pybullet world, rebuilt for every episode
        self.callback_group = ReentrantCallbackGroup()
        self.topics = RobotTopics(self)
        command_type = TwistStamped if self.settings.use_stamped_cmd_vel else Twist
        self.commands = CommandReceiver(self, command_type)
        self.channel = RobotChannel(self.topics, self.commands, command_type.__name__)
        """A single robot's topics and command reader, in our namespace."""
        self.fleet_channels: list[RobotChannel] = []
        """Fleet robots' topics and command readers, in namespaces r0, r1, ... (made when
        a fleet episode first needs them)."""
        self.stack = Nav2Stack(self, self.callback_group, lambda: self.commands.running)
        self.clock_origin_ns = int(round(self.settings.sim_time_origin * 1e9))
        self.bags_root = Path(self.settings.bags_root).resolve()
        self.cleaned_directories: set[Path] = set()
        self.free_record_directory()  # removes partial bags a killed worker left there

        self.action_server = ActionServer(
            self, EvaluateEnvironment, 'evaluate', execute_callback=self.execute,
            goal_callback=self.on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=self.callback_group)
        self.bag_server = BagServer(self.bags_root)
        self.create_service(WorkerBags, 'bags', self.on_bags_request,
                            callback_group=self.callback_group)
        if self.settings.free_mode:
            self.free_seed = self.settings.seed
            self.create_subscription(OccupancyGrid, 'environment', self.on_free_map, LATCHED_QOS,
                                     callback_group=self.callback_group)
        self.get_logger().info(
            f'simulator ready: {self.settings.mode} mode, action '
            f'{self.resolve_topic_name("evaluate")}, failure bags under {self.bags_root}')

    # ---- parameters ------------------------------------------------------------------------

    def declare_settings(self) -> SimulatorSettings:
        """Declare one parameter per setting and validate them together; InvalidConfigError
        names the parameter at fault (also a misspelt one given on the command line)."""
        docs = field_docs(SimulatorSettings)
        defaults = SimulatorSettings().to_dict()
        values = {}
        for name, default in defaults.items():
            descriptor = ParameterDescriptor(
                description=docs.get(name, ''), dynamic_typing=True,
                read_only=name in STRUCTURAL_SETTINGS)
            values[name] = self.declare_parameter(name, default, descriptor).value
        unknown = sorted(set(self._parameter_overrides) - set(defaults) - {'use_sim_time'})
        if unknown:
            raise InvalidConfigError(f'unknown parameter(s) {unknown}; the simulator has '
                                     f'{sorted(defaults)}')
        return SimulatorSettings.from_values(values)

    def check_parameters(self, parameters) -> SetParametersResult:
        try:
            self.settings_with(parameters)
        except InvalidConfigError as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def apply_parameters(self, parameters) -> None:
        self.settings = self.settings_with(parameters)  # the next episode uses them

    def settings_with(self, parameters) -> SimulatorSettings:
        values = self.settings.to_dict()
        values.update({p.name: p.value for p in parameters if p.name in values})
        return SimulatorSettings.from_values(values)

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
            if not self.commands.running:  # stopping: the world is (about to be) closed
                goal_handle.abort()
                return result
            record_directory = None
            try:
                if request.record_directory:
                    record_directory = record_directory_under(self.bags_root,
                                                              request.record_directory)
            except BagWriteError as err:
                # Refused (no episode runs): the goal's fault, a harness error, never a result.
                result.metrics = invalid_metrics(request.environment.id,
                                                 f'refusing the goal: {err}',
                                                 Outcome.HARNESS_ERROR)
                self.get_logger().warning(f'refusing an evaluate goal: {err}')
                goal_handle.succeed()
                return result
            try:
                environment = environment_from_msg(request.environment)
            except (SessganCoreError, SessganSimError, ValueError) as err:
                result.metrics = invalid_metrics(request.environment.id, str(err))
                self.get_logger().warning(f'invalid environment {request.environment.id!r}: {err}')
                goal_handle.succeed()
                return result
            result.metrics = self.run_episode(
                environment, robot=request.robot, time_limit=request.time_limit,
                seed=request.seed, record_directory=record_directory,
                controller=request.controller, goal_handle=goal_handle,
                real_time_factor_scale=request.real_time_factor_scale)
        if not self.context.ok():
            return result  # shut down: the goal handle belongs to a closed context
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif result.metrics.outcome == EpisodeMetricsMsg.OUTCOME_CANCELLED:
            goal_handle.abort()
        else:
            goal_handle.succeed()
        return result

    def on_bags_request(self, request, response):
        """Describe the worker; list, read or remove one of its failure bags."""
        response.software_version = __version__
        response.settings = json.dumps(self.settings.to_dict(), sort_keys=True)
        try:
            if request.bag and request.remove:
                if request.file:
                    raise BagServeError('a remove request names no file')
                self.bag_server.remove(request.bag)
            elif request.bag and request.file:
                response.data = self.bag_server.read(request.bag, request.file,
                                                     int(request.offset), int(request.length))
            elif request.bag:
                listing = self.bag_server.list_files(request.bag)
                response.files = list(listing)
                response.sizes = list(listing.values())
        except (BagServeError, OSError) as err:
            response.message = str(err)
            return response
        response.success = True
        return response

    def on_free_map(self, grid: OccupancyGrid) -> None:
        scenario = self.settings.scenario
        try:
            occupancy, _, _ = occupancy_from_grid_msg(grid)
            cells = occupancy_to_tokens(occupancy, get_scenario(scenario))
            environment = make_environment(cells, scenario, f'free-{self.free_seed}',
                                           seed=self.free_seed,
                                           mission=self.settings.mission(),
                                           fleet=self.settings.fleet())
        except (SessganCoreError, ValueError) as err:
            self.get_logger().error(f'ignoring the map on environment: {err}')
            return
        if not self.busy.acquire(blocking=False):
            self.get_logger().warning('ignoring a map on environment: an episode is running')
            return
        try:
            if not self.commands.running:  # stopping: the world is (about to be) closed
                return
            self.free_seed += 1
            metrics = self.run_episode(
                environment, robot='', time_limit=0.0, seed=environment.seed,
                record_directory=self.free_record_directory(),
                controller='external', goal_handle=None)
            self.get_logger().info(
                f'free-mode episode {environment.id}: {metrics.outcome}, '
                f'collisions {metrics.collisions}, risk {metrics.risk_score:.3f}')
        finally:
            self.busy.release()

    # ---- one episode -----------------------------------------------------------------------

    def run_episode(self, environment: Environment, robot: str, time_limit: float, seed: int,
                    record_directory: Path | None, controller: str,
                    goal_handle, real_time_factor_scale: float = 0.0) -> EpisodeMetricsMsg:
        wall_start = time.monotonic()
        settings = self.settings  # one snapshot for the whole episode
        recording = Recording() if record_directory is not None else None
        # The goal's options or this simulator's parameters, not the map, are at fault here:
        # a harness error the client runs again (sessgan_sim.metrics.HARNESS_OUTCOMES).
        try:
            scale = check_real_time_factor_scale(real_time_factor_scale)
            if scale != 1.0:  # a slower re-run of an overloaded episode (clocked mode)
                settings = dataclasses.replace(
                    settings, real_time_factor=settings.real_time_factor * scale)
            check_time_limit(time_limit, "the goal's time_limit")
            config = settings.episode_config(robot, time_limit, seed)
            config.validate()
        except (SessganSimError, ValueError) as err:
            return invalid_metrics(environment.id, str(err), Outcome.HARNESS_ERROR)
        if environment.fleet and (settings.goal_via.uses_action or settings.reset_costmaps):
            return invalid_metrics(environment.id, (
                "a fleet episode sends each robot's goal on its goal_pose: goal_interface "
                f'{settings.goal_interface!r} and reset_costmaps serve one robot'),
                Outcome.HARNESS_ERROR)
        episode = self.episode
        episode.reset(environment, config)
        config = episode.config  # resolved: scenario defaults filled in
        clock = EpisodeClock(self.clock_origin_ns)
        if episode.done:
            metrics = episode.metrics()
        else:
            metrics = self.run_ticks(episode, environment, clock, settings, recording,
                                     goal_handle)
        message = metrics_msg(environment.id, metrics, time.monotonic() - wall_start)
        if (recording is not None and record_directory is not None
                and metrics.outcome is not Outcome.CANCELLED and is_controller_failure(metrics)):
            self.clean_record_directory(record_directory)
            facts = EpisodeFacts(seed=seed, controller=controller,
                                 namespace=self.get_namespace(),
                                 sim_time_origin_ns=clock.origin_ns, settings=settings)
            message.bag_path, message.bag_error = write_failure_bag(
                record_directory, environment, config, metrics, recording, facts,
                self.get_logger())
        return message

    @staticmethod
    def why_unheard(commands) -> str:
        """Why a stack that publishes cmd_vel may not be heard: nothing publishes ours but
        another namespace's has a writer, or the writer's type is the other one."""
        elsewhere = commands.writers_elsewhere()
        if elsewhere and not commands.writers_in_graph():
            return (f'; nothing publishes {commands.topic}, but {", ".join(elsewhere)} '
                    f'{"has" if len(elsewhere) == 1 else "have"} a writer: is the controller '
                    "under another namespace? Start it in the worker's (-r __ns:=...)")
        others = commands.mistyped_writers()
        if not others:
            return ''
        stamped = commands.msg_type.__name__ == 'TwistStamped'
        return (f'; {commands.topic} is published as {", ".join(others)}, and this worker '
                f'reads geometry_msgs/msg/{commands.msg_type.__name__}: start the worker with '
                f'-p use_stamped_cmd_vel:={str(not stamped).lower()}, or publish '
                f'{"Twist" if stamped else "TwistStamped"} (Nav2: enable_stamped_cmd_vel: '
                f'{str(not stamped).lower()})')

    def run_ticks(self, episode: Episode, environment: Environment, clock: EpisodeClock,
                  settings: SimulatorSettings, recording: Recording | None, goal_handle):
        """The ticks of an episode that started: a single robot's topics in our namespace, a
        fleet's each in its own (r0, r1, ..., frames prefixed 'r0/', ...)."""
        fleet = bool(environment.fleet)
        stepper = EpisodeStepper(self.fleet_channels_for(episode.robot_count) if fleet
                                 else [self.channel])
        startup_timeout = settings.controller_startup_timeout
        missing = stepper.wait_for_controllers(startup_timeout)
        if missing is not None:
            if all(channel.commands.running for channel in stepper.channels):
                scan = stepper.channels[missing].topics.names['scan'] if fleet else 'scan'
                episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                              f'{stepper.who(missing)}no controller subscribed to {scan} and '
                              f'published cmd_vel within {startup_timeout:.1f} s wall time'
                              + self.why_unheard(stepper.channels[missing].commands))
            else:
                episode.abort(Outcome.CANCELLED, 'the simulator was shut down')
            return episode.metrics()
        mixed = self.warn_of_extra_controllers(stepper, set())
        start_ns = clock.stamp_ns(0.0)
        for channel, robot in zip(stepper.channels, episode.robots, strict=True):
            channel.topics.publish_world(environment, robot.ride_height, robot.sensor_height,
                                         start_ns, recording, range_down=robot.flies)
        observations = episode.observations()

        def prepare_stack() -> str | None:
            """Costmap resets, then the goals: before time advances."""
            if settings.reset_costmaps:
                failure = self.stack.reset_costmaps(settings.stack_timeout)
                if failure:
                    return failure
            for index, observation in enumerate(observations):
                failure = send_goal(index, observation.goal, start_ns, first=True)
                if failure:
                    return failure
            return None

        def send_goal(index: int, goal, stamp_ns: int, first: bool = False) -> str | None:
            """Robot ``index``'s waypoint in force on its goal_pose and/or as a NavigateToPose
            goal (as Nav2's waypoint follower sends each waypoint; a single robot's, refused
            for fleets above); the first with the robot's waypoints (r1, r2, ...: its goal)."""
            topics = stepper.channels[index].topics
            if settings.goal_via.uses_topic:
                if first:
                    topics.publish_waypoints(environment.waypoints if index == 0 else [goal],
                                             stamp_ns, recording)
                if not fleet:  # the navigate_to_pose server serves a single robot
                    self.stack.watch_goal()  # before the goal goes out: its answer may be quick
                topics.publish_goal(goal, stamp_ns, recording)
            if settings.goal_via.uses_action:
                if not first:
                    self.stack.finish(settings.stack_timeout)
                return self.stack.send_goal(goal, stamp_ns, settings.stack_timeout)
            return None

        def stop_after_navigation() -> tuple[float, float, float] | None:
            """A stack that ended its goal (its NavigateToPose goal, or the one bt_navigator
            made of goal_pose) no longer drives: stand still (as a base with a command
            timeout does) instead of waiting for cmd_vel."""
            return (0.0, 0.0, 0.0) if self.stack.navigation_ended else None

        loop_start = time.monotonic()
        metrics = stepper.run(episode, clock, settings, recording, goal_handle,
                              before_first_step=prepare_stack,
                              # the NavigateToPose stack serves a single robot
                              command_override=None if fleet else stop_after_navigation,
                              new_goal=send_goal)
        # Discovery may show a second stack only once the episode ran (on a busy host).
        self.warn_of_extra_controllers(stepper, mixed)
        note = self.stack.finish(settings.stack_timeout)
        if note:
            metrics = dataclasses.replace(
                metrics, detail=f'{metrics.detail}; {note}' if metrics.detail else note)
        self.log_timing(environment.id, metrics, episode.profile,
                        time.monotonic() - loop_start,
                        stepper.paces[0] if len(stepper.paces) == 1 else None)
        # The next episode's clock starts one control period after this one's end: a
        # long-running stack never sees sim time go back (its tf buffer stays valid).
        self.clock_origin_ns = clock.stamp_ns(episode.time + episode.config.control_period)
        return metrics

    def warn_of_extra_controllers(self, stepper: EpisodeStepper, warned: set[int]) -> set[int]:
        """Warn of each robot whose cmd_vel more than one node publishes (a stack left
        running beside the one under test, say), unless its index is in ``warned``; returns
        the indices warned of so far."""
        for index, channel in enumerate(stepper.channels):
            writers = channel.commands.writers_in_graph()
            if writers > 1 and index not in warned:
                warned.add(index)
                self.get_logger().warning(
                    f'{stepper.who(index)}{writers} nodes publish on '
                    f'{channel.commands.topic}: more than one controller drives the robot, '
                    'and this episode mixes their commands')
        return warned

    def fleet_channels_for(self, robots: int) -> list[RobotChannel]:
        """The topics and command readers of ``robots`` fleet robots, each on a node of its
        own in namespace r<i> under ours (made once, kept for later episodes)."""
        command_type = self.commands.msg_type
        while len(self.fleet_channels) < robots:
            index = len(self.fleet_channels)
            namespace = f'{self.get_namespace().rstrip("/")}/r{index}'
            # Not the process's remappings: its __ns would move the node back to ours.
            node = rclpy.create_node(f'{self.get_name()}_r{index}', namespace=namespace,
                                     context=self.context, use_global_arguments=False)
            self.fleet_channels.append(RobotChannel(
                RobotTopics(node, frame_prefix=f'r{index}/'),
                CommandReceiver(node, command_type, use_global_arguments=False),
                command_type.__name__))
        return self.fleet_channels[:robots]

    def clean_record_directory(self, record_directory: Path) -> None:
        """Remove partial bags a killed worker left, once per directory and process."""
        if record_directory not in self.cleaned_directories:
            self.cleaned_directories.add(record_directory)
            remove_partial_bags(record_directory, self.get_logger())

    def free_record_directory(self) -> Path | None:
        """Where free-mode failure bags go (``record_directory`` under ``bags_root``, cleaned
        of partial bags); None when none are recorded or it leads out of the root."""
        if not self.settings.record_directory:
            return None
        try:
            directory = record_directory_under(self.bags_root, self.settings.record_directory)
        except BagWriteError as err:
            self.get_logger().error(f'recording no failure bags: {err}')
            return None
        self.clean_record_directory(directory)
        return directory

    def log_timing(self, environment_id: str, metrics, profile, loop_seconds: float,
                   pace: PaceFigures | None = None) -> None:
        """One line per episode: where the wall time of a tick goes (benchmarks parse it) and,
        in clocked mode, how late the commands came in sim time."""
        ticks = max(1, profile.ticks)
        per_tick = {'physics': profile.physics / ticks, 'sensors': profile.sensors / ticks,
                    'metrics': profile.metrics / ticks}
        per_tick['messaging'] = max(0.0, loop_seconds / ticks - sum(per_tick.values()))
        factor = metrics.simulation_time / loop_seconds if loop_seconds > 0 else 0.0
        self.get_logger().info(
            f'episode {environment_id}: {metrics.outcome.value} after '
            f'{metrics.simulation_time:.2f} sim s in {loop_seconds:.2f} wall s '
            f'(x{factor:.1f} real time); per tick ms: ' +
            ' '.join(f'{name}={value * 1e3:.3f}' for name, value in per_tick.items())
            + ('' if pace is None else f'; commands: {pace.summary()}'))

    def stop(self, grace: float) -> None:
        """Cut a running episode off (outcome cancelled, its goal aborted) and wait up to
        ``grace`` seconds for it to end; no new episode starts (at exit, ROS still up)."""
        self.commands.stop()
        for channel in self.fleet_channels:
            channel.commands.stop()
        if self.busy.acquire(timeout=grace):
            self.busy.release()

    def close(self) -> None:
        """Release the world and the command reader once no episode runs (at exit)."""
        idle = self.busy.acquire(timeout=5.0)
        self.episode.close()
        self.commands.destroy()
        for channel in self.fleet_channels:
            channel.commands.destroy()
            channel.topics.node.destroy_node()
        if idle:
            self.busy.release()


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
    msg.robot_into_robot_collisions = int(metrics.robot_into_robot_collisions)
    msg.robot_hit_by_robot_collisions = int(metrics.robot_hit_by_robot_collisions)
    msg.fault_risk_score = float(metrics.fault_risk_score)
    msg.invalid_commands = int(metrics.invalid_commands)
    msg.legs = int(metrics.legs)
    msg.legs_completed = int(metrics.legs_completed)
    msg.leg_times = [float(value) for value in metrics.leg_times]
    msg.failed_leg = int(metrics.failed_leg)
    for name in NAVIGATION_FIELDS:
        setattr(msg, name, float(getattr(metrics, name)))
    msg.success = bool(metrics.success)
    return msg


NAVIGATION_FIELDS = ('time_to_goal', 'path_length_ratio', 'mean_clearance', 'linear_jerk',
                     'angular_jerk', 'mean_speed')
"""EpisodeMetrics' float navigation fields, copied as they are (NaN: not reached / none)."""


def invalid_metrics(environment_id: str, detail: str,
                    outcome: Outcome = Outcome.INVALID_ENVIRONMENT) -> EpisodeMetricsMsg:
    """The result of an episode that could not start: ``outcome`` invalid_environment (the
    map's fault) or harness_error (this simulator's or the goal's)."""
    msg = EpisodeMetricsMsg()
    msg.environment_id = environment_id
    msg.outcome = outcome.value
    msg.detail = detail
    msg.legs = 1
    msg.failed_leg = -1
    msg.time_to_goal = msg.path_length_ratio = msg.mean_clearance = math.nan
    return msg


def main(args=None) -> None:
    exit_if_help('sessgan_sim simulator', __doc__ or '', SimulatorNode, args)
    # Two threads: one runs an episode inside the evaluate callback, the other keeps the
    # action server (and Nav2 clients) answering meanwhile.
    try:
        status = run_node(
            SimulatorNode, lambda context: MultiThreadedExecutor(num_threads=2, context=context),
            args=args, stop=SimulatorNode.stop, before_destroy=SimulatorNode.close)
    except InvalidConfigError as err:
        rclpy.logging.get_logger('sessgan_sim').fatal(f'cannot start the simulator: {err}')
        status = 2
    exit_process(status)
