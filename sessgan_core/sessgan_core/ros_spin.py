"""Run a node until SIGINT or SIGTERM, then exit at once and cleanly (no traceback).

rclpy's own signal handling raises KeyboardInterrupt wherever the main thread happens to be
and shuts the context down under callbacks that are still running, so an idle node sometimes
stayed in ``rcl_wait`` after the first Ctrl-C and a running one printed RCLError tracebacks
from goal handles and publishers of the shut-down context. Here the executor spins in a thread
of its own; the main thread only waits for a signal, asks the node to stop its work (while
ROS still runs, so a running action goal is still answered), shuts the context down (which
wakes the executor and every wait that watches the context), gives running callbacks a few
seconds to return and tears the node down. :func:`exit_process` then ends the process without
the interpreter's finalization: with the executor in a thread of its own, finalizing torch's
and DDS's native threads took about a second and, in 1 of 8 generator exits measured, aborted
with "terminate called without an active exception". rclpy is imported when a node is run, so
this module imports without ROS.

Commands (campaign, evaluate, replay, ...) stop the other way, through
:func:`run_command`: SIGINT and SIGTERM raise KeyboardInterrupt in the main thread, the
command cleans up where it stands and exits 130, and a command that uses rclpy starts it with
:func:`init_rclpy`, without rclpy's own handlers (which shut the context down under a
spinning command, so it ended with an ExternalShutdownException traceback and exit 1). Such a
command spins through :func:`spin_interruptibly`: a KeyboardInterrupt raised while rclpy's
native code was calling back into Python reaches the spin as another error (pybind11 reports
it as "Unable to convert function return value to a Python type"), so the command would skip
its clean-up and exit 1.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

POLL_PERIOD = 0.1
"""Seconds between the main thread's checks (a signal handler runs within one sleep)."""


class StopRequest:
    """Set by SIGINT or SIGTERM; the handlers only record the signal (safe at any moment)."""

    def __init__(self) -> None:
        self.signal: int | None = None
        self._previous: dict[int, Any] = {}

    def install(self) -> None:
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)

    def restore(self) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()

    def _handle(self, signum, frame) -> None:
        if self.signal is not None:  # a second signal: the user insists
            os._exit(128 + signum)
        self.signal = signum

    @property
    def requested(self) -> bool:
        return self.signal is not None


INTERRUPTED_STATUS = 130
"""A command's exit status after SIGINT or SIGTERM (128 + SIGINT, as shells report Ctrl-C)."""


class _InterruptOnSignals(StopRequest):
    """SIGINT or SIGTERM raise KeyboardInterrupt in the main thread; a second one ends the
    process at once."""

    def _handle(self, signum, frame) -> None:
        super()._handle(signum, frame)
        raise KeyboardInterrupt


_command_request: StopRequest | None = None
"""The signal record of the running :func:`run_command` (signals are the process's)."""


def run_command(body: Callable[[], int], interrupted: str = 'interrupted',
                stream: Any = None) -> int:
    """Run a command's ``body`` and return its exit status; on SIGINT or SIGTERM print
    ``interrupted`` to ``stream`` (stderr) and return INTERRUPTED_STATUS, without a traceback.
    ``body`` may catch KeyboardInterrupt itself to clean up or say more (a --resume hint).
    argparse's exit (--help: 0, a usage error: 2) is returned as the status too, so a caller of
    ``main`` gets every outcome as its return value."""
    global _command_request
    request = _InterruptOnSignals()
    request.install()
    _command_request = request
    try:
        return body()
    except SystemExit as stop:
        if stop.code is None or isinstance(stop.code, int):
            return stop.code or 0
        raise
    except KeyboardInterrupt:
        print(interrupted, file=stream or sys.stderr, flush=True)
        return INTERRUPTED_STATUS
    finally:
        _command_request = None
        request.restore()


def spin_interruptibly(spin: Callable[[], Any]) -> Any:
    """Return ``spin()`` (an rclpy spin call of a command under :func:`run_command`); an error
    it raises after SIGINT or SIGTERM arrived is the signal's KeyboardInterrupt, mangled by the
    native code it was raised under, and is raised as KeyboardInterrupt."""
    try:
        return spin()
    except Exception as error:
        if _command_request is not None and _command_request.requested:
            raise KeyboardInterrupt from error
        raise


def init_rclpy(args: list[str] | None = None) -> None:
    """rclpy.init without rclpy's signal handlers: a command under :func:`run_command` gets
    SIGINT and SIGTERM as KeyboardInterrupt, with its context still up for the clean-up."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)


def run_node(make_node: Callable[[], Any], make_executor: Callable[[Any], Any] | None = None,
             args: list[str] | None = None, stop: Callable[[Any, float], None] | None = None,
             before_destroy: Callable[[Any], None] | None = None, grace: float = 5.0) -> int:
    """Create the node with ``make_node()`` and spin it until a signal or shutdown.

    ``make_executor(context)`` builds the executor (default: single-threaded).
    ``stop(node, grace)`` runs first after a signal, with ROS still up: end running work
    within ``grace`` seconds. ``before_destroy(node)`` runs after the executor stopped and
    before the node is destroyed (close resources the callbacks used). Exceptions of
    ``make_node`` propagate after rclpy is shut down. Returns the exit status: 0 after a
    signal or shutdown, 1 when the executor failed or callbacks did not return in time.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    request = StopRequest()
    request.install()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    context = rclpy.get_default_context()
    node: Any = None
    executor: Any = None
    failure: list[BaseException] = []

    def spin() -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass
        except BaseException as err:  # reported by the main thread
            if context.ok():
                failure.append(err)

    status = 0
    try:
        node = make_node()
        executor = (make_executor or (lambda ctx: SingleThreadedExecutor(context=ctx)))(context)
        executor.add_node(node)
        spinner = threading.Thread(target=spin, name='executor', daemon=True)
        spinner.start()
        while not request.requested and context.ok() and spinner.is_alive():
            time.sleep(POLL_PERIOD)
        if failure:
            logging.getLogger(__name__).error('the executor failed: %r', failure[0])
            status = 1
        if stop is not None and context.ok():
            stop(node, grace)
    finally:
        rclpy.try_shutdown(context=context)
        if executor is not None:
            if not _within(grace, executor.shutdown):
                status = 1
        if node is not None:
            if before_destroy is not None:
                before_destroy(node)
            node.destroy_node()
        request.restore()
    if any(thread.is_alive() and not thread.daemon and thread is not threading.main_thread()
           for thread in threading.enumerate()):
        status = status or 1  # a callback that ignores shutdown
    return status


def exit_process(status: int) -> None:
    """End the process now with ``status``, after flushing stdout and stderr (no interpreter
    finalization: see the module docstring)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def _within(seconds: float, function: Callable[[], Any]) -> bool:
    """Run ``function`` in a daemon thread; False if it has not returned after ``seconds``."""
    worker = threading.Thread(target=function, daemon=True)
    worker.start()
    worker.join(seconds)
    return not worker.is_alive()
