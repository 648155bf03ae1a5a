"""The campaign loop without ROS: an in-process evaluator runs the real simulator core and
controller, so sampling, fitness, checkpoints, resume and the report are exercised end to end."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import torch

from sessgan_controllers.controller_interface import Goal, observed
from sessgan_controllers.registry import get_controller
from sessgan_evolver.campaign import Campaign, CampaignConfig, CampaignError, CampaignResult
from sessgan_evolver.campaign_cli import (
    campaign_parser,
    config_from_args,
    invocation_of,
    parse_args,
)
from sessgan_gen.checkpoint import save_checkpoint
from sessgan_gen.environment_sampler import EnvironmentSampler
from sessgan_gen.errors import CheckpointError
from sessgan_gen.model import GeneratorPyramid, pyramid_scale_shapes
from sessgan_sim.episode import Episode, EpisodeConfig

pytestmark = pytest.mark.unit
torch.set_num_threads(1)


class Interrupted(Exception):
    pass


class InProcessEvaluator:
    """Generator and simulator in this process: what the ROS graph does, minus the messages."""

    harness_reruns = 0

    def __init__(self, interrupt_at_generation: int | None = None) -> None:
        self.sampler = EnvironmentSampler()
        self.interrupt_at_generation = interrupt_at_generation

    def sample(self, weights, seeds, generation, member):
        return self.sampler.sample(seeds, weights, 'factory', generation=generation,
                                   member=member)

    def evaluate(self, jobs, on_result):
        for job in jobs:
            if job.generation == self.interrupt_at_generation:
                raise Interrupted()
            on_result(job, self.run(job))

    def run(self, job) -> dict:
        controller = get_controller('nearness_diagram').make()
        goal = Goal(job.environment.goal.x, job.environment.goal.y)
        with Episode() as episode:
            observation = episode.reset(job.environment,
                                        EpisodeConfig(seed=job.seed, time_limit=4.0))
            while not episode.done:
                command = controller.compute_command(*observed(observation), goal)
                observation = episode.step(command.values()).observation
            metrics = episode.metrics().to_dict()
        return metrics


@pytest.fixture(scope='module')
def checkpoint(tmp_path_factory):
    torch.manual_seed(0)
    pyramid = GeneratorPyramid(2, pyramid_scale_shapes(32, 32), channels=8)
    pyramid.noise_amplitudes.fill_(0.5)
    pyramid.reconstruction_noise.normal_()
    return str(save_checkpoint(tmp_path_factory.mktemp('gen') / 'tiny.pt', pyramid,
                               {'scenario': 'factory', 'tokens': ['G', 'W'], 'seed': 0}))


def config(checkpoint: str) -> CampaignConfig:
    return CampaignConfig(scenario='factory', generations=3, population=3, maps_per_member=2,
                          workers=1, seed=11, checkpoint=checkpoint, time_limit=4.0)


def rows(run_dir) -> list[dict]:
    with open(run_dir / 'metrics_episodes.csv') as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope='module')
def straight(checkpoint, tmp_path_factory) -> tuple[Path, CampaignResult]:
    """The runs root and result of an uninterrupted campaign (config()), run once for the
    tests that read it."""
    root = tmp_path_factory.mktemp('straight')
    campaign = Campaign(config(checkpoint), 'straight', root / 'runs', root / 'bags',
                        log=lambda _: None)
    return root, campaign.run(InProcessEvaluator())


def test_campaign_runs_and_reports(checkpoint, straight):
    root, result = straight
    assert [row['generation'] for row in result.generations] == [0, 1, 2]
    assert len(rows(result.run_dir)) == 3 * 3 * 2
    assert result.report_path.exists()
    assert (result.run_dir / 'report' / 'generation_metrics.png').stat().st_size > 0
    # The same run name is not silently reused (refused before an episode runs).
    with pytest.raises(CampaignError, match='--resume'):
        Campaign(config(checkpoint), 'straight', root / 'runs', root / 'bags',
                 log=lambda _: None).run(InProcessEvaluator())


def test_resume_after_interruption_gives_the_uninterrupted_results(checkpoint, straight,
                                                                    tmp_path):
    _, uninterrupted = straight
    with pytest.raises(Interrupted):
        Campaign(config(checkpoint), 'killed', tmp_path / 'runs', tmp_path / 'bags',
                 log=lambda _: None).run(InProcessEvaluator(interrupt_at_generation=2))
    resumed = Campaign(config(checkpoint), 'killed', tmp_path / 'runs', tmp_path / 'bags',
                       log=lambda _: None).run(InProcessEvaluator(), resume=True)

    def comparable(run_dir):
        return [{k: v for k, v in row.items() if k != 'environment_id'} for row in rows(run_dir)]

    assert comparable(resumed.run_dir) == comparable(uninterrupted.run_dir)
    assert resumed.generations == uninterrupted.generations


def test_episode_timeout_grows_with_the_map_and_the_time_limit():
    short = CampaignConfig(scenario='factory', time_limit=20.0)
    assert short.episode_timeout_for(32 * 32) == pytest.approx(40.0 + 32 * 32 * 25e-5)
    assert CampaignConfig(time_limit=5.0).episode_timeout_for(0) == 30.0  # at least 30 s
    assert CampaignConfig(time_limit=200.0).episode_timeout_for(0) == 400.0
    # The largest map a simulator accepts took 22 s to build and 5.6 s per sim second:
    # measured times, with margin, fit into its timeout.
    cells = 1024 * 1024
    assert short.episode_timeout_for(cells) > 1.5 * (22.0 + 5.6 * 20.0)
    assert CampaignConfig(time_limit=60.0).episode_timeout_for(cells) > 1.5 * (22 + 5.6 * 60)
    assert CampaignConfig(episode_timeout=7.0).episode_timeout_for(cells) == 7.0


def test_a_bad_checkpoint_is_refused_before_a_run_directory_exists(tmp_path):
    (tmp_path / 'a_directory.pt').mkdir()
    for bad, reason in ((tmp_path / 'missing.pt', 'does not exist'),
                        (tmp_path / 'a_directory.pt', 'is a directory')):
        bad_config = CampaignConfig(scenario='factory', checkpoint=str(bad))
        with pytest.raises(CheckpointError, match=f'{bad.name}.* {reason}'):
            Campaign(bad_config, 'bad', tmp_path / 'runs', tmp_path / 'bags', log=lambda _: None)
    assert not (tmp_path / 'runs').exists() and not (tmp_path / 'bags').exists()


def test_every_campaign_option_is_in_config_json(checkpoint, tmp_path):
    argv = ['--method', 'sessgan', '--scenario', 'factory', '--generations', '1',
            '--population', '2',
            '--maps-per-member', '1', '--workers', '1', '--seed', '11', '--checkpoint',
            checkpoint, '--time-limit', '4', '--mode', 'clocked', '--external',
            '--fitness-tpkl-tolerance', '0.2', '--run', 'options', '--runs-root',
            str(tmp_path / 'runs')]
    args = parse_args(argv)
    config = config_from_args(args)
    assert (config.mode, config.external, config.fitness.tpkl_tolerance) == ('clocked', True, 0.2)
    Campaign(config, args.run, args.runs_root, tmp_path / 'bags', log=lambda _: None,
             invocation=invocation_of(args, argv)).run(InProcessEvaluator())
    document = json.loads((tmp_path / 'runs' / 'options' / 'config.json').read_text())
    assert document['config']['mode'] == 'clocked' and document['config']['external'] is True
    assert document['config']['fitness']['tpkl_tolerance'] == 0.2
    assert document['invocation']['command_line'][4:] == argv
    assert document['invocation']['runs_root'] == str(tmp_path / 'runs')
    # Every option of the command line is a config field or an invocation entry.
    options = {action.dest for action in campaign_parser()._actions}
    stored = set(document['config']) | {f'fitness_{name}' for name in
                                        document['config']['fitness']}
    assert options - {'help'} <= stored | set(document['invocation'])



def test_bag_storage_is_checked_against_the_storage_registry():
    from sessgan_sim.bag_recording import BagStorage

    for storage in BagStorage:
        CampaignConfig(bag_storage=storage.value).validate()
    with pytest.raises(CampaignError, match=r"one of \['mcap', 'sqlite3'\], got 'zip'"):
        CampaignConfig(bag_storage='zip').validate()
