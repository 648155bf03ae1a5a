"""The simulator, the controllers and the core they share load no torch, no matplotlib and
nothing of sessgan_gen (the GAN, which needs both): sessgan_core is all they take from it."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.unit.test_core_without_ros import BLOCKED, ROS_MODULES, ROS_SUBPACKAGES

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]
# The packages that must stay torch-free, and where their code lives.
PACKAGES = {'sessgan_core': ROOT / 'sessgan_core', 'sessgan_sim': ROOT / 'sessgan_sim',
            'sessgan_controllers': ROOT / 'controllers'}
FORBIDDEN = ['torch', 'matplotlib', 'sessgan_gen']


def package_modules(package: str) -> list[str]:
    """Every module of ``package``, subpackages included (a subpackage by its name)."""
    root = PACKAGES[package]
    modules = []
    for path in (root / package).rglob('*.py'):
        parts = path.relative_to(root).with_suffix('').parts
        modules.append('.'.join(parts[:-1] if parts[-1] == '__init__' else parts))
    return sorted(modules)


def is_ros_adapter(module: str) -> bool:
    return module in ROS_MODULES or any(
        module == package or module.startswith(f'{package}.') for package in ROS_SUBPACKAGES)


def first_importers(modules: list[str], block_ros: bool) -> dict[str, str]:
    """In a fresh interpreter, import ``modules`` in turn; for each forbidden package that gets
    loaded, the first module whose import loaded it."""
    script = (
        'import json, sys\n'
        f'for name in {BLOCKED if block_ros else []!r}:\n'
        '    sys.modules[name] = None  # any import of it raises ImportError\n'
        'found = {}\n'
        f'for module in {modules!r}:\n'
        '    __import__(module)\n'
        f'    for name in {FORBIDDEN!r}:\n'
        '        if name in sys.modules and name not in found:\n'
        '            found[name] = module\n'
        'print(json.dumps(found))\n')
    # sessgan_gen is on the path too, so that importing it shows here by name rather than
    # as a missing module.
    paths = [str(root) for root in PACKAGES.values()] + [str(ROOT / 'sessgan_gen')]
    if block_ros:  # as the ROS-free test: nothing of the workspace or a sourced ROS
        env = {'PATH': '/usr/bin:/bin', 'PYTHONPATH': ':'.join(paths)}
    else:
        env = dict(os.environ)
        env['PYTHONPATH'] = ':'.join([*paths, env.get('PYTHONPATH', '')])
    result = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                            env=env, timeout=180)
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_the_core_simulator_and_controllers_load_no_torch():
    modules = [module for package in PACKAGES for module in package_modules(package)
               if not is_ros_adapter(module)]
    assert first_importers(modules, block_ros=True) == {}
    # The scan found the packages, their subpackages included.
    assert {'sessgan_sim.episode', 'sessgan_controllers.reference_navigator'} <= set(modules)
    assert len(modules) > 40


def test_their_ros_adapters_load_no_torch_either():
    # What `ros2 run sessgan_sim simulator` and the controller nodes import, worker included.
    if importlib.util.find_spec('sessgan_interfaces') is None:
        pytest.skip('the ROS workspace is not sourced (source setup.bash)')
    adapters = [module for package in PACKAGES for module in package_modules(package)
                if is_ros_adapter(module)]
    assert {'sessgan_sim.simulator_node', 'sessgan_sim.worker.stepping',
            'sessgan_controllers.controller_node'} <= set(adapters)
    assert first_importers(adapters, block_ros=False) == {}
