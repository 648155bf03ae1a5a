"""Every executable answers --help with its usage and options (with defaults), exits 0, and
starts nothing."""

from __future__ import annotations

import subprocess

import pytest

pytestmark = pytest.mark.smoke

# (package, executable, texts the help must show: parameters/options and their defaults)
EXECUTABLES = [
    ('sessgan_gen', 'generator', ["checkpoint (string) = ''", 'max_cells_per_request (integer) '
                                  '= 4194304', "scenario (string) = 'factory'"]),
    ('sessgan_sim', 'simulator', ["mode (string) = 'lockstep'",
                                  'controller_timeout (double) = 2.0']),
    ('sessgan_controllers', 'nearness_diagram', ['max_linear_speed (double) = ',
                                                 'use_stamped_cmd_vel (bool, read-only) = False',
                                                 'Nearness-Diagram']),
    ('sessgan_controllers', 'velocity_projection', ['field_of_view (double) = ']),
    ('sessgan_controllers', 'race_controller', ['goal_tolerance (double) = ']),
    ('sessgan_evolver', 'campaign', ['--fitness-tpkl-tolerance', '--generations GENERATIONS',
                                     '(default: 30)', '--mode', '--external',
                                     '20 % above the reference is free', '--method METHOD',
                                     '--budget BUDGET']),
    ('sessgan_evolver', 'replay', ['--resimulate', '--rate']),
    ('sessgan_evolver', 'evaluate', ['--external', '--max-fault-records', '--fresh-episodes',
                                     '--evaluation-seed', '--output-dir']),
    ('sessgan_evolver', 'compare', ['--external', '--no-external', '--budget', '--output-dir']),
    ('sessgan_evolver', 'suite', ['--retries', '--record {all,failures,none}', '--external',
                                  '(default: runs/suite-<suite name>)']),
    ('sessgan_gen', 'train', ['--iterations', '(default:']),
    ('sessgan_gen', 'report', ['--samples', '(default: 100)']),
]


@pytest.mark.parametrize(('package', 'executable', 'expected'), EXECUTABLES,
                         ids=[executable for _, executable, _ in EXECUTABLES])
def test_help_prints_usage_and_defaults_and_exits(ros_workspace, package, executable, expected):
    result = subprocess.run(['ros2', 'run', package, executable, '--help'],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.startswith('usage:'), result.stdout[:500]
    for text in expected:
        assert text in result.stdout, f'{text!r} missing from:\n{result.stdout}'
    assert 'Traceback' not in result.stderr
    assert "'option_strings'" not in result.stdout, 'argparse printed an action, not a help'
