"""The rob6 bus: Zenoh sessions, key expressions, request/reply, liveliness, replicas.

Key expressions (``<id>`` is the robot id, so several robots share one network)::

    rob6/<id>/<service>/<instance>/<op>    queryable of one service instance (requests)
    rob6/<id>/alive/<service>/<instance>   liveliness token: the instance is up
    rob6/<id>/driver/state                 joint state, every driver cycle
    rob6/<id>/gripper/state                gripper state
    rob6/<id>/control/<name>               verbosity, shutdown (gateway -> all)
    rob6/<id>/log/<service>                log records of every process
    rob6/<id>/trace/<service>/<op>         each served request with its reply (recorder)
    rob6/<id>/trace/gateway/session        each client line in / reply out (recorder)

Requests go to one *instance*: the bus watches the liveliness tokens and spreads the
calls of a service over its live instances (least in flight, then round robin).
Zenoh itself would send every query to one complete queryable, so replicas would sit
idle without this. When an instance vanishes mid-request (its token disappears) or
does not answer in time, a request to an idempotent service is retried once on
another instance; everything else fails with a structured ``BusError``.

Zenoh runs callbacks on its own threads: the callbacks here only hand data over
(set a future, update a dict) and never block. Served requests are taken from a
FIFO channel by worker threads.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import itertools
import logging
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass

import msgspec
import zenoh

from .config import BusSettings
from .messages import (
    IDEMPOTENT_SERVICES,
    OPS,
    SCHEMA_VERSION,
    ErrorBody,
    ReplyEnvelope,
    RequestEnvelope,
)

log = logging.getLogger("rob6.bus")

_encoder = msgspec.json.Encoder()


class BusError(Exception):
    """A request that failed: ``code`` is machine-readable, ``message`` is for humans."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


class _InstanceLost(Exception):
    """The instance vanished or did not answer; the request may be retried elsewhere."""


@dataclass(frozen=True)
class Context:
    """What a request handler knows about the call."""

    cid: str
    op: str


def new_cid() -> str:
    return uuid.uuid4().hex[:12]


def zenoh_config(settings: BusSettings, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None) -> zenoh.Config:
    """Zenoh configuration from rob6 settings.

    A JSON5 file in the settings (TLS, access control) is the base; mode, connect and
    listen come from the settings unless the file sets them itself.
    """
    config = zenoh.Config.from_file(settings.zenoh_config) if settings.zenoh_config else zenoh.Config()
    defaults = zenoh.Config()
    file_mode = msgspec.json.decode(config.get_json("mode"))
    if file_mode != msgspec.json.decode(defaults.get_json("mode")):
        mode = file_mode  # the file decides (a secure profile runs every service as a TLS client)
    mode = mode or settings.mode
    listen = settings.listen if listen is None else listen
    if mode == "peer" and not listen:
        # loopback only unless asked: peers link to each other directly (one hop)
        # without opening ports on the lab network
        listen = ("tcp/127.0.0.1:0",)

    def set_unless_in_file(key: str, value) -> None:
        if config.get_json(key) == defaults.get_json(key):
            config.insert_json5(key, msgspec.json.encode(value).decode())

    set_unless_in_file("mode", mode)
    if mode != "router" and settings.connect:
        set_unless_in_file("connect/endpoints", list(settings.connect))
    if listen:
        set_unless_in_file("listen/endpoints", list(listen))
    # no multicast scouting: rob6 finds its router by configuration, never by
    # broadcasting on the lab network
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


class Bus:
    """One Zenoh session of one rob6 process (a service instance, the gateway, a tool)."""

    def __init__(self, settings: BusSettings, service: str, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None):
        self.settings = settings
        self.service = service
        self.instance = settings.instance
        self.prefix = f"rob6/{settings.robot_id}"
        self.session = zenoh.open(zenoh_config(settings, mode=mode, listen=listen))
        self._lock = threading.Lock()
        self._live: dict[str, list[str]] = {}
        self._inflight: dict[str, int] = {}
        self._pending: dict[str, set[concurrent.futures.Future]] = {}
        self._rotation = itertools.count()
        self._listeners: list[Callable[[str, str, bool], None]] = []
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._declared: list = []
        self._workers: list[threading.Thread] = []
        self._closed = threading.Event()
        self._executor = concurrent.futures.ThreadPoolExecutor(8, thread_name_prefix=f"{service}-req")
        self._decoders: dict[type, msgspec.json.Decoder] = {}
        self._live_sub = self.session.liveliness().declare_subscriber(
            self.key("alive", "**"), zenoh.handlers.Callback(self._on_liveliness), history=True)

    # ------------------------------------------------------------------ keys
    def key(self, *parts: str) -> str:
        return "/".join((self.prefix, *parts))

    # ------------------------------------------------------------------ liveliness
    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        parts = str(sample.key_expr).split("/")
        if len(parts) != 5:
            return
        service, instance = parts[3], parts[4]
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            instances = self._live.setdefault(service, [])
            if alive and instance not in instances:
                instances.append(instance)
            elif not alive and instance in instances:
                instances.remove(instance)
            lost = self._pending.pop(instance, set()) if not alive else set()
        for fut in lost:
            _fail(fut, _InstanceLost(f"{service} instance {instance} went away"))
        for listener in list(self._listeners):
            try:
                listener(service, instance, alive)
            except Exception:  # a listener must not break the bus
                log.exception("liveliness listener failed")

    def on_liveliness(self, listener: Callable[[str, str, bool], None]) -> None:
        """Call ``listener(service, instance, alive)`` on every change; it must not block."""
        self._listeners.append(listener)

    def instances(self, service: str) -> list[str]:
        with self._lock:
            return list(self._live.get(service, ()))

    def wait_for(self, services: tuple[str, ...] | list[str], timeout: float) -> list[str]:
        """Wait until every service has a live instance; returns the ones still missing."""
        deadline = time.monotonic() + timeout
        while True:
            missing = [s for s in services if not self.instances(s)]
            if not missing or time.monotonic() >= deadline:
                return missing
            time.sleep(0.02)

    def _pick(self, service: str, exclude: set[str]) -> str | None:
        with self._lock:
            candidates = [i for i in self._live.get(service, ()) if i not in exclude]
            if not candidates:
                return None
            start = next(self._rotation) % len(candidates)
            ordered = candidates[start:] + candidates[:start]
            return min(ordered, key=lambda i: self._inflight.get(i, 0))

    # ------------------------------------------------------------------ serving
    def serve(self, handlers: dict[str, Callable], *, workers: int = 4) -> None:
        """Answer ``handlers[op](request, ctx)`` for this service and announce it as alive.

        Handlers run on ``workers`` threads, so a long request (a motion) does not
        hold up short ones (a ping).
        """
        unknown = [op for op in handlers if (self.service, op) not in OPS]
        if unknown:
            raise ValueError(f"operations not in rob6.messages.OPS: {unknown}")
        queryable = self.session.declare_queryable(
            self.key(self.service, self.instance, "*"), zenoh.handlers.FifoChannel(1024))
        self._declared.append(queryable)
        for n in range(workers):
            thread = threading.Thread(target=self._serve_loop, args=(queryable, handlers),
                                      name=f"{self.service}-worker-{n}", daemon=True)
            thread.start()
            self._workers.append(thread)
        self.announce()

    def announce(self) -> None:
        """Declare this instance alive (its liveliness token) on the bus."""
        self._declared.append(self.session.liveliness().declare_token(
            self.key("alive", self.service, self.instance)))

    def _serve_loop(self, queryable, handlers) -> None:
        while not self._closed.is_set():
            try:
                query = queryable.recv()
            except Exception:  # channel closed: the session is going away
                return
            try:
                self._answer(query, handlers)
            except Exception:
                log.exception("failed to answer a query")

    def _answer(self, query: zenoh.Query, handlers) -> None:
        started = time.time()
        op = str(query.key_expr).rsplit("/", 1)[-1]
        cid = ""
        raw = query.payload.to_bytes() if query.payload is not None else b""
        try:
            spec = OPS.get((self.service, op))
            if spec is None or op not in handlers:
                raise BusError("unknown_op", f"{self.service} has no operation {op!r}")
            try:
                envelope = self._decoder(RequestEnvelope[spec.request]).decode(raw)
            except msgspec.DecodeError as exc:
                raise BusError("schema", f"malformed {self.service}.{op} request: {exc}") from None
            cid = envelope.cid
            if envelope.v != SCHEMA_VERSION:
                raise BusError("schema", f"schema version {envelope.v}, expected {SCHEMA_VERSION}")
            body = handlers[op](envelope.body, Context(cid=cid, op=op))
            reply = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=True, body=body)
        except BusError as exc:
            reply = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=False,
                                  error=ErrorBody(code=exc.code, message=exc.message))
        except Exception as exc:  # never a traceback on the wire; the log has it
            log.exception("%s.%s failed (cid %s)", self.service, op, cid)
            reply = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=False, error=ErrorBody(
                code="internal", message=f"{self.service}.{op}: {type(exc).__name__}: {exc}"))
        payload = _encoder.encode(reply)
        query.reply(query.key_expr, payload)
        query.drop()
        # after the reply: the recorder's copy stays off the request's latency path
        self.publish(f"trace/{self.service}/{op}",
                     b'{"t":%.6f,"dt":%.6f,"instance":"%s","request":%s,"reply":%s}' % (
                         started, time.time() - started, self.instance.encode(),
                         raw or b"null", payload), reliable=True)

    def _decoder(self, typ: type) -> msgspec.json.Decoder:
        decoder = self._decoders.get(typ)
        if decoder is None:
            decoder = self._decoders[typ] = msgspec.json.Decoder(typ)
        return decoder

    # ------------------------------------------------------------------ requests
    def request(self, service: str, op: str, body, *, timeout: float | None = None,
                cid: str | None = None, instance: str | None = None):
        """Send ``body`` to ``service.op`` and return the typed reply body.

        Raises ``BusError`` with code ``unavailable`` (no live instance), ``timeout``,
        or whatever the service answered (``rejected``, ``invalid``, ``internal``...).
        """
        spec = OPS[(service, op)]
        timeout = spec.timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        cid = cid or new_cid()
        payload = _encoder.encode(RequestEnvelope(v=SCHEMA_VERSION, cid=cid, body=body))
        retry = instance is None and service in IDEMPOTENT_SERVICES
        tried: set[str] = set()
        while True:
            target = instance or self._pick(service, tried)
            if target is None:
                if tried:
                    raise BusError("timeout", f"{service} did not answer {op} in time")
                raise BusError("unavailable", f"{service} unavailable")
            try:
                return self._call(service, target, op, spec, payload, deadline)
            except _InstanceLost as exc:
                tried.add(target)
                remaining = deadline - time.monotonic()
                if not retry or len(tried) >= 2 or remaining <= 0:
                    code = "timeout" if remaining <= 0 else "unavailable"
                    raise BusError(code, f"{service} unavailable ({exc})") from None
                log.warning("retrying %s.%s on another instance: %s", service, op, exc)

    def _call(self, service, instance, op, spec, payload, deadline):
        fut: concurrent.futures.Future = concurrent.futures.Future()

        def on_reply(reply: zenoh.Reply) -> None:
            if reply.ok is not None:
                _resolve(fut, reply.ok.payload.to_bytes())
            else:
                message = reply.err.payload.to_string()
                if message == "Timeout":  # Zenoh's own error reply: the query timed out
                    # (a stopped/hung instance); report it like any lost instance, not as
                    # a bare "ERROR: Timeout" that names no service
                    _fail(fut, _InstanceLost(f"no reply from {service} instance {instance} in time"))
                else:
                    _fail(fut, BusError("internal", message))

        def on_done() -> None:
            _fail(fut, _InstanceLost(f"no reply from {service} instance {instance}"))

        with self._lock:
            self._pending.setdefault(instance, set()).add(fut)
            self._inflight[instance] = self._inflight.get(instance, 0) + 1
        try:
            remaining = max(deadline - time.monotonic(), 0.001)
            self.session.get(self.key(service, instance, op),
                             zenoh.handlers.Callback(on_reply, on_done),
                             payload=payload, timeout=remaining)
            try:
                raw = fut.result(timeout=remaining + 0.05)
            except concurrent.futures.TimeoutError:
                raise _InstanceLost(f"no reply from {service} instance {instance}") from None
        finally:
            with self._lock:
                self._pending.get(instance, set()).discard(fut)
                self._inflight[instance] = self._inflight.get(instance, 1) - 1
        try:
            envelope = self._decoder(ReplyEnvelope[spec.reply]).decode(raw)
        except msgspec.DecodeError as exc:
            raise BusError("schema", f"malformed {service}.{op} reply: {exc}") from None
        if not envelope.ok:
            error = envelope.error or ErrorBody(code="internal", message="error without detail")
            raise BusError(error.code, error.message)
        return envelope.body

    async def arequest(self, service: str, op: str, body, **kwargs):
        """``request`` for asyncio code (runs on the bus's request threads)."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(
            self._executor, functools.partial(self.request, service, op, body, **kwargs))

    # ------------------------------------------------------------------ pub/sub
    def publish(self, suffix: str, data, *, reliable: bool = False) -> None:
        """Publish a message struct, dict or raw JSON bytes on ``rob6/<id>/<suffix>``.

        ``reliable`` blocks rather than drops under congestion (logs, traces); state
        streams drop, because only the latest sample matters to a controller.
        """
        if self._closed.is_set():  # shutting down: nothing is listening any more
            return
        publisher = self._publishers.get(suffix)
        if publisher is None:
            congestion = zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
            publisher = self._publishers[suffix] = self.session.declare_publisher(
                self.key(suffix), congestion_control=congestion)
        publisher.put(data if isinstance(data, bytes) else _encoder.encode(data))

    def subscribe(self, suffix: str, on_message: Callable[[str, bytes], None]):
        """Call ``on_message(key, payload)`` for every sample; it must not block."""
        def callback(sample: zenoh.Sample) -> None:
            try:
                on_message(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:
                log.exception("subscriber of %s failed", suffix)

        subscriber = self.session.declare_subscriber(self.key(suffix), zenoh.handlers.Callback(callback))
        self._declared.append(subscriber)
        return subscriber

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        self._executor.shutdown(wait=False, cancel_futures=True)
        try:
            self.session.close()
        except Exception:
            log.debug("closing the zenoh session failed", exc_info=True)


def _resolve(fut: concurrent.futures.Future, value) -> None:
    try:
        fut.set_result(value)
    except concurrent.futures.InvalidStateError:
        pass


def _fail(fut: concurrent.futures.Future, exc: BaseException) -> None:
    try:
        fut.set_exception(exc)
    except concurrent.futures.InvalidStateError:
        pass


def decode(typ: type, payload: bytes):
    """Decode a published message of type ``typ``."""
    return msgspec.json.decode(payload, type=typ)
