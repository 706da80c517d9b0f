"""Records for the recorder: trace batches out of each process, and the recorder's subscription in.

Records for the recorder: each process's ``trace/<service>`` batches out (``Bus.trace``),
and the recorder's subscription that gets every batch in (``Bus.subscribe_traces``).

Records leave in batches, one message per few milliseconds (``TRACE_BATCH_S``): a JSON
array of ``[suffix, record]`` pairs, read with ``trace_records``. They come from a
zenoh.ext advanced publisher that keeps the last ``TRACE_CACHE_S`` of batches and numbers
them: a recorder that was partitioned away or restarted gets what it missed and learns of
what it could not get (``_TraceSubscription``). The suffixes are listed in ``rob6.bus``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from queue import Empty, SimpleQueue
from typing import Any

import msgspec
import zenoh
import zenoh.ext

from .codec import _encoder
from .session import BusSession

log = logging.getLogger("rob6.bus")

#: traces gather this long before they leave as one message: a request pays for a queue
#: put, not for a thread wake-up and a publication of its own (the recording overhead)
TRACE_BATCH_S = 0.005
TRACE_BATCH_MAX = 256

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
#: a stopping recorder asks the caches once more for whatever is still missing, all at
#: once, for at most this long (the launcher gives the recorder 1.5 s to stop)
TRACE_LAST_ASK_S = 0.5

_trace_batch = msgspec.json.Decoder(list[tuple[str, msgspec.Raw]])


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
    """The ``(suffix, record JSON)`` pairs of one ``trace/<service>`` batch (for tools and
    tests; the recorder splits its batches natively: services/recorder/native/src/batch.rs)."""
    return [(suffix, bytes(record)) for suffix, record in _trace_batch.decode(payload)]


class Tracing(BusSession):
    """The batching of this process's records (a mixin of ``Bus``)."""

    def _init_traces(self) -> None:
        # records for the recorder leave from a thread of their own, in order, so a request
        # never waits for their encoding or for the network (see ``trace``)
        self._traces: SimpleQueue[tuple[str, object] | None] = SimpleQueue()
        # declared now, not with the first batch: a recorder learns of it (publisher
        # detection) before there is anything to miss
        self._trace_publisher = zenoh.ext.declare_advanced_publisher(
            self.session, self.key("trace", self.service), congestion_control=zenoh.CongestionControl.BLOCK,
            cache=zenoh.ext.CacheConfig(TRACE_CACHE_SAMPLES, replies_config=zenoh.ext.RepliesConfig(
                congestion_control=zenoh.CongestionControl.BLOCK)),  # history, like the batches: never dropped
            sample_miss_detection=zenoh.ext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=TRACE_HEARTBEAT_S),
            publisher_detection=True)
        self._tracer = threading.Thread(target=self._trace_loop, name=f"{self.service}-traces", daemon=True)
        self._tracer.start()

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
                         on_miss: Callable[[str, int], None]) -> _TraceSubscription:
        """Every ``trace/<service>`` batch of every process, with what the publishers kept
        (``TRACE_CACHE_S``): ``on_batch(key, payload)`` for each batch, the ones published
        before this subscriber came (history of every publisher, also of one detected
        later) and the ones lost on the way (recovered from the publisher's cache) included,
        each once; ``on_miss(source, count)`` for batches that could not be recovered
        (``source``: the key and instance of the publisher, or its Zenoh id until one of its
        batches came). Both are called on Zenoh's threads and must not block."""
        return _TraceSubscription(self, on_batch, on_miss)

    def _flush_traces(self) -> None:
        """What was traced before the close still goes out: the trace thread sends it and ends."""
        self._traces.put(None)
        self._tracer.join(5.0)


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
    number). The first goes ``TRACE_RESUBSCRIBE_S`` after that, not at once: zenoh.ext
    holds a publisher's live batches while a history query is out, and when its query to
    that one publisher (late-publisher detection) outlasts its first, wider one, it passes
    the next live batch on and drops the ones it held as duplicates (zenoh-ext 1.10's
    ``handle_sample`` and ``flush_sequenced_source``); the multi-host test lost 25 and 53
    client records from where the switch fell, in 2 of 3 full runs. While the first
    subscriber still passes those batches on, they are not lost (deploy/MULTI_HOST.md).
    In a multi-host run even the second one's history sometimes brought nothing from a
    publisher, and a batch now and then was neither delivered nor reported missed, so
    ``_repair`` asks the publishers' caches directly for whatever is missing by sequence
    number, and reports what they no longer have. It is the one reporter of misses: a miss zenoh.ext reports
    leaves a hole that the repair asks for once more and then reports, so it is only logged.
    A recorder stopped before the repair came round (a hole waits two rounds) asks once
    more as it stops (``undeclare``).
    """

    def __init__(self, bus: BusSession, on_batch: Callable[[str, bytes], None], on_miss: Callable[[str, int], None]):
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
                _undeclare(second)
                return
            first = self._current
            self._current = first + second
            # both pass batches on until the second's history has surely come (see the class)
            self._timer = threading.Timer(TRACE_RESUBSCRIBE_S, self._retire, (len(first),))
            self._timer.daemon = True
            self._timer.start()

    def _retire(self, count: int) -> None:
        """The first subscriber goes (its ``count`` declarations, first in ``_current``)."""
        with self._lock:
            if self._closed:
                return
            first, self._current = self._current[:count], self._current[count:]
        _undeclare(first)

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
            known = self._known()
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

    def _known(self) -> dict[str, tuple[str, int, int, set[int]]]:
        """Each publisher with a batch here: its cache, the first and last sequence number
        that came, and all that came."""
        with self._lock:
            return {source: (self._caches[source], min(seen), max(seen), set(seen))
                    for source, seen in self._seen.items() if seen and source in self._caches}

    def _ask_cache(self, cache: str, sn_range: str) -> int:
        """Ask one publisher's cache for the batches with sequence numbers ``sn_range``
        (``a..b``, ``..b``, ``a..`` or ``n``); each one that comes is passed on (once).
        Returns how many came."""
        return self._take(self._ask(cache, sn_range, TRACE_REPAIR_TIMEOUT_S), cache, sn_range)

    def _ask(self, cache: str, sn_range: str, timeout: float) -> Iterable[zenoh.Reply]:
        """The query of ``_ask_cache``, sent; its replies are read by ``_take``."""
        try:
            return self.bus.session.get(zenoh.Selector(cache, f"_sn={sn_range}"), target=zenoh.QueryTarget.ALL,
                                        timeout=timeout, consolidation=zenoh.ConsolidationMode.NONE,
                                        accept_replies=zenoh.ReplyKeyExpr.ANY)  # the batches' own key
        except Exception:
            log.exception("asking %s for its batches %s failed", cache, sn_range)
            return ()

    def _take(self, replies: Iterable[zenoh.Reply], cache: str, sn_range: str) -> int:
        got = 0
        try:
            for reply in replies:
                if reply.ok is not None:
                    got += 1
                    self._sample(reply.ok)
        except Exception:
            log.exception("asking %s for its batches %s failed", cache, sn_range)
        log.info("trace repair: %s gave %d batches of %s", cache, got, sn_range)
        return got

    def _last_ask(self) -> None:
        """As the subscription ends: ask every publisher's cache at once, for at most
        ``TRACE_LAST_ASK_S``, for each batch still missing here (the holes, the ones before
        the first that came if its cache has not answered for them yet, and any after the
        last that came), then report the holes that are still there as missed: a recorder
        stopped right after a hole, before the repair came round, loses nothing a cache
        still has, and nothing silently."""
        known = self._known()
        asked = []
        for source, (cache, first, last, seen) in known.items():
            ranges = [f"{start}..{end}" for _, start, end in _runs(
                [(source, sn) for sn in range(first, last) if sn not in seen])] + [f"{last + 1}.."]
            if first > 0 and source not in self._backfilled:
                ranges.append(f"..{first - 1}")
            asked += [(cache, sn_range, self._ask(cache, sn_range, TRACE_LAST_ASK_S)) for sn_range in ranges]
        for cache, sn_range, replies in asked:
            self._take(replies, cache, sn_range)
        for source, (_cache, first, last, _seen) in known.items():
            with self._lock:
                still = [sn for sn in range(first, last) if sn not in self._seen[source]]
            if still:
                self._report_missed(source, len(still))

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
        """End the subscription, then ask once more for what is missing (``_last_ask``)."""
        self._timer.cancel()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            current, self._current = self._current, []
        _undeclare(current)
        self._last_ask()


def _undeclare(declarations: list[Any]) -> None:
    for declaration in declarations:
        try:
            declaration.undeclare()
        except Exception:
            log.debug("undeclaring a trace subscriber failed", exc_info=True)

