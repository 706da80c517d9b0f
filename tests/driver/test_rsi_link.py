"""The RSI link's rules, packet by packet, against a scripted controller on real UDP:
a run's first packet answered from where the arm stands, one step per cycle, the same
setpoint again when an answer came too late, duplicates and garbage unanswered, link lost
and back (from AIPos), a restart re-based on the new start pose, Stop answered until the
controller switches RSI off."""

from __future__ import annotations

import re
import socket
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
import pytest

from rob6.messages import LinkEvent
from rob6.robots import get_robot
from rob6_driver.links.rsi import RsiLink
from rob6_driver.motion import CoreState, Motion, MotionCore
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import TrajectoryPlanner

HOME = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
SEN = re.compile(rb'<Sen Type="ImFree"><AK A1="([^"]+)" A2="([^"]+)" A3="([^"]+)" A4="([^"]+)" '
                 rb'A5="([^"]+)" A6="([^"]+)"/><Stop>([01])</Stop><IPOC>(\d+)</IPOC></Sen>$')


def axes(name: str, q: Sequence[float]) -> str:
    return f"<{name} " + " ".join(f'A{i + 1}="{v:.4f}"' for i, v in enumerate(q)) + "/>"


class Controller:
    """Sends hand-made <Rob> packets to the link and reads its answers."""

    def __init__(self, address: str) -> None:
        host, port = address.rsplit(":", 1)
        self.target = (host, int(port))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.ipoc = 1000

    def send(self, aipos: Sequence[float] = HOME, aspos: Sequence[float] = HOME, delay: int = 0,
             ipoc: int | None = None, raw: bytes | None = None) -> int:
        if ipoc is None:
            self.ipoc += 4
            ipoc = self.ipoc
        data = raw or (f'<Rob TYPE="KUKA">{axes("AIPos", aipos)}{axes("ASPos", aspos)}<Delay D="{delay}"/>'
                       f"<IPOC>{ipoc}</IPOC></Rob>").encode()
        self.sock.sendto(data, self.target)
        return ipoc

    def answer(self, timeout: float = 2.0) -> tuple[np.ndarray, bool, int] | None:
        """(AK, stop, ipoc) of the next answer, or None if none comes within timeout."""
        self.sock.settimeout(timeout)
        try:
            data = self.sock.recv(4096)
        except TimeoutError:
            return None
        m = SEN.match(data)
        assert m, data
        return np.array([float(x) for x in m.groups()[:6]]), m.group(7) == b"1", int(m.group(8))

    def cycle(self, **kw: Any) -> np.ndarray:
        ipoc = self.send(**kw)
        answer = self.answer()
        assert answer is not None, "no answer"
        ak, stop, echoed = answer
        assert echoed == ipoc
        return ak


#: the fixture: core, link, the fake controller, the states published, the link's events
Rig = tuple[MotionCore, RsiLink, Controller, list[CoreState], list[LinkEvent]]


@pytest.fixture
def rig() -> Iterator[Rig]:
    robot = get_robot("kr16rt")
    core = MotionCore(robot)
    states: list[CoreState] = []
    events: list[LinkEvent] = []
    link = RsiLink(core, robot, "127.0.0.1:0", states.append, events.append, lost_after_s=0.3)
    link.start()
    controller = Controller(link.address)
    yield core, link, controller, states, events
    link.stop()
    controller.sock.close()


def wait(predicate: Callable[[], object], timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)


def ptp(core: MotionCore, target: Sequence[float]) -> Motion:
    plan = TrajectoryPlanner(core.robot).plan_ptp(core.state().q.tolist(), list(target), MotionSettings(core.robot))
    t = plan.trajectory
    assert t is not None, plan.reason
    return core.execute(t.q, t.dt, t.qd, t.qdd)


def test_start_steps_and_late_answers(rig: Rig) -> None:
    core, link, ctl, states, events = rig
    assert link.state == "waiting"
    assert core.execute([list(HOME)] * 2, core.dt).error.startswith("robot not connected (waiting for RSI on 127.0.0.1:")
    assert np.array_equal(ctl.cycle(aspos=HOME), np.zeros(6))  # the first packet: zero correction
    assert link.state == "connected" and core.state().q.tolist() == list(HOME)
    motion = ptp(core, (20.0, -90.0, 90.0, 0.0, 0.0, 0.0))
    ak = [ctl.cycle() for _ in range(60)]
    steps = np.diff([a[0] for a in ak])
    assert np.all(steps > 0)  # one step a cycle
    # our last answer came too late: the controller counted it and still applies the one before
    held = ctl.cycle(delay=1)
    assert np.array_equal(held, ak[-1]), "the same setpoint again, not a second step"
    nxt = ctl.cycle(delay=1)
    one_step = steps[-1] + 1e-3  # the next sample (accelerating), never two
    assert 0 < nxt[0] - held[0] <= one_step
    # a packet that never reached us: its lateness is explained by the gap, the robot steps on
    ctl.ipoc += 4
    after_gap = ctl.cycle(delay=2)
    assert 0 < after_gap[0] - nxt[0] <= one_step + 1e-3
    assert link.late == 2 and link.missed == 1
    wait(lambda: [e.event for e in events if e.event == "late"] == ["late", "late"])  # published after the answers
    # a duplicate of the last packet, an older one, garbage and a stranger get no answer
    stranger = Controller(link.address)
    sends: tuple[Callable[[], int], ...] = (
        lambda: ctl.send(delay=2, ipoc=ctl.ipoc), lambda: ctl.send(delay=2, ipoc=ctl.ipoc - 8),
        lambda: ctl.send(raw=b"<Rob><IPOC>12</IPOC>"), lambda: stranger.send(delay=2, ipoc=ctl.ipoc + 4))
    for send in sends:
        send()
        time.sleep(0.01)  # one at a time (several waiting at once: only the newest is looked at)
    assert ctl.answer(timeout=0.05) is None and stranger.answer(timeout=0.05) is None
    assert link.garbage == 1
    while not motion.done.is_set():
        ctl.cycle(delay=2)
    assert motion.ok
    assert ctl.cycle(delay=2)[0] == pytest.approx(20.0, abs=1e-6)


def test_lost_and_back_in_the_same_run_continues_from_aipos(rig: Rig) -> None:
    core, link, ctl, states, events = rig
    last = ctl.cycle()
    motion = ptp(core, (20.0, -90.0, 90.0, 0.0, 0.0, 0.0))
    for _ in range(100):  # the arm follows the answers, a cycle behind (AIPos as a real one reports it)
        last = ctl.cycle(aipos=np.array(HOME) + last)
    motion.wait(2.0)  # the link is lost (no packet for 0.3 s): the motion ends with the error
    assert motion.ok is False and motion.error.startswith("RSI link lost: no packet from the controller at 127.0.0.1:")
    assert link.state == "lost"
    wait(lambda: states[-1].cycle == core.cycle and states[-1].mode == "idle")
    # the controller held; its robot settled a little beyond the last answer
    aipos = np.array(HOME) + last + [0.0005, 0, 0, 0, 0, 0]
    back = ctl.cycle(aipos=aipos, delay=30)
    assert np.allclose(back, aipos - HOME, atol=1e-9), "AK = AIPos - ASPos: no jump"
    assert link.state == "connected" and link.late == 30
    wait(lambda: [e.event for e in events][-2:] == ["lost", "back"])
    # a new motion starts from there
    motion = ptp(core, HOME)
    first = ctl.cycle(aipos=aipos, delay=30)
    assert abs(first[0] - back[0]) < 0.01


def test_a_restart_rebases_on_the_new_start_pose(rig: Rig) -> None:
    core, link, ctl, states, events = rig
    ctl.cycle()
    motion = ptp(core, (20.0, -90.0, 90.0, 0.0, 0.0, 0.0))
    for _ in range(50):
        ctl.cycle()
    new_start = (5.0, -80.0, 85.0, 0.0, 10.0, 0.0)
    assert np.array_equal(ctl.cycle(aipos=new_start, aspos=new_start), np.zeros(6))
    assert motion.ok is False and "restarted" in motion.error
    assert core.state().q.tolist() == list(new_start) and link.runs == 2
    wait(lambda: [e.event for e in events][-2:] == ["trip", "restart"])
    assert events[-1].start_pose == list(new_start)
    assert np.array_equal(ctl.cycle(aipos=new_start, aspos=new_start), np.zeros(6))


def test_an_arm_moved_farther_than_its_axes_can_between_two_packets_starts_a_new_run(rig: Rig) -> None:
    """The operator jogged the arm and restarted RSI at the same start pose, with no late
    packet in the run before and a pause shorter than the lost-link time: AIPos has moved
    farther than the axes can in that time, so it is a new run (AK = 0 there), not the old
    setpoint answered (a step of degrees: 'Command velocity' on the controller)."""
    core, link, ctl, states, events = rig
    ctl.cycle()
    jogged = (3.0, -87.0, 90.0, 0.0, 2.0, 0.0)
    answer = ctl.cycle(aipos=jogged)
    assert np.allclose(answer, np.array(jogged) - HOME) and link.runs == 2
    assert core.state().q.tolist() == list(jogged)


def test_a_new_run_starts_where_the_arm_stands_whatever_aspos(rig: Rig) -> None:
    """RSI_OFF/RSI_ON without a motion keeps the old programmed ASPos while the arm stands
    where the corrections put it: AK = AIPos - ASPos holds it there (zero would jump back)."""
    core, link, ctl, states, events = rig
    last = ctl.cycle()
    motion = ptp(core, (5.0, -90.0, 90.0, 0.0, 0.0, 0.0))
    while not motion.done.is_set():  # the arm follows the answers, a cycle behind
        last = ctl.cycle(aipos=np.array(HOME) + last)
    assert motion.ok and last[0] == pytest.approx(5.0)
    stands = (5.0, -90.0, 90.0, 0.0, 0.0, 0.0)
    ctl.cycle(aipos=stands, delay=3)  # a few late ones in this run
    first = ctl.cycle(aipos=stands, delay=0)  # Delay from 0 again: RSI_ON, ASPos as before
    assert np.allclose(first, np.array(stands) - HOME) and link.runs == 2
    assert core.state().q.tolist() == list(stands)


def test_stop_is_answered_until_the_controller_switches_rsi_off() -> None:
    """The program's RSI_OFF comes after RSI_MOVECORR returned: every packet until then is
    answered (with Stop), and stop() returns once the packets have ended."""
    robot = get_robot("kr16rt")
    core = MotionCore(robot)
    events: list[LinkEvent] = []
    # lost_after_s: the silence that tells RSI is off; long, so that a loaded machine's pauses
    # between the packets below never look like it
    link = RsiLink(core, robot, "127.0.0.1:0", lambda s: None, events.append, lost_after_s=1.0)
    link.start()
    ctl = Controller(link.address)
    try:
        assert ctl.cycle() is not None
        stopper = threading.Thread(target=link.stop)
        stopper.start()
        wait(lambda: link._stopping)
        for _ in range(3):  # RSI_MOVECORR returns with the first; RSI_OFF comes later
            ipoc = ctl.send()
            answer = ctl.answer()
            assert answer is not None
            ak, stop, echoed = answer
            assert stop and echoed == ipoc and np.array_equal(ak, np.zeros(6))
        assert stopper.is_alive(), "stop() returned while the controller still sends"
        stopper.join(5)  # no more packets: RSI is off
        assert not stopper.is_alive() and link.state == "stopped"
        wait(lambda: "stopped" in [e.event for e in events])
    finally:
        ctl.sock.close()
