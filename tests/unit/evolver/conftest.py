"""Fixtures of the evolver tests: small generator-like state dicts, no GAN training."""

from __future__ import annotations

import pytest
import torch


def fake_pyramid_state_dict(scales: int = 2, channels: int = 4, tokens: int = 2,
                            seed: int = 0) -> dict[str, torch.Tensor]:
    """A state dict shaped like sessgan_gen's GeneratorPyramid: per scale a head and body
    Conv-BatchNorm block and a conv tail, plus the fixed noise buffers and BatchNorm's
    integer counters that evolution must leave alone."""
    generator = torch.Generator().manual_seed(seed)
    state: dict[str, torch.Tensor] = {}
    for scale in range(scales):
        prefix = f'generators.{scale}'
        for block, inputs in (('head', tokens), ('body', channels)):
            state[f'{prefix}.{block}.conv.weight'] = 0.02 * torch.randn(
                channels, inputs, 3, 3, generator=generator)
            state[f'{prefix}.{block}.conv.bias'] = torch.zeros(channels)
            state[f'{prefix}.{block}.norm.weight'] = torch.ones(channels)
            state[f'{prefix}.{block}.norm.bias'] = torch.zeros(channels)
            state[f'{prefix}.{block}.norm.running_mean'] = 0.1 * torch.randn(
                channels, generator=generator)
            state[f'{prefix}.{block}.norm.running_var'] = 0.5 + torch.rand(
                channels, generator=generator)
            state[f'{prefix}.{block}.norm.num_batches_tracked'] = torch.tensor(100)
        state[f'{prefix}.tail.weight'] = 0.02 * torch.randn(tokens, channels, 3, 3,
                                                            generator=generator)
        state[f'{prefix}.tail.bias'] = torch.zeros(tokens)
    state['noise_amplitudes'] = torch.tensor([1.0, 0.1][:scales] + [0.05] * (scales - 2))
    state['reconstruction_noise'] = torch.randn(1, tokens, 8, 8, generator=generator)
    return state


@pytest.fixture
def state_dict() -> dict[str, torch.Tensor]:
    return fake_pyramid_state_dict()


@pytest.fixture
def make_state_dict():
    """The factory itself, for tests that need several state dicts or other sizes."""
    return fake_pyramid_state_dict
