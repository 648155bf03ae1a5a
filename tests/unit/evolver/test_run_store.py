"""Run directory: atomic checkpoints, metrics files, and resume equal to an uninterrupted run."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from sessgan_core.atomic_files import atomic_write_bytes
from sessgan_evolver.algorithm import GeneticAlgorithm, GeneticAlgorithmConfig
from sessgan_evolver.errors import RunStoreError
from sessgan_evolver.fitness import (
    generation_summary,
    map_diversity,
    member_fitness,
    tpkl_reference_from,
)
from sessgan_evolver.genome import Genome
from sessgan_evolver.run_store import RunStore
from sessgan_evolver.seeding import shared_seeds

pytestmark = pytest.mark.unit

CAMPAIGN_SEED = 5
MAPS_PER_MEMBER = 2


class Killed(Exception):
    """Stands in for SIGKILL: the campaign stops dead at a chosen point."""


def fake_episode(genome: Genome, map_seed: int) -> dict:
    """A deterministic stand-in for generator + simulator: metrics from genome and seed."""
    rng = np.random.default_rng([map_seed, int(genome.digest()[:12], 16)])
    collisions = int(rng.integers(0, 3))
    simulation_time = float(rng.uniform(5.0, 30.0))
    proximity_time = float(rng.uniform(0.0, simulation_time / 2))
    return {'collisions': collisions, 'fault_collisions': collisions,
            'proximity_time': proximity_time, 'simulation_time': simulation_time,
            'risk_score': collisions * proximity_time / simulation_time,
            'fault_risk_score': collisions * proximity_time / simulation_time,
            'feasible': bool(rng.random() > 0.2),
            'outcome': 'collision_limit' if collisions else 'goal_reached'}


def fake_maps(genome: Genome, seeds: list[int]) -> list[np.ndarray]:
    return [np.random.default_rng([s, int(genome.digest()[:12], 16)]).integers(0, 2, (6, 6))
            for s in seeds]


def fake_tpkl(genome: Genome, initial: Genome) -> float:
    drift = sum(float((genome[n] - initial[n]).abs().mean()) for n in genome.names())
    return 0.2 + drift


def campaign(store: RunStore, initial: Genome, generations: int,
             kill_at: tuple | None = None, resume: bool = False) -> GeneticAlgorithm:
    """The campaign order of run_store's docstring, with a fake evaluation."""
    config = GeneticAlgorithmConfig(population_size=4, seed=CAMPAIGN_SEED)
    if resume:
        point = store.resume()
        assert point is not None
        algorithm = GeneticAlgorithm.from_state_dict(point.checkpoint['algorithm'])
        reference = point.checkpoint['extra']['tpkl_reference']
    else:
        store.write_config({'population_size': 4, 'maps_per_member': MAPS_PER_MEMBER},
                           CAMPAIGN_SEED)
        algorithm = GeneticAlgorithm(config, initial)
        reference = None
        store.save_checkpoint(0, algorithm.state_dict(), {'tpkl_reference': reference})
    while algorithm.generation < generations:
        generation = algorithm.generation
        seeds = shared_seeds(CAMPAIGN_SEED, generation, MAPS_PER_MEMBER)
        genomes = algorithm.ask()
        tpkls = [fake_tpkl(genome, initial) for genome in genomes]
        if reference is None:
            reference = tpkl_reference_from(tpkls)
        breakdowns = []
        for member, genome in enumerate(genomes):
            episodes = [fake_episode(genome, seed) for seed in seeds]
            for map_index, (seed, episode) in enumerate(zip(seeds, episodes)):
                if kill_at == ('episode', generation, member, map_index):
                    raise Killed
                store.append_episode({'generation': generation, 'member': member,
                                      'map_index': map_index, 'seed': seed, **episode,
                                      'tpkl': tpkls[member]})
            breakdown = member_fitness(episodes, tpkls[member], reference,
                                       map_diversity(fake_maps(genome, seeds)))
            store.append_member({'generation': generation, 'member': member,
                                 'genome': genome.digest()[:16], **breakdown.as_row()})
            breakdowns.append(breakdown)
        algorithm.tell([b.fitness for b in breakdowns])
        store.append_generation(generation_summary(generation, breakdowns))
        if kill_at == ('checkpoint', algorithm.generation):
            raise Killed
        store.save_checkpoint(algorithm.generation, algorithm.state_dict(),
                              {'tpkl_reference': reference})
    return algorithm


def files_of(store: RunStore) -> dict[str, bytes]:
    return {str(path.relative_to(store.run_dir)): path.read_bytes()
            for path in sorted(store.run_dir.rglob('*')) if path.is_file()
            and path.suffix != '.pt'}


@pytest.mark.parametrize('kill_at', [('episode', 3, 2, 1), ('checkpoint', 3),
                                     ('episode', 0, 1, 0)])
def test_resume_after_a_kill_ends_like_an_uninterrupted_run(tmp_path, state_dict, kill_at):
    initial = Genome.from_state_dict(state_dict)
    uninterrupted_store = RunStore(tmp_path / 'a', 'run')
    uninterrupted = campaign(uninterrupted_store, initial, generations=5)

    store = RunStore(tmp_path / 'b', 'run')
    with pytest.raises(Killed):
        campaign(store, initial, generations=5, kill_at=kill_at)
    # What a SIGKILL can leave: a torn metrics line and a half-written checkpoint temp file.
    with store.metrics_jsonl_path.open('a') as handle:
        handle.write('{"kind": "episode", "generation": 3, "mem')
    (store.checkpoints_dir / '.generation_0004.pt.tmp-abc123').write_bytes(b'\x80partial')
    resumed = campaign(RunStore(tmp_path / 'b', 'run'), initial, generations=5, resume=True)

    assert files_of(store) == files_of(uninterrupted_store)
    assert [c.generation for c in store.checkpoints()] == [0, 1, 2, 3, 4, 5]
    assert not list(store.checkpoints_dir.glob('.*'))
    assert [g.digest() for g in resumed.ask()] == [g.digest() for g in uninterrupted.ask()]
    assert resumed.history == uninterrupted.history
    final = store.load_checkpoint(5)['algorithm']
    expected = uninterrupted_store.load_checkpoint(5)['algorithm']
    assert final['rng_state'] == expected['rng_state']
    assert final['generation'] == 5


def test_resume_without_a_checkpoint_returns_none(tmp_path):
    assert RunStore(tmp_path, 'fresh').resume() is None


def test_resume_from_an_earlier_generation_drops_later_state(tmp_path, state_dict):
    initial = Genome.from_state_dict(state_dict)
    store = RunStore(tmp_path, 'run')
    campaign(store, initial, generations=4)
    point = store.resume(generation=2)
    assert point is not None and point.generation == 2
    assert [c.generation for c in store.checkpoints()] == [0, 1, 2]
    assert {row['generation'] for row in store.read_rows()} == {0, 1}
    with pytest.raises(RunStoreError, match='no checkpoint of generation 7'):
        store.resume(generation=7)


def test_a_truncated_latest_checkpoint_falls_back_to_the_previous_generation(tmp_path,
                                                                           state_dict):
    initial = Genome.from_state_dict(state_dict)
    uninterrupted_store = RunStore(tmp_path / 'a', 'run')
    uninterrupted = campaign(uninterrupted_store, initial, generations=5)
    store = RunStore(tmp_path / 'b', 'run')
    with pytest.raises(Killed):
        campaign(store, initial, generations=5, kill_at=('episode', 3, 2, 1))
    latest = store.checkpoint_path(3)
    latest.write_bytes(latest.read_bytes()[:100])  # a disk that lost the file's end

    point = store.resume()
    assert point is not None and point.generation == 2
    assert len(point.set_aside) == 1
    assert 'generation_0003.pt is not a valid checkpoint' in point.set_aside[0]
    assert 'renamed to generation_0003.pt.corrupt' in point.set_aside[0]
    assert (store.checkpoints_dir / 'generation_0003.pt.corrupt').is_file()
    assert {row['generation'] for row in store.read_rows()} == {0, 1}
    # Going on from generation 2 ends where the uninterrupted run ended.
    resumed = campaign(RunStore(tmp_path / 'b', 'run'), initial, generations=5, resume=True)
    assert files_of(store) == {**files_of(uninterrupted_store),
                               'checkpoints/generation_0003.pt.corrupt':
                                   files_of(store)['checkpoints/generation_0003.pt.corrupt']}
    assert resumed.history == uninterrupted.history


def test_no_readable_checkpoint_says_how_to_start_over_and_changes_nothing(tmp_path):
    store = RunStore(tmp_path, 'run')
    for generation in (0, 1):
        store.checkpoint_path(generation).write_bytes(b'torn data')
    before = sorted(path.name for path in store.checkpoints_dir.iterdir())
    with pytest.raises(RunStoreError, match=r'cannot be resumed: none of its 2 checkpoints is '
                                            r'readable .*remove .*run.* another --run name'):
        store.resume()
    assert sorted(path.name for path in store.checkpoints_dir.iterdir()) == before


def test_latest_checkpoint_ignores_temporary_and_foreign_files(tmp_path):
    store = RunStore(tmp_path, 'run')
    store.save_checkpoint(1, {'x': 1})
    store.save_checkpoint(12, {'x': 12})
    (store.checkpoints_dir / '.generation_0013.pt.tmp-xyz').write_bytes(b'half')
    (store.checkpoints_dir / 'generation_0014.pt.partial').write_bytes(b'half')
    (store.checkpoints_dir / 'notes.txt').write_text('hello')
    latest = store.latest_checkpoint()
    assert latest is not None and latest.generation == 12
    assert latest.path.name == 'generation_0012.pt'
    payload = store.load_checkpoint(12)
    assert payload['algorithm'] == {'x': 12} and payload['generation'] == 12


def test_a_failed_atomic_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / 'generation_0001.pt'
    atomic_write_bytes(target, b'old')

    def crash(*_args):
        raise OSError('disk gone')

    monkeypatch.setattr(os, 'replace', crash)
    with pytest.raises(OSError):
        atomic_write_bytes(target, b'new')
    assert target.read_bytes() == b'old'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['generation_0001.pt']


def test_a_corrupt_checkpoint_is_reported(tmp_path):
    store = RunStore(tmp_path, 'run')
    store.checkpoint_path(3).write_bytes(b'garbage')
    with pytest.raises(RunStoreError, match='is not a valid checkpoint') as caught:
        store.load_checkpoint(3)
    assert 'weights_only' not in str(caught.value)
    with pytest.raises(RunStoreError, match='is a directory, not a checkpoint file'):
        store.load_checkpoint(tmp_path)
    other = tmp_path / 'other.pt'
    torch.save({'weights': torch.ones(1)}, other)
    with pytest.raises(RunStoreError, match='not a sessgan_evolver'):
        store.load_checkpoint(other)
    with pytest.raises(RunStoreError, match='does not exist'):
        store.load_checkpoint(9)


def test_config_is_written_once_and_guarded(tmp_path):
    store = RunStore(tmp_path, 'run')
    store.write_config({'generations': 30, 'scenario': 'factory'}, seed=1)
    store.write_config({'generations': 30, 'scenario': 'factory'}, seed=1,
                       software_version='9.9.9')
    document = json.loads(store.config_path.read_text())
    assert document['seed'] == 1 and document['config']['scenario'] == 'factory'
    assert document['software_version'] != '9.9.9'
    with pytest.raises(RunStoreError, match='generations: 30 -> 40'):
        store.write_config({'generations': 40, 'scenario': 'factory'}, seed=1)
    with pytest.raises(RunStoreError, match='seed'):
        store.write_config({'generations': 30, 'scenario': 'factory'}, seed=2)


def test_metrics_rows_go_to_jsonl_and_per_kind_csv(tmp_path):
    store = RunStore(tmp_path, 'run')
    store.append_episode({'generation': 0, 'member': 1, 'risk_score': np.float32(0.5),
                          'feasible': np.bool_(True), 'tpkl': float('nan'),
                          'bag_path': Path('bags/run/e1')})
    store.append_episode({'generation': 0, 'member': 2, 'risk_score': 0.0,
                          'feasible': False})
    store.append_generation({'generation': 0, 'mean_risk_score': 0.25})
    rows = store.read_rows()
    assert [row['kind'] for row in rows] == ['episode', 'episode', 'generation']
    assert rows[0]['tpkl'] is None and rows[0]['feasible'] is True
    assert rows[0]['bag_path'] == 'bags/run/e1'
    lines = store.metrics_csv_path('episode').read_text().splitlines()
    assert lines[0] == 'generation,member,risk_score,feasible,tpkl,bag_path'
    assert lines[2] == '0,2,0.0,False,,'
    assert store.read_rows('generation') == [{'kind': 'generation', 'generation': 0,
                                              'mean_risk_score': 0.25}]
    with pytest.raises(RunStoreError, match='lacks'):
        store.append_episode({'generation': 0, 'member': 3, 'surprise': 1})
    with pytest.raises(RunStoreError, match='generation'):
        store.append_member({'member': 3})
    with pytest.raises(RunStoreError, match='kind'):
        store.append_row('bag', {'generation': 0})


def test_a_corrupt_line_inside_metrics_is_an_error(tmp_path):
    store = RunStore(tmp_path, 'run')
    store.append_generation({'generation': 0})
    with store.metrics_jsonl_path.open('a') as handle:
        handle.write('not json\n')
    store.append_generation({'generation': 1})
    with pytest.raises(RunStoreError, match='not valid JSON'):
        store.read_rows()


@pytest.mark.parametrize('name', ['', '../escape', 'a/b', '.hidden', 'run\n', 'run\nx', 'a..b',
                                  'run.tmp-5', 'x' * 129])
def test_invalid_run_names_are_rejected(tmp_path, name):
    """A trailing newline too (a regex ending in '$' matched before it); and the names a
    simulator would refuse as record directory (bags/<run>/)."""
    with pytest.raises(RunStoreError, match='run name'):
        RunStore(tmp_path, name)
    assert list(tmp_path.iterdir()) == []


def test_a_checkpoint_name_with_a_trailing_newline_is_no_checkpoint(tmp_path):
    store = RunStore(tmp_path, 'run')
    (store.checkpoints_dir / 'generation_0001.pt\n').write_bytes(b'not a checkpoint')
    assert store.checkpoints() == []
