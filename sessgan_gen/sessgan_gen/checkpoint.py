"""Generator checkpoints: one .pt file (state dicts and metadata) plus a JSON copy of the
metadata next to it, both written atomically (temporary file, then os.replace).

The .pt file is a torch-saved dict of plain types and tensors only, so it loads
with ``weights_only=True`` and is safe to accept over the network (the evolver
sends weights to generator nodes as checkpoint bytes)::

    {'format': 'sessgan_gen.pyramid', 'format_version': 1,
     'metadata': {...}, 'pyramid': state_dict, 'training_state': {...} or None}
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from sessgan_core.atomic_files import atomic_write_bytes
from sessgan_core.errors import SessganCoreError, UnknownScenarioError
from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import load_example_map, read_token_map
from sessgan_gen.errors import CheckpointError
from sessgan_gen.model import GeneratorPyramid, pyramid_from_state_dict, resolve_device

CHECKPOINT_FORMAT = 'sessgan_gen.pyramid'
FORMAT_VERSION = 1
CHECKPOINT_DIR = Path(__file__).resolve().parent / 'data' / 'checkpoints'
"""Where the shipped pre-trained checkpoints live."""


def default_checkpoint_path(scenario: str) -> Path:
    """Path of the shipped pre-trained checkpoint of ``scenario`` (UnknownScenarioError if the
    scenario is not registered; the file may be absent for user-registered scenarios)."""
    get_scenario(scenario)
    return CHECKPOINT_DIR / f'{scenario}.pt'


def metadata_path(path: str | Path) -> Path:
    """The JSON metadata file that accompanies checkpoint ``path``."""
    return Path(path).with_suffix('.json')


def structural_metadata(pyramid: GeneratorPyramid) -> dict[str, Any]:
    """Metadata fields that describe the pyramid itself (always taken from the pyramid)."""
    return {
        'num_tokens': pyramid.num_tokens,
        'channels': pyramid.channels,
        'num_scales': pyramid.num_scales,
        'scale_shapes': [list(shape) for shape in pyramid.scale_shapes],
        'noise_amplitudes': [round(float(a), 8) for a in pyramid.noise_amplitudes.cpu()],
    }


def training_map_rows(cells: np.ndarray, tokens: list[str] | tuple[str, ...]) -> list[str]:
    """The ``training_map`` metadata field: the learned token map as rows of token characters,
    top row first (as in the token text format), so the checkpoint carries its own TPKL
    reference."""
    chars = np.array(list(tokens))
    return [''.join(row) for row in chars[np.asarray(cells)[::-1]]]


def training_map(metadata: Mapping[str, Any]) -> np.ndarray:
    """The token map (cells, OccupancyGrid row order) the checkpoint was trained on: its
    ``training_map`` field; for a checkpoint written before that field existed, the map its
    ``map_source`` names (the scenario's example map for ``example:<scenario>``, as for the
    shipped checkpoints, or the token file it learned); for one that names no source (made by
    hand, not trained), the scenario's example map. Every TPKL figure of a generator is
    measured against this map. CheckpointError if the source named cannot be read back."""
    rows = metadata.get('training_map')
    tokens = list(metadata.get('tokens') or [])
    if rows is not None:
        index = {token: value for value, token in enumerate(tokens)}
        try:
            cells = np.array([[index[char] for char in row] for row in rows[::-1]],
                             dtype=np.int64)
        except (KeyError, TypeError) as err:
            raise CheckpointError(f'checkpoint training_map holds a token not in {tokens}: '
                                  f'{err}') from err
        if cells.ndim != 2 or cells.size == 0:
            raise CheckpointError('checkpoint training_map is not a rectangular token map')
        return cells
    source = str(metadata.get('map_source') or '')
    scenario = str(metadata.get('scenario') or '')
    try:
        if not source or source == f'example:{scenario}':
            return load_example_map(scenario).cells
        if source.endswith('.txt') and Path(source).is_file():
            return read_token_map(source, scenario).cells
    except SessganCoreError as err:
        raise CheckpointError(f'cannot read the training map {source!r} of the checkpoint: '
                              f'{err}') from err
    raise CheckpointError(
        f'the checkpoint holds no training map and its map source {source!r} cannot be read '
        'back; train it again with this version to store the map in it')


def checkpoint_metadata(scenario: str, checkpoint: str | Path | bytes | None = None
                        ) -> Mapping[str, Any]:
    """The metadata of ``checkpoint`` (a path or bytes; None or empty: the scenario's shipped
    one), checked to be a checkpoint of ``scenario``."""
    payload = read_checkpoint(checkpoint or default_checkpoint_path(scenario))
    _check_scenario(payload['label'], payload['metadata'], scenario)
    return payload['metadata']


def checkpoint_training_map(scenario: str, checkpoint: str | Path | bytes | None = None
                            ) -> np.ndarray:
    """:func:`training_map` of :func:`checkpoint_metadata`."""
    return training_map(checkpoint_metadata(scenario, checkpoint))


def incomplete_warning(metadata: Mapping[str, Any], label: str = 'the checkpoint') -> str:
    """A warning for a checkpoint of a training that stopped before its last scale (its finer
    scales are untrained, so its maps are noise), or '' for a complete one."""
    if metadata.get('complete', True) is not False:
        return ''
    return (f'{label} is of a training that stopped after scale '
            f'{metadata.get("trained_scales", "?")} of {metadata.get("num_scales", "?")}: its '
            'finer scales are untrained and its maps mostly noise; finish it with '
            '`ros2 run sessgan_gen train ... --resume`')


def map_size(metadata: Mapping[str, Any]) -> tuple[int, int]:
    """(height, width) in cells of the map the checkpoint learned: the size its generator
    serves by default."""
    shape = metadata.get('map_shape') or metadata['scale_shapes'][-1]
    return int(shape[0]), int(shape[1])


def map_origin(metadata: Mapping[str, Any]) -> tuple[float, float]:
    """Map-frame position (x, y) in metres of the corner of cell (0, 0) of every map the
    checkpoint's generator serves: its training map's origin (``map_origin``, that of the
    map_server map it imported, moved to the cropped region), so generated maps, their
    OccupancyGrid and failure bags overlay the original map in RViz; (0, 0) for a checkpoint
    that stores none (token maps, the shipped ones). A rotated origin keeps only its position:
    the simulator and OccupancyGrid consumers take axis-aligned maps. CheckpointError when
    the field is malformed."""
    value = metadata.get('map_origin')
    if value is None:
        return (0.0, 0.0)
    if (not isinstance(value, (list, tuple)) or len(value) not in (2, 3)
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for v in value)):
        raise CheckpointError(f'checkpoint map_origin must be [x, y, yaw] of finite numbers, '
                              f'got {value!r}')
    return (float(value[0]), float(value[1]))


def _payload(
    pyramid: GeneratorPyramid,
    metadata: Mapping[str, Any],
    training_state: Mapping[str, Any] | None,
) -> dict[str, Any]:
    full = {'format_version': FORMAT_VERSION, **dict(metadata), **structural_metadata(pyramid)}
    try:  # plain JSON types only: the .pt must load with weights_only=True
        full = json.loads(json.dumps(full))
    except (TypeError, ValueError) as err:
        raise CheckpointError(f'checkpoint metadata is not JSON-serialisable: {err}') from err
    return {
        'format': CHECKPOINT_FORMAT,
        'format_version': FORMAT_VERSION,
        'metadata': full,
        'pyramid': {k: v.detach().cpu().clone() for k, v in pyramid.state_dict().items()},
        'training_state': dict(training_state) if training_state is not None else None,
    }


def checkpoint_bytes(
    pyramid: GeneratorPyramid,
    metadata: Mapping[str, Any],
    training_state: Mapping[str, Any] | None = None,
) -> bytes:
    """The checkpoint as bytes (what :func:`save_checkpoint` writes to the .pt file)."""
    buffer = io.BytesIO()
    torch.save(_payload(pyramid, metadata, training_state), buffer)
    return buffer.getvalue()


def save_checkpoint(
    path: str | Path,
    pyramid: GeneratorPyramid,
    metadata: Mapping[str, Any],
    training_state: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``pyramid`` and ``metadata`` to ``path`` (.pt) and its .json metadata file.

    ``metadata`` should name at least 'scenario' and 'tokens'; the structural
    fields (num_tokens, channels, scale_shapes, noise_amplitudes) are added from
    the pyramid. ``training_state`` (resume data) goes into the .pt only.
    Returns the .pt path.
    """
    path = Path(path)
    payload = _payload(pyramid, metadata, training_state)
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    atomic_write_bytes(path, buffer.getvalue())
    text = json.dumps(payload['metadata'], indent=2, sort_keys=True) + '\n'
    atomic_write_bytes(metadata_path(path), text.encode())
    return path


def check_checkpoint_file(path: Path, label: str) -> None:
    """CheckpointError unless ``path`` is an existing regular file: says whether it is
    missing, a directory or something else."""
    if path.is_dir():
        raise CheckpointError(f'{label} is a directory, not a checkpoint file')
    if not path.exists():
        raise CheckpointError(f'{label} does not exist')
    if not path.is_file():
        raise CheckpointError(f'{label} is not a regular file')


def not_a_checkpoint_message(label: str, err: BaseException) -> str:
    """The message for a file torch cannot load with ``weights_only=True``.

    PyTorch's own message advises loading with ``weights_only=False``, which runs any code
    the file holds: never do that with a file from elsewhere, so the advice is left out.
    """
    return (f'{label} is not a valid checkpoint: it is truncated, corrupt or not a '
            f'checkpoint at all ({type(err).__name__})')


def read_checkpoint(source: str | Path | bytes) -> dict[str, Any]:
    """Read and check the raw payload of a checkpoint file or bytes (no pyramid built)."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        label = f'checkpoint bytes ({len(source)} bytes)'
        stream: Any = io.BytesIO(bytes(source))
    else:
        path = Path(source)
        label = f'checkpoint {str(path)!r}'
        check_checkpoint_file(path, label)
        stream = path
    if isinstance(stream, io.BytesIO) and not stream.getbuffer().nbytes:
        raise CheckpointError(f'{label} is empty')
    try:
        payload = torch.load(stream, map_location='cpu', weights_only=True)
    except Exception as err:  # torch raises many types for a truncated or foreign file
        raise CheckpointError(not_a_checkpoint_message(label, err)) from err
    if not isinstance(payload, dict) or payload.get('format') != CHECKPOINT_FORMAT:
        raise CheckpointError(f'{label} is not a sessgan_gen generator checkpoint')
    version = payload.get('format_version')
    if version != FORMAT_VERSION:
        raise CheckpointError(
            f'{label} has format version {version}; this software reads {FORMAT_VERSION}')
    metadata = payload.get('metadata')
    if not isinstance(metadata, dict):
        raise CheckpointError(f'{label} has no metadata')
    for key in ('scenario', 'tokens', 'scale_shapes'):
        if key not in metadata:
            raise CheckpointError(f'{label} metadata lacks {key!r}')
    if not isinstance(payload.get('pyramid'), dict):
        raise CheckpointError(f'{label} holds no generator weights')
    payload['label'] = label
    return payload


def _check_scenario(label: str, metadata: Mapping[str, Any], scenario: str | None) -> None:
    name = metadata['scenario']
    if scenario is not None and name != scenario:
        raise CheckpointError(f'{label} was trained for scenario {name!r}, not {scenario!r}')
    try:
        known = get_scenario(name)
    except UnknownScenarioError:
        return  # a user scenario registered elsewhere; its tokens cannot be checked
    if list(metadata['tokens']) != list(known.tokens):
        raise CheckpointError(
            f'{label} has tokens {list(metadata["tokens"])}, but scenario {name!r} has '
            f'{list(known.tokens)}')


def _build(label: str, payload: Mapping[str, Any], device: str | torch.device) -> GeneratorPyramid:
    metadata = payload['metadata']
    try:
        shapes = [(int(h), int(w)) for h, w in metadata['scale_shapes']]
    except (TypeError, ValueError) as err:
        raise CheckpointError(f'{label} has malformed scale_shapes: {err}') from err
    try:
        pyramid = pyramid_from_state_dict(payload['pyramid'], shapes)
    except CheckpointError as err:
        raise CheckpointError(f'{label}: {err}') from err
    if pyramid.num_tokens != len(metadata['tokens']):
        raise CheckpointError(
            f'{label}: weights are for {pyramid.num_tokens} tokens but metadata lists '
            f'{len(metadata["tokens"])}')
    pyramid.eval()
    return pyramid.to(resolve_device(device))


def load_checkpoint(
    source: str | Path | bytes,
    device: str | torch.device = 'cpu',
    scenario: str | None = None,
) -> tuple[GeneratorPyramid, dict[str, Any]]:
    """Load a checkpoint file or its bytes; returns (pyramid in eval mode, metadata).

    ``scenario``, if given, must be the one the checkpoint was trained for.
    Raises CheckpointError naming what is wrong: missing, empty, truncated or
    corrupt file, foreign format, wrong scenario or tokens, missing keys or
    tensors of the wrong shape.
    """
    payload = read_checkpoint(source)
    label = payload['label']
    _check_scenario(label, payload['metadata'], scenario)
    return _build(label, payload, device), dict(payload['metadata'])


def load_training_checkpoint(
    path: str | Path, device: str | torch.device = 'cpu'
) -> tuple[GeneratorPyramid, dict[str, Any], dict[str, Any]]:
    """Load a (possibly partial) training checkpoint: (pyramid, metadata, training state)."""
    payload = read_checkpoint(path)
    label = payload['label']
    _check_scenario(label, payload['metadata'], None)
    state = payload.get('training_state')
    if not isinstance(state, dict):
        raise CheckpointError(f'{label} holds no training state to resume from')
    return _build(label, payload, device), dict(payload['metadata']), state

