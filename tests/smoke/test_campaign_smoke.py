"""Tiny campaigns through the real command: results, bags, replay, and resume after SIGKILL."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.ros_processes import REPO_ROOT

pytestmark = pytest.mark.smoke

# Small but real: two workers, three generations, each episode at most 20 sim seconds.
TINY = ['--method', 'sessgan', '--scenario', 'factory', '--generations', '3', '--population', '3',
        '--maps-per-member', '1', '--workers', '2', '--time-limit', '20', '--seed', '5']
IGNORED_COLUMNS = {'wall_time', 'bag_path', 'harness_reruns'}
"""Columns that differ between runs with the same results (harness re-runs are no result)."""


def campaign(tmp_path: Path, run: str, *extra: str) -> list[str]:
    return ['ros2', 'run', 'sessgan_evolver', 'campaign', *TINY, '--run', run,
            '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags'), *extra]


def episode_rows(run_dir: Path, kind: str = 'episodes') -> list[dict]:
    with open(run_dir / f'metrics_{kind}.csv') as handle:
        return [{k: v for k, v in row.items() if k not in IGNORED_COLUMNS}
                for row in csv.DictReader(handle)]


@pytest.fixture(scope='module')
def straight(ros_workspace, tmp_path_factory) -> Path:
    """The run directory of an undisturbed TINY campaign, to compare disturbed runs with."""
    root = tmp_path_factory.mktemp('straight')
    complete = subprocess.run(campaign(root, 'straight'), capture_output=True, text=True,
                              timeout=600)
    assert complete.returncode == 0, complete.stderr[-3000:]
    assert 'report:' in complete.stdout and 'failure bags:' in complete.stdout
    return root / 'runs' / 'straight'


def test_campaign_resumes_after_sigkill_with_identical_results(straight, tmp_path):
    report = straight / 'report'
    for name in ('report.md', 'generation_metrics.png', 'maps.png'):
        assert (report / name).stat().st_size > 0

    # Kill the second run (SIGKILL: no cleanup at all) once generation 1 is under way.
    killed = subprocess.Popen(campaign(tmp_path, 'killed'), stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    checkpoint = tmp_path / 'runs' / 'killed' / 'checkpoints' / 'generation_0001.pt'
    deadline = time.monotonic() + 300
    while not checkpoint.exists():
        assert killed.poll() is None, 'the campaign ended before it could be killed'
        assert time.monotonic() < deadline, 'generation 1 never started'
        time.sleep(0.2)
    time.sleep(1.0)
    os.killpg(killed.pid, signal.SIGKILL)
    killed.wait(timeout=10)
    time.sleep(1.0)  # its workers get SIGTERM from the kernel as their parent died

    resumed = subprocess.run(campaign(tmp_path, 'killed', '--resume'), capture_output=True,
                             text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert 'resuming' in resumed.stderr
    assert episode_rows(tmp_path / 'runs' / 'killed') == episode_rows(straight)


def child_of(parent_pid: int, *markers: str) -> int:
    """The pid of the child process of ``parent_pid`` whose command line has every marker."""
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / 'stat').read_text()
            command = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode()
        except OSError:
            continue
        parent = int(stat.rsplit(')', 1)[1].split()[1])
        if parent == parent_pid and all(marker in command for marker in markers):
            return int(entry.name)
    raise AssertionError(f'no child of {parent_pid} runs {markers}')


@pytest.mark.parametrize('victim', ['controller', 'simulator'])
def test_a_worker_process_killed_mid_episode_is_restarted_and_the_episode_rerun(
        straight, tmp_path, victim):
    """SIGKILL of worker /w0's controller (or simulator) while it runs an episode: the campaign
    sees the death at once (not after the episode timeout), restarts the pair, runs the
    episode again, and ends with the rows of the undisturbed run: nothing of the dead pair's
    episode reaches the metrics."""
    stderr_path = tmp_path / 'campaign.err'
    with open(stderr_path, 'wb') as stderr:
        run = subprocess.Popen(campaign(tmp_path, 'disturbed'), stdout=subprocess.DEVNULL,
                               stderr=stderr, start_new_session=True)
    try:
        controller_log = tmp_path / 'runs' / 'disturbed' / 'logs' / 'nearness_diagram_w0.log'
        deadline = time.monotonic() + 300
        # The controller logs every goal it gets: kill as soon as /w0's second episode began.
        while not (controller_log.exists()
                   and controller_log.read_text(errors='replace').count('New goal') >= 2):
            assert run.poll() is None, stderr_path.read_text()[-3000:]
            assert time.monotonic() < deadline, 'worker /w0 never got a second episode'
            time.sleep(0.01)
        markers = (('sessgan_controllers/nearness_diagram',) if victim == 'controller'
                   else ('sessgan_sim/simulator',))
        os.kill(child_of(run.pid, *markers, '__ns:=/w0'), signal.SIGKILL)
        assert run.wait(timeout=600) == 0, stderr_path.read_text()[-3000:]
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
    log = stderr_path.read_text()
    assert 'a harness failure, not a result; the episode will run again' in log, log[-3000:]
    assert 'worker /w0: restarted its simulator and controller (restart 1 of' in log
    assert 'gave no result within' not in log, 'the death was noticed only at the timeout'
    rows = episode_rows(tmp_path / 'runs' / 'disturbed')
    assert 'controller_unresponsive' not in {row['outcome'] for row in rows}
    with open(tmp_path / 'runs' / 'disturbed' / 'metrics_generations.csv') as handle:
        assert sum(int(row['harness_reruns']) for row in csv.DictReader(handle)) >= 1
    assert rows == episode_rows(straight)
    for kind in ('members', 'generations'):  # fitness, and what evolution made of it
        assert episode_rows(tmp_path / 'runs' / 'disturbed', kind) == \
            episode_rows(straight, kind)


def test_failure_bag_replays_and_resimulates_to_the_same_outcome(ros_workspace, tmp_path):
    # Five seconds cannot cross a factory map: a timeout in a valid test, a controller failure
    # with a bag, whichever maps are drawn (the Nearness-Diagram robot reaches most goals).
    result = subprocess.run(campaign(tmp_path, 'bags', '--generations', '1', '--time-limit', '5'),
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    bags = sorted((tmp_path / 'bags' / 'bags').iterdir())
    assert bags, 'no failure bag was written'
    bag = bags[0]
    files = {path.name for path in bag.iterdir()}
    assert {'episode.json', 'map.pgm', 'map.yaml', 'metadata.yaml'} <= files
    assert not list((tmp_path / 'bags' / 'bags').glob('*.tmp-*'))

    replay = subprocess.run(['ros2', 'run', 'sessgan_evolver', 'replay', str(bag), '--rate',
                             '50'], capture_output=True, text=True, timeout=120)
    assert replay.returncode == 0, replay.stderr[-2000:]
    assert 'replayed' in replay.stderr
    # Interrupted before the bag's end: 130, as every command; a --loop ends so: 0.
    for loop, status in (([], 130), (['--loop'], 0)):
        slow = subprocess.Popen(['ros2', 'run', 'sessgan_evolver', 'replay', str(bag),
                                 '--rate', '0.05', *loop], stderr=subprocess.PIPE, text=True)
        try:
            while 'replaying' not in (line := slow.stderr.readline()):
                assert line, 'replay ended before it began'
            slow.send_signal(signal.SIGINT)
            assert slow.wait(timeout=60) == status, loop
        finally:
            slow.kill()
            slow.wait()

    again = subprocess.run(['ros2', 'run', 'sessgan_evolver', 'replay', str(bag),
                            '--resimulate'], capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stdout + again.stderr[-2000:]
    assert again.stdout.strip().splitlines()[-1] == 'as expected'  # not 'NOT as expected'

    bad = subprocess.run(['ros2', 'run', 'sessgan_evolver', 'replay', str(tmp_path / 'nothing')],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and 'does not exist' in bad.stderr

    # Half a bag: refused before its episode.json is trusted (no simulator is started).
    storage = next(bag.glob('*.mcap'))
    storage.write_bytes(storage.read_bytes()[:storage.stat().st_size // 2])
    half = subprocess.run(['ros2', 'run', 'sessgan_evolver', 'replay', str(bag),
                           '--resimulate'], capture_output=True, text=True, timeout=60)
    assert half.returncode == 2, half.stdout + half.stderr[-2000:]
    assert 'incomplete or corrupt' in half.stderr and 'recorded' not in half.stdout


def test_campaign_rejects_bad_settings_clearly(ros_workspace, tmp_path):
    for arguments, message in ((['--scenario', 'moon'], 'moon'),
                               (['--population', '0'], 'population'),
                               (['--bag-storage', 'zip'], 'storage')):
        result = subprocess.run(
            ['ros2', 'run', 'sessgan_evolver', 'campaign', '--runs-root', str(tmp_path),
             *arguments], capture_output=True, text=True, timeout=60, cwd=REPO_ROOT)
        assert result.returncode == 2, result.stderr
        assert message in result.stderr


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_stops_a_ros_campaign_cleanly_with_the_resume_hint(ros_workspace, tmp_path,
                                                                   signum):
    """Ctrl-C (SIGINT to the terminal's process group) during generation 0 ends the campaign
    as SIGTERM does: exit 130, the --resume hint, no traceback."""
    stderr_path = tmp_path / 'campaign.err'
    with open(stderr_path, 'wb') as stderr:
        # Far more generations than run before the signal: on a quiet machine one generation
        # and the report took less than the 2 s the test waits.
        run = subprocess.Popen(campaign(tmp_path, 'interrupted', '--generations', '100'),
                               stdout=subprocess.DEVNULL, stderr=stderr,
                               start_new_session=True)
    try:
        checkpoint = tmp_path / 'runs' / 'interrupted' / 'checkpoints' / 'generation_0000.pt'
        deadline = time.monotonic() + 300
        while not checkpoint.exists():  # episodes are being run
            assert run.poll() is None, stderr_path.read_text()[-3000:]
            assert time.monotonic() < deadline, 'generation 0 never started'
            time.sleep(0.1)
        time.sleep(2.0)
        os.killpg(run.pid, signum)
        assert run.wait(timeout=120) == 130, stderr_path.read_text()[-3000:]
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
    log = stderr_path.read_text(errors='replace')
    hint = next(line for line in log.splitlines() if 'continue later with: ' in line)
    assert '--run interrupted' in hint and hint.endswith(' --resume)'), hint
    assert 'Traceback' not in log and 'ExternalShutdownException' not in log, log[-3000:]
