"""Clocked mode with a timer-driven controller (a Nav2 stand-in), goals for late subscribers,
free mode and the validation of the stepping mode, each with the simulator as a process."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

from tests.graph.test_simulator_graph import (
    environment_msg,
    evaluate_with_reruns,
    room,
    start_external,
    start_simulator,
)
from tests.ros_processes import spin_until

pytestmark = pytest.mark.graph

NAV2_STAND_IN = Path(__file__).with_name('nav2_stand_in.py')
STACK_REMAPS = ('-r', '/clock:=clock', '-r', '/tf:=tf', '-r', '/tf_static:=tf_static')
"""What a namespaced stack with sim-time timers and tf needs (Nav2's launch file does the same)."""


def start_stand_in(node_processes, namespace: str, *options: str):
    process = node_processes.start(
        [sys.executable, str(NAV2_STAND_IN), *options, '--ros-args', '-r', f'__ns:={namespace}',
         *STACK_REMAPS, '-p', 'use_sim_time:=true'],
        name=f'nav2_stand_in{namespace.replace("/", "_")}')
    process.wait_for_output('stand-in ready', timeout=30)
    return process


def count_messages(ros_node, topic: str, msg_type) -> list:
    """Every message received on ``topic`` from now on (while the node is spun), once a
    publisher has matched (a reliable writer drops what it sent before the match)."""
    received: list = []
    subscription = ros_node.create_subscription(msg_type, topic, received.append, 100)
    assert spin_until(ros_node, lambda: subscription.get_publisher_count() > 0, timeout=20), (
        f'no publisher of {topic} matched')
    return received


@pytest.mark.parametrize('stamped, real_time_factor', [(False, 4.0), (True, 2.0)],
                         ids=['twist', 'twist_stamped'])
def test_timer_driven_controller_reaches_goal_in_clocked_mode(node_processes, ros_node, stamped,
                                                              real_time_factor):
    from geometry_msgs.msg import Twist, TwistStamped

    namespace = '/clk_stamped' if stamped else '/clk_twist'
    parameters = ['dummy_agents:=0', 'mode:=clocked', f'real_time_factor:={real_time_factor}']
    if stamped:
        parameters.append('use_stamped_cmd_vel:=true')
    start_simulator(node_processes, namespace, *parameters)
    stand_in = start_stand_in(node_processes, namespace, *(['--stamped'] if stamped else []))
    commands = count_messages(ros_node, f'{namespace}/cmd_vel',
                              TwistStamped if stamped else Twist)
    metrics, feedback, _ = evaluate_with_reruns(
        ros_node, namespace, environment_msg(room(), 'factory', 'room'), time_limit=60.0)
    assert metrics.outcome == 'goal_reached', metrics.detail
    assert metrics.collisions == 0 and metrics.simulation_time > 2.0
    assert feedback
    # The controller's timer runs on sim time: 20 commands per sim second whatever the
    # real-time factor (a wall-clock timer would give 20 / real_time_factor). Counted where
    # they are sent: this test process need not keep up with them.
    sent, sim_time = re.findall(r'(\d+) commands sent by sim time ([\d.]+)', stand_in.output())[-1]
    assert 18.0 < int(sent) / float(sim_time) < 22.0, (sent, sim_time)
    assert 'jumped back' not in stand_in.output()
    assert commands, 'no cmd_vel seen by a third reader'
    if stamped:
        assert all(c.header.frame_id == 'base_footprint' for c in commands)


def test_a_stack_publishing_the_other_command_type_is_named(node_processes, ros_node):
    """ROS 2 matches no Twist reader to a TwistStamped writer and says nothing: the worker
    names the type it sees and the option that fixes it (a harness outcome, never a result)."""
    from tests.graph.test_simulator_graph import evaluate

    namespace = '/mistyped'
    start_simulator(node_processes, namespace, 'dummy_agents:=0',
                    'controller_startup_timeout:=8.0')
    start_stand_in(node_processes, namespace, '--stamped')  # the worker reads Twist
    # The stand-in's writer in the graph before the start-up wait begins (a loaded machine
    # took over 3 s to discover it).
    assert spin_until(ros_node, lambda: ros_node.get_publishers_info_by_topic(
        f'{namespace}/cmd_vel'), timeout=60), 'the stand-in never advertised cmd_vel'
    metrics, _ = evaluate(ros_node, namespace, environment_msg(room(), 'factory', 'room'))
    assert metrics.outcome == 'controller_unresponsive', metrics.detail
    assert ('cmd_vel is published as geometry_msgs/msg/TwistStamped' in metrics.detail
            and 'use_stamped_cmd_vel:=true' in metrics.detail), metrics.detail


def test_a_stack_in_another_namespace_is_named(node_processes, ros_node):
    """A controller started under another namespace than the worker's: the worker names the
    cmd_vel that has a writer and the one it reads (a harness outcome, never a result)."""
    from tests.graph.test_simulator_graph import evaluate

    start_simulator(node_processes, '/here', 'dummy_agents:=0',
                    'controller_startup_timeout:=8.0')
    start_stand_in(node_processes, '/there')
    assert spin_until(ros_node, lambda: ros_node.get_publishers_info_by_topic(
        '/there/cmd_vel'), timeout=60), 'the stand-in never advertised cmd_vel'
    metrics, _ = evaluate(ros_node, '/here', environment_msg(room(), 'factory', 'room'))
    assert metrics.outcome == 'controller_unresponsive', metrics.detail
    # Other tests' stand-ins may linger in the graph a moment: /there's is among those named.
    assert ('nothing publishes /here/cmd_vel, but ' in metrics.detail
            and '/there/cmd_vel' in metrics.detail.split('but ', 1)[1]
            and '-r __ns:=' in metrics.detail), metrics.detail


@pytest.mark.parametrize('mode', ['lockstep', 'clocked'])
def test_goal_reaches_subscribers_that_join_during_the_episode(node_processes, ros_node, mode):
    from geometry_msgs.msg import PoseStamped
    from rclpy.action import ActionClient
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from sessgan_interfaces.action import EvaluateEnvironment

    namespace = f'/late_{mode}'
    # A controller that never answers holds a lockstep episode at its first tick for the
    # start-up timeout; in clocked mode the episode runs on meanwhile, here at 4x real time,
    # so the stuck rule (10 sim s) would end it in 2.5 wall s if the wait were judged: a
    # robot that never got a command must end controller_unresponsive, never stuck.
    start_simulator(node_processes, namespace, 'dummy_agents:=0', f'mode:={mode}',
                    'controller_startup_timeout:=8.0', 'real_time_factor:=4.0')
    start_stand_in(node_processes, namespace, '--silent')
    environment = environment_msg(room(), 'factory', 'late')
    client = ActionClient(ros_node, EvaluateEnvironment, f'{namespace}/evaluate')
    assert client.wait_for_server(timeout_sec=30)
    reliable = ReliabilityPolicy.RELIABLE
    # A reader there from the start: once it has the goal, the episode runs and the goal is
    # out, so the two readers below join late.
    early: list = []
    probe = ros_node.create_subscription(PoseStamped, f'{namespace}/goal_pose', early.append,
                                         QoSProfile(depth=1, reliability=reliable))
    assert spin_until(ros_node, lambda: probe.get_publisher_count() > 0, timeout=20)
    sent = client.send_goal_async(EvaluateEnvironment.Goal(environment=environment, seed=1))
    assert spin_until(ros_node, sent.done, timeout=30) and sent.result().accepted
    assert spin_until(ros_node, lambda: early, timeout=30), 'the episode never sent its goal'

    latched, volatile = [], []
    ros_node.create_subscription(PoseStamped, f'{namespace}/goal_pose', latched.append,
                                 QoSProfile(depth=1, reliability=reliable,
                                            durability=DurabilityPolicy.TRANSIENT_LOCAL))
    ros_node.create_subscription(PoseStamped, f'{namespace}/goal_pose', volatile.append,
                                 QoSProfile(depth=1, reliability=reliable,
                                            durability=DurabilityPolicy.VOLATILE))
    assert spin_until(ros_node, lambda: latched and volatile, timeout=5.0), (latched, volatile)
    for goal in (latched[0], volatile[0]):
        assert goal.header.frame_id == 'map'
        assert (goal.pose.position.x, goal.pose.position.y) == pytest.approx(
            (environment.goal.position.x, environment.goal.position.y))
    result = sent.result().get_result_async()
    assert spin_until(ros_node, result.done, timeout=30)
    assert result.result().result.metrics.outcome == 'controller_unresponsive'


def test_a_stack_that_falls_silent_mid_episode_gives_no_test_result(node_processes, ros_node):
    # At 8x real time a stuck rule of 10 sim s ends a standing robot after 1.25 wall s, before
    # the wall-clock silence rule (controller_timeout, 2 s) could: the stack stopped the robot
    # and fell silent (its controller died), which must end controller_unresponsive (re-run,
    # never a result), not stuck.
    namespace = '/fell_silent'
    start_simulator(node_processes, namespace, 'dummy_agents:=0', 'mode:=clocked',
                    'real_time_factor:=8.0', 'stuck_timeout:=10.0')
    stand_in = start_stand_in(node_processes, namespace, '--fall-silent-after', '20')
    metrics, _, attempt = evaluate_with_reruns(
        ros_node, namespace, environment_msg(room(), 'factory', 'fell'), time_limit=60.0)
    assert 'falling silent' in stand_in.output()
    assert metrics.outcome == 'controller_unresponsive', metrics.detail
    if attempt == 1:  # at 8x (a starved try is re-run slower, where the wall clock may rule)
        assert 'its stack fell silent' in metrics.detail and 'had ended stuck' in metrics.detail


@pytest.mark.parametrize('real_time_factor', [1.0, 4.0])
def test_a_stack_that_stops_the_robot_and_waits_is_judged_on_its_driving(
        node_processes, ros_node, real_time_factor):
    # Nav2's default behaviour tree recovers with Wait (5 s): behavior_server stops the robot
    # and nothing publishes cmd_vel meanwhile. That pause is neither silence (at 1x it lasts
    # 5 wall s, past controller_timeout) nor lateness (one gap of 100 command periods): the
    # robot stood as commanded, and the episode goes on to its result.
    namespace = f'/nav2_wait_{int(real_time_factor)}'
    start_simulator(node_processes, namespace, 'dummy_agents:=0', 'mode:=clocked',
                    f'real_time_factor:={real_time_factor}')
    stand_in = start_stand_in(node_processes, namespace, '--wait-after', '30')
    # On a busy machine the stand-in may also be starved (overloaded: re-run at half the pace,
    # as campaigns do); the pause itself would make every try overloaded.
    metrics, _, _ = evaluate_with_reruns(
        ros_node, namespace, environment_msg(room(), 'factory', 'wait'), time_limit=60.0)
    assert 'waiting 5 sim s' in stand_in.output()
    assert metrics.outcome == 'goal_reached', metrics.detail


def test_free_mode_runs_an_episode_for_every_map(node_processes, ros_node, tmp_path):
    from nav_msgs.msg import OccupancyGrid
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    simulator = start_simulator(node_processes, '/free', 'free_mode:=true', 'seed:=40',
                                'dummy_agents:=0', f'bags_root:={tmp_path}',
                                'record_directory:=bags')
    start_external(node_processes, '/free')
    publisher = ros_node.create_publisher(
        OccupancyGrid, '/free/environment',
        QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.TRANSIENT_LOCAL))
    publisher.publish(environment_msg(room(), 'factory', 'free').map)
    simulator.wait_for_output(r'free-mode episode free-40: goal_reached', timeout=90)
    # A wall across most of the room: the go-to-goal controller gets stuck behind it, a
    # failure in a feasible map, so free mode records its bag.
    walled = room(20)
    walled[10, 1:15] = 1
    publisher.publish(environment_msg(walled, 'factory', 'free').map)
    simulator.wait_for_output(r'free-mode episode free-41: (stuck|timeout)', timeout=90)
    bags = sorted(path.name for path in (tmp_path / 'bags').iterdir())
    assert bags == ['free-41'], bags
    episode = json.loads((tmp_path / 'bags' / 'free-41' / 'episode.json').read_text())
    assert episode['controller'] == 'external' and episode['namespace'] == '/free'
    assert episode['episode_seed'] == 41


def test_misspelt_mode_stops_the_simulator_with_a_clear_error(node_processes):
    process = node_processes.start(['ros2', 'run', 'sessgan_sim', 'simulator', '--ros-args',
                                    '-p', 'mode:=clockd'], name='bad_mode')
    assert process.wait(timeout=60) == 2
    assert "parameter 'mode' must be one of lockstep, clocked; got 'clockd'" in process.output()
