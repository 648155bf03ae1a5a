"""How users ask for fleets (--robots, the robots parameter), and fleets in episode.json, the
replayed environment and the fault picture."""

import pytest

from sessgan_core.environment import MAX_ROBOTS
from sessgan_core.fleet import FleetSpec
from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver import campaign_cli, compare_cli, evaluate_cli, replay_cli
from sessgan_evolver.bag_export import write_trace_bag
from sessgan_evolver.bag_reading import read_episode_json
from sessgan_evolver.episode_runner import EpisodeRunner
from sessgan_evolver.fault_picture import (
    FLEET_COLOURS,
    fleet_members,
    scene_from_bag,
    write_scene_png,
)

pytestmark = pytest.mark.unit


@pytest.fixture(scope='module')
def fleet():
    environment = make_environment(load_example_map('factory').cells, 'factory',
                                   'factory-fleet', seed=0, fleet=FleetSpec(3))
    assert environment.feasible and environment.robots == 3
    return environment


def test_campaigns_and_comparisons_ask_for_fleets_through_one_validated_spec():
    from sessgan_evolver.campaign import CampaignConfig
    from sessgan_evolver.comparison import CompareConfig
    from sessgan_evolver.errors import CampaignError, CompareError

    with pytest.raises(CampaignError, match='robots .*got 0'):
        CampaignConfig(robots=0).validate()
    with pytest.raises(CampaignError, match=f'1..{MAX_ROBOTS}'):
        CampaignConfig(robots=MAX_ROBOTS + 1).validate()
    with pytest.raises(CampaignError, match='mission_stations'):
        CampaignConfig(robots=2, mission_stations=1).validate()
    config = CampaignConfig(robots=4)
    config.validate()
    assert config.fleet() == FleetSpec(4)
    with pytest.raises(CompareError, match='robots'):
        CompareConfig(robots=-2).validate()
    compare = CompareConfig(robots=2)
    compare.validate()
    assert compare.campaign_config(seed=3).robots == 2


def test_a_campaign_runs_the_fleet_its_command_line_asks_for():
    config = campaign_cli.config_from_args(campaign_cli.parse_args(['--robots', '5']))
    config.validate()
    assert config.fleet() == FleetSpec(5)
    assert campaign_cli.config_from_args(campaign_cli.parse_args([])).fleet() == FleetSpec(1)


@pytest.mark.parametrize('command', ['campaign', 'evaluate', 'compare'])
def test_every_command_refuses_a_fleet_it_cannot_run_before_writing(command, tmp_path, capsys):
    # --robots reaches each command's validation (0 robots, or a fleet on a mission).
    output = tmp_path / 'out'
    main, arguments = {
        'campaign': (campaign_cli.main, ['--in-process', '--runs-root', str(output),
                                         '--bags-root', str(output)]),
        'evaluate': (evaluate_cli.main, ['--fresh-episodes', '1', '--output-dir', str(output)]),
        'compare': (compare_cli.main, ['--output-dir', str(output)]),
    }[command]
    for bad in (['--robots', '0'], ['--robots', '2', '--mission-stations', '1']):
        status = main([*arguments, *bad])
        err = capsys.readouterr().err
        assert status == 2, err
        assert 'robots' in err and 'Traceback' not in err
        assert not output.exists()


def test_a_fleet_survives_episode_json_and_replay(fleet, tmp_path):
    with EpisodeRunner('factory', 'reference_navigator', time_limit=0.5) as runner:
        run = runner.run(fleet, seed=1, trace=True, keep_scans=True)
    bag = write_trace_bag(tmp_path / 'bag', fleet, run.trace, {
        'controller': 'nav',
        'metrics': {k: v for k, v in run.metrics.items() if k != 'bag_path'}})
    episode = read_episode_json(bag)
    assert episode is not None
    assert len(episode['fleet']) == 2

    replayed = replay_cli.bag_environment(bag, episode)
    assert replayed.fleet == fleet.fleet
    old = {key: value for key, value in episode.items() if key != 'fleet'}  # before fleets
    assert replay_cli.bag_environment(bag, old).fleet == ()

    # The fault picture draws every robot, its goal and its certified route.
    scene = scene_from_bag(bag)
    assert [(m.start, m.goal) for m in scene.fleet] == \
        [((r.start.x, r.start.y), (r.goal.x, r.goal.y)) for r in fleet.fleet]
    assert all(len(member.route) >= 2 for member in scene.fleet)
    assert tuple(scene.route[0]) == pytest.approx((fleet.start.x, fleet.start.y))
    assert write_scene_png(scene, tmp_path / 'fleet.png').stat().st_size > 0


def test_fleet_members_have_their_own_colours_and_routes(fleet):
    members = fleet_members(fleet)
    assert len(members) == 2 <= len(FLEET_COLOURS)
    for member, robot in zip(members, fleet.fleet):
        assert tuple(member.route[0]) == pytest.approx((robot.start.x, robot.start.y))
        assert tuple(member.route[-1]) == pytest.approx((robot.goal.x, robot.goal.y))
    single = make_environment(load_example_map('factory').cells, 'factory', 'one', seed=0)
    assert fleet_members(single) == []


def test_replay_gives_a_viewer_one_clock_tf_and_map_of_a_fleet():
    """RViz reads /clock, /tf, /tf_static and /map: a fleet's are recorded once per robot."""
    where = replay_cli.republished_topic
    assert where('/w0/r1/tf', '/w0', '/', fleet=True) == '/tf'
    assert where('/w0/r1/tf_static', '/w0', '/v', fleet=True) == '/v/tf_static'
    assert where('/w0/r0/map', '/w0', '/', fleet=True) == '/map'
    assert where('/w0/r0/clock', '/w0', '/', fleet=True) == '/clock'
    assert where('/w0/r1/clock', '/w0', '/', fleet=True) is None  # r0's ticks the same times
    assert where('/w0/r1/scan', '/w0', '/', fleet=True) == '/r1/scan'
    # One robot: as recorded, under the namespace asked for.
    assert where('/w0/tf', '/w0', '/', fleet=False) == '/tf'
    assert where('/w0/r1/tf', '/w0', '/', fleet=False) == '/r1/tf'
