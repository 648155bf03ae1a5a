"""Realism is measured against the map the generator learned: a checkpoint carries its
training map, and the campaign, the search methods, evaluate's sources, compare and the
generator report use it as their TPKL reference (not the scenario's example map)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from sessgan_core.token_map import load_example_map, occupancy_to_tokens
from sessgan_evolver.campaign import Campaign, CampaignConfig
from sessgan_evolver.comparison import CompareConfig, _final_source
from sessgan_evolver.fresh_seed import AutomatonSource, PyramidSource
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.search_methods import make_baseline
from sessgan_gen.checkpoint import (
    checkpoint_training_map,
    default_checkpoint_path,
    load_checkpoint,
    save_checkpoint,
    training_map,
)
from sessgan_gen.environment_metrics import tile_pattern_kl
from sessgan_gen.errors import CheckpointError
from sessgan_gen.report import collect_samples
from tests.unit.gen.facility_checkpoint import train_facility_checkpoint

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


@pytest.fixture(scope='module')
def facility(tmp_path_factory):
    return train_facility_checkpoint(tmp_path_factory.mktemp('facility'))


def test_training_stores_the_learned_map_in_the_checkpoint(facility):
    path, cells = facility
    stored = json.loads(path.with_suffix('.json').read_text())['training_map']
    assert stored[0] == 'W' * cells.shape[1] and len(stored) == cells.shape[0]
    _, metadata = load_checkpoint(path)
    assert np.array_equal(training_map(metadata), cells)
    assert not np.array_equal(cells.shape, load_example_map('factory').cells.shape)


@pytest.mark.parametrize('scenario', ['factory', 'racetrack', 'drone'])
def test_shipped_checkpoints_learned_their_example_map(scenario):
    assert np.array_equal(checkpoint_training_map(scenario),
                          load_example_map(scenario).cells)


def test_a_training_map_that_cannot_be_read_back_is_an_error(tmp_path):
    pyramid, metadata = load_checkpoint(default_checkpoint_path('factory'))
    gone = str(tmp_path / 'gone.txt')
    path = save_checkpoint(tmp_path / 'old.pt', pyramid, {**metadata, 'map_source': gone})
    with pytest.raises(CheckpointError, match='gone.txt'):
        checkpoint_training_map('factory', str(path))


class Recording(InProcessEvaluator):
    """The in-process evaluator, keeping every map it sampled (member order)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.sampled: list[list[np.ndarray]] = []

    def sample(self, weights, seeds, generation, member):
        environments = super().sample(weights, seeds, generation, member)
        self.sampled.append([occupancy_to_tokens(env.occupancy, 'factory')
                             for env in environments])
        return environments


def test_the_campaign_measures_tpkl_against_the_checkpoints_map(facility, tmp_path):
    path, cells = facility
    config = CampaignConfig(scenario='factory', generations=1, population=2, maps_per_member=1,
                            workers=1, seed=4, checkpoint=str(path), time_limit=1.0,
                            record_failures=False)
    campaign = Campaign(config, 'facility', tmp_path / 'runs', tmp_path / 'bags',
                        log=lambda _: None)
    assert np.array_equal(campaign.example, cells)
    with Recording('factory', time_limit=1.0) as evaluator:
        campaign.run(evaluator)
    members = campaign.store.read_rows('member')
    example = load_example_map('factory').cells
    for row, maps in zip(members, evaluator.sampled):
        assert row['tpkl'] == pytest.approx(tile_pattern_kl(cells, maps))
        assert row['tpkl'] != pytest.approx(tile_pattern_kl(example, maps))


def test_search_methods_sources_compare_and_report_use_the_checkpoints_map(facility):
    path, cells = facility
    for method in ('grid_ga', 'latent'):
        assert np.array_equal(make_baseline(method, 'factory', 0, str(path)).example, cells)
    assert np.array_equal(PyramidSource('facility', 'factory', path).reference, cells)
    assert np.array_equal(AutomatonSource('factory').reference,
                          load_example_map('factory').cells)
    source, _ = _final_source(CompareConfig(scenario='factory', checkpoint=str(path)),
                              'cellular_automaton')
    assert source is not None and np.array_equal(source.reference, cells)
    assert np.array_equal(collect_samples('factory', path, 2, 0).example, cells)
