"""campaign --external with no simulator up: an error that says what to check, and no empty
run directory left behind."""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy')

from sessgan_evolver import campaign_cli  # noqa: E402
from sessgan_evolver.ros_evaluator import RosEvaluator  # noqa: E402

pytestmark = pytest.mark.unit


def test_no_external_worker_says_what_to_check_and_leaves_no_run(tmp_path, monkeypatch,
                                                                  capsys):
    wait = RosEvaluator.wait_for_workers
    monkeypatch.setattr(RosEvaluator, 'wait_for_workers',
                        lambda self, count, timeout: wait(self, count, 0.3))
    runs = tmp_path / 'runs'
    status = campaign_cli.run_campaign([
        '--external', '--method', 'random', '--budget', '2', '--run', 'nobody',
        '--runs-root', str(runs), '--bags-root', str(tmp_path / 'bags')])
    error = capsys.readouterr().err
    assert status == 1
    assert not (runs / 'nobody').exists() and not (tmp_path / 'bags').exists()
    assert 'only 0 of 1 simulator workers answered' in error
    assert 'any <namespace>/evaluate, e.g. /w0/evaluate; found none' in error
    assert 'ros2 run sessgan_sim simulator --ros-args -r __ns:=/w0' in error
    assert 'ROS_DOMAIN_ID' in error and 'ROS_AUTOMATIC_DISCOVERY_RANGE' in error


def test_a_run_directory_with_a_file_is_kept(tmp_path):
    run = tmp_path / 'run'
    (run / 'checkpoints').mkdir(parents=True)
    (run / 'logs').mkdir()
    (run / 'logs' / 'generator.log').write_text('started')
    campaign_cli.remove_if_empty(run)
    assert (run / 'logs' / 'generator.log').exists()
    (run / 'logs' / 'generator.log').unlink()
    campaign_cli.remove_if_empty(run)
    assert not run.exists()


def test_a_worker_not_asked_for_is_named():
    """--worker /w1 with /w0 up: the message says /w0 runs but was not asked for."""
    evaluator = object.__new__(RosEvaluator)
    evaluator.allowed = {'/w1/evaluate'}
    evaluator.evaluate_servers = lambda: ['/w0/evaluate']
    evaluator.pool = type('Pool', (), {'pairs': [None]})()
    text = evaluator.missing_workers(1, [], 60.0)
    assert '/w1/evaluate; found none; not asked for, but running: /w0/evaluate)' in text


def test_a_run_another_campaign_holds_is_refused_before_anything_runs(tmp_path, capsys):
    """Two campaigns started at once with one --run both ran and interleaved their rows."""
    from sessgan_core.atomic_files import lock_folder

    runs = tmp_path / 'runs'
    held = lock_folder(runs / 'dup', campaign_cli.RUN_LOCK)
    assert held is not None
    try:
        status = campaign_cli.run_campaign([
            '--in-process', '--method', 'random', '--budget', '2', '--run', 'dup',
            '--runs-root', str(runs), '--bags-root', str(tmp_path / 'bags')])
    finally:
        held.close()
    assert status == 2
    assert "run 'dup' is in use by another campaign" in capsys.readouterr().err
    assert not (runs / 'dup' / 'config.json').exists()
    again = lock_folder(runs / 'dup', campaign_cli.RUN_LOCK)  # let go
    assert again is not None
    again.close()


def test_the_overhead_line_counts_bags_the_workers_wrote_in_place(tmp_path):
    """A campaign's own workers write into its bags folder: nothing to copy, but not '0 bags'
    (the demo said so with 17 failure bags)."""
    from sessgan_evolver.ros_evaluator import CampaignOverhead

    evaluator = object.__new__(RosEvaluator)
    evaluator.overhead, evaluator.collect_into = CampaignOverhead(), None
    evaluator.collect_bag('/w0/evaluate', None, {'bag_path': str(tmp_path / 'b0')})
    evaluator.collect_bag('/w0/evaluate', None, {'bag_path': ''})  # a pass: no bag
    assert '(0 bags copied, 0.0 ms each; 1 written in place by the workers)' in (
        evaluator.overhead.summary())
