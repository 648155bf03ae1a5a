"""Confirming distinct faults and keeping one record of each: a bag and a picture.

For every distinct fault (sessgan_evolver.faults) the episode of its first occurrence is run
again ``repeats`` times on the same runner (not counted in any search budget). The first
re-run keeps its scans, so when records are wanted it becomes the fault's failure bag
(``<directory>/<nn>-<fault label>/``, replayable with ``ros2 run sessgan_evolver replay``)
with ``fault.png`` drawn from the bag beside it. A re-run on an external worker
(sessgan_evolver.worker_episodes) left its own failure bag, with the worker's settings: that
bag is copied instead, with the fault's facts added to its episode.json.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from sessgan_evolver.bag_export import write_trace_bag
from sessgan_evolver.bag_reading import EPISODE_FILE
from sessgan_evolver.fault_picture import scene_from_bag, write_scene_png
from sessgan_evolver.faults import Confirmation, FaultEntry, FaultRule, confirm, key_of_failure
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.search import EpisodeRecord
from sessgan_sim.bag_recording import FAULT_PICTURE_FILE


def confirm_faults(entries: Sequence[FaultEntry], records: Sequence[EpisodeRecord],
                   evaluator: InProcessEvaluator, rule: FaultRule, repeats: int,
                   record_directory: str | Path | None = None, max_records: int = 0,
                   metadata: Mapping[str, Any] | None = None) -> list[Path]:
    """Confirm each fault (stored in ``entry.confirmation``) and write up to ``max_records``
    records of confirmed faults under ``record_directory`` (a negative ``max_records``: one
    per confirmed fault); returns the record paths."""
    written: list[Path] = []
    for number, entry in enumerate(entries):
        record = records[entry.first]
        want_record = record_directory is not None and (max_records < 0
                                                        or len(written) < max_records)
        kept: dict[str, Any] = {}

        def rerun() -> tuple[Mapping[str, Any], Any, float]:
            keep = want_record and 'run' not in kept
            started = time.perf_counter()
            run = evaluator.runner.run(record.environment, record.sim_seed, trace=True,
                                       keep_scans=keep)
            seconds = time.perf_counter() - started
            if keep:
                kept['run'] = run
            return run.metrics, key_of_failure(record.environment, run.metrics, run.trace,
                                               rule), seconds

        confirmation = confirm(entry, record.metrics, rerun, repeats)
        if record_directory is not None and want_record and confirmation.confirmed \
                and 'run' in kept:
            directory = Path(record_directory) / f'{number:03d}-{entry.key.label}'
            written.append(write_fault_record(directory, record, kept['run'], evaluator, rule,
                                              confirmation, metadata))
    return written


def write_fault_record(directory: Path, record: EpisodeRecord, run: Any,
                       evaluator: InProcessEvaluator, rule: FaultRule,
                       confirmation: Confirmation | None = None,
                       metadata: Mapping[str, Any] | None = None) -> Path:
    """The fault's bag (from ``run``, traced with scans, or the bag its worker wrote) and its
    picture."""
    fault_facts = {
        'origin': record.origin,
        'fault': record.fault.to_dict() if record.fault else None,
        'fault_rule': asdict(rule), 'search_episode': record.index,
        'confirmation': asdict(confirmation) if confirmation else None,
        **dict(metadata or {}),
    }
    worker_bag = str(run.metrics.get('bag_path') or '')
    if worker_bag and (run.trace is None or run.trace.scans is None):
        bag = copy_worker_bag(Path(worker_bag), directory, fault_facts)
        write_scene_png(scene_from_bag(bag), bag / FAULT_PICTURE_FILE)
        return bag
    facts = {
        **evaluator.episode_facts(record.sim_seed, record.environment),
        'controller': evaluator.controller,
        'metrics': {k: v for k, v in run.metrics.items() if k != 'bag_path'},
        **fault_facts,
    }
    bag = write_trace_bag(directory, record.environment, run.trace, facts)
    write_scene_png(scene_from_bag(bag), bag / FAULT_PICTURE_FILE)
    return bag


def copy_worker_bag(bag: Path, directory: Path, facts: Mapping[str, Any]) -> Path:
    """A copy of a worker's failure bag at ``directory`` with ``facts`` added to its
    episode.json; copied under a temporary name and renamed, so no half copy appears."""
    staging = directory.with_name(f'{directory.name}.tmp-{os.getpid()}')
    shutil.rmtree(staging, ignore_errors=True)
    shutil.copytree(bag, staging)
    episode_path = staging / EPISODE_FILE
    episode = json.loads(episode_path.read_text(encoding='utf-8'))
    episode.update(facts)
    episode_path.write_text(json.dumps(episode, indent=2), encoding='utf-8')
    if directory.exists():
        shutil.rmtree(directory)
    os.rename(staging, directory)
    return directory
