"""Pick-up -> place missions over real topics (issue 13, part 1).

The reference navigator (its own process, as ``ros2 run sessgan_controllers
reference_navigator``) drives a two-leg mission on the factory example map: to the station,
a dwell standing still, then home. The simulator sends each waypoint on ``goal_pose`` when the
previous one was reached and all of them at once on ``waypoints``. A mission that times out on
its second leg leaves a failure bag that replays and re-simulates to the same legs.
"""

from __future__ import annotations

import json
import math

import pytest

from tests.graph.test_reference_navigator_graph import start_navigator
from tests.graph.test_resimulation import replay_all, resimulate_same
from tests.graph.test_simulator_graph import evaluate, evaluate_with_reruns, start_simulator

pytestmark = pytest.mark.graph

DWELL_TIME = 2.0


def mission_environment(stations: int = 1):
    """The factory example with ``stations`` stations before home (core Environment)."""
    from sessgan_core.missions import MissionSpec
    from sessgan_core.token_map import load_example_map
    from sessgan_core.valid_tests import make_environment

    environment = make_environment(load_example_map('factory').cells, 'factory',
                                   'factory-mission', seed=0,
                                   mission=MissionSpec(stations, DWELL_TIME))
    assert environment.feasible and len(environment.stations) == stations
    return environment


def watch_goals(ros_node, namespace: str):
    """Every goal_pose and waypoints message of ``namespace`` (reliable, transient local)."""
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import Path
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    goals: list = []
    paths: list = []
    ros_node.create_subscription(PoseStamped, f'{namespace}/goal_pose', goals.append, qos)
    ros_node.create_subscription(Path, f'{namespace}/waypoints', paths.append, qos)
    return goals, paths


def test_two_leg_mission_reaches_the_station_and_home(node_processes, ros_node):
    from sessgan_core.ros_conversion import environment_to_msg

    environment = mission_environment()
    station, home = environment.stations[0], environment.goal
    namespace = '/mission'
    goals, paths = watch_goals(ros_node, namespace)
    start_simulator(node_processes, namespace)
    navigator = start_navigator(node_processes, namespace, 'diff_drive')
    metrics, _ = evaluate(ros_node, namespace, environment_to_msg(environment), timeout=300)
    assert metrics.outcome == 'goal_reached', (metrics.outcome, metrics.detail)
    assert 'completed the mission' in metrics.detail
    assert metrics.fault_collisions == 0, metrics.detail
    assert (metrics.legs, metrics.legs_completed, metrics.failed_leg) == (2, 2, -1)
    assert len(metrics.leg_times) == 2 and all(t > 0 for t in metrics.leg_times)
    # The second leg starts only after the dwell: the legs and the dwell fit the episode.
    assert sum(metrics.leg_times) + DWELL_TIME <= metrics.simulation_time + 1e-6

    # goal_pose carried the station, then home; waypoints both at once, in frame map.
    positions = [(goal.pose.position.x, goal.pose.position.y) for goal in goals]
    assert positions == [(station.x, station.y), (home.x, home.y)], positions
    assert all(goal.header.frame_id == 'map' for goal in goals)
    assert len(paths) == 1 and paths[0].header.frame_id == 'map'
    assert [(pose.pose.position.x, pose.pose.position.y) for pose in paths[0].poses] == \
        [(station.x, station.y), (home.x, home.y)]
    # The second goal went out once the robot had stood at the station for the dwell time.
    first, second = (goal.header.stamp.sec + goal.header.stamp.nanosec * 1e-9 for goal in goals)
    assert second - first >= metrics.leg_times[0] + DWELL_TIME - 1e-6
    assert navigator.output().count('New goal') >= 2


def test_mission_failure_bag_replays_and_resimulates(node_processes, ros_node, tmp_path):
    from sessgan_core.ros_conversion import environment_to_msg

    environment = mission_environment()
    namespace = '/mission_bag'
    start_simulator(node_processes, namespace, f'bags_root:={tmp_path}')
    start_navigator(node_processes, namespace, 'diff_drive')
    # Enough time for the first leg and the dwell (about 20 s), not for the way home.
    metrics, _ = evaluate(ros_node, namespace, environment_to_msg(environment), time_limit=25.0,
                          record_directory='bags', timeout=300)
    assert metrics.outcome == 'timeout', (metrics.outcome, metrics.detail)
    assert (metrics.legs, metrics.legs_completed, metrics.failed_leg) == (2, 1, 1)
    assert 'failed on leg 2 of 2 (home)' in metrics.detail
    assert metrics.bag_path
    episode = json.loads((tmp_path / 'bags' / 'factory-mission' / 'episode.json').read_text())
    station = environment.stations[0]
    assert episode['stations'] == [[station.x, station.y, station.yaw]]
    assert episode['dwell_time'] == DWELL_TIME
    assert episode['metrics']['failed_leg'] == 1

    from sessgan_evolver.bag_reading import read_bag_topics

    counts = {topic.topic: topic.message_count for topic in read_bag_topics(metrics.bag_path)}
    assert counts[f'{namespace}/goal_pose'] == 2 and counts[f'{namespace}/waypoints'] == 1

    # Replay re-publishes every message; re-simulation rebuilds the mission from episode.json
    # and fails on the same leg.
    replay_all(metrics.bag_path, sum(counts.values()), '/mission_replay')
    rows = resimulate_same(metrics.bag_path, '--controller', 'reference_navigator')
    assert rows['legs completed'][0] == '1/2'
    assert math.isclose(float(rows['sim time'][0]), 25.0, abs_tol=0.06)


@pytest.mark.parametrize('interface, forwarding', [
    ('navigate_to_pose', []),
    # bt_navigator's way with goals on goal_pose: the stack's server reaches (and, preempted
    # by the next waypoint, aborts) each; neither may stop the robot before home.
    ('goal_pose', ['--forward-goal-pose'])])
def test_a_nav2_stack_gets_each_waypoint_as_a_navigate_to_pose_goal(node_processes, ros_node,
                                                                     interface, forwarding):
    from sessgan_core.missions import MissionSpec
    from sessgan_core.ros_conversion import environment_to_msg
    from sessgan_core.valid_tests import make_environment
    from tests.graph.test_clocked_mode import start_stand_in
    from tests.graph.test_simulator_graph import room

    environment = make_environment(room(12), 'factory', 'room-mission', seed=4,
                                   mission=MissionSpec(1, 1.0))
    assert environment.feasible and len(environment.stations) == 1
    namespace = f'/mission_{interface}'
    start_simulator(node_processes, namespace, 'dummy_agents:=0', 'mode:=clocked',
                    'real_time_factor:=3.0', f'goal_interface:={interface}')
    stand_in = start_stand_in(node_processes, namespace, '--action', *forwarding)
    metrics, _, tries = evaluate_with_reruns(ros_node, namespace, environment_to_msg(environment),
                                          time_limit=60.0)
    assert metrics.outcome == 'goal_reached', metrics.detail
    assert (metrics.legs, metrics.legs_completed) == (2, 2)
    output = stand_in.output()
    # The station's goal ended (the stack reached it and stood for the dwell), then home's
    # (an overloaded try sent its station goal at least).
    assert output.count('goal from navigate_to_pose') >= 2 + (tries - 1), output
    assert 'goal from goal_pose' not in output
