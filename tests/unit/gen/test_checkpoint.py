"""Generator checkpoints: round trips through files and bytes, and clear errors."""

from __future__ import annotations

import io
import json

import pytest
import torch

from sessgan_core.errors import UnknownScenarioError
from sessgan_gen.checkpoint import (
    CHECKPOINT_DIR,
    checkpoint_bytes,
    default_checkpoint_path,
    load_checkpoint,
    load_training_checkpoint,
    metadata_path,
    save_checkpoint,
)
from sessgan_gen.errors import CheckpointError
from sessgan_gen.model import GeneratorPyramid, pyramid_scale_shapes

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


def factory_pyramid(channels: int = 8) -> GeneratorPyramid:
    torch.manual_seed(0)
    pyramid = GeneratorPyramid(2, pyramid_scale_shapes(16, 16), channels=channels)
    pyramid.noise_amplitudes.copy_(torch.tensor([1.0, 0.25]))
    pyramid.reconstruction_noise.normal_()
    return pyramid


METADATA = {'scenario': 'factory', 'tokens': ['G', 'W'], 'seed': 3}


def test_file_round_trip_with_json_metadata(tmp_path):
    pyramid = factory_pyramid()
    path = save_checkpoint(tmp_path / 'factory.pt', pyramid, METADATA)
    loaded, metadata = load_checkpoint(path)
    assert torch.equal(loaded.sample(seeds=[1, 2]), pyramid.sample(seeds=[1, 2]))
    assert not loaded.training
    assert metadata['scale_shapes'] == [[8, 8], [16, 16]]
    assert metadata['noise_amplitudes'] == [1.0, 0.25]
    on_disk = json.loads(metadata_path(path).read_text())
    assert on_disk == metadata
    assert on_disk['seed'] == 3 and on_disk['num_tokens'] == 2 and on_disk['channels'] == 8
    assert sorted(p.name for p in tmp_path.iterdir()) == ['factory.json', 'factory.pt']


def test_bytes_round_trip_and_scenario_check():
    pyramid = factory_pyramid()
    data = checkpoint_bytes(pyramid, METADATA)
    loaded, metadata = load_checkpoint(data, scenario='factory')
    assert torch.equal(loaded.reconstruct(), pyramid.reconstruct())
    with pytest.raises(CheckpointError, match="trained for scenario 'factory', not 'drone'"):
        load_checkpoint(data, scenario='drone')


def test_missing_empty_truncated_and_foreign_files(tmp_path):
    with pytest.raises(CheckpointError, match='does not exist'):
        load_checkpoint(tmp_path / 'nothing.pt')
    with pytest.raises(CheckpointError, match='is empty'):
        load_checkpoint(b'')
    data = checkpoint_bytes(factory_pyramid(), METADATA)
    truncated = tmp_path / 'truncated.pt'
    truncated.write_bytes(data[: len(data) // 2])
    for bad in (truncated, b'not a checkpoint at all'):
        with pytest.raises(CheckpointError, match='is not a valid checkpoint') as caught:
            load_checkpoint(bad)
        # Never PyTorch's advice to load untrusted files with weights_only=False.
        assert 'weights_only' not in str(caught.value)
    with pytest.raises(CheckpointError, match='is a directory, not a checkpoint file'):
        load_checkpoint(tmp_path)
    foreign = tmp_path / 'foreign.pt'
    torch.save({'weights': torch.zeros(3)}, foreign)
    with pytest.raises(CheckpointError, match='not a sessgan_gen generator checkpoint'):
        load_checkpoint(foreign)


def test_wrong_tokens_and_wrong_shapes_are_named():
    pyramid = factory_pyramid()
    with pytest.raises(CheckpointError, match="tokens \\['G', 'O'\\]"):
        load_checkpoint(checkpoint_bytes(pyramid, {**METADATA, 'tokens': ['G', 'O']}))
    three_tokens = GeneratorPyramid(3, pyramid.scale_shapes, channels=8)
    data = checkpoint_bytes(three_tokens, METADATA)
    with pytest.raises(CheckpointError, match='3 tokens'):
        load_checkpoint(data)
    payload = torch.load(io.BytesIO(checkpoint_bytes(pyramid, METADATA)),
                         weights_only=True)
    payload['pyramid']['generators.1.body.conv.weight'] = torch.zeros(8, 8, 5, 5)
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    with pytest.raises(CheckpointError, match="'generators.1.body.conv.weight' has shape"):
        load_checkpoint(buffer.getvalue())


def test_training_state_travels_in_the_pt_only(tmp_path):
    pyramid = factory_pyramid()
    state = {'trained_scales': 1, 'rng_state': torch.get_rng_state(), 'seconds': 1.5}
    path = save_checkpoint(tmp_path / 'partial.pt', pyramid, METADATA, state)
    _, _, loaded_state = load_training_checkpoint(path)
    assert loaded_state['trained_scales'] == 1
    assert torch.equal(loaded_state['rng_state'], state['rng_state'])
    assert 'rng_state' not in metadata_path(path).read_text()
    plain = save_checkpoint(tmp_path / 'plain.pt', pyramid, METADATA)
    with pytest.raises(CheckpointError, match='no training state'):
        load_training_checkpoint(plain)


def test_unserialisable_metadata_is_refused(tmp_path):
    with pytest.raises(CheckpointError, match='JSON'):
        save_checkpoint(tmp_path / 'x.pt', factory_pyramid(), {**METADATA, 'bad': object()})
    assert not list(tmp_path.iterdir())


def test_default_checkpoint_paths():
    assert default_checkpoint_path('drone') == CHECKPOINT_DIR / 'drone.pt'
    with pytest.raises(UnknownScenarioError):
        default_checkpoint_path('moon')


@pytest.mark.parametrize('scenario', ['factory', 'racetrack', 'drone'])
def test_shipped_checkpoints_load_and_sample(scenario):
    path = default_checkpoint_path(scenario)
    assert path.is_file(), f'{path} is shipped with the package and must be there'
    assert path.stat().st_size < 4 * 2**20  # a few MB at most
    pyramid, metadata = load_checkpoint(path, scenario=scenario)
    assert metadata['complete'] is True
    maps = pyramid.sample(seeds=[0, 1])
    assert tuple(maps.shape[1:]) == tuple(metadata['map_shape'])
