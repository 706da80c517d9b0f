"""The RSI link against the stand-in KR C4 running the shipped program: stop and restart.

rob6's stop ends the program cleanly (RSI_MOVECORR returns, RSI_OFF, END, no message) and
an operator's restart brings a new run the link follows from where the arm stands, twice
in a row, on KSS 8.6 (RSI 4.1, the kr16 at 12 ms) and on KSS 8.3 (RSI 3.x, where only
#IPO_FAST corrects in RSI_MOVECORR: the kr16rt at 4 ms). At 12 ms each run stays under 100
packets, so the shipped Timeout (100 late packets a run) cannot trip however slow the
machine is; at 4 ms a run is longer, and the Timeout is the system tests' (SYSTEM_TIMEOUT):
a fault here is the files' or the link's."""

from __future__ import annotations

import socket
from collections.abc import Callable

import numpy as np
import pytest

from harness.ports import free_port
from rob6.messages import LinkEvent
from rob6.robots import get_robot
from rob6_driver.links.rsi import RsiLink
from rob6_driver.motion import MotionCore
from tests.controllers.rsi_controller import RSI3_KSS, SYSTEM_TIMEOUT, RsiController
from tests.driver.test_rsi_link import ptp, wait

HOME = [0.0, -90.0, 90.0, 0.0, 0.0, 0.0]


def connected(link: RsiLink) -> Callable[[], bool]:
    return lambda: link.state == "connected"


@pytest.mark.parametrize("kss", ["8.3", "8.6"])
def test_stop_and_restart_twice_without_a_fault(kss: str) -> None:
    name = "kr16rt" if kss in RSI3_KSS else "kr16"
    robot = get_robot(name)
    port = free_port(socket.SOCK_DGRAM)
    timeout = SYSTEM_TIMEOUT if kss in RSI3_KSS else None
    with RsiController(rob6=("127.0.0.1", port), robot=name, kss=kss, timeout=timeout) as kuka:
        for run in (1, 2, 3):
            core = MotionCore(robot)
            events: list[LinkEvent] = []
            link = RsiLink(core, robot, f"127.0.0.1:{port}", lambda s: None, events.append)
            link.start()
            try:
                if run > 1:
                    assert kuka.restart()["program"] == "running"  # the operator starts the program again
                wait(connected(link), timeout=10)
                start = core.state().q.copy()
                assert np.allclose(start, kuka.status()["aipos"], atol=1e-4)
                target = start + [0.5, 0.0, 0.0, 0.0, 0.0, 0.0]
                motion = ptp(core, target.tolist())
                assert motion.wait(10) and motion.ok, motion.error
            finally:
                link.stop()
            st = kuka.wait_for(lambda s: s["state"] == "stopped" and s["program"] != "running", timeout=15,
                               what=f"run {run}: the program to end after rob6's Stop")
            assert st["program"] == "ended", st["program"]
            assert st["trips"] == [] and st["messages"] == [], (st["trips"], st["messages"])
            assert st["runs"] == run and st["stop_reason"] == "RSI_OFF"
            assert np.allclose(st["aipos"], target, atol=1e-3)  # the arm stays where rob6 left it
            assert np.allclose(st["aspos"], start, atol=1e-3)  # ASPos: where this run's PTP $AXIS_ACT was
            assert [e.event for e in events][-2:] == ["stop_sent", "stopped"]
        assert np.allclose(kuka.status()["aipos"], np.array(HOME) + [1.5, 0, 0, 0, 0, 0], atol=1e-3)


def test_a_12_ms_robot_refuses_a_4_ms_run_in_one_line(caplog: pytest.LogCaptureFixture) -> None:
    """ROB6_ROBOT=kr16 (12 ms) on a KSS 8.3 controller running the shipped .dat (rob6IpoFast
    TRUE: a packet every 4 ms): rob6 would command three times its planned speeds. The link
    refuses the run: one ERROR line naming both cycles and what to set, motion commands
    refused with it, and Stop answered, so the program ends with no fault and the arm where
    it stood. A restart is refused again."""
    robot = get_robot("kr16")
    port = free_port(socket.SOCK_DGRAM)
    caplog.set_level("ERROR", logger="rob6.driver")
    with RsiController(rob6=("127.0.0.1", port), robot="kr16rt", kss="8.3", timeout=SYSTEM_TIMEOUT) as kuka:
        assert kuka.cycle_ms == 4
        core = MotionCore(robot)
        events: list[LinkEvent] = []
        link = RsiLink(core, robot, f"127.0.0.1:{port}", lambda s: None, events.append)
        link.start()
        try:
            for run in (1, 2):
                if run > 1:
                    wait(lambda: link.state == "stopped")  # the driver saw RSI off: a packet now is a new run
                    assert kuka.restart()["program"] == "running"
                def refused(n: int = run) -> bool:
                    return link.runs == n and link.state in ("refused", "stopped")

                wait(refused, timeout=10)
                st = kuka.wait_for(lambda s: s["state"] == "stopped" and s["program"] != "running", timeout=15,
                                   what=f"run {run}: the program to end after the refusal's Stop")
                assert st["program"] == "ended", st["program"]
                assert st["trips"] == [] and st["messages"] == [], (st["trips"], st["messages"])
                assert st["stop_reason"] == "RSI_OFF"
                assert np.allclose(st["aipos"], HOME, atol=1e-4)  # nothing moved
                motion = ptp(core, (np.array(HOME) + [0.5, 0, 0, 0, 0, 0]).tolist())
                assert motion.wait(1) and not motion.ok
                assert motion.error == core.offline_reason
        finally:
            link.stop()
    expected = ("RSI run refused: ROB6_ROBOT=kr16 expects a packet every 12 ms, the controller sends one every "
                "4 ms: set ROB6_ROBOT=kr16rt (4 ms, #IPO_FAST), or rob6IpoFast FALSE in rob6_rsi.dat (#IPO, 12 ms: "
                "KSS 8.5 and later only)")
    assert core.offline_reason == expected
    lines = [e for e in events if e.event == "wrong_cycle"]
    assert [e.message for e in lines] == [expected, expected]  # one line a run
    assert [r.getMessage() for r in caplog.records if r.levelname == "ERROR"] == [f"driver: {expected}"] * 2
    assert [e.event for e in events if e.event in ("trip", "late")] == []
