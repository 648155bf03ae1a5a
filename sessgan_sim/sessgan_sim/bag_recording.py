"""Failure bags: one episode's messages as a rosbag2 bag, plus its map and metrics.

``write_episode_bag`` produces ``<directory>/``::

    metadata.yaml, <name>.mcap | <name>.db3   the rosbag2 bag (version 9, readable by
                                              ``ros2 bag`` on Jazzy and by rosbags)
    map.pgm, map.yaml                         the episode's map for map_server / RViz
    episode.json                              metrics, seed, member, generation,
                                              controller, software version, ...

Everything is written under ``<directory>.tmp-<pid>/`` and moved into place with one
``os.replace`` of a finished directory, so a reader (or a killed writer) never sees a
half-written bag. A bag's directory is ``<record directory>/<episode id>``
(:func:`episode_bag_directory`); the id must be a safe name
(``sessgan_gen.environment.check_environment_id``: no path separators, no '..', at most 128
characters), checked before anything on disk is touched. An existing directory is replaced
(``overwrite``) only if it is itself a failure bag (:func:`is_episode_bag`), never a
directory someone else made. The messages arrive already CDR-serialized (the node serializes them
with ``rclpy.serialization``); this module imports no rclpy and no message types.

QoS recorded per topic (what ``ros2 bag play`` will offer on replay): ``map`` and
``tf_static`` as reliable, transient local, keep last 1 (late subscribers still get the
map and static transforms); every other topic reliable, volatile, keep last 10.
"""

from __future__ import annotations

import json
import math
import os
import shutil
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

from sessgan_gen.atomic_files import fsync_directory, fsync_tree
from sessgan_gen.environment import check_environment_id
from sessgan_gen.errors import InvalidEnvironmentError
from sessgan_gen.json_data import to_json_data
from sessgan_gen.map_server_io import write_map_server
from sessgan_sim import __version__
from sessgan_sim.errors import BagWriteError

BAG_VERSION: Final[Literal[9]] = 9
"""rosbag2 metadata version; Jazzy's ``ros2 bag`` reads version 9."""

TRANSIENT_LOCAL_TOPICS = frozenset({'map', 'tf_static'})
"""Topic base names recorded as transient local (reliable, depth 1)."""

VOLATILE_DEPTH = 10
"""History depth recorded for the other (volatile) topics: rclpy's default depth."""

EPISODE_FILE = 'episode.json'
MAP_YAML_FILE = 'map.yaml'
METADATA_FILE = 'metadata.yaml'
_BAG_SIDE_FILES = frozenset({EPISODE_FILE, MAP_YAML_FILE, 'map.pgm', METADATA_FILE})

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
    if not (math.isfinite(resolution) and resolution > 0):
        raise BagWriteError(f'map resolution must be a positive number of metres, '
                            f'got {resolution}')
    store = typestore if typestore is not None else jazzy_typestore()
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = final.parent / f'{final.name}.tmp-{os.getpid()}'
    shutil.rmtree(staging, ignore_errors=True)  # a leftover of a killed earlier process
    staging.mkdir()
    bag_path = staging / final.name
    try:
        custom_data = {'sessgan.episode': final.name, 'sessgan.software_version': __version__}
        counts, first_ns, last_ns = _write_bag(bag_path, records, storage, store, custom_data)
        _describe_as_jazzy(bag_path / METADATA_FILE)
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
    """Delete ``*.tmp-<pid>`` staging directories under ``parent`` whose writer process is
    gone (a killed campaign); returns what was removed."""
    removed = []
    for path in Path(parent).glob('*.tmp-*'):
        pid_text = path.name.rsplit('.tmp-', 1)[-1]
        if not (path.is_dir() and pid_text.isdigit()):
            continue
        if int(pid_text) != os.getpid() and not _process_exists(int(pid_text)):
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
    return removed


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
    """Plain JSON data (see sessgan_gen.json_data)."""
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
