"""Hedged requests (rob6.bus): a single-pose kinematics call that a replica leaves
unanswered is sent a second time after HEDGE_DELAY_S, and the first answer wins; an
owner service is never sent a request twice.

A real Zenoh router and real sessions (one per replica, each serving on its own worker
threads), all in this process: a replica that never answers is a handler that blocks.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from pytest import MonkeyPatch

from harness.system import zenoh_router
from rob6.bus import HEDGE_DELAY_S, Bus, BusError, Context, call as bus_call
from rob6.config import BusSettings
from rob6.deadlines import REMOTE_POSE_S
from rob6.messages import OPS, Empty, FkReply, FkRequest, Op, PingReply

JOINTS = [10.0, -60.0, 80.0, 20.0, 40.0, 30.0]


class _Replica:
    """One instance of ``service`` serving ``op`` in its own Zenoh session; ``delays``
    gives the handling time of each call in turn (None: never answers), then 0."""

    def __init__(self, settings: BusSettings, service: str, op: str, name: str,
                 delays: Callable[[int], float | None], reply: Any) -> None:
        self.calls = 0
        self.release = threading.Event()
        self._lock = threading.Lock()
        self.bus = Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect, instance=name), service)

        def handler(_body: Any, _ctx: Context) -> Any:
            with self._lock:
                n, self.calls = self.calls, self.calls + 1
            delay = delays(n)
            if delay is None:
                self.release.wait(30)  # never answers (until the test ends)
            elif delay:
                time.sleep(delay)
            return reply

        self.bus.serve({op: handler}, workers=4)

    def close(self) -> None:
        self.release.set()
        self.bus.close()


def _never(_n: int) -> float | None:
    return None


def _fast(_n: int) -> float | None:
    return 0.0


FK = FkReply(poses=[[1.0] * 12], status=["ok"])


@contextmanager
def _kinematics(*replicas: tuple[str, Callable[[int], float | None]]) -> Iterator[tuple[Bus, list[_Replica]]]:
    with zenoh_router("hedge") as settings:
        served = [_Replica(settings, "kinematics", "fk", name, delays, FK) for name, delays in replicas]
        client = Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect, instance="client"), "test")
        try:
            assert not client.wait_for(("kinematics",), 10)
            deadline = time.monotonic() + 10
            while len(client.instances("kinematics")) < len(replicas):
                assert time.monotonic() < deadline, "the replicas did not come up"
                time.sleep(0.02)
            client.request("kinematics", "fk", FkRequest(joints=[JOINTS]), instance=served[-1].bus.instance)
            yield client, served
        finally:
            client.close()
            for replica in served:
                replica.close()


def test_single_pose_ops_are_hedged_with_a_longer_deadline() -> None:
    for op in ("fk", "forward_calc", "backward_calc", "select"):
        assert OPS[("kinematics", op)].hedged and OPS[("kinematics", op)].timeout == REMOTE_POSE_S
    assert not OPS[("kinematics", "ik_batch")].hedged
    assert not any(spec.hedged for (service, _op), spec in OPS.items() if service != "kinematics")
    assert HEDGE_DELAY_S < 0.2 < REMOTE_POSE_S  # out before TCP's retransmission timeout


def test_a_never_answering_replica_costs_the_hedge_delay_not_the_timeout() -> None:
    with _kinematics(("hung", _never), ("fast", _fast)) as (client, (hung, fast)):
        times = []
        for _ in range(8):
            started = time.monotonic()
            reply = client.request("kinematics", "fk", FkRequest(joints=[JOINTS]))
            times.append(time.monotonic() - started)
            assert reply == FK
        assert hung.calls >= 2  # some calls went to the hung replica first...
        assert max(times) < HEDGE_DELAY_S + 0.25  # ...and were answered by the hedge
        assert max(times) >= HEDGE_DELAY_S  # (that one waited for the hedge delay)


def test_the_hedge_goes_to_the_same_replica_when_it_is_the_only_one() -> None:
    # the first copy sits in a slow handler (or behind a lost packet): the second, served
    # by another worker of the same replica, answers
    with _kinematics(("only", lambda n: 3.0 if n == 1 else 0.0)) as (client, (only,)):
        started = time.monotonic()
        assert client.request("kinematics", "fk", FkRequest(joints=[JOINTS])) == FK
        elapsed = time.monotonic() - started
        assert HEDGE_DELAY_S <= elapsed < HEDGE_DELAY_S + 0.25
        assert only.calls == 3  # the warm-up, the slow copy and the hedge


def test_the_hedge_goes_to_another_host() -> None:
    # two replicas of one host hang (say, behind the same lost TCP segment): the second copy
    # goes to the other host's replica, not to its hung neighbour (instance ids are host-suffix)
    with _kinematics(("c1-aaaa", _never), ("c1-bbbb", _never), ("c2-cccc", _fast)) as (client, served):
        first_c1 = 0
        for _ in range(9):
            before = served[0].calls + served[1].calls
            started = time.monotonic()
            assert client.request("kinematics", "fk", FkRequest(joints=[JOINTS])) == FK
            assert time.monotonic() - started < HEDGE_DELAY_S + 0.25
            first_c1 += served[0].calls + served[1].calls - before
        assert first_c1 >= 2  # calls did go to c1 first, and the hedge never did


def test_a_fast_answer_sends_no_second_copy() -> None:
    with _kinematics(("a", _fast), ("b", _fast)) as (client, (a, b)):
        before = a.calls + b.calls
        for _ in range(20):
            client.request("kinematics", "fk", FkRequest(joints=[JOINTS]))
        assert a.calls + b.calls - before == 20


def test_when_every_copy_is_lost_the_call_times_out_at_its_deadline() -> None:
    with _kinematics(("hung", _never), ("fast", _fast)) as (client, (hung, fast)):
        with pytest.raises(BusError) as error:
            started = time.monotonic()
            client.request("kinematics", "fk", FkRequest(joints=[JOINTS]), instance=hung.bus.instance,
                           timeout=0.5)
        assert error.value.code == "timeout"
        assert 0.5 <= time.monotonic() - started < 0.8
        assert hung.calls == 1  # a call for one named instance is never hedged


def test_an_owner_service_is_never_sent_a_request_twice(monkeypatch: MonkeyPatch) -> None:
    # even if its operation were marked hedged and idempotent by mistake: one robot, one owner
    monkeypatch.setitem(OPS, ("driver", "ping"), Op(Empty, PingReply, timeout=1.0, hedged=True))
    monkeypatch.setattr(bus_call, "IDEMPOTENT_SERVICES", frozenset({"kinematics", "driver"}))
    with zenoh_router("hedge") as settings:
        driver = _Replica(settings, "driver", "ping", "driver1", lambda n: 0.5,
                          PingReply(robot_time=1.0, wall_time=2.0))
        client = Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect, instance="client"), "test")
        try:
            assert not client.wait_for(("driver",), 10)
            started = time.monotonic()
            assert client.request("driver", "ping", Empty()).robot_time == 1.0
            assert time.monotonic() - started >= 0.5
            time.sleep(0.2)
            assert driver.calls == 1
        finally:
            client.close()
            driver.close()
