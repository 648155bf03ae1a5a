"""An in-process episode is the lockstep episode of a simulator worker and a controller node:
the failure bag of an in-process fault re-simulates through the ROS graph to the same
outcome, collisions, risk and simulation time."""

from __future__ import annotations

import subprocess

import pytest

from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_gen.environment_sampler import EnvironmentSampler

pytestmark = pytest.mark.graph


def test_an_in_process_fault_re_simulates_identically_through_ros(ros_workspace, tmp_path):
    sampler = EnvironmentSampler()
    bag = None
    with InProcessEvaluator('factory', record_directory=tmp_path) as evaluator:
        # The first controller failure among some shipped-generator maps (the
        # Nearness-Diagram robot fails in about one in seven: a collision).
        for seed in range(1, 41):
            environment = sampler.sample([seed], None, 'factory')[0]
            run = evaluator.run_environment(environment, seed)
            if run.metrics['bag_path']:
                bag = run.metrics['bag_path']
                break
    assert bag is not None, 'no controller failure in 40 factory maps'
    result = subprocess.run(['ros2', 'run', 'sessgan_evolver', 'replay', bag, '--resimulate'],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    lines = {line.split()[0]: line.split()[1:] for line in result.stdout.splitlines()
             if line.strip() and line.split()[0] in ('outcome', 'collisions', 'risk', 'sim')}
    for label, values in lines.items():
        assert values[-1] == values[-2], f'{label}: recorded {values[-2]}, ROS {values[-1]}'
    assert set(lines) == {'outcome', 'collisions', 'risk', 'sim'}
