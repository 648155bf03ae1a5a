"""The simulator node's parameters, validated in one place (sessgan_sim.simulator_settings)."""

from __future__ import annotations

import math

import pytest

from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.simulator_settings import (
    STRUCTURAL_SETTINGS,
    GoalInterface,
    SimulatorSettings,
    StepMode,
    episode_config_record,
    resimulation_settings,
)

pytestmark = pytest.mark.unit


def test_defaults_are_valid_and_build_the_reference_episode():
    settings = SimulatorSettings.from_values({})
    assert settings.step_mode is StepMode.LOCKSTEP
    assert settings.goal_via is GoalInterface.GOAL_POSE
    config = settings.episode_config()
    assert config.control_rate_hz == 20.0 and config.physics_rate_hz == 100.0
    assert config.lidar.beams == 360 and config.lidar.field_of_view == pytest.approx(2 * math.pi)
    assert config.lidar.rate_hz == 20.0  # lidar_rate 0: the control rate
    assert config.robot is None and config.dummy_agents is None and config.time_limit is None


@pytest.mark.parametrize('values, named', [
    ({'mode': 'clockd'}, "'mode' must be one of lockstep, clocked; got 'clockd'"),
    ({'goal_interface': 'nav2'}, "'goal_interface' must be one of goal_pose"),
    ({'mission_stations': -1}, 'mission_stations must be an integer in 0..16'),
    ({'mission_stations': 17}, 'mission_stations must be an integer in 0..16'),
    ({'station_dwell_time': -1.0}, 'station_dwell_time must be >= 0 s'),
    ({'robots': 0}, 'robots must be an integer in 1..8'),
    ({'robots': 9}, 'robots must be an integer in 1..8'),
    ({'robots': 2, 'mission_stations': 1}, 'robots=2 cannot be combined with mission_stations'),
    ({'bag_storage': 'rosbag'}, "'bag_storage' must be one of mcap, sqlite3"),
    ({'real_time_factor': 0.0}, "'real_time_factor' must be > 0"),
    ({'lidar_beams': 0}, "'lidar_beams' must be in 1..16384"),
    ({'lidar_beams': 'many'}, "'lidar_beams' must be an integer, got 'many'"),
    ({'lidar_beams': 3.5}, "'lidar_beams' must be an integer"),
    ({'control_rate': True}, "'control_rate' must be a number"),
    ({'control_rate': math.inf}, "'control_rate' must be a finite number"),
    ({'free_mode': 1}, "'free_mode' must be true or false"),
    ({'lidar_fov_deg': 400.0}, "'lidar_fov_deg' must be in (0, 360]"),
    ({'lidar_range_min': 5.0, 'lidar_range_max': 4.0}, "'lidar_range_max' (4.0) must exceed"),
    ({'control_rate': 50.0, 'physics_rate': 40.0}, "'physics_rate' (40.0) must be at least"),
    ({'dummy_agents': -2}, "'dummy_agents' must be >= 0, or -1"),
    ({'scenario': 'moon'}, "'scenario': unknown scenario 'moon'"),
    ({'robot': 'tank'}, 'unknown robot'),
    ({'robot': 'diff_drive', 'robot_params': 'max_speed=1'}, "no parameter(s) ['max_speed']"),
    ({'robot_params': 'max_linear_speed'}, "'max_linear_speed' is not name=number"),
    ({'robot_params': 'a=1,a=2'}, "sets 'a' twice"),
    ({'sim_time_origin': -1.0}, "'sim_time_origin' must be >= 0"),
    ({'lidar_beam': 10}, "unknown simulator parameter(s) ['lidar_beam']"),
])
def test_every_bad_parameter_is_named(values, named):
    with pytest.raises(InvalidConfigError) as caught:
        SimulatorSettings.from_values(values)
    assert named in str(caught.value)


def test_numbers_of_either_kind_are_accepted_where_a_float_is_meant():
    settings = SimulatorSettings.from_values({'real_time_factor': 3, 'control_rate': 10})
    assert settings.real_time_factor == 3.0 and isinstance(settings.real_time_factor, float)


def test_non_default_settings_reach_the_episode_config():
    settings = SimulatorSettings.from_values({
        'robot': 'diff_drive', 'robot_params': 'max_linear_speed=0.5, max_angular_speed=1.5',
        'control_rate': 10.0, 'physics_rate': 50.0, 'lidar_beams': 90, 'lidar_fov_deg': 180.0,
        'lidar_range_min': 0.2, 'lidar_range_max': 4.0, 'lidar_rate': 5.0,
        'lidar_noise_std': 0.0, 'dummy_agents': 1, 'agent_speed': 0.3, 'stuck_timeout': 4.0,
        'collision_limit': 3, 'time_limit': 30.0, 'agent_behaviour': 'cautious',
        'goal_tolerance': 0.25})
    config = settings.episode_config(seed=7)
    assert config.goal_tolerance == 0.25  # 0 (the default): the scenario's one cell
    assert SimulatorSettings().episode_config().goal_tolerance is None
    with pytest.raises(InvalidConfigError, match='goal_tolerance'):
        SimulatorSettings.from_values({'goal_tolerance': -1.0})
    assert config.robot == 'diff_drive'
    assert config.robot_params == {'max_linear_speed': 0.5, 'max_angular_speed': 1.5}
    assert (config.control_rate_hz, config.physics_rate_hz) == (10.0, 50.0)
    lidar = config.lidar
    assert (lidar.beams, lidar.range_min, lidar.range_max, lidar.rate_hz, lidar.noise_std) == (
        90, 0.2, 4.0, 5.0, 0.0)
    assert lidar.field_of_view == pytest.approx(math.pi)
    assert config.dummy_agents == 1 and config.agents.speed == 0.3
    assert config.agents.behaviour == 'cautious'
    with pytest.raises(InvalidConfigError, match='agent_behaviour'):
        SimulatorSettings.from_values({'agent_behaviour': 'reckless'})
    assert (config.stuck_timeout, config.collision_limit, config.time_limit, config.seed) == (
        4.0, 3, 30.0, 7)
    # An evaluate goal's robot and time limit win over the parameters.
    assert settings.episode_config(robot='flyer', time_limit=5.0).robot == 'flyer'
    assert settings.episode_config(robot='flyer', time_limit=5.0).time_limit == 5.0
    assert settings.changed_from_defaults()['lidar_beams'] == 90


def recorded_episode(settings: SimulatorSettings, scenario: str = 'factory') -> dict:
    """What a failure bag's episode.json holds about its simulator."""
    from sessgan_core.scenarios import get_scenario

    config = settings.episode_config(seed=11).resolved(get_scenario(scenario))
    return {'scenario': scenario, 'robot': config.robot, 'time_limit': config.time_limit,
            'episode_seed': 11, 'sim_time_origin': 12.35, 'simulator': settings.to_dict(),
            'episode_config': episode_config_record(config)}


def test_resimulation_rebuilds_the_recorded_settings_and_clock():
    recorded = SimulatorSettings.from_values({
        'lidar_beams': 90, 'lidar_fov_deg': 270.0, 'robot_params': 'max_linear_speed=0.6',
        'free_mode': True, 'bags_root': '/srv/bags', 'record_directory': 'free'})
    episode = recorded_episode(recorded)
    assert episode['episode_config']['robot_params']['max_linear_speed'] == 0.6
    assert episode['episode_config']['robot_params']['max_reverse_speed'] == 0.3  # the model's
    settings, notes = resimulation_settings(episode)
    assert settings.lidar_beams == 90 and settings.lidar_fov_deg == 270.0
    assert settings.robot_params == 'max_linear_speed=0.6'
    assert settings.sim_time_origin == 12.35
    assert not settings.free_mode and settings.record_directory == ''  # the worker's own
    assert settings.bags_root == 'bags'
    assert notes == []


@pytest.mark.parametrize('record_directory', ['/tmp/bags', '../outside', 'run/../..', 'a b'])
def test_the_free_mode_record_directory_must_stay_under_the_bags_root(record_directory):
    with pytest.raises(InvalidConfigError, match="parameter 'record_directory'.*relative"):
        SimulatorSettings.from_values({'record_directory': record_directory})
    assert SimulatorSettings.from_values({'record_directory': 'free/run1'}).bags_root == 'bags'


def test_the_bags_root_is_fixed_at_start_up_and_not_empty():
    assert 'bags_root' in STRUCTURAL_SETTINGS  # a read-only parameter: no client moves it
    with pytest.raises(InvalidConfigError, match="parameter 'bags_root'"):
        SimulatorSettings.from_values({'bags_root': ''})


def test_resimulation_refuses_settings_that_no_longer_build_the_recorded_episode():
    episode = recorded_episode(SimulatorSettings.from_values({'lidar_beams': 90}))
    episode['episode_config']['lidar']['beams'] = 45  # as if recorded by another version
    with pytest.raises(InvalidConfigError, match=r"differs in \['lidar'\]"):
        resimulation_settings(episode)


def test_resimulation_says_what_cannot_be_exact():
    clocked = recorded_episode(SimulatorSettings.from_values({'mode': 'clocked'}))
    assert any('clocked' in note for note in resimulation_settings(clocked)[1])
    settings, notes = resimulation_settings({'scenario': 'factory'})  # an older bag
    assert settings == SimulatorSettings() and 'default simulator' in notes[0]
