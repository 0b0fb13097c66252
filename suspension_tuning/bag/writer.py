"""rosbag2-style bag writer (plain Python): ``metadata.yaml`` plus one MCAP file.

What it writes follows rosbag2's MCAP storage plugin (ros2/rosbag2
``rosbag2_storage_mcap/src/mcap_storage.cpp``, Jazzy; notes ros2-conventions B.3):

* MCAP header profile ``ros2``; one schema per type, encoding ``ros2msg`` with the text
  of :func:`suspension_tuning.bag.definitions.definition_text`, or for a service's event
  and parts ``ros2idl`` (:func:`~suspension_tuning.bag.definitions.schema_of`): each
  text names every type in full, so its RIHS01 hash is the channel's
  ``topic_type_hash`` (rosbags' AnyReader checks it); one channel per topic,
  message encoding ``cdr``, channel metadata ``offered_qos_profiles`` (YAML string,
  bag version 9 names) and ``topic_type_hash`` (RIHS01);
* messages as raw CDR bytes (never re-encoded), ``log_time`` = receive time,
  ``publish_time`` = send time;
* chunks compressed with zstd, with message indexes, and a summary section with a
  Statistics record;
* an MCAP Metadata record ``rosbag2`` (key ``serialized_metadata``: the BagMetadata
  YAML) and any further metadata records (e.g. ``run_config``);
* ``metadata.yaml`` (rosbag2 BagMetadata version 9) beside the ``.mcap`` when the bag
  is closed.

Crash safety: the writer closes a chunk when it holds ``chunk_size`` bytes or when
``max_chunk_interval_s`` has passed since the chunk's first message, and flushes the
file after every chunk, so a process killed mid-run leaves every closed chunk on
disk; :func:`suspension_tuning.bag.reader.read_messages` reads such a file up to its
last complete chunk and :func:`suspension_tuning.bag.reader.reindex` repairs it.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.writer import CompressionType, Writer

from suspension_tuning.bag.definitions import DefinitionNotFoundError, schema_of, type_hash

#: rosbag2 BagMetadata format version written (Jazzy writes 9: QoS with names).
BAG_VERSION = 9
#: ROS distribution recorded in metadata.yaml.
ROS_DISTRO = 'jazzy'
#: rosbag2 encodes "infinite" durations as these (rmw_time_t of RMW_DURATION_INFINITE as
#: written by rosbag2_storage qos.cpp, Jazzy).
INFINITE_DURATION = {'sec': 2147483647, 'nsec': 4294967295}
#: Default chunk size, bytes (uncompressed). Moderate, so a killed recorder loses little.
DEFAULT_CHUNK_SIZE = 512 * 1024
#: Default longest time a chunk stays open, s (bounds the loss of a killed recorder).
DEFAULT_CHUNK_INTERVAL_S = 1.0


def qos_profile_dict(
    reliability: str = 'reliable',
    durability: str = 'volatile',
    history: str = 'keep_last',
    depth: int = 10,
    deadline: Mapping[str, int] | None = None,
    lifespan: Mapping[str, int] | None = None,
    liveliness: str = 'automatic',
    liveliness_lease_duration: Mapping[str, int] | None = None,
    avoid_ros_namespace_conventions: bool = False,
) -> dict[str, Any]:
    """One offered QoS profile in rosbag2 bag-version-9 form (policy names, not numbers).

    Raises
    ------
    ValueError
        If a policy name is not one rosbag2 knows.
    """
    allowed = {
        'reliability': {'reliable', 'best_effort', 'system_default', 'best_available', 'unknown'},
        'durability': {
            'volatile',
            'transient_local',
            'system_default',
            'best_available',
            'unknown',
        },
        'history': {'keep_last', 'keep_all', 'system_default', 'unknown'},
        'liveliness': {
            'automatic',
            'manual_by_topic',
            'system_default',
            'best_available',
            'unknown',
        },
    }
    values = {
        'reliability': reliability,
        'durability': durability,
        'history': history,
        'liveliness': liveliness,
    }
    for name, value in values.items():
        if value not in allowed[name]:
            raise ValueError(f'{name} {value!r} is not one of {sorted(allowed[name])}')
    return {
        'history': history,
        'depth': int(depth),
        'reliability': reliability,
        'durability': durability,
        'deadline': dict(deadline or INFINITE_DURATION),
        'lifespan': dict(lifespan or INFINITE_DURATION),
        'liveliness': liveliness,
        'liveliness_lease_duration': dict(liveliness_lease_duration or INFINITE_DURATION),
        'avoid_ros_namespace_conventions': bool(avoid_ros_namespace_conventions),
    }


def dump_qos(profiles: Sequence[Mapping[str, Any]]) -> str:
    """The ``offered_qos_profiles`` YAML string of an MCAP channel ('' for none)."""
    if not profiles:
        return ''
    return yaml.safe_dump([dict(p) for p in profiles], sort_keys=False).strip()


@dataclass
class TopicInfo:
    """A topic of the bag: its channel and what metadata.yaml says about it."""

    name: str
    type: str
    channel_id: int
    offered_qos_profiles: list[dict[str, Any]] = field(default_factory=list)
    type_description_hash: str = ''
    message_count: int = 0


class _CountingFile:
    """Unbuffered file with a position counter: every write reaches the OS at once."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, 'wb', buffering=0)  # noqa: SIM115 (closed in close())
        self.position = 0

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            written = self._file.write(view)
            view = view[written:]
        self.position += len(data)
        return len(data)

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            os.fsync(self._file.fileno())
            self._file.close()


class BagWriter:
    """Write a rosbag2-style bag folder: ``<path>/metadata.yaml`` + ``<path>/<name>_0.mcap``.

    Parameters
    ----------
    path : str or Path
        Bag folder; created, and must not exist yet (or be empty).
    chunk_size : int
        Uncompressed bytes after which a chunk is closed and flushed to disk.
    max_chunk_interval_s : float
        A chunk is also closed once its first message is this old (wall time, s), so
        that a slow topic still reaches the disk.
    compression : str
        'zstd' (default), 'lz4' or 'none'.

    Examples
    --------
    >>> with BagWriter('bags/run') as bag:                        # doctest: +SKIP
    ...     bag.add_topic('/chatter', 'std_msgs/msg/String')
    ...     bag.write('/chatter', cdr_bytes, log_time_ns)
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        max_chunk_interval_s: float = DEFAULT_CHUNK_INTERVAL_S,
        compression: str = 'zstd',
    ) -> None:
        if chunk_size <= 0:
            raise ValueError(f'chunk_size must be positive, got {chunk_size}')
        if not max_chunk_interval_s > 0:
            raise ValueError(f'max_chunk_interval_s must be positive, got {max_chunk_interval_s}')
        compressions = {
            'zstd': CompressionType.ZSTD,
            'lz4': CompressionType.LZ4,
            'none': CompressionType.NONE,
        }
        if compression not in compressions:
            raise ValueError(f'compression {compression!r} is not one of {list(compressions)}')
        self.path = Path(path)
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise ValueError(f'bag folder {self.path} already exists and is not empty')
        self.path.mkdir(parents=True, exist_ok=True)
        self.compression = compression
        self.mcap_path = self.path / f'{self.path.name}_0.mcap'
        self._file = _CountingFile(self.mcap_path)
        # The mcap writer never closes a chunk itself (its size limit is out of reach);
        # this class decides, so that it can flush the file after each chunk.
        self._writer = Writer(
            self._file, chunk_size=1 << 62, compression=compressions[compression]
        )
        self._writer.start(profile='ros2', library='suspension_tuning.bag')
        self._chunk_size = int(chunk_size)
        self._chunk_interval_s = float(max_chunk_interval_s)
        self._chunk_bytes = 0
        self._chunk_opened = 0.0
        self._schemas: dict[str, int] = {}
        self.topics: dict[str, TopicInfo] = {}
        self.custom_data: dict[str, str] = {}
        self.message_count = 0
        self.chunk_count = 0
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.closed = False

    # ------------------------------------------------------------------ topics
    def add_topic(
        self,
        topic: str,
        type_name: str,
        offered_qos_profiles: Sequence[Mapping[str, Any]] = (),
        definition: str | None = None,
        type_description_hash: str | None = None,
        schema_encoding: str = 'ros2msg',
    ) -> TopicInfo:
        """Register a topic (its schema once per type, and a ``cdr`` channel).

        Parameters
        ----------
        topic : str
            Topic name, e.g. ``/optimisation/progress``.
        type_name : str
            ``pkg/msg/T``, ``pkg/srv/T_Event``, ``pkg/action/T_FeedbackMessage``, ...
        offered_qos_profiles : sequence of dict
            The publishers' offered QoS (see :func:`qos_profile_dict`).
        definition : str, optional
            The schema's text, in ``schema_encoding``; by default
            :func:`~suspension_tuning.bag.definitions.schema_of` the type (``ros2msg``,
            or ``ros2idl`` for a service's event and parts).
        type_description_hash : str, optional
            RIHS01 hash; by default read from the installed interface description.
        schema_encoding : str
            Encoding of a given ``definition``: ``ros2msg`` or ``ros2idl``.

        Raises
        ------
        ValueError
            If the topic is already registered with another type, or the bag is closed.
        DefinitionNotFoundError
            If no definition is given and none can be found.
        """
        self._check_open()
        if topic in self.topics:
            if self.topics[topic].type != type_name:
                raise ValueError(
                    f'topic {topic} already has type {self.topics[topic].type}, not {type_name}'
                )
            return self.topics[topic]
        if type_name not in self._schemas:
            encoding, text = ((schema_encoding, definition) if definition is not None
                              else schema_of(type_name))
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding=encoding, data=text.encode()
            )
        if type_description_hash is None:
            try:
                type_description_hash = type_hash(type_name)
            except (DefinitionNotFoundError, ValueError):
                type_description_hash = ''
        profiles = [dict(p) for p in offered_qos_profiles]
        metadata = {'offered_qos_profiles': dump_qos(profiles)}
        if type_description_hash:
            metadata['topic_type_hash'] = type_description_hash
        channel_id = self._writer.register_channel(
            topic=topic,
            message_encoding='cdr',
            schema_id=self._schemas[type_name],
            metadata=metadata,
        )
        info = TopicInfo(topic, type_name, channel_id, profiles, type_description_hash)
        self.topics[topic] = info
        return info

    # ---------------------------------------------------------------- messages
    def write(
        self,
        topic: str,
        data: bytes,
        log_time_ns: int,
        publish_time_ns: int | None = None,
        sequence: int = 0,
    ) -> None:
        """Append one serialized (CDR) message of a registered topic.

        Parameters
        ----------
        topic : str
            A topic registered with :meth:`add_topic`.
        data : bytes
            The message as serialized by the middleware (CDR with encapsulation header).
        log_time_ns : int
            Receive time, ns since the Unix epoch.
        publish_time_ns : int, optional
            Send time, ns; defaults to ``log_time_ns``.
        sequence : int
            Publisher sequence number, if known.

        Raises
        ------
        ValueError
            If the topic is unknown, a time is negative or the bag is closed.
        """
        self._check_open()
        if topic not in self.topics:
            raise ValueError(f'topic {topic} was not registered with add_topic()')
        if log_time_ns < 0 or (publish_time_ns is not None and publish_time_ns < 0):
            raise ValueError(f'negative time on {topic}: {log_time_ns}, {publish_time_ns}')
        info = self.topics[topic]
        publish = log_time_ns if publish_time_ns is None else publish_time_ns
        if self._chunk_bytes == 0:
            self._chunk_opened = time.monotonic()
        self._writer.add_message(
            channel_id=info.channel_id,
            log_time=int(log_time_ns),
            data=bytes(data),
            publish_time=int(publish),
            sequence=int(sequence) & 0xFFFFFFFF,
        )
        info.message_count += 1
        self.message_count += 1
        self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns, log_time_ns)
        self.end_ns = log_time_ns if self.end_ns is None else max(self.end_ns, log_time_ns)
        self._chunk_bytes += len(data) + 31  # + the Message record's fixed fields
        if (
            self._chunk_bytes >= self._chunk_size
            or time.monotonic() - self._chunk_opened >= self._chunk_interval_s
        ):
            self.flush()

    def flush(self) -> None:
        """Close the open chunk (if any) and push everything written so far to disk."""
        self._check_open()
        if self._chunk_bytes:
            self.chunk_count += 1
        self._writer.flush()
        self._chunk_bytes = 0

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Add an MCAP Metadata record (string keys and values), e.g. ``run_config``.

        Raises
        ------
        ValueError
            If a key or value is not a string, or the name is ``rosbag2`` (written at
            close).
        """
        self._check_open()
        if name == 'rosbag2':
            raise ValueError("the 'rosbag2' metadata record is written by close()")
        for key, value in data.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise ValueError(f'metadata {name}: {key!r}: {value!r} is not str: str')
        self.flush()
        self._writer.add_metadata(name, dict(data))
        self._file.flush()

    # ---------------------------------------------------------------- closing
    def bag_metadata(self) -> dict[str, Any]:
        """The rosbag2 BagMetadata (version 9) of what has been written so far."""
        start = self.start_ns or 0
        duration = (self.end_ns - self.start_ns) if self.start_ns is not None else 0
        name = self.mcap_path.name
        return {
            'version': BAG_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': self.message_count,
            'topics_with_message_count': [
                {
                    'topic_metadata': {
                        'name': t.name,
                        'type': t.type,
                        'serialization_format': 'cdr',
                        'offered_qos_profiles': t.offered_qos_profiles,
                        'type_description_hash': t.type_description_hash,
                    },
                    'message_count': t.message_count,
                }
                for t in self.topics.values()
            ],
            # Chunks are compressed inside the MCAP file; rosbag2's own compression
            # (whole file or per message) is not used.
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [name],
            'files': [
                {
                    'path': name,
                    'starting_time': {'nanoseconds_since_epoch': start},
                    'duration': {'nanoseconds': duration},
                    'message_count': self.message_count,
                }
            ],
            'custom_data': dict(self.custom_data),
            'ros_distro': ROS_DISTRO,
        }

    def close(self) -> Path:
        """Write the summary (statistics, indexes), the ``rosbag2`` record and metadata.yaml.

        Returns
        -------
        Path
            The bag folder.
        """
        if self.closed:
            return self.path
        self.flush()
        info = self.bag_metadata()
        self._writer.add_metadata(
            'rosbag2', {'serialized_metadata': yaml.safe_dump(info, sort_keys=False)}
        )
        self._writer.finish()
        self._file.close()
        self.closed = True
        text = yaml.safe_dump({'rosbag2_bagfile_information': info}, sort_keys=False)
        tmp = self.path / 'metadata.yaml.tmp'
        tmp.write_text(text)
        tmp.replace(self.path / 'metadata.yaml')
        return self.path

    def _check_open(self) -> None:
        if self.closed:
            raise ValueError(f'bag {self.path} is closed')

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def size_bytes(self) -> int:
        """Bytes written to the MCAP file so far."""
        return self._file.position


def nanoseconds_now() -> int:
    """Wall-clock time, ns since the Unix epoch."""
    return time.time_ns()


__all__ = [
    'BAG_VERSION',
    'BagWriter',
    'TopicInfo',
    'dump_qos',
    'nanoseconds_now',
    'qos_profile_dict',
]
