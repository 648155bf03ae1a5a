"""Files that are either complete or absent: what every writer of this project uses.

A killed process, a full disk or a power loss must never leave half a checkpoint, map or
metrics file behind, so data goes to a temporary file in the target's directory, is fsynced,
and is renamed over the target (``os.replace`` is atomic within a file system).
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO

TEMPORARY_MARK = '.tmp-'
"""Temporary files are named ``.<target name>.tmp-<random>`` (hidden, recognisable)."""


def atomic_write_bytes(path: str | os.PathLike, data: bytes, mode: int = 0o644) -> None:
    """Write ``data`` to ``path``: readers see the old file or the new one, never a part."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(dir=target.parent,
                                             prefix=f'.{target.name}{TEMPORARY_MARK}')
    try:
        with os.fdopen(descriptor, 'wb') as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(temporary, mode)  # mkstemp creates 0600; these are shared files
        os.replace(temporary, target)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    fsync_directory(target.parent)


def fsync_directory(directory: str | os.PathLike) -> None:
    """fsync a directory so a rename inside it survives a power loss (no-op where the OS
    cannot open directories)."""
    try:
        descriptor = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass
    finally:
        os.close(descriptor)


def fsync_tree(directory: str | os.PathLike) -> None:
    """fsync every file below ``directory`` and the directory itself (before renaming it)."""
    for path in Path(directory).rglob('*'):
        if path.is_file():
            with path.open('rb') as handle:
                os.fsync(handle.fileno())
    fsync_directory(directory)


def lock_folder(folder: str | os.PathLike, name: str = '.lock') -> IO[str] | None:
    """Hold ``folder`` (made if missing) for this process: its open lock file ``name``,
    whose closing (or the process's end) lets go; None when another process holds it. Two
    writers of one run or report folder would mix their files."""
    path = Path(folder)
    path.mkdir(parents=True, exist_ok=True)
    handle = open(path / name, 'a')  # noqa: SIM115 (held until the caller closes it)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        return None
    return handle
