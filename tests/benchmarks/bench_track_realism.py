"""Benchmark of race-track realism: generated tracks against the example track.

Not a test (pytest does not collect it); run it and read the figures::

    python tests/benchmarks/bench_track_realism.py                      # 200 seeds
    python tests/benchmarks/bench_track_realism.py --seeds 20 --png tracks.png
    python tests/benchmarks/bench_track_realism.py --no-post-process   # the raw generator
    python tests/benchmarks/bench_track_realism.py --checkpoint my_racetrack.pt

It samples race tracks from the shipped generator (through the sampler, so with the
racetrack scenario's structural post-process unless ``--no-post-process``) with fresh seeds
(800000 on, never used by training or tests), places start and goal on the example map with
the same seeds, and prints the measures of :mod:`sessgan_gen.track_realism` as mean / median
/ percentiles, generated against the example: the share of track cells on the route's
corridor and on the lap's (route plus a way back beside it), how often a lap exists, the
share of track cells in the route's connected piece, fragments and dead ends per map, the
local track width along the route and the route's curvature, plus the valid-map fraction.
With ``--png`` it draws sample generated tracks next to the example, with their certified
routes.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

for package in ('sessgan_core', 'sessgan_gen'):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / package))

from sessgan_core.environment import Environment  # noqa: E402
from sessgan_core.progress import ProgressPrinter  # noqa: E402
from sessgan_core.token_map import load_example_map  # noqa: E402
from sessgan_core.valid_tests import certify_environment, make_environment  # noqa: E402
from sessgan_gen.environment_sampler import EnvironmentSampler  # noqa: E402
from sessgan_gen.track_realism import TrackRealism, measure_environment  # noqa: E402

FIRST_SEED = 800_000
BATCH = 20
SCENARIO = 'racetrack'


def generated_environments(seeds: list[int], progress: ProgressPrinter,
                           post_process: bool, checkpoint: Path | None = None
                           ) -> list[Environment]:
    sampler = EnvironmentSampler()
    environments: list[Environment] = []
    progress.start('generated tracks', len(seeds))
    for first in range(0, len(seeds), BATCH):
        batch = seeds[first:first + BATCH]
        environments += sampler.sample(batch, checkpoint=checkpoint, scenario=SCENARIO,
                                       post_process=post_process)
        progress.update(len(environments))
    return environments


def example_environments(seeds: list[int]) -> list[Environment]:
    cells = load_example_map(SCENARIO).cells
    return [make_environment(cells, SCENARIO, f'example-s{seed}', seed=seed) for seed in seeds]


def measure_all(environments: list[Environment], label: str,
                progress: ProgressPrinter) -> list[TrackRealism]:
    results = []
    progress.start(f'measuring {label}', len(environments))
    for environment in environments:
        results.append(measure_environment(environment))
        progress.update(len(results))
    return results


def spread(values: np.ndarray, scale: float = 1.0, digits: int = 2) -> str:
    """'mean / median (p10-p90)' of the values, or '-' when there are none."""
    if not len(values):
        return '-'
    values = np.asarray(values, dtype=np.float64) * scale
    p10, p90 = np.percentile(values, [10, 90])
    return (f'{values.mean():.{digits}f} / {np.median(values):.{digits}f} '
            f'({p10:.{digits}f}-{p90:.{digits}f})')


def summary(environments: list[Environment], results: list[TrackRealism]) -> dict[str, str]:
    valid = [r for e, r in zip(environments, results) if e.feasible]
    widths = np.concatenate([r.route_widths for r in valid]) if valid else np.zeros(0)
    curvatures = (np.concatenate([r.route_curvatures for r in valid]) if valid
                  else np.zeros(0))
    mean_turn = np.array([r.route_curvatures.mean() for r in valid if len(r.route_curvatures)])
    sharp = (f'{np.percentile(curvatures, 90):.3f} / {np.percentile(curvatures, 95):.3f} / '
             f'{np.percentile(curvatures, 99):.3f}') if len(curvatures) else '-'
    width_percentiles = (' / '.join(f'{v:.1f}' for v in np.percentile(widths, [5, 25, 50, 75,
                                                                               95]))
                         if len(widths) else '-')
    return {
        'maps': str(len(environments)),
        'valid maps': f'{100 * len(valid) / max(1, len(environments)):.1f} %',
        'route corridor share of track (valid maps)': spread(
            np.array([r.route_corridor_fraction for r in valid]), 100, 1),
        'lap corridor share of track (valid maps)': spread(
            np.array([r.lap_corridor_fraction for r in valid]), 100, 1),
        'maps with a lap through start and goal': (
            f'{100 * sum(r.closed_lap for r in valid) / max(1, len(valid)):.1f} %'),
        'route piece share of track (valid maps)': spread(
            np.array([r.route_component_fraction for r in valid]), 100, 1),
        'fragments per map': spread(np.array([r.fragments for r in results]), 1, 1),
        'dead ends per map': spread(np.array([r.dead_ends for r in results]), 1, 1),
        'track width along the route m (mean / median (p10-p90))': spread(widths, 1, 2),
        'track width m, p5 / p25 / p50 / p75 / p95': width_percentiles,
        'curvature rad/m, mean turn per metre a map': spread(mean_turn, 1, 4),
        'curvature rad/m, p90 / p95 / p99 of route samples': sharp,
        'track cells per map': spread(np.array([r.track_cells for r in results]), 1, 0),
    }


def draw(path: Path, example: Environment, generated: list[Environment], count: int) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    shown = [example] + [e for e in generated if e.feasible][:count - 1]
    columns = min(4, len(shown))
    rows = -(-len(shown) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(4 * columns, 4.5 * rows),
                                squeeze=False)
    for axis in axes.ravel():
        axis.axis('off')
    for axis, environment in zip(axes.ravel(), shown):
        axis.imshow(environment.occupancy == 0, origin='lower', cmap='Greys_r',
                    interpolation='nearest',
                    extent=(0, environment.width * environment.resolution, 0,
                            environment.height * environment.resolution))
        certificate = certify_environment(environment)
        if certificate is not None:
            axis.plot(*certificate.points.T, color='tab:red', linewidth=1.2)
        axis.plot(environment.start.x, environment.start.y, 'o', color='tab:green')
        axis.plot(environment.goal.x, environment.goal.y, 's', color='tab:blue')
        result = measure_environment(environment)
        name = 'example' if environment is example else f'generated seed {environment.seed}'
        axis.set_title(f'{name}\nlap {"yes" if result.closed_lap else "no"}, '
                       f'{result.dead_ends} dead ends, {result.fragments} pieces', fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, default=200, help='generated maps [200]')
    parser.add_argument('--example-placements', type=int, default=50,
                        help='start/goal placements on the example map (its route-free '
                             'measures are the same for all) [50]')
    parser.add_argument('--png', type=Path, default=None,
                        help='write sample generated tracks next to the example here')
    parser.add_argument('--samples', type=int, default=8,
                        help='tracks in the picture, the example included [8]')
    parser.add_argument('--no-post-process', action='store_true',
                        help="the generator's raw maps, without the racetrack scenario's "
                             'track_cleanup (sessgan_gen.track_cleanup)')
    parser.add_argument('--checkpoint', type=Path, default=None,
                        help='a racetrack generator checkpoint (.pt) instead of the shipped one')
    args = parser.parse_args()
    progress = ProgressPrinter()
    started = time.perf_counter()
    seeds = list(range(FIRST_SEED, FIRST_SEED + args.seeds))
    generated = generated_environments(seeds, progress, not args.no_post_process,
                                       args.checkpoint)
    sample_seconds = time.perf_counter() - started
    example = example_environments(seeds[:max(1, args.example_placements)])
    columns = {
        'generated': summary(generated, measure_all(generated, 'generated', progress)),
        'example': summary(example, measure_all(example, 'example', progress)),
    }
    source = args.checkpoint or 'the shipped generator'
    print(f'racetrack, {args.seeds} generated maps of {source} '
          f'(seeds {FIRST_SEED}..'
          f'{FIRST_SEED + args.seeds - 1}; '
          f'{"raw generator output" if args.no_post_process else "with the track cleanup"}'
          '), example map with '
          f'{len(example)} placements; sampling {1000 * sample_seconds / len(generated):.0f} '
          'ms a map')
    print('| measure | generated | example |')
    print('|---|---:|---:|')
    for key in columns['generated']:
        print(f'| {key} | {columns["generated"][key]} | {columns["example"][key]} |')
    if args.png:
        draw(args.png, example[0], generated, args.samples)
        print(f'picture: {args.png}')


if __name__ == '__main__':
    main()
