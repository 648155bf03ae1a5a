"""The tick loops of one episode: lockstep and clocked.

Lockstep publishes a tick's clock, odom, tf, scan (and the flyer's range_down), waits for the
controller's cmd_vel and only then advances the simulation by one control period. Clocked
advances the simulation at ``real_time_factor`` times the wall clock and applies the latest
command received; a stack whose commands come too late in sim time ends it as overloaded
(sessgan_sim.command_pace). Either way a silent controller ends the episode as
controller_unresponsive after a wall-clock timeout, an evaluate client's cancel or a shutdown
ends it as cancelled, and nothing waits forever.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from sessgan_sim import ros_messages as rm
from sessgan_sim.command_pace import PaceFigures, PaceMonitor
from sessgan_sim.metrics import Outcome, is_harness_outcome
from sessgan_sim.simulator_settings import SimulatorSettings, StepMode
from sessgan_sim.worker.commands import CommandReceiver
from sessgan_sim.worker.topics import Recording, RobotTopics

GOAL_REPUBLISH_PERIOD = 1.0
"""Wall seconds between checks for late goal_pose readers (and, in lockstep before the first
command, between unconditional resends of the goal)."""
SETTLE_PERIOD = 0.5
"""Wall seconds a fleet's controllers that just came up get before the first tick."""
FEEDBACK_PERIOD = 0.25
"""Sim seconds between evaluate feedback messages (at least FEEDBACK_WALL_PERIOD apart)."""
FEEDBACK_WALL_PERIOD = 0.2
"""Wall seconds between evaluate feedback messages at least: a lockstep episode runs at 50x
real time, where feedback every 0.25 sim s cost a sixth of the simulator's messaging (an
action feedback message costs about 0.2 ms of CPU, tests/benchmarks/bench_simulator_node.py)
and told a client watching progress nothing it could follow. Shorter than FEEDBACK_PERIOD, so
a real-time (clocked) episode keeps its cadence despite jitter."""


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


class EpisodeStepper:
    """Runs an episode's ticks between the topics and the command reader."""

    def __init__(self, topics: RobotTopics, commands: CommandReceiver,
                 command_type_name: str) -> None:
        self.topics = topics
        self.commands = commands
        self.command_msgtype = f'geometry_msgs/msg/{command_type_name}'
        self.pace: PaceFigures | None = None
        """The last clocked episode's command pace (None after a lockstep one)."""

    # ---- before the first tick -------------------------------------------------------------

    def wait_for_controller(self, timeout: float) -> bool:
        """Wait until a controller reads our scan and publishes cmd_vel, with every endpoint of
        the tick's topics that discovery shows matched to ours.

        Only matched endpoints exchange messages: a tick published before the controller's odom
        reader matched our writer, or an answer sent before our best-effort cmd_vel reader
        matched its writer, would be lost and stall the episode until the startup timeout. A
        tick is never published twice (a repeated one would earn a second answer and shift
        every later command by a tick). An endpoint that never matches (incompatible QoS) holds
        the start up for at most a second. False after ``timeout`` wall seconds or on shutdown.
        """
        topics, commands = self.topics, self.commands
        deadline = time.monotonic() + timeout
        settle_deadline = None
        waited = False
        while self.commands.running:
            matched_commands = commands.matched_writers()
            if topics.readers('scan') > 0 and matched_commands > 0:
                complete = matched_commands >= commands.writers_in_graph() and all(
                    topics.readers(name) >= commands.node.count_subscribers(topics.names[name])
                    for name in ('clock', 'odom', 'scan'))
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
        return False

    # ---- the loop ---------------------------------------------------------------------------

    def run(self, episode, observation, clock: EpisodeClock, settings: SimulatorSettings,
            recording: Recording | None, goal_handle=None,
            before_first_step: Callable[[], str | None] | None = None,
            command_override: Callable[[], tuple[float, float, float] | None] | None = None,
            new_goal: Callable[[object, int], str | None] | None = None):
        """Step ``episode`` from ``observation`` until it ends; returns its metrics.

        ``before_first_step`` runs once before time advances (costmap resets and the goal);
        a string it returns ends the episode as controller_unresponsive with that detail.
        ``command_override`` may replace the received command (a stack that finished its
        navigation goal is stopped). ``new_goal(goal, stamp_ns)`` sends a mission's next
        waypoint (the observation's goal changed) before the tick that follows is published;
        a string it returns ends the episode like ``before_first_step``'s.
        """
        lockstep = settings.step_mode is StepMode.LOCKSTEP
        timeout = settings.controller_timeout
        startup_timeout = settings.controller_startup_timeout
        dt = episode.config.control_period
        feedback = FeedbackSchedule()
        topics, commands = self.topics, self.commands
        topics.forget_goal()
        command = None
        last_command_wall = time.monotonic()
        wall_origin = time.monotonic()
        next_goal_check = time.monotonic() + GOAL_REPUBLISH_PERIOD
        first = True
        commands.take_all()  # stale answers of an earlier episode
        pace = PaceMonitor(settings.pace_rule(), dt)  # fed in clocked mode only
        while not episode.done:
            if goal_handle is not None and goal_handle.is_cancel_requested:
                episode.abort(Outcome.CANCELLED, 'cancelled by the evaluate client')
                break
            if not commands.running:  # stopping (SIGINT, SIGTERM): end at once
                episode.abort(Outcome.CANCELLED, 'the simulator was shut down')
                break
            stamp_ns = clock.stamp_ns(observation.time)
            # The stack is prepared (resets, goal) before the first tick in lockstep, so the
            # controller's first answer already knows the goal; after it in clocked mode, so a
            # stack like Nav2 sees the new pose in tf before it plans.
            if first and lockstep and not self.prepare(episode, before_first_step):
                break
            topics.publish_tick(observation, stamp_ns, recording)
            if first and not lockstep:
                if not self.prepare(episode, before_first_step):
                    break
                wall_origin = time.monotonic() - observation.time / settings.real_time_factor
                last_command_wall = time.monotonic()
            if time.monotonic() >= next_goal_check:
                topics.republish_goal()  # to a goal_pose reader that joined late
                next_goal_check = time.monotonic() + GOAL_REPUBLISH_PERIOD
            if lockstep:
                limit = startup_timeout if first else timeout
                received = self.wait_for_command(
                    time.monotonic() + limit,
                    (lambda: topics.republish_goal(force=True)) if first else None)
                if received is None:
                    if not commands.running:
                        continue  # the loop's head ends it as cancelled
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                                  f'no cmd_vel within {limit:.1f} s wall time')
                    break
                command = received
            else:
                tick_deadline = wall_origin + (observation.time + dt) / settings.real_time_factor
                while (remaining := tick_deadline - time.monotonic()) > 0:
                    if not commands.wait(remaining):
                        break
                    received_all = commands.take_all()
                    if received_all:
                        command = received_all[-1]
                        last_command_wall = time.monotonic()
                        pace.command(observation.time)
                overridden = command_override() if command_override is not None else None
                limit = startup_timeout if command is None else timeout
                if overridden is None and time.monotonic() - last_command_wall > limit:
                    if not commands.running:
                        continue
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                                  f'no cmd_vel within {limit:.1f} s wall time')
                    break
                if overridden is not None:
                    pace.restart_gap()  # a stack told its navigation ended may fall silent
                overload = pace.overload()
                if overload:
                    episode.abort(Outcome.OVERLOADED, self.overload_detail(overload, settings))
                    break
            first = False
            values = rm.twist_values(command) if command is not None else (0.0, 0.0, 0.0)
            if not lockstep and overridden is not None:
                values = overridden
            if recording is not None and command is not None:
                recording.add(topics.names['cmd_vel'], self.command_msgtype, stamp_ns, command)
            goal = observation.goal
            observation = episode.step(values).observation
            if new_goal is not None and observation.goal != goal and not episode.done:
                failure = new_goal(observation.goal, clock.stamp_ns(observation.time))
                if failure:
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE, failure)
                    break
                pace.restart_gap()  # a stack may pause between a mission's waypoints
            if goal_handle is not None and feedback.due(observation.time):
                self.publish_feedback(goal_handle, episode, observation)
        if not lockstep:
            # The final state, so subscribers and bags see where the robot ended. Not in
            # lockstep: its answer could arrive during the next episode.
            topics.publish_tick(observation, clock.stamp_ns(observation.time), recording)
        metrics = episode.metrics()
        self.pace = None if lockstep else pace.figures
        if not lockstep and not is_harness_outcome(metrics.outcome):
            # A result reached while starved (a collision, stuck, even the goal) says how busy
            # the machine was, not how the stack drives.
            overload = pace.overload(final=True)
            if overload:
                metrics = dataclasses.replace(
                    metrics, outcome=Outcome.OVERLOADED, success=False,
                    detail=self.overload_detail(overload, settings) + (
                        f' (it had ended {metrics.outcome.value})' if metrics.outcome else ''))
        return metrics

    @staticmethod
    def overload_detail(overload: str, settings: SimulatorSettings) -> str:
        return f'{overload}; real_time_factor {settings.real_time_factor:g}'

    @staticmethod
    def prepare(episode, before_first_step) -> bool:
        """Run ``before_first_step``; False (the episode ended) when it reports a failure."""
        failure = before_first_step() if before_first_step is not None else None
        if failure:
            episode.abort(Outcome.CONTROLLER_UNRESPONSIVE, failure)
            return False
        return True

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

    @staticmethod
    def publish_feedback(goal_handle, episode, observation) -> None:
        from sessgan_interfaces.action import EvaluateEnvironment

        so_far = episode.metrics()
        feedback = EvaluateEnvironment.Feedback()
        feedback.sim_time = observation.time
        feedback.collisions = so_far.collisions
        feedback.distance_to_goal = so_far.final_distance_to_goal
        goal_handle.publish_feedback(feedback)


class FleetStepper:
    """Runs a fleet episode's ticks: one EpisodeStepper (topics and command reader in the
    robot's namespace) per robot under test, r0 first. In clocked mode each robot's stack
    is held to the pace rule on its own (the episode ends overloaded when one could not keep
    pace; a robot that ended at its goal may fall silent).

    Each tick publishes every robot's clock, odom, tf and scan; lockstep then waits for a
    command from every robot still driving (one that ended, at its goal say, stands still
    and may fall silent, as Nav2 does after a goal succeeds). Goals go out on each robot's
    goal_pose (and waypoints); a fleet has no NavigateToPose client.
    """

    def __init__(self, steppers: list[EpisodeStepper]) -> None:
        self.steppers = steppers

    def wait_for_controllers(self, timeout: float) -> int | None:
        """Wait for every robot's controller (EpisodeStepper.wait_for_controller); the
        index of the first that did not come within ``timeout`` wall seconds, else None."""
        deadline = time.monotonic() + timeout
        started = time.monotonic()
        for index, stepper in enumerate(self.steppers):
            if not stepper.wait_for_controller(max(0.0, deadline - time.monotonic())):
                return index
        if time.monotonic() - started > 0.05:
            # Controllers that came up just now: while we waited for one, discovery of
            # another's odom or clock reader may still have been under way (a tick it misses
            # is never sent again). Let it settle, then check everyone once more.
            time.sleep(SETTLE_PERIOD)
            for index, stepper in enumerate(self.steppers):
                if not stepper.wait_for_controller(max(0.0, deadline - time.monotonic())):
                    return index
        return None

    def run(self, episode, observations, clock: EpisodeClock, settings: SimulatorSettings,
            recording: Recording | None, goal_handle=None):
        """Step the fleet ``episode`` from ``observations`` (a robot each) until it ends;
        returns its metrics."""
        lockstep = settings.step_mode is StepMode.LOCKSTEP
        timeout = settings.controller_timeout
        dt = episode.config.control_period
        feedback = FeedbackSchedule()
        steppers = self.steppers
        stamp_ns = clock.stamp_ns(0.0)
        for stepper, observation in zip(steppers, observations, strict=True):
            stepper.commands.take_all()  # stale answers of an earlier episode
            stepper.topics.forget_goal()
            stepper.topics.publish_waypoints([observation.goal], stamp_ns, recording)
            stepper.topics.publish_goal(observation.goal, stamp_ns, recording)
        commands: list = [None] * len(steppers)
        heard = [time.monotonic()] * len(steppers)
        # Each robot's stack keeps pace or not on its own (fed in clocked mode only).
        paces = [PaceMonitor(settings.pace_rule(), dt) for _ in steppers]
        wall_origin = time.monotonic()
        next_goal_check = time.monotonic() + GOAL_REPUBLISH_PERIOD
        first = True
        while not episode.done:
            if goal_handle is not None and goal_handle.is_cancel_requested:
                episode.abort(Outcome.CANCELLED, 'cancelled by the evaluate client')
                break
            if not all(stepper.commands.running for stepper in steppers):
                episode.abort(Outcome.CANCELLED, 'the simulator was shut down')
                break
            stamp_ns = clock.stamp_ns(observations[0].time)
            for stepper, observation in zip(steppers, observations):
                stepper.topics.publish_tick(observation, stamp_ns, recording)
            if time.monotonic() >= next_goal_check:
                for stepper in steppers:
                    stepper.topics.republish_goal()  # to a goal_pose reader that joined late
                next_goal_check = time.monotonic() + GOAL_REPUBLISH_PERIOD
            driving = [index for index in range(len(steppers))
                       if episode.robot_metrics(index).outcome is None]
            limit = settings.controller_startup_timeout if first else timeout
            silent = None
            if lockstep:
                for index in driving:
                    stepper = steppers[index]
                    received = stepper.wait_for_command(
                        time.monotonic() + limit,
                        (lambda topics=stepper.topics: topics.republish_goal(force=True))
                        if first else None)
                    if received is None:
                        silent = index
                        break
                    commands[index] = received
            else:
                tick_deadline = (wall_origin
                                 + (observations[0].time + dt) / settings.real_time_factor)
                time.sleep(max(0.0, tick_deadline - time.monotonic()))
                now = time.monotonic()
                for index, stepper in enumerate(steppers):
                    received_all = stepper.commands.take_all()
                    if received_all:
                        commands[index], heard[index] = received_all[-1], now
                        paces[index].command(observations[0].time)
                for index in driving:
                    limit = (settings.controller_startup_timeout if commands[index] is None
                             else timeout)
                    if now - heard[index] > limit:
                        silent = index
                        break
                overloaded = next(((index, detail) for index in driving
                                   if (detail := paces[index].overload())), None)
                if silent is None and overloaded is not None:
                    episode.abort(Outcome.OVERLOADED, f'robot r{overloaded[0]}: '
                                  + EpisodeStepper.overload_detail(overloaded[1], settings))
                    break
            if silent is not None:
                if all(stepper.commands.running for stepper in steppers):
                    episode.abort(Outcome.CONTROLLER_UNRESPONSIVE,
                                  f'robot r{silent}: no cmd_vel within {limit:.1f} s wall time')
                continue  # the loop's head ends a shut-down episode as cancelled
            first = False
            values = []
            for stepper, command in zip(steppers, commands):
                values.append(rm.twist_values(command) if command is not None
                              else (0.0, 0.0, 0.0))
                if recording is not None and command is not None:
                    recording.add(stepper.topics.names['cmd_vel'], stepper.command_msgtype,
                                  stamp_ns, command)
            if lockstep:
                commands = [None] * len(steppers)  # each tick waits for fresh ones
            observations = [result.observation for result in episode.step_fleet(values)]
            if goal_handle is not None and feedback.due(observations[0].time):
                EpisodeStepper.publish_feedback(goal_handle, episode, observations[0])
        if not lockstep:
            stamp_ns = clock.stamp_ns(observations[0].time)
            for stepper, observation in zip(steppers, observations):
                stepper.topics.publish_tick(observation, stamp_ns, recording)
        metrics = episode.metrics()
        if not lockstep and not is_harness_outcome(metrics.outcome):
            for index, pace in enumerate(paces):
                overload = pace.overload(final=True)
                if overload:  # a result reached while one robot's stack was starved
                    return dataclasses.replace(
                        metrics, outcome=Outcome.OVERLOADED, success=False,
                        detail=f'robot r{index}: '
                        + EpisodeStepper.overload_detail(overload, settings)
                        + (f' (it had ended {metrics.outcome.value})' if metrics.outcome
                           else ''))
        return metrics
