"""One reader over every kind of bag other tools write: the small interface ``rosbag.py`` uses.

``open_reader(path)`` returns a ``BagReader`` with

- ``connections``: ``BagConnection(topic, msgtype, msgcount)``, ``msgtype`` always spelled
  ``pkg/msg/Type`` (ROS1 writes ``sensor_msgs/Image``, ROS2 ``sensor_msgs/msg/Image``;
  ``normalize_type`` turns either into the second, so types are matched one way everywhere);
- ``messages(connections, start, stop)``: ``(connection, log time ns, raw bytes)`` in log time
  order, ``start`` inclusive, ``stop`` exclusive; raw bytes are the serialised message, already
  decompressed;
- ``deserialize(raw, msgtype)`` and ``is2`` (True: CDR, the header stamp at bytes 4..12 after
  the encapsulation; False: ROS1 serialisation);
- ``close()``, which may be called twice.

Backends:
- rosbags' ``AnyReader`` for ROS1 .bag files (any chunk compression: none, bz2, lz4) and
  ROS2 bags (sqlite3 or MCAP storage with profile ``ros2``; ``compression_mode`` file or
  message from metadata.yaml; MCAP chunks zstd or lz4).
- the ``mcap`` library for MCAP files whose profile is not ``ros2``: ``ros1`` (written by
  ``mcap convert`` from a .bag, Foxglove's and the ``mcap`` ROS1 writers) or none, with
  channels in ``ros1`` or ``cdr`` message encoding and ``ros1msg`` / ``ros2msg`` / ``ros2idl``
  schemas.

A bare .db3/.mcap file recorded with ``ros2 bag record --compression-mode message`` has every
message compressed by zstd, and only its metadata.yaml says so. A CDR message starts with a
zero byte, a zstd frame with 28 B5 2F FD, so such a message is recognised by its first bytes
and decompressed whatever the metadata says.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path, PurePosixPath
from typing import Any, BinaryIO, Iterator, Optional, Sequence

ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
MCAP_MAGIC = b"\x89MCAP0\r\n"


class BagFormatError(Exception):
    """The file is a bag, but of a kind this reader cannot read (one-line reason)."""


def normalize_type(name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type`` (ROS1 and ROS2 spellings)."""
    path = PurePosixPath(str(name))
    if path.parent.name not in ("msg", "action", "srv") and str(path.parent) not in ("", "."):
        path = path.parent / "msg" / path.name
    return str(path)


@dataclasses.dataclass(frozen=True)
class BagConnection:
    topic: str
    msgtype: str          # normalised: pkg/msg/Type
    msgcount: int
    key: Any = dataclasses.field(compare=False, hash=False)  # the backend's own connection


def _zstd_decompress(data: bytes) -> bytes:
    try:
        from compression import zstd  # Python >= 3.14
    except ImportError:  # rosbags depends on the backport below Python 3.14
        from backports import zstd
    return zstd.decompress(data)


def decompressed(raw: Any, cdr: bool) -> Any:
    """``raw`` itself, or its zstd decompression when it is a zstd frame of a CDR message."""
    if cdr and len(raw) >= 4 and bytes(raw[:4]) == ZSTD_MAGIC:
        return _zstd_decompress(bytes(raw))
    return raw


class BagReader:
    """Common face of the backends (see the module docstring)."""

    is2: bool
    connections: list[BagConnection]

    def messages(self, connections: Optional[Sequence[BagConnection]] = None,
                 start: Optional[int] = None, stop: Optional[int] = None
                 ) -> Iterator[tuple[BagConnection, int, Any]]:
        raise NotImplementedError

    def deserialize(self, raw: Any, msgtype: str) -> Any:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> "BagReader":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class RosbagsReader(BagReader):
    """rosbags' AnyReader, with normalised types and message decompression."""

    def __init__(self, target: Path) -> None:
        from rosbags.highlevel import AnyReader

        self._any = AnyReader([target])
        self._any.open()
        self.is2 = bool(self._any.is2)
        # The type name the typestore knows for each normalised name.
        self._names = {normalize_type(c.msgtype): c.msgtype for c in self._any.connections}
        self.connections = [BagConnection(c.topic, normalize_type(c.msgtype), int(c.msgcount), c)
                            for c in self._any.connections]
        self._by_key = {id(c.key): c for c in self.connections}

    def messages(self, connections=None, start=None, stop=None):
        keys = None if connections is None else [c.key for c in connections]
        for conn, t, raw in self._any.messages(connections=keys, start=start, stop=stop):
            yield self._by_key[id(conn)], t, decompressed(raw, self.is2)

    def deserialize(self, raw, msgtype):
        name = self._names.get(msgtype, msgtype)
        try:
            return self._any.deserialize(raw, name)
        except Exception:
            if name == msgtype:
                raise
            return self._any.deserialize(raw, msgtype)

    def close(self) -> None:
        if self._any.stack is not None:
            self._any.close()


class McapReader(BagReader):
    """An MCAP file of profile ``ros1`` or none, read with the ``mcap`` library."""

    def __init__(self, target: Path) -> None:
        try:
            from mcap.reader import make_reader
        except ImportError:
            raise BagFormatError("reading an MCAP file whose profile is not ros2 needs the "
                                 "'mcap' package (pip install mcap)") from None
        self._file: Optional[BinaryIO] = open(target, "rb")
        try:
            self._reader = make_reader(self._file)
            self._open()
        except BaseException:
            self.close()
            raise

    def _open(self) -> None:
        summary = self._reader.get_summary()
        if summary is None:  # no summary section (a cut recording): one scan for what it holds
            schemas, channels, counts = {}, {}, {}
            for schema, channel, _ in self._reader.iter_messages(log_time_order=False):
                channels[channel.id] = channel
                if schema is not None:
                    schemas[schema.id] = schema
                counts[channel.id] = counts.get(channel.id, 0) + 1
        else:
            schemas, channels = summary.schemas, summary.channels
            stats = summary.statistics
            counts = dict(stats.channel_message_counts) if stats is not None else None
            if counts is None:
                counts = {}
                for _, channel, _ in self._reader.iter_messages(log_time_order=False):
                    counts[channel.id] = counts.get(channel.id, 0) + 1
        encodings = {ch.message_encoding for ch in channels.values()}
        unknown = encodings - {"ros1", "cdr"}
        if unknown:
            raise BagFormatError(f"MCAP message encoding {', '.join(sorted(unknown))} is not ROS "
                                 f"(ros1 or cdr)")
        if len(encodings) > 1:
            raise BagFormatError("MCAP file mixes ros1 and cdr message encodings")
        self.is2 = encodings == {"cdr"}
        from rosbags.typesys import Stores, get_typestore

        self.connections = []
        self._by_channel: dict[int, BagConnection] = {}
        types: dict[str, Any] = {}
        for cid, ch in sorted(channels.items()):
            schema = schemas.get(ch.schema_id)
            name = normalize_type(schema.name) if schema is not None else ""
            if schema is not None and schema.data:
                types.update(_schema_types(schema, name))
            conn = BagConnection(ch.topic, name, int(counts.get(cid, 0)), cid)
            self.connections.append(conn)
            self._by_channel[cid] = conn
        # The recording's own definitions first (as rosbags' AnyReader does); the standard
        # ones of its ROS version only for types it does not define.
        default = get_typestore(Stores.ROS2_HUMBLE if self.is2 else Stores.ROS1_NOETIC)
        for typename, fields in default.fielddefs.items():
            types.setdefault(typename, fields)
        self._store = get_typestore(Stores.EMPTY)
        self._store.register(types)

    def messages(self, connections=None, start=None, stop=None):
        wanted = None if connections is None else {c.key for c in connections}
        topics = None if connections is None else sorted({c.topic for c in connections})
        if start is not None and stop is not None and stop <= start:
            return
        assert self._file is not None, "MCAP reader is closed"
        for _, channel, message in self._reader.iter_messages(topics=topics, starting_at=start,
                                                              ending_before=stop):
            if wanted is None or channel.id in wanted:
                yield (self._by_channel[channel.id], int(message.log_time),
                       decompressed(message.data, self.is2))

    def deserialize(self, raw, msgtype):
        if self.is2:
            return self._store.deserialize_cdr(bytes(raw), msgtype)
        return self._store.deserialize_ros1(bytes(raw), msgtype)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def _schema_types(schema: Any, name: str) -> dict[str, Any]:
    """Type definitions of an MCAP schema (ros1msg, ros2msg or ros2idl text)."""
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    text = bytes(schema.data).decode("utf-8")
    if schema.encoding in ("ros1msg", "ros2msg"):
        return get_types_from_msg(text, name)
    if schema.encoding in ("ros2idl", "omgidl"):
        types: dict[str, Any] = {}
        sep = "=" * 80 + "\n"
        parts = text.split(sep)[1:] if text.startswith(sep + "IDL: ") else [text]
        for part in parts:
            types.update(get_types_from_idl(part.split("\n", 1)[1] if part.startswith("IDL: ") else part))
        return types
    raise BagFormatError(f"MCAP schema encoding {schema.encoding!r} of {schema.name} is not a ROS "
                         f"message definition")


def mcap_profile(path: Path) -> Optional[str]:
    """The profile in an MCAP file's header (None when the file is not MCAP)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    if not head.startswith(MCAP_MAGIC) or len(head) < len(MCAP_MAGIC) + 13:
        return None
    # Header record: opcode 0x01, uint64 length, then string profile (uint32 length + bytes).
    at = len(MCAP_MAGIC)
    if head[at] != 0x01:
        return None
    size = int.from_bytes(head[at + 9:at + 13], "little")
    return head[at + 13:at + 13 + size].decode("utf-8", "replace")


def open_reader(target: Path) -> BagReader:
    """A reader for the bag file or directory ``target`` (exceptions as the backends raise them)."""
    target = Path(target)
    if target.is_file() and target.suffix == ".mcap":
        profile = mcap_profile(target)
        if profile is not None and profile != "ros2":
            return McapReader(target)
    return RosbagsReader(target)
