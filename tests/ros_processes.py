"""Start real ROS nodes as separate processes and always stop them, also when a test fails.

Fixtures:
* ``ros_workspace``: checks that the workspace is built and sourced (``ros2`` on PATH and
  ``sessgan_interfaces`` importable); skips graph tests outside it, except under CI where a
  missing workspace is an error.
* ``node_processes``: a :class:`NodeProcesses` whose ``start(...)`` runs a command (usually
  ``ros2 run <pkg> <exe> ...``) in its own process group with its output in a log file; at
  teardown every process group gets SIGINT, then SIGKILL after a grace period, and the logs of
  a failed test are printed.
* ``ros_node``: an rclpy node in this test process (its own context), destroyed afterwards.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from sessgan_evolver.process_supervisor import die_with_parent, restore_sigint

REPO_ROOT = Path(__file__).resolve().parents[1]


@dataclass
class NodeProcess:
    name: str
    command: list[str]
    process: subprocess.Popen
    log_path: Path

    def output(self) -> str:
        return self.log_path.read_text(errors='replace') if self.log_path.exists() else ''

    def wait_for_output(self, pattern: str, timeout: float = 20.0) -> re.Match:
        """Wait until the process log matches ``pattern``; fail with the log otherwise."""
        deadline = time.monotonic() + timeout
        regex = re.compile(pattern)
        while time.monotonic() < deadline:
            match = regex.search(self.output())
            if match:
                return match
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(
            f'{self.name}: no output matching {pattern!r} within {timeout} s '
            f'(exit code {self.process.poll()}); log:\n{self.output()[-4000:]}')

    def wait(self, timeout: float) -> int:
        return self.process.wait(timeout=timeout)


class NodeProcesses:
    """Processes started by one test; stopped in reverse order at teardown."""

    def __init__(self, log_dir: Path, env: dict[str, str]) -> None:
        self.log_dir = log_dir
        self.env = env
        self.processes: list[NodeProcess] = []

    def start(self, command: list[str], name: str | None = None,
              env: dict[str, str] | None = None, cwd: Path | None = None) -> NodeProcess:
        name = name or command[min(2, len(command) - 1)]
        safe_name = re.sub(r'[^A-Za-z0-9_.-]', '_', name)
        log_path = self.log_dir / f'{len(self.processes):02d}-{safe_name}.log'
        log_file = open(log_path, 'wb')
        try:
            process = subprocess.Popen(
                command, stdout=log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                env={**self.env, **(env or {})}, cwd=cwd or REPO_ROOT, start_new_session=True,
                preexec_fn=prepare_child)
        finally:
            log_file.close()
        node_process = NodeProcess(name, command, process, log_path)
        self.processes.append(node_process)
        return node_process

    def stop_all(self, grace: float = 5.0) -> None:
        for node_process in reversed(self.processes):
            _signal_group(node_process.process, signal.SIGINT)
        deadline = time.monotonic() + grace
        for node_process in reversed(self.processes):
            try:
                node_process.process.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                _signal_group(node_process.process, signal.SIGKILL)
                node_process.process.wait(timeout=5)


def prepare_child() -> None:
    """As the campaign's supervisor prepares its children: stopped with their parent, and
    stopped by SIGINT even when this test run was started in the background."""
    die_with_parent()
    restore_sigint()


def _signal_group(process: subprocess.Popen, sig: int) -> None:
    # Signal the whole group even if the leader exited: its children may not have.
    try:
        os.killpg(process.pid, sig)
    except ProcessLookupError:
        pass


def workspace_ready() -> tuple[bool, str]:
    if shutil.which('ros2') is None:
        return False, "'ros2' is not on PATH: run ./sessgan test, or source setup.bash"
    try:
        import sessgan_interfaces.msg  # noqa: F401
    except ImportError as err:
        return False, f'sessgan_interfaces is not importable ({err}): source setup.bash'
    return True, ''


@pytest.fixture(scope='session')
def ros_workspace() -> None:
    ready, reason = workspace_ready()
    if not ready:
        if os.environ.get('CI'):
            pytest.fail(f'graph tests need the built workspace under CI: {reason}')
        pytest.skip(reason)


@pytest.fixture
def node_processes(request, tmp_path, ros_workspace):
    manager = NodeProcesses(tmp_path, dict(os.environ))
    yield manager
    manager.stop_all()
    report = getattr(request.node, 'rep_call', None)
    if report is not None and report.failed:
        for node_process in manager.processes:
            print(f'\n----- log of {node_process.name}: {" ".join(node_process.command)}')
            print(node_process.output()[-6000:])


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item, call):
    report = yield
    setattr(item, f'rep_{report.when}', report)
    return report


@pytest.fixture
def ros_node(ros_workspace):
    """An rclpy node in the test process, with its own context."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(f'test_probe_{os.getpid()}', context=context)
    try:
        yield node
    finally:
        # destroy_node leaves action clients and servers up (each keeps the node, so the
        # DDS participant, alive until garbage collection): a later test would see them.
        for waitable in list(node.waitables):
            if hasattr(waitable, 'destroy'):
                waitable.destroy()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def spin_until(node, predicate, timeout: float) -> bool:
    """Spin ``node`` until ``predicate()`` is true or ``timeout`` seconds pass."""
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            executor.spin_once(timeout_sec=0.05)
        return predicate()
    finally:
        executor.remove_node(node)
        executor.shutdown()
