"""Goals as NavigateToPose action goals and per-episode costmap resets, against an rclpy
stand-in of Nav2's bt_navigator and costmaps (tests/graph/nav2_stand_in.py)."""

from __future__ import annotations

import re

import pytest

from tests.graph.test_clocked_mode import start_stand_in
from tests.graph.test_long_running_stack import swapped
from tests.graph.test_simulator_graph import (
    environment_msg,
    evaluate,
    evaluate_with_reruns,
    room,
    start_simulator,
)

pytestmark = pytest.mark.graph

CLOCKED = ('dummy_agents:=0', 'mode:=clocked', 'real_time_factor:=3.0')


def test_each_episode_resets_costmaps_then_sends_a_navigate_to_pose_goal(node_processes,
                                                                          ros_node):
    namespace = '/ntp'
    start_simulator(node_processes, namespace, *CLOCKED, 'goal_interface:=navigate_to_pose',
                    'reset_costmaps:=true')
    stand_in = start_stand_in(node_processes, namespace, '--action', '--costmaps')
    episodes = 0
    for index in range(3):
        environment = environment_msg(room(10), 'factory', f'ntp{index}')
        if index % 2:
            environment = swapped(environment)
        metrics, _, tries = evaluate_with_reruns(ros_node, namespace, environment, time_limit=40.0,
                                              seed=index)
        episodes += tries
        assert metrics.outcome == 'goal_reached', metrics.detail
        # The simulator's goal tolerance (a cell) is reached before the stack's (0.25 m): the
        # goal is still active at the end and the simulator cancels it.
        assert f'{namespace}/navigate_to_pose goal still active at the end: canceled' in \
            metrics.detail, metrics.detail
    events = re.findall(r'cleared the (global|local) costmap|goal from (navigate_to_pose|'
                        r'goal_pose)|navigate_to_pose goal (canceled)', stand_in.output())
    steps = [next(part for part in event if part) for event in events]
    # Per episode: both costmaps cleared, then the action goal, then its cancel at the end;
    # nothing on goal_pose (the topic is not used). An overloaded try is an episode too.
    assert steps == ['global', 'local', 'navigate_to_pose', 'canceled'] * episodes, steps


@pytest.mark.parametrize('forward', [False, True])
def test_goal_on_the_topic_and_the_action(node_processes, ros_node, forward):
    """Forwarded (as bt_navigator does), the goal_pose makes a second goal of the stack's
    server, and one preempts the other: the stack still drives, so the episode goes on."""
    namespace = f'/ntp_both{int(forward)}'
    start_simulator(node_processes, namespace, *CLOCKED, 'goal_interface:=both')
    stand_in = start_stand_in(node_processes, namespace, '--action',
                              *(['--forward-goal-pose'] if forward else []))
    metrics, _, _ = evaluate_with_reruns(ros_node, namespace,
                                      environment_msg(room(10), 'factory', 'both'),
                                      time_limit=40.0)
    assert metrics.outcome == 'goal_reached', metrics.detail
    output = stand_in.output()
    if forward:
        assert 'goal_pose forwarded' in output
        assert output.count('goal from navigate_to_pose') >= 2
    else:
        assert 'goal from goal_pose' in output and 'goal from navigate_to_pose' in output
    assert 'cleared the' not in output  # resets are off by default


def test_a_stack_that_gives_up_on_a_goal_pose_goal_fails_the_test(node_processes, ros_node):
    """bt_navigator makes a goal_pose a NavigateToPose goal of its own server. When it gives
    up on it (aborted), the robot stands and no command comes: a navigation failure, a result
    (stuck), not a silent stack (controller_unresponsive: re-run, and never a result)."""
    namespace = '/ntp_gave_up'
    start_simulator(node_processes, namespace, *CLOCKED)  # goal_interface: goal_pose
    stand_in = start_stand_in(node_processes, namespace, '--action', '--forward-goal-pose',
                              '--abort-after', '20')
    metrics, _, _ = evaluate_with_reruns(ros_node, namespace,
                                      environment_msg(room(10), 'factory', 'gave_up'),
                                      time_limit=60.0)
    assert 'navigate_to_pose goal aborted' in stand_in.output()
    assert metrics.outcome == 'stuck', metrics.detail
    assert (f'{namespace}/navigate_to_pose goal aborted by the stack (seen on its status '
            'topic)') in metrics.detail, metrics.detail


@pytest.mark.parametrize('stand_in_options, parameters, expected', [
    ([], ['reset_costmaps:=true'],
     r'costmap reset: no /ntp_fail\d/global_costmap/clear_entirely_global_costmap service '
     r'within 1\.0 s'),
    (['--costmaps', '--reset-delay', '3'], ['reset_costmaps:=true'],
     r'costmap reset: /ntp_fail\d/global_costmap/clear_entirely_global_costmap did not answer '
     r'within 1\.0 s'),
    ([], ['goal_interface:=navigate_to_pose'],
     r'no NavigateToPose action server at /ntp_fail\d/navigate_to_pose within 1\.0 s'),
    (['--action', '--reject-goals'], ['goal_interface:=navigate_to_pose'],
     r'/ntp_fail\d/navigate_to_pose rejected the goal'),
], ids=['reset_not_served', 'reset_too_slow', 'no_action_server', 'goal_rejected'])
def test_a_stack_that_does_not_respond_ends_the_episode_with_the_reason(
        node_processes, ros_node, stand_in_options, parameters, expected, request):
    namespace = f'/ntp_fail{request.node.callspec.indices["stand_in_options"]}'
    start_simulator(node_processes, namespace, *CLOCKED, 'stack_timeout:=1.0', *parameters)
    start_stand_in(node_processes, namespace, *stand_in_options)
    metrics, _ = evaluate(ros_node, namespace, environment_msg(room(10), 'factory', 'fail'),
                          time_limit=40.0)
    assert metrics.outcome == 'controller_unresponsive'
    assert re.search(expected, metrics.detail), metrics.detail


def test_an_old_goal_s_end_does_not_stop_the_robot(node_processes, ros_node):
    """The stack's server still lists a goal that ended before the episode (here one a user
    sent and cancelled); the transient-local status topic delivers it when the simulator
    starts reading. It is not the episode's goal: the robot must not be stood still."""
    from nav2_msgs.action import NavigateToPose
    from rclpy.action import ActionClient

    from tests.ros_processes import spin_until

    namespace = '/ntp_old_goal'
    start_simulator(node_processes, namespace, *CLOCKED)  # goal_interface: goal_pose
    stand_in = start_stand_in(node_processes, namespace, '--action')
    client = ActionClient(ros_node, NavigateToPose, f'{namespace}/navigate_to_pose')
    assert client.wait_for_server(timeout_sec=30)
    sent = client.send_goal_async(NavigateToPose.Goal())
    assert spin_until(ros_node, sent.done, timeout=30) and sent.result().accepted
    cancelled = sent.result().cancel_goal_async()
    assert spin_until(ros_node, cancelled.done, timeout=30)
    assert spin_until(ros_node, lambda: 'navigate_to_pose goal canceled' in stand_in.output(),
                      timeout=30)
    metrics, _, _ = evaluate_with_reruns(ros_node, namespace,
                                      environment_msg(room(10), 'factory', 'old_goal'),
                                      time_limit=40.0)
    assert metrics.outcome == 'goal_reached', metrics.detail
    assert 'by the stack' not in metrics.detail, metrics.detail

