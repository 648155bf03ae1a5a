"""The TOAD-GAN model: a pyramid of fully convolutional per-scale generators.

Every scale has a generator and (during training only) a patch discriminator,
each of ``NUM_CONV_LAYERS`` 3x3 convolutions: two Conv-BatchNorm-LeakyReLU(0.2)
blocks and a plain convolution head. The generator's head maps to one channel per
token, takes a softmax and adds the (bilinearly upsampled) output of the coarser
scale, as TOAD-GAN does; its input is that upsampled output plus noise scaled by
the scale's noise amplitude (added, not concatenated).

One change to TOAD-GAN: the sum of softmax and coarser output is halved. In
TOAD-GAN's plain sum the output of scale s sums to s + 1 per cell, so the
coarser scales outvote the finest 2:1 with three scales, and where the coarse map
says wall the finest scale can at best tie: it can never thin a wall that the
upsampling doubled (samples had two-cell borders and blotchy blocks, TPKL 1.05 on
the factory). Halved, every scale outputs a distribution like the real map it is
compared with, and the finest scale decides every cell the upsampled coarse map
leaves uncertain (wall edges).

The pyramid (:class:`GeneratorPyramid`) is what gets checkpointed and what the
evolver evolves: its ``state_dict()`` holds every generator weight and BatchNorm
statistic, plus two buffers, the per-scale noise amplitudes and the fixed
reconstruction noise ``z_rec`` of the coarsest scale (TOAD-GAN uses zero
reconstruction noise at every finer scale, so only the coarsest one is stored).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import torch
import torch.nn.functional as F
from torch import nn

from sessgan_gen.errors import CheckpointError

NUM_CONV_LAYERS = 3
"""3x3 convolutions per generator and per discriminator."""
KERNEL_SIZE = 3
LEAKY_SLOPE = 0.2
GENERATOR_PADDING = NUM_CONV_LAYERS * (KERNEL_SIZE // 2)
"""Zero padding added around a generator's input (its convolutions are unpadded)."""

DEFAULT_SCALE_FACTOR = 0.5
"""Side ratio between consecutive scales."""
DEFAULT_COARSEST_COVERAGE = 2.0
"""Longest side of the coarsest scale, in receptive fields (see pyramid_scale_shapes)."""


def receptive_field(num_layers: int = NUM_CONV_LAYERS, kernel_size: int = KERNEL_SIZE) -> int:
    """Side in cells of the window one output cell of a generator or discriminator sees."""
    return 1 + num_layers * (kernel_size - 1)


def pyramid_scale_shapes(
    height: int,
    width: int,
    scale_factor: float = DEFAULT_SCALE_FACTOR,
    coarsest_coverage: float = DEFAULT_COARSEST_COVERAGE,
    max_scales: int = 0,
) -> list[tuple[int, int]]:
    """Return the (height, width) of every scale, coarsest first, finest = (height, width).

    This is the one place that decides the number of scales. Scales shrink by
    ``scale_factor`` per step until the coarsest map's longest side is at most
    ``coarsest_coverage`` receptive fields (``receptive_field()`` = 7 cells), so
    the coarsest GAN sees the whole layout: with the default 2.0, every 7x7
    window the coarsest discriminator judges spans at least half the map, and
    the generator's windows overlap over the whole of it (SinGAN's rule). A
    32x32 room gets 3 scales (8, 16, 32), a 128x128 track 5 (8 ... 128). No side
    shrinks below one receptive field. ``max_scales`` > 0 keeps only the finest that many
    (a 128x128 facility with 3: 32, 64, 128), where the whole layout matters less than
    the detail and a 16x downsampled map has lost its 1-cell walls.
    """
    if height < 1 or width < 1:
        raise ValueError(f'map size must be positive, got {height}x{width}')
    if not 0.0 < scale_factor < 1.0:
        raise ValueError(f'scale_factor must lie in (0, 1), got {scale_factor}')
    if coarsest_coverage <= 0:
        raise ValueError(f'coarsest_coverage must be positive, got {coarsest_coverage}')
    if max_scales < 0:
        raise ValueError(f'max_scales must not be negative, got {max_scales}')
    field = receptive_field()
    target = coarsest_coverage * field
    longest = max(height, width)
    steps = 0 if longest <= target else math.ceil(
        math.log(target / longest) / math.log(scale_factor) - 1e-9)
    if max_scales:
        steps = min(steps, max_scales - 1)
    shapes = []
    for step in range(steps, -1, -1):
        factor = scale_factor ** step
        shapes.append((max(min(height, field), round(height * factor)),
                       max(min(width, field), round(width * factor))))
    return shapes


def init_weights(module: nn.Module) -> None:
    """TOAD-GAN / SinGAN initialisation: conv weights N(0, 0.02), BatchNorm scale N(1, 0.02)."""
    if isinstance(module, nn.Conv2d):
        nn.init.normal_(module.weight, 0.0, 0.02)
        if module.bias is not None:
            nn.init.zeros_(module.bias)
    elif isinstance(module, nn.BatchNorm2d):
        nn.init.normal_(module.weight, 1.0, 0.02)
        nn.init.zeros_(module.bias)


class ConvBlock(nn.Sequential):
    """3x3 convolution, BatchNorm, LeakyReLU(0.2)."""

    def __init__(self, in_channels: int, out_channels: int, padding: int) -> None:
        super().__init__()
        self.add_module('conv', nn.Conv2d(in_channels, out_channels, KERNEL_SIZE, padding=padding))
        self.add_module('norm', nn.BatchNorm2d(out_channels))
        self.add_module('activation', nn.LeakyReLU(LEAKY_SLOPE))


class ScaleGenerator(nn.Module):
    """Generator of one scale: softmax(convs(noisy input)) + upsampled coarser output."""

    def __init__(self, num_tokens: int, channels: int) -> None:
        super().__init__()
        self.head = ConvBlock(num_tokens, channels, padding=0)
        self.body = ConvBlock(channels, channels, padding=0)
        self.tail = nn.Conv2d(channels, num_tokens, KERNEL_SIZE, padding=0)

    def forward(
        self, noisy_input: torch.Tensor, previous: torch.Tensor | None
    ) -> torch.Tensor:
        """``noisy_input``: (batch, tokens, h + 2p, w + 2p), padded by GENERATOR_PADDING;
        ``previous``: (batch, tokens, h, w), the upsampled coarser output, or None at the
        coarsest scale. Returns (batch, tokens, h, w), a distribution over tokens per cell."""
        tokens = torch.softmax(self.tail(self.body(self.head(noisy_input))), dim=1)
        if previous is None:
            return tokens
        # TOAD-GAN adds the two; halving the sum keeps a distribution per cell, so the
        # finest scale weighs as much as all coarser ones together (see module docstring).
        return 0.5 * (tokens + previous)


class PatchDiscriminator(nn.Module):
    """WGAN critic of one scale: a score per 7x7 patch (zero padded, so borders count)."""

    def __init__(self, num_tokens: int, channels: int) -> None:
        super().__init__()
        self.head = ConvBlock(num_tokens, channels, padding=1)
        self.body = ConvBlock(channels, channels, padding=1)
        self.tail = nn.Conv2d(channels, 1, KERNEL_SIZE, padding=1)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.tail(self.body(self.head(image)))


def scaled_shapes(
    shapes: Sequence[tuple[int, int]], size: tuple[int, int] | None
) -> list[tuple[int, int]]:
    """Scale every pyramid shape proportionally so the finest becomes ``size`` (h, w)."""
    shapes = [(int(shape[0]), int(shape[1])) for shape in shapes]
    if size is None or tuple(size) == shapes[-1]:
        return shapes
    height, width = int(size[0]), int(size[1])
    if height < 1 or width < 1:
        raise ValueError(f'sample size must be positive, got {height}x{width}')
    ratio_h, ratio_w = height / shapes[-1][0], width / shapes[-1][1]
    result = [(max(1, round(h * ratio_h)), max(1, round(w * ratio_w))) for h, w in shapes[:-1]]
    return result + [(height, width)]


def upsample(image: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    """Bilinear resize of a (batch, tokens, h, w) map to ``shape`` (TOAD-GAN's draw_concat)."""
    if tuple(image.shape[-2:]) == tuple(shape):
        return image
    return F.interpolate(image, size=tuple(shape), mode='bilinear', align_corners=False)


def pad(image: torch.Tensor) -> torch.Tensor:
    """Zero padding of a generator input (TOAD-GAN pads noise and image with zeros)."""
    return F.pad(image, (GENERATOR_PADDING,) * 4)


class GeneratorPyramid(nn.Module):
    """All scale generators of one trained TOAD-GAN, coarsest scale first.

    ``scale_shapes`` are the (height, width) of each scale at training size; they
    are structure, not state, so they travel in checkpoint metadata rather than
    in the state dict. Use :meth:`sample` to make maps.
    """

    noise_amplitudes: torch.Tensor
    """Buffer (num_scales,): the noise amplitude of each scale (1 at the coarsest)."""
    reconstruction_noise: torch.Tensor
    """Buffer (1, tokens, h0, w0): the fixed noise z_rec that reconstructs the example."""

    def __init__(
        self, num_tokens: int, scale_shapes: Sequence[tuple[int, int]], channels: int = 32
    ) -> None:
        super().__init__()
        if num_tokens < 2:
            raise ValueError(f'a pyramid needs at least 2 tokens, got {num_tokens}')
        if not scale_shapes:
            raise ValueError('a pyramid needs at least one scale')
        self.num_tokens = int(num_tokens)
        self.channels = int(channels)
        self.scale_shapes: tuple[tuple[int, int], ...] = tuple(
            (int(h), int(w)) for h, w in scale_shapes)
        self.generators = nn.ModuleList(
            ScaleGenerator(num_tokens, channels) for _ in self.scale_shapes)
        self.generators.apply(init_weights)
        self.register_buffer('noise_amplitudes', torch.ones(len(self.scale_shapes)))
        self.register_buffer(
            'reconstruction_noise', torch.zeros(1, num_tokens, *self.scale_shapes[0]))

    @property
    def num_scales(self) -> int:
        return len(self.scale_shapes)

    @property
    def device(self) -> torch.device:
        return self.noise_amplitudes.device

    @property
    def size(self) -> tuple[int, int]:
        """(height, width) of the training map."""
        return self.scale_shapes[-1]

    # ---- generation -------------------------------------------------------------------------

    def generate(
        self,
        noises: Sequence[torch.Tensor],
        amplitudes: Sequence[float] | torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Run the first ``len(noises)`` scales; noise ``s`` has shape (batch, tokens, h_s, w_s)
        and fixes that scale's size. Returns the soft output (batch, tokens, h, w) of the last
        scale run (its argmax over tokens is the map)."""
        if not 1 <= len(noises) <= self.num_scales:
            raise ValueError(f'need 1..{self.num_scales} noise maps, got {len(noises)}')
        scale_amplitudes = self.noise_amplitudes if amplitudes is None else amplitudes
        output: torch.Tensor = self.generators[0](pad(scale_amplitudes[0] * noises[0]), None)
        for scale, noise in enumerate(noises[1:], start=1):
            previous = upsample(output, (int(noise.shape[-2]), int(noise.shape[-1])))
            output = self.generators[scale](
                pad(scale_amplitudes[scale] * noise + previous), previous)
        return output

    def reconstruction_noises(self, num_scales: int | None = None) -> list[torch.Tensor]:
        """The fixed noise that reconstructs the training map: z_rec, then zeros."""
        count = self.num_scales if num_scales is None else num_scales
        noises = [self.reconstruction_noise]
        for shape in self.scale_shapes[1:count]:
            noises.append(torch.zeros(1, self.num_tokens, *shape, device=self.device))
        return noises[:count]

    def draw_noise(
        self,
        rngs: Sequence[torch.Generator] | torch.Generator,
        shapes: Sequence[tuple[int, int]] | None = None,
        batch: int | None = None,
    ) -> list[torch.Tensor]:
        """Standard normal noise for every scale of ``shapes`` (default: training shapes).

        With a list of generators, map i draws all of its noise (every scale, in
        order) from ``rngs[i]`` alone, so its noise does not depend on the batch.
        With one generator, ``batch`` maps draw from it one after the other.
        Noise is drawn on the CPU and then moved to the pyramid's device, so a
        seed gives the same noise on every device.
        """
        shapes = list(self.scale_shapes if shapes is None else shapes)
        per_scale = [self.num_tokens * h * w for h, w in shapes]
        total = sum(per_scale)
        if isinstance(rngs, torch.Generator):
            count = 1 if batch is None else batch
            flat = torch.randn(count, total, generator=rngs)
        else:
            flat = torch.stack([torch.randn(total, generator=rng) for rng in rngs])
        flat = flat.to(self.device)
        noises = []
        for chunk, (h, w) in zip(flat.split(per_scale, dim=1), shapes, strict=True):
            noises.append(chunk.reshape(flat.shape[0], self.num_tokens, h, w))
        return noises

    @torch.no_grad()
    def sample(
        self,
        batch: int | None = None,
        seeds: Sequence[int] | None = None,
        generator: torch.Generator | None = None,
        size: tuple[int, int] | None = None,
    ) -> torch.Tensor:
        """Sample token maps; returns an int64 CPU tensor (batch, height, width) of token ids.

        ``seeds``: one seed per map; map i depends only on ``seeds[i]`` (the same
        map alone or in any batch). Otherwise ``batch`` maps draw their noise in
        turn from ``generator`` (default: torch's global generator). ``size`` =
        (height, width) in cells, default the training size; every scale is
        resized in proportion. BatchNorm uses its running statistics (eval mode).
        """
        if seeds is not None:
            seeds = [int(seed) for seed in seeds]
            if batch is not None and batch != len(seeds):
                raise ValueError(f'batch {batch} differs from the {len(seeds)} seeds given')
            rngs: Sequence[torch.Generator] | torch.Generator = [
                torch.Generator().manual_seed(seed) for seed in seeds]
            count = len(seeds)
        else:
            count = 1 if batch is None else int(batch)
            rngs = generator if generator is not None else torch.default_generator
        if count == 0:
            height, width = size if size is not None else self.size
            return torch.zeros(0, height, width, dtype=torch.long)
        shapes = scaled_shapes(self.scale_shapes, size)
        was_training = self.training
        self.eval()
        try:
            output = self.generate(self.draw_noise(rngs, shapes, batch=count))
        finally:
            self.train(was_training)
        return output.argmax(dim=1).cpu()

    @torch.no_grad()
    def reconstruct(self) -> torch.Tensor:
        """The training map as the pyramid reproduces it from z_rec: (height, width) token ids."""
        was_training = self.training
        self.eval()
        try:
            output = self.generate(self.reconstruction_noises())
        finally:
            self.train(was_training)
        return output.argmax(dim=1)[0].cpu()

    # ---- state ------------------------------------------------------------------------------

    def genome_names(self) -> list[str]:
        """State-dict keys the evolver may change: every generator weight and BatchNorm running
        statistic (float tensors), not the noise amplitudes, z_rec or batch counters."""
        return [name for name, tensor in self.state_dict().items()
                if name.startswith('generators.') and tensor.is_floating_point()]

    def check_state_dict(self, state_dict: Mapping[str, torch.Tensor]) -> None:
        """Raise CheckpointError naming the first missing, unexpected, misshapen or non-finite
        entry of ``state_dict`` compared with this pyramid."""
        check_state_dict_against(self.state_dict(), state_dict)

    def load_state_dict(
        self, state_dict: Mapping[str, torch.Tensor], strict: bool = True, assign: bool = False
    ):
        """Validate (CheckpointError naming the bad key), then load like nn.Module."""
        if strict:
            self.check_state_dict(state_dict)
        return super().load_state_dict(state_dict, strict=strict, assign=assign)


def check_state_dict_against(
    expected: Mapping[str, torch.Tensor], given: Mapping[str, torch.Tensor]
) -> None:
    """Raise CheckpointError for the first key of ``given`` that does not match ``expected``."""
    if not isinstance(given, Mapping):
        raise CheckpointError(f'generator weights must be a mapping of tensors, got {type(given)}')
    missing = [key for key in expected if key not in given]
    if missing:
        raise CheckpointError(
            f'generator weights lack key {missing[0]!r} ({len(missing)} missing in all)')
    unexpected = [key for key in given if key not in expected]
    if unexpected:
        raise CheckpointError(
            f'generator weights have unexpected key {unexpected[0]!r} '
            f'({len(unexpected)} unexpected in all)')
    for key, reference in expected.items():
        tensor = given[key]
        if not isinstance(tensor, torch.Tensor):
            raise CheckpointError(f'generator weight {key!r} is a {type(tensor).__name__}, '
                                  'not a tensor')
        if tuple(tensor.shape) != tuple(reference.shape):
            raise CheckpointError(
                f'generator weight {key!r} has shape {tuple(tensor.shape)}, '
                f'expected {tuple(reference.shape)}')
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise CheckpointError(f'generator weight {key!r} contains NaN or infinite values')


def pyramid_from_state_dict(
    state_dict: Mapping[str, torch.Tensor],
    scale_shapes: Iterable[tuple[int, int]],
    device: str | torch.device = 'cpu',
) -> GeneratorPyramid:
    """Build a pyramid for ``scale_shapes`` whose sizes (tokens, channels) are read from
    ``state_dict``, then load it; CheckpointError names what does not fit."""
    key = 'generators.0.head.conv.weight'
    weight = state_dict.get(key) if isinstance(state_dict, Mapping) else None
    if not isinstance(weight, torch.Tensor) or weight.ndim != 4:
        raise CheckpointError(f'generator weights lack key {key!r} (a 4-D tensor)')
    channels, num_tokens = int(weight.shape[0]), int(weight.shape[1])
    try:
        pyramid = GeneratorPyramid(num_tokens, list(scale_shapes), channels)
    except (TypeError, ValueError) as err:
        raise CheckpointError(f'cannot build a generator pyramid: {err}') from err
    pyramid.load_state_dict(
        {k: v.cpu() if isinstance(v, torch.Tensor) else v for k, v in state_dict.items()})
    return pyramid.to(device)


def resolve_device(device: str | torch.device | None = None) -> torch.device:
    """'auto' or None: CUDA when present, else CPU; otherwise the named device."""
    if device is None or str(device) == 'auto':
        return torch.device('cuda' if torch.cuda.is_available() else 'cpu')
    return torch.device(device)
