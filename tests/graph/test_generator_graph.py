"""The generator node, started with `ros2 run`, seen from another process over DDS."""

from __future__ import annotations

import pytest

from tests.ros_processes import spin_until

pytestmark = pytest.mark.graph


def start_generator(node_processes, namespace: str, *parameters: str):
    command = ['ros2', 'run', 'sessgan_gen', 'generator', '--ros-args', '-r', f'__ns:={namespace}']
    for parameter in parameters:
        command += ['-p', parameter]
    return node_processes.start(command, name=f'generator{namespace.replace("/", "_")}')


def test_generator_map_is_transient_local(node_processes, ros_node):
    from nav_msgs.msg import OccupancyGrid
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    generator = start_generator(node_processes, '/gen_a', 'scenario:=factory', 'seed:=7')
    generator.wait_for_output(r'published environment factory-s7', timeout=60)

    # Subscribing only now proves the map is kept for late joiners (transient local).
    received = []
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    ros_node.create_subscription(OccupancyGrid, '/gen_a/environment', received.append, qos)
    assert spin_until(ros_node, lambda: received, timeout=20), 'no map received'
    grid = received[0]
    assert (grid.info.width, grid.info.height) == (32, 32)
    assert grid.info.resolution == pytest.approx(0.5)
    assert set(grid.data) <= {0, 100}
    assert grid.header.frame_id == 'map'


def call_service(ros_node, client, request, timeout=60.0):
    assert client.wait_for_service(timeout_sec=30), 'generate_environments not available'
    future = client.call_async(request)
    assert spin_until(ros_node, future.done, timeout=timeout), 'service call timed out'
    return future.result()


def test_generate_environments_service(node_processes, ros_node):
    from sessgan_interfaces.srv import GenerateEnvironments

    generator = start_generator(node_processes, '/gen_b', 'scenario:=drone')
    client = ros_node.create_client(GenerateEnvironments, '/gen_b/generate_environments')

    request = GenerateEnvironments.Request(scenario='drone', seeds=[3, 4, 5], generation=2,
                                           member=1)
    response = call_service(ros_node, client, request)
    assert response.success, response.message
    assert [env.seed for env in response.environments] == [3, 4, 5]
    assert all(env.scenario == 'drone' and env.generation == 2 for env in response.environments)
    assert set(response.environments[0].map.data) <= {0, 50, 100}

    # Bad requests get a clear refusal and the node keeps serving.
    bad = call_service(ros_node, client, GenerateEnvironments.Request(scenario='moon', seeds=[1]))
    assert not bad.success and 'moon' in bad.message
    corrupt = call_service(ros_node, client, GenerateEnvironments.Request(
        scenario='drone', weights=list(b'not a checkpoint'), seeds=[1]))
    assert not corrupt.success and 'checkpoint' in corrupt.message.lower()
    huge = call_service(ros_node, client, GenerateEnvironments.Request(
        scenario='drone', seeds=[1], width=100000, height=100000))
    assert not huge.success and '100000' in huge.message

    again = call_service(ros_node, client, GenerateEnvironments.Request(seeds=[3]))
    assert again.success
    assert list(again.environments[0].map.data) == list(response.environments[0].map.data), \
        'the same seed must give the same map'
    assert generator.process.poll() is None


def test_requests_beyond_the_cell_cap_are_refused(node_processes, ros_node):
    from sessgan_interfaces.srv import GenerateEnvironments

    start_generator(node_processes, '/gen_c', 'scenario:=factory',
                    f'max_cells_per_request:={2 * 32 * 32}')
    client = ros_node.create_client(GenerateEnvironments, '/gen_c/generate_environments')
    refused = call_service(ros_node, client, GenerateEnvironments.Request(seeds=[1, 2, 3]))
    assert not refused.success
    assert '3 maps of 32x32 are 3,072 cells' in refused.message
    assert 'max_cells_per_request' in refused.message
    too_big = call_service(ros_node, client, GenerateEnvironments.Request(
        seeds=[1], width=2048, height=1024))
    assert not too_big.success and 'more than the 1,048,576' in too_big.message
    accepted = call_service(ros_node, client, GenerateEnvironments.Request(seeds=[1, 2]))
    assert accepted.success and len(accepted.environments) == 2


def test_an_unreadable_checkpoint_parameter_ends_the_node_with_the_reason(node_processes,
                                                                         tmp_path):
    corrupt = tmp_path / 'corrupt.pt'
    corrupt.write_bytes(b'not a checkpoint')
    for checkpoint, reason in ((tmp_path / 'missing.pt', 'missing.pt'),
                               (corrupt, 'not a valid checkpoint')):
        generator = start_generator(node_processes, '/gen_d', f'checkpoint:={checkpoint}')
        assert generator.wait(timeout=60) == 1, generator.output()
        assert 'cannot start the generator' in generator.output()
        assert reason in generator.output(), generator.output()


def test_a_facility_generator_serves_the_facilitys_size(node_processes, ros_node, tmp_path):
    from nav_msgs.msg import OccupancyGrid
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from sessgan_gen.checkpoint import load_checkpoint, save_checkpoint
    from sessgan_interfaces.srv import GenerateEnvironments
    from tests.unit.gen.facility_checkpoint import (
        FACILITY_HEIGHT,
        FACILITY_WIDTH,
        train_facility_checkpoint,
    )

    checkpoint, _ = train_facility_checkpoint(tmp_path)
    # A facility map's origin (a SLAM map's, moved to its known region) travels with it.
    pyramid, metadata = load_checkpoint(checkpoint)
    save_checkpoint(checkpoint, pyramid, {**metadata, 'map_origin': [-7.5, 2.25, 0.0]})
    generator = start_generator(node_processes, '/gen_e', f'checkpoint:={checkpoint}',
                                'seed:=2')
    generator.wait_for_output(r'published environment factory-s2', timeout=60)
    received = []
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
    ros_node.create_subscription(OccupancyGrid, '/gen_e/environment', received.append, qos)
    assert spin_until(ros_node, lambda: received, timeout=20), 'no map received'
    assert (received[0].info.width, received[0].info.height) == (FACILITY_WIDTH, FACILITY_HEIGHT)
    origin = received[0].info.origin.position
    assert (origin.x, origin.y) == (-7.5, 2.25)

    client = ros_node.create_client(GenerateEnvironments, '/gen_e/generate_environments')
    weights = list(checkpoint.read_bytes())
    served = call_service(ros_node, client, GenerateEnvironments.Request(
        scenario='factory', seeds=[1], weights=weights))
    assert served.success, served.message
    grid = served.environments[0].map.info
    assert (grid.width, grid.height) == (FACILITY_WIDTH, FACILITY_HEIGHT)
    assert (grid.origin.position.x, grid.origin.position.y) == (-7.5, 2.25)
    asked = call_service(ros_node, client, GenerateEnvironments.Request(
        scenario='factory', seeds=[1], weights=weights, width=36, height=24))
    assert asked.success, asked.message
    assert (asked.environments[0].map.info.width, asked.environments[0].map.info.height) == (
        36, 24)
