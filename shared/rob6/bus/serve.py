"""Serving: a service's queryable, its worker threads, and the answer to each request.

Serving: a service's queryable, its worker threads, and the answer to each request
(its envelope checked, its handler run, its reply and its trace record sent).

A reply that waits for the arm (``Op.waits``) is announced first: the handler says how
long and for what (``Context.waiting``), an interim reply the caller's deadline follows.
"""

from __future__ import annotations

import functools
import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from queue import SimpleQueue
from typing import Any, NamedTuple

import msgspec
import zenoh

from ..messages import OPS, SCHEMA_VERSION, ErrorBody, Op, ReplyEnvelope, RequestEnvelope, Waiting
from .codec import WAITING, _encoder
from .errors import BusError
from .trace import Tracing

log = logging.getLogger("rob6.bus")


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


class _Served(NamedTuple):
    """An operation this service answers: its handler, its spec, its requests' decoder
    (each looked up once, at ``serve``, not with every request)."""

    handler: Handler
    spec: Op
    decoder: msgspec.json.Decoder[Any]


class Serving(Tracing):
    """A service's side of the bus (a mixin of ``Bus``): every request it serves is traced."""

    def _init_serving(self) -> None:
        self._workers: list[threading.Thread] = []

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
        served = {op: _Served(handler, OPS[(self.service, op)],
                              self._decoder(RequestEnvelope, OPS[(self.service, op)].request))
                  for op, handler in handlers.items()}
        queue: SimpleQueue[tuple[zenoh.Query, str] | None] = SimpleQueue()

        def on_query(query: zenoh.Query) -> None:
            op = str(query.key_expr).rsplit("/", 1)[-1]
            if op in quick:
                self._answer(query, op, served)
            else:
                queue.put((query, op))

        def on_close() -> None:  # the session is going away: the workers end
            for _ in range(workers):
                queue.put(None)

        # complete: this instance answers every key under it (an unknown op with an error),
        # so a query for one of them goes to it alone. Without it Zenoh also sends each
        # query to the router, which answers only its end: measured, 5-6 context switches of
        # the router and 3-4 of the asking process per request (docs/PERFORMANCE.md)
        self._declared.append(self.session.declare_queryable(
            self.key(self.service, self.instance, "*"), zenoh.handlers.Callback(on_query, on_close), complete=True))
        for n in range(workers):
            thread = threading.Thread(target=self._serve_loop, args=(queue, served),
                                      name=f"{self.service}-worker-{n}", daemon=True)
            thread.start()
            self._workers.append(thread)
        self.announce()

    def announce(self) -> None:
        """Declare this instance alive (its liveliness token) on the bus."""
        self._declared.append(self.session.liveliness().declare_token(
            self.key("alive", self.service, self.instance)))

    def _serve_loop(self, queue: SimpleQueue[tuple[zenoh.Query, str] | None],
                    served: Mapping[str, _Served]) -> None:
        while (item := queue.get()) is not None:
            self._answer(*item, served)

    def _answer(self, query: zenoh.Query, op: str, served: Mapping[str, _Served]) -> None:
        started = time.time()
        cid = ""
        raw = query.payload.to_bytes() if query.payload is not None else b""
        try:
            if op not in served:
                raise BusError("unknown_op", f"{self.service} has no operation {op!r}")
            handler, spec, decoder = served[op]
            try:
                envelope = decoder.decode(raw)
            except msgspec.DecodeError as exc:
                raise BusError("schema", f"malformed {self.service}.{op} request: {exc}") from None
            cid = envelope.cid
            if envelope.v != SCHEMA_VERSION:
                raise BusError("schema", f"schema version {envelope.v}, expected {SCHEMA_VERSION}")
            waiting = functools.partial(self._announce, query) if spec.waits else _no_announcement
            body = handler(envelope.body, Context(cid=cid, op=op, waiting=waiting))
            reply: ReplyEnvelope[Any] = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=True, instance=self.instance, body=body)
        except BusError as exc:
            reply = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=False, instance=self.instance,
                                  error=ErrorBody(code=exc.code, message=exc.message))
        except Exception as exc:  # never a traceback on the wire; the log has it
            log.exception("%s.%s failed (cid %s)", self.service, op, cid)
            reply = ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=False, instance=self.instance, error=ErrorBody(
                code="internal", message=f"{self.service}.{op}: {type(exc).__name__}: {exc}"))
        try:
            payload = _encoder.encode(reply)
        except (TypeError, msgspec.EncodeError) as exc:  # a handler's reply the schema cannot carry
            log.exception("%s.%s: the reply cannot be encoded (cid %s)", self.service, op, cid)
            payload = _encoder.encode(ReplyEnvelope(v=SCHEMA_VERSION, cid=cid, ok=False, instance=self.instance,
                                                    error=ErrorBody(code="internal", message=(
                                                        f"{self.service}.{op}: the reply cannot be encoded: {exc}"))))
        query.reply(query.key_expr, payload)
        query.drop()
        self.trace(f"trace/{self.service}/{op}", b'{"t":%.6f,"dt":%.6f,"instance":"%s","request":%s,"reply":%s}' % (
            started, time.time() - started, self.instance.encode(), raw or b"null", payload))

    def _announce(self, query: zenoh.Query, seconds: float, what: str) -> None:
        """An interim reply: the final one takes up to ``seconds`` more (``Context.waiting``)."""
        query.reply(query.key_expr, _encoder.encode(Waiting(seconds=seconds, what=what)), attachment=WAITING)
