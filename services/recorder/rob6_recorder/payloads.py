"""How a record becomes its JSON payload, and back: ``encode`` and ``as_dict``.

The recorder writes every record as JSON (``writer.Recorder``); the live view publishes the same
payloads (``live.LiveView``).
"""

from __future__ import annotations

import json
from typing import Any

import msgspec

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
