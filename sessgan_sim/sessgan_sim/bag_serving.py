"""A simulator's failure bags, read for a campaign on another host (the ``bags`` service).

A worker writes failure bags under its own ``bags_root``; a campaign elsewhere collects them
(sessgan_evolver.bag_collection) by listing a bag's files, reading each in chunks and, once it
holds a verified copy, asking for the worker's copy to be removed. :class:`BagServer` answers
those requests (it is a sessgan_evolver.bag_collection.BagSource itself) for finished bags
under the root only (``is_episode_bag``: a staging directory or any other folder is refused),
naming only the bag's own plain files.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from sessgan_core.environment import check_environment_id
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_sim.bag_recording import is_episode_bag, record_directory_under
from sessgan_sim.errors import BagServeError, BagWriteError

MAX_CHUNK = 1 << 20
"""Bytes one read may ask for: 1 MiB (Fast DDS fragments larger samples; a few chunks are
cheaper than one huge sample on a congested link)."""


class BagServer:
    """Lists, reads and removes finished failure bags under ``bags_root``."""

    def __init__(self, bags_root: str | Path) -> None:
        self.bags_root = Path(bags_root).resolve()

    def directory(self, bag: str) -> Path:
        """The directory of ``bag`` (``<record_directory>/<environment id>``), else
        BagServeError saying why (unsafe name, out of the root, not a finished bag)."""
        record_directory, _, episode = str(bag).rpartition('/')
        try:
            check_environment_id(episode)
            directory = record_directory_under(self.bags_root, record_directory) / episode
        except (BagWriteError, InvalidEnvironmentError) as err:
            raise BagServeError(f'refusing bag {bag!r}: {err}') from err
        if not is_episode_bag(directory):
            raise BagServeError(f'no finished failure bag {bag!r} under {self.bags_root}')
        return directory

    def list_files(self, bag: str) -> dict[str, int]:
        """``{file name: size in bytes}`` of the bag's files."""
        directory = self.directory(bag)
        return {path.name: path.stat().st_size for path in sorted(directory.iterdir())}

    def read(self, bag: str, name: str, offset: int, length: int) -> bytes:
        """Up to ``length`` bytes of the bag's file ``name`` from ``offset`` (fewer only at
        its end)."""
        if not 0 < length <= MAX_CHUNK:
            raise BagServeError(f'a read must ask for 1 to {MAX_CHUNK} bytes, got {length}')
        if offset < 0:
            raise BagServeError(f'a read must start at an offset >= 0, got {offset}')
        directory = self.directory(bag)
        if name not in {path.name for path in directory.iterdir()}:
            raise BagServeError(f'bag {bag!r} has no file {name!r}')
        with open(directory / name, 'rb') as handle:
            handle.seek(offset)
            return handle.read(length)

    def remove(self, bag: str) -> None:
        """Delete the bag (its collector holds a verified copy)."""
        shutil.rmtree(self.directory(bag))
