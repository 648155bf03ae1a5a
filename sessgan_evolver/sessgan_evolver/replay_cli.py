"""`ros2 run sessgan_evolver replay <bag>`: replay a failure bag, or re-simulate it.

Replay republishes every recorded message with its recorded timing (scaled by ``--rate``),
including ``/clock``, for RViz or any subscriber. Topics recorded under a worker namespace
(``/w0/scan``) are republished under ``--namespace`` (default: the root, ``/scan``).

``--resimulate`` runs the bag's map, start, goal and seed again through a simulator worker and
its controller and compares the outcome with the recorded one. Exit codes: 0 as expected
(``--expect same``: same outcome and collision count; ``--expect pass``: no failure any more),
1 not as expected, 2 on an error (unreadable bag, no worker).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import tempfile
import time
from pathlib import Path

EXIT_AS_EXPECTED, EXIT_DIFFERENT, EXIT_ERROR = 0, 1, 2


def parse_args(argv):
    parser = argparse.ArgumentParser(prog='ros2 run sessgan_evolver replay', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='failure bag directory (bags/<run>/<episode>)')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed factor (replay; default 1.0 = recorded timing)')
    parser.add_argument('--namespace', default='/',
                        help='namespace to republish under (replay; default /)')
    parser.add_argument('--loop', action='store_true', help='replay until interrupted')
    parser.add_argument('--resimulate', action='store_true',
                        help="run the bag's map again against a live controller and compare")
    parser.add_argument('--worker', default='',
                        help='namespace of a running simulator worker to use (e.g. /w0); '
                             'default: start a simulator and the recorded built-in controller')
    parser.add_argument('--controller', default='',
                        help='built-in controller to start (default: the recorded one)')
    parser.add_argument('--expect', choices=('same', 'pass'), default='same',
                        help='same: the failure must reproduce; pass: it must be gone')
    parser.add_argument('--timeout', type=float, default=300.0,
                        help='wall seconds to wait for the re-simulated episode')
    args = parser.parse_args(argv)
    if not args.rate > 0:
        parser.error('--rate must be positive')
    return args


def message_class(msgtype: str):
    """The rclpy message class of 'pkg/msg/Name'."""
    package, kind, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def republished_topic(topic: str, recorded_namespace: str, namespace: str) -> str:
    recorded_namespace = recorded_namespace.rstrip('/')
    if recorded_namespace and topic.startswith(recorded_namespace + '/'):
        topic = topic[len(recorded_namespace):]
    return namespace.rstrip('/') + topic


def replay(args, episode) -> int:
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from sessgan_evolver.bag_reading import iter_bag_messages, read_bag_topics

    topics = read_bag_topics(args.bag)
    recorded_namespace = (episode or {}).get('namespace', '')
    rclpy.init()
    node = rclpy.create_node('sessgan_replay')
    try:
        publishers = {}
        for topic in topics:
            latched = topic.durability == 'transient_local'
            qos = QoSProfile(
                depth=max(1, topic.depth or 10), reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                else DurabilityPolicy.VOLATILE)
            name = republished_topic(topic.topic, recorded_namespace, args.namespace)
            publishers[topic.topic] = node.create_publisher(
                message_class(topic.msgtype), name, qos)
        total = sum(topic.message_count for topic in topics)
        node.get_logger().info(f'replaying {total} messages of {args.bag} at rate {args.rate}')
        time.sleep(0.5)  # let subscribers match before the first message
        while True:
            wall_start = time.monotonic()
            first_ns = None
            count = 0
            for message in iter_bag_messages(args.bag):
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
        return EXIT_AS_EXPECTED
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def bag_environment(bag: Path, episode: dict):
    from sessgan_gen.environment import Environment, Pose2D
    from sessgan_gen.map_server_io import read_map_server

    occupancy, resolution, origin = read_map_server(bag / 'map.yaml')
    return Environment(
        id=episode['environment_id'], scenario=episode['scenario'], occupancy=occupancy,
        resolution=resolution, origin=(origin[0], origin[1]), start=Pose2D(*episode['start']),
        goal=Pose2D(*episode['goal']), seed=int(episode.get('seed', 0)),
        generation=int(episode.get('generation', -1)), member=int(episode.get('member', -1)),
        feasible=bool(episode.get('feasible', True)),
        route_length=float(episode.get('route_length', 0.0)),
        route_min_clearance=float(episode.get('route_min_clearance', 0.0)))


def resimulate(args, episode: dict) -> int:
    import rclpy
    from rclpy.action import ActionClient

    from sessgan_evolver.process_supervisor import ProcessSupervisor, worker_cores
    from sessgan_gen.ros_conversion import environment_to_msg
    from sessgan_gen.scenarios import get_scenario
    from sessgan_interfaces.action import EvaluateEnvironment
    from sessgan_sim.metrics import is_controller_failure

    environment = bag_environment(args.bag, episode)
    recorded = episode['metrics']
    namespace = args.worker or f'/replay_{os.getpid()}'
    controller = args.controller or episode.get('controller') or \
        get_scenario(environment.scenario).controller
    with ProcessSupervisor(Path(tempfile.mkdtemp(prefix='sessgan-replay-'))) as supervisor:
        if not args.worker:
            ros_args = ['--ros-args', '-r', f'__ns:={namespace}']
            core = worker_cores(1)[0]
            supervisor.start('simulator', ['ros2', 'run', 'sessgan_sim', 'simulator', *ros_args],
                             core=core, batch=True)
            supervisor.start('controller', ['ros2', 'run', 'sessgan_controllers', controller,
                                            *ros_args, '-p', 'use_sim_time:=true'],
                             core=core, batch=True)
        rclpy.init()
        node = rclpy.create_node('sessgan_resimulate')
        try:
            client = ActionClient(node, EvaluateEnvironment, f'{namespace}/evaluate')
            if not client.wait_for_server(timeout_sec=60.0):
                logs = ''.join(child.log_tail(800) for child in supervisor.children)
                print(f'error: no simulator answers at {namespace}/evaluate\n{logs}',
                      file=sys.stderr)
                return EXIT_ERROR
            goal = EvaluateEnvironment.Goal()
            goal.environment = environment_to_msg(environment)
            goal.seed = int(episode.get('episode_seed', environment.seed))
            goal.time_limit = float(episode.get('time_limit', 0.0))
            goal.robot = episode.get('robot', '')
            goal.controller = controller
            send = client.send_goal_async(goal)
            rclpy.spin_until_future_complete(node, send, timeout_sec=30.0)
            handle = send.result()
            if handle is None or not handle.accepted:
                print('error: the simulator refused the goal', file=sys.stderr)
                return EXIT_ERROR
            result_future = handle.get_result_async()
            rclpy.spin_until_future_complete(node, result_future, timeout_sec=args.timeout)
            if not result_future.done():
                print(f'error: no result within {args.timeout} s', file=sys.stderr)
                return EXIT_ERROR
            new = result_future.result().result.metrics
        finally:
            node.destroy_node()
            rclpy.try_shutdown()
    print(f'{"":12}{"recorded":>18}{"re-simulated":>18}')
    for label, old, now in (('outcome', recorded['outcome'], new.outcome),
                            ('collisions', recorded['collisions'], new.collisions),
                            ('risk score', f'{recorded["risk_score"]:.3f}',
                             f'{new.risk_score:.3f}'),
                            ('sim time', f'{recorded["simulation_time"]:.2f}',
                             f'{new.simulation_time:.2f}')):
        print(f'{label:12}{str(old):>18}{str(now):>18}')
    same = (new.outcome == recorded['outcome']
            and int(new.collisions) == int(recorded['collisions']))
    failed = is_controller_failure(new)
    ok = same if args.expect == 'same' else not failed
    print('as expected' if ok else f'NOT as expected (--expect {args.expect})')
    return EXIT_AS_EXPECTED if ok else EXIT_DIFFERENT


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    from sessgan_evolver.bag_reading import read_episode_json
    from sessgan_evolver.errors import SessganEvolverError

    try:
        episode = read_episode_json(args.bag)
        if args.resimulate:
            if episode is None:
                print(f'error: {args.bag} has no episode.json to re-simulate', file=sys.stderr)
                return EXIT_ERROR
            return resimulate(args, episode)
        return replay(args, episode)
    except (SessganEvolverError, OSError, KeyError, ValueError) as err:
        print(f'error: {err}', file=sys.stderr)
        return EXIT_ERROR


if __name__ == '__main__':
    sys.exit(main())
