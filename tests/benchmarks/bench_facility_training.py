"""Benchmark: training on facility maps of 32x32, 64x64 and 128x128 cells.

Not a test (pytest does not collect it); run it and read the figures::

    python tests/benchmarks/bench_facility_training.py                  # 32, 64, 128; defaults
    python tests/benchmarks/bench_facility_training.py --sizes 128 --crop-size 0   # no crops
    python tests/benchmarks/bench_facility_training.py --layout mixed --max-scales 99  # 5 scales
    python tests/benchmarks/bench_facility_training.py --sizes 128 --layout mixed --png f.png

The maps are the factory example map tiled 1x1, 2x2 and 4x4 (no third-party map); with
``--layout mixed`` each 32x32 block is the example map turned and mirrored at random (seed 0),
so the larger map does not repeat every 32 cells (a repeating map aliases when it is
downsampled for the coarse scales). Each is
trained with the factory's default configuration (``train --scenario factory --map-file``:
1,000 iterations a scale, 32 channels, crops of ``TrainConfig.crop_size`` where the whole map
would train longer than ``TrainConfig.crop_budget``), then sampled at
its own size; printed per size: training seconds (and per scale), TPKL of the samples to the
map they learned, 8x8/16x16 uniqueness, and the share of samples that are valid tests (a
certified route for the factory robot). The shipped 32x32 factory generator's figures on
the same samples count are printed first, as the realism to match.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch

for package in ('sessgan_core', 'sessgan_gen'):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / package))

from sessgan_core.scenarios import get_scenario  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_core.valid_tests import make_environment  # noqa: E402
from sessgan_gen.checkpoint import default_checkpoint_path, load_checkpoint  # noqa: E402
from sessgan_gen.environment_metrics import tile_pattern_kl, uniqueness_report  # noqa: E402
from sessgan_gen.model import GeneratorPyramid  # noqa: E402
from sessgan_gen.sampling import sample_seeds, sample_token_maps  # noqa: E402
from sessgan_gen.seeding import seed_everything  # noqa: E402
from sessgan_gen.training import TrainConfig, Trainer, resolve_config  # noqa: E402

FACTORY = get_scenario('factory')


def facility_map(side: int, layout: str = 'tiled') -> np.ndarray:
    """The factory example map tiled to ``side`` x ``side`` cells (a multiple of 32); each
    block turned and mirrored at random for the ``mixed`` layout."""
    example = load_example_map('factory').cells
    repeats = side // example.shape[0]
    if repeats < 1 or repeats * example.shape[0] != side:
        raise SystemExit(f'--sizes takes multiples of {example.shape[0]}, got {side}')
    if layout == 'tiled':
        return np.tile(example, (repeats, repeats))
    rng = np.random.default_rng(0)

    def block() -> np.ndarray:
        turned = np.rot90(example, int(rng.integers(4)))
        return turned[:, ::-1] if rng.integers(2) else turned
    return np.ascontiguousarray(np.block([[block() for _ in range(repeats)]
                                          for _ in range(repeats)]))


def figures(pyramid: GeneratorPyramid, reference: np.ndarray, samples: int) -> str:
    """Valid-test share of ``samples`` maps; TPKL to ``reference`` and uniqueness of as many
    of them as hold the cells of ``samples`` 32x32 maps (both figures depend on the cells
    pooled, so every size is measured on the same number of cells)."""
    maps = list(sample_token_maps(pyramid, sample_seeds(0, samples)))
    valid = sum(make_environment(cells, FACTORY, f'bench-{i}').feasible
                for i, cells in enumerate(maps))
    pooled = maps[:max(2, -(-samples * 32 * 32 // maps[0].size))]
    unique = uniqueness_report(pooled)
    per_size = ', '.join(f'{s}x{s} {v:.1f} %' for s, v in unique.per_size.items())
    return (f'TPKL {tile_pattern_kl(reference, pooled):.3f} and uniqueness {unique.mean:.1f} % '
            f'({per_size}) of {len(pooled)} maps, valid tests {valid}/{samples}')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[32, 64, 128])
    parser.add_argument('--iterations', type=int, default=0,
                        help="iterations per scale (0: the factory's default)")
    parser.add_argument('--crop-size', type=int, default=TrainConfig.crop_size,
                        help='TrainConfig.crop_size (0: no crops)')
    parser.add_argument('--crop-budget', type=float, default=TrainConfig.crop_budget,
                        help='TrainConfig.crop_budget (0: crop whatever --crop-size allows)')
    parser.add_argument('--threads', type=int, default=1, help='torch threads')
    parser.add_argument('--device', default='cpu',
                        help='torch device of the training (cpu: the figures the issue asks for)')
    parser.add_argument('--seed', type=int, default=TrainConfig.seed,
                        help='training seed (TrainConfig.seed); another seed measures the spread')
    parser.add_argument('--samples', type=int, default=20, help='maps sampled per generator')
    parser.add_argument('--max-scales', type=int, default=TrainConfig.max_scales,
                        help="TrainConfig.max_scales (0: the factory's default, 3; 99: no limit)")
    parser.add_argument('--png', default='',
                        help='write each training map beside three of its samples here')
    parser.add_argument('--layout', choices=('tiled', 'mixed'), default='tiled',
                        help='the larger maps: the example map tiled, or its blocks turned and '
                             'mirrored at random')
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)

    shipped, _ = load_checkpoint(default_checkpoint_path('factory'), scenario='factory')
    print(f'shipped factory 32x32 generator: '
          f'{figures(shipped, load_example_map("factory").cells, args.samples)}', flush=True)
    pictures = []
    for side in args.sizes:
        cells = facility_map(side, args.layout)
        config = resolve_config(TrainConfig(scenario='factory', iterations=args.iterations,
                                            crop_size=args.crop_size,
                                            crop_budget=args.crop_budget, threads=args.threads,
                                            seed=args.seed, device=args.device,
                                            max_scales=args.max_scales, progress=False))
        seed_everything(config.seed)
        trainer = Trainer(cells, FACTORY, config)
        started, cpu_started = time.perf_counter(), time.process_time()
        trainer.run()
        seconds = time.perf_counter() - started
        cpu = time.process_time() - cpu_started
        scales = '; '.join(f'{r["shape"][0]}x{r["shape"][1]} {r["seconds"]:.0f} s'
                           for r in trainer.state.scale_results)
        # On a busy machine CPU seconds (one thread) are what a quiet core would take.
        print(f'{side}x{side} {args.layout}: trained in {seconds:.0f} s wall, {cpu:.0f} s CPU '
              f'({config.iterations} it/scale, crop '
              f'{trainer.crop_size}, seed {config.seed}, {args.threads} thread(s); {scales}); '
              f'{figures(trainer.pyramid, cells, args.samples)}', flush=True)
        pictures.append((f'{side}x{side}, {trainer.pyramid.num_scales} scales', cells,
                         list(sample_token_maps(trainer.pyramid, sample_seeds(0, 3)))))
    if args.png:
        write_picture(pictures, args.png)
        print(f'wrote {args.png}')
    return 0


def write_picture(rows: list[tuple[str, np.ndarray, list[np.ndarray]]], path: str) -> None:
    """Each training map (left) beside its samples; black: walls."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(len(rows), 4, figsize=(12, 3 * len(rows)), squeeze=False)
    for (label, cells, samples), row in zip(rows, axes):
        for axis, image, title in zip(row, [cells, *samples],
                                      ['training map', 'sample 1', 'sample 2', 'sample 3']):
            axis.imshow(image, cmap='gray_r', origin='lower', interpolation='nearest')
            axis.set_title(f'{label}: {title}', fontsize=8)
            axis.axis('off')
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


if __name__ == '__main__':
    sys.exit(main())
