"""Read bags written by :class:`~suspension_tuning.bag.writer.BagWriter` (or rosbag2).

:func:`read_messages` walks the MCAP records one by one, without the summary
section, so it also reads a file cut short (a recorder killed mid-run, a disk that
filled up): it keeps every complete chunk and stops at the first incomplete or
corrupt record (CRCs of chunks are checked), reporting how many messages it
recovered and why it stopped.  :func:`reindex` rewrites such a file into a complete
bag (summary, statistics, ``metadata.yaml``), like ``ros2 bag reindex``, with the
schemas of older bags in rosbag2's layout (:func:`~.definitions.rosbag2_form`).
:func:`decode` turns the raw CDR of a message into an object with the message's
fields (mcap-ros2-support's decoder, driven by the schema stored in the bag).
"""

from __future__ import annotations

import io
import os
import re
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Footer, Message, Metadata, Schema, Statistics
from mcap.stream_reader import breakup_chunk

#: The 8 bytes that open and close every MCAP file.
MCAP_MAGIC = b'\x89MCAP0\r\n'


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: raw CDR plus where and when."""

    topic: str
    type: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    sequence: int = 0


@dataclass
class ChannelInfo:
    """A channel of the bag with its schema (definition text) and offered QoS."""

    id: int
    topic: str
    type: str
    message_encoding: str
    schema_encoding: str
    definition: str
    metadata: dict[str, str]

    @property
    def offered_qos_profiles(self) -> list[dict[str, Any]]:
        """Offered QoS profiles parsed from the channel metadata (empty if none)."""
        text = self.metadata.get('offered_qos_profiles', '')
        loaded = yaml.safe_load(text) if text else None
        return list(loaded) if isinstance(loaded, list) else []


@dataclass
class BagContents:
    """What :func:`read_messages` recovered from a bag."""

    path: Path
    messages: list[BagMessage] = field(default_factory=list)
    channels: dict[int, ChannelInfo] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    statistics: Statistics | None = None
    complete: bool = False
    stop_reason: str = ''
    chunks: int = 0
    bytes_read: int = 0

    @property
    def message_count(self) -> int:
        """Number of messages recovered."""
        return len(self.messages)

    def topics(self) -> dict[str, str]:
        """Topic name -> type name."""
        return {c.topic: c.type for c in self.channels.values()}

    def counts(self) -> dict[str, int]:
        """Topic name -> number of recovered messages."""
        counts = {c.topic: 0 for c in self.channels.values()}
        for message in self.messages:
            counts[message.topic] += 1
        return counts

    def on(self, topic: str) -> list[BagMessage]:
        """The recovered messages of one topic, in log-time order."""
        return [m for m in self.messages if m.topic == topic]

    @property
    def start_ns(self) -> int:
        """Log time of the first message, ns (0 for an empty bag)."""
        return self.messages[0].log_time_ns if self.messages else 0

    @property
    def duration_ns(self) -> int:
        """Log time from the first to the last message, ns."""
        return self.messages[-1].log_time_ns - self.start_ns if self.messages else 0


def mcap_file(path: str | os.PathLike[str]) -> Path:
    """The ``.mcap`` file of a bag folder (from metadata.yaml, else the only one), or a file.

    Raises
    ------
    ValueError
        If the path does not exist or the folder holds no single ``.mcap`` file.
    """
    path = Path(path)
    if path.is_file():
        return path
    if not path.is_dir():
        raise ValueError(f'bag {path} does not exist')
    meta = path / 'metadata.yaml'
    if meta.is_file():
        info = yaml.safe_load(meta.read_text()).get('rosbag2_bagfile_information', {})
        files = info.get('relative_file_paths') or []
        if len(files) == 1 and (path / files[0]).is_file():
            return path / files[0]
    found = sorted(path.glob('*.mcap'))
    if len(found) != 1:
        raise ValueError(f'bag folder {path} holds {len(found)} .mcap files, expected 1')
    return found[0]


def _records(stream: io.BufferedReader, contents: BagContents) -> Iterator[tuple[int, bytes]]:
    """Yield (opcode, body) of each complete record; set stop_reason at the end."""
    magic = stream.read(len(MCAP_MAGIC))
    if magic != MCAP_MAGIC:
        contents.stop_reason = 'not an MCAP file (bad magic)'
        return
    contents.bytes_read = len(magic)
    while True:
        head = stream.read(9)
        if len(head) < 9:
            contents.stop_reason = 'file ends before the footer (truncated)'
            return
        opcode, length = struct.unpack('<BQ', head)
        body = stream.read(length)
        if len(body) < length:
            contents.stop_reason = (
                f'file ends inside a record (opcode {opcode:#04x}, {len(body)} of {length} bytes)'
            )
            return
        contents.bytes_read += 9 + length
        yield opcode, body
        if opcode == Opcode.FOOTER:
            return


def read_messages(
    path: str | os.PathLike[str],
    topics: Iterable[str] | None = None,
) -> BagContents:
    """Read every message of a bag, tolerating a file cut at any byte.

    Parameters
    ----------
    path : str or Path
        Bag folder or ``.mcap`` file.
    topics : iterable of str, optional
        Keep only these topics (all by default).

    Returns
    -------
    BagContents
        Messages sorted by log time, channels, metadata records, statistics (complete
        files only), ``complete`` (the footer was reached and every record was whole)
        and ``stop_reason`` otherwise.
    """
    wanted = set(topics) if topics is not None else None
    file = mcap_file(path)
    contents = BagContents(path=Path(path))
    schemas: dict[int, Schema] = {}
    pending: list[BagMessage] = []

    def channel_of(record: Channel) -> None:
        schema = schemas.get(record.schema_id)
        contents.channels[record.id] = ChannelInfo(
            id=record.id,
            topic=record.topic,
            type=schema.name if schema else '',
            message_encoding=record.message_encoding,
            schema_encoding=schema.encoding if schema else '',
            definition=schema.data.decode(errors='replace') if schema else '',
            metadata=dict(record.metadata),
        )

    def message_of(record: Message) -> None:
        channel = contents.channels.get(record.channel_id)
        if channel is None:
            raise McapError(f'message on unknown channel {record.channel_id}')
        if wanted is None or channel.topic in wanted:
            pending.append(
                BagMessage(
                    channel.topic,
                    channel.type,
                    record.log_time,
                    record.publish_time,
                    bytes(record.data),
                    record.sequence,
                )
            )

    def handle(record: object) -> None:
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel):
            if record.id not in contents.channels:
                channel_of(record)
        elif isinstance(record, Message):
            message_of(record)

    with open(file, 'rb') as stream:
        for opcode, body in _records(stream, contents):
            data = ReadDataStream(io.BytesIO(body))
            try:
                if opcode == Opcode.CHUNK:
                    chunk_records = breakup_chunk(Chunk.read(data), validate_crc=True)
                    # All or nothing per chunk: a corrupt chunk adds no message.
                    before = len(pending)
                    try:
                        for record in chunk_records:
                            handle(record)
                    except McapError:
                        del pending[before:]
                        raise
                    contents.chunks += 1
                elif opcode == Opcode.SCHEMA:
                    handle(Schema.read(data))
                elif opcode == Opcode.CHANNEL:
                    handle(Channel.read(data))
                elif opcode == Opcode.MESSAGE:
                    handle(Message.read(data, len(body)))
                elif opcode == Opcode.METADATA:
                    record = Metadata.read(data)
                    contents.metadata[record.name] = dict(record.metadata)
                elif opcode == Opcode.STATISTICS:
                    contents.statistics = Statistics.read(data)
                elif opcode == Opcode.FOOTER:
                    Footer.read(data)
                    contents.complete = True
            except Exception as exc:  # noqa: BLE001 - zstd/lz4/struct/CRC errors share no base
                contents.stop_reason = f'corrupt record (opcode {opcode:#04x}): {exc!r}'
                contents.complete = False
                break
    if contents.complete:
        contents.stop_reason = ''
    pending.sort(key=lambda m: m.log_time_ns)  # stable: equal times keep file order
    contents.messages = pending
    return contents


_DECODERS: dict[tuple[str, str], Any] = {}


def decode(contents: BagContents, message: BagMessage) -> Any:
    """Decode a message's CDR with the definition stored in the bag.

    Returns
    -------
    object
        An object whose attributes are the message's fields (mcap-ros2-support).

    A ``ros2idl`` schema (a service's event) is decoded with the installed type's
    ``ros2msg`` text (:func:`~suspension_tuning.bag.definitions.definition_text`):
    mcap-ros2-support reads ``ros2msg`` only, and the bytes are those of that type.

    Raises
    ------
    ValueError
        If the bag has no ``ros2msg`` or ``ros2idl`` definition for the message's type.
    """
    from mcap.records import Schema as SchemaRecord
    from mcap_ros2.decoder import DecoderFactory

    channel = next(c for c in contents.channels.values() if c.topic == message.topic)
    key = (channel.type, channel.definition)
    if key not in _DECODERS:
        definition = channel.definition
        if channel.schema_encoding == 'ros2idl':
            from suspension_tuning.bag.definitions import DefinitionNotFoundError, definition_text
            try:
                definition = definition_text(channel.type)
            except DefinitionNotFoundError as error:
                raise ValueError(f'topic {message.topic}: ros2idl schema of a type not '
                                 f'installed here ({error})') from None
        elif channel.schema_encoding != 'ros2msg':
            raise ValueError(
                f'topic {message.topic}: schema encoding '
                f'{channel.schema_encoding!r} is not ros2msg or ros2idl'
            )
        name, text = _rosidl_adapter_names(channel.type, definition)
        schema = SchemaRecord(id=1, name=name, encoding='ros2msg', data=text.encode())
        _DECODERS[key] = DecoderFactory().decoder_for('cdr', schema)
    return _DECODERS[key](message.data)


def _rosidl_adapter_names(type_name: str, definition: str) -> tuple[str, str]:
    """Rename types like ``pkg/srv/T_Event`` to ``pkg/srv/TEvent`` for mcap-ros2-support.

    Its vendored rosidl_adapter parser (0.6) only accepts message names matching
    ``^[A-Z][A-Za-z0-9]*$``, so service events and action messages, which the middleware
    names ``T_Event``, ``T_FeedbackMessage``, ..., cannot be parsed under their real
    names.  Names do not enter the CDR layout, so renaming every occurrence
    consistently decodes the same bytes; the bag itself keeps the real names.
    """
    names = {type_name} | set(re.findall(r'^MSG: (\S+)$', definition, flags=re.MULTILINE))
    for full in sorted(names, key=len, reverse=True):
        package, name = full.split('/')[0], full.split('/')[-1]
        if '_' not in name:
            continue
        fixed = name.replace('_', '')
        pattern = rf'(?<![\w/]){re.escape(package)}/(?:(msg|srv|action)/)?{re.escape(name)}(?!\w)'
        # two-part names in the text: its parser refuses pkg/action/T as a field type
        definition = re.sub(pattern, lambda m, p=package, f=fixed: f'{p}/{f}', definition)
        if full == type_name:
            type_name = (
                f'{package}/{full.split("/")[1]}/{fixed}'
                if full.count('/') == 2
                else f'{package}/{fixed}'
            )
    return type_name, definition


def read_metadata_yaml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``rosbag2_bagfile_information`` mapping of a bag folder's metadata.yaml."""
    meta = Path(path) / 'metadata.yaml'
    if not meta.is_file():
        raise ValueError(f'{path} has no metadata.yaml')
    return yaml.safe_load(meta.read_text())['rosbag2_bagfile_information']


def reindex(path: str | os.PathLike[str], output: str | os.PathLike[str] | None = None) -> Path:
    """Rewrite a (possibly truncated) bag into a complete one, like ``ros2 bag reindex``.

    Schemas written before the rosbag2 layout (dependencies headed ``MSG: pkg/msg/T``)
    come out in rosbag2's layout, from the texts stored in the bag
    (:func:`~suspension_tuning.bag.definitions.rosbag2_form`), so Foxglove can decode
    them; a schema that cannot be rewritten is kept as it is.

    Parameters
    ----------
    path : str or Path
        Bag folder or ``.mcap`` file to repair.
    output : str or Path, optional
        New bag folder; by default the bag folder is repaired in place (its ``.mcap``
        is replaced by the rewritten file and metadata.yaml rewritten).

    Returns
    -------
    Path
        The folder of the complete bag.
    """
    from suspension_tuning.bag.definitions import DefinitionNotFoundError, rosbag2_form
    from suspension_tuning.bag.writer import BagWriter

    contents = read_messages(path)
    source = mcap_file(path)
    in_place = output is None
    target = Path(output) if output is not None else source.parent / f'.{source.stem}.reindex'
    writer = BagWriter(target)
    by_topic = {}
    for channel in sorted(contents.channels.values(), key=lambda c: c.id):
        definition = channel.definition
        if channel.schema_encoding == 'ros2msg':
            try:
                definition = rosbag2_form(channel.type, definition)
            except (DefinitionNotFoundError, ValueError):
                pass  # the stored text stays: it still decodes with mcap-ros2-support
        by_topic[channel.topic] = writer.add_topic(
            channel.topic,
            channel.type,
            channel.offered_qos_profiles,
            definition=definition,
            type_description_hash=channel.metadata.get('topic_type_hash', ''),
            schema_encoding=channel.schema_encoding,
        )
    for name, data in contents.metadata.items():
        if name == 'rosbag2':
            continue
        writer.add_metadata(name, data)
    for message in contents.messages:
        writer.write(
            message.topic,
            message.data,
            message.log_time_ns,
            message.publish_time_ns,
            message.sequence,
        )
    writer.close()
    if not in_place:
        return target
    folder = source.parent
    os.replace(writer.mcap_path, source)
    text = (target / 'metadata.yaml').read_text().replace(writer.mcap_path.name, source.name)
    (folder / 'metadata.yaml').write_text(text)
    (target / 'metadata.yaml').unlink()
    target.rmdir()
    return folder
