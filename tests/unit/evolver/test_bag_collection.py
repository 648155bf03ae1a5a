"""Failure bags of remote workers copied into the campaign's bags/<run>/ (issue 24): the worker's
side (sessgan_sim.bag_serving) and the campaign's (sessgan_evolver.bag_collection) joined
directly, as the ``bags`` service joins them over ROS."""

from __future__ import annotations

import pytest

from sessgan_evolver.bag_collection import collect_bag
from sessgan_evolver.bag_reading import verify_bag_files
from sessgan_evolver.errors import BagCollectionError
from sessgan_sim.bag_recording import write_episode_bag
from sessgan_sim.bag_serving import MAX_CHUNK, BagServer
from sessgan_sim.errors import BagServeError
from tests.unit.evolver.test_bag_integrity import EPISODE
from tests.unit.evolver.test_failure_bags import (
    OCCUPANCY,
    ORIGIN,
    RESOLUTION,
    serialized_records,
)

pytestmark = pytest.mark.unit

BAG = 'run-1/g003-m07-s12'


@pytest.fixture
def server(tmp_path):
    """A worker's bags root holding one finished failure bag, BAG."""
    write_episode_bag(tmp_path / 'worker' / BAG, serialized_records(), EPISODE, OCCUPANCY,
                      RESOLUTION, ORIGIN)
    return BagServer(tmp_path / 'worker')


def files_of(directory) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(directory.iterdir())}


def test_a_collected_bag_is_byte_identical_and_the_worker_keeps_its_copy(server, tmp_path):
    worker_copy = tmp_path / 'worker' / BAG
    # Small chunks: every file arrives in several reads.
    copy = collect_bag(server, BAG, tmp_path / 'bags' / 'run-1', chunk_bytes=1000)
    assert copy == tmp_path / 'bags' / 'run-1' / 'g003-m07-s12'
    assert files_of(copy) == files_of(worker_copy)
    assert max(len(data) for data in files_of(copy).values()) > 3000
    assert verify_bag_files(copy) is None
    assert [path.name for path in copy.parent.iterdir()] == [copy.name]  # no staging left


def test_remove_deletes_the_workers_copy_once_collected(server, tmp_path):
    copy = collect_bag(server, BAG, tmp_path / 'bags', remove=True)
    assert verify_bag_files(copy) is None
    assert not (tmp_path / 'worker' / BAG).exists()


def test_a_file_corrupted_on_the_worker_is_refused_and_nothing_appears(server, tmp_path):
    (mcap,) = (tmp_path / 'worker' / BAG).glob('*.mcap')
    data = bytearray(mcap.read_bytes())
    data[len(data) // 2] ^= 0xFF
    mcap.write_bytes(bytes(data))
    with pytest.raises(BagCollectionError, match=f'SHA-256 digest of the copy of {mcap.name}'):
        collect_bag(server, BAG, tmp_path / 'bags', remove=True)
    assert not list((tmp_path / 'bags').iterdir())
    assert mcap.exists(), 'a bag that failed to arrive must stay on the worker'


class Lying:
    """A source that tells another story than the bag it serves."""

    def __init__(self, server: BagServer, listing=None, short=False, long=False) -> None:
        self.server, self.listing, self.short, self.long = server, listing, short, long

    def list_files(self, bag):
        files = self.server.list_files(bag)
        return self.listing(files) if self.listing else files

    def read(self, bag, name, offset, length):
        data = self.server.read(bag, name, offset, length)
        if self.short and name != 'episode.json':
            return b''
        return data + b'x' if self.long else data

    def remove(self, bag):
        raise AssertionError('nothing may be removed after a failed collection')


@pytest.mark.parametrize('source, message', [
    (lambda s: Lying(s, lambda files: {**files, 'extra.bin': 4}), 'lists .*extra.bin'),
    (lambda s: Lying(s, lambda files: {**files, '../escape': 4}), 'unsafe file name'),
    (lambda s: Lying(s, lambda files: {k: v for k, v in files.items() if k != 'episode.json'}),
     'has no episode.json'),
    (lambda s: Lying(s, lambda files: {k: (v + 1 if k == 'map.pgm' else v)
                                       for k, v in files.items()}),
     'bytes of map.pgm, episode.json recorded'),
    (lambda s: Lying(s, short=True), 'ended after 0 bytes'),
    (lambda s: Lying(s, long=True), 'the worker sent'),
])
def test_a_listing_or_transfer_that_does_not_match_episode_json_is_refused(
        server, tmp_path, source, message):
    with pytest.raises(BagCollectionError, match=message):
        collect_bag(source(server), BAG, tmp_path / 'bags', remove=True)
    assert not (tmp_path / 'bags').exists() or not list((tmp_path / 'bags').iterdir())


@pytest.mark.parametrize('bag', ['../outside/x', '/abs/x', 'run-1', 'run-1/x.tmp-12',
                                 'run-1/missing', ''])
def test_the_server_serves_finished_bags_under_its_root_only(server, bag):
    with pytest.raises(BagServeError):
        server.list_files(bag)


def test_the_server_reads_only_the_bags_files_in_bounded_chunks(server):
    with pytest.raises(BagServeError, match='no file'):
        server.read(BAG, '../../x', 0, 10)
    with pytest.raises(BagServeError, match='1 to'):
        server.read(BAG, 'episode.json', 0, MAX_CHUNK + 1)
    assert server.read(BAG, 'episode.json', 0, 1) == b'{'


def test_a_staging_directory_left_by_a_killed_collection_is_replaced(server, tmp_path):
    stale = tmp_path / 'bags' / '.g003-m07-s12.collecting-abc123'
    stale.mkdir(parents=True)
    (stale / 'episode.json').write_text('{"half": ')
    copy = collect_bag(server, BAG, tmp_path / 'bags')
    assert [path.name for path in (tmp_path / 'bags').iterdir()] == [copy.name]
