"""Where failure bags may be written and cleaned up, and how replay knows a bag is intact
(issue 19: a client-chosen record directory, silent corruption, malformed episode.json)."""

from __future__ import annotations

import json
import os
import socket
import struct
import zlib

import pytest

from sessgan_evolver import replay_cli
from sessgan_evolver.bag_reading import (
    BagReadError,
    check_bag_complete,
    check_episode_fields,
    verify_bag_files,
)
from sessgan_sim.bag_recording import (
    STAGING_MARKER,
    BagWriteError,
    add_mcap_chunk_crcs,
    check_record_subdirectory,
    record_directory_under,
    remove_stale_staging_directories,
    write_episode_bag,
)
from tests.unit.evolver.killed_bag_writer import killed_writer_staging
from tests.unit.evolver.test_failure_bags import (
    METADATA,
    OCCUPANCY,
    ORIGIN,
    RESOLUTION,
    serialized_records,
    snapshot,
)

pytestmark = pytest.mark.unit

EPISODE = {**METADATA, 'scenario': 'factory', 'start': [1.0, 1.0, 0.0], 'goal': [5.0, 5.0, 0.0],
           'episode_seed': 3, 'time_limit': 20.0, 'robot': 'diff_drive',
           'metrics': {**METADATA['metrics'], 'distance_travelled': 1.5, 'ticks': 80}}


# ---- record directories under a bags root ---------------------------------------------------

@pytest.mark.parametrize('subdirectory', ['run', 'factory-seed0', 'run/sub', 'a.b_c-d/x'])
def test_relative_subdirectories_are_accepted(tmp_path, subdirectory):
    assert check_record_subdirectory(subdirectory) == subdirectory
    assert record_directory_under(tmp_path, subdirectory) == tmp_path.resolve() / subdirectory


@pytest.mark.parametrize('subdirectory', [
    '', '/tmp/outside', '../outside', 'run/../../outside', '..', 'a//b', 'run/', './run',
    'run\n', 'with space', 'a/b/c/d/e', 'victim.tmp-999999', 'x' * 129, None])
def test_absolute_escaping_and_odd_subdirectories_are_refused(tmp_path, subdirectory):
    with pytest.raises(BagWriteError, match='relative subdirectory of the simulator'):
        record_directory_under(tmp_path / 'root', subdirectory)
    assert list(tmp_path.iterdir()) == []


def test_a_symbolic_link_out_of_the_root_is_refused(tmp_path):
    (tmp_path / 'root').mkdir()
    (tmp_path / 'outside').mkdir()
    (tmp_path / 'root' / 'run').symlink_to(tmp_path / 'outside')
    with pytest.raises(BagWriteError, match='leads out of the bags root'):
        record_directory_under(tmp_path / 'root', 'run')


# ---- staging directories: removed only with a marker that proves them ours ------------------

def test_only_marked_staging_directories_of_dead_writers_are_removed(tmp_path):
    record = tmp_path / 'run'
    record.mkdir()
    stale = killed_writer_staging(record)
    assert (stale / STAGING_MARKER).is_file()  # the writer's first file
    # The victim: named like a staging directory of a dead pid, but nobody's bag.
    victim = record / 'victim.tmp-999999'
    victim.mkdir()
    (victim / 'precious.txt').write_text('keep me')
    # A forged marker of another format, and a marker whose pid is not the name's.
    forged = record / 'forged.tmp-999998'
    forged.mkdir()
    (forged / STAGING_MARKER).write_text('{"pid": 999998}')
    renamed = record / 'renamed.tmp-999997'
    killed_writer_staging(tmp_path, 'other').rename(renamed)
    # A live writer (this process) and one of another host (a shared file system).
    live = killed_writer_staging(tmp_path, 'live')
    marker = json.loads((live / STAGING_MARKER).read_text())
    live_path = record / f'live.tmp-{os.getpid()}'
    live.rename(live_path)
    (live_path / STAGING_MARKER).write_text(json.dumps(
        {**marker, 'pid': os.getpid(),
         'process_start': int(open(f'/proc/{os.getpid()}/stat').read().rsplit(')', 1)[1]
                              .split()[19])}))
    elsewhere = killed_writer_staging(record, 'elsewhere')
    elsewhere_marker = json.loads((elsewhere / STAGING_MARKER).read_text())
    (elsewhere / STAGING_MARKER).write_text(json.dumps(
        {**elsewhere_marker, 'host': socket.gethostname() + '-other'}))
    kept = snapshot(tmp_path)

    assert remove_stale_staging_directories(record) == [stale]
    assert snapshot(tmp_path) == [entry for entry in kept
                                  if not entry[0].startswith(str(stale.relative_to(tmp_path)))]
    assert (victim / 'precious.txt').read_text() == 'keep me'


def test_a_reused_pid_does_not_keep_a_dead_writers_staging_directory(tmp_path):
    staging = killed_writer_staging(tmp_path)
    marker = json.loads((staging / STAGING_MARKER).read_text())
    parent = os.getppid()  # alive, but started at another time than the recorded writer
    reused = tmp_path / f'g000-m01-s5.tmp-{parent}'
    staging.rename(reused)
    (reused / STAGING_MARKER).write_text(json.dumps(
        {**marker, 'pid': parent, 'process_start': 1}))
    assert remove_stale_staging_directories(tmp_path) == [reused]


def test_a_foreign_directory_with_the_writers_staging_name_is_not_removed(tmp_path):
    foreign = tmp_path / f'episode.tmp-{os.getpid()}'
    foreign.mkdir()
    (foreign / 'precious.txt').write_text('keep me')
    with pytest.raises(BagWriteError, match='not the staging directory of a failure bag'):
        write_episode_bag(tmp_path / 'episode', serialized_records(), METADATA, OCCUPANCY,
                          RESOLUTION, ORIGIN)
    assert (foreign / 'precious.txt').read_text() == 'keep me'
    assert not (tmp_path / 'episode').exists()


# ---- silent corruption -----------------------------------------------------------------------

def chunk_crcs(mcap_file) -> list[int]:
    data = mcap_file.read_bytes()
    offset, crcs = 8, []
    while True:
        opcode, length = struct.unpack_from('<BQ', data, offset)
        if opcode == 0x02:
            return crcs
        if opcode == 0x06:
            crcs.append(struct.unpack_from('<I', data, offset + 9 + 24)[0])
        offset += 9 + length


def flip_middle(path, count: int = 64) -> None:
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    for index in range(middle - count // 2, middle + count // 2):
        data[index] ^= 0xFF
    path.write_bytes(bytes(data))


def flip_inside_a_scan(path, count: int = 64) -> None:
    """Flip ``count`` bytes amid the ranges of the first /scan message (lengths and headers
    intact: without CRCs every message still decodes, one with wrong ranges)."""
    scan = next(record.data for record in serialized_records() if record.topic == '/scan')
    data = bytearray(path.read_bytes())
    start = data.find(scan) + len(scan) // 2 - count // 2
    assert start > 0
    for index in range(start, start + count):
        data[index] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.fixture
def bag(tmp_path):
    return write_episode_bag(tmp_path / 'g003-m07-s12', serialized_records(), EPISODE, OCCUPANCY,
                             RESOLUTION, ORIGIN)


def test_mcap_chunks_carry_crcs_and_episode_json_the_digests(bag):
    mcap_file = bag / 'g003-m07-s12.mcap'
    crcs = chunk_crcs(mcap_file)
    assert crcs and all(crcs)
    files = json.loads((bag / 'episode.json').read_text())['files']
    assert sorted(files) == ['g003-m07-s12.mcap', 'map.pgm', 'map.yaml', 'metadata.yaml']
    assert files['g003-m07-s12.mcap']['size'] == mcap_file.stat().st_size
    assert verify_bag_files(bag) is None
    assert add_mcap_chunk_crcs(mcap_file) == len(crcs)  # idempotent: the same CRCs again
    assert chunk_crcs(mcap_file) == crcs


def test_a_bag_with_flipped_bytes_is_refused_naming_the_file(bag, capsys):
    mcap_file = bag / 'g003-m07-s12.mcap'
    flip_middle(mcap_file)
    with pytest.raises(BagReadError, match=f'SHA-256 digest of {mcap_file} is'):
        verify_bag_files(bag)
    assert replay_cli.main([str(bag)]) == 2
    assert str(mcap_file) in capsys.readouterr().err
    assert replay_cli.main([str(bag), '--resimulate']) == 2
    assert 'corrupt' in capsys.readouterr().err


def test_without_digests_the_chunk_crcs_still_catch_the_corruption(bag, capsys):
    episode = json.loads((bag / 'episode.json').read_text())
    del episode['files']  # a bag of an older version lists no digests
    (bag / 'episode.json').write_text(json.dumps(episode))
    assert 'records no file digests' in verify_bag_files(bag)
    assert check_bag_complete(bag) == len(serialized_records())
    flip_inside_a_scan(bag / 'g003-m07-s12.mcap')
    with pytest.raises(BagReadError, match='checksum mismatch'):
        check_bag_complete(bag)
    assert replay_cli.main([str(bag)]) == 2
    err = capsys.readouterr().err
    assert 'warning:' in err and 'checksum mismatch' in err


def test_a_bag_without_episode_json_says_so(bag):
    (bag / 'episode.json').unlink()  # replayable, but nothing to check its files against
    assert 'has no episode.json' in verify_bag_files(bag)


def test_a_changed_side_file_is_refused(bag):
    (bag / 'map.yaml').write_text((bag / 'map.yaml').read_text().replace('0.5', '0.25'))
    with pytest.raises(BagReadError, match='map.yaml'):
        verify_bag_files(bag)


# ---- malformed episode.json ------------------------------------------------------------------

def test_the_recorded_episode_passes_the_field_checks(bag):
    check_episode_fields(json.loads((bag / 'episode.json').read_text()), 'episode.json')


@pytest.mark.parametrize(('field', 'value', 'message'), [
    ('start', 5, 'field "start" must be a list'),
    ('goal', ['a', 1], 'field "goal" must be a list'),
    ('episode_seed', 'x', 'field "episode_seed" must be an integer'),
    ('stations', [[1.0]], 'field "stations"'),
    ('fleet', [{'start': 1}], 'field "fleet"'),
    ('metrics', {'outcome': 'stuck'}, 'field "metrics.collisions" is missing'),
    ('scenario', None, 'field "scenario" must be a string'),
    # It names the bag directory re-simulation writes: no path may escape through it.
    ('environment_id', '../../pwn', 'field "environment_id" must be a safe name'),
])
def test_resimulate_names_a_malformed_field_and_exits_2(bag, capsys, field, value, message):
    episode = json.loads((bag / 'episode.json').read_text())
    episode[field] = value
    (bag / 'episode.json').write_text(json.dumps(episode))
    assert replay_cli.main([str(bag), '--resimulate']) == 2
    err = capsys.readouterr().err
    assert message in err and 'episode.json' in err and 'Traceback' not in err


def test_chunk_crc_is_the_crc_of_the_chunk_records(bag):
    """An independent check of the field's position: recompute it from the record layout."""
    data = (bag / 'g003-m07-s12.mcap').read_bytes()
    offset = 8
    while data[offset] != 0x06:
        offset += 9 + struct.unpack_from('<Q', data, offset + 1)[0]
    body = data[offset + 9:]
    compression_length = struct.unpack_from('<I', body, 28)[0]
    records_length = struct.unpack_from('<Q', body, 32 + compression_length)[0]
    records = body[40 + compression_length:40 + compression_length + records_length]
    assert struct.unpack_from('<I', body, 24)[0] == zlib.crc32(records)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_digests_survive_reading_and_catch_flipped_bytes_in_either_storage(tmp_path, storage):
    bag = write_episode_bag(tmp_path / 'episode', serialized_records(), EPISODE, OCCUPANCY,
                            RESOLUTION, ORIGIN, storage=storage)
    assert check_bag_complete(bag) == len(serialized_records())
    assert verify_bag_files(bag) is None  # reading the bag changed none of its files
    storage_file = next(path for path in bag.iterdir() if path.suffix in ('.mcap', '.db3'))
    flip_middle(storage_file)
    with pytest.raises(BagReadError, match=f'SHA-256 digest of {storage_file} is'):
        verify_bag_files(bag)


def test_replay_takes_namespaces_and_refuses_what_is_none(capsys):
    args = replay_cli.parse_args(['bag', '--worker', 'w0', '--namespace', '/robot/'])
    assert (args.worker, args.namespace) == ('/w0', '/robot')
    with pytest.raises(SystemExit) as exit_info:
        replay_cli.parse_args(['bag', '--worker', '/w0/../w0'])
    assert exit_info.value.code == 2
    assert '--worker must be a ROS namespace such as /w0' in capsys.readouterr().err
