"""Every command refuses a setting it cannot work with before it writes anything: exit 2, a
message naming the option, no run or output directory."""

from __future__ import annotations

from pathlib import Path

import pytest

from sessgan_evolver import campaign_cli, compare_cli, evaluate_cli
from sessgan_evolver.campaign import CampaignConfig, CampaignError
from sessgan_evolver.errors import CompareError
from sessgan_gen import export_cli, report_cli, train_cli
from sessgan_gen.checkpoint import default_checkpoint_path
from sessgan_sim.episode import MAX_TIME_LIMIT

pytestmark = pytest.mark.unit

BAD_CAMPAIGN_SETTINGS = [
    (['--time-limit', '-5'], 'time_limit'),
    (['--time-limit', 'nan'], 'time_limit'),
    (['--time-limit', 'inf'], 'time_limit'),
    (['--time-limit', '1e9'], 'time_limit'),
    (['--episode-timeout', '-1'], 'episode_timeout'),
    (['--episode-timeout', 'nan'], 'episode_timeout'),
    (['--harness-tries', '0'], 'harness_tries'),
    (['--harness-tries', '21'], 'harness_tries'),
    (['--controller', 'nope'], 'nope'),
    (['--controller', 'race_controller'], 'does not drive'),
]


@pytest.mark.parametrize('in_process', [True, False])
@pytest.mark.parametrize(('arguments', 'named'), BAD_CAMPAIGN_SETTINGS)
def test_campaign_refuses_a_bad_setting_before_the_run_directory(tmp_path, capsys, monkeypatch,
                                                                  arguments, named, in_process):
    def no_ros(*args):
        raise AssertionError('the campaign started ROS with a bad setting')

    monkeypatch.setattr(campaign_cli, 'init_rclpy', no_ros)
    status = campaign_cli.main([
        *(['--in-process'] if in_process else []), '--scenario', 'factory', '--run', 'bad',
        '--runs-root', str(tmp_path / 'runs'), '--bags-root', str(tmp_path / 'bags'),
        *arguments])
    err = capsys.readouterr().err
    assert status == 2, err
    assert named in err and 'Traceback' not in err
    assert not (tmp_path / 'runs').exists() and not (tmp_path / 'bags').exists()


def test_the_time_limit_bound_is_documented_and_inclusive():
    CampaignConfig(time_limit=MAX_TIME_LIMIT).validate()
    with pytest.raises(CampaignError, match=f'time_limit must lie in \\[0, {MAX_TIME_LIMIT:.0f}'):
        CampaignConfig(time_limit=MAX_TIME_LIMIT + 1).validate()
    # An external stack is not started by the campaign: its name is free.
    CampaignConfig(external=True, controller='my_stack').validate()


@pytest.mark.parametrize(('arguments', 'named'), [
    (['--time-limit', '-5'], '--time-limit'), (['--time-limit', 'nan'], '--time-limit'),
    (['--time-limit', '1e9'], '--time-limit'), (['--controller', 'nope'], 'nope'),
    (['--repeats', '-1'], '--repeats'), (['--max-fault-records', '-2'], '--max-fault-records'),
    (['--coarse-cells', '0'], 'coarse_cells'), (['--evaluation-seed', '-1'], '--evaluation-seed'),
    # The spellings before the rename, accepted for one release: the new name is reported.
    (['--seed', '-1'], '--evaluation-seed'), (['--fault-records', '-2'], '--max-fault-records'),
    # A member of a run's population, with no --run to pick it from.
    (['--member', '3'], '--member')])
def test_evaluate_refuses_a_bad_setting_before_its_output(tmp_path, capsys, arguments, named):
    status = evaluate_cli.main(['--fresh-episodes', '1', '--output-dir', str(tmp_path / 'out'),
                                *arguments])
    err = capsys.readouterr().err
    assert status == 2, err
    assert named in err and not (tmp_path / 'out').exists()


@pytest.mark.parametrize(('arguments', 'named'), [
    (['--time-limit', '-5'], 'time_limit'), (['--time-limit', 'inf'], 'time_limit'),
    (['--controller', 'nope'], 'nope'), (['--max-fault-records', '-2'], 'max_fault_records'),
    (['--checkpoint', '/nonexistent.pt'], 'does not exist'),
    (['--station-dwell-time', 'nan'], 'station_dwell_time')])
def test_compare_refuses_a_bad_setting_before_its_output(tmp_path, capsys, arguments, named):
    status = compare_cli.main(['--output-dir', str(tmp_path / 'out'), *arguments])
    err = capsys.readouterr().err
    assert status == 2, err
    assert named in err and not (tmp_path / 'out').exists()


def test_compare_tells_a_usage_error_from_a_failed_comparison(tmp_path, capsys, monkeypatch):
    output = tmp_path / 'out'
    output.mkdir()
    (output / 'report.md').write_text('an earlier comparison')
    assert compare_cli.main(['--output-dir', str(output)]) == 2
    assert 'holds a comparison already' in capsys.readouterr().err

    def fails(*args):
        raise CompareError('a method failed')

    monkeypatch.setattr(compare_cli, 'run_comparison', fails)
    assert compare_cli.main(['--output-dir', str(tmp_path / 'other')]) == 1
    assert 'a method failed' in capsys.readouterr().err


@pytest.mark.parametrize(('arguments', 'named'), [
    (['--beta1', 'nan'], 'beta1'), (['--lr-decay', '0'], 'lr_decay'),
    (['--coarsest-coverage', 'inf'], 'coarsest_coverage'), (['--seed', '-1'], 'seed'),
    (['--max-scales', '-2'], 'max_scales'), (['--device', 'bogus'], 'device must be'),
    # A device this torch cannot use (CPU-only, as ./sessgan installs it; a 99th GPU).
    (['--device', 'cuda:99'], "device 'cuda:99'"),
    # The inputs an option names count as options: read before anything is written.
    (['--map-file', '/nonexistent.txt'], '/nonexistent.txt'),
    (['--map-yaml', '/nonexistent.yaml'], '/nonexistent.yaml'), (['--resume'], '--resume')])
def test_train_refuses_a_bad_setting_before_writing(tmp_path, capsys, arguments, named):
    output = tmp_path / 'out' / 'generator.pt'
    status = train_cli.main(['--output', str(output), '--iterations', '1', *arguments])
    err = capsys.readouterr().err
    assert status == 2, err
    assert named in err and not (tmp_path / 'out').exists()


@pytest.mark.parametrize(('arguments', 'named'), [
    (['--generate', '--seed', '-1'], '--seed'), (['--generate', '--width', '-3'], '--width'),
    (['--generate', '--scenario', 'moon'], 'moon'),
    (['--map-file', '/nonexistent.txt'], '--map-file'),
    # Another scenario's generator, a size it cannot make: bad options too (exit 1 before).
    (['--generate', '--checkpoint', str(default_checkpoint_path('drone')), '--scenario',
      'racetrack'], "'drone', not 'racetrack'"),
    (['--generate', '--width', '3', '--height', '3'], 'size 3x3 cells is outside')])
def test_export_refuses_a_bad_setting_before_writing(tmp_path, capsys, arguments, named):
    status = export_cli.main(['--output', str(tmp_path / 'out' / 'map.yaml'), *arguments])
    err = capsys.readouterr().err
    assert status == 2, err
    assert named in err and not (tmp_path / 'out').exists()


def test_export_and_report_refuse_a_truncated_checkpoint_before_writing(tmp_path, capsys):
    truncated = tmp_path / 'truncated.pt'
    truncated.write_bytes(default_checkpoint_path('factory').read_bytes()[:100_000])
    for command, arguments, output in (
            (export_cli, ['--generate', '--checkpoint', str(truncated), '--output',
                          str(tmp_path / 'out' / 'map.yaml')], tmp_path / 'out'),
            (report_cli, ['--scenarios', 'factory', '--factory-checkpoint', str(truncated),
                          '--output-dir', str(tmp_path / 'report')], tmp_path / 'report')):
        status = command.main(arguments)
        err = capsys.readouterr().err
        assert status == 2, err
        assert 'truncated.pt' in err and 'not a valid checkpoint' in err
        assert not output.exists()


def test_export_refuses_a_map_file_that_is_no_token_map(tmp_path, capsys):
    bad = tmp_path / 'notes.txt'
    bad.write_text('{}\n')
    status = export_cli.main(['--map-file', str(bad), '--output',
                              str(tmp_path / 'out' / 'map.yaml')])
    err = capsys.readouterr().err
    assert status == 2, err
    assert 'notes.txt' in err and not (tmp_path / 'out').exists()


@pytest.mark.parametrize(('arguments', 'named'), [
    (['--samples', '0'], '--samples'), (['--scenarios', 'moon'], 'moon'),
    (['--threads', '-1'], '--threads'),
    (['--factory-checkpoint', '/nonexistent.pt'], '--factory-checkpoint'),
    (['--scenarios', 'drone', '--drone-checkpoint', str(default_checkpoint_path('factory'))],
     "trained for scenario 'factory', not 'drone'")])
def test_report_refuses_a_bad_setting_before_writing(tmp_path, capsys, arguments, named):
    status = report_cli.main(['--output-dir', str(tmp_path / 'out'), *arguments])
    err = capsys.readouterr().err
    assert status == 2, err
    assert named in err and not (tmp_path / 'out').exists()


def test_renamed_options_keep_their_old_spelling_for_a_release(capsys):
    from sessgan_evolver.suite_cli import parse_args as suite_args

    new = evaluate_cli.parse_args(['--evaluation-seed', '7', '--fresh-episodes', '3',
                                   '--max-fault-records', '2', '--output-dir', 'here'])
    old = evaluate_cli.parse_args(['--seed', '7', '--episodes', '3', '--fault-records', '2',
                                   '--output', 'here'])
    assert vars(old) == vars(new)
    assert compare_cli.parse_args(['--output', 'here']).output_dir == \
        compare_cli.parse_args(['--output-dir', 'here']).output_dir
    assert suite_args(['s.yaml', '--output', 'here']).output_dir == \
        suite_args(['s.yaml', '--output-dir', 'here']).output_dir
    with pytest.raises(SystemExit):
        evaluate_cli.parse_args(['--help'])
    shown = capsys.readouterr().out
    assert '--output-dir' in shown and '--fault-records' not in shown.replace(
        '--max-fault-records', '')


def test_evaluate_takes_a_run_name_under_runs_root_and_a_run_folder_as_run_dir(
        tmp_path, capsys, monkeypatch):
    runs = tmp_path / 'runs'
    (runs / 'tiny').mkdir(parents=True)
    config = evaluate_cli.parse_args(['--run', 'tiny', '--runs-root', str(runs), '--run-dir',
                                      str(runs / 'tiny'), '--exclude-run', 'tiny'])
    assert config.run_directories() == ([runs / 'tiny'] * 2, [runs / 'tiny'])
    # A run folder given to --run (its meaning before --run became a name) is still taken.
    monkeypatch.chdir(tmp_path)
    config = evaluate_cli.parse_args(['--run', 'runs/tiny', '--runs-root', 'elsewhere'])
    assert config.run_directories() == ([Path('runs/tiny')], [])
    assert '--run-dir' in capsys.readouterr().err
    status = evaluate_cli.main(['--run', 'missing', '--runs-root', str(runs),
                                '--output-dir', str(tmp_path / 'out')])
    err = capsys.readouterr().err
    assert status == 2 and f'no run folder {runs / "missing"}' in err, err
    assert not (tmp_path / 'out').exists()


def test_list_options_take_commas_or_repeats_in_every_command():
    from sessgan_core.config_cli import parse_config
    from sessgan_evolver.suite_cli import parse_args as suite_args

    assert suite_args(['s.yaml', '--worker', '/w0,/w1']).worker == ('/w0', '/w1')
    assert suite_args(['s.yaml', '--worker', '/w0', '--worker', '/w1']).worker == ('/w0', '/w1')
    assert suite_args(['s.yaml', '--workers', '/w0,/w1']).worker == ('/w0', '/w1')  # old name
    for arguments in (['--scenarios', 'factory,drone'],
                      ['--scenarios', 'factory', '--scenarios', 'drone']):
        assert parse_config(report_cli.ReportConfig, arguments).scenarios == ('factory', 'drone')
    assert compare_cli.parse_args(['--methods', 'random', '--methods', 'latent',
                                   '--search-seeds', '4,5']).comparison().methods == (
                                       'random', 'latent')
    assert evaluate_cli.parse_args(['--checkpoint', 'a.pt,b.pt']).checkpoint == (
        Path('a.pt'), Path('b.pt'))
