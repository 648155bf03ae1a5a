"""Every core module imports without rclpy or message packages (only the nodes need ROS)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {'sessgan_gen': ROOT / 'sessgan_gen', 'sessgan_sim': ROOT / 'sessgan_sim',
            'sessgan_evolver': ROOT / 'sessgan_evolver',
            'sessgan_controllers': ROOT / 'controllers'}
# Modules that are ROS adapters by design: nodes, CLIs that start nodes, message conversion.
ROS_MODULES = {'generator_node', 'ros_conversion', 'simulator_node', 'ros_messages',
               'controller_node', 'messages', 'campaign_cli', 'replay_cli'}
BLOCKED = ['rclpy', 'std_msgs', 'geometry_msgs', 'nav_msgs', 'sensor_msgs', 'rosgraph_msgs',
           'tf2_msgs', 'builtin_interfaces', 'sessgan_interfaces']


def core_modules() -> list[str]:
    return sorted(f'{package}.{path.stem}' for package, root in PACKAGES.items()
                  for path in (root / package).glob('*.py')
                  if path.stem not in ROS_MODULES and path.stem != '__init__')


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
