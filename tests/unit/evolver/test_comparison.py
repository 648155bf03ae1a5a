"""A tiny comparison of every method: equal budgets, one fresh-seed evaluation per generator,
the report's files."""

from __future__ import annotations

import csv
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from sessgan_evolver.comparison import (
    CompareConfig,
    CompareError,
    fault_situations,
    figures_by_origin,
    run_comparison,
    spread,
)
from sessgan_evolver.fault_tally import origin_family
from sessgan_evolver.faults import (
    STRICT_SITUATION_CELLS,
    Confirmation,
    FaultEntry,
    FaultKey,
)
from sessgan_evolver.search_methods import METHODS

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


def read(path):
    with open(path) as handle:
        return list(csv.DictReader(handle))


def test_every_method_runs_at_equal_budget_and_is_reported(tmp_path):
    config = CompareConfig(search_seeds=(0, 1), budget=4, population=2, maps_per_member=2,
                           time_limit=2.0, fresh_episodes=2, repeats=1, max_fault_records=0)
    result = run_comparison(config, tmp_path / 'compare', 'compare --tiny', log=lambda _: None)
    assert [(r.figures.method, r.figures.search_seed) for r in result.runs] == \
        [(m, s) for s in (0, 1) for m in METHODS]
    for run in result.runs:
        figures = run.figures
        assert figures.episodes == 4 == len(run.records)
        assert figures.confirmed_faults <= figures.checked_faults == figures.distinct_faults
        assert figures.distinct_faults <= figures.valid_failures <= figures.valid_maps <= 4
        assert figures.confirmed_per_1000 == pytest.approx(250 * figures.confirmed_faults)
        assert figures.strict_situations_per_1000 <= figures.situations_per_1000 \
            <= figures.confirmed_per_1000
        assert figures.situations_per_1000 > 0 or not figures.confirmed_faults
        if figures.confirmed_faults:
            assert 1 <= figures.first_confirmed_episode <= 4
            assert figures.first_confirmed_wall > 0
        if figures.method == 'grid_ga':  # no generator to evaluate on fresh seeds
            assert figures.generator == '' and figures.fresh_valid_fraction is None
        else:
            assert figures.generator and figures.fresh_valid_fraction is not None
    # One fresh-seed evaluation per distinct generator: 2 SESS-GAN members, the shipped
    # generator (random, latent and screened), the cellular automaton.
    assert len(result.fresh) == 4
    output = tmp_path / 'compare'
    for name in ('report.md', 'compare.png', 'failing_maps.png', 'fresh_seed.csv',
                 'fresh_seed_plan.txt'):
        assert (output / name).stat().st_size > 0
    runs = read(output / 'runs.csv')
    assert len(runs) == 2 * len(METHODS) and len(read(output / 'episodes.csv')) == \
        8 * len(METHODS)
    # Only the screened search does cheap work before its episodes, inside its search time.
    for row in runs:
        cheap = float(row['cheap_wall'])
        assert (cheap > 0) == (row['method'] == 'screened')
        assert cheap < float(row['search_wall'])
    report = (output / 'report.md').read_text()
    assert 'compare --tiny' in report and all(method in report for method in METHODS)
    # Where the faults come from: every episode of a method in one origin row or another.
    for method in METHODS:
        rows = figures_by_origin([run for run in result.runs if run.figures.method == method])
        assert sum(row.episodes for row in rows.values()) == 8
        assert sum(row.faults for row in rows.values()) == sum(
            run.figures.confirmed_faults for run in result.runs if run.figures.method == method)
    assert '## Where the faults come from' in report and '| screened | fresh sample |' in report
    with pytest.raises(CompareError, match='holds a comparison'):
        run_comparison(config, output, log=lambda _: None)


def test_a_local_variant_of_a_failing_map_is_a_new_fault_but_the_same_situation():
    """Three faults of one kind in one coarse cell: on the map, on a variant 5 % of cells
    apart, on a map 20 % apart; and one of another kind on the first map."""
    base = np.zeros((10, 10), dtype=np.int8)
    near, far = base.copy(), base.copy()
    near.flat[:5] = 100
    far.flat[:20] = 100
    maps = [base, near, far, base]
    records = [SimpleNamespace(environment=SimpleNamespace(occupancy=grid)) for grid in maps]
    faults = [FaultEntry(FaultKey(kind, 1, 2, str(index)), [index])
              for index, kind in enumerate(['collision_static'] * 3 + ['stuck'])]
    assert fault_situations(faults, records) == 3  # the variant 5 % apart is one
    assert fault_situations(faults, records, STRICT_SITUATION_CELLS) == 2  # 20 % too
    assert fault_situations([], records) == 0


def test_faults_are_credited_to_the_origin_of_the_episode_that_first_showed_them():
    """Two runs alike: a fresh sample fails; of its children, one fails at the same place on a
    variant 5 % apart (a new distinct fault, the same situation), one shows nothing and one
    fails on a map 20 % apart (a new situation); an unconfirmed fault counts nowhere."""
    assert origin_family('child of collision_static r1c2 by local_0.8') == 'child by local_0.8'
    assert origin_family('generation 3 crossover 0x2 + paint') == 'crossover + paint'
    assert origin_family('generation 3 from 4 + move') == 'one parent + move'
    assert origin_family('generation 0 generation 0') == 'generation 0'
    assert origin_family('generation 0 member 3') == 'generation 0'
    assert origin_family('generation 7 member 3') == 'evolved generations'
    assert origin_family('fresh sample') == 'fresh sample' and origin_family('') == 'unlabelled'
    base = np.zeros((10, 10), dtype=np.int8)
    near, far = base.copy(), base.copy()
    near.flat[:5] = 100
    far.flat[:20] = 100
    origins = ['fresh sample', 'child of collision_static r1c2 by local_0.8',
               'child of collision_static r1c2 by local_0.8',
               'child of collision_static r1c2 by two_finest_0.9', 'fresh sample']
    maps = [base, near, near, far, base]
    records = [SimpleNamespace(origin=origin, environment=SimpleNamespace(occupancy=grid))
               for origin, grid in zip(origins, maps)]

    def entry(index, confirmed=True):
        return FaultEntry(FaultKey('collision_static', 1, 2, str(index)), [index],
                          Confirmation(3, 3 if confirmed else 1, 0, 1.0))

    run = SimpleNamespace(records=records, faults=[entry(0), entry(1), entry(3), entry(4, False)])
    table = figures_by_origin([run, run])  # pooled: each run's situations counted on its own
    assert {origin: (row.episodes, row.faults, row.situations)
            for origin, row in table.items()} == {
        'fresh sample': (4, 2, 2), 'child by local_0.8': (4, 2, 0),
        'child by two_finest_0.9': (2, 2, 2)}


def test_bad_settings_and_the_spread():
    with pytest.raises(CompareError, match='unknown'):
        CompareConfig(methods=('random', 'magic')).validate()
    with pytest.raises(CompareError, match='distinct'):
        CompareConfig(search_seeds=(1, 1)).validate()
    with pytest.raises(CompareError, match='no SESS-GAN generation'):
        CompareConfig(budget=10).validate()
    with pytest.raises(CompareError, match='screening_effort must be >= 0'):
        CompareConfig(methods=('screened',), screening_effort=-1).validate()
    with pytest.raises(CompareError, match='exploration must lie in'):
        CompareConfig(methods=('screened',), exploration=-1.0).validate()
    assert spread([1.0, 3.0, None]) == (2.0, pytest.approx(2 ** 0.5), 2)
    assert spread([None]) == (None, None, 0)


def test_evaluate_says_how_many_faults_their_re_runs_confirmed(tmp_path):
    """A fault whose re-runs ended elsewhere gets no record: evaluate says so, rather than
    leaving the user to wonder why faults/ is empty."""
    from sessgan_evolver.evaluate_cli import confirmation_line
    from sessgan_evolver.faults import Confirmation, FaultEntry, FaultKey

    fault = FaultEntry(FaultKey('stuck', 1, 2, 'ab'), [0])
    fault.confirmation = Confirmation(repeats=3, reproduced=2, exact=0, wall_time=1.0)
    assert confirmation_line('mine', [fault], 3, []) == (
        'mine: 0 of 1 distinct faults confirmed (3 re-runs each showed the same kind at the '
        'same place, its coarse cell or a neighbouring one); none kept (only confirmed faults '
        'are)')
    fault.confirmation = Confirmation(repeats=3, reproduced=3, exact=3, wall_time=1.0)
    record = tmp_path / 'faults' / 'mine' / '000-stuck'
    assert confirmation_line('mine', [fault], 3, [record]).endswith(
        f'1 of 1 distinct faults confirmed (3 re-runs each showed the same kind at the same '
        f'place, its coarse cell or a neighbouring one); 1 kept as bag + picture in '
        f'{record.parent}')
