"""Commands that use rclpy (campaign, replay, the benchmarks) stop on SIGINT as on SIGTERM:
the signal is a KeyboardInterrupt in the main thread while ROS is still up, so the command
stops its processes and exits 130 without a traceback (sessgan_core.ros_spin.run_command and
init_rclpy). With rclpy's own handlers the context was shut down under the spinning command,
which then raised ExternalShutdownException (a traceback and exit 1) whenever the shutdown
was seen before the KeyboardInterrupt."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.graph

PROBE = """
import os, signal, sys, threading
import rclpy
from sessgan_core.ros_spin import init_rclpy, run_command

def body():
    init_rclpy([])
    node = rclpy.create_node('signal_probe')
    threading.Timer(1.0, os.kill, (os.getpid(), SIGNUM)).start()
    try:
        while True:
            rclpy.spin_once(node, timeout_sec=0.05)
    except KeyboardInterrupt:
        print('ROS up' if rclpy.ok() else 'ROS shut down', flush=True)
        raise
    finally:
        node.destroy_node()
        rclpy.try_shutdown()

sys.exit(run_command(body, 'probe: interrupted'))
"""


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_reaches_a_spinning_command_as_keyboard_interrupt_with_ros_up(ros_workspace,
                                                                             signum):
    probe = subprocess.run([sys.executable, '-c', PROBE.replace('SIGNUM', str(int(signum)))],
                           capture_output=True, text=True, timeout=60)
    assert probe.returncode == 130, probe.stderr
    assert probe.stdout.strip() == 'ROS up'
    assert probe.stderr.strip() == 'probe: interrupted'
