"""CDR (XCDR1, little endian) serialisation of the ROS 2 messages in ``idl``, as rmw_zenoh sends them.

A message is a dict of its fields (missing fields take their zero value); nested messages are
dicts, sequences and arrays are lists (``uint8`` arrays and sequences may be ``bytes``). The
payload starts with the 4-byte encapsulation header ``00 01 00 00`` (CDR_LE); each primitive
is aligned to its size, counted from after the header; a string is its length including the
terminating NUL (uint32), its UTF-8 bytes and the NUL; a sequence is its length (uint32) and
its elements; an array only its elements.
"""

from __future__ import annotations

import struct
from typing import Any

from .idl import MESSAGES, FieldType, parse

HEADER = b"\x00\x01\x00\x00"
_FORMATS = {"bool": "?", "byte": "B", "char": "B", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H",
            "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q", "float32": "f", "float64": "d"}
_PARSED: dict[str, list[tuple[str, FieldType]]] = {}


def _fields(type_name: str) -> list[tuple[str, FieldType]]:
    fields = _PARSED.get(type_name)
    if fields is None:
        if type_name not in MESSAGES:
            raise KeyError(f"unknown ROS type {type_name}")
        fields = _PARSED[type_name] = [(name, parse(spec)) for name, spec in MESSAGES[type_name]]
    return fields


def _zero(base: str) -> Any:
    if base == "string":
        return ""
    if base == "bool":
        return False
    if base in _FORMATS:
        return 0.0 if base.startswith("float") else 0
    return {}


class _Writer:
    def __init__(self) -> None:
        self.buf = bytearray()

    def align(self, size: int) -> None:
        self.buf += b"\x00" * (-len(self.buf) % size)

    def primitive(self, base: str, value: Any) -> None:
        if base == "string":
            data = str(value).encode()
            self.primitive("uint32", len(data) + 1)
            self.buf += data + b"\x00"
            return
        fmt = _FORMATS[base]
        self.align(struct.calcsize(fmt))
        self.buf += struct.pack("<" + fmt, value)

    def element(self, base: str, value: Any) -> None:
        if base in _FORMATS or base == "string":
            self.primitive(base, value)
        else:
            self.message(base, value)

    def message(self, type_name: str, value: dict[str, Any]) -> None:
        for name, ftype in _fields(type_name):
            item = value.get(name)
            if ftype.kind == "single":
                self.element(ftype.base, _zero(ftype.base) if item is None else item)
                continue
            items = list(item) if item is not None else []
            if ftype.kind == "array":
                if not items:
                    items = [_zero(ftype.base)] * ftype.size
                if len(items) != ftype.size:
                    raise ValueError(f"{type_name}.{name}: {len(items)} elements, the array has {ftype.size}")
            else:
                if ftype.kind == "bounded" and len(items) > ftype.size:
                    raise ValueError(f"{type_name}.{name}: {len(items)} elements, at most {ftype.size}")
                self.primitive("uint32", len(items))
            for element in items:
                self.element(ftype.base, element)


class _Reader:
    def __init__(self, data: bytes) -> None:
        self.data = memoryview(data)
        self.pos = 0

    def primitive(self, base: str) -> Any:
        if base == "string":
            length = self.primitive("uint32")
            raw = bytes(self.data[self.pos:self.pos + length])
            if length < 1 or len(raw) != length:
                raise ValueError("truncated string")
            self.pos += length
            return raw[:-1].decode()
        fmt = _FORMATS[base]
        size = struct.calcsize(fmt)
        self.pos += -self.pos % size
        if self.pos + size > len(self.data):
            raise ValueError("truncated message")
        (value,) = struct.unpack_from("<" + fmt, self.data, self.pos)
        self.pos += size
        return value

    def element(self, base: str) -> Any:
        return self.primitive(base) if base in _FORMATS or base == "string" else self.message(base)

    def message(self, type_name: str) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, ftype in _fields(type_name):
            if ftype.kind == "single":
                out[name] = self.element(ftype.base)
                continue
            count = ftype.size if ftype.kind == "array" else self.primitive("uint32")
            if count > len(self.data):  # a corrupt length, not a huge message
                raise ValueError(f"{type_name}.{name}: {count} elements in {len(self.data)} bytes")
            if ftype.kind == "bounded" and count > ftype.size:
                raise ValueError(f"{type_name}.{name}: {count} elements, at most {ftype.size}")
            out[name] = [self.element(ftype.base) for _ in range(count)]
        return out


def serialize(type_name: str, value: dict[str, Any]) -> bytes:
    """``value`` as the CDR payload of a ``type_name`` message (with the encapsulation header)."""
    writer = _Writer()
    writer.message(type_name, value)
    return HEADER + bytes(writer.buf)


def deserialize(type_name: str, payload: bytes) -> dict[str, Any]:
    """A ``type_name`` message from its CDR payload; ``ValueError`` if it is not one."""
    if len(payload) < 4 or payload[:2] != b"\x00\x01":
        raise ValueError("not a little-endian CDR payload (encapsulation header 00 01)")
    return _Reader(payload[4:]).message(type_name)
