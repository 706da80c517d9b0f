"""One MCAP recording file, and how a record becomes its JSON payload.

``McapFile`` is a file of the recorder: lazy channels (one JSON schema per channel type,
from ``schemas.schema_for``), JSON messages, the URDF as an attachment and on
``/robot_description``; it is not thread safe (the recorder's writer thread, or a tool).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import msgspec

from . import __version__
from .mcapwriter import LeanWriter
from .schemas import schema_for

ROBOT_DESCRIPTION_TOPIC = "/robot_description"

_encoder = msgspec.json.Encoder()
_decoder = msgspec.json.Decoder()


def encode(data: Any) -> bytes:
    """JSON bytes of a record: dict/list/msgspec Struct, or bytes passed through."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        return bytes(data)
    try:
        return _encoder.encode(data)
    except (TypeError, msgspec.EncodeError):
        import json
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
                 chunk_size: int = 1 << 20, compression: str = "zstd"):
        self.path = Path(path)
        self.start_ns = time.time_ns() if start_ns is None else start_ns
        self.opened = time.monotonic()
        self._fh = open(self.path, "xb")
        self._w = LeanWriter(self._fh, chunk_size=chunk_size,
                             compression="" if compression == "none" else compression)
        self._w.start(profile="", library=f"rob6-recorder/{__version__}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: dict[int, int] = {}
        self.messages = 0
        self.pending = 0  # messages not yet flushed to the OS
        self.closed = False
        for name, values in (metadata or {}).items():
            self._w.add_metadata(name, {k: str(v) for k, v in values.items()})
        if urdf:
            self._w.add_attachment(create_time=self.start_ns, log_time=self.start_ns,
                                   name="robot.urdf", media_type="application/xml",
                                   data=urdf.encode())
            self.write(ROBOT_DESCRIPTION_TOPIC, self.start_ns, self.start_ns,
                       _encoder.encode({"data": urdf}))
        self.flush()

    def channel(self, topic: str) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            spec = schema_for(topic)
            sid = self._schemas.get(spec.name)
            if sid is None:
                sid = self._schemas[spec.name] = self._w.register_schema(
                    spec.name, "jsonschema", spec.data)
            ch = self._channels[topic] = self._w.register_channel(topic, "json", sid)
            self._seq[ch] = 0
        return ch

    def write(self, topic: str, log_time: int, publish_time: int, payload: bytes) -> None:
        ch = self._channels.get(topic) or self.channel(topic)
        seq = self._seq[ch] = (self._seq[ch] + 1) & 0xFFFFFFFF
        self._w.add_message(ch, log_time, payload, publish_time, seq)
        self.messages += 1
        self.pending += 1

    def add_metadata(self, name: str, values: dict[str, Any]) -> None:
        self._w.add_metadata(name, {k: str(v) for k, v in values.items()})

    def flush(self, fsync: bool = False) -> None:
        """Close the open chunk and hand everything to the OS (and the disk if fsync)."""
        self._w.flush()
        if fsync:
            os.fsync(self._fh.fileno())
        self.pending = 0

    def size(self) -> int:
        return self._w.tell()

    def close(self, metadata: dict[str, Any] | None = None) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            if metadata:
                self.add_metadata("rob6.end", metadata)
            self._w.finish()
            self._fh.flush()
            os.fsync(self._fh.fileno())
        finally:
            self._fh.close()
