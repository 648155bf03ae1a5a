"""Lidar geometry and readings, seeded noise, what each robot sees, odometry and clearance;
the analytic lidar and clearance against pybullet's rays and closest points."""

import math

import numpy as np
import pybullet as p
import pytest

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.robots import BodyCommand, Robot
from sessgan_sim.sensors import (
    ClearanceSensor,
    Lidar,
    LidarConfig,
    RangeFinder,
    RangeFinderConfig,
    RayCaster,
    grid_faces,
    upright_footprint,
)
from sessgan_sim.world import World, WorldLayout, vertical_faces

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


def test_ground_robots_and_a_low_flyer_see_low_obstacles_and_a_high_flyer_sees_over_them(
        episode):
    rows = ['############', '#..........#', '#......OO..#', '#..........#', '############']
    env = environment(rows, (1.25, 1.25, 0.0), scenario='drone', goal=(5.0, 1.75))
    ahead = 180
    ground = episode.reset(env, config(robot='diff_drive'))
    assert ground.scan[ahead] == pytest.approx(3.5 - 1.25, abs=1e-4)
    landed = episode.reset(env, config(robot='flyer'))
    assert landed.altitude == 0.0
    assert landed.scan[ahead] == pytest.approx(3.5 - 1.25, abs=1e-4)
    climbing = BodyCommand(0.0, 0.0, 0.0, 1.0)
    for _ in range(10):  # 0.5 s: still below 0.3 m - 0.05 m (the scan plane is mid-body)
        observation = episode.step(climbing).observation
    assert observation.altitude < 0.25
    assert observation.scan[ahead] == pytest.approx(3.5 - 1.25, abs=1e-4)
    for _ in range(20):
        observation = episode.step(climbing).observation
    assert observation.altitude > 0.3
    assert observation.scan[ahead] == pytest.approx(5.5 - 1.25, abs=1e-4)


def test_flying_agents_are_seen_only_when_the_scan_plane_cuts_them(episode):
    rows = ['#' * 16] + ['#' + '.' * 14 + '#'] * 14 + ['#' * 16]
    env = environment(rows, (1.25, 1.25, 0.0), scenario='drone', goal=(6.0, 6.0))
    episode.reset(env, config(robot='flyer', dummy_agents=3, seed=2))
    robot, agents = episode.robot, episode.agents
    assert agents.centre_height == pytest.approx(robot.traffic_height)
    assert robot.traffic_height == pytest.approx(1.0)
    with_agents, walls_only = (Lidar(LidarConfig(noise_std=0.0), np.random.default_rng(0))
                               for _ in range(2))
    with_agents.attach(robot.client, robot, episode.layout, agents)
    walls_only.attach(robot.client, robot, episode.layout, None)
    # Landed, the scan plane (0.05 m) passes under the agents (0.85 to 1.15 m).
    np.testing.assert_array_equal(with_agents.scan(), walls_only.scan())
    move(robot, 1.25, 1.25, 0.0, robot.params.traffic_altitude)
    assert (with_agents.scan() < walls_only.scan() - 0.1).sum() > 3
    move(robot, 1.25, 1.25, 0.0, robot.params.max_altitude)  # plane at 1.55 m: above them
    np.testing.assert_array_equal(with_agents.scan(), walls_only.scan())


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
        result = episode.step(BodyCommand(0.5, 0.0, 0.0))
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
        observation = episode.step(BodyCommand()).observation
        updates.append(observation.scan_updated)
        scans.append(observation.scan)
    assert updates == [False, True, False, True, False, True]
    assert scans[1] is scans[0] and scans[2] is not scans[1]


def test_clearance_below_the_proximity_distance_counts_as_proximity_time(episode):
    env = environment(ROOM, (2.0, 0.8, 0.0))  # 0.1 m between body and south wall
    episode.reset(env, config())
    for _ in range(20):
        episode.step(BodyCommand())
    metrics = episode.metrics()
    assert metrics.proximity_time == pytest.approx(1.0)
    assert metrics.min_clearance == pytest.approx(0.1, abs=2e-3)
    assert metrics.collisions == 0


def test_min_clearance_is_capped_at_the_clearance_range(episode):
    env = environment(ROOM, (2.0, 1.1, 0.0))  # 0.4 m between body and south wall
    episode.reset(env, config())
    episode.step(BodyCommand())
    assert episode.metrics().min_clearance == pytest.approx(0.25)  # the proximity distance
    episode.reset(env, config(clearance_range=1.0))
    episode.step(BodyCommand())
    metrics = episode.metrics()
    assert metrics.min_clearance == pytest.approx(0.4, abs=2e-3)
    assert metrics.proximity_time == 0.0


# --- the analytic lidar and clearance against pybullet --------------------------------------


def example(scenario: str) -> Environment:
    return make_environment(load_example_map(scenario).cells, scenario, scenario)


def move(robot: Robot, x: float, y: float, yaw: float, altitude: float = 0.0) -> None:
    """Put the robot's body at (x, y, yaw) and ``altitude`` (a flyer's) and read its state
    back, as after a step."""
    p.resetBasePositionAndOrientation(robot.body_id, [x, y, robot.ride_height + altitude],
                                      p.getQuaternionFromEuler([0.0, 0.0, yaw]),
                                      physicsClientId=robot.client)
    robot.sync()


def lidars(episode: Episode, lidar: LidarConfig, agents: bool = True) -> tuple[Lidar, Lidar]:
    """An analytic and a pybullet lidar on the episode's robot."""
    pair = []
    for caster in (RayCaster.ANALYTIC, RayCaster.PYBULLET):
        config = LidarConfig(beams=lidar.beams, field_of_view=lidar.field_of_view,
                             range_max=lidar.range_max, range_min=0.0, noise_std=0.0,
                             caster=caster)
        sensor = Lidar(config, np.random.default_rng(0))
        sensor.attach(episode.robot.client, episode.robot, episode.layout,
                      episode.agents if agents else None)
        pair.append(sensor)
    return pair[0], pair[1]


def face_ends(layout: WorldLayout, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Ends (n, 2) of the scan surface's quads that span ``height``, and how close (m) a ray
    may pass by each and still hit its quad: Bullet's triangle test lets a ray through a
    triangle's edge up to 1e-4 times the other side's length (btTriangleRaycastCallback)."""
    resolution = layout.resolution
    heights = np.pad(layout.heights, 1, constant_values=layout.border_height)
    quads = [quad for quad in vertical_faces(heights, resolution,
                                             (layout.origin[0] - resolution,
                                              layout.origin[1] - resolution))
             if quad[2] < height < quad[3]]
    ends = np.array([end for quad in quads for end in quad[:2]]).reshape(-1, 2)
    slack = np.repeat([1.5e-4 * math.dist(*quad[:2]) + 1e-6 for quad in quads], 2)
    return ends, slack


def grazing_corners(x: float, y: float, angles: np.ndarray, reach: np.ndarray,
                    ends: np.ndarray, slack: np.ndarray) -> np.ndarray:
    """bool per beam: the ray from (x, y) along ``angles`` passes a quad's end within its
    slack before ``reach`` (m), where Bullet and the exact geometry may disagree."""
    relative = ends - (x, y)
    near = np.hypot(relative[:, 0], relative[:, 1]) < reach.max() + slack
    relative, slack = relative[near], slack[near]
    if not len(relative):
        return np.zeros(len(angles), dtype=bool)
    directions = np.stack((np.cos(angles), np.sin(angles)), axis=1)
    along = np.clip(directions @ relative.T, 0.0, reach[:, None])
    gap = np.hypot(relative[:, 0] - along * directions[:, :1],
                   relative[:, 1] - along * directions[:, 1:])
    return (gap < slack).any(axis=1)


@pytest.mark.parametrize('scenario, robot', [
    ('factory', 'diff_drive'), ('drone', 'flyer'), ('drone', 'diff_drive'),
    ('racetrack', 'car'), ('racetrack', 'flyer')])
def test_analytic_lidar_matches_pybullet_rays_on_the_example_maps(episode, scenario, robot):
    env = example(scenario)
    episode.reset(env, EpisodeConfig(robot=robot, dummy_agents=0))
    body = episode.robot
    analytic, bullet = lidars(episode, LidarConfig())
    # A flyer scans low (below the low obstacles' 0.3 m) and at its traffic altitude.
    altitudes = (0.1, 0.95) if body.flies else (0.0,)
    faces = {altitude: face_ends(episode.layout, body.sensor_height + altitude)
             for altitude in altitudes}
    rng = np.random.default_rng(7)
    height, width = np.array(env.occupancy.shape) * env.resolution
    inside = compared = grazing = 0
    for index in range(60):
        # Anywhere, obstacles and the outside of the map included.
        x, y = rng.uniform(-1.0, width + 1.0), rng.uniform(-1.0, height + 1.0)
        yaw = rng.uniform(-math.pi, math.pi)
        altitude = altitudes[index % len(altitudes)]
        ends, slack = faces[altitude]
        move(body, x, y, yaw, altitude)
        row, col = env.cell_of(x, y)
        inside += (0 <= row < env.occupancy.shape[0] and 0 <= col < env.occupancy.shape[1]
                   and int(env.occupancy[row, col]) not in body.passable_values)
        exact = np.array(analytic.scan(), dtype=float)
        reference = np.array(bullet.scan(), dtype=float)
        reach = np.minimum(np.fmax(np.nan_to_num(exact, posinf=np.inf),
                                   np.nan_to_num(reference, posinf=np.inf)), 10.0) + 1e-3
        skip = grazing_corners(x, y, yaw + analytic.info.angles(), reach, ends, slack)
        grazing += int(skip.sum())
        compared += int((~skip).sum())
        np.testing.assert_array_equal(np.isinf(exact[~skip]), np.isinf(reference[~skip]))
        finite = ~skip & np.isfinite(exact)
        np.testing.assert_allclose(exact[finite], reference[finite], rtol=0, atol=1e-4)
    assert grazing < 0.01 * compared
    if scenario != 'drone' or robot != 'flyer':
        assert inside > 0  # the rays from inside an obstacle were compared too


@pytest.mark.parametrize('lidar', [
    LidarConfig(beams=181, field_of_view=math.pi), LidarConfig(beams=1081, field_of_view=4.7),
    LidarConfig(beams=1), LidarConfig(beams=7, field_of_view=6.0),
    LidarConfig(beams=90, range_max=3.0)])
def test_analytic_lidar_matches_pybullet_rays_for_any_fan(episode, lidar):
    episode.reset(example('factory'), EpisodeConfig(dummy_agents=0))
    analytic, bullet = lidars(episode, lidar)
    ends, slack = face_ends(episode.layout, episode.robot.sensor_height)
    rng = np.random.default_rng(3)
    for _ in range(40):
        x, y, yaw = rng.uniform(0.0, 16.0), rng.uniform(0.0, 16.0), rng.uniform(-4.0, 4.0)
        move(episode.robot, x, y, yaw)
        exact = np.array(analytic.scan(), dtype=float)
        reference = np.array(bullet.scan(), dtype=float)
        reach = np.full(len(exact), lidar.range_max + 1e-3)
        keep = ~grazing_corners(x, y, yaw + analytic.info.angles(), reach, ends, slack)
        np.testing.assert_allclose(exact[keep], reference[keep], rtol=0, atol=1e-4)


def test_a_beam_through_a_corner_meets_it(episode):
    # From a cell's centre the beams at 45 degrees pass exactly through grid corners: the
    # beam at 135 degrees passes the top right corner (2.5, 2.0) of the wall cell south of it.
    rows = ['##########', '#........#', '#........#', '#........#', '#........#',
            '#...#....#', '#........#', '#........#', '##########']
    env = environment(rows, (3.25, 1.25, 0.0), goal=(4.0, 3.0))
    scans = [np.array(episode.reset(env, config(lidar=LidarConfig(noise_std=0.0,
                                                                   caster=caster))).scan)
             for caster in (RayCaster.ANALYTIC, RayCaster.PYBULLET)]
    beam = 315  # -pi + 315 degrees
    assert scans[0][beam] == pytest.approx(0.75 * math.sqrt(2), abs=1e-6)
    np.testing.assert_allclose(scans[0], scans[1], rtol=0, atol=1e-4)


def test_agents_are_seen_as_exact_circles(episode):
    episode.reset(example('factory'), EpisodeConfig(dummy_agents=6, seed=3))
    agents, body = episode.agents, episode.robot
    analytic, bullet = lidars(episode, LidarConfig())
    walls_only, _ = lidars(episode, LidarConfig(), agents=False)
    radius = agents.config.radius
    rng = np.random.default_rng(1)
    differences = []
    for _ in range(40):
        centre_x, centre_y = agents.positions[rng.integers(len(agents.positions))]
        x, y = centre_x + rng.uniform(-3.0, 3.0), centre_y + rng.uniform(-3.0, 3.0)
        move(body, x, y, rng.uniform(-math.pi, math.pi))
        angles = body.state.yaw + analytic.info.angles()
        exact, reference, walls = (np.array(lidar.scan(), dtype=float)
                                   for lidar in (analytic, bullet, walls_only))
        # Closed-form ray-circle hits, nearest agent in front of the viewpoint.
        expected = walls.copy()
        for agent_x, agent_y in agents.positions:
            dx, dy = agent_x - x, agent_y - y
            if math.hypot(dx, dy) <= radius:
                continue  # Bullet sees no agent around the viewpoint, nor does the lidar
            along = np.cos(angles) * dx + np.sin(angles) * dy
            discriminant = along ** 2 - (dx * dx + dy * dy - radius ** 2)
            hit = (discriminant >= 0) & (along > 0)
            distance = along - np.sqrt(np.where(hit, discriminant, 0.0))
            expected = np.where(hit & (distance < expected), distance, expected)
        expected = np.where(expected >= 10.0, np.inf, expected)
        np.testing.assert_allclose(exact, expected.astype(np.float32), rtol=0, atol=1e-5)
        seen = exact < walls
        differences += np.abs(exact[seen] - reference[seen]).tolist()
    # Bullet's convex ray cast against a cylinder is off by ~0.1 mm typically and by up to
    # about a centimetre at grazing incidence.
    differences = np.array(differences)
    assert len(differences) > 200
    assert np.median(differences) < 3e-4
    assert np.percentile(differences, 95) < 3e-3
    assert differences.max() < 0.03


def test_agents_out_of_the_scan_plane_are_not_seen(episode):
    rows = ['#' * 16] + ['#' + '.' * 14 + '#'] * 14 + ['#' * 16]
    env = environment(rows, (1.25, 1.25, 0.0), goal=(6.0, 6.0))
    # Agents (0.3 m tall) ride with their centre at the robot's ride height, 0.16 m.
    over = config(dummy_agents=3, seed=2, robot_params={'sensor_height': 0.33})
    for settings in (over, config(dummy_agents=3, seed=2)):
        episode.reset(env, settings)
        analytic, bullet = lidars(episode, LidarConfig())
        walls, _ = lidars(episode, LidarConfig(), agents=False)
        exact = np.array(analytic.scan())
        np.testing.assert_allclose(exact, np.array(bullet.scan()), atol=0.03)
        assert (exact < np.array(walls.scan())).any() == (settings is not over)


def test_both_casters_draw_the_same_noise(episode):
    env = environment(ROOM, (2.0, 1.7, 0.3))
    scans = []
    for caster in (RayCaster.ANALYTIC, RayCaster.PYBULLET):
        lidar = LidarConfig(noise_std=0.05, caster=caster)
        scans.append(np.array(episode.reset(env, config(lidar=lidar, seed=4)).scan))
    np.testing.assert_allclose(scans[0], scans[1], rtol=0, atol=1e-5)


def test_an_unknown_caster_is_named():
    with pytest.raises(InvalidConfigError, match='caster'):
        LidarConfig(caster='raymarch').validate()


def test_grid_faces_are_oriented_counter_clockwise_seen_from_outside():
    faces = grid_faces(np.array([[True]]), 0.5, (1.0, 2.0))
    assert len(faces) == 4
    first, second = faces.ends
    centre = np.array([1.25, 2.25])
    # Seen from outside, a face turns counter-clockwise from its first end to its second:
    # the outside lies to the left of the direction from one to the other, the cell's
    # centre to the right.
    along, inward = second - first, centre - first
    assert (along[:, 0] * inward[:, 1] - along[:, 1] * inward[:, 0] < 0).all()
    corners = {tuple(end) for end in first.tolist()}
    assert corners == {(1.0, 2.0), (1.5, 2.0), (1.5, 2.5), (1.0, 2.5)}
    assert len(grid_faces(np.zeros((2, 3), dtype=bool), 0.5, (0.0, 0.0))) == 0


@pytest.mark.parametrize('seed', range(4))
def test_grid_faces_are_the_scan_surface_quads_at_the_scan_height(seed):
    rng = np.random.default_rng(seed)
    heights = rng.choice([0.0, 0.3, 2.0], size=(9, 13), p=[0.6, 0.2, 0.2])
    for scan_height in (0.2, 1.0):
        faces = grid_faces(heights > scan_height, 0.5, (-1.0, 0.5))
        quads = [quad for quad in vertical_faces(heights, 0.5, (-1.0, 0.5))
                 if quad[2] < scan_height < quad[3]]

        def unit_edges(segments):
            """The cell-sized pieces of the segments, as sorted pairs of ends."""
            edges = set()
            for (x0, y0), (x1, y1) in segments:
                pieces = round(math.dist((x0, y0), (x1, y1)) / 0.5)
                for step in range(pieces):
                    a = (round(x0 + (x1 - x0) * step / pieces, 6),
                         round(y0 + (y1 - y0) * step / pieces, 6))
                    b = (round(x0 + (x1 - x0) * (step + 1) / pieces, 6),
                         round(y0 + (y1 - y0) * (step + 1) / pieces, 6))
                    edges.add(tuple(sorted((a, b))))
            return edges

        ours = unit_edges(zip(faces.ends[0].tolist(), faces.ends[1].tolist(), strict=True))
        assert ours == unit_edges(quad[:2] for quad in quads)


@pytest.mark.parametrize('scenario, robot, range_', [
    ('factory', 'diff_drive', 0.5), ('drone', 'flyer', 0.8), ('racetrack', 'car', 0.8),
    ('racetrack', 'flyer', 0.8)])
def test_analytic_clearance_matches_pybullet(episode, scenario, robot, range_):
    env = example(scenario)
    episode.reset(env, EpisodeConfig(robot=robot, dummy_agents=4, seed=1))
    body, agents = episode.robot, episode.agents
    analytic = ClearanceSensor(body.client, body, episode.layout, range_)
    analytic.set_agent_heights(agents.centre_height, agents.config.height)
    bullet = ClearanceSensor(body.client, body, episode.layout, range_, analytic=False)
    assert analytic.analytic and not bullet.analytic
    rng = np.random.default_rng(5)
    height, width = np.array(env.occupancy.shape) * env.resolution
    readings = []
    for index in range(300):
        x, y = rng.uniform(0.0, width), rng.uniform(0.0, height)
        if index % 3 == 0 and len(agents.positions):
            x, y = agents.positions[index % len(agents.positions)] + rng.uniform(-1, 1, 2)
        # A flyer anywhere between the ground and its ceiling: the distance is 3-D.
        altitude = rng.uniform(0.0, body.params.max_altitude) if body.flies else 0.0
        move(body, x, y, rng.uniform(-math.pi, math.pi), altitude)
        readings.append([sensor.measure(agents.body_ids, agents.positions,
                                        agents.config.radius)
                         for sensor in (analytic, bullet)])
    exact, reference = np.array(readings).T
    assert ((exact > 0) & (exact < range_)).mean() > 0.1
    # Bullet is exact along faces and reads up to about a millimetre too much near the
    # corners of boxes, never too little.
    assert (exact <= reference + 1e-9).all()
    assert (reference - exact).max() < 1.5e-3
    assert (np.abs(reference - exact) < 1e-6).mean() > 0.7


def test_clearance_of_a_turned_car_is_exact(episode):
    rows = ['##########', '#........#', '#........#', '#........#', '#........#', '##########']
    env = environment(rows, (2.5, 1.5, 0.0), scenario='racetrack', goal=(4.0, 2.0))
    episode.reset(config=config(robot='car'), environment=Environment(
        'car', 'racetrack', env.occupancy, 1.0, Pose2D(3.0, 2.0, 0.0), Pose2D(6.0, 3.0)))
    body = episode.robot
    sensor = ClearanceSensor(body.client, body, episode.layout, 2.0)
    assert upright_footprint(body.client, body).half_length == pytest.approx(0.5)
    # South wall's face at y = 1: a car turned by 30 degrees reaches down with a corner.
    for yaw in (0.0, math.pi / 6, math.pi / 2):
        move(body, 3.0, 2.0, yaw)
        lowest = 0.5 * abs(math.sin(yaw)) + 0.25 * abs(math.cos(yaw))
        assert sensor.measure([], np.zeros((0, 2)), 0.2) == pytest.approx(
            2.0 - 1.0 - lowest, abs=1e-12)


def test_clearance_falls_back_to_pybullet_for_other_shapes():
    class Ball:
        """Stands in for a robot whose body is a sphere."""

        footprint_radius = 0.2
        ride_height = 0.2

        def __init__(self, client: int) -> None:
            shape = p.createCollisionShape(p.GEOM_SPHERE, radius=0.2, physicsClientId=client)
            self.body_id = p.createMultiBody(1.0, shape, basePosition=[1.25, 1.25, 0.2],
                                             physicsClientId=client)
            self.position = (1.25, 1.25)

    with World() as world:
        layout = world.build(environment(ROOM, (1.25, 1.25, 0.0)), 0.01)
        ball = Ball(world.client)
        assert upright_footprint(world.client, ball) is None
        sensor = ClearanceSensor(world.client, ball, layout, 1.0)
        assert not sensor.analytic
        assert sensor.measure([], np.zeros((0, 2)), 0.2) == pytest.approx(0.55, abs=1e-6)


# --- the flyer's downward range sensor ---------------------------------------------------------


def test_range_down_reads_the_ground_or_the_low_obstacle_below(episode):
    rows = ['############', '#..........#', '#......OO..#', '#..........#', '############']
    env = environment(rows, (1.25, 1.25, 0.0), scenario='drone', goal=(5.0, 1.75))
    exact = RangeFinderConfig(noise_std=0.0)
    landed = episode.reset(env, config(robot='flyer', range_finder=exact))
    assert landed.range_down == 0.0 and landed.range_finder == exact
    robot = episode.robot
    move(robot, 1.25, 1.25, 0.0, 0.8)
    sensor = episode._live.range_finder
    assert sensor.measure() == pytest.approx(0.8)
    move(robot, 3.75, 1.25, 0.0, 0.8)  # above the low obstacle (0.3 m tall)
    assert sensor.measure() == pytest.approx(0.5)
    move(robot, 3.75, 1.25, 0.0, 0.2)  # inside it: too close (REP 117)
    assert sensor.measure() == -math.inf
    far = RangeFinder(RangeFinderConfig(max_range=0.6, noise_std=0.0), np.random.default_rng(0))
    far.attach(robot, episode.layout)
    move(robot, 1.25, 1.25, 0.0, 0.8)
    assert far.measure() == math.inf


def test_range_down_noise_is_seeded_and_stays_within_range(episode):
    rows = ['############', '#..........#', '#..........#', '############']
    env = environment(rows, (1.25, 1.25, 0.0), scenario='drone', goal=(5.0, 1.25))
    readings = []
    for _ in range(2):
        observation = episode.reset(env, config(robot='flyer', seed=4))
        series = [observation.range_down]
        for _ in range(20):
            observation = episode.step(BodyCommand(0.0, 0.0, 0.0, 0.5)).observation
            series.append(observation.range_down)
        readings.append(series)
        assert observation.range_down == pytest.approx(observation.altitude, abs=0.03)
    assert readings[0] == readings[1]
    assert min(readings[0]) >= 0.0  # a landed flyer's noisy reading stays within min_range


def test_only_the_flyer_has_a_range_sensor(episode):
    observation = episode.reset(environment(ROOM, (2.0, 1.0, 0.0)), config())
    assert observation.range_down is None and observation.range_finder is None
    with pytest.raises(InvalidConfigError, match='max_range'):
        RangeFinderConfig(min_range=1.0, max_range=0.5).validate()


@pytest.mark.parametrize('altitude, near', [(0.95, False), (0.35, True)])
def test_proximity_over_a_low_obstacle_uses_the_3d_distance(episode, altitude, near):
    rows = ['############', '#..........#', '#....OO....#', '#..........#', '############']
    env = environment(rows, (1.25, 1.25, 0.0), scenario='drone', goal=(5.0, 1.25))
    episode.reset(env, config(robot='flyer', clearance_range=1.0))
    robot = episode.robot
    for _ in range(200):  # climb in place to the altitude, then fly over the band
        error = altitude - robot.altitude
        episode.step(BodyCommand(0.0, 0.0, 0.0, max(-1.0, min(1.0, 3.0 * error))))
    assert robot.altitude == pytest.approx(altitude, abs=0.01)
    before = episode.metrics().proximity_time
    assert before == 0.0  # 0.85 m from the band's side: not near it at any altitude
    for _ in range(80):
        observation = episode.step(BodyCommand(0.8, 0.0, 0.0,
                                                   3.0 * (altitude - robot.altitude))).observation
    assert observation.pose.x > 3.5  # past the band (x 2.5 to 3.5)
    metrics = episode.metrics()
    assert metrics.collisions == 0
    assert (metrics.proximity_time > 0.5) is near
    # Right over the band the clearance is the vertical gap to its 0.3 m top (the side
    # walls are 0.55 m from the body).
    assert metrics.min_clearance == pytest.approx(min(altitude - 0.3, 0.55), abs=0.02)
