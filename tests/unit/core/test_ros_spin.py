"""A command's interrupt survives rclpy's native code (sessgan_core.ros_spin)."""

from __future__ import annotations

import io
import os
import signal
import time

import pytest

from sessgan_core.ros_spin import INTERRUPTED_STATUS, run_command, spin_interruptibly

pytestmark = pytest.mark.unit


def mangled_interrupt() -> None:
    """A spin that SIGINT reaches while the native code calls back into Python: pybind11
    reports the handler's KeyboardInterrupt as a failed conversion (seen in CI, 2026-12-07)."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5)  # the handler raises within it
    except KeyboardInterrupt:
        raise TypeError('Unable to convert function return value to a Python type!') from None


def test_an_error_out_of_a_spin_after_a_signal_is_the_interrupt_and_the_clean_up_runs():
    cleaned = []

    def body() -> int:
        try:
            spin_interruptibly(mangled_interrupt)
        except KeyboardInterrupt:
            cleaned.append('report written')
            raise
        return 0

    stderr = io.StringIO()
    assert run_command(body, 'stopped', stream=stderr) == INTERRUPTED_STATUS
    assert cleaned == ['report written']
    assert stderr.getvalue() == 'stopped\n'


def test_an_error_out_of_a_spin_without_a_signal_stays_that_error():
    def body() -> int:
        spin_interruptibly(lambda: int('not a number'))
        return 0

    with pytest.raises(ValueError):
        run_command(body)
    with pytest.raises(ValueError):  # outside a command there is no signal record
        spin_interruptibly(lambda: int('not a number'))
