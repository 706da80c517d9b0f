"""The gateway's joint state mirror over a real Zenoh bus: the followed driver's newest state
is read, a stray driver's never, and a driver that went silent is told (``rob6.state``).

The mirror has no event to wait on: it takes the states when it is read, so these tests read it
again until it shows what they wait for, as a lab client polling GetPositionJoints does
(``wait_until``); and a driver publishes every cycle, so a state published before Zenoh's
route to the gateway existed is followed by the next one, as the real driver's is."""

from __future__ import annotations

import queue
import time
from collections.abc import Callable, Iterator

import pytest

from harness.system import zenoh_router
from rob6.bus import Bus, decode
from rob6.config import BusSettings
from rob6.messages import JointState
from rob6.state import JointStateMirror
from tests.motion.link_session import wait_until

ZERO = [0.0] * 6
DEADLINE_S = 10.0
ARRIVAL_S = 0.5  # a published state that has not reached the gateway by then: publish the next


@pytest.fixture
def buses() -> Iterator[Callable[[str, str], Bus]]:
    opened: list[Bus] = []
    with zenoh_router("mirror") as settings:
        def bus(service: str, instance: str) -> Bus:
            opened.append(Bus(BusSettings(robot_id=settings.robot_id, connect=settings.connect,
                                          instance=instance), service))
            return opened[-1]

        try:
            yield bus
        finally:
            for b in opened:
                b.close()


def _publish(driver: Bus, cycle: int, q: list[float]) -> None:
    driver.publish("driver/state", JointState(t=cycle * 0.004, cycle=cycle, q=q, qd=ZERO,
                                              instance=driver.instance))


def test_the_followed_drivers_newest_state_is_read_and_a_strays_never(buses: Callable[[str, str], Bus]) -> None:
    driver, gateway = buses("driver", "driver-a"), buses("gateway", "gateway-1")
    driver.announce()
    wait_until(lambda: gateway.owner("driver") == "driver-a", DEADLINE_S, "the gateway to follow driver-a")
    stray = buses("driver", "driver-b")
    stray.announce()
    wait_until(lambda: len(gateway.instances("driver")) == 2, DEADLINE_S, "the stray driver's token")
    mirror = JointStateMirror(gateway)
    arrived: queue.SimpleQueue[JointState] = queue.SimpleQueue()  # every instance's, as they come
    gateway.subscribe("driver/state", lambda key, payload: arrived.put(decode(JointState, payload)))
    cycle = 0

    def both_published_and_arrived() -> bool:
        """The driver's state and then the stray's, a later cycle: both came to the gateway."""
        nonlocal cycle
        cycle += 1
        _publish(driver, cycle, [float(cycle)] * 6)
        _publish(stray, 10**6 + cycle, [99.0] * 6)
        waiting = {cycle, 10**6 + cycle}
        deadline = time.monotonic() + ARRIVAL_S
        try:
            while waiting:
                waiting.discard(arrived.get(timeout=max(0.0, deadline - time.monotonic())).cycle)
        except queue.Empty:
            return False  # the routes to the gateway are not there yet
        return True

    read: list[JointState] = []

    def read_the_drivers() -> bool:
        state = mirror.get()
        if state is not None:
            read.append(state)
        return state is not None and state.q == [float(cycle)] * 6

    for _ in range(3):
        wait_until(both_published_and_arrived, DEADLINE_S, "both states at the gateway")
        wait_until(read_the_drivers, DEADLINE_S, "the driver's newest state in the mirror")
    assert {state.instance for state in read} == {"driver-a"}


def test_a_driver_that_went_silent_is_told_although_it_is_alive(buses: Callable[[str, str], Bus]) -> None:
    driver, gateway = buses("driver", "driver-a"), buses("gateway", "gateway-1")
    driver.announce()
    wait_until(lambda: gateway.owner("driver") == "driver-a", DEADLINE_S, "the gateway to follow driver-a")
    mirror = JointStateMirror(gateway)
    cycle = 0

    def published_and_read() -> bool:
        nonlocal cycle
        cycle += 1
        _publish(driver, cycle, [3.0] * 6)
        return mirror.get() is not None

    wait_until(published_and_read, DEADLINE_S, "a published state in the mirror")
    wait_until(lambda: mirror.get() is None, DEADLINE_S, "the silent driver told")  # no state for STATE_STALE_S
    assert gateway.instances("driver") == ["driver-a"]  # though its token is still there
