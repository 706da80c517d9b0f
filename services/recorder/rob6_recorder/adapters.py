"""Turn bus payloads into recorder records (pure functions, for the service).

``bus_trace_records(service, op, payload)``: a ``rob6/<id>/trace/<service>/<op>``
payload (``{"t", "dt", "instance", "request": <envelope>, "reply": <envelope>}``,
see ``rob6.bus.Bus._answer``) -> the ``/bus/<service>/<op>/request`` and ``/reply``
records ``(topic, log_time_ns, publish_time_ns, data)``; the request at ``t``, the
reply at ``t + dt``, both with the envelope's ``cid``.
"""

from __future__ import annotations

from typing import Any

import msgspec

_decoder = msgspec.json.Decoder()

Record = tuple[str, int, int, dict[str, Any]]


def bus_trace_records(service: str, op: str, payload: bytes | dict[str, Any],
                      received_ns: int | None = None) -> list[Record]:
    trace: dict[str, Any] = _decoder.decode(payload) if isinstance(payload, (bytes, bytearray, memoryview)) else payload
    t = trace.get("t")
    dt = float(trace.get("dt") or 0.0)
    start = int(round(float(t) * 1e9)) if isinstance(t, (int, float)) else (received_ns or 0)
    end = start + int(round(dt * 1e9))
    request = trace.get("request") or {}
    reply = trace.get("reply") or {}
    instance = trace.get("instance", "")
    cid = str((request.get("cid") if isinstance(request, dict) else "") or
              (reply.get("cid") if isinstance(reply, dict) else "") or "")
    req = {"cid": cid, "service": service, "op": op, "instance": instance,
           "body": request.get("body") if isinstance(request, dict) else request}
    rep = {"cid": cid, "service": service, "op": op, "instance": instance,
           "ok": bool(reply.get("ok")) if isinstance(reply, dict) else False,
           "body": reply.get("body") if isinstance(reply, dict) else reply,
           "dt": dt}
    if isinstance(reply, dict) and reply.get("error") is not None:
        rep["error"] = reply["error"]
    published = received_ns if received_ns is not None else end
    return [(f"/bus/{service}/{op}/request", start, start, req),
            (f"/bus/{service}/{op}/reply", end, published, rep)]
