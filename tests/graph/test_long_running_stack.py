"""One controller process lives through ten episodes: sim time only moves forward, so a
long-running stack (Nav2 keeps a tf buffer and costmaps) never sees it jump back."""

from __future__ import annotations

import json
import re

import pytest

from tests.graph.test_clocked_mode import start_stand_in
from tests.graph.test_simulator_graph import (
    environment_msg,
    evaluate,
    evaluate_with_reruns,
    room,
    start_controller,
    start_simulator,
)

pytestmark = pytest.mark.graph


def swapped(environment_msg_):
    """The same map with start and goal exchanged (the next episode drives back)."""
    environment_msg_.start, environment_msg_.goal = environment_msg_.goal, environment_msg_.start
    return environment_msg_


def clock_recorder(ros_node, namespace: str) -> list[int]:
    from rosgraph_msgs.msg import Clock

    stamps: list[int] = []
    ros_node.create_subscription(
        Clock, f'{namespace}/clock',
        lambda msg: stamps.append(msg.clock.sec * 1_000_000_000 + msg.clock.nanosec), 1000)
    return stamps


def test_nav2_like_stack_lives_through_ten_clocked_episodes(node_processes, ros_node):
    namespace = '/long_clocked'
    start_simulator(node_processes, namespace, 'dummy_agents:=0', 'mode:=clocked',
                    'real_time_factor:=4.0')
    stand_in = start_stand_in(node_processes, namespace)
    stamps = clock_recorder(ros_node, namespace)
    ends = []
    episodes = 0
    for index in range(10):
        environment = environment_msg(room(10), 'factory', f'lap{index}')
        if index % 2:
            environment = swapped(environment)
        metrics, _, tries = evaluate_with_reruns(ros_node, namespace, environment, time_limit=40.0,
                                              seed=index)
        assert metrics.outcome == 'goal_reached', (index, metrics.detail)
        episodes += tries
        ends.append(metrics.simulation_time)
    assert 'jumped back' not in stand_in.output()
    assert stamps == sorted(stamps), 'the clock went back'
    # Each goal arrived at a later sim time than the one before, every episode after the last
    # one's end (time never restarted at 0).
    arrivals = [float(t) for t in re.findall(r'goal from goal_pose: .* at sim time ([\d.]+)',
                                             stand_in.output())]
    assert len(arrivals) == episodes, stand_in.output()[-3000:]
    assert all(later > earlier for earlier, later in zip(arrivals, arrivals[1:]))
    assert arrivals[-1] >= sum(ends[:-1]), (arrivals, ends)


def test_builtin_controller_lives_through_ten_lockstep_episodes(node_processes, ros_node,
                                                                tmp_path):
    namespace = '/long_lockstep'
    start_simulator(node_processes, namespace, 'dummy_agents:=0', f'bags_root:={tmp_path}')
    start_controller(node_processes, namespace, 'nearness_diagram')
    bags = tmp_path / 'bags'
    cut_short = []
    for index in range(10):
        environment = environment_msg(room(), 'factory', f'room{index}')
        if index % 2:
            # Two seconds cannot reach the goal: a timeout in a valid test, a controller
            # failure whose bag records where this episode's clock started.
            metrics, _ = evaluate(ros_node, namespace, environment, seed=3, time_limit=2.0,
                                  record_directory='bags')
            assert metrics.outcome == 'timeout' and metrics.bag_path, metrics.detail
            cut_short.append((metrics.ticks, round(metrics.distance_travelled, 9),
                              round(metrics.min_clearance, 9)))
        else:
            metrics, _ = evaluate(ros_node, namespace, environment, seed=3)
            assert metrics.outcome == 'goal_reached', (index, metrics.detail)
    # Same map, same seed: the same episode every time, whatever came before it.
    assert len(set(cut_short)) == 1, cut_short
    origins = [json.loads((bags / f'room{index}' / 'episode.json').read_text())
               ['sim_time_origin_ns'] for index in range(1, 10, 2)]
    assert origins == sorted(origins) and len(set(origins)) == 5 and origins[0] > 0, origins
