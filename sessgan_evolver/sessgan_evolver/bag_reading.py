"""Reading failure bags (``sessgan_sim.bag_recording``) for replay and re-simulation.

Works for MCAP and sqlite3 bags alike (rosbags picks the storage from metadata.yaml) and
for any rosbag2 bag, with or without the episode.json a failure bag carries. Messages come
back still CDR-serialized, in timestamp order, so replay can publish them unchanged; this
module imports no rclpy and no message types.

Before a bag is trusted, :func:`verify_bag_files` checks every file against the sizes and
SHA-256 digests its episode.json lists (rosbags checks MCAP chunk CRCs while reading), and
:func:`check_episode_fields` the types of the episode.json fields re-simulation uses.
"""

from __future__ import annotations

import json
import numbers
from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path
from typing import Any, NamedTuple

from rosbags.interfaces import Connection, ConnectionExtRosbag2
from rosbags.rosbag2 import Reader, ReaderError

from sessgan_core.environment import check_environment_id
from sessgan_core.errors import InvalidEnvironmentError
from sessgan_evolver.errors import BagReadError
from sessgan_sim.bag_recording import sha256_of

EPISODE_FILE = 'episode.json'
"""Name of the episode facts file inside a failure bag directory."""


class BagTopic(NamedTuple):
    """One recorded topic and the QoS it was offered with (for republishing)."""

    topic: str
    msgtype: str
    message_count: int
    durability: str
    """'transient_local', 'volatile', ... (lower-case rmw names; '' when not recorded)."""
    reliability: str
    """'reliable', 'best_effort', ... ('' when not recorded)."""
    depth: int
    """History depth (0 when not recorded)."""


class BagMessage(NamedTuple):
    """One recorded message."""

    topic: str
    msgtype: str
    timestamp_ns: int
    data: bytes
    """CDR-serialized message."""


class EpisodeBag(NamedTuple):
    """What ``read_episode_bag`` returns."""

    topics: list[BagTopic]
    messages: Iterator[BagMessage]
    """Every message in timestamp order; reading opens the bag and closes it at the end."""
    episode: dict[str, Any] | None
    """episode.json (metrics, seed, member, controller, ...); None for a bag without one."""


def bag_directory(path: str | Path) -> Path:
    """The bag directory for ``path``: the directory itself, or the directory holding a
    given metadata.yaml / storage file. BagReadError if there is no bag there."""
    candidate = Path(path)
    if not candidate.exists():
        raise BagReadError(f'no bag at {candidate}: the path does not exist')
    if candidate.is_file():
        candidate = candidate.parent
    if not (candidate / 'metadata.yaml').is_file():
        raise BagReadError(f'{candidate} is not a rosbag2 bag: it has no metadata.yaml '
                           '(a bag still being written is named <episode>.tmp-<pid>)')
    return candidate


def read_episode_bag(path: str | Path) -> EpisodeBag:
    """Open a failure bag: its topics, a lazy message iterator and its episode.json.

    BagReadError for a missing path, a directory that is no bag, unreadable metadata, a
    truncated or corrupt storage file, or a malformed episode.json.
    """
    directory = bag_directory(path)
    topics = read_bag_topics(directory)
    return EpisodeBag(topics, iter_bag_messages(directory), read_episode_json(directory))


def read_bag_topics(path: str | Path) -> list[BagTopic]:
    """The topics of a bag, sorted by name."""
    directory = bag_directory(path)
    reader = _open_reader(directory)
    try:
        topics = [_topic_of(connection) for connection in reader.connections]
    finally:
        reader.close()
    return sorted(topics, key=lambda t: t.topic)


def iter_bag_messages(path: str | Path, topics: Collection[str] | None = None
                      ) -> Iterator[BagMessage]:
    """Messages of a bag in timestamp order, optionally only of ``topics``. The bag is
    opened when iteration starts and closed when it ends (or the iterator is closed)."""
    directory = bag_directory(path)
    reader = _open_reader(directory)
    try:
        connections = [c for c in reader.connections if topics is None or c.topic in topics]
        if topics is not None and not connections:
            return
        for connection, timestamp, data in reader.messages(connections=connections):
            yield BagMessage(connection.topic, connection.msgtype, int(timestamp), bytes(data))
    except (ReaderError, OSError, ValueError, KeyError, IndexError) as err:
        raise BagReadError(f'bag {directory} is corrupt: {err}') from err
    finally:
        reader.close()


def check_bag_complete(path: str | Path) -> int:
    """Read every message of a bag; returns their number. BagReadError unless the storage
    opens, every message decodes from it, and their number is the one metadata.yaml (and
    episode.json, when there is one) recorded: a truncated or half-copied bag is refused
    before anything trusts its episode.json."""
    directory = bag_directory(path)
    try:
        topics = read_bag_topics(directory)
        count = sum(1 for _ in iter_bag_messages(directory))
    except BagReadError as err:
        raise BagReadError(f'bag {directory} is incomplete or corrupt ({err})') from err
    expected = sum(topic.message_count for topic in topics)
    if count != expected:
        raise BagReadError(f'bag {directory} is incomplete: {count} of the {expected} '
                           'messages metadata.yaml lists can be read')
    episode = read_episode_json(directory)
    recorded = (episode or {}).get('messages', {}).get('count')
    if recorded is not None and recorded != count:
        raise BagReadError(f'bag {directory} is incomplete: it holds {count} messages, '
                           f'episode.json recorded {recorded}')
    return count


def read_episode_json(path: str | Path) -> dict[str, Any] | None:
    """episode.json of a bag directory (None if the bag has none)."""
    directory = bag_directory(path)
    episode_path = directory / EPISODE_FILE
    if not episode_path.exists():
        return None
    try:
        episode = json.loads(episode_path.read_text(encoding='utf-8'))
    except (OSError, ValueError) as err:
        raise BagReadError(f'{episode_path} is unreadable or not JSON: {err}') from err
    if not isinstance(episode, dict):
        raise BagReadError(f'{episode_path} does not hold a JSON object')
    return episode


def _open_reader(directory: Path) -> Reader:
    try:
        reader = Reader(directory)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError, IndexError) as err:
        raise BagReadError(f'cannot open bag {directory}: {err}') from err
    return reader


def _topic_of(connection: Connection) -> BagTopic:
    durability = reliability = ''
    depth = 0
    if isinstance(connection.ext, ConnectionExtRosbag2) and connection.ext.offered_qos_profiles:
        qos = connection.ext.offered_qos_profiles[0]
        durability = qos.durability.name.lower()
        reliability = qos.reliability.name.lower()
        depth = int(qos.depth)
    return BagTopic(connection.topic, connection.msgtype, int(connection.msgcount),
                    durability, reliability, depth)


def verify_bag_files(path: str | Path) -> str | None:
    """Check every file episode.json lists (``files``: size and SHA-256) against the disk.

    BagReadError naming the file that is missing, of another size or with another digest
    (a bag corrupted after it was written). Returns a warning for a bag whose episode.json
    lists no digests (older bags, bags without episode.json), None when all match.
    """
    directory = bag_directory(path)
    episode = read_episode_json(directory)
    if episode is None:
        return (f'{directory} has no {EPISODE_FILE} (a bag recorded by another tool, or it '
                'was deleted): its files cannot be checked for corruption')
    files = episode.get('files')
    if files is None:
        return (f'{directory / EPISODE_FILE} records no file digests (a bag from a version '
                'before 2026-11-26): its files cannot be checked for corruption')
    if not isinstance(files, Mapping) or not files:
        raise BagReadError(f'{directory / EPISODE_FILE}: field "files" must map file names to '
                           '{size, sha256}')
    for name, expected in sorted(files.items()):
        file = directory / str(name)
        if (Path(str(name)).name != name or not isinstance(expected, Mapping)
                or not isinstance(expected.get('size'), int)
                or not isinstance(expected.get('sha256'), str)):
            raise BagReadError(f'{directory / EPISODE_FILE}: field "files" has a malformed entry '
                               f'{name!r}: {expected!r:.120}')
        if not file.is_file():
            raise BagReadError(f'bag {directory} is incomplete: {file} is missing')
        size = file.stat().st_size
        if size != expected['size']:
            raise BagReadError(f'bag {directory} is incomplete or corrupt: {file} has {size} '
                               f'bytes, episode.json recorded {expected["size"]}')
        digest = sha256_of(file)
        if digest != expected['sha256']:
            raise BagReadError(f'bag {directory} is corrupt: the SHA-256 digest of {file} is '
                               f'{digest}, episode.json recorded {expected["sha256"]}')
    return None


def _number(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _integer(value: object) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _pose(value: object) -> bool:
    return (isinstance(value, list) and len(value) in (2, 3)
            and all(_number(item) for item in value))


def _poses(value: object) -> bool:
    return isinstance(value, list) and all(_pose(item) for item in value)


def _safe_id(value: object) -> bool:
    """An id re-simulation may name a bag directory with (check_environment_id)."""
    try:
        check_environment_id(value)
    except InvalidEnvironmentError:
        return False
    return True


def _fleet(value: object) -> bool:
    return value is None or (isinstance(value, list) and all(
        isinstance(robot, Mapping) and _pose(robot.get('start')) and _pose(robot.get('goal'))
        and _number(robot.get('route_length', 0.0)) for robot in value))


_Check = tuple[Callable[[object], bool], str]
_EPISODE_FIELDS: dict[str, tuple[bool, _Check]] = {
    # name: (required, (check, what it must be))
    'environment_id': (True, (_safe_id, 'a safe name (a letter or digit, then letters, '
                                        'digits, ".", "_" or "-"; no "..")')),
    'scenario': (True, (lambda v: isinstance(v, str), 'a string')),
    'start': (True, (_pose, 'a list [x, y] or [x, y, yaw] of numbers')),
    'goal': (True, (_pose, 'a list [x, y] or [x, y, yaw] of numbers')),
    'metrics': (True, (lambda v: isinstance(v, Mapping), 'an object')),
    'seed': (False, (_integer, 'an integer')),
    'episode_seed': (False, (_integer, 'an integer')),
    'generation': (False, (_integer, 'an integer')),
    'member': (False, (_integer, 'an integer')),
    'feasible': (False, (lambda v: isinstance(v, bool), 'true or false')),
    'route_length': (False, (_number, 'a number')),
    'route_min_clearance': (False, (_number, 'a number')),
    'stations': (False, (_poses, 'a list of [x, y, yaw] poses')),
    'dwell_time': (False, (_number, 'a number')),
    'fleet': (False, (_fleet, 'a list of {start, goal, route_length} robots, or null')),
    'time_limit': (False, (_number, 'a number')),
    'robot': (False, (lambda v: isinstance(v, str), 'a string')),
    'controller': (False, (lambda v: isinstance(v, str), 'a string')),
    'namespace': (False, (lambda v: isinstance(v, str), 'a string')),
    'sim_time_origin': (False, (lambda v: v is None or _number(v), 'a number')),
    'simulator': (False, (lambda v: isinstance(v, Mapping), 'an object')),
    'episode_config': (False, (lambda v: isinstance(v, Mapping), 'an object')),
}
_METRICS_FIELDS: dict[str, tuple[bool, _Check]] = {
    'outcome': (True, (lambda v: isinstance(v, str), 'a string')),
    'collisions': (True, (_integer, 'an integer')),
    'risk_score': (True, (_number, 'a number')),
    'simulation_time': (True, (_number, 'a number')),
    'distance_travelled': (True, (_number, 'a number')),
    'ticks': (True, (_integer, 'an integer')),
    'fault_collisions': (False, (_integer, 'an integer')),
    'legs': (False, (_integer, 'an integer')),
    'legs_completed': (False, (_integer, 'an integer')),
}


def check_episode_fields(episode: Mapping[str, object], source: str | Path) -> None:
    """BagReadError naming the first field of episode.json (``source``, for the message) that
    re-simulation needs and that is missing or of the wrong type (``"start": 5``)."""
    for fields, document, prefix in ((_EPISODE_FIELDS, episode, ''),
                                     (_METRICS_FIELDS, episode.get('metrics'), 'metrics.')):
        if not isinstance(document, Mapping):
            return  # 'metrics' itself was checked (and named) in the first round
        for name, (required, (check, expected)) in fields.items():
            if name not in document:
                if required:
                    raise BagReadError(f'{source}: field "{prefix}{name}" is missing')
                continue
            if not check(document[name]):
                raise BagReadError(f'{source}: field "{prefix}{name}" must be {expected}, got '
                                   f'{json.dumps(document[name])[:80]}')
