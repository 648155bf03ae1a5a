"""A generated race track, served by the generator node, driven by a car over real topics.

The generator node serves race tracks through the racetrack scenario's track cleanup
(sessgan_gen.track_cleanup): one connected road network. The reference navigator with the
car drives one of them, taken from the node's generate_environments service, in a
simulator worker: the served map is a valid test the car can finish.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.graph.test_generator_graph import call_service, start_generator
from tests.graph.test_reference_navigator_graph import start_navigator
from tests.graph.test_simulator_graph import evaluate, start_simulator

pytestmark = pytest.mark.graph

SEED = 700002
"""A fresh seed whose served track is a valid test (the car reaches its goal in the unit
tier too: tests/unit/controllers/test_reference_navigator_episodes.py)."""


def test_the_car_drives_a_served_generated_track(node_processes, ros_node):
    from sessgan_core.valid_tests import reachable_regions
    from sessgan_interfaces.srv import GenerateEnvironments

    start_generator(node_processes, '/gen_track', 'scenario:=racetrack')
    client = ros_node.create_client(GenerateEnvironments, '/gen_track/generate_environments')
    response = call_service(ros_node, client, GenerateEnvironments.Request(
        scenario='racetrack', seeds=[SEED]))
    assert response.success, response.message
    served = response.environments[0]
    grid = np.array(served.map.data, dtype=np.int16).reshape(served.map.info.height,
                                                            served.map.info.width)
    assert grid.shape == (128, 128)
    # One road network: the track cleanup ran in the node's path.
    assert len(reachable_regions(grid == 0).sizes) == 1
    assert served.feasible

    start_simulator(node_processes, '/track', 'dummy_agents:=0')
    start_navigator(node_processes, '/track', 'car')
    metrics, _ = evaluate(ros_node, '/track', served, seed=SEED, timeout=300)
    assert metrics.feasible
    assert metrics.outcome == 'goal_reached', (metrics.outcome, metrics.detail)
    assert metrics.fault_collisions == 0, metrics.detail
