"""The train command's whole-run ETA: the model's figure at first, then the model scaled by the
run's measured speed, so it tracks the true time left without jumps."""

from __future__ import annotations

import pytest

from sessgan_gen.model import pyramid_scale_shapes
from sessgan_gen.train_cli import TotalEta
from sessgan_gen.training import estimated_training_seconds

pytestmark = pytest.mark.unit


def test_the_eta_tracks_a_run_three_times_slower_than_the_model_without_jumps():
    shapes = pyramid_scale_shapes(128, 128)
    iterations = 100
    now = [0.0]
    eta = TotalEta(shapes, iterations, 32, 48, clock=lambda: now[0])
    per_iteration = [3 * estimated_training_seconds([shape], 1, 32, 48) for shape in shapes]
    total = sum(iterations * cost for cost in per_iteration) + len(shapes)
    first = eta.estimate(0, 0)
    assert first == pytest.approx(estimated_training_seconds(shapes, iterations, 32, 48))
    estimates = []
    for scale, cost in enumerate(per_iteration):
        now[0] += 1.0  # a scale's set-up, which the old ETA took for its iteration rate
        for done in range(1, iterations + 1):
            now[0] += cost
            estimates.append((now[0], eta.estimate(scale, done)))
    for (when, left), (_, after) in zip(estimates, estimates[1:]):
        if when >= TotalEta.MIN_MEASURED_SECONDS:
            # The set-up seconds inflate the first rate; never more than the truth allows.
            assert (total - when) / 2.5 <= left <= 2.5 * (total - when) + 1.0
            assert after <= left * 1.25 + 1.0  # no jump (the old ETA: 115 h, then 7 min)
        if when >= 0.1 * total:
            assert left == pytest.approx(total - when, rel=0.25, abs=2.0)
    assert estimates[-1][1] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize('saved', [False, True])
def test_an_interrupted_training_advises_resume_only_when_a_scale_was_saved(
        tmp_path, monkeypatch, capsys, saved):
    from sessgan_gen import train_cli

    output = tmp_path / 'g.pt'
    if saved:
        output.write_bytes(b'a checkpoint of a finished scale')

    def interrupted(config, training_map):
        raise KeyboardInterrupt

    monkeypatch.setattr(train_cli, 'train', interrupted)
    assert train_cli.run_training(['--output', str(output), '--iterations', '1']) == 130
    err = capsys.readouterr().err
    assert ('run again with --resume' in err) == saved
    assert ('nothing was saved' in err) != saved
