"""Dummy agents: seeded patrols through free space, away from the start, and real contacts."""

import math

import numpy as np
import pytest

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_sim.agents import (
    PASSAGE_SHARE,
    AgentConfig,
    DummyAgents,
    KeepClear,
    PatrolPath,
    PatrolSpace,
)
from sessgan_sim.episode import Episode, EpisodeConfig
from sessgan_sim.errors import InvalidConfigError
from sessgan_sim.metrics import ContactKind
from sessgan_sim.robots import BodyCommand, create_robot
from sessgan_sim.sensors import LidarConfig
from sessgan_sim.world import World

pytestmark = pytest.mark.unit

STEP = 0.01


def factory() -> Environment:
    return make_environment(load_example_map('factory').cells, 'factory', 'factory')


def spawn(environment: Environment, count: int, seed: int, robot: str = 'diff_drive',
          config: AgentConfig | None = None):
    """Spawn agents in a fresh world; return their patrol paths and first positions."""
    with World() as world:
        world.build(environment, STEP)
        body = create_robot(robot)
        body.spawn(world.client, environment.start)
        agents = DummyAgents(config)
        agents.spawn(world.client, environment, body, count, np.random.default_rng(seed))
        return agents.paths, agents.positions.copy()


def test_patrol_path_goes_back_and_forth():
    path = PatrolPath(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0]]))
    assert path.length == pytest.approx(3.0)
    assert path.position(0.0) == (0.0, 0.0)
    assert path.position(1.0) == pytest.approx((1.0, 0.0))
    assert path.position(2.5) == pytest.approx((2.0, 0.5))
    assert path.position(3.0) == pytest.approx((2.0, 1.0))
    assert path.position(4.5) == pytest.approx((1.5, 0.0))  # on the way back
    assert path.position(6.0) == pytest.approx((0.0, 0.0))
    assert path.position(7.0) == pytest.approx((1.0, 0.0))


def test_a_one_point_path_stands_still():
    path = PatrolPath(np.array([[1.0, 2.0]]))
    assert path.length == 0.0
    assert path.position(5.0) == (1.0, 2.0)


def test_agents_patrol_free_cells_away_from_the_start():
    environment = factory()
    paths, positions = spawn(environment, 4, seed=1)
    assert len(paths) == 4
    start = environment.start
    for path, (x, y) in zip(paths, positions, strict=True):
        assert math.hypot(x - start.x, y - start.y) >= AgentConfig().min_start_distance
        assert len(path.points) >= AgentConfig().min_patrol_cells
        for px, py in path.points:
            row, col = environment.cell_of(px, py)
            assert environment.occupancy[row, col] == 0
        steps = np.abs(np.diff(path.points, axis=0)).sum(axis=1)
        assert np.allclose(steps, environment.resolution)  # 4-connected, cell to cell


def test_agent_patrols_are_seeded():
    environment = factory()
    first = spawn(environment, 3, seed=7)
    again = spawn(environment, 3, seed=7)
    other = spawn(environment, 3, seed=8)
    def same(a, b):
        return all(np.array_equal(x.points, y.points) for x, y in zip(a[0], b[0], strict=True))

    assert same(first, again)
    assert not same(first, other)


def test_flying_agents_may_cross_low_obstacles():
    environment = make_environment(load_example_map('drone').cells, 'drone', 'drone')
    paths, _ = spawn(environment, 6, seed=3, robot='flyer')
    cells = [environment.occupancy[environment.cell_of(x, y)] for path in paths
             for x, y in path.points]
    assert set(cells) <= {0, 50}


def test_no_room_far_from_the_start_means_no_agents():
    rows = np.zeros((3, 3), dtype=np.int8)
    environment = Environment('tiny', 'factory', rows, 0.5, Pose2D(0.75, 0.75), Pose2D(0.25, 0.25))
    paths, positions = spawn(environment, 2, seed=0)
    assert paths == [] and positions.shape == (0, 2)


def test_bad_agent_config_is_rejected():
    with pytest.raises(InvalidConfigError, match='speed'):
        DummyAgents(AgentConfig(speed=0.0))


def test_agents_move_at_their_speed():
    with Episode() as episode:
        episode.reset(factory(), EpisodeConfig(dummy_agents=2, stuck_timeout=0.0))
        before = episode.agents.positions.copy()
        paths = episode.agents.paths
        for _ in range(10):
            episode.step(BodyCommand())
        after = episode.agents.positions
        expected = [path.position(0.5 * 0.5) for path in paths]  # 0.5 m/s for 0.5 s
        np.testing.assert_allclose(after, expected)
        assert not np.allclose(before, after)


def test_an_agent_running_into_the_robot_is_a_collision():
    # A one-cell corridor: the agent patrols ahead of the robot, which drives into it.
    rows = np.zeros((3, 30), dtype=np.int8)
    rows[0, :] = rows[2, :] = 100
    environment = Environment('corridor', 'factory', rows, 0.5, Pose2D(0.25, 0.75),
                              Pose2D(14.75, 0.75))
    config = EpisodeConfig(dummy_agents=1, stuck_timeout=0.0, collision_limit=0,
                           lidar=LidarConfig(noise_std=0.0))
    with Episode() as episode:
        episode.reset(environment, config)
        for _ in range(1000):
            observation = episode.step(BodyCommand(0.3, 0.0, 0.0)).observation
            if episode.metrics().collisions:
                break
        x_agent = episode.agents.positions[0, 0]
        assert observation.pose.x < x_agent
        # Met head-on (the agent is faster): the robot drove into it, and the agent turned
        # back rather than push it (the contact lasted a physics step or two).
        (contact,) = episode.metrics().contacts
        assert contact.kind == ContactKind.ROBOT_INTO_AGENT
        assert episode.agents.velocities[0, 0] > 0.0


@pytest.mark.parametrize('scenario,kind', [('factory', 'plain'), ('drone', 'plain'),
                                           ('factory', 'mission'), ('factory', 'fleet'),
                                           ('factory', 'origin')])
def test_planned_patrols_are_the_patrols_an_episode_spawns(scenario, kind):
    """A screen predicts encounters from planned_patrols: they must be the episode's own."""
    from sessgan_core.fleet import FleetSpec
    from sessgan_core.missions import MissionSpec
    from sessgan_sim.episode import PatrolPlanner

    cells = load_example_map(scenario).cells
    options = {'mission': {'mission': MissionSpec(2, 1.0)}, 'fleet': {'fleet': FleetSpec(2)},
               'origin': {'origin': (-3.0, 5.5)}}.get(kind, {})
    compared = 0
    with Episode() as episode:
        for seed in range(4):
            environment = make_environment(cells, scenario, f'e{seed}', seed=seed, **options)
            if not environment.feasible:
                continue
            config = EpisodeConfig(seed=100 + seed, dummy_agents=3)
            # The planner's config may carry any seed: it plans for the one it is given.
            planned = PatrolPlanner(environment, EpisodeConfig(dummy_agents=3)).patrols(100 + seed)
            episode.reset(environment, config)
            spawned = episode._agents.paths
            assert len(planned) == len(spawned) > 0
            for mine, theirs in zip(planned, spawned):
                np.testing.assert_array_equal(mine.points, theirs.points)
            compared += 1
    assert compared >= 2


def test_no_agents_planned_without_agents():
    from sessgan_sim.episode import PatrolPlanner

    assert PatrolPlanner(factory(), EpisodeConfig(dummy_agents=0)).patrols(3) == []


def test_patrol_positions_of_many_distances_are_those_of_one():
    path = PatrolPath(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.5, 1.0]]))
    distances = np.linspace(0.0, 20.0, 97)
    np.testing.assert_allclose(path.positions(distances),
                               [path.position(d) for d in distances], atol=1e-12)
    still = PatrolPath(np.array([[1.0, 2.0]]))
    np.testing.assert_array_equal(still.positions(np.array([0.0, 3.0])), [[1.0, 2.0]] * 2)


def two_rooms() -> Environment:
    """Two rooms joined by a 3 m passage, 1.5 m wide (y 2.5-4.0 m)."""
    rows = np.full((12, 24), 100, dtype=np.int8)
    rows[1:11, 1:9] = rows[1:11, 15:23] = 0
    rows[5:8, 9:15] = 0
    return Environment('rooms', 'factory', rows, 0.5, Pose2D(1.0, 1.0), Pose2D(11.0, 1.0))


@pytest.mark.parametrize('route_y', [3.25, 3.75])
def test_a_patrol_may_cross_a_narrow_passage_but_never_runs_along_it(route_y):
    # Two rooms joined by a 3 m passage; the passage is narrow on some robot's route, which
    # runs along its middle or (3.75) half a metre beside the agents' only free row there
    # (y = 3.25), which the passage's discs around the route must still cover.
    environment = two_rooms()
    passage = [(x, route_y) for x in np.arange(4.5, 7.75, 0.25)]

    def patrols(narrow: bool) -> list[PatrolPath]:
        space = PatrolSpace(environment, (0,), AgentConfig(),
                            [KeepClear(x, y, 0.4, 0.5 if narrow else 0.0) for x, y in passage])
        return [path for seed in range(30)
                for path in space.patrols(3, np.random.default_rng(seed))]

    def passage_points(path: PatrolPath) -> int:
        return sum(4.3 < x < 7.7 and 2.8 < y < 3.7 for x, y in path.points)
    # Discs that only keep patrols from ending there: agents shuttle through the passage.
    assert max(passage_points(path) for path in patrols(narrow=False)) == 6
    # Narrow ones: a patrol at most crosses it (here: runs in one room), and an agent that
    # found no patrol is not placed (standing, it would hold up a robot waiting for it).
    kept = patrols(narrow=True)
    assert max(passage_points(path) for path in kept) <= 3
    assert all(len(path.points) >= AgentConfig().min_patrol_cells for path in kept)
    # And is long beside what it holds of the passage.
    assert all(len(path.points) >= PASSAGE_SHARE * passage_points(path) for path in kept)
    # Nor does one turn around inside the passage (where it would block it).
    ends = [point for path in kept for point in (path.points[0], path.points[-1])]
    assert not any(4.3 < x < 7.7 and 2.8 < y < 3.7 for x, y in ends)


def test_a_short_patrol_across_a_narrow_passage_is_refused():
    # A 4-cell patrol with 2 cells in a passage kept an agent there half its time: a robot
    # waiting beside it never got through (audit of 2026-11-28, a timeout judged unclear).
    environment = two_rooms()
    space = PatrolSpace(environment, (0,), AgentConfig(),
                        [KeepClear(x, 3.25, 0.4, 0.5) for x in np.arange(4.5, 7.75, 0.25)])
    first = min(col for col in range(24) if space.narrow[6, col])
    into = [(6, col) for col in range(first - 2, first + 2)]
    assert sum(space.narrow[cell] for cell in into) == 2
    assert not space.only_crosses(into)
    assert space.only_crosses([(6, col) for col in range(first - 4, first + 2)])
    assert not space.only_crosses([(6, col) for col in range(first - 8, first + 4)])
