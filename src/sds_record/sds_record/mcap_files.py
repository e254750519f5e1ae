"""MCAP files of serialized ROS 2 messages: a crash-safe writer, the one reader, repair.

Files follow rosbag2's MCAP layout (profile "ros2", schemas in `ros2msg` encoding, CDR
messages), so the `mcap` readers, `rosbags` and Foxglove open them. Every tool reads
recordings through `read_messages` (CDR bytes) or `decoded_messages` (message objects decoded
by rosbags from the embedded schemas, no generated classes needed). A recording whose recorder
did not close it (a crash, SIGKILL) has no summary: it is read in file order up to its last
complete chunk, and a warning (logger `sds_record.mcap_files`) says how many messages that
gave and that `sds mcap-repair` gives the file an index.
"""

from __future__ import annotations

import logging
import shlex
import struct
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.summary import Summary
from mcap.writer import CompressionType, Writer
from rosbags.serde import SerdeError
from rosbags.typesys import (
    Stores,
    TypesysError,
    get_types_from_idl,
    get_types_from_msg,
    get_typestore,
)
from sds_model.errors import InputError
from sds_model.staging import staged_file

from sds_record.schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, message_definition

PROFILE = "ros2"
DURABILITY_KEY = "durability"
"""Channel metadata key: the recorded publishers' durability, transient_local or volatile."""
NOT_RECORDED_METADATA = "sds.not_recorded"
"""Metadata record: topic → how many of its published messages the recorder never got."""
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}
_log = logging.getLogger(__name__)
_warned: set[tuple[Path, str]] = set()
"""(file, warning) pairs this process has given (each file is read several times): an
unfinished file, one that lacks messages its recorder never got."""


@dataclass(frozen=True)
class RecordedMessage:
    """One message of a recording: topic, type ('pkg/msg/Type'), CDR bytes, times [ns]."""

    topic: str
    type_name: str
    data: bytes
    log_time_ns: int
    publish_time_ns: int
    latched: bool = False


def header_stamp_ns(cdr: bytes) -> int:
    """Stamp [ns] of a serialized message whose first field is std_msgs/Header (or a
    builtin_interfaces/Time: foxglove_msgs/CompressedVideo's timestamp).

    CDR: a 4-byte encapsulation (byte 1 odd = little-endian), then int32 sec, uint32 nanosec.
    """
    order = "<" if cdr[1] & 1 else ">"
    sec, nanosec = struct.unpack_from(f"{order}iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


MCAP_MAGIC = b"\x89MCAP0\r\n"
"""The first bytes of every MCAP file."""


class McapRecorder:
    """Writes serialized messages; a chunk is closed and flushed at least every `flush_period_s`
    so that a killed process loses at most that much (the OS keeps what was written)."""

    def __init__(self, path: str | Path, compression: str = "zstd",
                 chunk_size: int = 4 * 1024 * 1024, flush_period_s: float = 0.5,
                 overwrite: bool = False) -> None:
        if compression not in COMPRESSIONS:
            raise InputError(f"compression {compression!r} is not one of {sorted(COMPRESSIONS)}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if not overwrite and self.path.is_file() and not holds_messages(self.path):
            # What a graph that never got going left: nothing to keep, nothing to block on.
            _log.warning(f"{self.path}: replacing a recording without messages")
            overwrite = True
        try:   # never replaces a recording with messages unless told to
            self._stream = self.path.open("wb" if overwrite else "xb")
        except FileExistsError:
            raise InputError(f"{self.path} exists (not replaced: choose another name, or "
                             "overwrite: --overwrite, or the recorder's overwrite=true)"
                             ) from None
        self._writer = Writer(self._stream, chunk_size=chunk_size,
                              compression=COMPRESSIONS[compression])
        self._writer.start(profile=PROFILE, library="sds_record")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._flush_period_s = flush_period_s
        self._last_flush = time.monotonic()
        self._lock = threading.Lock()
        self.message_count = 0
        self.closed = False

    def add_topic(self, topic: str, type_name: str, latched: bool = False) -> None:
        """Register a topic (and its type's schema) before its first message; `latched`
        (transient-local publishers) is kept in the channel's metadata for playback."""
        with self._lock:
            if topic in self._channels:
                return
            if type_name not in self._schemas:
                self._schemas[type_name] = self._writer.register_schema(
                    type_name, SCHEMA_ENCODING, message_definition(type_name).encode())
            self._channels[topic] = self._writer.register_channel(
                topic, MESSAGE_ENCODING, self._schemas[type_name],
                {DURABILITY_KEY: "transient_local" if latched else "volatile"})
            self._sequence[topic] = 0

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int) -> None:
        """Append one serialized message of a registered topic."""
        with self._lock:
            if self.closed:
                return
            self._writer.add_message(self._channels[topic], log_time_ns, data, publish_time_ns,
                                     self._sequence[topic])
            self._sequence[topic] += 1
            self.message_count += 1
            self._flush_if_due()

    def flush_if_due(self) -> None:
        """Close the open chunk if `flush_period_s` has passed (call from a timer)."""
        with self._lock:
            if not self.closed:
                self._flush_if_due()

    def _flush_if_due(self) -> None:
        if time.monotonic() - self._last_flush >= self._flush_period_s:
            self._writer.flush()
            self._last_flush = time.monotonic()

    def close(self, not_recorded: dict[str, int] | None = None) -> None:
        """Write the summary section and close the file; `not_recorded` (topic → messages
        its publishers wrote that never came) goes into a metadata record
        (NOT_RECORDED_METADATA, read back by `not_recorded`)."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            if not_recorded:
                self._writer.add_metadata(NOT_RECORDED_METADATA, {
                    topic: str(count) for topic, count in sorted(not_recorded.items())})
            self._writer.finish()
            self._stream.close()


def _summary(path: Path) -> Summary | None:
    """The file's summary section; None when it has none or ends early (a crash)."""
    with path.open("rb") as stream:
        try:
            return make_reader(stream).get_summary()
        except (McapError, OSError, ValueError, StopIteration):
            return None


def _linear_messages(path: Path) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """Every complete message in file order, stopping quietly at a truncated tail."""
    with path.open("rb") as stream:
        try:
            yield from NonSeekingReader(stream).iter_messages(log_time_order=False)
        except (McapError, EOFError, ValueError):
            return


def _indexed_messages(path: Path, topics: Iterable[str] | None
                      ) -> Iterator[tuple[Schema | None, Channel, Message]]:
    with path.open("rb") as stream:
        yield from make_reader(stream).iter_messages(topics=topics, log_time_order=True)


def holds_messages(path: Path) -> bool:
    """Whether the file at `path` holds a message, or is no MCAP file (then it is someone's
    data, not an empty recording): False only for an MCAP file without a message."""
    with path.open("rb") as stream:
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            return True
    summary = _summary(path)
    if summary is not None and summary.statistics is not None:
        return summary.statistics.message_count > 0
    return next(_linear_messages(path), None) is not None


def require_mcap(path: Path) -> None:
    """InputError unless `path` is a file that starts as an MCAP file does."""
    if not path.is_file():
        raise InputError(f"{path}: no such recording")
    with path.open("rb") as stream:
        if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise InputError(f"{path} is not an MCAP file (no MCAP magic at its start)")


def _records(path: Path, topics: Iterable[str] | None
             ) -> Iterator[tuple[Schema | None, Channel, Message]]:
    """The wanted topics' messages: log-time order from the index, else (an unfinished file)
    file order up to the last complete chunk, with one warning per file and process once a
    read that found some is done. InputError if the file is not MCAP or a chunk is corrupt."""
    require_mcap(path)
    wanted = set(topics) if topics is not None else None
    if _summary(path) is not None:
        if (path.resolve(), "not recorded") not in _warned:
            _warned.add((path.resolve(), "not recorded"))
            lost = not_recorded(path)
            if lost:
                _log.warning(f"{path} lacks messages its recorder never got: " + ", ".join(
                    f"{count} of {topic}" for topic, count in sorted(lost.items())))
        try:
            yield from _indexed_messages(path, wanted)
        except McapError as error:
            raise InputError(f"{path}: a corrupt chunk ({error}); `sds mcap-repair "
                             f"{shlex.quote(str(path))} REPAIRED.mcap` keeps what is whole"
                             ) from None
        return
    complete = found = 0
    for schema, channel, message in _linear_messages(path):
        complete += 1
        if wanted is None or channel.topic in wanted:
            found += 1
            yield schema, channel, message
    # Nothing found: the caller's own error (no such topic...) says it all.
    if found and (path.resolve(), "unfinished") not in _warned:
        _warned.add((path.resolve(), "unfinished"))
        _log.warning(f"{path} is unfinished (its recorder did not close it): {complete} "
                     "messages up to its last complete chunk are read; `sds mcap-repair "
                     f"{shlex.quote(str(path))} REPAIRED.mcap` gives it an index")


def read_messages(path: str | Path, topics: Iterable[str] | None = None
                  ) -> Iterator[RecordedMessage]:
    """Messages as CDR bytes, in log-time order (an unfinished file: in file order)."""
    for schema, channel, message in _records(Path(path), topics):
        yield RecordedMessage(channel.topic, schema.name if schema else "", message.data,
                              message.log_time, message.publish_time,
                              channel.metadata.get(DURABILITY_KEY) == "transient_local")


def decoded_messages(path: str | Path, topics: Iterable[str] | None = None,
                     types: Iterable[str] | None = None
                     ) -> Iterator[tuple[RecordedMessage, Any]]:
    """Messages with their objects, decoded by the schemas the file embeds (rclpy's field
    names; arrays of numbers as numpy arrays); only `types` ('pkg/msg/Type') if given, so that
    a reader of small messages does not decode the frames. Messages of a channel without a
    schema or not in CDR are skipped; a message or schema that does not decode raises
    InputError naming its topic."""
    decoders: dict[int, Callable[[memoryview], Any]] = {}
    wanted_types = set(types) if types is not None else None
    for schema, channel, message in _records(Path(path), topics):
        if schema is None or channel.message_encoding != MESSAGE_ENCODING or (
                wanted_types is not None and schema.name not in wanted_types):
            continue
        if schema.id not in decoders:
            decoders[schema.id] = _decoder(schema, channel.topic)
        recorded = RecordedMessage(channel.topic, schema.name, message.data, message.log_time,
                                   message.publish_time,
                                   channel.metadata.get(DURABILITY_KEY) == "transient_local")
        try:
            decoded = decoders[schema.id](memoryview(message.data))
        except SerdeError as error:
            raise InputError(f"{channel.topic}: the message logged at {message.log_time} ns "
                             f"does not decode ({error})") from None
        yield recorded, decoded


def _decoder(schema: Schema, topic: str) -> Callable[[memoryview], Any]:
    """CDR → message object for one schema (rosbags, its own typestore: two schemas may
    define a nested type differently)."""
    store = get_typestore(Stores.EMPTY)
    try:
        text = schema.data.decode()
        if schema.encoding == SCHEMA_ENCODING:
            store.register(get_types_from_msg(text, schema.name))
        elif schema.encoding == "ros2idl":
            store.register(get_types_from_idl(text))
        else:
            raise TypesysError(f"schema encoding {schema.encoding!r} is not ROS 2's")
        store.get_msgdef(schema.name)
    except (TypesysError, UnicodeDecodeError, KeyError) as error:
        raise InputError(f"{topic}: its schema {schema.name} does not parse ({error})") from None
    return partial(store.deserialize_cdr, typename=schema.name)


def message_counts(path: str | Path, topics: Iterable[str]) -> dict[str, int]:
    """How many messages each of `topics` has in the file: from its statistics, without
    reading them (an unfinished file: counted up to its last complete chunk)."""
    path = Path(path)
    require_mcap(path)
    counts = dict.fromkeys(topics, 0)
    summary = _summary(path)
    if summary is not None and summary.statistics is not None:
        for channel_id, count in summary.statistics.channel_message_counts.items():
            channel = summary.channels.get(channel_id)
            if channel is not None and channel.topic in counts:
                counts[channel.topic] += count
        return counts
    for _, channel, _ in _records(path, counts):
        counts[channel.topic] += 1
    return counts


def not_recorded(path: str | Path) -> dict[str, int]:
    """Topic → messages its publishers wrote that the recorder never got (before it
    subscribed, or lost on the way), as its recorder wrote them when closing the file; {}
    for a file without that record (none lost, or an unfinished file)."""
    path = Path(path)
    require_mcap(path)
    if _summary(path) is None:
        return {}
    counts: dict[str, int] = {}
    with path.open("rb") as stream:
        for record in make_reader(stream).iter_metadata():
            if record.name == NOT_RECORDED_METADATA:
                counts.update({topic: int(count) for topic, count in record.metadata.items()})
    return counts


def recorded_topics(path: str | Path) -> dict[str, tuple[str, bool]]:
    """Topic → (type name, latched) of every channel in the file (summary, else a scan)."""
    path = Path(path)
    require_mcap(path)
    summary = _summary(path)
    if summary is not None:
        schemas, channels = summary.schemas, list(summary.channels.values())
    else:
        records = list(r for r in _linear_records(path) if not isinstance(r, Message))
        schemas = {r.id: r for r in records if isinstance(r, Schema)}
        channels = [r for r in records if isinstance(r, Channel)]
    return {c.topic: (schemas[c.schema_id].name if c.schema_id in schemas else "",
                      c.metadata.get(DURABILITY_KEY) == "transient_local") for c in channels}


@dataclass(frozen=True)
class RepairReport:
    """What `repair` copied."""

    messages: int
    topics: int
    had_summary: bool


def repair(source: str | Path, target: str | Path, compression: str = "zstd",
           overwrite: bool = False) -> RepairReport:
    """Copy every complete message of `source` into a new file with a summary section (the
    target appears only when complete)."""
    source, target = Path(source), Path(target)
    if source.resolve() == target.resolve():
        raise InputError("repair writes a new file: give a target other than the source")
    require_mcap(source)
    if target.exists() and not overwrite:
        raise InputError(f"{target} exists (not replaced: choose another name, or --overwrite)")
    had_summary = _summary(source) is not None
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    count = 0
    with staged_file(target) as staging, staging.open("wb") as output:
        writer = Writer(output, compression=COMPRESSIONS[compression])
        writer.start(profile=PROFILE, library="sds_record repair")
        for record in _linear_records(source):
            if isinstance(record, Schema) and record.id not in schemas:
                schemas[record.id] = writer.register_schema(record.name, record.encoding,
                                                            record.data)
            elif isinstance(record, Channel) and record.id not in channels:
                channels[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schemas.get(record.schema_id, 0),
                    record.metadata)
            elif isinstance(record, Message) and record.channel_id in channels:
                writer.add_message(channels[record.channel_id], record.log_time, record.data,
                                   record.publish_time, record.sequence)
                count += 1
        writer.finish()
    return RepairReport(count, len(channels), had_summary)


def _linear_records(path: Path) -> Iterator[Schema | Channel | Message]:
    """Schema, channel and message records in file order (chunks opened), to a truncated end."""
    with path.open("rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False).records:
                if isinstance(record, Schema | Channel | Message):
                    yield record
        except (McapError, EOFError, ValueError):
            return
