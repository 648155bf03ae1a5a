"""Failure bags: one episode's messages as a rosbag2 bag, plus its map and metrics.

``write_episode_bag`` produces ``<directory>/``::

    metadata.yaml, <name>.mcap | <name>.db3   the rosbag2 bag (version 9, readable by
                                              ``ros2 bag`` on Jazzy and by rosbags)
    map.pgm, map.yaml                         the episode's map for map_server / RViz
    episode.json                              metrics, seed, member, generation,
                                              controller, software version, ...

Everything is written under ``<directory>.tmp-<pid>/`` and moved into place with one
``os.replace`` of a finished directory, so a reader (or a killed writer) never sees a
half-written bag. The staging directory's first file is a marker (:data:`STAGING_MARKER`:
the writer's pid, host and process start time), and clean-up
(:func:`remove_stale_staging_directories`) removes only staging directories whose marker shows
a writer of this host that is gone: a directory someone else named ``*.tmp-<pid>`` is never
touched. A bag's directory is ``<record directory>/<episode id>``
(:func:`episode_bag_directory`); the id must be a safe name
(``sessgan_core.environment.check_environment_id``: no path separators, no '..', at most 128
characters), checked before anything on disk is touched. An existing directory is replaced
(``overwrite``) only if it is itself a failure bag (:func:`is_episode_bag`), never a
directory someone else made. The messages arrive already CDR-serialized (the node serializes them
with ``rclpy.serialization``); this module imports no rclpy and no message types.

MCAP files get chunk CRCs (:func:`add_mcap_chunk_crcs`; rosbags writes none), and episode.json
lists the size and SHA-256 digest of every other file of the bag (``files``), so a reader can
refuse a bag corrupted after it was written (``sessgan_evolver.bag_reading.verify_bag_files``).

A simulator writes only under the bags root it was started with: the record directory an
evaluate goal names is a relative subdirectory of it (:func:`record_directory_under`).

QoS recorded per topic (what ``ros2 bag play`` will offer on replay): ``map``,
``tf_static``, ``goal_pose`` and ``waypoints`` as reliable, transient local, keep last 1, as
the simulator publishes them (late subscribers still get the map, the static transforms and
the goal); every other topic reliable, volatile, keep last 10.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import struct
import zlib
from collections.abc import Iterable, Mapping
from enum import StrEnum
from pathlib import Path
from typing import Any, Final, Literal, NamedTuple

import numpy as np
import yaml
from rosbags.interfaces import (
    Connection,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from sessgan_core.atomic_files import fsync_directory, fsync_tree
from sessgan_core.environment import check_environment_id
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_core.json_data import to_json_data
from sessgan_core.map_server_io import write_map_server
from sessgan_core.validation import require_positive
from sessgan_sim import __version__
from sessgan_sim.errors import BagWriteError

BAG_VERSION: Final[Literal[9]] = 9
"""rosbag2 metadata version; Jazzy's ``ros2 bag`` reads version 9."""

TRANSIENT_LOCAL_TOPICS = frozenset({'map', 'tf_static', 'goal_pose', 'waypoints'})
"""Topic base names recorded as transient local (reliable, depth 1), as the simulator
publishes them (README, the topic contract)."""

VOLATILE_DEPTH = 10
"""History depth recorded for the other (volatile) topics: rclpy's default depth."""

EPISODE_FILE = 'episode.json'
MAP_YAML_FILE = 'map.yaml'
METADATA_FILE = 'metadata.yaml'
FAULT_PICTURE_FILE = 'fault.png'
"""The picture a confirmed fault's record draws beside its bag (sessgan_evolver.fault_records)."""
_BAG_SIDE_FILES = frozenset({EPISODE_FILE, MAP_YAML_FILE, 'map.pgm', METADATA_FILE,
                             FAULT_PICTURE_FILE})

STAGING_MARKER = '.sessgan-staging.json'
"""The first file of a staging directory: who writes it (pid, host, process start time)."""
_STAGING_FORMAT = 'sessgan-failure-bag-staging/1'

MAX_RECORD_SUBDIRECTORY_DEPTH = 4
"""Components a record directory may have below the bags root (``<run>`` is one)."""

# rmw's "infinite" duration as Jazzy's rosbag2 writes it in metadata.yaml.
_INFINITE = QosTime(sec=9223372036, nsec=854775807)
_UNSPECIFIED = QosTime(sec=0, nsec=0)


class BagStorage(StrEnum):
    """Storage formats of a failure bag (the registry of supported formats)."""

    MCAP = 'mcap'
    """Jazzy's default storage."""
    SQLITE3 = 'sqlite3'
    """The classic storage, for older tools."""

    @property
    def plugin(self) -> StoragePlugin:
        return _STORAGE_PLUGINS[self]


_STORAGE_PLUGINS = {BagStorage.MCAP: StoragePlugin.MCAP,
                    BagStorage.SQLITE3: StoragePlugin.SQLITE3}


class BagRecord(NamedTuple):
    """One serialized message of an episode."""

    topic: str
    """Topic name; a missing leading '/' is added."""
    msgtype: str
    """ROS 2 type name, e.g. 'sensor_msgs/msg/LaserScan'."""
    timestamp_ns: int
    """Receive time in nanoseconds (sim time of the tick)."""
    data: bytes
    """CDR-serialized message."""


def qos_for_topic(topic: str) -> Qos:
    """The QoS profile recorded for ``topic`` (module docstring)."""
    if topic.rstrip('/').rsplit('/', 1)[-1] in TRANSIENT_LOCAL_TOPICS:
        durability, depth = QosDurability.TRANSIENT_LOCAL, 1
    else:
        durability, depth = QosDurability.VOLATILE, VOLATILE_DEPTH
    return Qos(history=QosHistory.KEEP_LAST, depth=depth,
               reliability=QosReliability.RELIABLE, durability=durability,
               deadline=_INFINITE, lifespan=_INFINITE, liveliness=QosLiveliness.AUTOMATIC,
               liveliness_lease_duration=_INFINITE, avoid_ros_namespace_conventions=False)


_JAZZY_TYPESTORE: Typestore | None = None


def jazzy_typestore() -> Typestore:
    """rosbags' ROS 2 Jazzy typestore (built once; it knows tf2_msgs and rosgraph_msgs)."""
    global _JAZZY_TYPESTORE
    if _JAZZY_TYPESTORE is None:
        _JAZZY_TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _JAZZY_TYPESTORE


def episode_bag_directory(record_directory: str | Path, episode_id: str) -> Path:
    """``<record_directory>/<episode_id>``, the directory of an episode's failure bag.

    BagWriteError if ``record_directory`` is empty or ``episode_id`` is not a safe name
    (empty, absolute, with '/' or '..', too long: see ``check_environment_id``), so a bag
    never lands outside its record directory or on the record directory itself.
    """
    if not str(record_directory):
        raise BagWriteError('no record directory given for the failure bag')
    try:
        check_environment_id(episode_id)
    except InvalidEnvironmentError as err:
        raise BagWriteError(f'refusing to write a failure bag: {err}') from err
    return Path(record_directory) / episode_id


def check_record_subdirectory(subdirectory: object) -> str:
    """``subdirectory`` if it names a directory inside a bags root, else BagWriteError saying
    why: relative, at most :data:`MAX_RECORD_SUBDIRECTORY_DEPTH` '/'-separated components, each
    a safe name as episode ids are (``check_environment_id``: a letter or digit first, then
    letters, digits, '.', '_', '-'; no '..', no '.tmp-'), so it can neither be absolute nor
    climb out of the root."""
    rule = ("a failure bag's record directory must be a relative subdirectory of the "
            "simulator's bags root (e.g. 'my-run'): '/'-separated names that start with a "
            "letter or digit and hold only letters, digits, '.', '_' and '-' (no '..')")
    if not isinstance(subdirectory, str):
        raise BagWriteError(f'{rule}; got a {type(subdirectory).__name__}')
    if not subdirectory:
        raise BagWriteError(f'{rule}; got an empty one')
    if subdirectory.startswith('/'):
        raise BagWriteError(f'{rule}; {subdirectory!r} is an absolute path')
    parts = subdirectory.split('/')
    if len(parts) > MAX_RECORD_SUBDIRECTORY_DEPTH:
        raise BagWriteError(f'{rule}; {subdirectory!r} has {len(parts)} components, at most '
                            f'{MAX_RECORD_SUBDIRECTORY_DEPTH}')
    for part in parts:
        try:
            check_environment_id(part)
        except InvalidEnvironmentError as err:
            raise BagWriteError(f'{rule}; {subdirectory!r} has the component {part!r}') from err
    return subdirectory


def record_directory_under(bags_root: str | Path, subdirectory: str) -> Path:
    """``<bags_root>/<subdirectory>`` resolved, after :func:`check_record_subdirectory`;
    BagWriteError also when an existing symbolic link would lead the path out of the root."""
    check_record_subdirectory(subdirectory)
    root = Path(bags_root).resolve()
    directory = (root / subdirectory).resolve()
    if not directory.is_relative_to(root):
        raise BagWriteError(f'record directory {subdirectory!r} leads out of the bags root '
                            f'{root} (to {directory}): refusing it')
    return directory


def is_episode_bag(directory: str | Path) -> bool:
    """True if ``directory`` is a failure bag :func:`write_episode_bag` wrote: a directory of
    plain files holding episode.json and metadata.yaml, and nothing but the bag's own files
    (so a directory a user put other things in is never taken for one)."""
    path = Path(directory)
    if path.is_symlink() or not path.is_dir():
        return False
    names = set()
    for entry in path.iterdir():
        if entry.is_symlink() or not entry.is_file():
            return False
        if entry.name not in _BAG_SIDE_FILES and not entry.name.startswith(f'{path.name}.'):
            return False
        names.add(entry.name)
    return {EPISODE_FILE, METADATA_FILE} <= names


def write_episode_bag(directory: str | Path,
                      records: Iterable[BagRecord | tuple[str, str, int, bytes]],
                      metadata: Mapping[str, Any],
                      map_occupancy: np.ndarray,
                      resolution: float,
                      origin: tuple[float, float] | tuple[float, float, float],
                      storage: str | BagStorage = BagStorage.MCAP,
                      *,
                      overwrite: bool = False,
                      typestore: Typestore | None = None) -> Path:
    """Write one episode as ``directory`` (layout in the module docstring); returns it.

    ``records``: (topic, msgtype, timestamp_ns, cdr bytes), streamed into the bag in the
    given order. ``metadata``: JSON-able episode facts (metrics, seed, member, generation,
    controller, ...) stored in episode.json, to which the storage, the software version
    (unless given), the map geometry and per-topic message counts are added.
    ``map_occupancy``: int8 (height, width) OccupancyGrid values; ``resolution``: metres per
    cell; ``origin``: map-frame (x, y[, yaw]) of cell (0, 0). ``overwrite``: replace an
    existing ``directory`` that is a failure bag (:func:`is_episode_bag`; the old one stays
    complete until the new one is in place); any other existing directory is an error.
    ``typestore``: message definitions (default: ROS 2 Jazzy).

    ``directory``'s last component must be a safe episode id and no component may be '..'
    (build it with :func:`episode_bag_directory`); both are checked before anything on disk
    is touched.
    """
    final = Path(directory)
    if '..' in final.parts:
        raise BagWriteError(f'refusing to write a failure bag to {final}: the path has a ".." '
                            'component')
    try:
        check_environment_id(final.name)
    except InvalidEnvironmentError as err:
        raise BagWriteError(f'refusing to write a failure bag to {final}: {err}') from err
    try:
        storage = BagStorage(storage)
    except ValueError as err:
        raise BagWriteError(f'unknown bag storage {storage!r}; expected one of '
                            f'{[s.value for s in BagStorage]}') from err
    _check_replaceable(final, overwrite)
    require_positive('map resolution', resolution, BagWriteError, ' m')
    store = typestore if typestore is not None else jazzy_typestore()
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = final.parent / f'{final.name}.tmp-{os.getpid()}'
    if staging.exists() or staging.is_symlink():
        # A leftover of a killed earlier process with our pid; anything else stays.
        if _staging_owner(staging) is None:
            raise BagWriteError(f'{staging} exists and is not the staging directory of a '
                                'failure bag: refusing to remove it')
        shutil.rmtree(staging)
    staging.mkdir()
    bag_path = staging / final.name
    try:
        _write_staging_marker(staging)
        custom_data = {'sessgan.episode': final.name, 'sessgan.software_version': __version__}
        counts, first_ns, last_ns = _write_bag(bag_path, records, storage, store, custom_data)
        _describe_as_jazzy(bag_path / METADATA_FILE)
        if storage is BagStorage.MCAP:
            for mcap_file in bag_path.glob('*.mcap'):
                add_mcap_chunk_crcs(mcap_file)
        origin_values = [float(value) for value in origin]
        write_map_server(bag_path / MAP_YAML_FILE, np.asarray(map_occupancy), float(resolution),
                         origin_values)
        episode = _json_ready(dict(metadata))
        episode.setdefault('software_version', __version__)
        episode['storage'] = storage.value
        episode['map'] = {'yaml': MAP_YAML_FILE, 'resolution': float(resolution),
                          'origin': origin_values,
                          'height': int(np.shape(map_occupancy)[0]),
                          'width': int(np.shape(map_occupancy)[1])}
        episode['messages'] = {'count': sum(counts.values()), 'topics': counts,
                               'first_timestamp_ns': first_ns, 'last_timestamp_ns': last_ns}
        episode['files'] = file_digests(bag_path)
        (bag_path / EPISODE_FILE).write_text(
            json.dumps(episode, indent=2, sort_keys=True, allow_nan=False) + '\n')
        fsync_tree(bag_path)
        if final.exists() or final.is_symlink():
            _check_replaceable(final, overwrite)
            os.replace(final, staging / 'replaced')
        os.replace(bag_path, final)
        fsync_directory(final.parent)
    except BaseException as err:
        shutil.rmtree(staging, ignore_errors=True)
        if isinstance(err, (WriterError, OSError, TypeError, ValueError)):
            raise BagWriteError(f'cannot write episode bag {final}: {err}') from err
        raise
    shutil.rmtree(staging, ignore_errors=True)
    return final


def _check_replaceable(final: Path, overwrite: bool) -> None:
    """BagWriteError unless ``final`` is absent, or a failure bag and ``overwrite`` is set."""
    if not (final.exists() or final.is_symlink()):
        return
    if not is_episode_bag(final):
        raise BagWriteError(f'{final} exists and is not a failure bag: refusing to replace it')
    if not overwrite:
        raise BagWriteError(f'{final} exists already (pass overwrite=True to replace it)')


def remove_stale_staging_directories(parent: str | Path) -> list[Path]:
    """Delete the ``*.tmp-<pid>`` staging directories under ``parent`` that a failure bag
    writer of this host left when it was killed; returns what was removed.

    A directory is removed only if its :data:`STAGING_MARKER` names the pid of its name, this
    host, and a process that is gone (no such pid, or the pid now belongs to a process started
    at another time). Directories without a valid marker, and those of other hosts (a bags
    root on a shared file system), are left alone.
    """
    removed = []
    for path in sorted(Path(parent).glob('*.tmp-*')):
        owner = _staging_owner(path)
        if owner is None or owner['host'] != socket.gethostname():
            continue
        if not _writer_alive(owner['pid'], owner['process_start']):
            shutil.rmtree(path)
            removed.append(path)
    return removed


def _write_staging_marker(staging: Path) -> None:
    pid = os.getpid()
    owner = {'format': _STAGING_FORMAT, 'pid': pid, 'host': socket.gethostname(),
             'process_start': _process_start_time(pid)}
    with open(staging / STAGING_MARKER, 'x', encoding='utf-8') as marker:
        json.dump(owner, marker)


def _staging_owner(path: Path) -> dict[str, Any] | None:
    """The marker of staging directory ``path`` if it is one this module wrote (format, and
    the pid of the directory's name), else None."""
    name_pid = path.name.rsplit('.tmp-', 1)[-1]
    marker = path / STAGING_MARKER
    if path.is_symlink() or not path.is_dir() or not name_pid.isdigit():
        return None
    if marker.is_symlink() or not marker.is_file():
        return None
    try:
        owner = json.loads(marker.read_text(encoding='utf-8'))
    except (OSError, ValueError):
        return None
    if not (isinstance(owner, dict) and owner.get('format') == _STAGING_FORMAT
            and owner.get('pid') == int(name_pid) and isinstance(owner.get('host'), str)
            and isinstance(owner.get('process_start'), (int, type(None)))):
        return None
    return owner


def _process_start_time(pid: int) -> int | None:
    """Start time of process ``pid`` in clock ticks after boot (Linux /proc), None if unknown:
    with the pid it names one process, even after the pid is reused."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text(encoding='utf-8')
        return int(stat.rsplit(')', 1)[1].split()[19])
    except (OSError, IndexError, ValueError):
        return None


def _writer_alive(pid: int, process_start: int | None) -> bool:
    if not _process_exists(pid):
        return False
    now = _process_start_time(pid)
    return process_start is None or now is None or now == process_start


def file_digests(directory: Path) -> dict[str, dict[str, Any]]:
    """``{name: {'size': bytes, 'sha256': hex}}`` of every file in ``directory`` except
    episode.json (which holds them)."""
    digests = {}
    for path in sorted(directory.iterdir()):
        if path.name != EPISODE_FILE and path.is_file():
            digests[path.name] = {'size': path.stat().st_size, 'sha256': sha256_of(path)}
    return digests


def sha256_of(path: Path) -> str:
    """Hex SHA-256 digest of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, 'rb') as stream:
        for block in iter(lambda: stream.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


_MCAP_MAGIC = b'\x89MCAP0\r\n'
_MCAP_CHUNK, _MCAP_FOOTER = 0x06, 0x02


def add_mcap_chunk_crcs(path: Path) -> int:
    """Fill in the ``uncompressed_crc`` (CRC-32 of the chunk's records) of every uncompressed
    chunk of an MCAP file, in place; returns the number of chunks.

    rosbags' writer leaves the field 0 ("no CRC"), so a reader (rosbags, the mcap library,
    ``ros2 bag``) could not notice a flipped byte; it checks the CRC when it is set.
    """
    chunks = 0
    with open(path, 'r+b') as stream:
        if stream.read(len(_MCAP_MAGIC)) != _MCAP_MAGIC:
            raise BagWriteError(f'{path} is not an MCAP file')
        while True:
            start = stream.tell()
            head = stream.read(9)
            if len(head) < 9:
                raise BagWriteError(f'{path}: MCAP record at byte {start} is cut off')
            opcode, length = struct.unpack('<BQ', head)
            if opcode == _MCAP_FOOTER:
                return chunks
            if opcode != _MCAP_CHUNK:
                stream.seek(length, os.SEEK_CUR)
                continue
            body = stream.read(length)
            uncompressed_size, = struct.unpack_from('<Q', body, 16)
            compression_length, = struct.unpack_from('<I', body, 28)
            compression = body[32:32 + compression_length]
            records_at = 32 + compression_length + 8
            records = body[records_at:]
            if compression or len(records) != uncompressed_size:
                raise BagWriteError(f'{path}: chunk at byte {start} is compressed '
                                    f'({compression!r}) or malformed: cannot add its CRC')
            stream.seek(start + 9 + 24)
            stream.write(struct.pack('<I', zlib.crc32(records)))
            stream.seek(start + 9 + length)
            chunks += 1


def _write_bag(bag_path: Path, records: Iterable[BagRecord | tuple[str, str, int, bytes]],
               storage: BagStorage, store: Typestore, custom_data: Mapping[str, str]
               ) -> tuple[dict[str, int], int | None, int | None]:
    """Stream the records into a new bag; returns per-topic counts and the time span."""
    connections: dict[tuple[str, str], Connection] = {}
    counts: dict[str, int] = {}
    first_ns: int | None = None
    last_ns: int | None = None
    with Writer(bag_path, version=BAG_VERSION, storage_plugin=storage.plugin) as writer:
        for name, value in custom_data.items():
            writer.set_custom_data(name, value)
        for index, record in enumerate(records):
            topic, msgtype, timestamp_ns, data = _checked_record(index, record)
            key = (topic, msgtype)
            connection = connections.get(key)
            if connection is None:
                if msgtype not in store.fielddefs:
                    raise BagWriteError(f'record {index}: message type {msgtype!r} of topic '
                                        f'{topic!r} is unknown to the typestore')
                connection = writer.add_connection(
                    topic, msgtype, typestore=store, serialization_format='cdr',
                    offered_qos_profiles=[qos_for_topic(topic)])
                connections[key] = connection
            writer.write(connection, timestamp_ns, data)
            counts[topic] = counts.get(topic, 0) + 1
            first_ns = timestamp_ns if first_ns is None else min(first_ns, timestamp_ns)
            last_ns = timestamp_ns if last_ns is None else max(last_ns, timestamp_ns)
    return counts, first_ns, last_ns


def _describe_as_jazzy(metadata_path: Path) -> None:
    """Make metadata.yaml read as Jazzy's recorder writes it: ``ros_distro: jazzy`` (rosbags
    writes its own name there), ``custom_data`` a mapping."""
    document = yaml.safe_load(metadata_path.read_text(encoding='utf-8'))
    information = document['rosbag2_bagfile_information']
    information['ros_distro'] = 'jazzy'
    information['custom_data'] = dict(information.get('custom_data') or {})
    metadata_path.write_text(yaml.safe_dump(document, default_flow_style=False, sort_keys=False),
                             encoding='utf-8')


def _checked_record(index: int, record: BagRecord | tuple[str, str, int, bytes]
                    ) -> tuple[str, str, int, bytes | memoryview]:
    try:
        topic, msgtype, timestamp_ns, data = record
    except (TypeError, ValueError) as err:
        raise BagWriteError(f'record {index} is not (topic, msgtype, timestamp_ns, data): '
                            f'{record!r:.80}') from err
    if not isinstance(topic, str) or not topic.strip('/'):
        raise BagWriteError(f'record {index}: invalid topic {topic!r}')
    if not isinstance(msgtype, str) or msgtype.count('/') != 2:
        raise BagWriteError(f'record {index}: message type {msgtype!r} is not of the form '
                            "'package/msg/Type'")
    if isinstance(timestamp_ns, bool) or not isinstance(timestamp_ns, (int, np.integer)) \
            or timestamp_ns < 0:
        raise BagWriteError(f'record {index}: timestamp {timestamp_ns!r} is not a '
                            'non-negative integer of nanoseconds')
    if isinstance(data, np.ndarray):
        data = data.tobytes()
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise BagWriteError(f'record {index}: data is a {type(data).__name__}, not CDR bytes')
    name = topic if topic.startswith('/') else f'/{topic}'
    return name, msgtype, int(timestamp_ns), bytes(data)


def _json_ready(value: Any) -> Any:
    """Plain JSON data (see sessgan_core.json_data)."""
    try:
        return to_json_data(value)
    except TypeError as err:
        raise BagWriteError(f'episode metadata: {err}') from err


def _process_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
