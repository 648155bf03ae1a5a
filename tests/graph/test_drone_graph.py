"""The flyer with altitude over low obstacles, as separate processes over real topics.

A drone map whose only way from start to goal crosses a band of low obstacles (0.3 m tall):
the built-in flyer controllers take off and fly over it, while the simulator publishes
``range_down`` (sensor_msgs/Range) every tick; a flyer kept below the obstacles' height sees
the band with its lidar and never gets over it; its failure bag holds ``range_down`` like the
other tick topics.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from tests.graph.test_simulator_graph import (
    environment_msg,
    evaluate,
    start_controller,
    start_simulator,
)
from tests.ros_processes import spin_until

pytestmark = pytest.mark.graph

LOW_BAND_COLUMNS = (14, 16)
"""Cells of the band of low obstacles across the corridor (x from 7.0 to 8.0 m)."""


def low_band() -> np.ndarray:
    """A drone token map (G 0, W 1, O 2): a 15 m x 5 m corridor with a band of low obstacles
    across it; the certified route from start to goal crosses the band."""
    cells = np.zeros((10, 30), dtype=np.int64)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 1
    cells[1:-1, LOW_BAND_COLUMNS[0]:LOW_BAND_COLUMNS[1]] = 2
    return cells


def band_msg(env_id: str):
    msg = environment_msg(low_band(), 'drone', env_id)
    assert msg.feasible
    band = (LOW_BAND_COLUMNS[0] * 0.5, LOW_BAND_COLUMNS[1] * 0.5)
    start, goal = msg.start.position.x, msg.goal.position.x
    assert min(start, goal) < band[0] and max(start, goal) > band[1], 'the route crosses'
    return msg


def drain(ros_node, *received: list, quiet: float = 1.0, timeout: float = 60.0) -> None:
    """Spin until no list in ``received`` has grown for ``quiet`` seconds."""
    state = {'sizes': [len(r) for r in received], 'since': time.monotonic()}

    def settled() -> bool:
        sizes = [len(r) for r in received]
        if sizes != state['sizes']:
            state['sizes'], state['since'] = sizes, time.monotonic()
        return time.monotonic() - state['since'] >= quiet

    spin_until(ros_node, settled, timeout=timeout)


@pytest.mark.parametrize('controller, parameters', [
    ('velocity_projection', ()),
    ('reference_navigator', ('robot:=flyer',)),
])
def test_flyer_takes_off_and_flies_over_low_obstacles_publishing_range_down(
        node_processes, ros_node, controller, parameters):
    from nav_msgs.msg import Odometry
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Range
    from tf2_msgs.msg import TFMessage

    namespace = f'/drone_{controller}'
    start_simulator(node_processes, namespace, 'dummy_agents:=0')
    start_controller(node_processes, namespace, controller, *parameters)
    ranges: list[Range] = []
    odometry: list[Odometry] = []
    static: list[TFMessage] = []
    reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    subscriptions = [
        ros_node.create_subscription(Range, f'{namespace}/range_down', ranges.append, reliable),
        ros_node.create_subscription(Odometry, f'{namespace}/odom', odometry.append, reliable),
        ros_node.create_subscription(TFMessage, f'{namespace}/tf_static', static.append,
                                     latched)]
    try:
        metrics, _ = evaluate(ros_node, namespace, band_msg(f'band-{controller}'),
                              timeout=300)
        # A busy test process is still taking the episode's messages from the readers'
        # queues: read them all before the readers go.
        drain(ros_node, odometry, ranges)
    finally:
        for subscription in subscriptions:
            ros_node.destroy_subscription(subscription)
    assert metrics.outcome == 'goal_reached', (metrics.outcome, metrics.detail)
    assert metrics.collisions == 0, metrics.detail
    assert ranges and odometry and static
    assert ranges[0].header.frame_id == 'base_range_down'
    assert ranges[0].radiation_type == Range.INFRARED
    frames = {t.child_frame_id: t for t in static[-1].transforms}
    down = frames['base_range_down']
    assert down.header.frame_id == 'base_link'
    assert down.transform.rotation.y == pytest.approx(math.sin(math.pi / 4))
    # Landed at the start, then at the cruise altitude; the ranger reads the ground there and
    # 0.3 m less over the band.
    altitudes = [o.pose.pose.position.z for o in odometry]
    assert altitudes[0] == 0.0 and max(altitudes) == pytest.approx(0.95, abs=0.05)
    band = (LOW_BAND_COLUMNS[0] * 0.5, LOW_BAND_COLUMNS[1] * 0.5)
    stamps = {(o.header.stamp.sec, o.header.stamp.nanosec): o for o in odometry}
    over_band, over_ground = [], []
    for reading in ranges:
        pose = stamps.get((reading.header.stamp.sec, reading.header.stamp.nanosec))
        if pose is None:
            continue
        x, z = pose.pose.pose.position.x, pose.pose.pose.position.z
        if band[0] + 0.05 < x < band[1] - 0.05:
            over_band.append(reading.range - z)
        elif x < band[0] - 0.3 or x > band[1] + 0.3:
            over_ground.append(reading.range - z)
    assert over_band and over_ground
    assert np.median(over_band) == pytest.approx(-0.3, abs=0.02)
    assert np.median(over_ground) == pytest.approx(0.0, abs=0.02)


def test_a_flyer_below_the_low_obstacles_sees_them_as_walls_and_its_bag_has_range_down(
        node_processes, ros_node, tmp_path):
    from sessgan_evolver.bag_reading import iter_bag_messages, read_episode_bag
    from sessgan_sim.bag_recording import jazzy_typestore

    namespace = '/drone_low'
    # A 10 s stuck window: stuck well within the 30 s the episode gets.
    start_simulator(node_processes, namespace, 'dummy_agents:=0', f'bags_root:={tmp_path}',
                    'stuck_timeout:=10.0')
    # Told to cruise at 5 cm: its route crosses the band as free space, but flying below the
    # obstacles its scan plane meets them: it stops in front of the band and never gets over.
    start_controller(node_processes, namespace, 'velocity_projection', 'cruise_altitude:=0.05',
                     'takeoff_altitude:=0.02')
    metrics, _ = evaluate(ros_node, namespace, band_msg('band-low'), time_limit=30.0,
                          record_directory='bags', timeout=300)
    assert metrics.feasible
    assert metrics.outcome == 'stuck', (metrics.outcome, metrics.detail)
    assert metrics.bag_path, 'a controller failure in a valid test is recorded'
    bag = read_episode_bag(metrics.bag_path)
    counts = {t.topic.rsplit('/', 1)[-1]: t.message_count for t in bag.topics}
    assert counts['range_down'] == counts['scan'] == counts['odom']
    store = jazzy_typestore()
    readings = [store.deserialize_cdr(m.data, m.msgtype)
                for m in iter_bag_messages(metrics.bag_path, [f'{namespace}/range_down'])]
    assert all(r.header.frame_id == 'base_range_down' for r in readings)
    assert max(r.range for r in readings) < 0.2  # it never rose over the obstacles
