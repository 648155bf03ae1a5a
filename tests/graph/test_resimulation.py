"""`replay --resimulate` rebuilds the simulator a failure was found with, from episode.json, for
built-in and external controllers."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import pytest

from tests.graph.test_simulator_graph import (
    environment_msg,
    evaluate,
    room,
    start_controller,
    start_external,
    start_simulator,
)

pytestmark = pytest.mark.graph

NON_DEFAULT = ('dummy_agents:=0', 'lidar_beams:=90', 'lidar_fov_deg:=240.0',
               'lidar_range_max:=4.0', 'lidar_noise_std:=0.03', 'control_rate:=10.0',
               'physics_rate:=50.0', 'robot_params:=max_linear_speed=0.6',
               'sim_time_origin:=500.0')
"""Settings that change what the controller sees and how the robot moves."""


def resimulate(bag: str, *options: str, timeout: float = 240.0) -> subprocess.CompletedProcess:
    return subprocess.run(['ros2', 'run', 'sessgan_evolver', 'replay', bag, '--resimulate',
                           *options], capture_output=True, text=True, timeout=timeout)


def table(stdout: str) -> dict[str, tuple[str, str]]:
    """The comparison table replay prints: {row: (recorded, re-simulated)}."""
    rows = {}
    for line in stdout.splitlines():
        match = re.match(r'(\w[\w ]*?)\s{2,}(\S+)\s+(\S+)$', line)
        if match:
            rows[match.group(1).strip()] = (match.group(2), match.group(3))
    return rows


def replay_all(bag: str, messages: int, namespace: str) -> None:
    """Replay re-publishes all ``messages`` of ``bag`` (at 20x, under ``namespace``)."""
    run = subprocess.run(['ros2', 'run', 'sessgan_evolver', 'replay', bag, '--rate', '20',
                          '--namespace', namespace], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    assert f'replayed {messages} messages' in run.stdout + run.stderr


def resimulate_same(bag: str, *options: str) -> dict[str, tuple[str, str]]:
    """Re-simulate ``bag`` and check the episode comes out the same (lockstep); the table."""
    run = resimulate(bag, *options)
    assert run.returncode == 0, run.stdout + run.stderr
    rows = table(run.stdout)
    for row in ('outcome', 'collisions', 'sim time', 'travelled m', 'ticks', 'legs completed'):
        recorded, again = rows[row]
        assert recorded == again, (row, run.stdout)
    return rows


def factory_example():
    from sessgan_core.token_map import load_example_map

    return environment_msg(load_example_map('factory').cells, 'factory', 'factory-example')


def test_failure_found_with_non_default_settings_resimulates_exactly(node_processes, ros_node,
                                                                     tmp_path):
    start_simulator(node_processes, '/rs', *NON_DEFAULT, f'bags_root:={tmp_path}')
    start_controller(node_processes, '/rs', 'nearness_diagram')
    # Ten seconds are not enough to cross the factory: a failure in a valid test (a timeout,
    # or a collision before it), whose trajectory depends on every setting above.
    metrics, _ = evaluate(ros_node, '/rs', factory_example(), time_limit=10.0,
                          record_directory='bags', timeout=300)
    assert metrics.bag_path, (metrics.outcome, metrics.detail)
    episode = json.loads((tmp_path / 'bags' / 'factory-example' / 'episode.json').read_text())
    assert episode['simulator']['lidar_beams'] == 90 and episode['mode'] == 'lockstep'
    assert episode['episode_config']['robot_params']['max_linear_speed'] == 0.6
    assert episode['sim_time_origin'] == 500.0

    # The test's evaluate client names its controller 'test': say which built-in one it was.
    run = resimulate(metrics.bag_path, '--controller', 'nearness_diagram')
    assert run.returncode == 0, run.stdout + run.stderr
    assert 'lidar_beams=90' in run.stderr  # rebuilt from the recorded settings
    rows = table(run.stdout)
    for row in ('outcome', 'collisions', 'fault collisions', 'sim time', 'travelled m', 'ticks',
                'risk score'):
        recorded, again = rows[row]
        assert recorded == again, (row, run.stdout)

    # The settings matter: the same episode on a default simulator goes elsewhere.
    start_simulator(node_processes, '/rs_default', 'dummy_agents:=0')
    start_controller(node_processes, '/rs_default', 'nearness_diagram')
    default, _ = evaluate(ros_node, '/rs_default', factory_example(), time_limit=10.0,
                          timeout=300)
    assert f'{default.distance_travelled:.3f}' != rows['travelled m'][0]


def test_failure_with_an_external_controller_resimulates_with_one_flag(node_processes, ros_node,
                                                                       tmp_path):
    # An external controller under /ext_rs: it drives blind into the wall.
    simulator = start_simulator(node_processes, '/ext_rs', *NON_DEFAULT,
                                f'bags_root:={tmp_path}')
    controller = start_external(node_processes, '/ext_rs', '--blind')
    metrics, _ = evaluate(ros_node, '/ext_rs', environment_msg(room(), 'factory', 'wall'),
                          time_limit=20.0, record_directory='bags')
    assert metrics.fault_collisions > 0 and metrics.bag_path, metrics.detail

    # Without the flag: a clear error naming it.
    run = resimulate(metrics.bag_path)
    assert run.returncode == 2 and '--external' in run.stderr, run.stderr
    # The recording worker still runs there: refused, not doubled.
    run = resimulate(metrics.bag_path, '--external')
    assert run.returncode == 2 and 'already serves /ext_rs/evaluate' in run.stderr, run.stderr

    simulator.process.terminate()
    simulator.wait(timeout=10)
    run = resimulate(metrics.bag_path, '--external')  # the recorded namespace: /ext_rs
    assert run.returncode == 0, run.stdout + run.stderr
    rows = table(run.stdout)
    for row in ('outcome', 'collisions', 'fault collisions', 'sim time', 'travelled m', 'ticks'):
        recorded, again = rows[row]
        assert recorded == again, (row, run.stdout)

    from sessgan_evolver.bag_reading import bag_directory

    # With the controller gone every try ends controller_unresponsive, an outcome of the
    # harness: run again, never compared, and after the last an error. (A copy of the bag
    # whose simulator waits 1 s for a controller, not the recorded 15 s.)
    controller.process.terminate()
    controller.wait(timeout=10)
    silent = tmp_path / 'silent'
    shutil.copytree(bag_directory(metrics.bag_path), silent)
    episode = json.loads((silent / 'episode.json').read_text())
    episode['simulator']['controller_startup_timeout'] = 1.0
    (silent / 'episode.json').write_text(json.dumps(episode))
    run = resimulate(str(silent), '--external')
    assert run.returncode == 2, run.stdout + run.stderr
    assert run.stderr.count('the harness, not the controller; running it again') == 2, run.stderr
    assert 'ended every one of 3 tries' in run.stderr and 'controller_unresponsive' in run.stderr
    assert 'outcome' not in table(run.stdout), run.stdout  # nothing compared
