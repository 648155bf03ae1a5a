"""`ros2 run sessgan_evolver replay <bag>`: replay a failure bag, or re-simulate it.

Replay republishes every recorded message with its recorded timing (scaled by ``--rate``),
including ``/clock``, for RViz or any subscriber. Topics recorded under a worker namespace
(``/w0/scan``) are republished under ``--namespace`` (default: the root, ``/scan``). A fleet's
bag has every topic once per robot (``/w0/r1/tf``): its robots' ``tf``, ``tf_static`` and
``map`` go to the one ``/tf``, ``/tf_static`` and ``/map`` a viewer reads (the frames are
already the robots' own, ``r1/odom``), r0's ``clock`` is ``/clock`` (the others tick the
same times), and the rest stays per robot (``/r1/scan``).

``--resimulate`` runs the bag's map, start, goal and seed again and compares the outcome with
the recorded one. It starts a simulator rebuilt from the settings episode.json records (mode,
rates, lidar, agents, robot parameters, clock origin; sessgan_sim.simulator_settings) and the
recorded built-in controller. For a bag recorded with your own controller, run that controller
under a namespace and pass ``--external`` (``--namespace /w0``; default: the recorded one): only
the simulator is started there. ``--worker /w0`` uses a simulator that already runs, with its
own settings. Exit codes: 0 as expected (``--expect same``: same outcome and collision count;
``--expect pass``: no failure any more), 1 not as expected, 2 on an error (unreadable bag, no
worker, settings that cannot be rebuilt, or every one of 3 tries ended by the harness rather
than the controller: a silent or slow-starting controller, a cancelled episode; such a try is
never compared, but run again).

Both modes first check the bag: every file against the size and SHA-256 digest episode.json
recorded, every message readable (MCAP chunk CRCs) and as many as recorded; a corrupt bag is
refused (exit 2) naming the file, one without digests (older bags) replays with a warning.
"""

from __future__ import annotations

import importlib
import os
import re
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from sessgan_core.config_cli import cli, parse_valid_config
from sessgan_core.ros_spin import INTERRUPTED_STATUS, init_rclpy, run_command, spin_interruptibly
from sessgan_core.validation import ros_namespace

EXIT_AS_EXPECTED, EXIT_DIFFERENT, EXIT_ERROR = 0, 1, 2


@dataclass
class ReplayConfig:
    """The ``replay`` command's arguments."""

    bag: Path = field(metadata=cli(positional=True))
    """Failure bag directory (bags/<run>/<episode>)."""
    rate: float = 1.0
    """Playback speed factor (replay; 1.0 = recorded timing)."""
    namespace: str = ''
    """Replay: namespace to republish under (default /); --resimulate --external: namespace
    of your controller (default: the recorded one)."""
    loop: bool = False
    """Replay until interrupted (SIGINT or SIGTERM then ends it with exit 0, not 130)."""
    resimulate: bool = False
    """Run the bag's map again against a live controller and compare."""
    worker: str = ''
    """Namespace of a running simulator worker to use as it is (e.g. /w0; its settings, not
    the recorded ones); default: start a simulator with the recorded settings."""
    external: bool = False
    """The recorded controller is yours: start only the simulator, under --namespace, where
    your controller runs."""
    controller: str = ''
    """Built-in controller to start (default: the recorded one)."""
    expect: Literal['same', 'pass'] = 'same'
    """same: the failure must reproduce; pass: it must be gone."""
    timeout: float = 300.0
    """Wall seconds to wait for the re-simulated episode."""

    def validate(self) -> None:
        if not self.rate > 0:
            raise ValueError(f'--rate must be positive, got {self.rate}')
        for option in ('worker', 'namespace'):
            if getattr(self, option):
                setattr(self, option, ros_namespace(f'--{option}', getattr(self, option)))


def parse_args(argv: Sequence[str] | None) -> ReplayConfig:
    """The validated arguments; a usage error exits 2 (EXIT_ERROR) naming the option."""
    return parse_valid_config(ReplayConfig, argv, 'ros2 run sessgan_evolver replay',
                              __doc__ or '')


def message_class(msgtype: str):
    """The rclpy message class of 'pkg/msg/Name'."""
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


FLEET_SHARED_TOPICS = ('clock', 'tf', 'tf_static', 'map')
"""A fleet's per-robot topics that a viewer needs once, at the namespace's root."""


def republished_topic(topic: str, recorded_namespace: str, namespace: str,
                      fleet: bool = False) -> str | None:
    """Where a recorded topic is republished; None for one that is not (a fleet's second
    clock)."""
    recorded_namespace = recorded_namespace.rstrip('/')
    if recorded_namespace and topic.startswith(recorded_namespace + '/'):
        topic = topic[len(recorded_namespace):]
    parts = topic.split('/')  # ['', 'r1', 'tf'] for a fleet robot's topic
    if (fleet and len(parts) == 3 and re.fullmatch(r'r\d+', parts[1])
            and parts[2] in FLEET_SHARED_TOPICS):
        if parts[2] == 'clock' and parts[1] != 'r0':
            return None
        topic = '/' + parts[2]
    return namespace.rstrip('/') + topic


def replay(args: ReplayConfig, episode) -> int:
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosbags.interfaces import QosDurability

    from sessgan_evolver.bag_reading import iter_bag_messages, read_bag_topics
    from sessgan_sim.bag_recording import qos_for_topic

    topics = read_bag_topics(args.bag)
    recorded_namespace = (episode or {}).get('namespace', '')
    fleet = bool((episode or {}).get('fleet'))
    init_rclpy()
    node = rclpy.create_node('sessgan_replay')
    try:
        publishers = {}
        for topic in topics:
            # The contract's QoS, not the recorded one: bags before 2026-11-28 recorded
            # goal_pose and waypoints as volatile, which a transient-local reader never gets.
            latched = qos_for_topic(topic.topic).durability == QosDurability.TRANSIENT_LOCAL
            qos = QoSProfile(
                depth=max(1, topic.depth or 10), reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                else DurabilityPolicy.VOLATILE)
            name = republished_topic(topic.topic, recorded_namespace, args.namespace or '/',
                                     fleet)
            if name is not None:
                publishers[topic.topic] = node.create_publisher(
                    message_class(topic.msgtype), name, qos)
        total = sum(topic.message_count for topic in topics if topic.topic in publishers)
        node.get_logger().info(f'replaying {total} messages of {args.bag} at rate {args.rate}')
        wait_for_subscribers(node, publishers.values())
        while True:
            wall_start = time.monotonic()
            first_ns = None
            count = 0
            for message in iter_bag_messages(args.bag):
                if message.topic not in publishers:
                    continue
                first_ns = message.timestamp_ns if first_ns is None else first_ns
                due = wall_start + (message.timestamp_ns - first_ns) / 1e9 / args.rate
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                publishers[message.topic].publish(message.data)  # raw CDR bytes
                count += 1
            node.get_logger().info(
                f'replayed {count} messages in {time.monotonic() - wall_start:.1f} s')
            if not args.loop:
                return EXIT_AS_EXPECTED
    except KeyboardInterrupt:
        if args.loop:  # how a loop ends
            return EXIT_AS_EXPECTED
        node.get_logger().info('interrupted before the end of the bag')
        return INTERRUPTED_STATUS
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


SUBSCRIBER_MATCH_WAIT = 5.0
"""Most wall seconds to wait for subscribers already in the graph to match the replay's
publishers: the first messages (a fleet's first second of /clock and /tf) went unheard with
a fixed half second on a loaded 2-core machine."""


def wait_for_subscribers(node, publishers) -> None:
    """Until every subscriber discovery shows on a replayed topic is matched, at most
    SUBSCRIBER_MATCH_WAIT s (one that is still starting up misses the start as it would with
    `ros2 bag play`)."""
    time.sleep(0.5)  # discovery of the subscribers that run already
    deadline = time.monotonic() + SUBSCRIBER_MATCH_WAIT
    while time.monotonic() < deadline and any(
            node.count_subscribers(publisher.topic_name) > publisher.get_subscription_count()
            for publisher in publishers):
        time.sleep(0.05)


def bag_environment(bag: Path, episode: dict):
    from sessgan_core.environment import Environment, Pose2D
    from sessgan_core.fleet import fleet_from_json
    from sessgan_core.map_server_io import read_map_server

    occupancy, resolution, origin = read_map_server(bag / 'map.yaml')
    return Environment(
        id=episode['environment_id'], scenario=episode['scenario'], occupancy=occupancy,
        resolution=resolution, origin=(origin[0], origin[1]), start=Pose2D(*episode['start']),
        goal=Pose2D(*episode['goal']), seed=int(episode.get('seed', 0)),
        generation=int(episode.get('generation', -1)), member=int(episode.get('member', -1)),
        feasible=bool(episode.get('feasible', True)),
        route_length=float(episode.get('route_length', 0.0)),
        route_min_clearance=float(episode.get('route_min_clearance', 0.0)),
        stations=tuple(Pose2D(*pose) for pose in episode.get('stations', ())),
        dwell_time=float(episode.get('dwell_time', 0.0)),
        fleet=fleet_from_json(episode.get('fleet')))


def resimulate(args: ReplayConfig, episode: dict) -> int:
    import rclpy
    from rclpy.action import ActionClient

    from sessgan_controllers.registry import CONTROLLERS
    from sessgan_core.ros_conversion import environment_to_msg
    from sessgan_core.scenarios import get_scenario
    from sessgan_evolver.harness import DEFAULT_HARNESS_TRIES
    from sessgan_evolver.process_supervisor import ProcessSupervisor, worker_cores
    from sessgan_interfaces.action import EvaluateEnvironment
    from sessgan_sim.errors import InvalidConfigError
    from sessgan_sim.metrics import is_controller_failure, is_harness_outcome
    from sessgan_sim.simulator_settings import resimulation_settings

    environment = bag_environment(args.bag, episode)
    recorded = episode['metrics']
    controller = args.controller or episode.get('controller') or \
        get_scenario(environment.scenario).controller
    try:
        settings, notes = resimulation_settings(episode)
    except InvalidConfigError as err:
        print(f'error: cannot rebuild the simulator of {args.bag}: {err}', file=sys.stderr)
        return EXIT_ERROR
    if args.worker:
        namespace = args.worker
        notes.append(f'using the running worker {namespace} with its own settings, not the '
                     'recorded ones')
    elif args.external:
        namespace = args.namespace or episode.get('namespace') or '/'
    else:
        if controller not in CONTROLLERS:
            which = (f'--controller {controller!r} is' if args.controller else
                     f'{args.bag} was recorded with controller {controller!r}, which is')
            print(f'error: {which} not a built-in one ({", ".join(sorted(CONTROLLERS))}): '
                  'start your controller under a namespace and pass --external --namespace '
                  '<it>', file=sys.stderr)
            return EXIT_ERROR
        namespace = f'/replay_{os.getpid()}'
    action_name = f'{namespace.rstrip("/")}/evaluate'
    changed = settings.changed_from_defaults()
    if not args.worker and changed:
        print('re-simulating with the recorded settings: ' +
              ', '.join(f'{name}={value}' for name, value in sorted(changed.items())),
              file=sys.stderr)
    for note in notes:
        print(f'note: {note}', file=sys.stderr)
    log_directory = Path(tempfile.mkdtemp(prefix='sessgan-replay-'))
    with ProcessSupervisor(log_directory) as supervisor:
        init_rclpy()
        node = rclpy.create_node('sessgan_resimulate')
        try:
            if not args.worker:
                if args.external and action_present(node, action_name, wait=DISCOVERY_WAIT):
                    print(f'error: a simulator already serves {action_name}: stop it (the '
                          're-simulation starts one with the recorded settings there) or pass '
                          f'--worker {namespace} to use it as it is', file=sys.stderr)
                    return EXIT_ERROR
                start_resimulation_graph(supervisor, settings, namespace, log_directory,
                                         None if args.external else controller, worker_cores,
                                         str(episode.get('robot', '')), environment.robots)
            client = ActionClient(node, EvaluateEnvironment, action_name)
            if not client.wait_for_server(timeout_sec=60.0):
                logs = ''.join(child.log_tail(800) for child in supervisor.children)
                print(f'error: no simulator answers at {action_name}\n{logs}',
                      file=sys.stderr)
                return EXIT_ERROR
            goal = EvaluateEnvironment.Goal()
            goal.environment = environment_to_msg(environment)
            goal.seed = int(episode.get('episode_seed', environment.seed))
            goal.time_limit = float(episode.get('time_limit', 0.0))
            goal.robot = episode.get('robot', '')
            goal.controller = controller
            for attempt in range(DEFAULT_HARNESS_TRIES):
                send = client.send_goal_async(goal)
                spin_interruptibly(lambda: rclpy.spin_until_future_complete(node, send,
                                                                            timeout_sec=30.0))
                handle = send.result()
                if handle is None or not handle.accepted:
                    print('error: the simulator refused the goal', file=sys.stderr)
                    return EXIT_ERROR
                result_future = handle.get_result_async()
                spin_interruptibly(lambda: rclpy.spin_until_future_complete(
                    node, result_future, timeout_sec=args.timeout))
                if not result_future.done():
                    print(f'error: no result within {args.timeout} s', file=sys.stderr)
                    return EXIT_ERROR
                new = result_future.result().result.metrics
                if not is_harness_outcome(new.outcome):
                    break
                # The harness, not the controller, ended it (a controller slow to start on a
                # busy host, say): no result to compare, so run it again.
                if attempt + 1 < DEFAULT_HARNESS_TRIES:
                    print(f'note: try {attempt + 1} ended {new.outcome} ({new.detail}): the '
                          'harness, not the controller; running it again', file=sys.stderr)
            else:
                print(f'error: the harness, not the controller, ended every one of '
                      f'{DEFAULT_HARNESS_TRIES} tries (last: {new.outcome}: {new.detail}); '
                      'nothing to compare', file=sys.stderr)
                return EXIT_ERROR
        finally:
            node.destroy_node()
            rclpy.try_shutdown()
    print(f'{"":16} {"recorded":>18} {"re-simulated":>18}')
    for label, old, now in (
            ('outcome', recorded['outcome'], new.outcome),
            ('collisions', recorded['collisions'], new.collisions),
            ('fault collisions', recorded.get('fault_collisions', '-'), new.fault_collisions),
            ('risk score', f'{recorded["risk_score"]:.3f}', f'{new.risk_score:.3f}'),
            ('sim time', f'{recorded["simulation_time"]:.2f}', f'{new.simulation_time:.2f}'),
            ('travelled m', f'{recorded["distance_travelled"]:.3f}',
             f'{new.distance_travelled:.3f}'),
            ('ticks', recorded['ticks'], new.ticks),
            ('legs completed', f'{recorded.get("legs_completed", "-")}/'
                               f'{recorded.get("legs", 1)}',
             f'{new.legs_completed}/{new.legs}')):
        print(f'{label:16} {str(old):>18} {str(now):>18}')  # spaced: a long outcome
    same = (new.outcome == recorded['outcome']
            and int(new.collisions) == int(recorded['collisions']))
    failed = is_controller_failure(new)
    ok = same if args.expect == 'same' else not failed
    print('as expected' if ok else f'NOT as expected (--expect {args.expect})')
    return EXIT_AS_EXPECTED if ok else EXIT_DIFFERENT


DISCOVERY_WAIT = 5.0
"""Seconds to look for a simulator already serving the recorded namespace: discovery of a
running one took over 2 s on this 2-core machine with both cores busy."""


def action_present(node, name: str, wait: float) -> bool:
    """Whether discovery shows action server ``name`` within ``wait`` seconds."""
    from sessgan_evolver.ros_evaluator import EVALUATE_TYPE, served_actions

    deadline = time.monotonic() + wait
    while True:
        if name in served_actions(node, EVALUATE_TYPE):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.1)


def start_resimulation_graph(supervisor, settings, namespace: str, log_directory: Path,
                             controller: str | None, worker_cores, robot_model: str,
                             robots: int = 1) -> None:
    """A simulator with ``settings`` under ``namespace`` and, unless None, the built-in
    ``controller`` beside it (one per robot of a fleet; one core, batch scheduling, like a
    campaign's workers)."""
    import yaml

    from sessgan_evolver.process_supervisor import controller_placements

    params_file = log_directory / 'simulator_params.yaml'
    params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': settings.to_dict()}}))
    ros_args = ['--ros-args', '-r', f'__ns:={namespace}']
    core = worker_cores(1)[0]
    supervisor.start('simulator', ['ros2', 'run', 'sessgan_sim', 'simulator', *ros_args,
                                   '--params-file', str(params_file)], core=core, batch=True)
    if controller is not None:
        from sessgan_controllers.registry import CONTROLLERS

        stamped = ['-p', 'use_stamped_cmd_vel:=true'] if settings.use_stamped_cmd_vel else []
        spec = CONTROLLERS.get(controller)
        robot = spec.node_arguments(robot_model) if spec else []
        for index, (_, placement) in enumerate(controller_placements(namespace, robots)):
            supervisor.start(f'controller{index if robots > 1 else ""}', [
                'ros2', 'run', 'sessgan_controllers', controller, '--ros-args', *placement,
                '-p', 'use_sim_time:=true', *stamped, *robot], core=core, batch=True)


def main(argv=None) -> int:
    arguments = sys.argv[1:] if argv is None else argv
    # SIGINT and SIGTERM: 130 (run_command), except for a --loop replay, which ends so.
    return run_command(lambda: replay_or_resimulate(arguments))


def replay_or_resimulate(argv) -> int:
    args = parse_args(argv)
    from sessgan_core.errors import SessganCoreError
    from sessgan_evolver.bag_reading import (
        bag_directory,
        check_bag_complete,
        check_episode_fields,
        read_episode_json,
        verify_bag_files,
    )
    from sessgan_evolver.errors import SessganEvolverError
    from sessgan_gen.errors import SessganGenError

    try:
        episode = read_episode_json(args.bag)
        # Nothing is published or re-simulated from a bag that changed since it was written
        # (digests), or whose messages are cut off or corrupt (counts, MCAP chunk CRCs).
        warning = verify_bag_files(args.bag)
        if warning:
            print(f'warning: {warning}', file=sys.stderr)
        check_bag_complete(args.bag)
        if args.resimulate:
            if episode is None:
                print(f'error: {args.bag} has no episode.json to re-simulate', file=sys.stderr)
                return EXIT_ERROR
            check_episode_fields(episode, bag_directory(args.bag) / 'episode.json')
            return resimulate(args, episode)
        return replay(args, episode)
    except (SessganEvolverError, SessganCoreError, SessganGenError, OSError, KeyError,
            ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
        return EXIT_ERROR


if __name__ == '__main__':
    sys.exit(main())
