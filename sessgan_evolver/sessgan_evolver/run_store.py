"""The run directory of a campaign: config, atomic checkpoints, metrics, resume.

Layout of ``<runs_root>/<run_name>/``::

    config.json                      campaign config, seed, software version, invocation
    checkpoints/generation_0003.pt   algorithm state ready to evaluate generation 3
    metrics.jsonl                    every metrics row, one JSON object per line, with 'kind'
    metrics_episodes.csv             the 'episode' rows (one per map and member)
    metrics_members.csv              the 'member' rows (fitness breakdown per member)
    metrics_generations.csv          the 'generation' rows (summary per generation)
    report/                          written by ``report.write_report``

Crash safety: checkpoints and config are written to a temporary file in the same
directory, fsynced and renamed over the final name, so a SIGKILL leaves either the old
file or the new one, never half of one (a stray ``.generation_0003.pt.tmp-*`` may stay
behind and is ignored and later removed). ``metrics.jsonl`` is the source of truth; the
CSV files are derived from it and rebuilt on resume. Metrics rows are flushed on every
append (a killed process loses nothing written) and fsynced before each checkpoint.

The order a campaign follows, which makes resume exact: save checkpoint g (before
evaluating g) -> append g's episode and member rows -> tell -> append g's generation row
-> save checkpoint g+1. ``resume()`` loads the latest checkpoint g and deletes every
metrics row of generation >= g, so generation g is evaluated again from the same state,
with the same seeds, and the files end up as an uninterrupted run would leave them.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import shlex
import shutil
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from sessgan_core.atomic_files import atomic_write_bytes
from sessgan_core.environment import MAX_ENVIRONMENT_ID_LENGTH, check_environment_id
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_core.json_data import to_json_data
from sessgan_evolver import __version__
from sessgan_evolver.errors import RunStoreError
from sessgan_gen.checkpoint import check_checkpoint_file, not_a_checkpoint_message
from sessgan_gen.errors import CheckpointError

CHECKPOINT_FORMAT = 'sessgan_evolver.checkpoint/1'
"""Tag stored in every population checkpoint."""

ROW_KINDS = ('episode', 'member', 'generation')
"""Kinds of metrics rows; each kind has its own CSV file."""

# Used with fullmatch: '$' alone also matches before a trailing newline.
_CHECKPOINT_NAME = re.compile(r'generation_(\d{4,})\.pt')


@dataclass(frozen=True)
class CheckpointInfo:
    """A population checkpoint on disk."""

    generation: int
    path: Path


@dataclass(frozen=True)
class ResumePoint:
    """Where a resumed campaign continues: evaluate ``generation`` from ``checkpoint``."""

    generation: int
    checkpoint: dict[str, Any]
    """The payload of ``save_checkpoint``: 'algorithm' (the state dict) and 'extra'."""
    path: Path
    set_aside: tuple[str, ...] = ()
    """One line per newer checkpoint that could not be read and was renamed to
    ``*.pt.corrupt`` (the run continues from an earlier generation instead)."""


class RunStore:
    """Files of one campaign run under ``<runs_root>/<run_name>/``."""

    def __init__(self, runs_root: str | Path, run_name: str) -> None:
        """Create the run directory (and its checkpoints folder) if needed."""
        # The rule of environment ids: bags/<run>/ is also the record directory simulators
        # are asked to write into, and they accept only such names.
        try:
            check_environment_id(run_name)
        except InvalidEnvironmentError as err:
            raise RunStoreError(f'run name {run_name!r} must start with a letter or digit, '
                                'contain only letters, digits, ".", "_" and "-" (no "..", no '
                                f'".tmp-") and have at most {MAX_ENVIRONMENT_ID_LENGTH} '
                                'characters') from err
        self.run_name = run_name
        self.run_dir = Path(runs_root) / run_name
        self.checkpoints_dir = self.run_dir / 'checkpoints'
        try:
            self.checkpoints_dir.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise RunStoreError(f'cannot create run directory {self.run_dir}: {err}') from err

    # -- paths ----------------------------------------------------------------------------

    @property
    def config_path(self) -> Path:
        return self.run_dir / 'config.json'

    @property
    def metrics_jsonl_path(self) -> Path:
        return self.run_dir / 'metrics.jsonl'

    @property
    def situations_path(self) -> Path:
        """The fault situations found so far (sessgan_evolver.fault_tally), for a resume."""
        return self.run_dir / 'situations.npz'

    @property
    def report_dir(self) -> Path:
        return self.run_dir / 'report'

    def metrics_csv_path(self, kind: str) -> Path:
        """The CSV file of one row kind ('episode', 'member' or 'generation')."""
        _check_kind(kind)
        return self.run_dir / f'metrics_{kind}s.csv'

    def checkpoint_path(self, generation: int) -> Path:
        return self.checkpoints_dir / f'generation_{generation:04d}.pt'

    # -- config ---------------------------------------------------------------------------

    def write_config(self, config: Mapping[str, Any], seed: int,
                     software_version: str = __version__,
                     invocation: Mapping[str, Any] | None = None) -> None:
        """Write config.json once. Writing the same config and seed again is a no-op (a
        resumed run; the recorded software version stays the original one); a different
        config or seed raises RunStoreError listing what differs, so a run name is never
        reused with other settings by accident. ``invocation`` (command line, paths) is
        stored for the record but not compared."""
        document = {'config': _plain(config), 'seed': int(seed),
                    'software_version': software_version,
                    'invocation': _plain(dict(invocation or {}))}
        self.check_config(config, seed)
        if self.config_path.exists():
            return
        text = json.dumps(document, indent=2, sort_keys=True, allow_nan=False) + '\n'
        atomic_write_bytes(self.config_path, text.encode())

    def check_config(self, config: Mapping[str, Any], seed: int) -> None:
        """RunStoreError listing what differs when the run exists with another config or seed
        (nothing written: a command checks this before it starts anything)."""
        if not self.config_path.exists():
            return
        existing = self.read_config()
        differences = _differences({'config': existing.get('config'),
                                    'seed': existing.get('seed')},
                                   {'config': _plain(config), 'seed': int(seed)})
        if differences:
            made_with = (existing.get('invocation') or {}).get('command_line')
            raise RunStoreError(
                f'run {self.run_name!r} already exists with a different config: '
                f'{"; ".join(differences[:10])}' + (
                    f'; it was made with `{shlex.join(made_with)}` (that command with '
                    '--resume continues it)' if isinstance(made_with, list) else ''))

    def read_config(self) -> dict[str, Any]:
        """The config.json document: {'config', 'seed', 'software_version'}."""
        try:
            return json.loads(self.config_path.read_text())
        except (OSError, ValueError) as err:
            raise RunStoreError(f'cannot read {self.config_path}: {err}') from err

    # -- checkpoints ----------------------------------------------------------------------

    def save_checkpoint(self, generation: int, algorithm_state: Mapping[str, Any],
                        extra: Mapping[str, Any] | None = None) -> Path:
        """Atomically write ``checkpoints/generation_<g>.pt`` holding the algorithm state
        (ready to evaluate generation ``generation``) and ``extra`` plain data that the
        campaign needs on resume (e.g. the TPKL reference). Returns the path."""
        # Rows appended so far must be durable before a checkpoint that follows them is.
        for path in [self.metrics_jsonl_path] + [self.metrics_csv_path(k) for k in ROW_KINDS]:
            _fsync_file(path)
        payload = {'format': CHECKPOINT_FORMAT, 'generation': int(generation),
                   'algorithm': dict(algorithm_state), 'extra': dict(extra or {})}
        buffer = io.BytesIO()
        torch.save(payload, buffer)
        path = self.checkpoint_path(generation)
        atomic_write_bytes(path, buffer.getvalue())
        return path

    def checkpoints(self) -> list[CheckpointInfo]:
        """Every complete checkpoint, by generation (temporary files are ignored)."""
        found = []
        for path in self.checkpoints_dir.iterdir():
            match = _CHECKPOINT_NAME.fullmatch(path.name)
            if match and path.is_file():
                found.append(CheckpointInfo(int(match.group(1)), path))
        return sorted(found, key=lambda info: info.generation)

    def latest_checkpoint(self) -> CheckpointInfo | None:
        """The checkpoint of the highest generation, or None if there is none."""
        found = self.checkpoints()
        return found[-1] if found else None

    def load_checkpoint(self, generation_or_path: int | str | Path) -> dict[str, Any]:
        """Load a checkpoint (by generation or path) with ``weights_only=True``."""
        path = (self.checkpoint_path(generation_or_path)
                if isinstance(generation_or_path, int) else Path(generation_or_path))
        label = f'population checkpoint {path}'
        try:
            check_checkpoint_file(path, label)
        except CheckpointError as err:
            raise RunStoreError(str(err)) from err
        try:
            payload = torch.load(path, map_location='cpu', weights_only=True)
        except Exception as err:  # torch raises many types for a corrupt file
            raise RunStoreError(not_a_checkpoint_message(label, err)) from err
        if not isinstance(payload, dict) or payload.get('format') != CHECKPOINT_FORMAT:
            raise RunStoreError(f'{path} is not a sessgan_evolver population checkpoint')
        return payload

    def remove_stray_temporary_files(self) -> list[Path]:
        """Delete temporary files a killed write left behind; returns what was removed."""
        removed = []
        for directory in (self.run_dir, self.checkpoints_dir):
            for path in directory.glob('.*.tmp-*'):
                if path.is_file():
                    path.unlink()
                    removed.append(path)
        return removed

    # -- metrics --------------------------------------------------------------------------

    def append_row(self, kind: str, row: Mapping[str, Any]) -> None:
        """Append one metrics row of ``kind`` to metrics.jsonl and to its CSV file.

        ``row`` must have an integer 'generation'. Values become plain JSON: numpy
        scalars are converted, non-finite floats are stored as null. A kind's CSV columns
        are the keys of its first row; later rows may leave columns out but not add any.
        """
        _check_kind(kind)
        record = {'kind': kind, **_plain(row)}
        if not isinstance(record.get('generation'), int):
            raise RunStoreError(f'a metrics row needs an integer "generation", got {row!r}')
        csv_path = self.metrics_csv_path(kind)
        header = _read_csv_header(csv_path)
        if header is not None:
            extra = [key for key in record if key != 'kind' and key not in header]
            if extra:
                raise RunStoreError(f'{kind} row has columns {extra} that {csv_path.name} '
                                    f'lacks (its columns: {header})')
        line = json.dumps(record, allow_nan=False, sort_keys=False) + '\n'
        _append_text(self.metrics_jsonl_path, line)
        _append_csv_rows(csv_path, header, [record])

    def append_episode(self, row: Mapping[str, Any]) -> None:
        """Append a per-episode row (generation, member, seed, outcome, metrics, ...)."""
        self.append_row('episode', row)

    def append_member(self, row: Mapping[str, Any]) -> None:
        """Append a per-member row (generation, member, fitness breakdown, ...)."""
        self.append_row('member', row)

    def append_generation(self, row: Mapping[str, Any]) -> None:
        """Append a per-generation summary row (``fitness.generation_summary``)."""
        self.append_row('generation', row)

    def read_rows(self, kind: str | None = None) -> list[dict[str, Any]]:
        """Rows of metrics.jsonl in file order, optionally only one kind (the 'kind' key is
        kept). A torn last line (a write killed half-way) is skipped."""
        if kind is not None:
            _check_kind(kind)
        rows = _read_jsonl(self.metrics_jsonl_path)
        return [row for row in rows if kind is None or row.get('kind') == kind]

    def truncate_metrics(self, from_generation: int) -> int:
        """Delete every metrics row of generation >= ``from_generation`` (and a torn last
        line), rewriting metrics.jsonl atomically and rebuilding the CSV files from it.
        Returns the number of rows removed."""
        rows = _read_jsonl(self.metrics_jsonl_path)
        kept = [row for row in rows if int(row['generation']) < from_generation]
        text = ''.join(json.dumps(row, allow_nan=False) + '\n' for row in kept)
        if self.metrics_jsonl_path.exists() or kept:
            atomic_write_bytes(self.metrics_jsonl_path, text.encode())
        for kind in ROW_KINDS:
            csv_path = self.metrics_csv_path(kind)
            kind_rows = [row for row in kept if row.get('kind') == kind]
            if kind_rows:
                buffer = io.StringIO()
                _write_csv(buffer, None, kind_rows)
                atomic_write_bytes(csv_path, buffer.getvalue().encode())
            elif csv_path.exists():
                csv_path.unlink()
        return len(rows) - len(kept)

    # -- resume ---------------------------------------------------------------------------

    def resume(self, generation: int | None = None) -> ResumePoint | None:
        """Prepare to continue a killed campaign; None when it has no checkpoint yet.

        Loads the latest checkpoint (or the one of ``generation``), deletes metrics rows of
        that generation and later, checkpoints of later generations, and stray temporary
        files. The caller restores the algorithm from ``checkpoint['algorithm']`` and
        evaluates ``generation`` next.

        A latest checkpoint that cannot be read (truncated or corrupted on disk) is renamed
        to ``*.pt.corrupt`` and the run goes back to the newest readable one; evaluating from
        there gives the same results, as every generation does (see ``set_aside``). When no
        checkpoint is readable, RunStoreError says how to start over; nothing is changed.
        """
        self.remove_stray_temporary_files()
        set_aside: list[str] = []
        if generation is None:
            found = self.checkpoints()
            if not found:
                return None
            errors = []
            for info in reversed(found):
                try:
                    payload = self.load_checkpoint(info.path)
                    break
                except RunStoreError as err:
                    errors.append(str(err))
            else:
                raise RunStoreError(
                    f'run {self.run_name!r} cannot be resumed: none of its {len(found)} '
                    f'checkpoints is readable (latest: {errors[0]}). Start it over: remove '
                    f'{self.run_dir} (and its failure bags), or run with another --run name')
            for newer, error in zip(reversed(found), errors, strict=False):
                corrupt = newer.path.with_name(newer.path.name + '.corrupt')
                os.replace(newer.path, corrupt)
                set_aside.append(f'{error}; renamed to {corrupt.name}')
        else:
            info = CheckpointInfo(generation, self.checkpoint_path(generation))
            if not info.path.is_file():
                raise RunStoreError(f'run {self.run_name!r} has no checkpoint of generation '
                                    f'{generation}')
            payload = self.load_checkpoint(info.path)
        for later in self.checkpoints():
            if later.generation > info.generation:
                later.path.unlink()
        self.truncate_metrics(info.generation)
        return ResumePoint(info.generation, payload, info.path, tuple(set_aside))

    def delete(self) -> None:
        """Remove the whole run directory (for a fresh start under the same name)."""
        shutil.rmtree(self.run_dir, ignore_errors=True)


# -- file helpers ---------------------------------------------------------------------------


def _append_text(path: Path, text: str) -> None:
    # flush, no fsync: the page cache survives a killed process; save_checkpoint fsyncs the
    # metrics files before a checkpoint claims their rows, which covers a power loss.
    with path.open('a', encoding='utf-8') as handle:
        handle.write(text)
        handle.flush()


def _fsync_file(path: Path) -> None:
    if path.exists():
        with path.open('rb') as handle:
            os.fsync(handle.fileno())


def _read_jsonl(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    lines = path.read_text(encoding='utf-8').split('\n')
    rows = []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError as err:
            is_torn_tail = number == len(lines)  # a killed append: no newline after it
            if is_torn_tail:
                break
            raise RunStoreError(f'{path}:{number} is not valid JSON: {err}') from err
        if not isinstance(row, dict) or 'generation' not in row:
            raise RunStoreError(f'{path}:{number} is not a metrics row')
        rows.append(row)
    return rows


def _read_csv_header(path: Path) -> list[str] | None:
    if not path.exists():
        return None
    with path.open(newline='', encoding='utf-8') as handle:
        header = next(csv.reader(handle), None)
    return header or None


def _append_csv_rows(path: Path, header: list[str] | None,
                     rows: Iterable[Mapping[str, Any]]) -> None:
    with path.open('a', newline='', encoding='utf-8') as handle:
        _write_csv(handle, header, list(rows))
        handle.flush()


def _write_csv(handle: Any, header: list[str] | None,
               rows: Sequence[Mapping[str, Any]]) -> None:
    """Write ``rows`` (without their 'kind'); a header is written when ``header`` is None,
    made of the first row's keys."""
    columns = header
    if columns is None:
        columns = [key for key in rows[0] if key != 'kind']
    writer = csv.DictWriter(handle, fieldnames=columns, extrasaction='ignore',
                            lineterminator='\n')
    if header is None:
        writer.writeheader()
    for row in rows:
        writer.writerow({key: _csv_value(row.get(key)) for key in columns})


def _csv_value(value: Any) -> Any:
    if value is None:
        return ''
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return value


def _plain(value: Any) -> Any:
    """JSON-ready plain data (see sessgan_core.json_data)."""
    try:
        return to_json_data(value)
    except TypeError as err:
        raise RunStoreError(f'cannot store it in metrics or config: {err}') from err


def _differences(old: Any, new: Any, prefix: str = '') -> list[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        found = []
        for key in sorted(set(old) | set(new)):
            found += _differences(old.get(key), new.get(key), f'{prefix}{key}.')
        return found
    return [] if old == new else [f'{prefix.rstrip(".")}: {old!r} -> {new!r}']


def _check_kind(kind: str) -> None:
    if kind not in ROW_KINDS:
        raise RunStoreError(f'unknown metrics row kind {kind!r}; expected one of {ROW_KINDS}')
