"""The shipped Nav2 configuration (sessgan_sim/config/nav2_params.yaml and
sessgan_sim/launch/nav2_worker.launch.py) against the simulator's contract.

Nav2 cannot be installed on this project's machines, so the files are checked statically: the
YAML is parsed, the launch file read as Python source (``launch`` is not installed either)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import yaml

from sessgan_core.scenarios import get_scenario
from sessgan_sim.robots import DiffDriveParams
from sessgan_sim.simulator_settings import GoalInterface, SimulatorSettings, StepMode

pytestmark = pytest.mark.unit

PACKAGE = Path(__file__).resolve().parents[3] / 'sessgan_sim'
PARAMS = PACKAGE / 'config' / 'nav2_params.yaml'
LAUNCH = PACKAGE / 'launch' / 'nav2_worker.launch.py'


def module_constants(path: Path) -> dict:
    """Module-level NAME = <literal> assignments of a Python file, without importing it."""
    constants = {}
    for statement in ast.parse(path.read_text()).body:
        if isinstance(statement, ast.Assign) and len(statement.targets) == 1 and isinstance(
                statement.targets[0], ast.Name):
            try:
                constants[statement.targets[0].id] = ast.literal_eval(statement.value)
            except ValueError:
                pass
    return constants


CONTRACT = module_constants(PACKAGE / 'sessgan_sim' / 'frames.py')
MAP, ODOM, BASE = CONTRACT['MAP_FRAME'], CONTRACT['ODOM_FRAME'], CONTRACT['BASE_FOOTPRINT']
RESET_SERVICES = module_constants(
    PACKAGE / 'sessgan_sim' / 'worker' / 'nav2_stack.py')['RESET_SERVICES']


@pytest.fixture(scope='module')
def nodes() -> dict[str, dict]:
    """ros__parameters of every node, by its name below the /** (any namespace) key."""
    document = yaml.safe_load(PARAMS.read_text())
    assert list(document) == ['/**'], 'one wildcard root: the file serves any namespace'
    found = {}

    def collect(prefix: str, tree: dict) -> None:
        for key, value in tree.items():
            if key == 'ros__parameters':
                found[prefix] = value
            elif isinstance(value, dict):
                collect(f'{prefix}/{key}' if prefix else key, value)

    collect('', document['/**'])
    return found


def launch_calls(function: str) -> list[ast.Call]:
    tree = ast.parse(LAUNCH.read_text())
    return [node for node in ast.walk(tree)
            if isinstance(node, ast.Call) and getattr(node.func, 'id', '') == function]


def keyword(call: ast.Call, name: str):
    return next((k.value for k in call.keywords if k.arg == name), None)


def test_every_node_runs_on_sim_time(nodes):
    assert set(nodes) == {'bt_navigator', 'controller_server', 'planner_server',
                          'behavior_server', 'local_costmap/local_costmap',
                          'global_costmap/global_costmap', 'lifecycle_manager_navigation'}
    for name, parameters in nodes.items():
        assert parameters.get('use_sim_time') is True, name


def test_frames_are_the_contract_frames(nodes):
    assert (MAP, ODOM, BASE) == ('map', 'odom', 'base_footprint')
    expected = {
        'bt_navigator': {'global_frame': MAP, 'robot_base_frame': BASE},
        'behavior_server': {'global_frame': MAP, 'local_frame': ODOM, 'robot_base_frame': BASE},
        'local_costmap/local_costmap': {'global_frame': ODOM, 'robot_base_frame': BASE},
        'global_costmap/global_costmap': {'global_frame': MAP, 'robot_base_frame': BASE},
    }
    for name, frames in expected.items():
        for key, frame in frames.items():
            assert nodes[name][key] == frame, (name, key)

    # No other frame anywhere (a stray base_link or a namespaced frame would break tf lookups).
    def frame_values(tree):
        for key, value in tree.items():
            if isinstance(value, dict):
                yield from frame_values(value)
            elif key.endswith('frame'):
                yield value

    for name, parameters in nodes.items():
        assert set(frame_values(parameters)) <= {MAP, ODOM, BASE}, name


def test_topics_are_the_contract_topics_and_relative(nodes):
    for costmap in ('local_costmap/local_costmap', 'global_costmap/global_costmap'):
        parameters = nodes[costmap]
        obstacles = parameters['obstacle_layer']
        assert obstacles['observation_sources'] == 'scan'
        source = obstacles['scan']
        assert source['topic'] == 'scan' and source['data_type'] == 'LaserScan'
        assert source['inf_is_valid'] is True  # the simulator's no-return beams are +inf
        assert source['obstacle_max_range'] <= SimulatorSettings().lidar_range_max
        for layer in parameters['plugins']:
            assert 'plugin' in parameters[layer], (costmap, layer)
    static = nodes['global_costmap/global_costmap']['static_layer']
    assert static['map_topic'] == 'map' and static['map_subscribe_transient_local'] is True
    assert nodes['bt_navigator']['odom_topic'] == 'odom'
    assert nodes['controller_server']['odom_topic'] == 'odom'
    behaviors = nodes['behavior_server']
    for key in ('local_costmap_topic', 'global_costmap_topic', 'local_footprint_topic',
                'global_footprint_topic'):
        assert not behaviors[key].startswith('/'), key
    # Twist, the simulator's default cmd_vel type.
    assert nodes['controller_server']['enable_stamped_cmd_vel'] is SimulatorSettings(
    ).use_stamped_cmd_vel


def test_robot_and_rates_match_the_factory_scenario(nodes):
    scenario = get_scenario('factory')
    robot = DiffDriveParams()
    assert scenario.robot == 'diff_drive' and robot.radius == scenario.robot_radius
    for costmap in ('local_costmap/local_costmap', 'global_costmap/global_costmap'):
        assert nodes[costmap]['robot_radius'] == scenario.robot_radius
    assert nodes['global_costmap/global_costmap']['resolution'] == scenario.cell_size
    controller = nodes['controller_server']
    assert controller['controller_frequency'] == SimulatorSettings().control_rate
    follow = controller['FollowPath']
    assert follow['desired_linear_vel'] <= robot.max_linear_speed
    assert follow['rotate_to_heading_angular_vel'] <= robot.max_angular_speed
    assert follow['max_angular_accel'] <= robot.max_angular_acceleration
    # Nav2 stops within its tolerance, inside the simulator's (one cell): goal_reached.
    assert controller['general_goal_checker']['xy_goal_tolerance'] < scenario.cell_size
    for plugin_list, in (('controller_plugins',), ('goal_checker_plugins',),
                         ('progress_checker_plugins',)):
        for name in controller[plugin_list]:
            assert 'plugin' in controller[name], name
    planner = nodes['planner_server']
    assert all('plugin' in planner[name] for name in planner['planner_plugins'])
    behaviors = nodes['behavior_server']
    assert all('plugin' in behaviors[name] for name in behaviors['behavior_plugins'])


def test_costmap_nodes_serve_the_resets_the_simulator_calls(nodes):
    # Nav2 names each costmap's service clear_entirely_<costmap name>, under the node.
    served = {f'{name.split("/")[0]}/clear_entirely_{name.split("/")[1]}'
              for name in nodes if name.endswith('costmap')}
    assert served == set(RESET_SERVICES)


def test_launch_file_starts_nav2_against_one_worker(nodes):
    constants = module_constants(LAUNCH)
    lifecycle = constants['LIFECYCLE_NODES']
    assert lifecycle == nodes['lifecycle_manager_navigation']['node_names']
    assert [name for _, _, name in constants['NAV2_NODES']] == lifecycle
    assert set(lifecycle) <= set(nodes)
    assert {('/tf', 'tf'), ('/tf_static', 'tf_static'), ('/clock', 'clock')} <= set(
        constants['REMAPPINGS'])

    every_node = launch_calls('Node')
    assert len(every_node) == 3  # the worker, the NAV2_NODES comprehension, lifecycle manager
    for call in every_node:
        assert isinstance(keyword(call, 'namespace'), ast.Name), 'every node under namespace'
    calls = [call for call in every_node if isinstance(keyword(call, 'package'), ast.Constant)]
    packages = [ast.literal_eval(keyword(call, 'package')) for call in calls]
    assert packages == ['sessgan_sim', 'nav2_lifecycle_manager'], packages
    for call in calls:
        assert isinstance(keyword(call, 'namespace'), ast.Name), 'every node under namespace'
    lifecycle_call = calls[1]
    assert ast.unparse(keyword(lifecycle_call, 'remappings')) == 'REMAPPINGS'
    nav2_call = next(node for node in ast.walk(ast.parse(LAUNCH.read_text()))
                     if isinstance(node, ast.ListComp))
    assert ast.unparse(keyword(nav2_call.elt, 'remappings')) == 'REMAPPINGS'
    assert ast.unparse(keyword(nav2_call.elt, 'parameters')) == '[params_file]'

    # The worker: every parameter is one the simulator has, with a usable value.
    parameters = keyword(calls[0], 'parameters').elts[0]
    literal = {ast.literal_eval(k): ast.literal_eval(v) for k, v in
               zip(parameters.keys, parameters.values) if isinstance(v, ast.Constant)}
    settings = SimulatorSettings.from_values(literal)
    assert settings.step_mode is StepMode.CLOCKED
    assert settings.goal_via is GoalInterface.NAVIGATE_TO_POSE
    assert settings.reset_costmaps is True
    # A stuck window that outlasts Nav2's progress checker and a recovery after it.
    checker = nodes['controller_server']['progress_checker']
    assert settings.stuck_timeout >= checker['movement_time_allowance'] + 20.0
    dynamic = {ast.literal_eval(k) for k, v in zip(parameters.keys, parameters.values)
               if not isinstance(v, ast.Constant)}
    assert dynamic == {'real_time_factor'}

    # The default params file is the one checked above, installed with the package.
    source = LAUNCH.read_text()
    assert "FindPackageShare('sessgan_sim'), 'config', 'nav2_params.yaml'" in source
    setup = (PACKAGE / 'setup.py').read_text()
    assert "['config/nav2_params.yaml']" in setup
    assert "['launch/nav2_worker.launch.py']" in setup
