"""A failure bag writer killed mid-write, for the tests of staging directory clean-up."""

from __future__ import annotations

import subprocess
import sys
import textwrap

KILLED_WRITER = textwrap.dedent("""
    import os, signal, sys
    import numpy as np
    from sessgan_sim.bag_recording import BagRecord, write_episode_bag

    def records():
        yield BagRecord('/chatter', 'std_msgs/msg/String', 1, b'\\0\\1\\0\\0\\2\\0\\0\\0x\\0')
        os.kill(os.getpid(), signal.SIGKILL)  # killed mid-write, like a worker

    write_episode_bag(sys.argv[1], records(), {}, np.zeros((2, 2), np.int8), 1.0, (0.0, 0.0))
""")


def killed_writer_staging(directory, episode_id: str = 'g000-m01-s5'):
    """The staging directory a writer killed in the middle of a bag leaves in ``directory``."""
    process = subprocess.run([sys.executable, '-c', KILLED_WRITER, str(directory / episode_id)],
                             capture_output=True, text=True, timeout=120)
    assert process.returncode == -9, process.stderr
    found = list(directory.glob(f'{episode_id}.tmp-*'))
    assert len(found) == 1, found
    return found[0]
