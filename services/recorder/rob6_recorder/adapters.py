"""Turn bus payloads into recorder records (pure functions, for the service).

``bus_trace_records(service, op, payload)``: a ``rob6/<id>/trace/<service>/<op>``
payload (``{"t", "dt", "instance", "request": <envelope>, "reply": <envelope>}``,
see ``rob6.bus.Bus._answer``) -> the ``/bus/<service>/<op>/request`` and ``/reply``
records ``(topic, log_time_ns, publish_time_ns, JSON bytes)``; the request at ``t``, the
reply at ``t + dt``, both with the envelope's ``cid``.

The bodies are passed through as the service sent them, never decoded: a BackwardCalc's
trace holds some 50 numbers, and parsing and printing each again was most of what the
recorder did per request (docs/PERFORMANCE.md).
"""

from __future__ import annotations

import msgspec

_NULL = msgspec.Raw(b"null")


class _Trace(msgspec.Struct):
    """A trace as the service wrote it; any value is taken (a record is never lost to a
    field of an unexpected type), the envelopes undecoded."""

    t: object = None
    dt: object = None
    instance: object = ""
    request: msgspec.Raw = _NULL
    reply: msgspec.Raw = _NULL


class _Envelope(msgspec.Struct):
    """The parts of a request or reply envelope a record keeps; the body as it is."""

    cid: object = None
    ok: object = None
    body: msgspec.Raw = _NULL
    error: msgspec.Raw = _NULL


class _RequestRecord(msgspec.Struct):
    cid: str
    service: str
    op: str
    instance: object
    body: msgspec.Raw


class _ReplyRecord(msgspec.Struct, omit_defaults=True):
    cid: str
    service: str
    op: str
    instance: object
    ok: bool
    body: msgspec.Raw
    dt: float
    error: msgspec.Raw | None = None  # only when the reply has one


_trace = msgspec.json.Decoder(_Trace)
_envelope = msgspec.json.Decoder(_Envelope)
_encoder = msgspec.json.Encoder()

Record = tuple[str, int, int, bytes]


def _open(raw: msgspec.Raw) -> _Envelope | None:
    """The envelope, or None when the trace holds something else there (kept as the body)."""
    try:
        return _envelope.decode(raw)
    except msgspec.ValidationError:
        return None


def _number(value: object) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def bus_trace_records(service: str, op: str, payload: bytes, received_ns: int | None = None) -> list[Record]:
    """The request and reply records of one bus trace (``msgspec.DecodeError`` if it is not
    a JSON object)."""
    trace = _trace.decode(payload)
    t, dt = _number(trace.t), _number(trace.dt) or 0.0
    start = int(round(t * 1e9)) if t is not None else (received_ns or 0)
    end = start + int(round(dt * 1e9))
    request, reply = _open(trace.request), _open(trace.reply)
    cid = str((request.cid if request is not None else "") or (reply.cid if reply is not None else "") or "")
    req = _RequestRecord(cid=cid, service=service, op=op, instance=trace.instance,
                         body=request.body if request is not None else trace.request)
    rep = _ReplyRecord(cid=cid, service=service, op=op, instance=trace.instance,
                       ok=bool(reply.ok) if reply is not None else False,
                       body=reply.body if reply is not None else trace.reply, dt=dt,
                       error=reply.error if reply is not None and reply.error != _NULL else None)
    published = received_ns if received_ns is not None else end
    return [(f"/bus/{service}/{op}/request", start, start, _encoder.encode(req)),
            (f"/bus/{service}/{op}/reply", end, published, _encoder.encode(rep))]
