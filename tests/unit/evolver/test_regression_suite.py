"""Regression suites: reading and checking suites, verdicts over attempts, JUnit/markdown/CSV,
and the ``suite`` command run in process (no ROS) on a real failure bag."""

from __future__ import annotations

import csv
import json
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest
import yaml

from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver import suite_cli
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.regression_suite import (
    Attempt,
    AttemptKind,
    ScenarioProgress,
    SuiteEntry,
    SuiteError,
    Verdict,
    classify,
    exit_code,
    junit_xml,
    load_suite,
    load_suite_source,
    markdown_summary,
    suite_from_bag_directory,
    write_suite_file,
)
from sessgan_gen.environment_sampler import EnvironmentSampler

pytestmark = pytest.mark.unit


@pytest.fixture(scope='module')
def failure_bag(tmp_path_factory) -> Path:
    """The Nearness-Diagram robot's fault collision on a fresh factory map (a wall clipped in
    a turn, its documented weakness; simulator seed 0; the reference navigator reaches the
    goal there without one)."""
    root = tmp_path_factory.mktemp('bags')
    (environment,) = EnvironmentSampler().sample([1_000_000], scenario='factory')
    with InProcessEvaluator('factory', 'nearness_diagram', record_directory=root) as evaluator:
        run = evaluator.run_environment(environment, 0)
    assert run.metrics['fault_collisions'] > 0, run.metrics
    return Path(run.metrics['bag_path'])


def entry(name: str = 'a') -> SuiteEntry:
    return SuiteEntry(name, Path('/nowhere'), {'scenario': 'factory', 'environment_id': name},
                      'stuck')


def attempt(kind: str, outcome: str = 'goal_reached') -> Attempt:
    return Attempt(AttemptKind(kind), {'outcome': outcome, 'fault_collisions': 0,
                                       'wall_time': 1.0})


# ---- judging ----------------------------------------------------------------------------


@pytest.mark.parametrize('metrics, kind', [
    ({'outcome': 'goal_reached', 'feasible': True, 'fault_collisions': 0}, 'pass'),
    ({'outcome': 'goal_reached', 'feasible': True, 'fault_collisions': 1}, 'fail'),
    ({'outcome': 'collision_limit', 'feasible': True, 'fault_collisions': 3}, 'fail'),
    ({'outcome': 'stuck', 'feasible': True, 'fault_collisions': 0}, 'fail'),
    ({'outcome': 'timeout', 'feasible': True, 'fault_collisions': 0}, 'fail'),
    ({'outcome': 'controller_unresponsive', 'feasible': True, 'fault_collisions': 0},
     'harness'),
    ({'outcome': 'cancelled', 'feasible': True, 'fault_collisions': 2}, 'harness'),
    ({'outcome': 'invalid_environment', 'feasible': True, 'fault_collisions': 0}, 'harness'),
    # The recorded map was a valid test: not feasible now is the harness's doing.
    ({'outcome': 'stuck', 'feasible': False, 'fault_collisions': 0}, 'harness'),
])
def test_classify(metrics, kind):
    assert classify(metrics) is AttemptKind(kind)


def test_one_exact_result_is_the_verdict():
    progress = ScenarioProgress(entry(), results_wanted=1, harness_tries=3)
    assert progress.needed() == 1 and progress.verdict is Verdict.NOT_RUN
    progress.add(attempt('fail', 'stuck'))
    assert progress.needed() == 0 and progress.verdict is Verdict.FAIL


def test_retries_give_pass_fail_or_flaky():
    for kinds, verdict in ((['pass'] * 3, Verdict.PASS), (['fail'] * 3, Verdict.FAIL),
                           (['pass', 'fail', 'pass'], Verdict.FLAKY)):
        progress = ScenarioProgress(entry(), results_wanted=3, harness_tries=2)
        assert progress.needed() == 3  # all at once: they may run in parallel
        for kind in kinds:
            progress.add(attempt(kind))
        assert progress.done and progress.verdict is verdict


def test_harness_outcomes_are_rerun_and_become_an_error_after_n_in_a_row():
    progress = ScenarioProgress(entry(), results_wanted=2, harness_tries=2)
    progress.add(attempt('harness', 'controller_unresponsive'))
    assert progress.needed() == 1 and not progress.done
    progress.add(attempt('pass'))
    assert progress.needed() == 1  # the harness outcome did not count as a result
    progress.add(attempt('harness', 'cancelled'))
    progress.add(attempt('harness', 'controller_unresponsive'))
    assert progress.done and progress.verdict is Verdict.ERROR
    assert 'harness error' in progress.detail() and 'controller_unresponsive' in progress.detail()
    assert exit_code([progress]) == 3


def test_exit_codes():
    def finished(kinds):
        progress = ScenarioProgress(entry(), len(kinds), 1)
        for kind in kinds:
            progress.add(attempt(kind))
        return progress
    assert exit_code([finished(['pass']), finished(['pass', 'fail'])]) == 0
    assert exit_code([finished(['pass', 'fail'])], fail_on_flaky=True) == 1
    assert exit_code([finished(['pass']), finished(['fail'])]) == 1
    assert exit_code([finished(['pass']), finished(['harness'])]) == 3
    assert exit_code([finished(['fail']), finished(['harness'])]) == 1
    assert exit_code([finished(['pass'])], interrupted=True) == 130
    # An interrupted run is incomplete whatever it saw: CI tells it from a regression.
    assert exit_code([finished(['fail'])], interrupted=True) == 130


def test_junit_counts_and_elements():
    progresses = []
    for name, kinds in (('p', ['pass']), ('f', ['fail']), ('e', ['harness']),
                        ('flaky', ['pass', 'fail']), ('unrun', [])):
        progress = ScenarioProgress(entry(name), max(1, len(kinds)), 1)
        for kind in kinds:
            progress.add(attempt(kind, 'stuck' if kind == 'fail' else 'goal_reached'))
        progresses.append(progress)
    root = ElementTree.fromstring(junit_xml('s', progresses, 2.0, interrupted=True))
    suite = root.find('testsuite')
    assert suite is not None
    assert (suite.get('tests'), suite.get('failures'), suite.get('errors'),
            suite.get('skipped')) == ('5', '1', '1', '1')
    cases = {case.get('name'): case for case in suite.iter('testcase')}
    assert cases['f'].find('failure') is not None and cases['p'].find('failure') is None
    assert cases['e'].find('error') is not None
    assert cases['unrun'].find('skipped') is not None
    flaky = cases['flaky']
    assert flaky.find('failure') is None and len(flaky.findall('flakyFailure')) == 1
    props = {p.get('name'): p.get('value') for p in flaky.iter('property')}
    assert props['verdict'] == 'flaky' and props['attempts'] == '2'
    assert props['attempt_outcomes'] == 'pass:goal_reached fail:stuck'


# ---- reading suites ---------------------------------------------------------------------


def test_a_bag_directory_and_a_written_suite_file_list_the_same_scenario(failure_bag, tmp_path):
    suite = suite_from_bag_directory(failure_bag.parent)
    assert [e.bag for e in suite.entries] == [failure_bag]
    assert suite.entries[0].expected_outcome == 'goal_reached'
    assert suite.entries[0].expected_fault_collisions > 0
    path = write_suite_file(tmp_path / 'suite.yaml', 'mine', [failure_bag], {'run': 'r'})
    document = yaml.safe_load(path.read_text())
    assert document['run'] == 'r' and document['scenarios'][0]['scenario'] == 'factory'
    loaded = load_suite(path)
    assert loaded.name == 'mine' and loaded.entries[0].bag.resolve() == failure_bag.resolve()
    assert loaded.entries[0].environment_id == 'factory-s1000000'
    assert path.read_text().splitlines()[0] == \
        '# Regression suite: ros2 run sessgan_evolver suite suite.yaml'


def test_a_suite_of_another_stack_s_bags_names_external_in_its_command(failure_bag, tmp_path):
    """The bags of a stack that is no built-in controller re-run only beside it: the suite
    file's own command line says --external."""
    import json
    import shutil

    bag = tmp_path / 'bags' / failure_bag.name
    shutil.copytree(failure_bag, bag)
    episode = json.loads((bag / 'episode.json').read_text())
    episode['controller'] = 'external'
    (bag / 'episode.json').write_text(json.dumps(episode))
    path = write_suite_file(tmp_path / 'suite.yaml', 'mine', [bag])
    assert path.read_text().splitlines()[0] == \
        '# Regression suite: ros2 run sessgan_evolver suite suite.yaml --external'


def write_yaml(path: Path, document) -> Path:
    path.write_text(yaml.safe_dump(document) if not isinstance(document, str) else document)
    return path


@pytest.mark.parametrize('document, message', [
    ({'scenarios': [{'name': 'gone', 'bag': 'no/such/bag'}]}, r'scenario 1 \(gone\).*not exist'),
    ({'scenarios': [{'name': 'x', 'bag': '{bag}', 'scenario': 'racetrack'}]},
     r'scenario 1 \(x\).*scenario .racetrack. but bag .* holds .factory. \(a bag of another'),
    ({'scenarios': [{'name': 'y', 'bag': '{bag}', 'environment_id': 'other'}]},
     r'scenario 1 \(y\).*environment_id .other.'),
    ({'scenarios': []}, 'lists no scenarios: an empty suite'),
    ({'name': 'nothing'}, 'lists no scenarios'),
    ('scenarios: [ {bag: x\n', 'not valid YAML'),
    ({'scenarios': [{'name': 'z'}]}, r'scenario 1 \(z\): field "bag"'),
    ({'scenarios': [{'bag': '{bag}', 'bogus': 1}]}, r"scenario 1: unknown field\(s\) \['bogus'\]"),
    ({'format': 9, 'scenarios': [{'bag': '{bag}'}]}, 'format 9 is not supported'),
    ({'scenarios': [{'bag': '{bag}', 'expected': {'outcome': 'teleported'}}]},
     r"scenario 1: expected outcome 'teleported' is none of collision_limit, goal_reached, "
     'stuck, timeout'),
    ({'scenarios': [{'bag': '{bag}'}, {'bag': '{bag}'}]}, 'scenario 2.*used twice'),
])
def test_bad_suites_are_refused_naming_the_entry(failure_bag, tmp_path, document, message):
    if not isinstance(document, str):
        document = json.loads(json.dumps(document).replace('{bag}', str(failure_bag)))
    path = write_yaml(tmp_path / 'suite.yaml', document)
    with pytest.raises(SuiteError, match=message):
        load_suite(path)
    output = tmp_path / 'out'
    assert suite_cli.main([str(path), '--output', str(output)]) == 2
    assert not output.exists()  # nothing half-written


def test_a_controller_that_cannot_drive_the_recorded_robot_is_refused(failure_bag, tmp_path,
                                                                     capsys):
    output = tmp_path / 'out'
    assert suite_cli.main([str(failure_bag), '--controller', 'race_controller', '--output',
                           str(output)]) == 2
    assert f'scenario {failure_bag.name}' in capsys.readouterr().err
    assert not output.exists()
    assert suite_cli.main([str(failure_bag), '--controller', 'no_such', '--output',
                           str(output)]) == 2
    # It names what was given, not the bag's recorded controller.
    assert "--controller 'no_such' is not a built-in controller" in capsys.readouterr().err


def test_an_empty_bag_directory_and_a_missing_source_are_refused(tmp_path):
    with pytest.raises(SuiteError, match='holds no failure bag'):
        load_suite_source(tmp_path)
    with pytest.raises(SuiteError, match='does not exist'):
        load_suite_source(tmp_path / 'nope')


def test_a_bag_without_episode_json_is_refused(failure_bag, tmp_path):
    import shutil

    bag = tmp_path / 'bag'
    shutil.copytree(failure_bag, bag)
    (bag / 'episode.json').unlink()
    path = write_yaml(tmp_path / 'suite.yaml', {'scenarios': [{'name': 'b', 'bag': 'bag'}]})
    with pytest.raises(SuiteError, match=r'scenario 1 \(b\).*no episode.json'):
        load_suite(path)


# ---- the command, in process --------------------------------------------------------------


def read_junit(output: Path) -> tuple[dict[str, str], dict[str, dict[str, str]]]:
    root = ElementTree.parse(output / 'junit.xml').getroot()
    suite = root.find('testsuite')
    assert suite is not None
    cases = {case.get('name') or '': {p.get('name') or '': p.get('value') or ''
                                      for p in case.iter('property')}
             for case in suite.iter('testcase')}
    return dict(suite.attrib), cases


def test_the_recorded_fault_fails_again_and_a_fixed_controller_passes(failure_bag, tmp_path):
    suite_file = write_suite_file(tmp_path / 'suite.yaml', 'nd', [failure_bag])
    failed = tmp_path / 'failed'
    assert suite_cli.main([str(suite_file), '--output', str(failed)]) == 1
    counts, cases = read_junit(failed)
    assert (counts['tests'], counts['failures'], counts['errors']) == ('1', '1', '0')
    (name, props), = cases.items()
    assert props['verdict'] == 'fail' and int(props['fault_collisions']) > 0
    recorded = json.loads((failure_bag / 'episode.json').read_text())['metrics']
    # In process, lockstep: exact, the same episode as recorded.
    assert int(props['fault_collisions']) == recorded['fault_collisions']
    assert int(props['ticks']) == recorded['ticks']
    # The standard navigation metrics are properties: reached, but with a fault collision.
    assert props['success'] == '0' and float(props['time_to_goal']) > 0
    assert float(props['path_length']) == pytest.approx(recorded['distance_travelled'])
    assert float(props['path_length_ratio']) > 0.9 and float(props['linear_jerk']) > 0
    assert float(props['min_clearance']) == 0.0 < float(props['mean_clearance'])  # it touched
    assert props['bag'] and (Path(props['bag']) / 'episode.json').is_file()
    rows = list(csv.DictReader((failed / 'scenarios.csv').open()))
    assert rows[0]['verdict'] == 'fail' and rows[0]['name'] == name
    assert '| fail |' in (failed / 'summary.md').read_text()

    fixed = tmp_path / 'fixed'
    assert suite_cli.main([str(suite_file), '--output', str(fixed),
                           '--controller', 'reference_navigator']) == 0
    counts, cases = read_junit(fixed)
    assert (counts['tests'], counts['failures']) == ('1', '0')
    assert cases[name]['verdict'] == 'pass' and cases[name]['bag'] == ''
    assert not (fixed / 'bags').exists()  # --record failures: no bag of a pass

    everything = tmp_path / 'all'
    assert suite_cli.main([str(failure_bag.parent), '--output', str(everything), '--record',
                           'all', '--controller', 'reference_navigator']) == 0
    _, cases = read_junit(everything)
    assert Path(next(iter(cases.values()))['bag']).is_dir()

    none = tmp_path / 'none'
    assert suite_cli.main([str(failure_bag), '--output', str(none), '--record', 'none']) == 1
    _, cases = read_junit(none)
    assert next(iter(cases.values()))['bag'] == '' and not (none / 'bags').exists()


def test_ctrl_c_reports_what_ran(failure_bag, tmp_path, monkeypatch):
    suite_file = write_yaml(tmp_path / 'suite.yaml', {'name': 'two', 'scenarios': [
        {'name': 'first', 'bag': str(failure_bag)},
        {'name': 'second', 'bag': str(failure_bag)}]})
    real_run = suite_cli.InProcessRunner.run
    calls = []

    def interrupted_run(self, prepared, number):
        calls.append(prepared.entry.name)
        if prepared.entry.name == 'second':
            raise KeyboardInterrupt
        return real_run(self, prepared, number)

    monkeypatch.setattr(suite_cli.InProcessRunner, 'run', interrupted_run)
    output = tmp_path / 'out'
    # 130, not the failure's 1: the run is incomplete. What ran is reported, the rest not run.
    assert suite_cli.main([str(suite_file), '--output', str(output), '--record', 'none']) == 130
    counts, cases = read_junit(output)
    assert (counts['tests'], counts['failures'], counts['skipped']) == ('2', '1', '1')
    assert cases['first']['verdict'] == 'fail' and cases['second']['verdict'] == 'not_run'
    assert 'Interrupted' in (output / 'summary.md').read_text()


def test_a_campaign_keeps_its_failure_bags_as_a_suite(failure_bag, tmp_path, capsys):
    import shutil

    from sessgan_evolver.campaign import CampaignResult
    from sessgan_evolver.campaign_cli import report_result

    run_dir, bags_dir = tmp_path / 'runs' / 'r', tmp_path / 'bags' / 'r'
    run_dir.mkdir(parents=True)
    generations = [{'generation': 0, 'mean_risk_score': 0.0}]
    report_result(CampaignResult(run_dir, bags_dir, run_dir / 'report.md', generations, 1.0),
                  print)
    assert not (run_dir / 'suite.yaml').exists()  # no bag, no (empty) suite
    shutil.copytree(failure_bag, bags_dir / 'g0-m0-k0')
    report_result(CampaignResult(run_dir, bags_dir, run_dir / 'report.md', generations, 1.0),
                  print)
    suite = load_suite(run_dir / 'suite.yaml')
    assert [entry.bag.resolve() for entry in suite.entries] == [(bags_dir / 'g0-m0-k0').resolve()]
    out = capsys.readouterr().out
    assert f're-run: ros2 run sessgan_evolver suite {run_dir / "suite.yaml"})' in out
    # An external campaign's bags name no built-in controller: its re-run needs --external.
    report_result(CampaignResult(run_dir, bags_dir, run_dir / 'report.md', generations, 1.0),
                  print, external=True)
    assert f'suite {run_dir / "suite.yaml"} --external)' in capsys.readouterr().out
    assert load_suite_source(run_dir).entries == suite.entries  # the run folder names it
    # Relative to the file, so the run and bag folders can move together.
    document = yaml.safe_load((run_dir / 'suite.yaml').read_text())
    assert document['scenarios'][0]['bag'] == '../../bags/r/g0-m0-k0'


@pytest.mark.parametrize('text', ['ci', '000-collision_static-r2c1', '_x', '../..', 'ü b/c',
                                  '.hidden', 'x' * 300, '', 'a..b', 'a...b'])
def test_record_directory_names_are_ones_a_simulator_accepts(text):
    from sessgan_core.environment import check_environment_id

    check_environment_id(suite_cli.safe_name(text))  # raises for a name it would refuse


def test_mission_and_fleet_bags_rerun_exactly_in_process(tmp_path):
    from sessgan_core.fleet import FleetSpec
    from sessgan_core.missions import MissionSpec

    cells = load_example_map('factory').cells
    environments = [
        make_environment(cells, 'factory', 'mission', seed=0, mission=MissionSpec(1, 2.0)),
        make_environment(cells, 'factory', 'fleet', seed=3, fleet=FleetSpec(2))]
    recorded = {}
    # Three seconds are too short for either: a timeout (a failure) whose trajectory
    # depends on the stations and on every robot.
    with InProcessEvaluator('factory', 'reference_navigator', time_limit=3.0) as evaluator:
        for environment in environments:
            run = evaluator.runner.run(environment, 1, trace=True, keep_scans=True)
            evaluator.write_bag(tmp_path / 'bags' / environment.id, environment, 1, run)
            recorded[environment.id] = run.metrics
    assert suite_cli.main([str(tmp_path / 'bags'), '--output', str(tmp_path / 'out'),
                           '--record', 'none']) == 1
    _, cases = read_junit(tmp_path / 'out')
    assert set(cases) == {'mission', 'fleet'}
    for name, props in cases.items():
        assert props['verdict'] == 'fail' and props['outcome'] == recorded[name]['outcome']
        assert int(props['ticks']) == recorded[name]['ticks']
        assert float(props['path_length']) == recorded[name]['distance_travelled']


def test_the_output_folder_is_resolved_locked_and_each_run_keeps_its_own_bags(
        failure_bag, tmp_path, monkeypatch, capsys):
    suite_file = write_yaml(tmp_path / 'suite.yaml', {'name': 'clash', 'scenarios': [
        {'name': 'a/b', 'bag': str(failure_bag)}, {'name': 'a_b', 'bag': str(failure_bag)}]})
    (tmp_path / 'work').mkdir()
    monkeypatch.chdir(tmp_path / 'work')
    # '..' in a relative folder: resolved, not refused by the bag writer half-way.
    assert suite_cli.main([str(suite_file), '--output-dir', '../ci']) == 1
    _, first = read_junit(tmp_path / 'ci')
    bags = {name: Path(props['bag']) for name, props in first.items()}
    # Names that clash once made safe for a path still get a folder each.
    assert len({bag.parent for bag in bags.values()}) == 2
    assert all((bag / 'episode.json').is_file() for bag in bags.values())
    # A second run into the same folder leaves the first one's bags as they were.
    assert suite_cli.main([str(suite_file), '--output-dir', '../ci']) == 1
    _, second = read_junit(tmp_path / 'ci')
    assert all(Path(props['bag']) != bags[name] for name, props in second.items())
    assert all((bag / 'episode.json').is_file() for bag in bags.values())
    # Another run holding the folder, or a file in its place: refused, nothing run.
    capsys.readouterr()
    with suite_cli.lock_output(tmp_path / 'ci'):
        assert suite_cli.main([str(suite_file), '--output-dir', '../ci']) == 2
    assert 'another suite run is writing to' in capsys.readouterr().err
    (tmp_path / 'afile').write_text('x')
    assert suite_cli.main([str(suite_file), '--output-dir', '../afile']) == 2
    assert 'is a file, not a folder' in capsys.readouterr().err


def test_a_bag_changed_since_it_was_written_is_refused(failure_bag, tmp_path, capsys):
    import shutil

    bag = tmp_path / 'bag'
    shutil.copytree(failure_bag, bag)
    mcap = next(bag.glob('*.mcap'))
    mcap.write_bytes(mcap.read_bytes()[:mcap.stat().st_size // 2])
    output = tmp_path / 'out'
    assert suite_cli.main([str(bag), '--output-dir', str(output)]) == 2
    assert f'scenario bag: bag {bag} is incomplete or corrupt' in capsys.readouterr().err
    assert not output.exists()


@pytest.mark.parametrize('given, worker', [('w0', '/w0'), ('/w1/', '/w1'), ('/a/b', '/a/b'),
                                           ('/', '/')])
def test_worker_names_are_namespaces(given, worker):
    assert suite_cli.parse_args(['x', '--external', '--worker', given]).worker == (worker,)


@pytest.mark.parametrize('given', ['/w0/../w0', '//w0', '0w', 'w 0', 'a-b'])
def test_a_worker_that_is_no_namespace_is_refused(given, capsys):
    with pytest.raises(SystemExit) as exit_info:
        suite_cli.parse_args(['x', '--external', '--worker', given])
    assert exit_info.value.code == 2
    assert '--worker must be a ROS namespace such as /w0' in capsys.readouterr().err


def test_the_summary_says_how_the_workers_ran_the_scenarios():
    assert suite_cli.worker_note('/w0', {'mode': 'clocked', 'real_time_factor': 3.0}) == (
        'worker /w0: clocked at 3x real time')
    assert suite_cli.worker_note('/w1', {'mode': 'lockstep', 'real_time_factor': 1.0}) == (
        'worker /w1: lockstep')
    assert suite_cli.worker_note('/w2', None) == 'worker /w2: its settings are unknown'
    progresses = [ScenarioProgress(entry(name), 1, 1) for name in 'ab']
    assert suite_cli.recorded_modes(progresses) == 'recorded: 2 lockstep'
    note = 'worker /w0: clocked at 3x real time'
    assert f'* {note}' in markdown_summary('s', progresses, 1.0, notes=[note])


def test_the_summary_warns_of_a_worker_whose_episodes_differ_from_the_recordings():
    """A worker started with a longer stuck window turns recorded `stuck` failures green:
    the summary says so, where the verdicts' reason is read."""
    def recorded(name: str, stuck_timeout: float) -> ScenarioProgress:
        episode = {'scenario': 'factory', 'environment_id': name,
                   'simulator': {'mode': 'clocked', 'stuck_timeout': stuck_timeout,
                                 'real_time_factor': 1.0, 'dummy_agents': 2}}
        return ScenarioProgress(SuiteEntry(name, Path('/nowhere'), episode, 'stuck'), 1, 1)

    progresses = [recorded('a', 10.0), recorded('b', 10.0), recorded('c', 60.0)]
    worker = {'mode': 'clocked', 'real_time_factor': 2.0, 'stuck_timeout': 60.0,
              'dummy_agents': 2}
    assert suite_cli.setting_differences('/w0', worker, progresses) == [
        'WARNING: worker /w0 runs with stuck_timeout 60.0, recorded: 10.0 in 2 scenarios (a '
        'verdict may change for that, not for the stack)']  # pace and mode: worker_note
    assert suite_cli.setting_differences('/w0', {**worker, 'stuck_timeout': 10.0},
                                         progresses[:2]) == []
    assert suite_cli.setting_differences('/w0', None, progresses) == []


@pytest.mark.parametrize('timeout', ['-5', 'nan', 'inf'])
def test_an_episode_timeout_that_is_none_is_refused(timeout, capsys):
    with pytest.raises(SystemExit) as exit_info:
        suite_cli.parse_args(['x', '--external', '--episode-timeout', timeout])
    assert exit_info.value.code == 2
    assert 'episode_timeout must lie in [0, ' in capsys.readouterr().err
