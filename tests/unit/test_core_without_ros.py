"""Every core module imports without rclpy or message packages (only the nodes need ROS)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {'sessgan_core': ROOT / 'sessgan_core', 'sessgan_gen': ROOT / 'sessgan_gen',
            'sessgan_sim': ROOT / 'sessgan_sim',
            'sessgan_evolver': ROOT / 'sessgan_evolver',
            'sessgan_controllers': ROOT / 'controllers'}
# Modules that are ROS adapters by design: nodes, CLIs that start nodes, message conversion;
# and subpackages that are (sessgan_sim.worker: the simulator node's side, in parts).
ROS_MODULES = {'sessgan_gen.generator_node', 'sessgan_core.ros_conversion',
               'sessgan_sim.simulator_node', 'sessgan_sim.ros_messages',
               'sessgan_controllers.controller_node', 'sessgan_controllers.messages',
               'sessgan_evolver.campaign_cli', 'sessgan_evolver.replay_cli'}
ROS_SUBPACKAGES = {'sessgan_sim.worker'}
BLOCKED = ['rclpy', 'std_msgs', 'geometry_msgs', 'nav_msgs', 'sensor_msgs', 'rosgraph_msgs',
           'tf2_msgs', 'builtin_interfaces', 'sessgan_interfaces']


def all_modules() -> list[str]:
    """Every module of every package, subpackages included (a subpackage by its name)."""
    modules = []
    for package, root in PACKAGES.items():
        for path in (root / package).rglob('*.py'):
            parts = path.relative_to(root).with_suffix('').parts
            modules.append('.'.join(parts[:-1] if parts[-1] == '__init__' else parts))
    return sorted(modules)


def core_modules() -> list[str]:
    return [name for name in all_modules()
            if name not in PACKAGES and name not in ROS_MODULES
            and not any(name.startswith(f'{package}.') for package in ROS_SUBPACKAGES)]


def test_every_ros_exemption_names_a_module_that_exists():
    # A renamed adapter must not leave its old name exempt and its new one unchecked.
    assert ROS_MODULES | ROS_SUBPACKAGES <= set(all_modules())
    assert 'sessgan_sim.worker.stepping' in all_modules()  # subpackages are found


def test_core_modules_import_without_ros():
    script = (
        'import sys\n'
        f'for name in {BLOCKED!r}:\n'
        '    sys.modules[name] = None  # any import of it raises ImportError\n'
        f'for module in {core_modules()!r}:\n'
        '    __import__(module)\n')
    paths = [str(root) for root in PACKAGES.values()]
    result = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                            env={'PYTHONPATH': ':'.join(paths), 'PATH': '/usr/bin:/bin'},
                            timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert len(core_modules()) > 30
