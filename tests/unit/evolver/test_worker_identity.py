"""A discovered worker of another version, or set up for another scenario's robot, is refused
with the difference named (issue 24)."""

from __future__ import annotations

import json

import pytest

from sessgan_evolver.worker_identity import worker_difference

pytestmark = pytest.mark.unit


def test_a_matching_worker_is_accepted():
    for robot in ('', 'diff_drive'):
        assert worker_difference('/w0/evaluate', '0.1.0', json.dumps({'robot': robot}),
                                 '0.1.0', 'diff_drive', 'factory') is None


def test_another_version_is_named():
    why = worker_difference('/w1/evaluate', '0.0.9', '{}', '0.1.0', 'diff_drive', 'factory')
    assert why == ('worker /w1/evaluate runs sessgan 0.0.9, this campaign 0.1.0: install the '
                   'same version on every host')


def test_a_worker_for_another_scenarios_robot_is_named():
    why = worker_difference('/w1/evaluate', '0.1.0', json.dumps({'robot': 'car'}), '0.1.0',
                            'diff_drive', 'factory')
    assert "hosts robot 'car'" in why and "scenario factory needs 'diff_drive'" in why


def test_malformed_settings_are_named():
    assert 'malformed JSON' in worker_difference('/w1/evaluate', '0.1.0', '{', '0.1.0',
                                                 'diff_drive', 'factory')
