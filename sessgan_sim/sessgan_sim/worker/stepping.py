"""The tick loop of one episode, lockstep or clocked, for one robot under test or a fleet (a
single robot is a fleet of one).

Lockstep publishes a tick's clock, odom, tf, scan (and the flyer's range_down) for every robot,
waits for the cmd_vel of every robot still driving and only then advances the simulation by one
control period. Clocked advances the simulation at ``real_time_factor`` times the wall clock and
applies the latest command received from each robot; a robot's stack whose commands come too
late in sim time ends it as overloaded (sessgan_sim.command_pace), while one that stopped its
robot may pause as long as the stuck window (Nav2's Wait recovery). Either way a silent
controller ends the episode as controller_unresponsive after a wall-clock timeout, an evaluate
client's cancel or a shutdown ends it as cancelled, and nothing waits forever.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from sessgan_sim import ros_messages as rm
from sessgan_sim.command_pace import PaceFigures, PaceMonitor
from sessgan_sim.metrics import FAILURE_OUTCOMES, Outcome, is_harness_outcome
from sessgan_sim.simulator_settings import SimulatorSettings, StepMode
from sessgan_sim.worker.commands import CommandReceiver
from sessgan_sim.worker.topics import Recording, RobotTopics

GOAL_REPUBLISH_PERIOD = 1.0
"""Wall seconds between checks for late goal_pose readers (and, in lockstep before the first
command, between unconditional resends of the goal)."""
SETTLE_PERIOD = 0.5
"""Wall seconds a fleet's controllers that just came up get before the first tick."""
StepHook = Callable[[], 'str | None']
"""Runs between ticks; a string it returns ends the episode as controller_unresponsive."""
FEEDBACK_PERIOD = 0.25
"""Sim seconds between evaluate feedback messages (at least FEEDBACK_WALL_PERIOD apart)."""
FEEDBACK_WALL_PERIOD = 0.2
"""Wall seconds between evaluate feedback messages at least: a lockstep episode runs at 50x
real time, where feedback every 0.25 sim s cost a sixth of the simulator's messaging (an
action feedback message costs about 0.2 ms of CPU, tests/benchmarks/bench_simulator_node.py)
and told a client watching progress nothing it could follow. Shorter than FEEDBACK_PERIOD, so
a real-time (clocked) episode keeps its cadence despite jitter."""


STOP_TOLERANCE = 1e-3
"""m/s and rad/s: a command whose every component is within this is a stop."""


def is_stop(command) -> bool:
    """Whether a Twist or TwistStamped tells the robot to stand still."""
    return all(abs(value) <= STOP_TOLERANCE for value in rm.twist_values(command))


class FeedbackSchedule:
    """When the next evaluate feedback is due: FEEDBACK_PERIOD sim seconds and
    FEEDBACK_WALL_PERIOD wall seconds (``clock``) after the last, the first one FEEDBACK_PERIOD
    sim seconds into the episode."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._next_sim_time = FEEDBACK_PERIOD
        self._next_wall_time = -math.inf

    def due(self, sim_time: float) -> bool:
        """Whether feedback goes out at episode time ``sim_time`` (seconds); if so, the next
        is scheduled from now."""
        if sim_time < self._next_sim_time - 1e-9:
            return False
        now = self._clock()
        if now < self._next_wall_time:
            return False
        self._next_sim_time = sim_time + FEEDBACK_PERIOD
        self._next_wall_time = now + FEEDBACK_WALL_PERIOD
        return True


@dataclass
class EpisodeClock:
    """Maps an episode's sim time (seconds from its start) to stamps on the worker's clock."""

    origin_ns: int

    def stamp_ns(self, episode_time: float) -> int:
        return self.origin_ns + int(round(episode_time * 1e9))


class RobotChannel:
    """One robot under test's topics and command reader (a fleet has one per robot, each in
    its namespace r0, r1, ...)."""

    def __init__(self, topics: RobotTopics, commands: CommandReceiver,
                 command_type_name: str) -> None:
        self.topics = topics
        self.commands = commands
        self.command_msgtype = f'geometry_msgs/msg/{command_type_name}'
        self.expected_readers = {'odom'}
        """Topics of the tick besides scan that the controller is expected to read: odom at
        first, then those it read when it last started. Under load discovery may show its scan
        reader before its odom reader; a tick sent then would miss the odom and never be
        answered (seen in a fresh-clone test run: controller_unresponsive after 15 s)."""

    def wait_for_controller(self, timeout: float) -> bool:
        """Wait until a controller reads our scan and publishes cmd_vel, with every endpoint of
        the tick's topics that discovery shows matched to ours.

        Only matched endpoints exchange messages: a tick published before the controller's odom
        reader matched our writer, or an answer sent before our best-effort cmd_vel reader
        matched its writer, would be lost and stall the episode until the startup timeout. A
        tick is never published twice (a repeated one would earn a second answer and shift
        every later command by a tick). An endpoint that never matches (incompatible QoS) holds
        the start up for at most a second, as does a controller without a reader of one of
        its ``expected_readers``. False after ``timeout`` wall seconds or on shutdown.
        """
        topics, commands = self.topics, self.commands
        deadline = time.monotonic() + timeout
        settle_deadline = None
        waited = False
        while self.commands.running:
            matched_commands = commands.matched_writers()
            if topics.readers('scan') > 0 and matched_commands > 0:
                complete = matched_commands >= commands.writers_in_graph() and all(
                    topics.readers(name) >= max(name in self.expected_readers,
                                                commands.node.count_subscribers(topics.names[name]))
                    for name in ('clock', 'odom', 'scan'))
                now = time.monotonic()
                settle_deadline = settle_deadline or now + 1.0
                if complete or now >= settle_deadline:
                    if waited:  # just matched: let the controller's side catch up too
                        time.sleep(0.1)
                    self.expected_readers = {name for name in ('clock', 'odom')
                                             if topics.readers(name) > 0}
                    return True
            if time.monotonic() > deadline:
                return False
            waited = True
            time.sleep(0.01)
        return False

    def wait_for_command(self, deadline: float, republish) -> object | None:
        """The next command received before the wall-clock ``deadline``, else None (also at
        shutdown)."""
        next_republish = time.monotonic() + GOAL_REPUBLISH_PERIOD
        while True:
            command = self.commands.take()
            if command is not None:
                return command
            now = time.monotonic()
            if now >= deadline:
                return None
            if republish is not None and now >= next_republish:
                republish()  # covers a controller that matched our publishers only now
                next_republish = now + GOAL_REPUBLISH_PERIOD
            if not self.commands.wait(min(deadline, next_republish) - now):
                return None


class EpisodeStepper:
    """Runs an episode's ticks between its robots' channels (r0 first; one for a single robot).

    Each tick publishes every robot's clock, odom, tf and scan; lockstep then waits for a
    command from every robot still driving (one that ended, at its goal say, stands still
    and may fall silent, as Nav2 does after a goal succeeds). In clocked mode each robot's
    stack is held to the pace rule on its own (the episode ends overloaded when one could not
    keep pace; a robot that ended at its goal may fall silent).
    """

    def __init__(self, channels: list[RobotChannel]) -> None:
        self.channels = channels
        self.paces: list[PaceFigures] = []
        """The last clocked episode's command pace per robot ([] after a lockstep one)."""

    def who(self, index: int) -> str:
        """How a detail names robot ``index``: 'robot r<i>: ' in a fleet, '' otherwise."""
        return f'robot r{index}: ' if len(self.channels) > 1 else ''

    # ---- before the first tick -------------------------------------------------------------

    def wait_for_controllers(self, timeout: float) -> int | None:
        """Wait for every robot's controller (RobotChannel.wait_for_controller); the index of
        the first that did not come within ``timeout`` wall seconds, else None."""
        deadline = time.monotonic() + timeout
        started = time.monotonic()
        for index, channel in enumerate(self.channels):
            if not channel.wait_for_controller(max(0.0, deadline - time.monotonic())):
                return index
        if len(self.channels) > 1 and time.monotonic() - started > 0.05:
            # Controllers that came up just now: while we waited for one, discovery of
            # another's odom or clock reader may still have been under way (a tick it misses
            # is never sent again). Let it settle, then check everyone once more.
            time.sleep(SETTLE_PERIOD)
            for index, channel in enumerate(self.channels):
                if not channel.wait_for_controller(max(0.0, deadline - time.monotonic())):
                    return index
        return None

    # ---- the loop ---------------------------------------------------------------------------

    def run(self, episode, clock: EpisodeClock, settings: SimulatorSettings,
            recording: Recording | None, goal_handle=None,
            before_first_step: StepHook | None = None,
            command_override: Callable[[], tuple[float, float, float] | None] | None = None,
            new_goal: Callable[[int, object, int], str | None] | None = None):
        """Step ``episode`` from its robots' latest observations until it ends; returns its
        metrics.

        ``before_first_step`` runs once before time advances (costmap resets and the goals).
        ``command_override`` may replace every received command (a stack that finished its
        navigation goal is stopped). ``new_goal(index, goal, stamp_ns)`` sends robot
        ``index``'s next waypoint of a mission (its observation's goal changed) before the
        tick that follows is published. A string either returns ends the episode as
        controller_unresponsive with that detail.
        """
        lockstep = settings.step_mode is StepMode.LOCKSTEP
        timeout = settings.controller_timeout
        startup_timeout = settings.controller_startup_timeout
        # A stack that stopped its robot may pause (Nav2's Wait recovery: 5 s) as long as the
        # stuck window; note_left_robots judges a longer silence when the robot ends.
        pause_timeout = max(timeout, episode.config.stuck_timeout / settings.real_time_factor)
        dt = episode.config.control_period
        feedback = FeedbackSchedule()
        channels = self.channels
        observations = episode.observations()
        for channel in channels:
            channel.commands.take_all()  # stale answers of an earlier episode
            channel.topics.forget_goal()
        commands: list = [None] * len(channels)
        heard = [time.monotonic()] * len(channels)
        left: dict[int, float] = {}  # robots that ended after their stack fell silent
        # Each robot's stack keeps pace or not on its own (fed in clocked mode only).
        paces = [PaceMonitor(settings.pace_rule(), dt) for _ in channels]
        wall_origin = time.monotonic()
        next_goal_check = time.monotonic() + GOAL_REPUBLISH_PERIOD
        first = True
        overridden = None
        while not episode.done:
            if goal_handle is not None and goal_handle.is_cancel_requested:
                episode.abort(Outcome.CANCELLED, 'cancelled by the evaluate client')
                break
            if not all(channel.commands.running for channel in channels):
                # stopping (SIGINT, SIGTERM): end at once
                episode.abort(Outcome.CANCELLED, 'the simulator was shut down')
                break
            sim_time = observations[0].time
            stamp_ns = clock.stamp_ns(sim_time)
            # The stack is prepared (resets, goal) before the first tick in lockstep, so the
            # controller's first answer already knows the goal; after it in clocked mode, so a
            # stack like Nav2 sees the new pose in tf before it plans.
            if first and lockstep and not self.prepare(episode, before_first_step):
                break
            for channel, observation in zip(channels, observations):
                channel.topics.publish_tick(observation, stamp_ns, recording)
            if first and not lockstep:
                if not self.prepare(episode, before_first_step):
                    break
                wall_origin = time.monotonic() - sim_time / settings.real_time_factor
                heard = [time.monotonic()] * len(channels)
            if time.monotonic() >= next_goal_check:
                for channel in channels:
                    channel.topics.republish_goal()  # to a goal_pose reader that joined late
                next_goal_check = time.monotonic() + GOAL_REPUBLISH_PERIOD
            driving = episode.driving()
            silent = None
            if lockstep:
                limit = startup_timeout if first else timeout
                for index in driving:
                    channel = channels[index]
                    received = channel.wait_for_command(
                        time.monotonic() + limit,
                        (lambda topics=channel.topics: topics.republish_goal(force=True))
                        if first else None)
                    if received is None:
                        silent = index
                        break
                    commands[index] = received
            else:
                self.receive(wall_origin + (sim_time + dt) / settings.real_time_factor,
                             commands, heard, paces, sim_time)
                overridden = command_override() if command_override is not None else None
                if overridden is not None:
                    for pace in paces:
                        pace.restart_gap()  # a stack told its navigation ended may fall silent
                now = time.monotonic()
                for index in driving if overridden is None else ():
                    limit = (startup_timeout if commands[index] is None
                             else pause_timeout if paces[index].paused else timeout)
                    if now - heard[index] > limit:
                        silent = index
                        break
                if silent is None and overridden is None:
                    # The wait for a stack's first command is not judged (the startup timeout
                    # bounds it): a stack that never answers, or plans its first route slowly
                    # on a fast clock, must not end the episode stuck or timed out.
                    for index in driving:
                        if commands[index] is None:
                            episode.await_first_command(index)
                if silent is None and any(paces[index].overload() for index in driving):
                    # The episode ends here, so every robot is judged as at an episode's end:
                    # each that could not keep pace is named, also one whose stack started
                    # later and has not yet been measured long enough to be judged mid-way.
                    episode.abort(Outcome.OVERLOADED,
                                  self.overloads(paces, driving, settings))
                    break
            if silent is not None:
                if all(channel.commands.running for channel in channels):
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                                  f'{self.who(silent)}no cmd_vel within {limit:.1f} s wall time')
                continue  # the loop's head ends a shut-down episode as cancelled
            first = False
            values = []
            for channel, command in zip(channels, commands):
                values.append(overridden if overridden is not None
                              else rm.twist_values(command) if command is not None
                              else (0.0, 0.0, 0.0))
                if recording is not None and command is not None:
                    recording.add(channel.topics.names['cmd_vel'], channel.command_msgtype,
                                  stamp_ns, command)
            if lockstep:
                commands = [None] * len(channels)  # each tick waits for fresh ones
            goals = [observation.goal for observation in observations]
            results = episode.step_fleet(values)
            observations = [result.observation for result in results]
            if not lockstep and overridden is None:
                self.note_left_robots(driving, results, paces, episode.config.stuck_timeout,
                                      left)
            if new_goal is not None and not episode.done:
                failure = self.send_new_goals(new_goal, goals, observations, clock, paces)
                if failure:
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE, failure)
                    break
            if goal_handle is not None and feedback.due(observations[0].time):
                self.publish_feedback(goal_handle, episode, observations[0])
        if not lockstep:
            # The final state, so subscribers and bags see where the robots ended. Not in
            # lockstep: its answer could arrive during the next episode.
            stamp_ns = clock.stamp_ns(observations[0].time)
            for channel, observation in zip(channels, observations):
                channel.topics.publish_tick(observation, stamp_ns, recording)
        metrics = episode.metrics()
        self.paces = [] if lockstep else [pace.figures for pace in paces]
        if left and not is_harness_outcome(metrics.outcome):
            return dataclasses.replace(
                metrics, outcome=Outcome.CONTROLLER_UNRESPONSIVE, success=False,
                detail='; '.join(f'{self.who(index)}no cmd_vel in the last {silent:.1f} sim s '
                                 f'(real_time_factor {settings.real_time_factor:g}): its '
                                 'stack fell silent, the robot was not driven'
                                 for index, silent in sorted(left.items()))
                + (f' (it had ended {metrics.outcome.value})' if metrics.outcome else ''))
        if not lockstep and not is_harness_outcome(metrics.outcome):
            # A result reached while starved (a collision, stuck, even the goal) says how busy
            # the machine was, not how the stack drives.
            overloaded = self.overloads(paces, range(len(paces)), settings)
            if overloaded:
                return dataclasses.replace(
                    metrics, outcome=Outcome.OVERLOADED, success=False,
                    detail=overloaded + (f' (it had ended {metrics.outcome.value})'
                                         if metrics.outcome else ''))
        return metrics

    def receive(self, deadline: float, commands: list, heard: list[float],
                paces: list[PaceMonitor], sim_time: float) -> None:
        """Clocked mode: take every robot's commands until the wall-clock ``deadline`` (the
        latest of each in ``commands``, when it came in ``heard``), waking as r0's arrive
        (a single robot's arrival times are exact), the others' taken at the deadline."""
        channels = self.channels
        first = channels[0].commands
        while (remaining := deadline - time.monotonic()) > 0:
            if not first.wait(remaining):
                break  # stopping: the loop's head ends the episode
            self.take(0, commands, heard, paces, sim_time)
        if len(channels) > 1:
            time.sleep(max(0.0, deadline - time.monotonic()))
            for index in range(1, len(channels)):
                self.take(index, commands, heard, paces, sim_time)

    def take(self, index: int, commands: list, heard: list[float], paces: list[PaceMonitor],
             sim_time: float) -> None:
        """Take robot ``index``'s received commands: keep the latest, note when and its pace."""
        received = self.channels[index].commands.take_all()
        if received:
            commands[index], heard[index] = received[-1], time.monotonic()
            paces[index].command(sim_time, stop=is_stop(received[-1]))

    @staticmethod
    def note_left_robots(driving: Sequence[int], results: Sequence, paces: Sequence[PaceMonitor],
                         stuck_timeout: float, left: dict[int, float]) -> None:
        """Clocked mode: note in ``left`` each robot of ``driving`` that just ended stuck or
        timed out while its stack had sent nothing for the whole stuck window. In sim time
        the stuck rule can come before the wall-clock silence rule (at a real-time factor
        above stuck_timeout / controller_timeout, 5 by default): a stack that died after its
        first command would otherwise fail its test."""
        if stuck_timeout <= 0:
            return  # no stuck rule, no window to judge silence by in sim time
        for index in driving:
            if results[index].outcome in FAILURE_OUTCOMES:
                silent = paces[index].silent_for(results[index].observation.time)
                if silent is not None and silent >= stuck_timeout - 1e-9:
                    left[index] = silent

    @staticmethod
    def send_new_goals(new_goal, goals: list, observations: list, clock: EpisodeClock,
                       paces: list[PaceMonitor]) -> str | None:
        """Send each robot whose goal changed (a mission's next waypoint) its new one; the
        first failure, else None."""
        for index, (goal, observation) in enumerate(zip(goals, observations)):
            if observation.goal != goal:
                failure = new_goal(index, observation.goal, clock.stamp_ns(observation.time))
                if failure:
                    return failure
                paces[index].restart_gap()  # a stack may pause between a mission's waypoints
        return None

    @staticmethod
    def overload_detail(overload: str, settings: SimulatorSettings) -> str:
        return f'{overload}; real_time_factor {settings.real_time_factor:g}'

    def overloads(self, paces: Sequence[PaceMonitor], robots: Iterable[int],
                  settings: SimulatorSettings) -> str:
        """The detail naming every robot of ``robots`` whose stack could not keep pace,
        judged as at the episode's end; '' when none."""
        return '; '.join(self.who(index) + self.overload_detail(detail, settings)
                         for index in robots if (detail := paces[index].overload(final=True)))

    @staticmethod
    def prepare(episode, before_first_step) -> bool:
        """Run ``before_first_step``; False (the episode ended) when it reports a failure."""
        failure = before_first_step() if before_first_step is not None else None
        if failure:
            episode.abort(Outcome.CONTROLLER_UNRESPONSIVE, failure)
            return False
        return True

    @staticmethod
    def publish_feedback(goal_handle, episode, observation) -> None:
        from sessgan_interfaces.action import EvaluateEnvironment

        so_far = episode.metrics()
        feedback = EvaluateEnvironment.Feedback()
        feedback.sim_time = observation.time
        feedback.collisions = so_far.collisions
        feedback.distance_to_goal = so_far.final_distance_to_goal
        goal_handle.publish_feedback(feedback)
