"""Benchmark of the TOAD-GAN generator: training time per scenario and sampling throughput.

Not a test (pytest does not collect it); run it and read the figures::

    python tests/benchmarks/bench_gan.py             # full training budgets (minutes)
    python tests/benchmarks/bench_gan.py --quick     # 40 iterations per scale
    python tests/benchmarks/bench_gan.py --skip-training

Training uses each scenario's example map and default configuration (the one the
shipped checkpoints were trained with), so its time is the time a user waits for
`ros2 run sessgan_gen train --scenario X`. Sampling is measured on the shipped
checkpoints (an untrained pyramid of the same shape if one is missing), batched
(``sampling.batch_size_for``: 32 maps of 32x32, 2 of 128x128 per forward pass)
against the baseline of one map per call, on 1 and 2 torch threads.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

for package in ('sessgan_core', 'sessgan_gen'):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / package))

from sessgan_core.scenarios import get_scenario  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_gen.checkpoint import default_checkpoint_path, load_checkpoint  # noqa: E402
from sessgan_gen.model import GeneratorPyramid, pyramid_scale_shapes  # noqa: E402
from sessgan_gen.sampling import batch_size_for, sample_seeds, sample_token_maps  # noqa: E402
from sessgan_gen.seeding import seed_everything  # noqa: E402
from sessgan_gen.training import TrainConfig, Trainer, resolve_config  # noqa: E402

SCENARIOS = ('factory', 'drone', 'racetrack')
QUICK_ITERATIONS = 40


def bench_training(scenario: str, iterations: int, threads: int) -> tuple[float, list[str]]:
    """Seconds to train ``scenario``'s default configuration (``iterations`` per scale, 0 =
    the default), and a per-scale breakdown."""
    torch.set_num_threads(threads)
    config = resolve_config(TrainConfig(scenario=scenario, iterations=iterations,
                                        progress=False, threads=threads))
    seed_everything(config.seed)
    trainer = Trainer(load_example_map(scenario).cells, get_scenario(scenario), config)
    started = time.perf_counter()
    trainer.run()
    seconds = time.perf_counter() - started
    detail = [f'{r["shape"][0]}x{r["shape"][1]} {r["seconds"]:.1f} s'
              for r in trainer.state.scale_results]
    return seconds, [f'{config.iterations} it/scale, {config.channels} ch'] + detail


def pyramid_for(scenario: str) -> tuple[GeneratorPyramid, str]:
    path = default_checkpoint_path(scenario)
    if path.exists():
        return load_checkpoint(path, scenario=scenario)[0], 'shipped checkpoint'
    spec = get_scenario(scenario)
    pyramid = GeneratorPyramid(spec.num_tokens, pyramid_scale_shapes(*spec.default_size), 32)
    return pyramid.eval(), 'untrained pyramid (no shipped checkpoint)'


def maps_per_second(pyramid: GeneratorPyramid, count: int, batch_size: int) -> float:
    seeds = sample_seeds(0, count)
    sample_token_maps(pyramid, seeds[:batch_size], batch_size=batch_size)  # warm-up
    started = time.perf_counter()
    sample_token_maps(pyramid, seeds, batch_size=batch_size)
    return count / (time.perf_counter() - started)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help=f'train {QUICK_ITERATIONS} iterations per scale instead of the '
                             'defaults')
    parser.add_argument('--skip-training', action='store_true', help='only measure sampling')
    parser.add_argument('--scenarios', default=','.join(SCENARIOS))
    parser.add_argument('--training-threads', type=int, default=1,
                        help='torch threads while training (the train command defaults to 1)')
    parser.add_argument('--samples', type=int, default=1000,
                        help='maps per throughput measurement (32x32; fewer for larger maps)')
    args = parser.parse_args(argv)
    scenarios = [s for s in args.scenarios.split(',') if s]

    print(f'torch {torch.__version__}, {torch.get_num_threads()} threads available by default')
    if not args.skip_training:
        iterations = QUICK_ITERATIONS if args.quick else 0
        print(f'\n## Training time ({"quick" if args.quick else "default budget"}, '
              f'{args.training_threads} threads)')
        for scenario in scenarios:
            seconds, detail = bench_training(scenario, iterations, args.training_threads)
            print(f'{scenario:10s} {seconds:8.1f} s  ({"; ".join(detail)})', flush=True)

    print('\n## Sampling throughput (maps per second; baseline = one map per call)')
    print(f'{"scenario":10s} {"size":>8s} {"threads":>7s} {"batch":>5s} {"batched":>9s} '
          f'{"one-by-one":>11s} {"ratio":>6s}')
    for scenario in scenarios:
        pyramid, source = pyramid_for(scenario)
        height, width = pyramid.size
        count = max(50, args.samples * 1024 // (height * width))
        for threads in (1, 2):
            torch.set_num_threads(threads)
            batch = batch_size_for((height, width))
            batched = maps_per_second(pyramid, count, batch)
            single = maps_per_second(pyramid, max(20, count // 5), batch_size=1)
            print(f'{scenario:10s} {f"{height}x{width}":>8s} {threads:7d} {batch:5d} '
                  f'{batched:9.0f} {single:11.0f} {batched / single:6.2f}  ({source})',
                  flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
