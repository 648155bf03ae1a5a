"""Failure bags of workers on other hosts, collected into the campaign's own ``bags/<run>/``.

A worker writes a failure bag under its own bags_root, on its own machine; a campaign with
``--external`` copies it here (:func:`collect_bag`) so that every failure of a run is in one
place, whatever host found it. The copy is byte-identical and checked before it appears: the
listing must name episode.json and exactly the files episode.json records (``files``: size
and SHA-256, written by sessgan_sim.bag_recording), every file must arrive with its recorded
size and digest, and the files go to a hidden staging directory that is renamed to
``<bags dir>/<episode>`` only when all of them are verified, so no half-copied bag appears.
The worker's copy is removed afterwards only when asked (``remove``).

The transport is a :class:`BagSource` (sessgan_evolver.remote_bags serves one over ROS).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Protocol

from sessgan_core.atomic_files import fsync_directory, fsync_tree
from sessgan_core.environment import check_environment_id
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_evolver.errors import BagCollectionError
from sessgan_sim.bag_recording import EPISODE_FILE, is_episode_bag

CHUNK_BYTES = 1 << 20
"""Bytes asked for per read (the worker serves at most sessgan_sim.bag_serving.MAX_CHUNK)."""
STAGING_MARK = '.collecting-'
"""A bag being copied is in ``.<episode>.collecting-<random>`` beside where it goes."""
MAX_EPISODE_FILE_BYTES = 16 << 20
"""An episode.json larger than this is refused before it is read (it is a few kB)."""


class BagSource(Protocol):
    """Where a bag is read from: ``bag`` is ``<record_directory>/<environment id>``."""

    def list_files(self, bag: str) -> dict[str, int]:
        """``{file name: size in bytes}``."""

    def read(self, bag: str, name: str, offset: int, length: int) -> bytes:
        """Up to ``length`` bytes of file ``name`` from ``offset``."""

    def remove(self, bag: str) -> None:
        """Remove the source's copy."""


def collect_bag(source: BagSource, bag: str, bags_dir: Path, remove: bool = False,
                chunk_bytes: int = CHUNK_BYTES) -> Path:
    """Copy ``bag`` from ``source`` to ``bags_dir/<episode>`` (module docstring) and return
    that path; BagCollectionError naming what did not match (nothing is left here then)."""
    episode = bag.rpartition('/')[2]
    try:
        check_environment_id(episode)
    except InvalidEnvironmentError as err:
        raise BagCollectionError(f'refusing to collect bag {bag!r}: {err}') from err
    listing = source.list_files(bag)
    for name in listing:
        if Path(name).name != name or name.startswith('.') or name in ('', '..'):
            raise BagCollectionError(f'bag {bag!r}: the worker lists an unsafe file name '
                                     f'{name!r}')
    if EPISODE_FILE not in listing:
        raise BagCollectionError(f'bag {bag!r} has no {EPISODE_FILE}: not a failure bag')
    if listing[EPISODE_FILE] > MAX_EPISODE_FILE_BYTES:
        raise BagCollectionError(f'bag {bag!r}: its {EPISODE_FILE} has '
                                 f'{listing[EPISODE_FILE]} bytes, more than any episode.json')
    bags_dir = Path(bags_dir)
    bags_dir.mkdir(parents=True, exist_ok=True)
    final = bags_dir / episode
    if final.exists() and not is_episode_bag(final):
        raise BagCollectionError(f'refusing to replace {final}: it is not a failure bag')
    for stale in bags_dir.glob(f'.{episode}{STAGING_MARK}*'):  # of a campaign killed here
        shutil.rmtree(stale, ignore_errors=True)
    staging = Path(tempfile.mkdtemp(dir=bags_dir, prefix=f'.{episode}{STAGING_MARK}'))
    try:
        episode_bytes = _copy(source, bag, EPISODE_FILE, listing[EPISODE_FILE], None,
                              staging, chunk_bytes)
        recorded = _recorded_files(bag, episode_bytes)
        expected = set(recorded) | {EPISODE_FILE}
        if set(listing) != expected:
            raise BagCollectionError(
                f'bag {bag!r}: the worker lists {sorted(listing)}, its {EPISODE_FILE} records '
                f'{sorted(expected)}')
        for name, facts in sorted(recorded.items()):
            if listing[name] != facts['size']:
                raise BagCollectionError(
                    f'bag {bag!r}: the worker has {listing[name]} bytes of {name}, '
                    f'{EPISODE_FILE} recorded {facts["size"]}')
            _copy(source, bag, name, facts['size'], facts['sha256'], staging, chunk_bytes)
        fsync_tree(staging)
        if final.exists():  # an earlier copy of this episode (a collection cut short)
            shutil.rmtree(final)
        os.replace(staging, final)
        fsync_directory(bags_dir)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if remove:
        source.remove(bag)
    return final


def _recorded_files(bag: str, episode_bytes: bytes) -> dict[str, dict]:
    try:
        files = json.loads(episode_bytes).get('files')
    except (ValueError, AttributeError) as err:
        raise BagCollectionError(f'bag {bag!r}: its {EPISODE_FILE} is not a JSON object: '
                                 f'{err}') from err
    if not isinstance(files, dict) or not files:
        raise BagCollectionError(f'bag {bag!r}: its {EPISODE_FILE} records no file sizes and '
                                 'digests ("files"), so a copy could not be checked')
    for name, facts in files.items():
        if (not isinstance(facts, dict) or not isinstance(facts.get('size'), int)
                or not isinstance(facts.get('sha256'), str)):
            raise BagCollectionError(f'bag {bag!r}: {EPISODE_FILE} has a malformed "files" '
                                     f'entry {name!r}')
    return files


def _copy(source: BagSource, bag: str, name: str, size: int, sha256: str | None,
          staging: Path, chunk_bytes: int) -> bytes:
    """Read ``name`` whole into ``staging``; check its size and (if given) digest. Returns
    the bytes of episode.json (``sha256`` None), else b''."""
    digest = hashlib.sha256()
    kept = bytearray()
    offset = 0
    with open(staging / name, 'wb') as handle:
        while offset < size:
            asked = min(chunk_bytes, size - offset)
            data = source.read(bag, name, offset, asked)
            if len(data) > asked:
                raise BagCollectionError(f'bag {bag!r}: asked for {asked} bytes of {name}, the '
                                         f'worker sent {len(data)}')
            if not data:
                raise BagCollectionError(f'bag {bag!r}: {name} ended after {offset} bytes, the '
                                         f'worker listed {size}')
            handle.write(data)
            digest.update(data)
            if sha256 is None:
                kept += data
            offset += len(data)
    if offset != size:
        raise BagCollectionError(f'bag {bag!r}: received {offset} bytes of {name}, expected '
                                 f'{size}')
    if sha256 is not None and digest.hexdigest() != sha256:
        raise BagCollectionError(f'bag {bag!r}: the SHA-256 digest of the copy of {name} is '
                                 f'{digest.hexdigest()}, {EPISODE_FILE} recorded {sha256}')
    return bytes(kept)
