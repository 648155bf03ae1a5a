"""A generator trained on a facility serves maps of the facility's size by default, and any
size on request, in every command: the sampler (generator node, export --generate), the
campaign, evaluate's sources, compare's search methods and final sources."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sessgan_core.map_server_io import read_map_server
from sessgan_evolver.campaign import Campaign, CampaignConfig, CampaignError
from sessgan_evolver.campaign_cli import main as campaign_main
from sessgan_evolver.comparison import CompareConfig, _final_source
from sessgan_evolver.errors import SearchMethodError
from sessgan_evolver.evaluate_cli import build_sources, parse_args
from sessgan_evolver.fresh_seed import campaign_sources
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.search_methods import BASELINES, make_baseline
from sessgan_gen.environment_sampler import EnvironmentSampler
from sessgan_gen.errors import SamplingRequestError
from sessgan_gen.export_cli import main as export_main
from tests.unit.gen.facility_checkpoint import (
    FACILITY_HEIGHT,
    FACILITY_WIDTH,
    train_facility_checkpoint,
)

pytestmark = pytest.mark.unit
torch.set_num_threads(1)

FACILITY = (FACILITY_HEIGHT, FACILITY_WIDTH)


@pytest.fixture(scope='module')
def facility(tmp_path_factory):
    return str(train_facility_checkpoint(tmp_path_factory.mktemp('facility'))[0])


def test_the_sampler_serves_the_learned_size_unless_asked(facility):
    sampler = EnvironmentSampler()
    assert sampler.sample([1], facility)[0].occupancy.shape == FACILITY
    assert sampler.sample([1], facility, size=(0, 0))[0].occupancy.shape == FACILITY
    assert sampler.sample([1], facility, size=(24, 40))[0].occupancy.shape == (24, 40)
    # A zero side takes the learned map's.
    assert sampler.sample([1], facility, size=(0, 36))[0].occupancy.shape == (20, 36)
    assert sampler.sample([1], None, 'factory')[0].occupancy.shape == (32, 32)
    with pytest.raises(SamplingRequestError, match='outside'):
        sampler.sample([1], facility, size=(2, 2))


def test_export_generate_writes_the_learned_size_or_the_one_asked(facility, tmp_path):
    assert export_main(['--generate', '--checkpoint', facility, '--output',
                        str(tmp_path / 'a.yaml')]) == 0
    assert read_map_server(tmp_path / 'a.yaml').occupancy.shape == FACILITY
    assert export_main(['--generate', '--checkpoint', facility, '--width', '40', '--height',
                        '24', '--output', str(tmp_path / 'b.yaml')]) == 0
    assert read_map_server(tmp_path / 'b.yaml').occupancy.shape == (24, 40)


def campaign_argv(facility: str, tmp_path, run: str, *extra: str) -> list[str]:
    return ['--in-process', '--scenario', 'factory', '--checkpoint', facility,
            '--method', 'sessgan', '--generations', '1', '--population', '2',
            '--maps-per-member', '1', '--time-limit', '1', '--no-record-failures', '--run', run,
            '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags'),
            *extra]


def test_the_campaign_runs_at_the_learned_size_or_the_one_asked(facility, tmp_path):
    # Exit 1 means that no map was a valid test (a 2-iteration generator rarely makes one).
    assert campaign_main(campaign_argv(facility, tmp_path, 'learned')) in (0, 1)
    maps = np.load(tmp_path / 'runs' / 'learned' / 'sample_maps' / 'generation_0000.npy')
    assert maps.shape[1:] == FACILITY
    assert campaign_main(campaign_argv(facility, tmp_path, 'asked', '--width', '36',
                                       '--height', '24')) in (0, 1)
    maps = np.load(tmp_path / 'runs' / 'asked' / 'sample_maps' / 'generation_0000.npy')
    assert maps.shape[1:] == (24, 36)
    # evaluate's sources of a campaign keep the campaign's size.
    assert campaign_sources(tmp_path / 'runs' / 'asked')[0].maps([5]).shape == (1, 24, 36)
    assert campaign_sources(tmp_path / 'runs' / 'learned')[0].maps([5]).shape == (1, *FACILITY)


def test_the_campaign_refuses_a_size_or_maps_it_cannot_use(facility, tmp_path):
    config = CampaignConfig(scenario='factory', generations=1, population=2,
                            maps_per_member=1, checkpoint=facility, time_limit=1.0)
    with pytest.raises(CampaignError, match='outside'):
        Campaign(CampaignConfig(**{**config.to_dict(), 'fitness': config.fitness,
                                   'width': 2}), 'tiny', tmp_path / 'runs', tmp_path / 'bags')
    campaign = Campaign(config, 'other', tmp_path / 'runs', tmp_path / 'bags',
                        log=lambda _: None)
    assert campaign.size == FACILITY
    # An evaluator that serves another size (a generator node started elsewhere) is caught.
    with InProcessEvaluator('factory', time_limit=1.0, size=(32, 32)) as evaluator:
        with pytest.raises(CampaignError, match='32x32'):
            campaign.run(evaluator)


def test_evaluate_sources_follow_the_checkpoint(facility):
    sources = build_sources(parse_args(['--checkpoint', facility, '--cellular-automaton']),
                            'factory')
    assert [source.maps([1, 2]).shape for source in sources] == [(2, *FACILITY)] * 2
    sources = build_sources(parse_args(['--checkpoint', facility, '--cellular-automaton',
                                        '--width', '30', '--height', '22']), 'factory')
    assert [source.maps([1]).shape for source in sources] == [(1, 22, 30)] * 2
    shipped = build_sources(parse_args(['--cellular-automaton']), 'factory')
    assert [source.maps([1]).shape for source in shipped] == [(1, 32, 32)] * 2


@pytest.mark.parametrize('method', sorted(BASELINES))
def test_search_methods_follow_the_checkpoint(facility, method):
    shapes = {np.shape(p.cells) for p in make_baseline(method, 'factory', 0, facility).ask()}
    assert shapes == {FACILITY}
    asked = make_baseline(method, 'factory', 0, facility, size=(22, 30)).ask()
    assert {np.shape(p.cells) for p in asked} == {(22, 30)}
    with pytest.raises(SearchMethodError, match='outside'):
        make_baseline(method, 'factory', 0, facility, size=(1, 1))


def test_compare_final_sources_follow_the_checkpoint(facility):
    for method in ('random', 'cellular_automaton'):
        source, _ = _final_source(CompareConfig(checkpoint=facility), method)
        assert source is not None and source.maps([3]).shape == (1, *FACILITY)
        source, _ = _final_source(CompareConfig(checkpoint=facility, width=26, height=18),
                                  method)
        assert source is not None and source.maps([3]).shape == (1, 18, 26)
    assert CompareConfig(width=26, height=18).campaign_config(0).width == 26


def test_evaluate_warns_about_an_incomplete_checkpoint(facility, tmp_path, capsys):
    from sessgan_gen.checkpoint import incomplete_warning, load_checkpoint, save_checkpoint

    pyramid, metadata = load_checkpoint(facility)
    assert incomplete_warning(metadata) == ''
    partial = save_checkpoint(tmp_path / 'partial.pt', pyramid,
                              {**metadata, 'complete': False, 'trained_scales': 1})
    build_sources(parse_args(['--checkpoint', str(partial)]), 'factory')
    assert 'stopped after scale 1 of 2' in capsys.readouterr().err
