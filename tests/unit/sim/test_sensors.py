"""Lidar geometry and readings, seeded noise, what each robot sees, odometry and clearance."""

import math

import numpy as np
import pytest

from sessgan_gen.environment import Environment, Pose2D
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.robots import VelocityCommand
from sessgan_sim.sensors import LidarConfig

pytestmark = pytest.mark.unit

VALUES = {'#': 100, 'O': 50, '.': 0}
ROOM = ['############', '#..........#', '#..........#', '#..........#', '#..........#',
        '#..........#', '#..........#', '#..........#', '#..........#', '############']
"""Interior x in [0.5, 5.5] m, y in [0.5, 4.5] m (0.5 m cells)."""
INSIDE = (0.5, 0.5, 5.5, 4.5)


def environment(rows, start, scenario='factory', goal=(5.0, 4.0)) -> Environment:
    grid = np.array([[VALUES[char] for char in row] for row in reversed(rows)], dtype=np.int8)
    return Environment('sensors', scenario, grid, 0.5, Pose2D(*start), Pose2D(*goal))


def config(**overrides) -> EpisodeConfig:
    base = {'lidar': LidarConfig(noise_std=0.0), 'dummy_agents': 0, 'stuck_timeout': 0.0,
            'collision_limit': 0, 'time_limit': 100.0}
    base.update(overrides)
    return EpisodeConfig(**base)


def ranges_in_box(x, y, angles, box):
    """Exact ranges from (x, y) to the inside walls of an axis-aligned box."""
    x_min, y_min, x_max, y_max = box
    cos, sin = np.cos(angles), np.sin(angles)
    with np.errstate(divide='ignore'):
        to_x = np.where(cos > 0, (x_max - x) / cos, np.where(cos < 0, (x_min - x) / cos, np.inf))
        to_y = np.where(sin > 0, (y_max - y) / sin, np.where(sin < 0, (y_min - y) / sin, np.inf))
    return np.minimum(to_x, to_y)


@pytest.fixture
def episode():
    with Episode() as running:
        yield running


def test_full_turn_geometry_does_not_repeat_the_first_beam():
    info = LidarConfig().info
    assert info.beams == 360
    assert info.angle_min == pytest.approx(-math.pi)
    assert info.angle_increment == pytest.approx(2 * math.pi / 360)
    assert info.angle_max == pytest.approx(math.pi - 2 * math.pi / 360)
    assert info.scan_time == pytest.approx(0.05)


def test_partial_field_of_view_spans_both_edges():
    info = LidarConfig(beams=181, field_of_view=math.pi).info
    assert info.angle_min == pytest.approx(-math.pi / 2)
    assert info.angle_max == pytest.approx(math.pi / 2)
    assert info.angle_increment == pytest.approx(math.pi / 180)


@pytest.mark.parametrize('field, message', [
    ({'beams': 0}, 'beams'), ({'field_of_view': 7.0}, 'field_of_view'),
    ({'range_max': 0.1}, 'range_max'), ({'noise_std': -0.1}, 'noise_std'),
    ({'rate_hz': 0.0}, 'rate_hz')])
def test_bad_lidar_parameters_are_named(field, message):
    with pytest.raises(InvalidConfigError, match=message):
        LidarConfig(**field).validate()


@pytest.mark.parametrize('yaw', [0.0, 0.7, -2.0])
def test_ranges_match_the_room_geometry(episode, yaw):
    observation = episode.reset(environment(ROOM, (2.0, 1.7, yaw)), config())
    expected = ranges_in_box(2.0, 1.7, observation.lidar.angles() + yaw, INSIDE)
    assert observation.scan.dtype == np.float32
    assert observation.scan.shape == (360,)
    assert not observation.scan.flags.writeable
    np.testing.assert_allclose(observation.scan, expected, atol=1e-4)


def test_partial_field_of_view_looks_ahead(episode):
    lidar = LidarConfig(beams=181, field_of_view=math.pi, noise_std=0.0)
    observation = episode.reset(environment(ROOM, (2.0, 1.7, 0.0)), config(lidar=lidar))
    assert observation.scan[0] == pytest.approx(1.2, abs=1e-4)  # south wall, to the right
    assert observation.scan[90] == pytest.approx(3.5, abs=1e-4)  # east wall, ahead
    assert observation.scan[180] == pytest.approx(2.8, abs=1e-4)  # north wall, to the left


def test_no_return_reads_plus_inf_and_too_close_minus_inf(episode):
    observation = episode.reset(environment(ROOM, (2.0, 1.7, 0.0)),
                                config(lidar=LidarConfig(range_max=1.0, noise_std=0.0)))
    assert np.isposinf(observation.scan).all()
    observation = episode.reset(environment(ROOM, (2.0, 1.7, 0.0)),
                                config(lidar=LidarConfig(range_min=1.3, noise_std=0.0)))
    exact = ranges_in_box(2.0, 1.7, observation.lidar.angles(), INSIDE)
    assert (np.isneginf(observation.scan) == (exact < 1.3)).all()
    assert np.isneginf(observation.scan).any()


def test_the_robot_does_not_see_its_own_body(episode):
    observation = episode.reset(environment(ROOM, (2.0, 1.7, 0.0)),
                                config(lidar=LidarConfig(range_min=0.0, noise_std=0.0)))
    assert observation.scan.min() == pytest.approx(1.2, abs=1e-4)


def test_noise_is_gaussian_and_seeded(episode):
    env = environment(ROOM, (2.0, 1.7, 0.0))
    lidar = LidarConfig(noise_std=0.01)
    scans = []
    for seed in (5, 5, 6):
        scans.append(np.array(episode.reset(env, config(lidar=lidar, seed=seed)).scan))
    exact = ranges_in_box(2.0, 1.7, LidarConfig().info.angles(), INSIDE)
    np.testing.assert_array_equal(scans[0], scans[1])
    assert not np.array_equal(scans[0], scans[2])
    assert np.std(scans[0] - exact) == pytest.approx(0.01, rel=0.2)


def test_ground_robots_see_low_obstacles_and_the_flyer_sees_over_them(episode):
    rows = ['############', '#..........#', '#......OO..#', '#..........#', '############']
    env = environment(rows, (1.25, 1.25, 0.0), scenario='drone', goal=(5.0, 1.75))
    ahead = 180
    ground = episode.reset(env, config(robot='diff_drive'))
    assert ground.scan[ahead] == pytest.approx(3.5 - 1.25, abs=1e-4)
    flyer = episode.reset(env, config(robot='flyer'))
    assert flyer.scan[ahead] == pytest.approx(5.5 - 1.25, abs=1e-4)


def test_agents_show_up_in_the_scan(episode):
    rows = ['#' * 16] + ['#' + '.' * 14 + '#'] * 14 + ['#' * 16]  # all within range_max
    env = environment(rows, (1.25, 1.25, 0.0), goal=(6.0, 6.0))
    observation = episode.reset(env, config(dummy_agents=3, seed=2))
    angles = observation.lidar.angles()
    radius = episode.agents.config.radius
    assert len(episode.agents.positions) == 3
    for x, y in episode.agents.positions:
        bearing = math.atan2(y - 1.25, x - 1.25)
        beam = int(np.argmin(np.abs(np.angle(np.exp(1j * (angles - bearing))))))
        assert observation.scan[beam] <= math.hypot(x - 1.25, y - 1.25) - radius + 0.05


def test_odometry_reports_the_body_frame_twist(episode):
    episode.reset(environment(ROOM, (2.0, 1.0, math.pi / 2)), config())
    for _ in range(20):
        result = episode.step(VelocityCommand(0.5, 0.0, 0.0))
    observation = result.observation
    assert observation.twist.vx == pytest.approx(0.5, abs=1e-6)
    assert observation.twist.vy == pytest.approx(0.0, abs=1e-6)
    assert observation.pose.x == pytest.approx(2.0, abs=1e-6)
    assert observation.pose.y > 1.3
    assert observation.pose.yaw == pytest.approx(math.pi / 2, abs=1e-6)
    assert observation.time == pytest.approx(1.0)


def test_a_slower_lidar_updates_every_other_tick(episode):
    lidar = LidarConfig(rate_hz=10.0, noise_std=0.01)
    first = episode.reset(environment(ROOM, (2.0, 1.7, 0.0)), config(lidar=lidar))
    assert first.scan_updated
    updates, scans = [], [first.scan]
    for _ in range(6):
        observation = episode.step(VelocityCommand()).observation
        updates.append(observation.scan_updated)
        scans.append(observation.scan)
    assert updates == [False, True, False, True, False, True]
    assert scans[1] is scans[0] and scans[2] is not scans[1]


def test_clearance_below_the_proximity_distance_counts_as_proximity_time(episode):
    env = environment(ROOM, (2.0, 0.8, 0.0))  # 0.1 m between body and south wall
    episode.reset(env, config())
    for _ in range(20):
        episode.step(VelocityCommand())
    metrics = episode.metrics()
    assert metrics.proximity_time == pytest.approx(1.0)
    assert metrics.min_clearance == pytest.approx(0.1, abs=2e-3)
    assert metrics.collisions == 0


def test_min_clearance_is_capped_at_the_clearance_range(episode):
    env = environment(ROOM, (2.0, 1.1, 0.0))  # 0.4 m between body and south wall
    episode.reset(env, config())
    episode.step(VelocityCommand())
    assert episode.metrics().min_clearance == pytest.approx(0.25)  # the proximity distance
    episode.reset(env, config(clearance_range=1.0))
    episode.step(VelocityCommand())
    metrics = episode.metrics()
    assert metrics.min_clearance == pytest.approx(0.4, abs=2e-3)
    assert metrics.proximity_time == 0.0
