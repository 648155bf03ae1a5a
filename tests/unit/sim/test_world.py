"""World builder: merged geometry, obstacle kinds and heights, rays, rebuilds without leaks."""

import time

import numpy as np
import pybullet as p
import pytest

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.errors import InvalidConfigError, WorldError
from sessgan_sim.sensors import LidarConfig, RayCaster
from sessgan_sim.world import (
    BOXES_PER_BODY,
    SCAN_RAY_MASK,
    ObstacleKind,
    World,
    WorldStyle,
    group_rectangles,
    merge_cells,
    vertical_faces,
)

pytestmark = pytest.mark.unit

VALUES = {'#': 100, 'O': 50, '.': 0}
STEP = 0.01


def environment(rows: list[str], scenario: str = 'factory',
                resolution: float = 0.5) -> Environment:
    """An Environment from a picture, top row first; start and goal in the first free cell."""
    grid = np.array([[VALUES[char] for char in row] for row in reversed(rows)], dtype=np.int8)
    row, col = np.argwhere(grid == 0)[0]
    centre = Pose2D((col + 0.5) * resolution, (row + 0.5) * resolution)
    return Environment('test', scenario, grid, resolution, centre, centre)


def covered(rectangles, shape):
    cover = np.zeros(shape, dtype=int)
    for row, col, rows, cols in rectangles:
        cover[row:row + rows, col:col + cols] += 1
    return cover


@pytest.mark.parametrize('seed', range(5))
def test_merge_cells_covers_every_cell_exactly_once(seed):
    mask = np.random.default_rng(seed).random((17, 23)) < 0.4
    assert (covered(merge_cells(mask), mask.shape) == mask.astype(int)).all()


def test_merge_cells_merges_the_walls_of_a_real_map():
    cells = load_example_map('factory').cells
    walls = cells == 1
    rectangles = merge_cells(walls)
    assert (covered(rectangles, walls.shape) == walls.astype(int)).all()
    assert len(rectangles) < walls.sum() / 5


def test_group_rectangles_keeps_every_rectangle_once_in_small_groups():
    rectangles = merge_cells(np.random.default_rng(1).random((40, 40)) < 0.5)
    groups = group_rectangles(rectangles, BOXES_PER_BODY)
    assert all(1 <= len(group) <= BOXES_PER_BODY for group in groups)
    assert sorted(r for group in groups for r in group) == sorted(rectangles)


def test_vertical_faces_of_a_block_and_a_merged_row():
    block = vertical_faces(np.array([[2.0]]), 0.5, (0.0, 0.0))
    assert sorted(block) == sorted([
        ((0.0, 0.0), (0.0, 0.5), 0.0, 2.0), ((0.5, 0.0), (0.5, 0.5), 0.0, 2.0),
        ((0.0, 0.0), (0.5, 0.0), 0.0, 2.0), ((0.0, 0.5), (0.5, 0.5), 0.0, 2.0)])
    row = vertical_faces(np.array([[2.0, 2.0, 2.0]]), 1.0, (1.0, 2.0))
    assert len(row) == 4
    assert ((1.0, 2.0), (4.0, 2.0), 0.0, 2.0) in row


def test_vertical_faces_between_heights_span_the_difference():
    faces = vertical_faces(np.array([[2.0, 0.3]]), 1.0, (0.0, 0.0))
    assert ((1.0, 0.0), (1.0, 1.0), 0.3, 2.0) in faces


def test_blocked_cells_are_walls_or_out_of_bounds_barriers_by_scenario():
    style = WorldStyle()
    with World() as world:
        factory = world.build(environment(['###', '#.#', '###']), STEP)
        assert {box.kind for box in factory.obstacles} == {ObstacleKind.WALL}
        assert {box.height for box in factory.obstacles} == {style.wall_height}
        track = world.build(environment(['###', '#.#', '###'], 'racetrack', 1.0), STEP)
        assert {box.kind for box in track.obstacles} == {ObstacleKind.OUT_OF_BOUNDS}
        assert {box.height for box in track.obstacles} == {style.barrier_height}
        drone = world.build(environment(['#####', '#.O.#', '#####']), STEP)
        heights = {box.kind: box.height for box in drone.obstacles}
        assert heights == {ObstacleKind.WALL: style.wall_height,
                           ObstacleKind.LOW_OBSTACLE: style.low_obstacle_height}


def test_the_outside_of_the_grid_is_closed_by_a_ring():
    with World() as world:
        layout = world.build(environment(['...', '...']), STEP)
        x_min = min(box.x_min for box in layout.obstacles)
        y_max = max(box.y_max for box in layout.obstacles)
        assert x_min == pytest.approx(-0.5)
        assert y_max == pytest.approx(1.5)
        area = sum((b.x_max - b.x_min) * (b.y_max - b.y_min) for b in layout.obstacles)
        assert area == pytest.approx((5 * 4 - 3 * 2) * 0.25)


def test_merged_world_needs_few_bodies():
    env = make_environment(load_example_map('factory').cells, 'factory', 'factory')
    with World() as world:
        merged = world.build(env, STEP)
        merged_bodies = world.body_count()
        unmerged = world.build(env, STEP, WorldStyle(merge_obstacles=False))
        assert len(unmerged.obstacles) == int((np.pad(env.occupancy, 1,
                                                      constant_values=100) == 100).sum())
        assert merged_bodies < 10 < world.body_count()
        assert len(merged.body_ids) <= len(merged.obstacles) / 8


def test_rays_see_low_obstacles_only_below_their_height():
    # West to east: free, free, low obstacle, free, wall.
    env = environment(['#######', '#..O..#', '#######'])
    with World() as world:
        world.build(env, STEP)
        client = world.client
        ground, cruise = p.rayTestBatch(
            [[0.6, 0.75, 0.2], [0.6, 0.75, 1.0]], [[3.4, 0.75, 0.2], [3.4, 0.75, 1.0]],
            collisionFilterMask=SCAN_RAY_MASK, physicsClientId=client)
        assert ground[0] >= 0 and ground[3][0] == pytest.approx(1.5)
        assert cruise[0] >= 0 and cruise[3][0] == pytest.approx(3.0)


@pytest.mark.parametrize('style', [
    WorldStyle(scan_surface=False),
    WorldStyle(merge_obstacles=False, scan_surface=False),
    WorldStyle(merge_obstacles=False)])
def test_every_world_style_gives_the_same_scans_and_motion(style):
    env = make_environment(load_example_map('factory').cells, 'factory', 'factory')
    # A fixed pose in the open hall: from some seeded starts, beams graze wall corners
    # (either face may be hit) and the comparison would measure that, not the styles.
    env.start = Pose2D(8.0, 11.0, 0.0)
    trajectories = []
    # The pybullet lidar, whose rays meet the bodies the style builds.
    lidar = LidarConfig(noise_std=0.0, caster=RayCaster.PYBULLET)
    for world in (WorldStyle(), style):
        config = EpisodeConfig(lidar=lidar, dummy_agents=0, world=world)
        with Episode() as episode:
            scans = [episode.reset(env, config).scan]
            for _ in range(40):
                result = episode.step((0.6, 0.0, 0.4))
                scans.append(result.observation.scan)
            trajectories.append((np.array(scans), result.observation.pose,
                                 episode.metrics().collisions))
    (scans, pose, collisions), (other_scans, other_pose, other_collisions) = trajectories
    # Bullet's ray cast against a box is off by a few mm at grazing angles, and a beam
    # that grazes a corner may hit either face: nearly all beams still agree.
    with np.errstate(invalid='ignore'):  # inf - inf: both beams saw nothing
        agree = (scans == other_scans) | (np.abs(scans - other_scans) < 0.01)
    assert agree.mean() > 0.995
    assert pose.x == pytest.approx(other_pose.x, abs=1e-3)
    assert pose.y == pytest.approx(other_pose.y, abs=1e-3)
    assert collisions == other_collisions


def test_obstacles_near_finds_bodies_within_reach():
    env = environment(['#####', '#...#', '#...#', '#...#', '#####'])
    with World() as world:
        layout = world.build(env, STEP, WorldStyle(merge_obstacles=False))
        near = layout.obstacles_near(1.25, 1.25, 0.3)
        assert near == []
        near = layout.obstacles_near(0.8, 1.25, 0.35)
        assert len(near) == 1
        assert layout.kind_of(near[0]) is ObstacleKind.WALL
        assert layout.kind_of(layout.ground_id) is None


def test_closed_world_says_how_to_use_it():
    world = World()
    with pytest.raises(WorldError, match='closed'):
        _ = world.client
    with world, pytest.raises(WorldError, match='build'):
        _ = world.layout
    assert not world.is_open


def test_bad_style_or_timestep_is_rejected():
    with World() as world:
        with pytest.raises(InvalidConfigError, match='wall_height'):
            world.build(environment(['.']), STEP, WorldStyle(wall_height=-1.0))
        with pytest.raises(InvalidConfigError, match='timestep'):
            world.build(environment(['.']), 0.0)


def resident_kib() -> int:
    with open('/proc/self/statm') as statm:
        return int(statm.read().split()[1]) * 4


def test_rebuilding_two_hundred_times_leaks_neither_bodies_memory_nor_time():
    env = make_environment(load_example_map('factory').cells, 'factory', 'factory')
    durations = []
    with World() as world:
        world.build(env, STEP)
        bodies = world.body_count()
        memory_before = None
        for index in range(200):
            started = time.thread_time()
            world.build(env, STEP)
            durations.append(time.thread_time() - started)
            assert world.body_count() == bodies
            if index == 19:
                memory_before = resident_kib()
        growth_kib = resident_kib() - memory_before
    first, last = np.median(durations[:50]), np.median(durations[-50:])
    assert last < 1.5 * first + 1e-3
    assert growth_kib < 8 * 1024
