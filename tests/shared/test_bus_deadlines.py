"""A reply that waits is bounded by what the service says it waits for (rob6.bus,
rob6.deadlines): a call to a live instance that announced a wait gets its reply however
long past the quick-call deadline; a live instance that stays silent is ``timeout``
naming what it waited for, never ``unavailable``; a service in between passes the
announcement on, and its own late call is the error the caller sees. Real router, real
sessions, in this process."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from harness.system import zenoh_router
from rob6.bus import Bus, BusError, BusTimeout, Context
from rob6.config import BusSettings
from rob6.deadlines import HOP_S, QUICK_S
from rob6.messages import Ack, AlterMode, Empty, ModeRequest, PingReply

STOPPING = "waiting for the arm to stop"


#: what the driver announces it waits for: beyond the quick-call deadline
ANNOUNCED_S = QUICK_S + 0.4


@pytest.fixture
def buses() -> Iterator[tuple[Bus, Bus, Bus, threading.Event]]:
    """A caller, a planner and a driver on one router; the driver's handlers hang until
    the event is set (at the end of the test)."""
    release = threading.Event()
    with zenoh_router("deadlines") as settings:
        def bus(service: str) -> Bus:
            return Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect,
                                   instance=f"{service}-1"), service)

        caller, planner, driver = bus("gateway"), bus("planner"), bus("driver")

        def alter_mode(req: AlterMode, ctx: Context) -> Ack:
            ctx.waiting(ANNOUNCED_S, STOPPING)
            if req.enable:  # the arm comes to rest after the quick deadline, within what was announced
                time.sleep(QUICK_S + 0.3)
                return Ack(ok=True)
            release.wait(30)  # never at rest: the caller gives up
            return Ack(ok=False)

        def ping(_req: Empty, _ctx: Context) -> PingReply:
            release.wait(30)  # a hung instance, its token alive
            return PingReply(robot_time=0.0, wall_time=0.0)

        def mode(req: ModeRequest, ctx: Context) -> Ack:
            reply: Ack = planner.request("driver", "alter_mode", AlterMode(enable=req.command == "EnableAlter"),
                                         waiting=ctx.waiting)
            return reply

        driver.serve({"alter_mode": alter_mode, "ping": ping})
        planner.serve({"mode": mode})
        try:
            assert not caller.wait_for(["planner", "driver"], 20.0)
            yield caller, planner, driver, release
        finally:
            release.set()
            for b in (caller, planner, driver):
                b.close()


def test_an_announced_wait_beyond_the_quick_deadline_is_answered(buses: tuple[Bus, Bus, Bus, threading.Event]) -> None:
    caller, *_ = buses
    announced: list[tuple[float, str]] = []
    began = time.monotonic()
    reply = caller.request("driver", "alter_mode", AlterMode(enable=True),
                           waiting=lambda seconds, what: announced.append((seconds, what)))
    assert reply == Ack(ok=True)
    assert time.monotonic() - began > QUICK_S  # answered after the quick-call deadline
    assert announced == [(ANNOUNCED_S + HOP_S, STOPPING)]  # passed on with a hop's margin


def test_a_silent_live_instance_is_timeout_naming_what_it_waited_for(buses: tuple[Bus, Bus, Bus, threading.Event]) -> None:
    caller, *_ = buses
    with pytest.raises(BusTimeout) as error:
        caller.request("driver", "alter_mode", AlterMode(enable=False))
    assert error.value.code == "timeout"
    assert error.value.waiting_for == STOPPING
    assert ANNOUNCED_S + HOP_S <= error.value.seconds < 10  # what was announced, with a hop's margin
    assert error.value.message == f"driver: no reply to alter_mode within {error.value.seconds:.1f} s ({STOPPING})"
    with pytest.raises(BusTimeout) as error:  # a quick call: no announcement, still not "unavailable"
        caller.request("driver", "ping", Empty())
    assert (error.value.code, error.value.waiting_for) == ("timeout", "")
    assert error.value.message == f"driver: no reply to ping within {QUICK_S:.1f} s"


def test_a_service_in_between_passes_the_wait_on_and_reports_its_own_late_call(buses: tuple[Bus, Bus, Bus, threading.Event]) -> None:
    caller, *_ = buses
    assert caller.request("planner", "mode", ModeRequest(command="EnableAlter")) == Ack(ok=True)
    with pytest.raises(BusError) as error:  # the planner gives up first: its error names the driver
        caller.request("planner", "mode", ModeRequest(command="DisableAlter"))
    assert not isinstance(error.value, BusTimeout)  # the planner's answer, not the caller's own timeout
    assert error.value.code == "timeout"
    assert error.value.message.startswith("driver: no reply to alter_mode within")
    assert error.value.message.endswith(f"({STOPPING})")
