"""Smoke: a facility's own map through the real commands: a SLAM map trains on its known
region and the learned map keeps its origin; bad inputs fail clearly and leave nothing
behind; a huge map warns before training; a generator that makes no valid test is warned
about in train, export and campaign, and a campaign without a valid test exits 1."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import torch
import yaml
from PIL import Image

from sessgan_core.map_server_io import read_map_server
from sessgan_core.scenarios import get_scenario
from sessgan_evolver.campaign_cli import main as campaign_main
from sessgan_gen import train_cli
from sessgan_gen.checkpoint import load_checkpoint, save_checkpoint, training_map
from sessgan_gen.export_cli import main as export_main
from tests.unit.core.nav2_map_loading import nav2_load_map
from tests.unit.gen.test_facility_import import slam_map

pytestmark = pytest.mark.smoke
torch.set_num_threads(1)

TINY = ['--iterations', '2', '--channels', '4', '--threads', '1', '--no-progress', '--seed', '2']


def test_a_slam_map_trains_on_its_known_region_and_keeps_its_origin(tmp_path, capsys):
    path = slam_map(tmp_path, origin=(-5.0, -3.0, 0.0))
    output = tmp_path / 'slam.pt'
    assert train_cli.main(['--map-yaml', str(path), '--output', str(output), *TINY]) == 0
    err = capsys.readouterr().err
    assert 'cropped to its known region of 160x120 px' in err
    _, metadata = load_checkpoint(output)
    assert training_map(metadata).shape == (12, 16)
    learned = read_map_server(tmp_path / 'slam.map.yaml')
    assert learned.occupancy.shape == (12, 16)
    assert learned.origin == pytest.approx((-5.0 + 3.5, -3.0 + 3.5, 0.0))


def test_a_tiny_image_fails_clearly_and_leaves_no_files(tmp_path, capsys):
    Image.fromarray(np.full((3, 3), 254, dtype=np.uint8), mode='L').save(tmp_path / 'tiny.pgm')
    (tmp_path / 'tiny.yaml').write_text(yaml.safe_dump({
        'image': 'tiny.pgm', 'resolution': 0.05, 'origin': [0, 0, 0], 'negate': 0,
        'occupied_thresh': 0.65, 'free_thresh': 0.196}))
    output = tmp_path / 'out' / 'tiny.pt'
    assert train_cli.main(['--map-yaml', str(tmp_path / 'tiny.yaml'), '--output', str(output),
                           *TINY]) == 2  # an unusable map is a usage error
    err = capsys.readouterr().err
    assert 'the map is 1x1 cells' in err and 'at least 8 cells per side' in err
    assert 'Expected more than 1 value' not in err  # not torch's message
    assert not (tmp_path / 'out').exists() or not list((tmp_path / 'out').iterdir())


def test_a_huge_map_warns_about_time_and_memory_before_training(tmp_path, capsys, monkeypatch):
    # 600 x 600 cells of 0.5 m, as a 6,000 x 6,000 image at 0.05 m would make.
    pixels = np.full((600, 600), 254, dtype=np.uint8)
    pixels[::40, :] = 0
    Image.fromarray(pixels, mode='L').save(tmp_path / 'huge.pgm')
    (tmp_path / 'huge.yaml').write_text(yaml.safe_dump({
        'image': 'huge.pgm', 'resolution': 0.5, 'origin': [0, 0, 0], 'negate': 0,
        'occupied_thresh': 0.65, 'free_thresh': 0.196}))

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(train_cli.Trainer, 'run', stop)
    assert train_cli.main(['--map-yaml', str(tmp_path / 'huge.yaml'), '--output',
                           str(tmp_path / 'huge.pt'), '--threads', '1', '--no-progress']) == 130
    err = capsys.readouterr().err
    assert 'WARNING: a 600x600-cell map' in err and 'memory' in err


@pytest.fixture(scope='module')
def walled(tmp_path_factory):
    """A generator trained on a map whose floor is a 1-cell corridor: no valid test."""
    folder = tmp_path_factory.mktemp('walled')
    rows = ['W' * 16] * 7 + ['W' + 'G' * 14 + 'W'] + ['W' * 16] * 8
    (folder / 'walled.txt').write_text('# scenario: factory\n' + '\n'.join(rows) + '\n')
    output = folder / 'walled.pt'
    assert train_cli.main(['--map-file', str(folder / 'walled.txt'), '--output', str(output),
                           *TINY]) == 0
    return output


def test_a_generator_of_no_valid_test_is_warned_about(walled, tmp_path, capsys):
    # train said so at its end (the fixture ran it); export says so for its map.
    assert export_main(['--generate', '--checkpoint', str(walled), '--output',
                        str(tmp_path / 'map.yaml')]) == 0
    assert 'WARNING: the map of seed 0 holds no route' in capsys.readouterr().err
    log = io.StringIO()
    assert train_cli.report_valid_tests(walled, get_scenario('factory'), log) == 0.0
    assert '0% of 20 sampled maps are valid tests' in log.getvalue()
    assert 'WARNING: only 0% of the maps this generator makes hold a route' in log.getvalue()


@pytest.mark.parametrize('method, first', [('sessgan', 'generation 0'),
                                           ('screened', 'batch 0')])
def test_a_campaign_without_a_valid_test_exits_1_and_names_no_bag_folder(walled, tmp_path,
                                                                         capsys, method, first):
    argv = ['--in-process', '--scenario', 'factory', '--checkpoint', str(walled),
            '--method', method, '--generations', '1', '--population', '2',
            '--maps-per-member', '1', '--time-limit', '1', '--run', 'walled',
            '--runs-root', str(tmp_path / 'runs'),
            '--bags-root', str(tmp_path / 'bags')]
    assert campaign_main(argv) == 1
    captured = capsys.readouterr()
    assert f'WARNING: only 0% of the maps of {first} are valid tests' in captured.err
    assert 'no map of this campaign was a valid test' in captured.err
    assert 'failure bags: none' in captured.out and str(tmp_path / 'bags') not in captured.out
    report = (tmp_path / 'runs' / 'walled' / 'report' / 'report.md').read_text()
    assert 'No failure bag was written' in report and str(tmp_path / 'bags') not in report


def test_an_incomplete_checkpoint_is_warned_about(walled, tmp_path, capsys):
    pyramid, metadata = load_checkpoint(walled)
    partial = save_checkpoint(tmp_path / 'partial.pt', pyramid,
                              {**metadata, 'complete': False, 'trained_scales': 1})
    assert export_main(['--generate', '--checkpoint', str(partial), '--output',
                        str(tmp_path / 'p.yaml')]) == 0
    assert 'stopped after scale 1 of 2' in capsys.readouterr().err
    # The campaign's default method (screened) warns too.
    from sessgan_evolver.campaign import CampaignConfig
    from sessgan_evolver.method_campaign import MethodCampaign

    said: list[str] = []
    MethodCampaign(CampaignConfig(scenario='factory', method='screened',
                                  checkpoint=str(partial)), 'partial', tmp_path / 'runs',
                   tmp_path / 'bags', log=said.append)
    assert any('stopped after scale 1 of 2' in line for line in said), said
    argv = ['--in-process', '--scenario', 'factory', '--checkpoint', str(partial),
            '--method', 'sessgan', '--generations', '1', '--population', '2',
            '--maps-per-member', '1', '--time-limit', '1', '--run', 'partial',
            '--runs-root', str(tmp_path / 'runs'),
            '--bags-root', str(tmp_path / 'bags')]
    campaign_main(argv)
    assert 'stopped after scale 1 of 2' in capsys.readouterr().err
    assert json.loads(partial.with_suffix('.json').read_text())['complete'] is False


def test_generated_maps_and_failure_bags_sit_at_the_original_maps_origin(tmp_path):
    """Checkpoint -> generated map -> OccupancyGrid -> failure bag -> export --bag: every map
    keeps the learned map's origin, so each overlays the original SLAM map in RViz."""
    from sessgan_core.ros_conversion import environment_to_msg, occupancy_from_grid_msg
    from sessgan_evolver.fault_picture import scene_from_bag
    from sessgan_evolver.in_process import InProcessEvaluator
    from sessgan_gen.environment_sampler import EnvironmentSampler

    path = slam_map(tmp_path, origin=(-5.0, -3.0, 0.0))
    output = tmp_path / 'slam.pt'
    assert train_cli.main(['--map-yaml', str(path), '--output', str(output), *TINY]) == 0
    learned = read_map_server(tmp_path / 'slam.map.yaml').origin
    assert learned == pytest.approx((-1.5, 0.5, 0.0))
    _, metadata = load_checkpoint(output)
    assert metadata['map_origin'] == pytest.approx(list(learned))

    assert export_main(['--generate', '--checkpoint', str(output), '--seed', '3',
                        '--output', str(tmp_path / 'generated.yaml')]) == 0
    assert read_map_server(tmp_path / 'generated.yaml').origin == pytest.approx(learned)

    environment = EnvironmentSampler().sample([3], output)[0]
    environment.validate()  # start and goal lie on the map at its origin
    assert environment.origin == pytest.approx(learned[:2])
    _, _, grid_origin = occupancy_from_grid_msg(environment_to_msg(environment).map)
    assert grid_origin == pytest.approx(learned[:2])
    with InProcessEvaluator('factory', time_limit=1.0) as evaluator:
        run = evaluator.runner.run(environment, 1, trace=True, keep_scans=True)
        bag = evaluator.write_bag(tmp_path / 'bags' / environment.id, environment, 1, run)
    assert scene_from_bag(bag).origin == pytest.approx(learned[:2])
    assert export_main(['--bag', str(bag), '--output', str(tmp_path / 'failing.yaml')]) == 0
    exported = read_map_server(tmp_path / 'failing.yaml')
    assert exported.origin == pytest.approx(learned)
    assert np.array_equal(exported.occupancy, environment.occupancy)
    # ... and loads so in map_server (its loading rules, transcribed: Nav2 is not installed).
    served = nav2_load_map(tmp_path / 'failing.yaml')
    assert np.array_equal(served.data, environment.occupancy)
    assert served.origin == pytest.approx(learned) and served.resolution == 0.5


def test_a_method_campaign_places_its_maps_and_measures_tpkl_at_the_checkpoints_map(
        tmp_path):
    from sessgan_evolver.campaign import CampaignConfig
    from sessgan_evolver.method_campaign import MethodCampaign
    from sessgan_evolver.search_methods import Proposal

    path = slam_map(tmp_path, origin=(-5.0, -3.0, 0.0))
    output = tmp_path / 'slam.pt'
    assert train_cli.main(['--map-yaml', str(path), '--output', str(output), *TINY]) == 0
    _, metadata = load_checkpoint(output)
    campaign = MethodCampaign(CampaignConfig(scenario='factory', method='screened',
                                             checkpoint=str(output), time_limit=1.0),
                              'screened', tmp_path / 'runs', tmp_path / 'bags')
    assert np.array_equal(campaign.example, training_map(metadata))
    cells = training_map(metadata)
    environment = campaign.environment_of(Proposal(cells, 1, 1, 'test'), 'e0', 0, 0)
    assert environment.origin == pytest.approx((-1.5, 0.5))
    environment.validate()
    # The whole campaign on these small (12 x 16) maps; its report names no bag folder
    # while none was written.
    assert campaign_main(['--in-process', '--scenario', 'factory', '--checkpoint', str(output),
                          '--method', 'screened', '--budget', '2', '--time-limit', '1',
                          '--no-record-failures', '--run', 'small',
                          '--runs-root', str(tmp_path / 'runs'),
                          '--bags-root', str(tmp_path / 'bags')]) == 0
    report = (tmp_path / 'runs' / 'small' / 'report' / 'report.md').read_text()
    assert 'No failure bag was written' in report and str(tmp_path / 'bags') not in report
