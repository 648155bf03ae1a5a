"""Start the processes of a campaign (generator, simulator workers, controllers) and stop them.

Each child runs in its own process group with its output in a log file, so a campaign can stop
everything it started (and their children) on exit, on Ctrl-C and on SIGTERM, and a user can read
why a worker died.

A simulator worker and its lockstep controller take turns on the CPU: they run fastest on one
core together (a wake-up across cores can cost as much as the messages themselves: it doubled a
bare rclpy lockstep tick on the machines measured) and as batch processes (a woken process then
does not preempt the one that woke it until that one waits: the simulator publishes a whole
tick before the controller reads it). ``worker_cores`` spreads worker pairs over the cores this
process may use.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass
class ChildProcess:
    name: str
    command: list[str]
    process: subprocess.Popen
    log_path: Path

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def log_tail(self, characters: int = 2000) -> str:
        try:
            return self.log_path.read_text(errors='replace')[-characters:]
        except OSError:
            return ''


class ProcessSupervisor:
    """Owns child processes; ``stop_all`` (also run by ``with``) ends every one of them."""

    def __init__(self, log_directory: Path, env: dict[str, str] | None = None) -> None:
        self.log_directory = Path(log_directory)
        self.log_directory.mkdir(parents=True, exist_ok=True)
        self.env = dict(os.environ if env is None else env)
        self.children: list[ChildProcess] = []

    def start(self, name: str, command: list[str], core: int | None = None,
              batch: bool = False) -> ChildProcess:
        """Start ``command``; ``core``: pin it (and its threads) to that CPU; ``batch``: run it
        with the SCHED_BATCH policy (both inherited across exec)."""
        log_path = self.log_directory / f'{name}.log'

        def prepare_child() -> None:
            die_with_parent()
            if core is not None and hasattr(os, 'sched_setaffinity'):
                os.sched_setaffinity(0, {core})
            if batch and hasattr(os, 'SCHED_BATCH'):
                os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))

        with open(log_path, 'ab') as log_file:
            process = subprocess.Popen(
                command, stdout=log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env=self.env, start_new_session=True, preexec_fn=prepare_child)
        child = ChildProcess(name, command, process, log_path)
        self.children.append(child)
        return child

    def dead_children(self) -> list[ChildProcess]:
        return [child for child in self.children if not child.alive]

    def stop_all(self, grace_seconds: float = 5.0) -> None:
        """SIGINT to every process group, then SIGKILL to those still alive after the grace."""
        for child in reversed(self.children):
            _signal_group(child.process.pid, signal.SIGINT)
        deadline = time.monotonic() + grace_seconds
        for child in reversed(self.children):
            try:
                child.process.wait(timeout=max(0.05, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
            # The leader may be gone while its children live on: kill the group regardless.
            _signal_group(child.process.pid, signal.SIGKILL)
            try:
                child.process.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                pass
        self.children.clear()

    def __enter__(self) -> ProcessSupervisor:
        return self

    def __exit__(self, *exc_info) -> None:
        self.stop_all()


def worker_cores(workers: int) -> list[int | None]:
    """The core for each of ``workers`` simulator/controller pairs: round robin over the cores
    this process may use; None (no pinning) where that set cannot be read."""
    try:
        cores = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return [None] * workers
    return [cores[index % len(cores)] for index in range(workers)]


def die_with_parent() -> None:
    """In a child (preexec): get SIGTERM when the parent dies, even by SIGKILL (Linux).

    Without it a killed campaign would leave its workers running, and a resumed campaign
    would find two action servers under the same namespace.
    """
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux: Ctrl-C and normal exits still stop every child


def _signal_group(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass
