"""The rob6 bus: Zenoh sessions, key expressions, request/reply, liveliness, replicas.

Key expressions (``<id>`` is the robot id, so several robots share one network)::

    rob6/<id>/<service>/<instance>/<op>    queryable of one service instance (requests)
    rob6/<id>/alive/<service>/<instance>   liveliness token: the instance is up
    rob6/<id>/driver/state                 joint state, every driver cycle (at rest 25 Hz)
    rob6/<id>/gripper/state                gripper state
    rob6/<id>/control/<name>               verbosity, shutdown (gateway -> all)
    rob6/<id>/trace/<service>              the records below, in batches (recorder)

Records for the recorder (``Bus.trace``) leave in batches, one message per few
milliseconds (``TRACE_BATCH_S``): a JSON array of ``[suffix, record]`` pairs, read
with ``trace_records``. They come from a zenoh.ext advanced publisher that keeps the
last ``TRACE_CACHE_S`` of batches and numbers them: a recorder that was partitioned
away or restarted gets what it missed and learns of what it could not get
(``Bus.subscribe_traces``). The suffixes::

    trace/<service>/<op>                   each served request with its reply
    trace/gateway/session                  each client line in / reply out
    trace/gateway/event                    a client session opening or closing
    log/<service>                          a log record (rob6.logs.BusLogHandler)
    driver/link                            an event of the driver's robot link

Requests go to one *instance*: the bus watches the liveliness tokens and spreads the
calls of a replicated service (kinematics) over its live instances (least in flight,
then round robin). A robot has one driver, planner, gripper and gateway
(``OWNER_SERVICES``, claimed in ``rob6.ownership``): calls to those go to the one
instance this process follows (the first it saw alive), and subscriptions made with
``owner=`` drop samples any other instance publishes (every publication carries its
instance id as the Zenoh attachment), so a stray second driver is never mixed in.
Zenoh itself would send every query to one complete queryable, so replicas would sit
idle without this. When an instance vanishes mid-request (its token disappears) or
does not answer in time, a request to an idempotent service is retried once on
another instance; a hedged one (single-pose kinematics, ``Op.hedged``) not answered
after ``HEDGE_DELAY_S`` is sent a second time, to another live instance (or the same
one when it is the only one), and the first answer wins. A retry or a hedge prefers an
instance on another host (the host part of its id): its network path is not the first's.
Never for an owner service: one robot, one owner, a motion is never sent twice.
Everything else fails with a structured ``BusError``. A service with no live instance
is waited for (``LIVELINESS_GRACE_S``, within the call's deadline) before the call fails
``unavailable``: a token can be missing for a moment (an instance reconnecting). Only
then, or when the instance goes away mid-request: a live instance that does not answer
in time fails the call ``timeout`` (``BusTimeout``), naming what it waited for.

A reply that waits for the arm (``Op.waits``: a motion, a stop, the gripper) is not
bounded by the quick-call deadline: the handler announces how long and for what
(``Context.waiting``, an interim reply), and the caller's deadline becomes that plus
``rob6.deadlines.HOP_S``; a caller that is itself a handler passes the announcement on
(``request(..., waiting=ctx.waiting)``), so each hop outward waits a little longer.

Zenoh runs callbacks on its own threads: the callbacks here only hand data over
(release the waiting caller, update a dict) and never block. Served requests are taken from a
FIFO channel by worker threads.
"""

from __future__ import annotations

import functools
import itertools
import logging
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from queue import Empty, SimpleQueue
from typing import Any, TypeVar

import msgspec
import zenoh
import zenoh.ext

from .config import BusSettings
from .deadlines import HOP_S
from .messages import (
    IDEMPOTENT_SERVICES,
    OPS,
    OWNER_SERVICES,
    SCHEMA_VERSION,
    ErrorBody,
    ErrorCode,
    ReplyEnvelope,
    RequestEnvelope,
    Waiting,
)

log = logging.getLogger("rob6.bus")

T = TypeVar("T")

_encoder = msgspec.json.Encoder()
_DECODER_LOCK = threading.Lock()

#: traces gather this long before they leave as one message: a request pays for a queue
#: put, not for a thread wake-up and a publication of its own (the recording overhead)
TRACE_BATCH_S = 0.005
TRACE_BATCH_MAX = 256
#: a hedged request (``Op.hedged``: single-pose kinematics) not answered after this long
#: is sent a second time: the first copy may sit on a replica that hangs or on a remote
#: host behind a lost TCP segment (retransmission >= 200 ms). Above the p99 of a healthy
#: remote call (tens of ms, deploy/MULTI_HOST.md), so a second copy costs a replica
#: something only when the first is already late; below TCP's 200 ms retransmission
#: timeout, so the copy is out before a stalled exchange would recover by itself.
HEDGE_DELAY_S = 0.15
#: how long a call waits for a service with no live instance before it answers
#: ``unavailable`` (never past its deadline). In full multi-host test runs the gateway lost
#: the planner's token right after the recorder restarted, cause not known
#: (deploy/MULTI_HOST.md); a peer that reconnects is back within 0.25-1 s. A service really
#: gone costs its callers this long once per call.
LIVELINESS_GRACE_S = 1.0

#: every ``trace/<service>`` batch is kept this long by its (advanced) publisher, so a
#: recorder partitioned away or restarted gets what it missed (``Bus.subscribe_traces``):
#: a 10 s partition of the storage host, the lease and the reconnection fit. Batches leave
#: at most every TRACE_BATCH_S: at most ~6,000, a few MB at 250 Hz Alter
TRACE_CACHE_S = 30.0
TRACE_CACHE_SAMPLES = int(TRACE_CACHE_S / TRACE_BATCH_S)
#: how often a trace publisher tells its subscribers the sequence number of its last
#: batch, when it changed (a lost *last* batch is detected and recovered within this)
TRACE_HEARTBEAT_S = 0.5
#: when the recorder's second trace subscriber comes (see ``_TraceSubscription``)
TRACE_RESUBSCRIBE_S = 2.0
#: the repair of what zenoh.ext's recovery left out (``_TraceSubscription._repair``): how
#: often, how many asks before a missing batch is reported missed, how long each ask
TRACE_REPAIR_S = 2.0
TRACE_REPAIR_TRIES = 3
TRACE_REPAIR_TIMEOUT_S = 5.0

_trace_batch = msgspec.json.Decoder(list[tuple[str, msgspec.Raw]])
_waiting = msgspec.json.Decoder(Waiting)
#: the Zenoh attachment of an interim reply (``Context.waiting``)
WAITING = b"waiting"
#: a waiting operation's Zenoh query lives this long at most: its real deadline is the
#: bus's own, which the service's announcements move; the query is cancelled with it
WAITING_QUERY_S = 24 * 3600.0
#: a caller's own deadline fires this long after the service's, so a reply sent just in
#: time is not lost to the caller's timer
REPLY_GRACE_S = 0.05
#: how often the watcher (``_Watcher``) acts for callers blocked on their reply channel:
#: sends a hedge that is due, ends a waiting call past its deadline (an announcement can
#: bring it nearer as well as push it out) or abandoned by its caller. A hedge goes out
#: within this after ``HEDGE_DELAY_S``.
WATCH_TICK_S = 0.02


def _host(instance: str) -> str:
    """The host part of an instance id (``rob6.config.default_instance``: host-suffix)."""
    return instance.rpartition("-")[0] or instance


def _runs(keys: list[tuple[str, int]]) -> Iterator[tuple[str, int, int]]:
    """``(source, first, last)`` for each run of consecutive numbers of one source in the
    sorted ``keys``."""
    run: list[Any] = []
    for source, sn in keys:
        if run and run[0] == source and run[2] + 1 == sn:
            run[2] = sn
            continue
        if run:
            yield run[0], run[1], run[2]
        run = [source, sn, sn]
    if run:
        yield run[0], run[1], run[2]


def trace_records(payload: bytes) -> list[tuple[str, bytes]]:
    """The ``(suffix, record JSON)`` pairs of one ``trace/<service>`` batch."""
    return [(suffix, bytes(record)) for suffix, record in _trace_batch.decode(payload)]


class BusError(Exception):
    """A request that failed: ``code`` is machine-readable, ``message`` is for humans."""

    def __init__(self, code: ErrorCode, message: str):
        super().__init__(message)
        self.code = code
        self.message = message


class BusTimeout(BusError):
    """A live instance did not answer in time: ``seconds`` waited, ``waiting_for`` what the
    service said it waited for ("" when it said nothing: a quick call)."""

    def __init__(self, service: str, op: str, seconds: float, waiting_for: str):
        detail = f" ({waiting_for})" if waiting_for else ""
        super().__init__("timeout", f"{service}: no reply to {op} within {seconds:.1f} s{detail}")
        self.service, self.op, self.seconds, self.waiting_for = service, op, seconds, waiting_for


class CallAbandoned(Exception):
    """The caller gave up on a request (``Bus.request``'s ``abandon``); its query is cancelled."""


class _InstanceLost(Exception):
    """The instance vanished (``gone``) or did not answer; the request may be retried elsewhere."""

    def __init__(self, message: str, gone: bool = False):
        super().__init__(message)
        self.gone = gone


def _no_announcement(seconds: float, what: str) -> None:
    """Operations that never wait have no one to tell."""


@dataclass(frozen=True)
class Context:
    """What a request handler knows about the call.

    ``waiting(seconds, what)``: the reply will take up to ``seconds`` more, waiting for
    ``what`` ("waiting for the arm to stop"); the caller's deadline follows (``Op.waits``
    operations only). Announce before the wait, as soon as its bound is known."""

    cid: str
    op: str
    waiting: Callable[[float, str], None] = _no_announcement


#: a request handler: ``handler(request body, ctx) -> reply body``, of the types
#: ``rob6.messages.OPS`` gives for its operation
Handler = Callable[[Any, Context], Any]


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

    def set_unless_in_file(key: str, value: object) -> None:
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


def open_session(settings: BusSettings, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None) -> zenoh.Session:
    zenoh.try_init_log_from_env()  # Zenoh's own log on stderr, only when RUST_LOG asks for it
    return zenoh.open(zenoh_config(settings, mode=mode, listen=listen))


class Bus:
    """One Zenoh session of one rob6 process (a service instance, the gateway, a tool)."""

    def __init__(self, settings: BusSettings, service: str, *, mode: str | None = None,
                 listen: tuple[str, ...] | None = None):
        self.settings = settings
        self.service = service
        self.instance = settings.instance
        self.prefix = f"rob6/{settings.robot_id}"
        self.session = open_session(settings, mode=mode, listen=listen)
        self._lock = threading.Lock()
        self._live: dict[str, list[str]] = {}
        self._inflight: dict[str, int] = {}
        self._pending: dict[str, set[_Exchange]] = {}  # instance -> exchanges waiting for it
        self._watcher: _Watcher | None = None
        self._rotation = itertools.count()
        self._listeners: list[Callable[[str, str, bool], None]] = []
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._declared: list[Any] = []  # zenoh declarations that live as long as the session
        self._workers: list[threading.Thread] = []
        self._closed = threading.Event()
        self._decoders: dict[Any, msgspec.json.Decoder[Any]] = {}
        self._attachment = self.instance.encode()
        self._foreign_warned: set[tuple[str, str]] = set()
        # records for the recorder leave from a thread of their own, in order, so a request
        # never waits for their encoding or for the network (see ``trace``)
        self._traces: SimpleQueue[tuple[str, object] | None] = SimpleQueue()
        # declared now, not with the first batch: a recorder learns of it (publisher
        # detection) before there is anything to miss
        self._trace_publisher = zenoh.ext.declare_advanced_publisher(
            self.session, self.key("trace", service), congestion_control=zenoh.CongestionControl.BLOCK,
            cache=zenoh.ext.CacheConfig(TRACE_CACHE_SAMPLES, replies_config=zenoh.ext.RepliesConfig(
                congestion_control=zenoh.CongestionControl.BLOCK)),  # history, like the batches: never dropped
            sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=TRACE_HEARTBEAT_S),
            publisher_detection=True)
        self._tracer = threading.Thread(target=self._trace_loop, name=f"{service}-traces", daemon=True)
        self._tracer.start()
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
        for exchange in lost:
            exchange.end(_InstanceLost(f"{service} instance {instance} went away", gone=True), instance)
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

    def owner(self, service: str) -> str | None:
        """The instance of an owner service this process follows: the first it saw alive."""
        with self._lock:
            live = self._live.get(service)
            return live[0] if live else None

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
            live = self._live.get(service, ())
            if service in OWNER_SERVICES:  # the followed one, never a second owner
                return live[0] if live and live[0] not in exclude else None
            candidates = [i for i in live if i not in exclude]
            if not candidates:
                return None
            # a retry or a hedge goes to another host where there is one: the instances of
            # one host share its network path, and a copy sent the same way would wait
            # behind the same lost TCP segment or partition
            elsewhere = [i for i in candidates if _host(i) not in {_host(t) for t in exclude}]
            candidates = elsewhere or candidates
            start = next(self._rotation) % len(candidates)
            ordered = candidates[start:] + candidates[:start]
            return min(ordered, key=lambda i: self._inflight.get(i, 0))

    # ------------------------------------------------------------------ serving
    def serve(self, handlers: Mapping[str, Handler], *, workers: int = 4,
              inline: Iterable[str] = ()) -> None:
        """Answer ``handlers[op](request, ctx)`` for this service and announce it as alive.

        Handlers run on ``workers`` threads, so a long request (a motion) does not
        hold up short ones (a ping). ``inline`` ops (quick, never blocking: a ping, a
        state read, an Alter target, one pose) are answered on Zenoh's callback thread
        itself, which saves the hand-off to a worker on the latency path.
        """
        unknown = [op for op in handlers if (self.service, op) not in OPS]
        if unknown:
            raise ValueError(f"operations not in rob6.messages.OPS: {unknown}")
        quick = frozenset(inline)
        queue: SimpleQueue[zenoh.Query | None] = SimpleQueue()

        def on_query(query: zenoh.Query) -> None:
            if str(query.key_expr).rsplit("/", 1)[-1] in quick:
                self._answer(query, handlers)
            else:
                queue.put(query)

        def on_close() -> None:  # the session is going away: the workers end
            for _ in range(workers):
                queue.put(None)

        self._declared.append(self.session.declare_queryable(
            self.key(self.service, self.instance, "*"), zenoh.handlers.Callback(on_query, on_close)))
        for n in range(workers):
            thread = threading.Thread(target=self._serve_loop, args=(queue, handlers),
                                      name=f"{self.service}-worker-{n}", daemon=True)
            thread.start()
            self._workers.append(thread)
        self.announce()

    def announce(self) -> None:
        """Declare this instance alive (its liveliness token) on the bus."""
        self._declared.append(self.session.liveliness().declare_token(
            self.key("alive", self.service, self.instance)))

    def _serve_loop(self, queue: "SimpleQueue[zenoh.Query | None]", handlers: Mapping[str, Handler]) -> None:
        while (query := queue.get()) is not None:
            self._answer(query, handlers)

    def _answer(self, query: zenoh.Query, handlers: Mapping[str, Handler]) -> None:
        started = time.time()
        op = str(query.key_expr).rsplit("/", 1)[-1]
        cid = ""
        raw = query.payload.to_bytes() if query.payload is not None else b""
        try:
            spec = OPS.get((self.service, op))
            if spec is None or op not in handlers:
                raise BusError("unknown_op", f"{self.service} has no operation {op!r}")
            try:
                envelope = self._decoder(_parametrize(RequestEnvelope, spec.request)).decode(raw)
            except msgspec.DecodeError as exc:
                raise BusError("schema", f"malformed {self.service}.{op} request: {exc}") from None
            cid = envelope.cid
            if envelope.v != SCHEMA_VERSION:
                raise BusError("schema", f"schema version {envelope.v}, expected {SCHEMA_VERSION}")
            waiting = functools.partial(self._announce, query) if spec.waits else _no_announcement
            body = handlers[op](envelope.body, Context(cid=cid, op=op, waiting=waiting))
            reply: ReplyEnvelope[Any] = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=True, instance=self.instance, body=body)
        except BusError as exc:
            reply = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=False, instance=self.instance,
                                  error=ErrorBody(code=exc.code, message=exc.message))
        except Exception as exc:  # never a traceback on the wire; the log has it
            log.exception("%s.%s failed (cid %s)", self.service, op, cid)
            reply = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=False, instance=self.instance, error=ErrorBody(
                code="internal", message=f"{self.service}.{op}: {type(exc).__name__}: {exc}"))
        payload = _encoder.encode(reply)
        query.reply(query.key_expr, payload)
        query.drop()
        self.trace(f"trace/{self.service}/{op}", b'{"t":%.6f,"dt":%.6f,"instance":"%s","request":%s,"reply":%s}' % (
            started, time.time() - started, self.instance.encode(), raw or b"null", payload))

    def _announce(self, query: zenoh.Query, seconds: float, what: str) -> None:
        """An interim reply: the final one takes up to ``seconds`` more (``Context.waiting``)."""
        query.reply(query.key_expr, _encoder.encode(Waiting(seconds=seconds, what=what)), attachment=WAITING)

    def _decoder(self, typ: Any) -> msgspec.json.Decoder[Any]:
        decoder = self._decoders.get(typ)
        if decoder is None:
            # built under a lock: two threads building a decoder for the same generic type at
            # once crashed the interpreter (SIGSEGV in msgspec's annotation walk, seen in CI)
            with _DECODER_LOCK:
                decoder = self._decoders.get(typ)
                if decoder is None:
                    decoder = self._decoders[typ] = msgspec.json.Decoder(typ)
        return decoder

    # ------------------------------------------------------------------ requests
    def request(self, service: str, op: str, body: object, *, timeout: float | None = None,
                cid: str | None = None, instance: str | None = None,
                waiting: Callable[[float, str], None] | None = None,
                abandon: Callable[[], bool] | None = None) -> Any:
        """Send ``body`` to ``service.op`` and return the typed reply body, received on
        the calling thread (no hand-off: the reply wakes it straight from Zenoh's thread).

        Raises ``BusError`` with code ``unavailable`` (no live instance), ``timeout``
        (``BusTimeout``: a live instance did not answer in time), or whatever the service
        answered (``rejected``, ``invalid``, ``internal``...). A hedged operation
        (``Op.hedged``) not answered after ``HEDGE_DELAY_S`` is sent a second time, to
        another replica when there is one: the first answer wins. ``waiting``: called with
        what the service announces it waits for (``Context.waiting``), each time plus
        ``HOP_S``: a handler passes its own ``ctx.waiting`` to tell its caller in turn.
        ``abandon``: asked every ``WAIT_SLICE_S`` while the reply is awaited; when it
        answers True (the client left), the query is cancelled and ``CallAbandoned`` raised.
        """
        call = _Request(self, service, op, body, timeout, cid, instance, waiting)
        while True:
            while (target := call.next_target()) is None:
                time.sleep(0.005)
            exchange = _Exchange(self, call, target, abandon)
            try:
                return call.decode(*exchange.run())
            except _InstanceLost as exc:
                call.lost(target, exc)
            finally:
                exchange.close()

    def _watch(self, exchange: "_Exchange") -> None:
        if self._watcher is None:
            with self._lock:
                if self._watcher is None:
                    self._watcher = _Watcher(self)
        self._watcher.add(exchange)

    def _query(self, call: "_Request", instance: str, token: zenoh.CancellationToken,
               handler: Any = None) -> Any:
        """Send the query to ``instance``: its replies come through ``handler`` (a callback),
        or, without one, on a channel the caller reads (returned)."""
        # a waiting operation's deadline moves with what the service announces; Zenoh's
        # timeout cannot, so the query lives long and is cancelled when the call ends
        timeout = WAITING_QUERY_S if call.spec.waits else max(call.remaining() + REPLY_GRACE_S, 0.001)
        # no consolidation: the reply is passed on when it arrives. Zenoh's default holds it
        # back until every route has sent its final, and a route through a router whose link
        # to a partitioned host is still open never does before the timeout: measured, every
        # gateway -> driver call on the robot PC timed out 2 s into a partition of the
        # remote hosts (deploy/MULTI_HOST.md). The key names one instance: one reply.
        return self.session.get(self.key(call.service, instance, call.op), handler, payload=call.payload,
                                timeout=timeout, consolidation=zenoh.ConsolidationMode.NONE,
                                cancellation_token=token)

    def _track(self, exchange: "_Exchange", instance: str, add: bool) -> None:
        with self._lock:
            if add:
                self._pending.setdefault(instance, set()).add(exchange)
                self._inflight[instance] = self._inflight.get(instance, 0) + 1
            else:
                self._pending.get(instance, set()).discard(exchange)
                self._inflight[instance] = self._inflight.get(instance, 1) - 1

    # ------------------------------------------------------------------ pub/sub
    def publish(self, suffix: str, data: object, *, reliable: bool = False) -> None:
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
        publisher.put(data if isinstance(data, bytes) else _encoder.encode(data), attachment=self._attachment)

    def trace(self, suffix: str, data: object) -> None:
        """Queue a record for the recorder (struct or JSON bytes): it leaves, in order and
        reliably, in the next ``trace/<service>`` batch from the trace thread, so the
        caller, usually a request on its latency path, waits for nothing."""
        self._traces.put((suffix, data))

    def _trace_loop(self) -> None:
        closing = full = False
        while not closing:
            first = self._traces.get()
            if first is None:
                break
            if not full:
                time.sleep(TRACE_BATCH_S)  # a burst gathers
            batch = [first]
            while len(batch) < TRACE_BATCH_MAX:
                try:
                    item = self._traces.get_nowait()
                except Empty:
                    break
                if item is None:
                    closing = True
                    break
                batch.append(item)
            full = len(batch) == TRACE_BATCH_MAX  # a backlog: no pause before the next
            try:
                self._publish_traces(_encoder.encode([
                    (suffix, msgspec.Raw(data) if isinstance(data, bytes) else data) for suffix, data in batch]))
            except Exception:
                log.exception("could not publish %d trace records", len(batch))

    def _publish_traces(self, payload: bytes) -> None:
        """One batch on ``trace/<service>``, from an advanced publisher: it keeps the last
        ``TRACE_CACHE_SAMPLES`` batches for a recorder that missed them (its history and
        recovery queries), numbers them so a gap is detected (sample-miss detection with
        a heartbeat for the last one), and announces itself (publisher detection), so a
        recorder started after it still asks it for its history."""
        if not self._closed.is_set():
            self._trace_publisher.put(payload, attachment=self._attachment)

    def subscribe_traces(self, on_batch: Callable[[str, bytes], None],
                         on_miss: Callable[[str, int], None]) -> "_TraceSubscription":
        """Every ``trace/<service>`` batch of every process, with what the publishers kept
        (``TRACE_CACHE_S``): ``on_batch(key, payload)`` for each batch, the ones published
        before this subscriber came (history of every publisher, also of one detected
        later) and the ones lost on the way (recovered from the publisher's cache) included,
        each once; ``on_miss(source, count)`` for batches that could not be recovered
        (``source``: the key and instance of the publisher, or its Zenoh id until one of its
        batches came). Both are called on Zenoh's threads and must not block."""
        return _TraceSubscription(self, on_batch, on_miss)

    def subscribe(self, suffix: str, on_message: Callable[[str, bytes], None], *,
                  owner: str | None = None) -> zenoh.Subscriber[None]:
        """Call ``on_message(key, payload)`` for every sample; it must not block.

        ``owner``: an owner service; only what its followed instance publishes is passed
        on, anything else is logged (once per publisher) and dropped.
        """
        def callback(sample: zenoh.Sample) -> None:
            try:
                if owner is not None and not self._from_owner(owner, suffix, sample):
                    return
                on_message(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:
                log.exception("subscriber of %s failed", suffix)

        subscriber = self.session.declare_subscriber(self.key(suffix), zenoh.handlers.Callback(callback))
        self._declared.append(subscriber)
        return subscriber

    def _from_owner(self, service: str, suffix: str, sample: zenoh.Sample) -> bool:
        attachment = sample.attachment
        sender = attachment.to_bytes().decode(errors="replace") if attachment is not None else "?"
        followed = self.owner(service)
        if sender == followed:
            return True
        if followed is None:  # its liveliness token has not arrived yet (start-up)
            return False
        if (suffix, sender) not in self._foreign_warned and len(self._foreign_warned) < 100:
            self._foreign_warned.add((suffix, sender))
            log.warning("ignoring %s from %s: this %s follows the %s %s", self.key(suffix), sender,
                        self.service, service, followed)
        return False

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        if self._closed.is_set():
            return
        self._traces.put(None)  # what was traced before the close still goes out
        self._tracer.join(5.0)
        self._closed.set()
        try:
            self.session.close()
        except Exception:
            log.debug("closing the zenoh session failed", exc_info=True)


class _TraceSubscription:
    """``Bus.subscribe_traces``: a zenoh.ext advanced subscriber, declared twice, and a
    repair from the publishers' caches.

    Its history query reaches only the publishers whose cache this session already has a
    route to; right after the session opened it may come back without them, and the
    first live batch of a publisher then becomes where that publisher starts (the
    subscriber drops older batches its history brings later): measured, 1 to 3 restarts
    in 6 lost the batches published while the recorder was down. So a second subscriber
    is declared ``TRACE_RESUBSCRIBE_S`` later, when the routes are there, whose history
    brings what the first missed; batches are passed on once (by publisher and sequence
    number), and the first subscriber goes. In a multi-host run even the second one's
    history sometimes brought nothing from a publisher, and a batch now and then was
    neither delivered nor reported missed (deploy/MULTI_HOST.md), so ``_repair`` asks the
    publishers' caches directly for whatever is missing by sequence number, and reports
    what they no longer have. It is the one reporter of misses: a miss zenoh.ext reports
    leaves a hole that the repair asks for once more and then reports, so it is only logged.
    """

    def __init__(self, bus: Bus, on_batch: Callable[[str, bytes], None], on_miss: Callable[[str, int], None]):
        self.bus, self.on_batch, self.on_miss = bus, on_batch, on_miss
        self._lock = threading.Lock()
        self._sources: dict[str, str] = {}  # publisher's entity id -> "<key> <instance>"
        self._seen: dict[str, set[int]] = {}  # publisher's entity id -> sequence numbers passed on
        self._caches: dict[str, str] = {}  # publisher's entity id -> key expression of its cache
        self._backfilled: set[str] = set()  # publishers whose cache answered for what came before
        self._closed = False
        self._current: list[Any] = self._declare()
        self._timer = threading.Timer(TRACE_RESUBSCRIBE_S, self._redeclare)
        self._timer.daemon = True
        self._timer.start()
        self._repairer = threading.Thread(target=self._repair, name="trace-repair", daemon=True)
        self._repairer.start()

    def _declare(self) -> list[Any]:
        subscriber = zenoh.ext.declare_advanced_subscriber(
            self.bus.session, self.bus.key("trace", "*"), zenoh.handlers.Callback(self._sample),
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=TRACE_CACHE_SAMPLES,
                                            max_age=TRACE_CACHE_S),
            recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
            subscriber_detection=True)
        return [subscriber.sample_miss_listener(zenoh.handlers.Callback(self._missed)), subscriber]

    def _redeclare(self) -> None:
        if self._closed or self.bus._closed.is_set():
            return
        try:
            second = self._declare()  # not under the lock: its replies take it
        except Exception:
            log.exception("could not declare the second trace subscriber")
            return
        with self._lock:
            if self._closed:
                first = second
            else:
                first, self._current = self._current, second
        for declaration in first:
            try:
                declaration.undeclare()
            except Exception:
                log.debug("undeclaring the first trace subscriber failed", exc_info=True)

    def _sample(self, sample: zenoh.Sample) -> None:
        try:
            info = sample.source_info
            if info is not None:
                source, sn = str(info.source_id), info.source_sn
                with self._lock:
                    seen = self._seen.setdefault(source, set())
                    if sn in seen:
                        return  # the second subscriber's history: passed on already
                    seen.add(sn)
                    if len(seen) > 4 * TRACE_CACHE_SAMPLES:  # keep the newest, enough for any history
                        self._seen[source] = set(sorted(seen)[-2 * TRACE_CACHE_SAMPLES:])
                    if source not in self._caches:
                        self._caches[source] = "%s/@adv/pub/%s/%s/**" % (  # zenoh.ext's cache queryable
                            sample.key_expr, info.source_id.zid, info.source_id.eid)
                    if source not in self._sources:
                        attachment = sample.attachment
                        self._sources[source] = "%s %s" % (sample.key_expr, attachment.to_bytes().decode(
                            errors="replace") if attachment is not None else "?")
            self.on_batch(str(sample.key_expr), sample.payload.to_bytes())
        except Exception:
            log.exception("trace subscriber failed")

    def _repair(self) -> None:
        """From the time the second subscriber's history had, every ``TRACE_REPAIR_S``: ask
        each publisher's cache for the batches missing here (zenoh.ext's own recovery left
        them out, see the class): the ones before the first that came (until the cache
        answers), and the holes between the ones that came, once a hole was seen twice in a
        row (not merely on its way). A hole the cache no longer has after
        ``TRACE_REPAIR_TRIES`` asks is reported missed, and not asked for again."""
        time.sleep(TRACE_RESUBSCRIBE_S + 1.0)
        asks: dict[tuple[str, int], int] = {}  # (publisher, sequence number) -> asks so far
        previous: set[tuple[str, int]] = set()
        while True:
            with self._lock:
                if self._closed:
                    return
                known = {source: (self._caches[source], min(seen), max(seen), set(seen))
                         for source, seen in self._seen.items() if seen and source in self._caches}
            holes: set[tuple[str, int]] = set()
            for source, (cache, first, last, seen) in known.items():
                if first > 0 and source not in self._backfilled and self._ask_cache(cache, f"..{first - 1}"):
                    self._backfilled.add(source)
                holes.update((source, sn) for sn in range(first, last) if sn not in seen)
            for source, start, end in _runs(sorted(holes & previous)):  # seen twice: not on their way
                self._ask_cache(known[source][0], f"{start}..{end}")
                with self._lock:
                    still = [sn for sn in range(start, end + 1) if sn not in self._seen[source]]
                    for sn in still:
                        asks[(source, sn)] = asks.get((source, sn), 0) + 1
                    given_up = [sn for sn in still if asks[(source, sn)] >= TRACE_REPAIR_TRIES]
                    self._seen[source].update(given_up)  # reported once, never asked for again
                for sn in given_up:
                    del asks[(source, sn)]
                if given_up:
                    self._report_missed(source, len(given_up))
            previous = holes
            time.sleep(TRACE_REPAIR_S)

    def _ask_cache(self, cache: str, sn_range: str) -> int:
        """Ask one publisher's cache for the batches with sequence numbers ``sn_range``
        (``a..b``, ``..b`` or ``n``); each one that comes is passed on (once). Returns how
        many came."""
        got = 0
        try:
            for reply in self.bus.session.get(zenoh.Selector(cache, f"_sn={sn_range}"), target=zenoh.QueryTarget.ALL,
                                              timeout=TRACE_REPAIR_TIMEOUT_S, consolidation=zenoh.ConsolidationMode.NONE,
                                              accept_replies=zenoh.ReplyKeyExpr.ANY):  # the batches' own key
                if reply.ok is not None:
                    got += 1
                    self._sample(reply.ok)
        except Exception:
            log.exception("asking %s for its batches %s failed", cache, sn_range)
        log.info("trace repair: %s gave %d batches of %s", cache, got, sn_range)
        return got

    def _report_missed(self, source: str, count: int) -> None:
        try:
            self.on_miss(self._sources.get(source, source), count)
        except Exception:
            log.exception("trace miss listener failed")

    def _missed(self, miss: zenoh.ext.Miss) -> None:
        source = str(miss.source)
        log.info("zenoh.ext missed %d trace batches of %s; the repair asks its cache once more",
                 miss.nb, self._sources.get(source, source))

    def undeclare(self) -> None:
        self._timer.cancel()
        with self._lock:
            self._closed = True
            current, self._current = self._current, []
        for declaration in current:
            try:
                declaration.undeclare()
            except Exception:
                log.debug("undeclaring the trace subscriber failed", exc_info=True)


class _Request:
    """One request: its encoded payload, deadline and the instances tried so far."""

    def __init__(self, bus: Bus, service: str, op: str, body: object, timeout: float | None,
                 cid: str | None, instance: str | None, waiting: Callable[[float, str], None] | None):
        self.bus, self.service, self.op, self.instance = bus, service, op, instance
        self.spec = OPS[(service, op)]
        self.start = start = time.monotonic()
        self.timeout = self.spec.timeout if timeout is None else timeout
        self.deadline = start + self.timeout
        self.waiting_for = ""  # what the service announced it waits for
        self.relay = waiting
        # a quick call finds its instance within its deadline; a waiting one's deadline
        # counts from when it was sent (until the service announces more)
        self.grace_end = start + LIVELINESS_GRACE_S if self.spec.waits else min(self.deadline, start + LIVELINESS_GRACE_S)
        self.payload = _encoder.encode(RequestEnvelope(v=SCHEMA_VERSION, cid=cid or new_cid(), body=body))
        self.retry = instance is None and service in IDEMPOTENT_SERVICES and service not in OWNER_SERVICES
        self.hedged = self.retry and self.spec.hedged
        self.tried: set[str] = set()
        self.sends = 0  # copies sent: never more than two (a retry or a hedge)

    def remaining(self) -> float:
        return self.deadline - time.monotonic()

    def announced(self, waiting: Waiting) -> None:
        """The service waits ``waiting.seconds`` more for ``waiting.what`` (Zenoh's thread):
        the deadline follows, with a hop's margin, and the caller's caller is told."""
        seconds = waiting.seconds + HOP_S
        # the service's word replaces what the caller allowed before it spoke (ANNOUNCE_S,
        # or an earlier announcement): each hop outward then ends HOP_S after the one it called
        self.deadline = time.monotonic() + seconds
        self.waiting_for = waiting.what
        if self.relay is not None:
            self.relay(seconds, waiting.what)

    def late(self) -> BusTimeout:
        return BusTimeout(self.service, self.op, self.deadline - self.start, self.waiting_for)

    def sent(self, target: str) -> None:
        self.tried.add(target)
        self.sends += 1

    def hedge_at(self) -> float | None:
        """When to send the second copy (monotonic), or None: not hedged, or no time."""
        if not self.hedged or self.sends >= 2:
            return None
        at = time.monotonic() + HEDGE_DELAY_S
        return at if at < self.deadline else None

    def next_target(self) -> str | None:
        """The instance to send to; None: none live yet, ask again (``LIVELINESS_GRACE_S``)."""
        target = self.instance or self.bus._pick(self.service, self.tried)
        if target is None:
            if self.tried:
                raise self.late()
            if time.monotonic() >= self.grace_end:
                raise BusError("unavailable", f"{self.service} unavailable")
        elif self.spec.waits and not self.tried:
            self.deadline = max(self.deadline, time.monotonic() + self.timeout)
        return target

    def lost(self, target: str, exc: _InstanceLost) -> None:
        """The target vanished or did not answer: raise, or return to try another replica.
        ``unavailable`` only when the instance went away (or no query reached it) and no
        other live one can be asked; a live instance that did not answer is late."""
        self.tried.add(target)
        remaining = self.remaining()
        if not self.retry or self.sends >= 2 or remaining <= 0:
            if exc.gone or (remaining > 0 and target not in self.bus.instances(self.service)):
                raise BusError("unavailable", f"{self.service} unavailable ({exc})") from None
            raise self.late() from None
        log.warning("retrying %s.%s on another instance: %s", self.service, self.op, exc)

    def decode(self, raw: bytes, target: str) -> Any:
        try:
            envelope = self.bus._decoder(_parametrize(ReplyEnvelope, self.spec.reply)).decode(raw)
        except msgspec.DecodeError as exc:
            raise BusError("schema", f"malformed {self.service}.{self.op} reply: {exc}") from None
        if envelope.instance != target:  # never a second owner's answer, whatever the network did
            raise BusError("foreign", f"{self.service}.{self.op} answered by {envelope.instance!r}, "
                                      f"asked {target!r}")
        if not envelope.ok:
            error = envelope.error or ErrorBody(code="internal", message="error without detail")
            raise BusError(error.code, error.message)
        return envelope.body


def _reply_outcome(reply: zenoh.Reply, call: _Request, instance: str) -> tuple[bytes, str] | None:
    """A final reply's ``(payload, instance)``; None for an announcement (``Context.waiting``,
    passed to the call); a failure raised."""
    ok = reply.ok
    if ok is not None:
        if ok.attachment is not None and ok.attachment.to_bytes() == WAITING:
            try:
                call.announced(_waiting.decode(ok.payload.to_bytes()))
            except Exception:  # an announcement must not break the call: its reply still comes
                log.exception("bad announcement from %s.%s", call.service, call.op)
            return None
        return ok.payload.to_bytes(), instance
    message = reply.err.payload.to_string() if reply.err is not None else "reply without content"
    if message == "Timeout":  # Zenoh's own error reply: the query timed out (a stopped or
        # hung instance); reported like any lost instance, not as a bare "ERROR: Timeout"
        raise _InstanceLost(f"no reply from {call.service} instance {instance} in time")
    raise BusError("internal", message)


class _Exchange:
    """One request sent to one instance, its reply received on the calling thread.

    The reply comes through a Zenoh channel the caller blocks on: it wakes straight from
    Zenoh's thread, without a Python callback in between (the callback and the hand-over
    to the caller cost more than the Zenoh round trip itself: docs/PERFORMANCE.md).
    Whatever else must end the wait cancels the query, which closes the channel, and says
    why (``end``): the instance went away (``Bus._on_liveliness``), a waiting call ran past
    its deadline or was abandoned, or the hedge's second copy answered first (``_Watcher``).
    The second copy of a hedged call is the one reply taken by a callback.
    """

    def __init__(self, bus: Bus, call: _Request, target: str, abandon: Callable[[], bool] | None):
        self.bus, self.call, self.target, self.abandon = bus, call, target, abandon
        self.token = zenoh.CancellationToken()
        self._lock = threading.Lock()
        self._ended: tuple[tuple[bytes, str] | BaseException, str] | None = None  # outcome, instance
        self._hedge: tuple[str, zenoh.CancellationToken] | None = None  # where the second copy went
        self._hedge_done = threading.Lock()  # released when the second copy has its outcome
        self._hedge_done.acquire()
        self._hedge_outcome: tuple[bytes, str] | BaseException | None = None
        self._answered = False  # the channel gave the reply: the query ends by itself
        self.hedge_at: float | None = None
        self.watched = False

    def run(self) -> tuple[bytes, str]:
        """The reply ``(payload, instance)``; ``_InstanceLost`` when none can come."""
        call, target = self.call, self.target
        call.sent(target)
        self.hedge_at = call.hedge_at()
        self.watched = bool(self.hedge_at) or call.spec.waits
        self.bus._track(self, target, True)
        if self.watched:
            self.bus._watch(self)
        try:
            replies = self.bus._query(call, target, self.token)
        except zenoh.ZError:  # cancelled before it was sent (the instance went away at once)
            replies = ()
        try:
            for reply in replies:
                outcome = _reply_outcome(reply, call, target)
                if outcome is not None:
                    self._answered = True
                    return outcome
        except _InstanceLost as exc:
            return self._second_copy(exc)
        # the channel closed without a reply: why it was cancelled, or the query's end
        with self._lock:
            ended = self._ended
        if ended is None:
            return self._second_copy(_InstanceLost(f"no reply from {call.service} instance {target}"))
        why = ended[0]
        if isinstance(why, tuple):
            return why
        if isinstance(why, _InstanceLost):
            return self._second_copy(why)
        raise why

    def _second_copy(self, exc: _InstanceLost) -> tuple[bytes, str]:
        """The first copy failed: the second's outcome, if one was sent; else ``exc``."""
        if self._hedge is None:
            raise exc
        if not self._hedge_done.acquire(timeout=max(self.call.remaining() + REPLY_GRACE_S, 0.0)):
            raise exc
        if isinstance(self._hedge_outcome, tuple):
            return self._hedge_outcome
        raise exc

    def end(self, outcome: tuple[bytes, str] | BaseException, instance: str) -> None:
        """End the wait from another thread, with ``outcome`` (a reply or the reason), if
        ``instance`` is the one waited for: the query is cancelled, the caller wakes."""
        if self._hedge is not None and instance == self._hedge[0] and isinstance(outcome, BaseException):
            self.hedged(outcome)  # the second copy's instance went away
        if instance != self.target:
            return
        with self._lock:
            if self._ended is not None:
                return
            self._ended = (outcome, instance)
        self.token.cancel()

    def tick(self, now: float) -> None:
        """The watcher's look (``WATCH_TICK_S``): a hedge due, a deadline past, an abandon."""
        if self.hedge_at is not None and now >= self.hedge_at:
            self.hedge_at = None
            self._send_hedge()
        call = self.call
        if call.spec.waits:
            if self.abandon is not None and self.abandon():
                self.end(CallAbandoned(f"{call.service}.{call.op} abandoned by its caller"), self.target)
            elif call.remaining() + REPLY_GRACE_S <= 0:
                self.end(_InstanceLost("no reply in time"), self.target)

    def _send_hedge(self) -> None:
        """No answer yet: the second copy, to another live instance (the same one if it is
        the only one; the first copy may be stuck behind a lost packet, not the replica)."""
        call, bus = self.call, self.bus
        with self._lock:
            if self._ended is not None or call.remaining() <= 0:
                return
        target = bus._pick(call.service, call.tried) or bus._pick(call.service, set())
        if target is None:
            return
        log.debug("hedging %s.%s on %s", call.service, call.op, target)
        token = zenoh.CancellationToken()
        self._hedge = (target, token)
        call.sent(target)
        bus._track(self, target, True)

        def on_reply(reply: zenoh.Reply) -> None:
            try:
                outcome = _reply_outcome(reply, call, target)
            except Exception as exc:  # the second copy failed
                self.hedged(exc)
                return
            if outcome is not None:
                self.hedged(outcome)

        def on_done() -> None:
            self.hedged(_InstanceLost(f"no reply from {call.service} instance {target}"))

        try:
            bus._query(call, target, token, zenoh.handlers.Callback(on_reply, on_done))
        except zenoh.ZError:
            self.hedged(_InstanceLost(f"could not ask {call.service} instance {target}"))

    def hedged(self, outcome: tuple[bytes, str] | BaseException) -> None:
        """The second copy's outcome (Zenoh's thread): an answer ends the first copy's wait."""
        with self._lock:
            if self._hedge_outcome is not None:
                return
            self._hedge_outcome = outcome
        self._hedge_done.release()
        if isinstance(outcome, tuple):
            self.end(outcome, self.target)

    def close(self) -> None:
        """The call is over: nothing waits for either copy any more."""
        with self._lock:
            if self._ended is None:
                self._ended = (CallAbandoned("closed"), self.target)
        if not self._answered:
            self.token.cancel()
        self.bus._track(self, self.target, False)
        if self._hedge is not None:
            self._hedge[1].cancel()
            self.bus._track(self, self._hedge[0], False)
        if self.watched and self.bus._watcher is not None:
            self.bus._watcher.discard(self)


class _Watcher:
    """One thread per bus that acts, every ``WATCH_TICK_S``, for the callers blocked on a
    reply channel whose exchange needs watching (a hedged call, a waiting one): see
    ``_Exchange.tick``. Started with the first such call."""

    def __init__(self, bus: Bus):
        self._bus = bus
        self._exchanges: set[_Exchange] = set()
        self._lock = threading.Lock()
        threading.Thread(target=self._run, name=f"{bus.service}-bus-watch", daemon=True).start()

    def add(self, exchange: _Exchange) -> None:
        with self._lock:
            self._exchanges.add(exchange)

    def discard(self, exchange: _Exchange) -> None:
        with self._lock:
            self._exchanges.discard(exchange)

    def _run(self) -> None:
        while not self._bus._closed.is_set():
            time.sleep(WATCH_TICK_S)
            with self._lock:
                exchanges = list(self._exchanges)
            now = time.monotonic()
            for exchange in exchanges:
                try:
                    exchange.tick(now)
                except Exception:  # one call's trouble must not stop the others' watch
                    log.exception("watching %s.%s failed", exchange.call.service, exchange.call.op)


def decode(typ: type[T], payload: bytes) -> T:
    """Decode a published message of type ``typ``."""
    return msgspec.json.decode(payload, type=typ)


def _parametrize(generic: Any, typ: type) -> Any:
    """``generic[typ]`` for a type known only at run time (the operation's message type)."""
    return generic[typ]
