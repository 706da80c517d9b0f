"""A call to a service with no live instance waits ``LIVELINESS_GRACE_S`` (within its
deadline) for one before it fails ``unavailable`` (rob6.bus): a token can vanish for a
moment while its instance lives on, and a restarted service comes back. Real router, real
sessions, in this process."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest
from pytest import MonkeyPatch

from harness.system import zenoh_router
from rob6.bus import Bus, BusError, call as bus_call
from rob6.config import BusSettings
from rob6.messages import Empty, MoveRequest, PingReply


@pytest.fixture
def settings() -> Iterator[BusSettings]:
    with zenoh_router("grace") as settings:
        yield settings


def _bus(settings: BusSettings, service: str, instance: str) -> Bus:
    return Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect, instance=instance), service)


def test_a_call_waits_for_an_owner_that_comes_up(settings: BusSettings, monkeypatch: MonkeyPatch) -> None:
    monkeypatch.setattr(bus_call, "LIVELINESS_GRACE_S", 20.0)  # a slow machine's start-up fits
    client = _bus(settings, "test", "client")
    drivers: list[Bus] = []

    def come_up() -> None:
        time.sleep(0.3)  # the call below is already waiting
        driver = _bus(settings, "driver", "driver-1")
        driver.serve({"ping": lambda _body, _ctx: PingReply(robot_time=1.0, wall_time=2.0)})
        drivers.append(driver)

    starter = threading.Thread(target=come_up)
    try:
        assert not client.instances("driver")
        starter.start()
        reply = client.request("driver", "ping", Empty(), timeout=30)  # failed at once before the grace
        assert reply == PingReply(robot_time=1.0, wall_time=2.0)
    finally:
        starter.join()
        for bus in (client, *drivers):
            bus.close()


def test_no_instance_fails_unavailable_after_the_grace_within_the_deadline(settings: BusSettings, monkeypatch: MonkeyPatch) -> None:
    monkeypatch.setattr(bus_call, "LIVELINESS_GRACE_S", 0.4)
    client = _bus(settings, "test", "client")
    try:
        started = time.monotonic()
        with pytest.raises(BusError) as error:  # a waiting operation: the grace decides
            client.request("planner", "move", MoveRequest(kind="MovePTPJoints", joints=[0.0] * 6))
        took = time.monotonic() - started
        assert (error.value.code, error.value.message) == ("unavailable", "planner unavailable")
        assert 0.4 <= took < 30
        monkeypatch.setattr(bus_call, "LIVELINESS_GRACE_S", 30.0)
        started = time.monotonic()
        with pytest.raises(BusError) as error:  # the deadline (0.1 s) comes before the grace
            client.request("driver", "ping", Empty(), timeout=0.1)
        assert error.value.code == "unavailable"
        assert 0.1 <= time.monotonic() - started < 30
    finally:
        client.close()
