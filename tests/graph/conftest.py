"""Fixtures shared by the graph tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope='session')
def room_bag(tmp_path_factory) -> Path:
    """A bag of an empty room (no agents), recorded in process once per run: the suites that
    re-run it only read it."""
    from sessgan_core.valid_tests import make_environment
    from sessgan_evolver.in_process import InProcessEvaluator
    from sessgan_sim.simulator_settings import SimulatorSettings
    from tests.graph.test_simulator_graph import room

    environment = make_environment(room(), 'factory', 'room')
    with InProcessEvaluator('factory', 'nearness_diagram', time_limit=60.0,
                            settings=SimulatorSettings(dummy_agents=0)) as evaluator:
        run = evaluator.runner.run(environment, 1, trace=True, keep_scans=True)
        return evaluator.write_bag(tmp_path_factory.mktemp('recorded') / 'room', environment,
                                   1, run, 'test')
