"""One MCAP recording file, and how a record becomes its JSON payload.

``McapFile`` is a file of the recorder: lazy channels (one JSON schema per channel type,
from ``schemas.schema_for``), JSON messages, the URDF as an attachment and on
``/robot_description``; it is not thread safe (the recorder's writer thread, or a tool).

It writes with foxglove-sdk's MCAP writer (Rust; one ``foxglove.Context`` per file, so a
file gets exactly the channels it is given): ~900,000 messages/s to one file, ~450,000/s
to two, against ~316,000/~218,000 for the hand-written ``mcapwriter.LeanWriter`` it replaces
and ~144,000/~67,000 for the ``mcap`` package's writer (services/recorder/README.md,
"Writer"). The SDK sets each message's publish time to its log time and numbers each
channel's messages itself (from 1, like the recorder did).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import foxglove
import msgspec
from foxglove._foxglove_py import BaseChannel
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from .schemas import schema_for

ROBOT_DESCRIPTION_TOPIC = "/robot_description"
#: a chunk is compressed when it holds this much (or at the writer's next flush): 32 KiB
#: keeps each compression to a fraction of a millisecond, where 1 MiB took milliseconds
#: of one CPU that a request beside it could not have (docs/PERFORMANCE.md, "The
#: recorder's writing"); the files grow by about a tenth for it (more chunk indexes)
CHUNK_SIZE = 32 << 10
#: zstd's fastest level, not its default 3: the chunks are JSON records much alike, which level
#: 1 packs within a few per cent of level 3 (a recording of 6,000 requests: 2.43 against 2.36
#: MB) for a fifth less CPU per record written (docs/PERFORMANCE.md, "What a record costs the
#: recorder, and zstd's fastest level")
ZSTD_LEVEL = 1

_encoder = msgspec.json.Encoder()
_decoder = msgspec.json.Decoder()


def encode(data: Any) -> bytes:
    """JSON bytes of a record: dict/list/msgspec Struct, or bytes passed through."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        return bytes(data)
    try:
        return _encoder.encode(data)
    except (TypeError, msgspec.EncodeError):
        return json.dumps(data, default=repr).encode()


def as_dict(data: Any) -> Any:
    """A record's data as Python objects: JSON bytes decoded, a Struct as builtins
    (anything else, and bytes that are not JSON, as they are)."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        try:
            return _decoder.decode(data)
        except msgspec.DecodeError:
            return data
    if isinstance(data, msgspec.Struct):
        return msgspec.to_builtins(data)
    return data


class McapFile:
    """One MCAP file: lazy channels (one JSON schema per channel type), JSON messages.

    Not thread safe: used by the recorder's writer thread (or a tool) only.
    """

    def __init__(self, path: str | os.PathLike[str], *, start_ns: int | None = None,
                 urdf: str | None = None, metadata: dict[str, dict[str, str]] | None = None,
                 chunk_size: int = CHUNK_SIZE, compression: str = "zstd"):
        self.path = Path(path)
        self.start_ns = time.time_ns() if start_ns is None else start_ns
        self.opened = time.monotonic()
        if compression not in ("zstd", "lz4", "none", ""):
            raise ValueError("compression must be 'zstd', 'lz4' or 'none'")
        self._context = foxglove.Context()
        self._w = foxglove.open_mcap(self.path, context=self._context, writer_options=MCAPWriteOptions(
            compression={"zstd": MCAPCompression.Zstd, "lz4": MCAPCompression.Lz4}.get(compression),
            profile="", chunk_size=chunk_size, compression_level=ZSTD_LEVEL if compression == "zstd" else 0,
            compression_threads=0))  # on the recorder's writer thread, not on every core
        self._fd = os.open(self.path, os.O_RDONLY)  # fsync and size; the SDK owns the writing
        self._channels: dict[str, BaseChannel] = {}
        self.messages = 0
        self.pending = 0  # messages not yet flushed to the OS
        self.closed = False
        for name, values in (metadata or {}).items():
            self.add_metadata(name, values)
        if urdf:
            self._w.attach(create_time=self.start_ns, log_time=self.start_ns,
                           name="robot.urdf", media_type="application/xml", data=urdf.encode())
            self.write(ROBOT_DESCRIPTION_TOPIC, self.start_ns, self.start_ns,
                       _encoder.encode({"data": urdf}))
        self.flush()

    def channel(self, topic: str) -> BaseChannel:
        ch = self._channels.get(topic)
        if ch is None:
            spec = schema_for(topic)
            # the context's own channel (not foxglove.Channel, which registers every channel
            # in a process-wide table for good: files rotate, their channels must go with them)
            ch = self._channels[topic] = self._context._create_channel(
                topic, message_encoding="json",
                schema=foxglove.Schema(name=spec.name, encoding="jsonschema", data=spec.data))
        return ch

    def write(self, topic: str, log_time: int, publish_time: int, payload: bytes) -> None:
        """One message; ``publish_time`` is not kept (the SDK writes the log time)."""
        (self._channels.get(topic) or self.channel(topic)).log(payload, log_time)
        self.messages += 1
        self.pending += 1

    def add_metadata(self, name: str, values: dict[str, Any]) -> None:
        self._w.write_metadata(name, {k: str(v) for k, v in values.items()})

    def flush(self, fsync: bool = False) -> None:
        """Close the open chunk and hand everything to the OS (and the disk if fsync)."""
        self._w.flush()
        if fsync:
            os.fsync(self._fd)
        self.pending = 0

    def size(self) -> int:
        """Bytes on disk (the open chunk not included)."""
        return os.fstat(self._fd).st_size

    def close(self, metadata: dict[str, Any] | None = None) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            if metadata:
                self.add_metadata("rob6.end", metadata)
            for ch in self._channels.values():
                ch.close()
            self._w.close()
            os.fsync(self._fd)
        finally:
            os.close(self._fd)
