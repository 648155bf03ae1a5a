"""Failure bags: write with sessgan_sim.bag_recording, read with sessgan_evolver.bag_reading."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import yaml
from rosbags.typesys import Stores, get_typestore

from sessgan_core.environment import check_environment_id
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_evolver.bag_reading import (
    check_bag_complete,
    iter_bag_messages,
    read_bag_topics,
    read_episode_bag,
)
from sessgan_evolver.errors import BagReadError
from sessgan_sim.bag_recording import (
    BagRecord,
    BagWriteError,
    episode_bag_directory,
    is_episode_bag,
    remove_stale_staging_directories,
    write_episode_bag,
)

pytestmark = pytest.mark.unit

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
T = TYPESTORE.types
OCCUPANCY = np.zeros((6, 8), dtype=np.int8)
OCCUPANCY[0, :] = 100
OCCUPANCY[3, 2:5] = 50
RESOLUTION = 0.5
ORIGIN = (-1.0, -2.0, 0.0)
METADATA = {'environment_id': 'g003-m07-s12', 'generation': 3, 'member': 7, 'seed': 12,
            'controller': 'nearness_diagram',
            'metrics': {'outcome': 'collision_limit', 'collisions': 2,
                        'proximity_time': np.float64(1.5), 'simulation_time': 4.0,
                        'risk_score': 0.75, 'feasible': np.bool_(True)}}


def stamp(ns: int):
    return T['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9)


def header(ns: int, frame: str):
    return T['std_msgs/msg/Header'](stamp=stamp(ns), frame_id=frame)


def pose(x: float, y: float):
    return T['geometry_msgs/msg/Pose'](
        position=T['geometry_msgs/msg/Point'](x=x, y=y, z=0.0),
        orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0))


def transform(ns: int, parent: str, child: str, x: float):
    return T['geometry_msgs/msg/TransformStamped'](
        header=header(ns, parent), child_frame_id=child,
        transform=T['geometry_msgs/msg/Transform'](
            translation=T['geometry_msgs/msg/Vector3'](x=x, y=0.0, z=0.0),
            rotation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)))


def twist(vx: float, wz: float):
    vector = T['geometry_msgs/msg/Vector3']
    return T['geometry_msgs/msg/Twist'](linear=vector(x=vx, y=0.0, z=0.0),
                                        angular=vector(x=0.0, y=0.0, z=wz))


def episode_messages() -> list[tuple[str, str, int, object]]:
    """An episode's worth of typed messages: latched ones first, then three ticks."""
    start = 10**9
    info = T['nav_msgs/msg/MapMetaData'](map_load_time=stamp(start), resolution=RESOLUTION,
                                         width=8, height=6, origin=pose(-1.0, -2.0))
    messages = [
        ('/map', 'nav_msgs/msg/OccupancyGrid', start, T['nav_msgs/msg/OccupancyGrid'](
            header=header(start, 'map'), info=info, data=OCCUPANCY.ravel().copy())),
        ('/tf_static', 'tf2_msgs/msg/TFMessage', start, T['tf2_msgs/msg/TFMessage'](
            transforms=[transform(start, 'base_footprint', 'base_link', 0.0),
                        transform(start, 'base_link', 'base_scan', 0.1)])),
        ('/goal_pose', 'geometry_msgs/msg/PoseStamped', start,
         T['geometry_msgs/msg/PoseStamped'](header=header(start, 'map'), pose=pose(2.0, 1.0))),
    ]
    for tick in range(3):
        ns = start + tick * 50_000_000
        messages += [
            ('/clock', 'rosgraph_msgs/msg/Clock', ns, T['rosgraph_msgs/msg/Clock'](
                clock=stamp(ns))),
            ('/scan', 'sensor_msgs/msg/LaserScan', ns, T['sensor_msgs/msg/LaserScan'](
                header=header(ns, 'base_scan'), angle_min=-3.14, angle_max=3.14,
                angle_increment=0.0175, time_increment=0.0, scan_time=0.05, range_min=0.05,
                range_max=8.0, ranges=np.linspace(0.5, 3.0, 360, dtype=np.float32),
                intensities=np.zeros(0, dtype=np.float32))),
            ('/odom', 'nav_msgs/msg/Odometry', ns, T['nav_msgs/msg/Odometry'](
                header=header(ns, 'odom'), child_frame_id='base_footprint',
                pose=T['geometry_msgs/msg/PoseWithCovariance'](
                    pose=pose(0.1 * tick, 0.0), covariance=np.zeros(36)),
                twist=T['geometry_msgs/msg/TwistWithCovariance'](
                    twist=twist(0.2, 0.0), covariance=np.zeros(36)))),
            ('/tf', 'tf2_msgs/msg/TFMessage', ns, T['tf2_msgs/msg/TFMessage'](
                transforms=[transform(ns, 'map', 'odom', 0.0),
                            transform(ns, 'odom', 'base_footprint', 0.1 * tick)])),
            ('cmd_vel', 'geometry_msgs/msg/Twist', ns + 1_000_000, twist(0.2, 0.1 * tick)),
        ]
    return messages


def serialized_records() -> list[BagRecord]:
    return [BagRecord(topic, msgtype, ns, bytes(TYPESTORE.serialize_cdr(message, msgtype)))
            for topic, msgtype, ns, message in episode_messages()]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_write_then_read_returns_every_message_unchanged(tmp_path, storage):
    records = serialized_records()
    target = tmp_path / 'bags' / 'run' / 'g003-m07-s12'
    path = write_episode_bag(target, iter(records), METADATA, OCCUPANCY, RESOLUTION, ORIGIN,
                             storage=storage)
    assert path == target
    suffix = '.mcap' if storage == 'mcap' else '.db3'
    assert (target / f'g003-m07-s12{suffix}').is_file()
    assert {'metadata.yaml', 'map.pgm', 'map.yaml', 'episode.json'} <= {
        p.name for p in target.iterdir()}
    assert sorted(p.name for p in target.parent.iterdir()) == ['g003-m07-s12']

    topics, messages, episode = read_episode_bag(target)
    expected = [(r.topic if r.topic.startswith('/') else '/' + r.topic, r.msgtype,
                 r.timestamp_ns, r.data) for r in records]
    got = [tuple(message) for message in messages]
    assert sorted(got, key=lambda m: (m[2], m[0])) == sorted(expected,
                                                              key=lambda m: (m[2], m[0]))
    assert [m[2] for m in got] == sorted(m[2] for m in got)  # timestamp order

    by_topic = {topic.topic: topic for topic in topics}
    assert set(by_topic) == {'/map', '/tf_static', '/goal_pose', '/clock', '/scan', '/odom',
                             '/tf', '/cmd_vel'}
    assert by_topic['/scan'].message_count == 3 and by_topic['/map'].message_count == 1
    # As the simulator publishes them: a late reader still gets the map and the goal.
    for latched in ('/map', '/tf_static', '/goal_pose'):
        assert by_topic[latched].durability == 'transient_local'
        assert by_topic[latched].reliability == 'reliable' and by_topic[latched].depth == 1
    assert by_topic['/scan'].durability == 'volatile'
    assert by_topic['/odom'].msgtype == 'nav_msgs/msg/Odometry'

    grid = next(TYPESTORE.deserialize_cdr(data, msgtype) for topic, msgtype, _, data in got
                if topic == '/map')
    assert np.array_equal(np.asarray(grid.data, dtype=np.int8).reshape(6, 8), OCCUPANCY)

    assert episode['member'] == 7 and episode['controller'] == 'nearness_diagram'
    assert episode['metrics']['proximity_time'] == 1.5 and episode['metrics']['feasible']
    assert episode['storage'] == storage and episode['software_version']
    assert episode['messages']['count'] == len(records)
    assert episode['messages']['topics']['/cmd_vel'] == 3
    assert episode['map']['resolution'] == RESOLUTION
    assert 'image: map.pgm' in (target / 'map.yaml').read_text()


def test_read_a_topic_subset(tmp_path):
    target = tmp_path / 'episode'
    write_episode_bag(target, serialized_records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    scans = list(iter_bag_messages(target, topics={'/scan'}))
    assert [m.topic for m in scans] == ['/scan'] * 3
    assert list(iter_bag_messages(target, topics={'/nothing'})) == []
    assert len(read_bag_topics(target / 'metadata.yaml')) == 8


def test_an_existing_bag_is_kept_unless_overwrite(tmp_path):
    target = tmp_path / 'episode'
    records = serialized_records()
    write_episode_bag(target, records, METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    with pytest.raises(BagWriteError, match='exists'):
        write_episode_bag(target, records, METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    write_episode_bag(target, records[:2], {**METADATA, 'member': 8}, OCCUPANCY, RESOLUTION,
                      ORIGIN, storage='sqlite3', overwrite=True)
    topics, messages, episode = read_episode_bag(target)
    assert episode['member'] == 8 and len(list(messages)) == 2
    assert not list(target.glob('*.mcap'))
    assert sorted(p.name for p in tmp_path.iterdir()) == ['episode']


def test_a_failure_mid_write_leaves_no_bag_and_no_staging(tmp_path):
    def records():
        yield from serialized_records()[:4]
        raise RuntimeError('simulator crashed')

    target = tmp_path / 'episode'
    with pytest.raises(RuntimeError, match='simulator crashed'):
        write_episode_bag(target, records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(('record', 'message'), [
    (('/x', 'unknown_msgs/msg/Thing', 0, b'\x00\x01\x00\x00'), 'unknown to the typestore'),
    (('/x', 'Twist', 0, b''), 'package/msg/Type'),
    (('/x', 'geometry_msgs/msg/Twist', -1, b''), 'timestamp'),
    (('/x', 'geometry_msgs/msg/Twist', 0, 'text'), 'CDR bytes'),
    (('/x', 'geometry_msgs/msg/Twist'), 'not \\(topic'),
])
def test_bad_records_are_rejected(tmp_path, record, message):
    with pytest.raises(BagWriteError, match=message):
        write_episode_bag(tmp_path / 'e', [record], METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    assert list(tmp_path.iterdir()) == []


def test_bad_arguments_are_rejected(tmp_path):
    records = serialized_records()
    with pytest.raises(BagWriteError, match='storage'):
        write_episode_bag(tmp_path / 'e', records, METADATA, OCCUPANCY, RESOLUTION, ORIGIN,
                          storage='rosbag1')
    with pytest.raises(BagWriteError, match='resolution'):
        write_episode_bag(tmp_path / 'e', records, METADATA, OCCUPANCY, 0.0, ORIGIN)
    with pytest.raises(BagWriteError, match='JSON'):
        write_episode_bag(tmp_path / 'e', records, {'bad': object()}, OCCUPANCY, RESOLUTION,
                          ORIGIN)
    assert list(tmp_path.iterdir()) == []


def test_missing_and_corrupt_bags_raise_bag_read_error(tmp_path):
    with pytest.raises(BagReadError, match='does not exist'):
        read_episode_bag(tmp_path / 'missing')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagReadError, match='no metadata.yaml'):
        read_episode_bag(tmp_path / 'empty')
    for storage, suffix in (('mcap', '.mcap'), ('sqlite3', '.db3')):
        target = tmp_path / f'broken-{storage}'
        write_episode_bag(target, serialized_records(), METADATA, OCCUPANCY, RESOLUTION,
                          ORIGIN, storage=storage)
        storage_file = target / f'{target.name}{suffix}'
        storage_file.write_bytes(storage_file.read_bytes()[:40])
        with pytest.raises(BagReadError):
            _, messages, _ = read_episode_bag(target)
            list(messages)
    target = tmp_path / 'bad-json'
    write_episode_bag(target, serialized_records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    (target / 'episode.json').write_text('{"truncated": ')
    with pytest.raises(BagReadError, match='episode.json'):
        read_episode_bag(target)
    (target / 'episode.json').unlink()
    assert read_episode_bag(target).episode is None


def test_unmarked_staging_directories_are_never_removed(tmp_path):
    """Names alone prove nothing (issue 19): directories named like the staging directory of
    a dead or live writer, without the marker a writer creates first, stay (the marked ones
    of killed writers: tests/unit/evolver/test_bag_integrity.py)."""
    dead = tmp_path / f'episode.tmp-{2**22 + 12345}'
    dead.mkdir()
    alive = tmp_path / f'other.tmp-{os.getpid()}'
    alive.mkdir()
    (tmp_path / 'kept').mkdir()
    assert remove_stale_staging_directories(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(['kept', alive.name, dead.name])


def test_episode_json_is_plain_json(tmp_path):
    target = tmp_path / 'episode'
    write_episode_bag(target, serialized_records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    document = json.loads((target / 'episode.json').read_text())
    assert document['generation'] == 3 and document['map']['origin'] == list(ORIGIN)


# ---- ids are safe names: a bag never escapes its record directory or replaces foreign data

UNSAFE_IDS = ['', '../victim', '/tmp/elsewhere', 'a/b', '..', '.hidden', 'a..b', 'x' * 129,
              'g1.tmp-123', 'with space', 'tab\tid', 'é', '-leading-dash']


@pytest.mark.parametrize('episode_id', ['g003-m07-s12', 'factory-g000-m00-s5', 'free-3', 'A',
                                        'a.b_c-d', 'x' * 128])
def test_safe_ids_are_accepted(episode_id):
    assert check_environment_id(episode_id) == episode_id


@pytest.mark.parametrize('episode_id', UNSAFE_IDS + [None, 7])
def test_unsafe_ids_are_rejected(episode_id):
    with pytest.raises(InvalidEnvironmentError, match='environment id'):
        check_environment_id(episode_id)


def fill_record_directory(tmp_path):
    """A record directory with an earlier bag, and a victim directory beside it."""
    record = tmp_path / 'bags' / 'run'
    write_episode_bag(record / 'earlier', serialized_records(), METADATA, OCCUPANCY,
                      RESOLUTION, ORIGIN)
    victim = tmp_path / 'bags' / 'victim'
    victim.mkdir()
    (victim / 'precious.txt').write_text('keep me')
    return record, victim


def snapshot(root):
    return sorted((str(path.relative_to(root)), path.read_bytes() if path.is_file() else None)
                  for path in root.rglob('*'))


@pytest.mark.parametrize('episode_id', ['../victim', 'ABSOLUTE', ''])
def test_the_issue_cases_touch_nothing(tmp_path, episode_id):
    """An evaluate goal with id '../victim' replaced a sibling directory, an absolute path one
    outside the record directory, an empty id the record directory itself: now each is refused
    before the file system is touched."""
    record, victim = fill_record_directory(tmp_path)
    outside = tmp_path / 'outside'
    write_episode_bag(outside, serialized_records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    if episode_id == 'ABSOLUTE':
        episode_id = str(outside)
    before = snapshot(tmp_path)
    with pytest.raises(BagWriteError, match='refusing'):
        write_episode_bag(episode_bag_directory(record, episode_id), serialized_records(),
                          METADATA, OCCUPANCY, RESOLUTION, ORIGIN, overwrite=True)
    assert snapshot(tmp_path) == before
    if episode_id != str(outside):
        # The naive join the simulator used to make ('..' in the path, or the record
        # directory itself, which is no failure bag) is refused by the writer, too.
        with pytest.raises(BagWriteError):
            write_episode_bag(record / episode_id, serialized_records(), METADATA, OCCUPANCY,
                              RESOLUTION, ORIGIN, overwrite=True)
        assert snapshot(tmp_path) == before


@pytest.mark.parametrize('episode_id', UNSAFE_IDS)
def test_episode_bag_directory_refuses_every_unsafe_id(tmp_path, episode_id):
    with pytest.raises(BagWriteError, match='environment id'):
        episode_bag_directory(tmp_path, episode_id)
    assert list(tmp_path.iterdir()) == []


def test_overwrite_replaces_only_a_failure_bag(tmp_path):
    record, _ = fill_record_directory(tmp_path)
    foreign = record / 'g003-m07-s12'
    foreign.mkdir()
    (foreign / 'notes.txt').write_text('not a bag')
    (foreign / 'episode.json').write_text('{}')
    (foreign / 'metadata.yaml').write_text('looks like a bag, but holds more')
    assert not is_episode_bag(foreign) and is_episode_bag(record / 'earlier')
    before = snapshot(tmp_path)
    with pytest.raises(BagWriteError, match='not a failure bag'):
        write_episode_bag(foreign, serialized_records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN,
                          overwrite=True)
    assert snapshot(tmp_path) == before
    # An earlier failure bag of the same episode (a resumed campaign) is replaced.
    write_episode_bag(record / 'earlier', serialized_records()[:3], METADATA, OCCUPANCY,
                      RESOLUTION, ORIGIN, storage='sqlite3', overwrite=True)
    assert read_episode_bag(record / 'earlier').episode['messages']['count'] == 3


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_metadata_reads_as_jazzy_writes_it(tmp_path, storage):
    target = tmp_path / 'g003-m07-s12'
    write_episode_bag(target, serialized_records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN,
                      storage=storage)
    information = yaml.safe_load((target / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert information['ros_distro'] == 'jazzy'
    assert information['version'] == 9
    assert information['custom_data'] == {'sessgan.episode': 'g003-m07-s12',
                                          'sessgan.software_version': '0.1.0'}
    assert check_bag_complete(target) == len(serialized_records())


@pytest.mark.parametrize(('storage', 'suffix'), [('mcap', '.mcap'), ('sqlite3', '.db3')])
def test_a_truncated_bag_is_refused_as_incomplete(tmp_path, storage, suffix):
    target = tmp_path / 'episode'
    records = serialized_records() * 40  # large enough that half of it is mid-message
    write_episode_bag(target, records, METADATA, OCCUPANCY, RESOLUTION, ORIGIN,
                      storage=storage)
    assert check_bag_complete(target) == len(records)
    storage_file = target / f'episode{suffix}'
    storage_file.write_bytes(storage_file.read_bytes()[:storage_file.stat().st_size // 2])
    with pytest.raises(BagReadError, match='incomplete'):
        check_bag_complete(target)


def test_a_bag_with_fewer_messages_than_its_episode_json_is_refused(tmp_path):
    target = tmp_path / 'episode'
    write_episode_bag(target, serialized_records(), METADATA, OCCUPANCY, RESOLUTION, ORIGIN)
    episode = json.loads((target / 'episode.json').read_text())
    episode['messages']['count'] += 1
    (target / 'episode.json').write_text(json.dumps(episode))
    with pytest.raises(BagReadError, match='episode.json recorded'):
        check_bag_complete(target)
