"""Bags of in-process episodes, fault pictures from them, and confirmed fault records."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sessgan_core.token_map import load_example_map
from sessgan_core.valid_tests import make_environment
from sessgan_evolver.bag_export import BagExportError, trace_records, write_trace_bag
from sessgan_evolver.bag_reading import iter_bag_messages, read_bag_topics
from sessgan_evolver.fault_picture import (
    certified_route,
    scene_from_bag,
    scene_from_run,
    write_scene_grid,
    write_scene_png,
)
from sessgan_evolver.fault_records import confirm_faults
from sessgan_evolver.faults import FaultRule, group_faults
from sessgan_evolver.in_process import InProcessEvaluator
from sessgan_evolver.search import EpisodeLog
from sessgan_sim.bag_recording import FAULT_PICTURE_FILE, jazzy_typestore

pytestmark = pytest.mark.unit


@pytest.fixture(scope='module')
def episode():
    environment = make_environment(load_example_map('factory').cells, 'factory', 'example')
    with InProcessEvaluator('factory', time_limit=3.0) as evaluator:
        run = evaluator.run_environment(environment, 2, keep_scans=True)
    return environment, run


def test_a_trace_becomes_a_bag_of_the_workers_topics(episode, tmp_path):
    environment, run = episode
    bag = write_trace_bag(tmp_path / 'bag', environment, run.trace, {'controller': 'nd'})
    counts = {topic.topic: topic.message_count for topic in read_bag_topics(bag)}
    ticks = run.metrics['ticks']
    assert counts == {'/map': 1, '/tf_static': 1, '/waypoints': 1, '/goal_pose': 1,
                      '/clock': ticks + 1,
                      '/odom': ticks + 1, '/tf': ticks + 1, '/scan': ticks + 1,
                      '/cmd_vel': ticks}
    store = jazzy_typestore()
    odom = [store.deserialize_cdr(m.data, m.msgtype) for m in iter_bag_messages(bag, ['/odom'])]
    assert np.allclose([(o.pose.pose.position.x, o.pose.pose.position.y) for o in odom],
                       run.trace.poses[:, :2])
    grid = store.deserialize_cdr(next(iter_bag_messages(bag, ['/map'])).data,
                                 'nav_msgs/msg/OccupancyGrid')
    assert np.array_equal(np.asarray(grid.data).reshape(32, 32), environment.occupancy)
    facts = json.loads((bag / 'episode.json').read_text())
    assert facts['controller'] == 'nd' and facts['environment_id'] == 'example'
    assert facts['trace']['contacts'] == run.metrics['contacts']
    assert facts['route_length'] == environment.route_length
    run.trace.scans, scans = None, run.trace.scans
    try:
        with pytest.raises(BagExportError, match='keep_scans'):
            list(trace_records(environment, run.trace))
    finally:
        run.trace.scans = scans


def test_a_flyer_trace_bag_has_range_down_altitude_and_climb_commands(tmp_path):
    environment = make_environment(load_example_map('drone').cells, 'drone', 'example')
    with InProcessEvaluator('drone', time_limit=2.0) as evaluator:
        run = evaluator.run_environment(environment, 1, keep_scans=True)
    bag = write_trace_bag(tmp_path / 'bag', environment, run.trace, {})
    ticks = run.metrics['ticks']
    counts = {topic.topic: topic.message_count for topic in read_bag_topics(bag)}
    assert counts['/range_down'] == counts['/scan'] == ticks + 1
    store = jazzy_typestore()
    ranges = [store.deserialize_cdr(m.data, m.msgtype)
              for m in iter_bag_messages(bag, ['/range_down'])]
    assert ranges[0].header.frame_id == 'base_range_down'
    odom = [store.deserialize_cdr(m.data, m.msgtype) for m in iter_bag_messages(bag, ['/odom'])]
    altitudes = np.array([o.pose.pose.position.z for o in odom])
    # It takes off: the altitude rises from the ground and the ranger reads it over free ground.
    assert altitudes[0] == 0.0 and altitudes[-1] > 0.5
    assert np.allclose(altitudes, run.trace.vertical[:, 0])
    assert np.allclose([r.range for r in ranges], run.trace.range_down, atol=1e-6)
    commands = [store.deserialize_cdr(m.data, m.msgtype)
                for m in iter_bag_messages(bag, ['/cmd_vel'])]
    assert commands[0].linear.z > 0.0
    static = store.deserialize_cdr(next(iter_bag_messages(bag, ['/tf_static'])).data,
                                   'tf2_msgs/msg/TFMessage')
    assert [t.child_frame_id for t in static.transforms] == ['base_link', 'base_scan',
                                                            'base_range_down']


def test_pictures_from_a_run_and_from_its_bag(episode, tmp_path):
    environment, run = episode
    route = certified_route(environment)
    assert np.allclose(route[0], (environment.start.x, environment.start.y))
    assert np.allclose(route[-1], (environment.goal.x, environment.goal.y))
    assert np.hypot(*np.diff(route, axis=0).T).sum() == pytest.approx(environment.route_length)
    scene = scene_from_run(environment, run.trace, run.metrics)
    assert np.array_equal(scene.route, route)
    assert len(scene.trajectory) == run.metrics['ticks'] + 1
    bag = write_trace_bag(tmp_path / 'bag', environment, run.trace, {})
    from_bag = scene_from_bag(bag)
    assert np.allclose(from_bag.trajectory, scene.trajectory)
    assert np.allclose(from_bag.route, route) and from_bag.contacts == scene.contacts
    assert write_scene_png(from_bag, tmp_path / 'fault.png').stat().st_size > 10_000
    grid = write_scene_grid([('a', [scene, from_bag]), ('b', [])], tmp_path / 'grid.png', 3)
    assert grid.stat().st_size > 10_000


def test_confirmed_faults_get_a_bag_and_a_picture(tmp_path):
    rule = FaultRule()
    log = EpisodeLog(rule)
    environments = [make_environment(load_example_map('factory').cells, 'factory', 'example')]
    with InProcessEvaluator('factory', time_limit=6.0, observer=log) as evaluator:
        for seed in range(3):
            evaluator.run_environment(environments[0], seed)
        faults = group_faults([record.fault for record in log.records])
        assert faults, 'the Nearness-Diagram robot fails on the example map within 6 s'
        written = confirm_faults(faults, log.records, evaluator, rule, repeats=2,
                                 record_directory=tmp_path, max_records=1,
                                 metadata={'method': 'test'})
        assert all(entry.confirmation.confirmed and entry.confirmation.exact == 2
                   for entry in faults)
        every = confirm_faults(faults, log.records, evaluator, rule, repeats=1,
                               record_directory=tmp_path / 'all', max_records=-1)
        # A comparison stopped after writing its records and run again into the same
        # folder replaces them (it used to refuse: the picture made the bag foreign).
        again = confirm_faults(faults, log.records, evaluator, rule, repeats=1,
                               record_directory=tmp_path / 'all', max_records=-1)
    assert len(every) == len(faults) and again == every
    assert all((path / FAULT_PICTURE_FILE).is_file() for path in again)
    assert len(written) == 1 and (written[0] / FAULT_PICTURE_FILE).stat().st_size > 10_000
    facts = json.loads((written[0] / 'episode.json').read_text())
    assert facts['fault'] == faults[0].key.to_dict() and facts['method'] == 'test'
    assert facts['confirmation']['reproduced'] == 2
    assert written[0].name == f'000-{faults[0].key.label}'
