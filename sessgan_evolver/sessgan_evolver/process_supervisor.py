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

A :class:`WorkerPool` watches simulator + controller pairs: the campaign asks it every loop
which pairs have a dead process (a poll of its own children, so a death is seen at once, not
after an episode timeout), restarts such a pair as a whole, and quarantines a pair that keeps
dying.
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
    core: int | None = None
    batch: bool = False
    log_offset: int = 0
    """Size of the log file when this process started: its own output begins there (a
    restarted process appends to its predecessor's log)."""

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def exit_description(self) -> str:
        """'is running', 'exited with status 1' or 'was killed by SIGKILL'."""
        code = self.process.poll()
        if code is None:
            return 'is running'
        if code < 0:
            try:
                return f'was killed by {signal.Signals(-code).name}'
            except ValueError:
                return f'was killed by signal {-code}'
        return f'exited with status {code}'

    def output(self) -> str:
        """What this process wrote to its log so far."""
        try:
            with open(self.log_path, 'rb') as log_file:
                log_file.seek(self.log_offset)
                return log_file.read().decode(errors='replace')
        except OSError:
            return ''

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
        log_offset = log_path.stat().st_size if log_path.exists() else 0

        def prepare_child() -> None:
            die_with_parent()
            restore_sigint()
            if core is not None and hasattr(os, 'sched_setaffinity'):
                os.sched_setaffinity(0, {core})
            if batch and hasattr(os, 'SCHED_BATCH'):
                os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))

        with open(log_path, 'ab') as log_file:
            process = subprocess.Popen(
                command, stdout=log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env=self.env, start_new_session=True, preexec_fn=prepare_child)
        child = ChildProcess(name, command, process, log_path, core, batch, log_offset)
        self.children.append(child)
        return child

    def dead_children(self) -> list[ChildProcess]:
        return [child for child in self.children if not child.alive]

    def stop(self, children: list[ChildProcess], grace_seconds: float = 5.0) -> None:
        """SIGINT to each child's process group, then SIGKILL to the groups after the grace;
        the children are forgotten."""
        for child in reversed(children):
            _signal_group(child.process.pid, signal.SIGINT)
        deadline = time.monotonic() + grace_seconds
        for child in reversed(children):
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
        stopped = {id(child) for child in children}
        self.children = [child for child in self.children if id(child) not in stopped]

    def restart(self, child: ChildProcess, grace_seconds: float = 2.0) -> ChildProcess:
        """Stop ``child`` if it still runs and start its command again (same core, same
        scheduling, output appended to the same log); returns the new child."""
        self.stop([child], grace_seconds)
        return self.start(child.name, child.command, child.core, child.batch)

    def stop_all(self, grace_seconds: float = 5.0) -> None:
        """SIGINT to every process group, then SIGKILL to those still alive after the grace."""
        self.stop(list(self.children), grace_seconds)

    def __enter__(self) -> ProcessSupervisor:
        return self

    def __exit__(self, *exc_info) -> None:
        self.stop_all()


@dataclass
class WorkerPair:
    """A simulator worker and the controller under test beside it, in one namespace (a
    fleet's: a controller per robot, in the robots' namespaces under it)."""

    namespace: str
    simulator: ChildProcess
    controllers: list[ChildProcess]
    restarts: int = 0
    """How often the pair was restarted after one of its processes died."""

    @property
    def controller(self) -> ChildProcess:
        """The (first robot's) controller."""
        return self.controllers[0]

    @property
    def children(self) -> list[ChildProcess]:
        return [self.simulator, *self.controllers]

    @property
    def alive(self) -> bool:
        return all(child.alive for child in self.children)

    def death_report(self) -> str:
        """Which of the pair's processes died and how, e.g. 'nearness_diagram_w0 (pid 42) was
        killed by SIGKILL'; empty while all live."""
        return '; '.join(f'{child.name} (pid {child.process.pid}) {child.exit_description()}'
                         for child in self.children if not child.alive)

    def logged_since_start(self, text: str) -> bool:
        """True once the pair's current simulator process has logged ``text``."""
        return text in self.simulator.output()


class WorkerPool:
    """The simulator + controller pairs a campaign started: death checks, restarts, quarantine.

    ``dead_pairs`` polls every pair's processes (cheap: a waitpid each), so the campaign sees a
    death in its next loop, whatever the pair was doing. ``restart`` starts a dead pair's
    processes again, both of them (a fresh controller for a fresh simulator, so no state of the
    old episode survives); a pair that has died ``max_restarts`` times already is stopped and
    dropped instead (quarantined for the rest of the campaign).
    """

    def __init__(self, supervisor: ProcessSupervisor, max_restarts: int = 3) -> None:
        self.supervisor = supervisor
        self.max_restarts = max_restarts
        self.pairs: dict[str, WorkerPair] = {}
        """Live pairs by namespace ('/w0')."""
        self.quarantined: dict[str, WorkerPair] = {}

    def start_pair(self, namespace: str, simulator: tuple[str, list[str]],
                   *controllers: tuple[str, list[str]], core: int | None = None,
                   batch: bool = False) -> WorkerPair:
        """Start a pair; ``simulator`` and each of ``controllers`` (one, or a fleet's one
        per robot) are (log name, command)."""
        pair = WorkerPair(namespace, self.supervisor.start(*simulator, core=core, batch=batch),
                          [self.supervisor.start(*controller, core=core, batch=batch)
                           for controller in controllers])
        self.pairs[namespace] = pair
        return pair

    def dead_pairs(self) -> list[WorkerPair]:
        """The pairs with a process that is no longer running."""
        return [pair for pair in self.pairs.values() if not pair.alive]

    def restart(self, pair: WorkerPair) -> bool:
        """Restart both processes of ``pair``; False (and the pair stopped and quarantined) if
        it was restarted ``max_restarts`` times already."""
        if pair.restarts >= self.max_restarts:
            self.supervisor.stop(pair.children, grace_seconds=2.0)
            self.quarantined[pair.namespace] = self.pairs.pop(pair.namespace)
            return False
        # The survivor goes first, so the new simulator never meets the old controller.
        self.supervisor.stop(pair.children, grace_seconds=2.0)
        pair.simulator, *pair.controllers = (
            self.supervisor.start(child.name, child.command, child.core, child.batch)
            for child in pair.children)
        pair.restarts += 1
        return True


def controller_placements(namespace: str, robots: int) -> list[tuple[str, list[str]]]:
    """Where each robot's controller runs beside a simulator in ``namespace``, and the ROS
    arguments that put it there: the simulator's namespace for one robot; for a fleet, r0,
    r1, ... under it, each on the clock the simulator publishes there and with its TwistStamped
    commands in frame r<i>/base_footprint."""
    if robots <= 1:
        return [(namespace, ['-r', f'__ns:={namespace}'])]
    placements = []
    for index in range(robots):
        robot_namespace = f'{namespace.rstrip("/")}/r{index}'
        placements.append((robot_namespace, [
            '-r', f'__ns:={robot_namespace}', '-r', f'/clock:={robot_namespace}/clock',
            '-p', f'base_frame_id:=r{index}/base_footprint']))
    return placements


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


def restore_sigint() -> None:
    """In a child (preexec): SIGINT at its default disposition, since a stop asks with SIGINT.

    A parent started in the background by a non-interactive shell (`cmd &`, some CI runners)
    has SIGINT ignored and hands that on: a child signalled before it installs a handler of its
    own (rclpy's, at init; a plain Python never does then) sat out the whole grace until
    SIGKILL.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _signal_group(pid: int, sig: int) -> None:
    try:
        os.killpg(pid, sig)
    except (ProcessLookupError, PermissionError):
        pass
