"""Robot registry and dynamics: limits, the bicycle model, the flyer's inertia, real contacts."""

import math

import numpy as np
import pytest

from sessgan_core.environment import Environment, Pose2D
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.errors import InvalidConfigError, UnknownRobotError
from sessgan_sim.metrics import Outcome
from sessgan_sim.robots import (
    ROBOTS,
    BodyCommand,
    CarRobot,
    DiffDriveRobot,
    FlyerRobot,
    TricycleRobot,
    create_robot,
    get_robot_class,
    robot_names,
)
from sessgan_sim.sensors import LidarConfig

pytestmark = pytest.mark.unit

VALUES = {'#': 100, 'O': 50, '.': 0}


def environment(rows: list[str], scenario: str, start: tuple[float, float, float],
                goal: tuple[float, float] | None = None) -> Environment:
    """An Environment from a picture (top row first) in the scenario's cells; without a goal,
    the goal is the free cell farthest from the start."""
    resolution = 1.0 if scenario == 'racetrack' else 0.5
    grid = np.array([[VALUES[char] for char in row] for row in reversed(rows)], dtype=np.int8)
    if goal is None:
        free = np.argwhere(grid == 0)
        centres = (free[:, ::-1] + 0.5) * resolution
        goal = tuple(centres[np.argmax(np.hypot(*(centres - start[:2]).T))])
    return Environment('robots', scenario, grid, resolution, Pose2D(*start), Pose2D(*goal))


def open_room(width: int, height: int) -> list[str]:
    return ['#' * width] + ['#' + '.' * (width - 2) + '#'] * (height - 2) + ['#' * width]


def config(**overrides) -> EpisodeConfig:
    base = {'lidar': LidarConfig(noise_std=0.0), 'dummy_agents': 0, 'stuck_timeout': 0.0,
            'collision_limit': 0, 'time_limit': 1000.0, 'goal_tolerance': 0.01}
    base.update(overrides)
    return EpisodeConfig(**base)


def drive(episode: Episode, command, seconds: float):
    """Apply a fixed command (or a function of the observation) for ``seconds``."""
    result = None
    for _ in range(round(seconds * episode.config.control_rate_hz)):
        observation = result.observation if result else None
        result = episode.step(command(observation) if callable(command) else command)
    return result.observation


@pytest.fixture
def episode():
    with Episode() as running:
        yield running


def test_registry_holds_the_four_robots():
    assert robot_names() == ['car', 'diff_drive', 'flyer', 'tricycle']
    assert ROBOTS['diff_drive'] is DiffDriveRobot
    assert ROBOTS['tricycle'] is TricycleRobot
    assert get_robot_class('car') is CarRobot
    assert get_robot_class('flyer') is FlyerRobot


def test_unknown_robot_lists_the_known_ones():
    with pytest.raises(UnknownRobotError) as error:
        create_robot('tank')
    assert str(error.value) == ("unknown robot 'tank'; known robots: car, diff_drive, flyer, "
                                'tricycle')
    assert isinstance(error.value, KeyError)


def test_parameter_overrides_are_checked():
    assert create_robot('car', {'max_speed': 5.0}).params.max_speed == 5.0
    with pytest.raises(InvalidConfigError, match='no parameter'):
        create_robot('car', {'top_speed': 5.0})
    with pytest.raises(InvalidConfigError, match='max_braking'):
        create_robot('car', {'max_braking': -1.0})


def test_diff_drive_respects_acceleration_and_speed_limits(episode):
    episode.reset(environment(open_room(40, 8), 'factory', (1.0, 2.0, 0.0)), config())
    observation = drive(episode, BodyCommand(5.0, 0.0, 0.0), 0.5)
    assert observation.twist.vx == pytest.approx(0.5, abs=0.011)  # 1 m/s^2 for 0.5 s
    observation = drive(episode, BodyCommand(5.0, 0.0, 0.0), 1.0)
    assert observation.twist.vx == pytest.approx(1.0, abs=1e-6)  # top speed
    assert observation.pose.x == pytest.approx(1.0 + 0.5 * 1.0 + 0.5, abs=0.02)


def test_diff_drive_cannot_move_sideways(episode):
    episode.reset(environment(open_room(12, 12), 'factory', (3.0, 3.0, 0.0)), config())
    observation = drive(episode, BodyCommand(0.0, 1.0, 0.0), 1.0)
    assert observation.pose.x == pytest.approx(3.0, abs=1e-6)
    assert observation.pose.y == pytest.approx(3.0, abs=1e-6)


def test_diff_drive_turn_rate_is_limited(episode):
    episode.reset(environment(open_room(12, 12), 'factory', (3.0, 3.0, 0.0)), config())
    observation = drive(episode, BodyCommand(0.0, 0.0, 10.0), 1.0)
    assert observation.twist.wz == pytest.approx(2.0, abs=1e-6)
    # 0.5 s ramp at 4 rad/s^2 (0.5 rad), then 0.5 s at 2 rad/s (1 rad).
    assert observation.pose.yaw == pytest.approx(1.5, abs=0.03)


def test_diff_drive_reverse_speed_is_limited(episode):
    episode.reset(environment(open_room(40, 8), 'factory', (15.0, 2.0, 0.0)), config())
    observation = drive(episode, BodyCommand(-2.0, 0.0, 0.0), 1.0)
    assert observation.twist.vx == pytest.approx(-0.3, abs=1e-6)


def test_tricycle_cannot_turn_in_place(episode):
    episode.reset(environment(open_room(12, 12), 'factory', (3.0, 3.0, 0.0)),
                  config(robot='tricycle'))
    observation = drive(episode, BodyCommand(0.0, 0.0, 2.0), 1.0)
    assert observation.pose.yaw == pytest.approx(0.0, abs=1e-6)
    assert (observation.pose.x, observation.pose.y) == pytest.approx((3.0, 3.0), abs=1e-6)


def test_tricycle_turns_no_tighter_than_its_radius(episode):
    episode.reset(environment(open_room(16, 16), 'factory', (2.0, 2.0, 0.0)),
                  config(robot='tricycle'))
    observation = drive(episode, BodyCommand(0.5, 0.0, 2.0), 1.0)  # speed up first
    observation = drive(episode, BodyCommand(0.5, 0.0, 2.0), 0.5)
    assert observation.twist.vx == pytest.approx(0.5, abs=1e-3)
    assert observation.twist.wz == pytest.approx(0.5 / 0.5, abs=1e-3)  # not 2 rad/s
    with pytest.raises(InvalidConfigError, match='tricycle: min_turn_radius'):
        create_robot('tricycle', {'min_turn_radius': 0.0})


def test_car_steering_follows_the_bicycle_model():
    car = CarRobot()
    params = car.params
    command = BodyCommand(2.0, 0.0, 1.0)
    assert car.target_steering(command) == pytest.approx(math.atan(params.wheelbase * 1.0 / 2.0))
    assert car.target_steering(BodyCommand(0.0, 0.0, 0.3)) == params.max_steering_angle
    assert car.target_steering(BodyCommand(0.0, 0.0, 0.0)) == 0.0
    reverse = car.target_steering(BodyCommand(-2.0, 0.0, 1.0))
    assert reverse == pytest.approx(-math.atan(params.wheelbase * 1.0 / 2.0))
    assert car.target_steering(BodyCommand(1.0, 0.0, 50.0)) == params.max_steering_angle


def test_car_accelerates_brakes_and_steers_within_limits(episode):
    env = environment(['#' * 130] + ['#' + '.' * 128 + '#'] * 20 + ['#' * 130], 'racetrack',
                      (3.0, 10.0, 0.0))
    episode.reset(env, config())
    observation = drive(episode, BodyCommand(20.0, 0.0, 0.0), 1.0)
    assert observation.twist.vx == pytest.approx(4.0, abs=0.05)  # 4 m/s^2
    observation = drive(episode, BodyCommand(20.0, 0.0, 0.0), 3.0)
    assert observation.twist.vx == pytest.approx(12.0, abs=1e-6)  # top speed
    x_braking = observation.pose.x
    observation = drive(episode, BodyCommand(0.0, 0.0, 0.0), 1.0)
    assert observation.twist.vx == pytest.approx(4.0, abs=0.05)  # 8 m/s^2 braking
    observation = drive(episode, BodyCommand(0.0, 0.0, 0.0), 1.0)
    assert observation.twist.vx == pytest.approx(0.0, abs=1e-6)
    assert observation.pose.x - x_braking == pytest.approx(12.0 ** 2 / (2 * 8.0), abs=0.2)
    # Steering angle moves at 1.5 rad/s at most.
    drive(episode, BodyCommand(2.0, 0.0, 10.0), 0.2)
    assert episode.robot.steering_angle == pytest.approx(0.3, abs=1e-6)


def test_car_understeers_at_speed(episode):
    env = environment(['#' * 130] + ['#' + '.' * 128 + '#'] * 120 + ['#' * 130], 'racetrack',
                      (10.0, 60.0, 0.0))
    episode.reset(env, config())
    drive(episode, BodyCommand(10.0, 0.0, 0.0), 3.0)
    observation = drive(episode, BodyCommand(10.0, 0.0, 10.0), 1.0)
    # Full lock would turn at 10 * tan(0.5) / 0.7 = 7.8 rad/s; grip allows 8 / 10.
    assert observation.twist.wz == pytest.approx(0.8, abs=1e-3)


def corner_track() -> list[str]:
    """A 5 m wide straight of 60 m (west to east) turning north into a 5 m wide lane."""
    rows = ['#' * 72] * 3
    rows += ['#' * 63 + '.....' + '####'] * 20
    rows += ['##' + '.' * 66 + '####'] * 5
    rows += ['#' * 72] * 3
    return rows


def corner_policy(speed: float):
    def command(observation):
        if observation is None or observation.pose.x < 63.5:
            return BodyCommand(speed, 0.0, 0.0)
        heading_error = math.pi / 2 - observation.pose.yaw
        # A sharp left toward the lane, then straight up it.
        return BodyCommand(speed, 0.0, 3.0 if heading_error > 0.2 else 2.0 * heading_error)
    return command


def test_a_fast_sharp_turn_ends_in_the_barrier_and_a_slow_one_does_not(episode):
    env = environment(corner_track(), 'racetrack', (4.0, 5.5, 0.0))
    episode.reset(env, config(time_limit=40.0))
    drive(episode, corner_policy(3.0), 26.0)
    slow = episode.metrics()
    assert slow.collisions == 0
    assert episode.robot.position[1] > 15.0  # it made the turn and drove up the lane
    episode.reset(env, config(time_limit=40.0))
    drive(episode, corner_policy(12.0), 10.0)
    fast = episode.metrics()
    assert fast.collisions >= 1
    assert episode.robot.position[0] < 68.5  # stopped by the barrier, not through it


def test_car_at_top_speed_cannot_tunnel_through_a_one_cell_barrier(episode):
    rows = ['#' * 40] * 2 + ['#' + '.' * 20 + '#' + '.' * 17 + '#'] * 3 + ['#' * 40] * 2
    env = environment(rows, 'racetrack', (2.0, 3.5, 0.0))
    episode.reset(env, config())
    observation = drive(episode, BodyCommand(12.0, 0.0, 0.0), 8.0)
    assert observation.pose.x < 21.0 - 0.5 + 0.05
    assert episode.metrics().collisions == 1


def test_flyer_is_holonomic_with_a_lag(episode):
    episode.reset(environment(open_room(30, 30), 'drone', (7.0, 7.0, 0.0)), config())
    observation = drive(episode, BodyCommand(0.0, 1.0, 0.0), 0.3)
    # First-order lag (0.3 s) under a 3 m/s^2 acceleration limit: well short of 1 m/s.
    assert 0.5 < observation.twist.vy < 0.8
    observation = drive(episode, BodyCommand(0.0, 1.0, 0.0), 2.0)
    assert observation.twist.vy == pytest.approx(1.0, abs=1e-3)
    assert observation.pose.x == pytest.approx(7.0, abs=1e-6)
    observation = drive(episode, BodyCommand(3.0, 3.0, 0.0), 3.0)
    assert math.hypot(observation.twist.vx, observation.twist.vy) == pytest.approx(2.0, abs=1e-3)


LOW_ROW = ['################', '#..............#', '#....OO........#', '#..............#',
           '################']


@pytest.mark.parametrize('robot, climb, hits', [('diff_drive', 0.0, True), ('flyer', 0.0, True),
                                                ('flyer', 0.5, False)])
def test_low_obstacles_stop_ground_robots_and_a_low_flyer_but_not_a_high_one(
        episode, robot, climb, hits):
    env = environment(LOW_ROW, 'drone', (1.25, 1.25, 0.0))
    episode.reset(env, config(robot=robot))
    if climb:  # one second's climb at 0.5 m/s: well above the low obstacles' 0.3 m
        drive(episode, BodyCommand(0.0, 0.0, 0.0, climb), 1.5)
    observation = drive(episode, BodyCommand(0.8, 0.0, 0.0), 5.0)
    assert (episode.metrics().collisions == 1) is hits
    assert (observation.pose.x < 2.5 - 0.2 + 0.02) is hits


def test_flyer_starts_landed_and_its_climb_rate_is_bounded_with_a_lag(episode):
    env = environment(open_room(12, 12), 'drone', (3.0, 3.0, 0.0))
    observation = episode.reset(env, config(robot='flyer'))
    assert observation.altitude == 0.0 and observation.climb_rate == 0.0
    assert episode.robot.state.z == 0.0
    params = episode.robot.params
    # The climb rate lags the command (response time 0.3 s, 2 m/s^2) and stops at its limit.
    observation = drive(episode, BodyCommand(0.0, 0.0, 0.0, 5.0), 0.1)
    assert 0.0 < observation.climb_rate < 0.2 + 1e-9
    observation = drive(episode, BodyCommand(0.0, 0.0, 0.0, 5.0), 1.0)
    assert params.max_climb_rate - 0.05 < observation.climb_rate <= params.max_climb_rate + 1e-9
    assert 0.5 < observation.altitude < 1.1
    # The ceiling holds it at max_altitude.
    observation = drive(episode, BodyCommand(0.0, 0.0, 0.0, 5.0), 2.0)
    assert observation.altitude == pytest.approx(params.max_altitude, abs=1e-9)
    assert observation.climb_rate == pytest.approx(0.0, abs=1e-6)
    # Horizontal motion keeps the altitude; descending stops on the ground.
    observation = drive(episode, BodyCommand(1.0, 0.0, 0.0), 1.0)
    assert observation.altitude == pytest.approx(params.max_altitude, abs=1e-6)
    assert observation.twist.vx > 0.9
    observation = drive(episode, BodyCommand(0.0, 0.0, 0.0, -5.0), 3.0)
    assert observation.altitude == 0.0
    assert episode.metrics().collisions == 0


def test_flyer_hovers_over_a_low_obstacle_and_touches_it_when_descending(episode):
    env = environment(LOW_ROW, 'drone', (1.25, 1.25, 0.0))
    episode.reset(env, config(robot='flyer'))
    drive(episode, BodyCommand(0.0, 0.0, 0.0, 0.5), 1.5)
    observation = drive(episode, lambda o: BodyCommand(
        4.0 * (2.75 - o.pose.x) if o else 0.0, 0.0, 0.0), 4.0)
    assert observation.pose.x == pytest.approx(2.75, abs=0.02) and not observation.in_contact
    observation = drive(episode, BodyCommand(0.0, 0.0, 0.0, -0.5), 3.0)
    # It comes to rest on the obstacle's top (0.3 m), which counts as one contact.
    assert observation.altitude == pytest.approx(0.3, abs=0.01)
    assert episode.metrics().collisions == 1


def test_flyer_starts_on_top_of_a_low_obstacle_under_its_footprint(episode):
    env = environment(LOW_ROW, 'drone', (2.6, 1.25, 0.0))
    observation = episode.reset(env, config(robot='flyer'))
    assert not episode.done
    assert observation.altitude == pytest.approx(0.3 + 0.005)
    drive(episode, BodyCommand(0.0, 0.0, 0.0, 0.5), 1.0)
    assert episode.metrics().collisions == 0


def test_walls_must_be_taller_than_the_flyer_flies(episode):
    env = environment(open_room(12, 12), 'drone', (3.0, 3.0, 0.0))
    with pytest.raises(InvalidConfigError, match='walls must be taller'):
        episode.reset(env, config(robot='flyer', robot_params={'max_altitude': 1.95}))
    with pytest.raises(InvalidConfigError, match='traffic_altitude'):
        create_robot('flyer', {'max_altitude': 0.5})


def test_a_wall_stops_the_diff_drive_and_counts_one_collision(episode):
    env = environment(open_room(12, 6), 'factory', (1.5, 1.5, 0.0))
    episode.reset(env, config())
    observation = drive(episode, BodyCommand(1.0, 0.0, 0.0), 8.0)
    assert observation.pose.x == pytest.approx(5.5 - 0.2, abs=0.01)
    assert observation.in_contact
    assert episode.metrics().collisions == 1
    assert episode.outcome is None


def test_contact_deflects_a_robot_along_the_wall(episode):
    env = environment(open_room(12, 12), 'factory', (2.0, 2.0, math.radians(30)))
    episode.reset(env, config(robot='flyer', physics_rate_hz=100.0))
    observation = drive(episode, BodyCommand(1.0, 0.0, 0.0), 6.0)
    # Pressed against the east wall, it slid north instead of stopping.
    assert observation.pose.x == pytest.approx(5.5 - 0.2, abs=0.02)
    assert observation.pose.y > 3.0
    assert episode.outcome is not Outcome.INVALID_ENVIRONMENT
