"""The bus's wire format: JSON encoding, decoders by message type, correlation ids, interim replies.

The bus's wire format: JSON encoding, decoders by message type, correlation ids, the
attachment that marks an interim reply."""

from __future__ import annotations

import random
import threading
from typing import Any

import msgspec

from ..messages import Waiting

_encoder = msgspec.json.Encoder()
_DECODER_LOCK = threading.Lock()

_waiting = msgspec.json.Decoder(Waiting)
#: the Zenoh attachment of an interim reply (``Context.waiting``)
WAITING = b"waiting"


#: correlation ids: 48 random bits, from a generator seeded once by the system's (os.urandom):
#: one per request, on every request's path, where uuid4 cost a system call (3.6 against 0.6 us)
_cids = random.Random()


def new_cid() -> str:
    """A request's correlation id: 12 hex digits, random, so no two processes share one."""
    return f"{_cids.getrandbits(48):012x}"


class Decoders:
    """A bus's envelope decoders, one per envelope and message type, each built once:
    ``decoders(ReplyEnvelope, Ack)``. Keyed by the two classes, not by ``ReplyEnvelope[Ack]``:
    building and hashing that generic alias cost more than the decoding (every request)."""

    def __init__(self) -> None:
        self._decoders: dict[tuple[Any, type], msgspec.json.Decoder[Any]] = {}

    def __call__(self, envelope: Any, typ: type) -> msgspec.json.Decoder[Any]:
        key = (envelope, typ)
        decoder = self._decoders.get(key)
        if decoder is None:
            # built under a lock: two threads building a decoder for the same generic type at
            # once crashed the interpreter (SIGSEGV in msgspec's annotation walk, seen in CI)
            with _DECODER_LOCK:
                decoder = self._decoders.get(key)
                if decoder is None:
                    decoder = self._decoders[key] = msgspec.json.Decoder(_parametrize(envelope, typ))
        return decoder


def _parametrize(generic: Any, typ: type) -> Any:
    """``generic[typ]`` for a type known only at run time (the operation's message type)."""
    return generic[typ]
