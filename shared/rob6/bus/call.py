"""Calls: a request to one live instance and its reply, with deadline, retry and hedge.

Calls: a request sent to one live instance and its reply received on the calling
thread, with its deadline, its retry and its hedge.

When an instance vanishes mid-request (its token disappears) or does not answer in time,
a request to an idempotent service is retried once on another instance; a hedged one
(single-pose kinematics, ``Op.hedged``) not answered after ``HEDGE_DELAY_S`` is sent a
second time, to another live instance (or the same one when it is the only one), and the
first answer wins. Never for an owner service: one robot, one owner, a motion is never
sent twice. A service with no live instance is waited for (``LIVELINESS_GRACE_S``, within
the call's deadline) before the call fails ``unavailable``.

A reply that waits for the arm (``Op.waits``) is not bounded by the quick-call deadline:
the service announces how long and for what (``Context.waiting``), and the caller's
deadline becomes that plus ``rob6.deadlines.HOP_S``; a caller that is itself a handler
passes the announcement on (``request(..., waiting=ctx.waiting)``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import msgspec
import zenoh

from ..deadlines import HOP_S
from ..messages import (
    IDEMPOTENT_SERVICES,
    OPS,
    OWNER_SERVICES,
    SCHEMA_VERSION,
    ErrorBody,
    ReplyEnvelope,
    RequestEnvelope,
    Waiting,
)
from .codec import WAITING, _encoder, _waiting, new_cid
from .errors import BusError, BusTimeout, CallAbandoned, _InstanceLost
from .liveliness import Liveliness

log = logging.getLogger("rob6.bus")

#: a hedged request (``Op.hedged``: single-pose kinematics) not answered after this long
#: is sent a second time: the first copy may sit on a replica that hangs or on a remote
#: host behind a lost TCP segment (retransmission >= 200 ms). Above the p99 of a healthy
#: remote call (tens of ms, deploy/MULTI_HOST.md), so a second copy costs a replica
#: something only when the first is already late; below TCP's 200 ms retransmission
#: timeout, so the copy is out before a stalled exchange would recover by itself.
HEDGE_DELAY_S = 0.15
#: how long a call waits for a service with no live instance before it answers
#: ``unavailable`` (never past its deadline): a peer that reconnects to its router (a router
#: restart) loses and regains its token within 0.25-1 s, and calls in that window wait
#: instead of failing. (It was added for a supposed token loss after a recorder restart,
#: which was a late reply misreported: deploy/MULTI_HOST.md.) A service really gone costs
#: its callers this long once per call.
LIVELINESS_GRACE_S = 1.0
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


class Calling(Liveliness):
    """A caller's side of the bus (a mixin of ``Bus``): calls go to the live instances."""

    def _init_calls(self) -> None:
        self._watcher: _Watcher | None = None

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
        ``abandon`` (waiting operations): asked every ``WATCH_TICK_S`` by the bus's watcher
        thread while the caller waits, never after the call ended; when it answers True (the
        client left), the query is cancelled and ``CallAbandoned`` raised.
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

    def _watch(self, exchange: _Exchange) -> None:
        if self._watcher is None:
            with self._lock:
                if self._watcher is None:
                    self._watcher = _Watcher(self)
        self._watcher.add(exchange)

    def _query(self, call: _Request, instance: str, token: zenoh.CancellationToken,
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


class _Request:
    """One request: its encoded payload, deadline and the instances tried so far."""

    def __init__(self, bus: Calling, service: str, op: str, body: object, timeout: float | None,
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
            envelope = self.bus._decoder(ReplyEnvelope, self.spec.reply).decode(raw)
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

    def __init__(self, bus: Calling, call: _Request, target: str, abandon: Callable[[], bool] | None):
        self.bus, self.call, self.target, self.abandon = bus, call, target, abandon
        self.token = zenoh.CancellationToken()
        self._lock = threading.Lock()
        self._ended: tuple[tuple[bytes, str] | BaseException, str] | None = None  # outcome, instance
        self._hedge: tuple[str, zenoh.CancellationToken] | None = None  # where the second copy went
        self._hedge_done = threading.Lock()  # released when the second copy has its outcome
        self._hedge_done.acquire()
        self._hedge_outcome: tuple[bytes, str] | BaseException | None = None
        self._answered = False  # the channel gave the reply: the query ends by itself
        # the watcher's look and the call's end exclude each other: ``abandon`` reads the
        # client's socket, which is the caller's again once the call is over, and a hedge
        # sent after the end would be left behind
        self._watch_lock = threading.Lock()
        self._closed = False
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
        with self._watch_lock:
            if self._closed:
                return
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
        with self._watch_lock:  # a look under way ends first; none comes after
            self._closed = True
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

    def __init__(self, bus: Calling):
        self._bus = bus
        self._exchanges: set[_Exchange] = set()
        self._lock = threading.Lock()
        self._watching = threading.Event()  # set while there is an exchange: idle, it sleeps
        self.thread = threading.Thread(target=self._run, name=f"{bus.service}-bus-watch", daemon=True)
        self.thread.start()

    def wake(self) -> None:
        """The bus closed: the thread sees it now, not at its next idle wake-up."""
        self._watching.set()

    def add(self, exchange: _Exchange) -> None:
        with self._lock:
            self._exchanges.add(exchange)
            if not self._watching.is_set():  # on every hedged call's path: the wake only when asleep
                self._watching.set()

    def discard(self, exchange: _Exchange) -> None:
        with self._lock:
            self._exchanges.discard(exchange)

    def _run(self) -> None:
        while not self._bus._closed.is_set():
            time.sleep(WATCH_TICK_S)
            with self._lock:
                exchanges = list(self._exchanges)
                if not exchanges:
                    self._watching.clear()
            if not exchanges:
                self._watching.wait(1.0)  # woken by the next exchange, or by the bus's close
                continue
            now = time.monotonic()
            for exchange in exchanges:
                try:
                    exchange.tick(now)
                except Exception:  # one call's trouble must not stop the others' watch
                    log.exception("watching %s.%s failed", exchange.call.service, exchange.call.op)

