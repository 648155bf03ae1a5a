"""Sampling many maps from a pyramid: chunked batches, seeds, conversions to numpy.

:meth:`GeneratorPyramid.sample` does the work; this module adds what callers that
need hundreds of maps want: one seed per map derived from a base seed, batches of
bounded size (memory), and numpy output.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from sessgan_gen.model import GeneratorPyramid, scaled_shapes
from sessgan_gen.seeding import derive_seeds

BATCH_CELLS = 32 * 32 * 32
"""Cells per forward pass: 32 maps of 32x32 or 2 of 128x128. Measured on a 2-core CPU,
throughput peaks between 16K and 64K cells per batch; larger batches fall out of cache
(128 maps of 128x128 per batch run at half the speed of one map per call)."""

SAMPLE_SEED_STREAM = 1
"""Stream number of :func:`sample_seeds` (so they differ from other seeds of a base seed)."""


def sample_seeds(base_seed: int, count: int) -> list[int]:
    """``count`` per-map seeds derived from one base seed (same base, same list)."""
    return derive_seeds(base_seed, count, SAMPLE_SEED_STREAM)


def batch_size_for(size: tuple[int, int], budget_cells: int = BATCH_CELLS) -> int:
    """Maps per batch so one batch has about ``budget_cells`` cells (at least 1)."""
    return max(1, budget_cells // max(1, size[0] * size[1]))


def sample_token_maps(
    pyramid: GeneratorPyramid,
    seeds: Sequence[int],
    size: tuple[int, int] | None = None,
    batch_size: int | None = None,
) -> np.ndarray:
    """Token maps (len(seeds), height, width) as int64, one per seed, in seed order.

    Map i depends only on ``seeds[i]`` (and the weights), whatever ``batch_size``.
    """
    shape = tuple(size) if size is not None else pyramid.size
    if batch_size is None:
        batch_size = batch_size_for(shape)  # type: ignore[arg-type]
    if batch_size < 1:
        raise ValueError(f'batch_size must be at least 1, got {batch_size}')
    chunks = []
    for start in range(0, len(seeds), batch_size):
        chunk = pyramid.sample(seeds=seeds[start:start + batch_size], size=size)
        chunks.append(chunk.numpy())
    if not chunks:
        return np.zeros((0, *shape), dtype=np.int64)
    return np.concatenate(chunks).astype(np.int64, copy=False)


def noise_shapes(
    pyramid: GeneratorPyramid, size: tuple[int, int] | None = None
) -> list[tuple[int, int, int]]:
    """(tokens, height, width) of each scale's noise map, coarsest first, for maps of ``size``
    (height, width; default the training size)."""
    return [(pyramid.num_tokens, h, w) for h, w in scaled_shapes(pyramid.scale_shapes, size)]


def seed_noise_maps(
    pyramid: GeneratorPyramid, seed: int, size: tuple[int, int] | None = None
) -> list[np.ndarray]:
    """The standard-normal noise maps (one float32 array per scale, shapes of
    :func:`noise_shapes`) that :func:`sample_token_maps` draws for ``seed``: feeding them to
    :func:`sample_token_maps_from_noise` gives the same map."""
    shapes = scaled_shapes(pyramid.scale_shapes, size)
    noises = pyramid.draw_noise([torch.Generator().manual_seed(int(seed))], shapes)
    return [noise[0].cpu().numpy() for noise in noises]


def sample_token_maps_from_noise(
    pyramid: GeneratorPyramid, noise_maps: Sequence[Sequence[np.ndarray]]
) -> np.ndarray:
    """Token maps (len(noise_maps), height, width) as int64 from explicit noise.

    ``noise_maps[i]`` holds map i's noise, one array per scale with the shapes of
    :func:`noise_shapes` (standard normal is what seeds give; the pyramid's noise amplitudes
    scale it as in sampling). The weights are used as they are (eval mode), so evolving the
    noise with the weights frozen searches the generator's own latent space.
    """
    if not noise_maps:
        height, width = pyramid.size
        return np.zeros((0, height, width), dtype=np.int64)
    expected = [tuple(np.shape(noise)) for noise in noise_maps[0]]
    if len(expected) != pyramid.num_scales:
        raise ValueError(f'map 0 has {len(expected)} noise maps; the pyramid has '
                         f'{pyramid.num_scales} scales')
    for index, noises in enumerate(noise_maps):
        shapes = [tuple(np.shape(noise)) for noise in noises]
        if shapes != expected:
            raise ValueError(f'map {index} has noise shapes {shapes}; map 0 has {expected}')
    for scale, shape in enumerate(expected):
        if len(shape) != 3 or shape[0] != pyramid.num_tokens:
            raise ValueError(f'scale {scale} noise has shape {shape}; expected '
                             f'({pyramid.num_tokens}, height, width)')
    batch = [torch.as_tensor(np.stack([np.asarray(noises[scale], dtype=np.float32)
                                       for noises in noise_maps])).to(pyramid.device)
             for scale in range(len(expected))]
    was_training = pyramid.training
    pyramid.eval()
    try:
        with torch.no_grad():
            output = pyramid.generate(batch)
    finally:
        pyramid.train(was_training)
    return output.argmax(dim=1).cpu().numpy().astype(np.int64, copy=False)


def sample_one(
    pyramid: GeneratorPyramid, seed: int, size: tuple[int, int] | None = None
) -> np.ndarray:
    """One token map (height, width) for ``seed``."""
    return pyramid.sample(seeds=[seed], size=size)[0].numpy().astype(np.int64, copy=False)

