"""The simulator worker and controllers as separate processes, driven through `evaluate`."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from tests.ros_processes import spin_until

pytestmark = pytest.mark.graph

EXTERNAL_CONTROLLER = Path(__file__).with_name('external_controller.py')
ROUTE_FOLLOWER = Path(__file__).with_name('route_follower.py')
DOG_LEG_MAP = Path(__file__).parents[1] / 'data' / 'narrow_dog_leg.txt'


def room(size: int = 16) -> np.ndarray:
    """A factory token map: an empty room with a wall around it."""
    cells = np.zeros((size, size), dtype=np.int64)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 1
    return cells


def start_simulator(node_processes, namespace: str, *parameters: str):
    command = ['ros2', 'run', 'sessgan_sim', 'simulator', '--ros-args', '-r',
               f'__ns:={namespace}']
    for parameter in parameters:
        command += ['-p', parameter]
    process = node_processes.start(command, name=f'simulator{namespace.replace("/", "_")}')
    process.wait_for_output('simulator ready', timeout=60)
    return process


def start_controller(node_processes, namespace: str, name: str, *parameters: str):
    """A built-in controller under ``namespace``; ``parameters`` as 'name:=value'."""
    settings = [arg for parameter in parameters for arg in ('-p', parameter)]
    return node_processes.start(
        ['ros2', 'run', 'sessgan_controllers', name, '--ros-args', '-r', f'__ns:={namespace}',
         '-p', 'use_sim_time:=true', *settings], name=f'{name}{namespace.replace("/", "_")}')


def start_external(node_processes, namespace: str, *behaviour: str, name: str = ''):
    """tests/graph/external_controller.py under ``namespace`` on sim time; ``behaviour``: its
    flags ('--blind', '--stall', ...; none: it drives to the goal)."""
    return node_processes.start(
        [sys.executable, str(EXTERNAL_CONTROLLER), *behaviour, '--ros-args', '-r',
         f'__ns:={namespace}', '-p', 'use_sim_time:=true'],
        name=name or 'external' + ''.join(behaviour) + namespace.replace('/', '_'))


def evaluate(ros_node, namespace: str, environment_msg, time_limit: float = 0.0, seed: int = 1,
             timeout: float = 120.0, record_directory: str = '',
             real_time_factor_scale: float = 0.0):
    from rclpy.action import ActionClient

    from sessgan_interfaces.action import EvaluateEnvironment

    client = ActionClient(ros_node, EvaluateEnvironment, f'{namespace}/evaluate')
    assert client.wait_for_server(timeout_sec=30), f'no action server at {namespace}/evaluate'
    goal = EvaluateEnvironment.Goal(environment=environment_msg, time_limit=time_limit, seed=seed,
                                    record_directory=record_directory, controller='test',
                                    real_time_factor_scale=real_time_factor_scale)
    feedback = []
    send = client.send_goal_async(goal, feedback_callback=feedback.append)
    assert spin_until(ros_node, send.done, timeout=30), 'goal not answered'
    handle = send.result()
    assert handle.accepted
    result = handle.get_result_async()
    assert spin_until(ros_node, result.done, timeout=timeout), 'no result in time'
    client.destroy()
    return result.result().result.metrics, feedback


def evaluate_with_reruns(ros_node, namespace: str, environment_msg, tries: int = 3,
                         rerun: tuple[str, ...] = ('overloaded',), **options):
    """``evaluate`` with the harness's re-run rule for the harness outcomes ``rerun`` (default:
    an overloaded episode of a clocked worker: on a busy machine the stack may not keep pace
    with sim time: no result, run again at half the pace, as campaigns do with --adaptive-rtf;
    sessgan_evolver.harness). Returns the metrics and feedback of the first try whose outcome
    is not in ``rerun`` and the number of tries; HarnessFailureError when every try's is.
    Other outcomes are the test's to judge."""
    from sessgan_evolver.harness import HarnessRetries

    retries = HarnessRetries(tries, print, adaptive_rtf=True)
    for attempt in range(1, tries + 1):
        metrics, feedback = evaluate(
            ros_node, namespace, environment_msg,
            real_time_factor_scale=retries.real_time_factor_scale(namespace), **options)
        if metrics.outcome not in rerun:
            return metrics, feedback, attempt
        retries.failed(namespace, environment_msg.id, metrics.outcome, metrics.detail)
    raise AssertionError('unreachable: HarnessRetries raises on the last overloaded try')


def environment_msg(cells, scenario: str, env_id: str):
    from sessgan_core.ros_conversion import environment_to_msg
    from sessgan_core.valid_tests import make_environment

    return environment_to_msg(make_environment(cells, scenario, env_id))


def test_external_controller_drives_robot_to_goal(node_processes, ros_node):
    start_simulator(node_processes, '/ext', 'dummy_agents:=0')
    start_external(node_processes, '/ext')
    metrics, feedback = evaluate(ros_node, '/ext', environment_msg(room(), 'factory', 'room'),
                                 time_limit=60.0)
    assert metrics.outcome == 'goal_reached', metrics.detail
    assert metrics.collisions == 0
    assert metrics.simulation_time > 1.0
    assert feedback, 'the action gave no feedback'


def test_bad_input_gets_clear_results_and_node_keeps_serving(node_processes, ros_node, tmp_path):
    start_simulator(node_processes, '/bad', 'dummy_agents:=0', 'controller_startup_timeout:=2.0',
                    'controller_timeout:=1.0')
    good = environment_msg(room(), 'factory', 'room')

    mismatched = environment_msg(room(), 'factory', 'mismatch')
    mismatched.map.info.width = 99
    metrics, _ = evaluate(ros_node, '/bad', mismatched)
    assert metrics.outcome == 'invalid_environment' and '99' in metrics.detail

    bad_resolution = environment_msg(room(), 'factory', 'resolution')
    bad_resolution.map.info.resolution = float('nan')
    metrics, _ = evaluate(ros_node, '/bad', bad_resolution)
    assert metrics.outcome == 'invalid_environment' and 'resolution' in metrics.detail

    in_wall = environment_msg(room(), 'factory', 'start-in-wall')
    in_wall.start.position.x = in_wall.start.position.y = 0.25  # the corner wall cell
    metrics, _ = evaluate(ros_node, '/bad', in_wall)
    assert metrics.outcome == 'invalid_environment', metrics.detail

    # More cells than a simulator accepts: refused before anything is built.
    huge = environment_msg(room(), 'factory', 'huge')
    huge.map.info.width, huge.map.info.height = 2048, 1024
    huge.map.data = bytes(2048 * 1024)
    metrics, _ = evaluate(ros_node, '/bad', huge, timeout=30)
    assert metrics.outcome == 'invalid_environment'
    assert '2,097,152 cells, more than the 1,048,576' in metrics.detail, metrics.detail

    unknown = environment_msg(room(), 'factory', 'moon')
    unknown.scenario = 'moon'
    metrics, _ = evaluate(ros_node, '/bad', unknown)
    assert metrics.outcome == 'invalid_environment' and 'moon' in metrics.detail

    # No controller at all: the episode ends, it never hangs.
    metrics, _ = evaluate(ros_node, '/bad', good, timeout=30)
    assert metrics.outcome == 'controller_unresponsive', metrics.detail

    # A controller spewing NaN: its commands become stops and are counted.
    node_processes.start([sys.executable, str(EXTERNAL_CONTROLLER), '--nan', '--ros-args', '-r',
                          '__ns:=/bad'], name='nan_controller')
    assert spin_until(ros_node, lambda: ros_node.count_publishers('/bad/cmd_vel') > 0, 30)
    # The simulator may discover the new controller later than this node did (a CI run under
    # load: over its 2 s start-up window); that is the harness outcome a campaign re-runs.
    metrics, _, _ = evaluate_with_reruns(ros_node, '/bad', good, tries=5, time_limit=3.0,
                                         rerun=('controller_unresponsive',))
    assert metrics.outcome in ('timeout', 'stuck'), metrics.detail
    assert 'NaN' in metrics.detail
    assert metrics.distance_travelled < 0.05


def test_unsafe_environment_ids_are_refused_and_touch_no_files(node_processes, ros_node,
                                                               tmp_path):
    """Ids name bag directories: '../victim', an absolute path and '' are invalid_environment,
    and no file under the record directory or beside it changes."""
    files = tmp_path / 'files'  # tmp_path itself holds the processes' logs
    record = files / 'bags' / 'run'
    (record / 'earlier').mkdir(parents=True)
    (record / 'earlier' / 'episode.json').write_text('{}')
    victim = files / 'bags' / 'victim'
    victim.mkdir()
    (victim / 'precious.txt').write_text('keep me')
    outside = files / 'outside'
    outside.mkdir()

    def snapshot():
        return sorted((str(path), path.read_bytes() if path.is_file() else b'')
                      for path in files.rglob('*'))

    before = snapshot()
    start_simulator(node_processes, '/ids', 'dummy_agents:=0', 'controller_startup_timeout:=2.0',
                    f'bags_root:={files / "bags"}')
    for unsafe in ('../victim', str(outside), ''):
        metrics, _ = evaluate(ros_node, '/ids', environment_msg(room(), 'factory', unsafe),
                              record_directory='run', timeout=30)
        assert metrics.outcome == 'invalid_environment', (unsafe, metrics.outcome)
        assert 'environment id' in metrics.detail, metrics.detail
        assert not metrics.bag_path
    assert snapshot() == before


def test_a_client_cannot_write_or_delete_outside_the_bags_root(node_processes, ros_node,
                                                              tmp_path):
    """Issue 19: a goal's record_directory '/…/outside' made the simulator write a bag there
    and delete a foreign 'victim.tmp-999999/'. Now absolute and escaping record directories
    are refused (harness_error: the goal's fault, never a result; nothing runs), and inside
    the root only a killed
    writer's marked staging directory is removed, never an unmarked one."""
    from tests.unit.evolver.killed_bag_writer import killed_writer_staging

    files = tmp_path / 'files'  # tmp_path itself holds the processes' logs
    root = files / 'root'
    outside = files / 'outside'
    for directory in (outside, root / 'run'):
        victim = directory / 'victim.tmp-999999'
        victim.mkdir(parents=True)
        (victim / 'precious.txt').write_text('keep me')
    stale = killed_writer_staging(root / 'run')

    def snapshot():
        return sorted((str(path), path.read_bytes() if path.is_file() else b'')
                      for path in files.rglob('*'))

    before = snapshot()
    start_simulator(node_processes, '/rooted', 'dummy_agents:=0', f'bags_root:={root}')
    start_external(node_processes, '/rooted', '--blind')
    for unsafe in (str(outside), '../outside', 'run/../../outside', str(root / 'run')):
        metrics, _ = evaluate(ros_node, '/rooted', environment_msg(room(), 'factory', 'room'),
                              record_directory=unsafe, time_limit=20.0, timeout=30)
        assert metrics.outcome == 'harness_error', (unsafe, metrics.outcome)
        assert 'refusing the goal' in metrics.detail and 'bags root' in metrics.detail, \
            metrics.detail
        assert not metrics.bag_path and metrics.ticks == 0
    assert snapshot() == before
    # The same episode with a subdirectory of the root: a failure, recorded there.
    metrics, _ = evaluate(ros_node, '/rooted', environment_msg(room(), 'factory', 'room'),
                          record_directory='run', time_limit=20.0)
    assert metrics.fault_collisions > 0 and metrics.bag_path == str(root / 'run' / 'room'), \
        (metrics.outcome, metrics.detail, metrics.bag_path)
    after = snapshot()
    assert not stale.exists()  # the killed writer's partial bag
    assert [entry for entry in after
            if not entry[0].startswith(str(root / 'run' / 'room'))] == [
        entry for entry in before if not entry[0].startswith(str(stale))]


@pytest.mark.parametrize('scenario, controller', [
    ('factory', 'nearness_diagram'),
    ('drone', 'velocity_projection'),
    ('racetrack', 'race_controller'),
])
def test_builtin_controller_reaches_goal_on_example_map(node_processes, ros_node, scenario,
                                                        controller):
    from sessgan_core.token_map import load_example_map

    namespace = f'/ex_{scenario}'
    start_simulator(node_processes, namespace)
    start_controller(node_processes, namespace, controller)
    metrics, _ = evaluate(ros_node, namespace, environment_msg(
        load_example_map(scenario).cells, scenario, f'{scenario}-example'), timeout=300)
    assert metrics.outcome == 'goal_reached', (metrics.outcome, metrics.detail)
    assert metrics.feasible


def test_a_failure_in_a_valid_test_leaves_a_complete_bag(node_processes, ros_node, tmp_path):
    from sessgan_evolver.bag_reading import read_episode_bag

    start_simulator(node_processes, '/blind', 'dummy_agents:=0', f'bags_root:={tmp_path}')
    start_external(node_processes, '/blind', '--blind')
    metrics, _ = evaluate(ros_node, '/blind', environment_msg(room(), 'factory', 'room'),
                          record_directory='bags', time_limit=20.0)
    assert metrics.feasible
    assert metrics.fault_collisions > 0 and metrics.static_collisions > 0, metrics.detail
    assert metrics.bag_path, 'a controller failure in a valid test is recorded'
    bag = read_episode_bag(metrics.bag_path)
    assert bag.episode['metrics']['fault_collisions'] == metrics.fault_collisions
    assert bag.episode['route_min_clearance'] >= 0.3
    recorded = {topic.topic.rsplit('/', 1)[-1] for topic in bag.topics}
    assert {'map', 'goal_pose', 'scan', 'odom', 'tf', 'tf_static', 'clock', 'cmd_vel'} <= recorded
    counts = {t.topic.rsplit('/', 1)[-1]: t.message_count for t in bag.topics}
    assert counts['cmd_vel'] == metrics.ticks, 'every command of the episode is recorded'


def test_collisions_in_an_invalid_test_are_not_recorded_as_failures(node_processes, ros_node,
                                                                    tmp_path):
    from sessgan_core.token_map import read_token_map

    # A 0.5 m zig-zag corridor leaves the 0.4 m robot 5 cm per side: no certified route.
    start_simulator(node_processes, '/dogleg', 'dummy_agents:=0', f'bags_root:={tmp_path}')
    # Without its protective field (which stops it short of the corner ahead), as the
    # reference implementation of Nearness-Diagram drives.
    start_controller(node_processes, '/dogleg', 'nearness_diagram', 'braking_deceleration:=0.0')
    cells = read_token_map(DOG_LEG_MAP, 'factory').cells
    msg = environment_msg(cells, 'factory', 'dogleg')
    assert not msg.feasible
    # Drive it from the start room anyway: the robot hits the corridor's corners.
    msg.start.position.x, msg.start.position.y = 1.25, 14.25
    msg.goal.position.x, msg.goal.position.y = 6.75, 8.25
    metrics, _ = evaluate(ros_node, '/dogleg', msg, record_directory='bags',
                          timeout=300)
    assert not metrics.feasible
    assert metrics.collisions > 0, (metrics.outcome, metrics.detail)
    assert metrics.bag_path == '' and not (tmp_path / 'bags' / 'dogleg').exists()


def test_a_route_follower_reaches_the_goal_of_a_certified_map(node_processes, ros_node):
    from sessgan_core.ros_conversion import environment_to_msg
    from sessgan_gen.environment_sampler import EnvironmentSampler

    start_simulator(node_processes, '/route', 'dummy_agents:=0')
    node_processes.start([sys.executable, str(ROUTE_FOLLOWER), '--ros-args', '-r',
                          '__ns:=/route', '-p', 'use_sim_time:=true'], name='route_follower')
    environment = EnvironmentSampler().sample([424242], scenario='factory')[0]
    assert environment.feasible and environment.route_length > 4.0
    metrics, _ = evaluate(ros_node, '/route', environment_to_msg(environment), timeout=300)
    assert metrics.outcome == 'goal_reached', (metrics.outcome, metrics.detail)
    assert metrics.fault_collisions == 0
