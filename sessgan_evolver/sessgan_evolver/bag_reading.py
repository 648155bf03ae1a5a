"""Reading failure bags (``sessgan_sim.bag_recording``) for replay and re-simulation.

Works for MCAP and sqlite3 bags alike (rosbags picks the storage from metadata.yaml) and
for any rosbag2 bag, with or without the episode.json a failure bag carries. Messages come
back still CDR-serialized, in timestamp order, so replay can publish them unchanged; this
module imports no rclpy and no message types.
"""

from __future__ import annotations

import json
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any, NamedTuple

from rosbags.interfaces import Connection, ConnectionExtRosbag2
from rosbags.rosbag2 import Reader, ReaderError

from sessgan_evolver.errors import BagReadError

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
