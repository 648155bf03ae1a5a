"""Start-up and shutdown of the simulator and generator nodes.

Both exit at once and cleanly on the first SIGINT or SIGTERM, idle or in an episode; an episode
cut off by the evaluate client or a shutdown is `cancelled` and leaves no failure bag; partial
bags of killed workers are removed when the simulator starts."""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest

from tests.graph.test_simulator_graph import (
    environment_msg,
    room,
    start_external,
    start_simulator,
)
from tests.ros_processes import spin_until
from tests.unit.evolver.killed_bag_writer import killed_writer_staging

pytestmark = pytest.mark.graph

EXIT_WITHIN = 5.0
"""Wall seconds a node may take to exit after the first signal."""


def assert_exits_cleanly(process, signum: int) -> float:
    """Send ``signum`` to the node's process group; assert a clean exit within EXIT_WITHIN
    seconds; returns the seconds it took."""
    sent = time.monotonic()
    process.process.send_signal(signum)  # the node itself: `ros2 run` execs it
    try:
        code = process.wait(timeout=EXIT_WITHIN)
    except subprocess.TimeoutExpired:
        pytest.fail(f'{process.name} still running {EXIT_WITHIN} s after '
                    f'{signal.Signals(signum).name}; log:\n{process.output()[-3000:]}')
    took = time.monotonic() - sent
    output = process.output()
    assert code == 0, f'exit status {code} after {signal.Signals(signum).name}:\n{output[-3000:]}'
    assert 'Traceback' not in output and 'RCLError' not in output, output[-3000:]
    print(f'{process.name} exited {took:.2f} s after {signal.Signals(signum).name}')
    return took


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_idle_simulator_exits_on_first_signal(node_processes, signum):
    for attempt in range(3):
        simulator = start_simulator(node_processes, f'/quit{attempt}')
        time.sleep(0.3 * attempt)  # idle for a while, or signalled right after start-up
        assert_exits_cleanly(simulator, signum)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_idle_generator_exits_on_first_signal(node_processes, signum):
    for attempt in range(3):
        generator = node_processes.start(
            ['ros2', 'run', 'sessgan_gen', 'generator', '--ros-args', '-r',
             f'__ns:=/gen_quit{attempt}'], name=f'generator{attempt}')
        generator.wait_for_output('published environment', timeout=60)
        time.sleep(0.3 * attempt)
        assert_exits_cleanly(generator, signum)


def start_episode(ros_node, namespace: str, environment, record_directory: str):
    """Send an evaluate goal; returns (client, goal handle, feedback list)."""
    from rclpy.action import ActionClient

    from sessgan_interfaces.action import EvaluateEnvironment

    client = ActionClient(ros_node, EvaluateEnvironment, f'{namespace}/evaluate')
    assert client.wait_for_server(timeout_sec=30)
    feedback = []
    goal = EvaluateEnvironment.Goal(environment=environment, seed=1, controller='test',
                                    record_directory=record_directory)
    send = client.send_goal_async(goal, feedback_callback=lambda f: feedback.append(f.feedback))
    assert spin_until(ros_node, send.done, timeout=30)
    handle = send.result()
    assert handle.accepted
    return client, handle, feedback


def start_blind_robot(node_processes, namespace: str, bags_root):
    """A clocked worker (real time, so an episode can be cut off midway) and a controller that
    drives straight into the wall: a controller failure in a valid test once it hits."""
    simulator = start_simulator(node_processes, namespace, 'dummy_agents:=0', 'mode:=clocked',
                                f'bags_root:={bags_root}')
    start_external(node_processes, namespace, '--blind')
    return simulator


def test_cancelled_episode_is_reported_and_leaves_no_bag(node_processes, ros_node, tmp_path):
    from action_msgs.msg import GoalStatus

    start_blind_robot(node_processes, '/cancel', tmp_path)
    bags = tmp_path / 'bags'
    _, handle, feedback = start_episode(ros_node, '/cancel', environment_msg(
        room(), 'factory', 'room'), 'bags')
    # Cancel once it has hit the wall (the episode would be a failure).
    assert spin_until(ros_node, lambda: feedback and feedback[-1].collisions > 0, timeout=90), \
        'no collision reported before the cancel'
    cancel = handle.cancel_goal_async()
    assert spin_until(ros_node, cancel.done, timeout=10)
    result = handle.get_result_async()
    assert spin_until(ros_node, result.done, timeout=20)
    assert result.result().status == GoalStatus.STATUS_CANCELED
    metrics = result.result().result.metrics
    assert metrics.outcome == 'cancelled', metrics.detail
    assert metrics.fault_collisions > 0 and metrics.feasible
    assert metrics.bag_path == ''
    assert not bags.exists() or not any(bags.iterdir()), list(bags.iterdir())


def test_simulator_signalled_mid_episode_exits_and_writes_no_bag(node_processes, ros_node,
                                                                 tmp_path):
    simulator = start_blind_robot(node_processes, '/midquit', tmp_path)
    bags = tmp_path / 'bags'
    _, _, feedback = start_episode(ros_node, '/midquit', environment_msg(
        room(), 'factory', 'room'), 'bags')
    assert spin_until(ros_node, lambda: feedback and feedback[-1].collisions > 0, timeout=90), \
        'no collision reported before the signal'
    assert_exits_cleanly(simulator, signal.SIGINT)
    assert 'episode room: cancelled' in simulator.output(), simulator.output()[-3000:]
    assert not bags.exists() or not any(bags.iterdir()), list(bags.iterdir())


def test_simulator_removes_partial_bags_of_killed_workers_at_start_up(node_processes, tmp_path):
    bags = tmp_path / 'bags'
    bags.mkdir()
    stale = killed_writer_staging(bags)  # a writer killed mid-bag: its marked staging directory
    # Named like a dead writer's staging directory, but without its marker (issue 19: it was
    # deleted): kept, as is what a live writer stages and a finished bag.
    victim = bags / f'victim.tmp-{2**22 + 12345}'
    victim.mkdir()
    (victim / 'precious.txt').write_text('keep me')
    live = bags / f'g000-m02-s5.tmp-{os.getpid()}'
    live.mkdir()
    kept = bags / 'g000-m03-s5'
    kept.mkdir()
    simulator = start_simulator(node_processes, '/cleanup', f'bags_root:={tmp_path}',
                                'record_directory:=bags')
    assert not stale.exists(), simulator.output()
    assert live.exists() and kept.exists()
    assert (victim / 'precious.txt').read_text() == 'keep me'
    assert 'removed a partial bag' in simulator.output()
