"""Training of a TOAD-GAN pyramid on one token map (WGAN-GP plus reconstruction loss).

Scales are trained one after the other, coarsest first, as in TOAD-GAN: at
scale s a fresh discriminator (or the previous scale's, see
``init_from_previous_scale``) and the scale's generator play a WGAN-GP game on
the map downsampled to that scale, while the generator also learns to
reproduce it from the fixed reconstruction noise (z_rec at the coarsest scale,
zeros above). The scale's noise amplitude is ``noise_update`` times the RMSE
between the real map and the upsampled reconstruction of the coarser scales
(1 at the coarsest scale), so noise is strong where the coarse scales leave the
most to invent.

Randomness comes only from torch's global generator, seeded once by
``seeding.seed_everything``; its state is saved after every finished scale so a
resumed run continues exactly as an uninterrupted one.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from sessgan_core.scenarios import Scenario
from sessgan_gen import __version__
from sessgan_gen.checkpoint import training_map_rows
from sessgan_gen.downsampling import downsample_pyramid, one_hot
from sessgan_gen.model import (
    GENERATOR_PADDING,
    GeneratorPyramid,
    PatchDiscriminator,
    init_weights,
    pad,
    pyramid_scale_shapes,
    resolve_device,
    upsample,
)

LR_DECAY_FRACTIONS = (0.4, 0.625)
"""Fractions of a scale's iterations after which the learning rate drops by
``lr_decay`` (TOAD-GAN: iterations 1600 and 2500 of 4000)."""


@dataclass
class TrainConfig:
    """Everything that decides a training run; the ``train`` command's options."""

    scenario: str = 'factory'
    """Scenario (factory, racetrack, drone): token alphabet, downsampling hierarchy and,
    without --map-file, the example map to learn."""
    map_file: str = ''
    """Token text file to train on instead of the scenario's example map."""
    map_yaml: str = ''
    """map_server map (YAML with its PGM or PNG) to train on instead: a SLAM map is cropped to
    its known region (unknown space around the mapped area is outside the map), then resampled
    to the scenario's cell size; the token map it becomes is written next to the checkpoint
    (<output>.map.txt, and <output>.map.yaml/.pgm as it looks at that cell size, at the
    original's origin)."""
    output: str = ''
    """Checkpoint file (.pt; the .json metadata goes next to it). Empty: <scenario>.pt."""
    iterations: int = 0
    """Training iterations per scale; 0 picks the scenario's default."""
    channels: int = 0
    """Convolution channels of every layer; 0 picks the scenario's default."""
    scale_factor: float = 0.5
    """Side ratio between consecutive scales."""
    coarsest_coverage: float = 2.0
    """Longest side of the coarsest scale in receptive fields (7 cells): sets the number
    of scales so the coarsest GAN sees the whole layout."""
    max_scales: int = 0
    """Most scales (the finest kept); 0 picks the scenario's default: 3 for the factory and the
    drone (a facility map's realism is in its detail: 128x128 maps, 3 seeds x 2 layouts, scored
    TPKL 0.88-1.08 to their map on 3 scales, 0.92-1.31 on 5), no limit for the race track (its
    loop is the layout). A large number (99) sets no limit."""
    noise_update: float = 0.1
    """Noise amplitude of a scale per unit RMSE of the coarser scales' reconstruction."""
    discriminator_steps: int = 3
    """Discriminator updates per iteration."""
    generator_steps: int = 3
    """Generator updates per iteration."""
    learning_rate: float = 5e-4
    """Adam learning rate of generators and discriminators."""
    beta1: float = 0.5
    """Adam beta1."""
    beta2: float = 0.999
    """Adam beta2."""
    lr_decay: float = 0.1
    """Learning-rate factor applied at 40 % and 62.5 % of a scale's iterations."""
    gradient_penalty_weight: float = 0.1
    """WGAN-GP lambda."""
    reconstruction_weight: float = 100.0
    """Weight alpha of the reconstruction loss."""
    init_from_previous_scale: bool = True
    """Start each scale's networks from the previous scale's weights (SinGAN); faster."""
    crop_size: int = 48
    """At a scale with a side longer than this, every update sees a random crop of at most
    this many cells a side instead of the whole map (0: never crop). The patch discriminator
    judges 7x7 windows and the losses are means over cells, so a crop's loss estimates the
    whole map's without bias; the generator's input is cut from the whole padded input, so a
    crop is generated exactly as inside the whole map. A 128x128 map's finest scale then costs
    a 48x48 one per update."""
    crop_budget: float = 600.0
    """Crops are used only when the whole map's training would take longer than this many
    seconds of one CPU thread (the cost model's estimate; 0: crop whatever crop_size allows).
    Crops save time at the price of realism (a 64x64 map: TPKL 1.15 cropped, 1.04 whole,
    three seeds each), so a map that trains whole within 10 minutes trains whole."""
    seed: int = 1
    """Seed of every random choice of the run."""
    device: str = 'auto'
    """Torch device: auto (CUDA when present, else CPU), cpu, cuda or cuda:N."""
    threads: int = 1
    """Torch CPU threads; 0 keeps torch's default (one per core). One is the robust choice on
    a shared machine: with 2 threads on a busy 2-core machine an iteration ran 100x slower
    (OpenMP threads wait for each other); raise it on idle cores for large maps."""
    deterministic: bool = True
    """Use deterministic torch algorithms (same seed, device and threads: same weights)."""
    resume: bool = False
    """Continue the partial checkpoint at --output after its last finished scale."""
    progress: bool = True
    """Print a progress line (rate, ETA) to stderr."""


SCENARIO_DEFAULTS: dict[str, dict[str, int]] = {
    'factory': {'iterations': 1000, 'channels': 32, 'max_scales': 3},
    'drone': {'iterations': 1000, 'channels': 32, 'max_scales': 3},
    'racetrack': {'iterations': 600, 'channels': 32, 'max_scales': 0},
}
"""Per-scenario iterations, channels and scale limit (0: none), chosen to meet the
training-time targets on a 2-core CPU (factory within 5 min, race track within 30 min)."""
FALLBACK_DEFAULTS = {'iterations': 600, 'channels': 32, 'max_scales': 0}

MIN_TRAINING_SIDE = 8
"""Fewest cells per side of a map to learn: one receptive field (7 cells) plus one, so the
patch GAN sees more than one window, and room for the 4 x 4 tiles TPKL counts."""

SECONDS_PER_ITERATION = (0.0158, 5.38e-5)
"""(a, b) of a training iteration's time a + b * cells at 32 channels on one CPU thread:
fitted to the shipped factory checkpoint's per-scale times (8x8 27.8 s, 16x16 29.6 s, 32x32
70.9 s per 1,000 iterations, scale_results in data/checkpoints/factory.json)."""
CROPPED_SECONDS_PER_CELL = 7e-7
"""What a scale trained on crops still spends per cell of its whole map and iteration
(generating the coarser scales whole and upsampling them): a 256x256 scale on 48x48 crops took
0.74 s for 4 iterations where the crop alone models 0.56 s (one thread, process time)."""
LONG_TRAINING_SECONDS = 600.0
"""An estimate above this warns before training starts (the target for a facility map of up
to 128x128 cells: 10 minutes; such a map is estimated at 6.7 min and measured at 6.5)."""


def check_training_map(cells: np.ndarray) -> None:
    """ValueError naming the size when a map is too small to learn."""
    height, width = np.shape(cells)
    if min(height, width) < MIN_TRAINING_SIDE:
        raise ValueError(
            f'the map is {width}x{height} cells (width x height); training needs at least '
            f'{MIN_TRAINING_SIDE} cells per side (one 7-cell receptive field and more)')


def estimated_training_seconds(shapes: list[tuple[int, int]] | tuple[tuple[int, int], ...],
                               iterations: int, channels: int, crop_size: int = 0) -> float:
    """Rough CPU seconds (one thread) to train scales of ``shapes``
    (:data:`SECONDS_PER_ITERATION`; the cell term grows with channels squared; a scale trained
    on crops costs its crop's cells)."""
    fixed, per_cell = SECONDS_PER_ITERATION
    scale = (channels / 32) ** 2
    total = 0.0
    for height, width in shapes:
        cropped = crop_size > 0 and max(height, width) > crop_size
        cells = (min(height, crop_size) * min(width, crop_size) if cropped
                 else height * width)
        whole = CROPPED_SECONDS_PER_CELL * height * width if cropped else 0.0
        total += iterations * (fixed + scale * (per_cell * cells + whole))
    return total


def long_training_warning(shapes: list[tuple[int, int]] | tuple[tuple[int, int], ...],
                          iterations: int, channels: int, crop_size: int = 0) -> str:
    """What to tell before a training of scales ``shapes`` that would take long (more than
    :data:`LONG_TRAINING_SECONDS` by :func:`estimated_training_seconds`), or ''."""
    seconds = estimated_training_seconds(shapes, iterations, channels, crop_size)
    if not shapes or seconds <= LONG_TRAINING_SECONDS:
        return ''
    height, width = shapes[-1]
    took = f'{seconds / 3600:.1f} h' if seconds >= 3600 else f'{seconds / 60:.0f} min'
    return (f'a {width}x{height}-cell map ({height * width:,} cells) at {iterations} iterations '
            f'a scale takes roughly {took} on one CPU thread (a 32x32 map: about 2 min), '
            'and memory grows with the cells too: crop the map to the area the robots use, '
            'train fewer --iterations, or use a GPU (--device cuda)')


def training_crop_size(shapes: list[tuple[int, int]] | tuple[tuple[int, int], ...],
                       config: TrainConfig) -> int:
    """The crop size a training of scales ``shapes`` uses: ``config.crop_size``, or 0 (the
    whole map at every scale) when the whole map trains within ``config.crop_budget`` seconds
    by :func:`estimated_training_seconds`."""
    whole = estimated_training_seconds(shapes, config.iterations, config.channels)
    return 0 if whole <= config.crop_budget else config.crop_size


RESULT_FIELDS = ('output', 'resume', 'progress', 'threads', 'device')
"""Config fields that do not change the trained weights (resume may differ in them)."""


def resolve_config(config: TrainConfig) -> TrainConfig:
    """Fill the derived defaults (iterations, channels, output) in one place."""
    defaults = SCENARIO_DEFAULTS.get(config.scenario, FALLBACK_DEFAULTS)
    return dataclasses.replace(
        config,
        iterations=config.iterations or defaults['iterations'],
        channels=config.channels or defaults['channels'],
        max_scales=config.max_scales or defaults['max_scales'],
        output=config.output or f'{config.scenario}.pt',
    )


def validate_config(config: TrainConfig) -> None:
    """Raise ValueError naming the first option that is out of range."""
    checks = [
        (config.iterations >= 1, 'iterations must be at least 1'),
        (config.channels >= 1, 'channels must be at least 1'),
        (0.0 < config.scale_factor < 1.0, 'scale_factor must lie in (0, 1)'),
        (config.coarsest_coverage > 0, 'coarsest_coverage must be positive'),
        (config.max_scales >= 0, 'max_scales must not be negative'),
        (config.noise_update >= 0, 'noise_update must not be negative'),
        (config.discriminator_steps >= 1, 'discriminator_steps must be at least 1'),
        (config.generator_steps >= 1, 'generator_steps must be at least 1'),
        (config.learning_rate > 0, 'learning_rate must be positive'),
        (config.threads >= 0, 'threads must not be negative'),
        (0.0 <= config.beta1 < 1.0, 'beta1 must lie in [0, 1)'),
        (0.0 <= config.beta2 < 1.0, 'beta2 must lie in [0, 1)'),
        (0.0 < config.lr_decay <= 1.0, 'lr_decay must lie in (0, 1]'),
        (config.gradient_penalty_weight >= 0, 'gradient_penalty_weight must not be negative'),
        (config.reconstruction_weight >= 0, 'reconstruction_weight must not be negative'),
        (config.seed >= 0, 'seed must not be negative'),
        (config.crop_size == 0 or config.crop_size >= MIN_TRAINING_SIDE,
         f'crop_size must be 0 (no crops) or at least {MIN_TRAINING_SIDE}'),
        (config.crop_budget >= 0, 'crop_budget must not be negative'),
    ]
    for field in dataclasses.fields(config):
        value = getattr(config, field.name)
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f'{field.name} must be a finite number, got {value}')
    for ok, message in checks:
        if not ok:
            raise ValueError(message)
    check_device(config.device)


def check_device(device: str) -> None:
    """Raise ValueError unless ``device`` is one training can use here."""
    try:
        resolved = resolve_device(device)
    except RuntimeError:
        raise ValueError(f'device must be auto, cpu, cuda or cuda:N, got {device!r}') from None
    if resolved.type not in ('cpu', 'cuda'):
        raise ValueError(f'device must be auto, cpu, cuda or cuda:N, got {device!r}')
    if resolved.type == 'cuda' and not torch.cuda.is_available():
        raise ValueError(f'device {device!r}: this torch sees no CUDA device (a CPU-only '
                         'build, or no GPU); use --device cpu or auto')
    if resolved.type == 'cuda' and (resolved.index or 0) >= torch.cuda.device_count():
        raise ValueError(f'device {device!r}: this machine has {torch.cuda.device_count()} '
                         'CUDA devices')


def config_dict(config: TrainConfig) -> dict[str, Any]:
    return dataclasses.asdict(config)


def same_training(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """Names of the config fields that differ between two runs and change the result (a field
    one of them lacks, from an older version, counts as its default)."""
    defaults = config_dict(TrainConfig())
    names = set(a) | set(b)
    return sorted(name for name in names if name not in RESULT_FIELDS
                  and a.get(name, defaults.get(name)) != b.get(name, defaults.get(name)))


@dataclass
class ScaleResult:
    """What one finished scale reports."""

    scale: int
    shape: tuple[int, int]
    noise_amplitude: float
    seconds: float
    reconstruction_accuracy: float
    """Fraction of cells whose token the pyramid reconstructs from z_rec at this scale."""


@dataclass
class TrainingState:
    """Everything besides the pyramid needed to resume after a finished scale."""

    trained_scales: int = 0
    rng_state: torch.Tensor | None = None
    discriminator: dict[str, torch.Tensor] | None = None
    seconds: float = 0.0
    scale_results: list[dict[str, Any]] = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self) | {
            'rng_state': self.rng_state, 'discriminator': self.discriminator}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainingState:
        return cls(
            trained_scales=int(data.get('trained_scales', 0)),
            rng_state=data.get('rng_state'),
            discriminator=data.get('discriminator'),
            seconds=float(data.get('seconds', 0.0)),
            scale_results=list(data.get('scale_results', [])),
        )


ProgressCallback = Callable[[int, int, int, int], None]
"""progress(scale, num_scales, iteration, iterations): called after every iteration."""
ScaleCallback = Callable[[GeneratorPyramid, TrainingState], None]
"""on_scale_done(pyramid, state): called after every finished scale (to checkpoint)."""


def gradient_penalty(
    discriminator: nn.Module, real: torch.Tensor, fake: torch.Tensor, weight: float
) -> torch.Tensor:
    """WGAN-GP: weight * mean over cells of (|grad D| - 1)^2 on a random real/fake mix."""
    # Drawn on the CPU generator like every other draw of training, whose state the
    # checkpoint saves: a resumed run on CUDA then continues the same stream.
    mix = torch.rand(1, 1, 1, 1).to(real.device)
    blend = (mix * real + (1 - mix) * fake).requires_grad_(True)
    score = discriminator(blend)
    (grads,) = torch.autograd.grad(score, blend, grad_outputs=torch.ones_like(score),
                                   create_graph=True)
    return weight * ((grads.norm(2, dim=1) - 1) ** 2).mean()


def build_pyramid(
    cells: np.ndarray, scenario: Scenario, config: TrainConfig
) -> tuple[GeneratorPyramid, list[torch.Tensor]]:
    """An untrained pyramid for ``cells`` and the real map at every scale."""
    height, width = (int(side) for side in np.asarray(cells).shape)
    shapes = pyramid_scale_shapes(height, width, config.scale_factor, config.coarsest_coverage,
                                  config.max_scales)
    pyramid = GeneratorPyramid(scenario.num_tokens, shapes, config.channels)
    reals = downsample_pyramid(one_hot(cells, scenario.num_tokens), shapes, scenario.hierarchy)
    return pyramid, reals


class Trainer:
    """Trains a pyramid scale by scale; :meth:`run` continues from ``state``."""

    def __init__(
        self,
        cells: np.ndarray,
        scenario: Scenario,
        config: TrainConfig,
        pyramid: GeneratorPyramid | None = None,
        state: TrainingState | None = None,
    ) -> None:
        validate_config(config)
        self.config = config
        self.scenario = scenario
        self.device = resolve_device(config.device)
        fresh, reals = build_pyramid(cells, scenario, config)
        self.pyramid = (pyramid if pyramid is not None else fresh).to(self.device)
        self.reals = [real.to(self.device) for real in reals]
        self.state = state if state is not None else TrainingState()
        self.crop_size = training_crop_size(self.pyramid.scale_shapes, config)
        """The crop size this training uses (:func:`training_crop_size`)."""

    @property
    def finished(self) -> bool:
        return self.state.trained_scales >= self.pyramid.num_scales

    def run(
        self,
        progress: ProgressCallback | None = None,
        on_scale_done: ScaleCallback | None = None,
        stop_after_scale: int | None = None,
    ) -> GeneratorPyramid:
        """Train the remaining scales (up to ``stop_after_scale`` scales in all, if given)."""
        if self.state.rng_state is not None:
            torch.set_rng_state(self.state.rng_state)
        last = self.pyramid.num_scales if stop_after_scale is None else stop_after_scale
        while self.state.trained_scales < min(last, self.pyramid.num_scales):
            result, discriminator = self.train_scale(self.state.trained_scales, progress)
            self.state.trained_scales += 1
            self.state.seconds += result.seconds
            self.state.scale_results.append(dataclasses.asdict(result))
            self.state.discriminator = {k: v.detach().cpu().clone()
                                        for k, v in discriminator.state_dict().items()}
            self.state.rng_state = torch.get_rng_state()
            if on_scale_done is not None:
                on_scale_done(self.pyramid, self.state)
        self.pyramid.eval()
        return self.pyramid

    def _discriminator(self, scale: int) -> PatchDiscriminator:
        config = self.config
        discriminator = PatchDiscriminator(self.scenario.num_tokens, config.channels)
        discriminator.apply(init_weights)
        if scale > 0 and config.init_from_previous_scale and self.state.discriminator:
            discriminator.load_state_dict(self.state.discriminator)
        return discriminator.to(self.device)

    def train_scale(
        self, scale: int, progress: ProgressCallback | None = None
    ) -> tuple[ScaleResult, PatchDiscriminator]:
        """Train scale ``scale`` (all coarser ones must be trained)."""
        config, pyramid, device = self.config, self.pyramid, self.device
        started = time.perf_counter()
        real = self.reals[scale]
        shape = (int(real.shape[-2]), int(real.shape[-1]))
        generator = pyramid.generators[scale]
        if scale > 0 and config.init_from_previous_scale:
            generator.load_state_dict(pyramid.generators[scale - 1].state_dict())
        discriminator = self._discriminator(scale)
        for coarser in pyramid.generators[:scale]:
            coarser.eval()
            coarser.requires_grad_(False)
        generator.train()
        generator.requires_grad_(True)

        # Reconstruction input of this scale and the noise amplitude it implies.
        with torch.no_grad():
            if scale == 0:
                pyramid.reconstruction_noise.copy_(
                    torch.randn(pyramid.reconstruction_noise.shape).to(device))
                reconstruction_previous: torch.Tensor | None = None
                amplitude = 1.0
                reconstruction_noise = pyramid.reconstruction_noise
            else:
                coarse = pyramid.generate(pyramid.reconstruction_noises(scale))
                reconstruction_previous = upsample(coarse, shape)
                amplitude = config.noise_update * math.sqrt(
                    F.mse_loss(reconstruction_previous, real).item())
                reconstruction_noise = torch.zeros_like(real)
            pyramid.noise_amplitudes[scale] = amplitude
        reconstruction_input = pad(amplitude * reconstruction_noise
                                   + _or_zero(reconstruction_previous))

        betas = (config.beta1, config.beta2)
        optimizer_d = torch.optim.Adam(discriminator.parameters(), config.learning_rate,
                                       betas=betas)
        optimizer_g = torch.optim.Adam(generator.parameters(), config.learning_rate, betas=betas)
        milestones = [max(1, round(config.iterations * f)) for f in LR_DECAY_FRACTIONS]
        schedulers = [torch.optim.lr_scheduler.MultiStepLR(opt, milestones, config.lr_decay)
                      for opt in (optimizer_d, optimizer_g)]
        coarse_shapes = pyramid.scale_shapes[:scale]

        def random_previous() -> torch.Tensor | None:
            if scale == 0:
                return None
            with torch.no_grad():
                noises = pyramid.draw_noise(torch.default_generator, coarse_shapes, batch=1)
                return upsample(pyramid.generate(noises), shape)

        crops = Crops(shape, self.crop_size)
        for iteration in range(config.iterations):
            noise = torch.randn(real.shape).to(device)
            for _ in range(config.discriminator_steps):
                previous = random_previous()
                optimizer_d.zero_grad(set_to_none=True)
                corner = crops.draw()
                fake = generator(crops.cut_padded(pad(amplitude * noise + _or_zero(previous)),
                                                  corner),
                                 crops.cut(previous, corner)).detach()
                real_crop = crops.cut(real, crops.draw())
                loss_d = (discriminator(fake).mean() - discriminator(real_crop).mean()
                          + gradient_penalty(discriminator, real_crop, fake,
                                             config.gradient_penalty_weight))
                loss_d.backward()
                optimizer_d.step()
            for _ in range(config.generator_steps):
                optimizer_g.zero_grad(set_to_none=True)
                corner = crops.draw()
                fake = generator(crops.cut_padded(pad(amplitude * noise + _or_zero(previous)),
                                                  corner),
                                 crops.cut(previous, corner))
                reconstruction = generator(crops.cut_padded(reconstruction_input, corner),
                                           crops.cut(reconstruction_previous, corner))
                loss_g = (-discriminator(fake).mean()
                          + config.reconstruction_weight * F.mse_loss(
                              reconstruction, crops.cut(real, corner)))
                loss_g.backward()
                optimizer_g.step()
            for scheduler in schedulers:
                scheduler.step()
            if progress is not None:
                progress(scale, pyramid.num_scales, iteration + 1, config.iterations)

        generator.eval()
        generator.requires_grad_(False)
        with torch.no_grad():
            rebuilt = pyramid.generate(pyramid.reconstruction_noises(scale + 1))
            accuracy = (rebuilt.argmax(dim=1) == real.argmax(dim=1)).float().mean().item()
        result = ScaleResult(scale=scale, shape=(int(shape[0]), int(shape[1])),
                             noise_amplitude=float(amplitude),
                             seconds=time.perf_counter() - started,
                             reconstruction_accuracy=accuracy)
        return result, discriminator


class Crops:
    """Random crops of a scale's maps (``TrainConfig.crop_size``); a scale that fits the crop
    is used whole and draws no random number, so such trainings are as before crops existed."""

    def __init__(self, shape: tuple[int, int], crop_size: int) -> None:
        self.shape = shape
        self.active = crop_size > 0 and max(shape) > crop_size
        self.window = (min(shape[0], crop_size), min(shape[1], crop_size)) if self.active \
            else shape

    def draw(self) -> tuple[int, int]:
        """Top-left cell of a random crop (from torch's global generator, so a seeded run
        repeats and a resumed one continues exactly)."""
        if not self.active:
            return 0, 0
        top = int(torch.randint(self.shape[0] - self.window[0] + 1, (1,)))
        left = int(torch.randint(self.shape[1] - self.window[1] + 1, (1,)))
        return top, left

    @overload
    def cut(self, image: torch.Tensor, corner: tuple[int, int]) -> torch.Tensor: ...

    @overload
    def cut(self, image: None, corner: tuple[int, int]) -> None: ...

    def cut(self, image: torch.Tensor | None, corner: tuple[int, int]) -> torch.Tensor | None:
        """The crop at ``corner`` of a (batch, tokens, h, w) map."""
        if image is None or not self.active:
            return image
        top, left = corner
        return image[..., top:top + self.window[0], left:left + self.window[1]]

    def cut_padded(self, padded: torch.Tensor, corner: tuple[int, int]) -> torch.Tensor:
        """The generator input of the crop at ``corner``, cut from the whole map's padded
        input with its margin, so the crop is generated as it is inside the whole map."""
        if not self.active:
            return padded
        top, left = corner
        margin = 2 * GENERATOR_PADDING
        return padded[..., top:top + self.window[0] + margin, left:left + self.window[1] + margin]


def _or_zero(previous: torch.Tensor | None) -> torch.Tensor | float:
    """The coarser output to add to a generator's noise (none at the coarsest scale)."""
    return 0.0 if previous is None else previous


def training_metadata(
    scenario: Scenario,
    config: TrainConfig,
    pyramid: GeneratorPyramid,
    state: TrainingState,
    map_source: str,
    cells: np.ndarray | None = None,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> dict[str, Any]:
    """The JSON metadata of a (possibly partial) training checkpoint; ``cells``, the map
    learned, is stored as ``training_map`` (the reference of every TPKL figure), ``origin``
    (x m, y m, yaw rad of its cell (0, 0) corner in the original map's frame) as
    ``map_origin``: the generated maps are placed there, so they overlay the original."""
    stored = {} if cells is None else {'training_map': training_map_rows(cells, scenario.tokens)}
    return {
        'scenario': scenario.name,
        'tokens': list(scenario.tokens),
        'map_source': map_source,
        'map_shape': list(pyramid.size),
        'map_origin': [float(value) for value in origin],
        **stored,
        'seed': config.seed,
        'training_config': config_dict(config),
        'trained_scales': state.trained_scales,
        'complete': state.trained_scales >= pyramid.num_scales,
        'training_seconds': round(state.seconds, 3),
        'scale_results': state.scale_results,
        'software_version': __version__,
        'torch_version': str(torch.__version__),
    }
