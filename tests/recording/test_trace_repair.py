"""The trace subscription's repair (rob6.bus.trace._TraceSubscription._repair): what zenoh.ext's
own history and recovery left out is asked from the publisher's cache by sequence number,
every batch is passed on once, and what the cache no longer has is reported missed. Seen in
the multi-host topology: a restarted recorder whose history brought nothing from a
publisher, and a batch neither delivered nor reported missed. Real Zenoh sessions through a
real router, in this process.

The failures are made here: the subscribers are declared without history and without the
recovery a publisher's heartbeat would start, and chosen batches are dropped on arrival.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import msgspec
import pytest
import zenoh

from harness.system import zenoh_router
from rob6.bus import Bus, trace as bus_trace, trace_records
from rob6.config import BusSettings

RECORDS = 80


def _without_history(self: bus_trace._TraceSubscription) -> list[zenoh.ext.AdvancedSubscriber[None]]:
    subscriber = zenoh.ext.declare_advanced_subscriber(
        self.bus.session, self.bus.key("trace", "*"), zenoh.handlers.Callback(self._sample))
    return [subscriber]


@contextmanager
def _session(monkeypatch: pytest.MonkeyPatch, drop: Callable[[int, int], bool] | None = None
             ) -> Iterator[tuple[Bus, Callable[[], bus_trace._TraceSubscription], list[int], list[tuple[str, int]],
                                 set[int]]]:
    """A publisher ("gateway"), a function that subscribes a recorder (its subscription, once
    its first subscriber has gone and the second alone passes batches on), the record
    numbers it was given, the misses it was told of, and the record numbers that arrived,
    dropped or not. ``drop(sn, times_seen)``: drop that arrival."""
    monkeypatch.setattr(bus_trace._TraceSubscription, "_declare", _without_history)
    monkeypatch.setattr(bus_trace, "TRACE_RESUBSCRIBE_S", 0.5)
    monkeypatch.setattr(bus_trace, "TRACE_REPAIR_S", 0.5)
    retired = threading.Event()
    retire = bus_trace._TraceSubscription._retire

    def retiring(self: bus_trace._TraceSubscription, count: int) -> None:
        retire(self, count)
        retired.set()

    monkeypatch.setattr(bus_trace._TraceSubscription, "_retire", retiring)
    arrived: set[int] = set()
    if drop is not None:
        original = bus_trace._TraceSubscription._sample
        arrivals: dict[int, int] = {}

        def dropping(self: bus_trace._TraceSubscription, sample: zenoh.Sample) -> None:
            sn = sample.source_info.source_sn if sample.source_info is not None else -1
            arrivals[sn] = arrivals.get(sn, 0) + 1
            arrived.update(_numbers(sample.payload.to_bytes()))
            if str(sample.key_expr).endswith("/gateway") and drop(sn, arrivals[sn]):
                return
            original(self, sample)

        monkeypatch.setattr(bus_trace._TraceSubscription, "_sample", dropping)
    with zenoh_router("repair") as settings:
        publisher = Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect, instance="pub"), "gateway")
        recorder = Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect, instance="rec"), "recorder")
        received: list[int] = []
        misses: list[tuple[str, int]] = []
        lock = threading.Lock()
        subscriptions = []

        def on_batch(_key: str, payload: bytes) -> None:
            with lock:
                received.extend(_numbers(payload))

        def subscribe() -> bus_trace._TraceSubscription:
            retired.clear()
            subscriptions.append(recorder.subscribe_traces(on_batch, lambda source, count: misses.append((source, count))))
            assert retired.wait(10.0), "the first trace subscriber did not go"
            return subscriptions[-1]

        try:
            yield publisher, subscribe, received, misses, arrived
        finally:
            for subscription in subscriptions:
                subscription.undeclare()
            recorder.close()
            publisher.close()


def _numbers(payload: bytes) -> list[int]:
    """The test's record numbers in one trace batch."""
    return [msgspec.json.decode(record)["n"] for suffix, record in trace_records(payload) if suffix == "trace/gateway/test"]


def _publish(publisher: Bus, numbers: range) -> None:
    for n in numbers:  # one record a batch: 10 ms apart, the batches gather for 5
        publisher.trace("trace/gateway/test", {"n": n})
        time.sleep(0.01)


def _wait_for(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.05)


def test_batches_published_before_the_subscription_come_from_the_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    with _session(monkeypatch) as (publisher, subscribe, received, _misses, _arrived):
        _publish(publisher, range(40))  # before any recorder: in the publisher's cache only
        subscribe()
        _publish(publisher, range(40, RECORDS))
        _wait_for(lambda: len(received) >= RECORDS)
        time.sleep(1.0)  # nothing more may come: each batch once
        assert sorted(received) == list(range(RECORDS)), sorted(set(range(RECORDS)) - set(received))
        assert min(received[:5]) >= 40  # the live ones came first: the old ones were asked for


def test_a_batch_lost_on_the_way_is_asked_for_again(monkeypatch: pytest.MonkeyPatch) -> None:
    lost = {20, 21, 35}
    with _session(monkeypatch, drop=lambda sn, seen: sn in lost and seen == 1) as (publisher, subscribe, received,
                                                                                   misses, _arrived):
        subscribe()
        _publish(publisher, range(RECORDS))
        _wait_for(lambda: len(received) >= RECORDS)
        time.sleep(1.0)
        assert sorted(received) == list(range(RECORDS)), sorted(set(range(RECORDS)) - set(received))
        assert not misses


def test_a_batch_the_cache_no_longer_has_is_reported_missed(monkeypatch: pytest.MonkeyPatch) -> None:
    with _session(monkeypatch, drop=lambda sn, _seen: sn == 30) as (publisher, subscribe, received, misses,
                                                                      _arrived):
        subscribe()
        _publish(publisher, range(RECORDS))
        _wait_for(lambda: bool(misses))
        assert misses == [("rob6/repair/trace/gateway pub", 1)]
        time.sleep(2.0)  # reported once, not asked for again
        assert len(misses) == 1
        assert RECORDS - 3 <= len(received) < RECORDS  # one batch: one record, two on a busy machine



def test_a_stopping_subscription_asks_for_what_is_still_missing(monkeypatch: pytest.MonkeyPatch) -> None:
    """A hole and a tail that had not come when the subscription ended, before the repair came
    round (a recorder stopped a moment after the hole): both are asked for as it ends."""
    with _session(monkeypatch, drop=lambda sn, seen: (sn in {20, 21} or sn >= 70) and seen == 1) as (
            publisher, subscribe, received, misses, arrived):
        monkeypatch.setattr(bus_trace, "TRACE_REPAIR_S", 3600.0)  # one round only, before the batches
        subscription = subscribe()
        _publish(publisher, range(RECORDS))
        _wait_for(lambda: RECORDS - 1 in arrived)  # the last batch arrived, and was dropped
        missing = set(range(RECORDS)) - set(received)  # a batch's number is not its record's
        assert min(missing) < 60 and RECORDS - 1 in missing, sorted(missing)  # a hole and the tail
        subscription.undeclare()
        assert sorted(received) == list(range(RECORDS)), sorted(set(range(RECORDS)) - set(received))
        assert not misses


def test_a_stopping_subscription_reports_what_no_cache_gave(monkeypatch: pytest.MonkeyPatch) -> None:
    with _session(monkeypatch, drop=lambda sn, _seen: sn == 30) as (publisher, subscribe, received, misses,
                                                                      arrived):
        monkeypatch.setattr(bus_trace, "TRACE_REPAIR_S", 3600.0)
        subscription = subscribe()
        _publish(publisher, range(RECORDS))
        _wait_for(lambda: RECORDS - 1 in arrived)
        assert not misses  # no repair round saw the hole twice
        subscription.undeclare()
        assert misses == [("rob6/repair/trace/gateway pub", 1)]
        assert len(set(range(RECORDS)) - set(received)) == 1
