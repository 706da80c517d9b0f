"""The simple_message link's rules against a scripted controller on real TCP (frames packed
by hand here): the stream's form (hold point, sequence, -3 at the end, one request at a
time), arrival before true, the faults (E-stop, drives off, refused points, silence,
late and missing acknowledgements, a robot that stops short) ending motions with their
error and the resync at the robot's actual position, and the robot's range guarded.
Assertions are about what was sent and said, never about how fast this machine is."""

from __future__ import annotations

import contextlib
import itertools
import math
import select
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import TypedDict

import numpy as np
import pytest
from pytest import FixtureRequest

from rob6.messages import LinkEvent
from rob6.robots import get_robot
from rob6_driver.links.simple_message import (
    MAX_SEGMENT_DEG,
    RATED_SPEED_DEG_S,
    AdeptLink,
    AdeptSettings,
    from_wire,
    to_wire,
)
from rob6_driver.motion import Motion, MotionCore
from rob6_planner.config import MotionSettings
from rob6_planner.trajectory import TrajectoryPlanner

ROBOT = get_robot("ad850")
ORDERS = {"big": ">", "little": "<"}
STATE_PERIOD_S = 0.02


class Point:
    def __init__(self, sequence: int, comm: int, joints: Sequence[float], velocity: float, duration: float) -> None:
        self.sequence, self.comm, self.velocity, self.duration = sequence, comm, velocity, duration
        self.joints = list(joints)  # ten, radians
        self.q = from_wire(self.joints)  # rob6 degrees


class Ports(TypedDict):
    """The fake controller's ports, as ``AdeptSettings`` takes them."""

    motion_port: int
    state_port: int


class FakeController:
    """Both ports of a simple_message controller, scripted by the test. The motion port reads
    fixed 68-byte records like the V+ program (``discard``: after taking the connection's
    first four bytes, as its ``GETC`` would if they are the client's); the records of the
    connection's opening are kept apart from the points."""

    def __init__(self, order: str = "big", discard: bool = False) -> None:
        self.e = ORDERS[order]
        self.discard = discard
        self.motion_server = socket.create_server(("127.0.0.1", 0))
        self.state_server = socket.create_server(("127.0.0.1", 0))
        self.points: list[Point] = []
        self.openings: list[Point] = []  # the records the link's openings were read as
        self.reply_code = 1
        self.ack_delay = 0.0
        self.follow = True  # the robot is at every acknowledged point at once
        self.in_motion = 0
        self.status = {"drives_powered": 1, "e_stopped": 0, "error_code": 0, "in_error": 0}
        self.position = [0.0, 0.0, math.pi / 2, 0.0, 0.0, 0.0]  # rob6's zero
        self.silent = False
        self.pipelined = 0  # requests sent before the previous one was answered
        self.connections = {"motion": 0, "state": 0}
        self._sockets: list[socket.socket] = []
        self._opened = 0  # openings before the current motion connection's
        self._closing = False
        for server, serve in ((self.motion_server, self._motion), (self.state_server, self._state)):
            threading.Thread(target=self._accept, args=(server, serve), daemon=True).start()

    @property
    def settings(self) -> Ports:
        motion: int = self.motion_server.getsockname()[1]
        state: int = self.state_server.getsockname()[1]
        return {"motion_port": motion, "state_port": state}

    def close(self) -> None:
        self._closing = True
        for sock in (self.motion_server, self.state_server, *self._sockets):
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()

    def drop(self) -> None:
        """Close every connection (the ports take new ones)."""
        for sock in self._sockets:
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
        self._sockets.clear()

    def _accept(self, server: socket.socket, serve: Callable[[socket.socket], None]) -> None:
        while not self._closing:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            self._sockets.append(conn)
            threading.Thread(target=serve, args=(conn,), daemon=True).start()

    def _frame(self, msg_type: int, comm: int, reply: int, body: bytes) -> bytes:
        e: str = self.e
        return struct.pack(e + "i", 12 + len(body)) + struct.pack(e + "3i", msg_type, comm, reply) + body

    def _motion(self, conn: socket.socket) -> None:
        self.connections["motion"] += 1
        self._opened = len(self.openings)
        e = self.e
        opening = 1  # records of the opening still to come (a stop read from byte 0: one more)
        try:
            if self.discard:
                _exact(conn, 4)
            while True:
                record = _exact(conn, 68)
                _length, msg_type, comm, _, seq = struct.unpack_from(e + "5i", record)
                point = Point(seq, comm, struct.unpack_from(e + "10f", record, 20), *struct.unpack_from(e + "ff", record, 60))
                if opening:
                    first = opening == 1 and not self.openings[self._opened:]
                    opening = 1 if first and seq == -4 else 0
                    self.openings.append(point)
                    conn.sendall(self._frame(11, 3, 1, struct.pack(e + "i", -4 if seq == -4 else 0)))
                    continue
                assert msg_type == 11, msg_type
                self.points.append(point)
                if self.ack_delay:
                    time.sleep(self.ack_delay)
                if conn.fileno() >= 0 and select.select([conn], [], [], 0)[0]:
                    self.pipelined += 1
                code = 1 if seq == -4 else self.reply_code
                if code == 1 and seq != -4 and self.follow:
                    self.position = point.joints[:6]
                conn.sendall(self._frame(11, 3, code, struct.pack(e + "i", -4 if seq == -4 else 0)))
        except (OSError, ConnectionError):
            pass

    def _state(self, conn: socket.socket) -> None:
        self.connections["state"] += 1
        e = self.e
        try:
            while not self._closing:
                if not self.silent:
                    st = self.status
                    conn.sendall(self._frame(10, 1, 0, struct.pack(e + "i10f", 0, *self.position, 0, 0, 0, 0))
                                 + self._frame(13, 1, 0, struct.pack(
                                     e + "7i", st["drives_powered"], st["e_stopped"], st["error_code"],
                                     st["in_error"], self.in_motion, 2, 1 - self.in_motion)))
                time.sleep(STATE_PERIOD_S)
        except OSError:
            pass


def _exact(conn: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = conn.recv(n - len(data))
        if not chunk:
            raise ConnectionError
        data += chunk
    return data


def wait(predicate: Callable[[], object], timeout: float = 15.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.005)


def ptp(core: MotionCore, target: Sequence[float], config: MotionSettings | None = None) -> tuple[Motion, int]:
    plan = TrajectoryPlanner(core.robot).plan_ptp(core.state().q.tolist(), list(target),
                                                  config or MotionSettings(core.robot))
    assert plan.ok, plan.reason
    t = plan.trajectory
    assert t is not None
    return core.execute(t.q, t.dt, t.qd, t.qdd), len(t.q)


def online(core: MotionCore, link: AdeptLink) -> None:
    wait(lambda: link.state == "connected" and not core.offline_reason, what="the link to be up")


#: the fixture: the fake controller, core, link and the link's events
Rig = tuple[FakeController, MotionCore, AdeptLink, list[LinkEvent]]


@pytest.fixture(params=["big", "little"])
def rig(request: FixtureRequest) -> Iterator[Rig]:
    fake = FakeController(request.param)
    core = MotionCore(ROBOT)
    events: list[LinkEvent] = []
    link = AdeptLink(core, ROBOT, AdeptSettings(byte_order=request.param, **fake.settings), lambda s: None,
                     events.append, ack_timeout_s=0.5, state_timeout_s=0.3, retry_s=0.1, no_progress_s=0.5)
    yield fake, core, link, events
    link.stop()
    fake.close()


def moving(rig: Rig, j1: float, points: int) -> Motion:
    """The link up and a PTP of joint 1 to ``j1`` under way: more than ``points`` points streamed."""
    fake, core, link, _events = rig
    link.start()
    online(core, link)
    motion, _ = ptp(core, [j1, 0.0, 0.0, 0.0, 0.0, 0.0])
    wait(lambda: len(fake.points) > points, what="points")
    return motion


def test_waiting_then_a_streamed_ptp_that_returns_when_the_robot_is_there(rig: Rig) -> None:
    fake, core, link, events = rig
    port, state_port = fake.settings["motion_port"], fake.settings["state_port"]
    refused = core.execute([[0.0] * 6] * 2, core.dt)
    assert refused.error == f"robot not connected (waiting for simple_message at 127.0.0.1:{port}/{state_port})"
    link.start()
    online(core, link)
    assert core.state().q.tolist() == [0.0] * 6 and link.q_actual == [0.0] * 6
    target = [10.0, -20.0, 15.0, 5.0, 20.0, -30.0]
    motion, samples = ptp(core, target)
    assert motion.wait(20) and motion.ok
    assert motion.final is not None
    assert link.settle(motion.final.q) == ""
    points = fake.points
    assert all(p.comm == 2 for p in points) and fake.pipelined == 0
    # the hold point: where the robot rests, for one period plus the lead
    assert points[0].sequence == 0 and points[0].q.tolist() == [0.0] * 6 and points[0].velocity == 0.0
    assert points[0].duration == pytest.approx(2 * link.period_s)
    # numbered as made: a point whose answer came late is merged into the next one (a busy
    # machine, not an error), and its number is skipped; the wire's numbers only ever rise
    numbers = [p.sequence for p in points[1:-1]]
    assert numbers == sorted(set(numbers)) and numbers[0] >= 1
    assert len(set(range(1, numbers[-1] + 1)) - set(numbers)) <= link.late
    assert points[-1].sequence == -3 and np.allclose(points[-1].q, target, atol=1e-4)
    # the durations add up to the trajectory (plus the hold point's own): the controller's timing is rob6's
    assert sum(p.duration for p in points) == pytest.approx((samples - 1) * core.dt + link.period_s + link.lead_s + core.dt,
                                                            abs=core.dt + 1e-6)
    assert link.period_s == pytest.approx(3 * core.dt)
    for before, point in itertools.pairwise(points):
        step = np.abs(np.degrees(np.subtract(point.joints[:6], before.joints[:6])))
        assert point.velocity == pytest.approx(min(1.0, np.max(step / point.duration / RATED_SPEED_DEG_S)),
                                               rel=1e-3, abs=1e-6)
        assert np.all(point.q >= ROBOT.hw_min) and np.all(point.q <= ROBOT.hw_max)
    assert link.packets == len(points)
    assert [e.event for e in events][:2] == ["waiting", "connected"]


@pytest.mark.parametrize("discard", [False, True])
def test_the_opening_reads_right_whether_the_first_four_bytes_are_discarded_or_not(discard: bool) -> None:
    """The V+ program discards four bytes when a client connects (adept_ros.v2 line 539);
    whether they are the client's cannot be told from the program. Read from its first
    byte the opening is two stops, from its fifth a point where the arm stands (a MOVE that
    goes nowhere); either way the stream that follows is framed right."""
    fake = FakeController(discard=discard)
    core = MotionCore(ROBOT)
    link = AdeptLink(core, ROBOT, AdeptSettings(**fake.settings), lambda s: None, retry_s=0.1)
    try:
        here = [10.0, -20.0, 15.0, 5.0, 20.0, -30.0]
        fake.position = to_wire(here)
        link.start()
        online(core, link)
        if discard:
            assert [p.sequence for p in fake.openings] == [0]
            assert np.allclose(fake.openings[0].q, here, atol=1e-4)
        else:
            assert [p.sequence for p in fake.openings] == [-4, -4]
        motion, _ = ptp(core, [0.0] * 6)
        assert motion.wait(20) and motion.ok
        assert motion.final is not None and link.settle(motion.final.q) == ""
        assert fake.points[0].sequence == 0 and fake.points[-1].sequence == -3
        assert [p.sequence for p in fake.points[1:-1]] == list(range(1, len(fake.points) - 1))
    finally:
        link.stop()
        fake.close()


def test_an_estop_ends_the_motion_and_the_robot_resumes_where_it_stopped(rig: Rig) -> None:
    fake, core, link, events = rig
    motion = moving(rig, 30.0, 10)
    fake.follow = False  # the arm stands where the E-stop caught it
    fake.status.update(e_stopped=1, drives_powered=0)
    assert motion.wait(10)
    assert (motion.ok, motion.error) == (False, "robot reports an E-stop")
    wait(lambda: fake.points[-1].sequence == -4, what="the stop request")  # the controller's queue is dropped
    assert core.execute([core.state().q.tolist()] * 2, core.dt).error == "robot reports an E-stop"
    stood = from_wire(fake.position)
    assert 0.0 < stood[0] < 30.0
    fake.status.update(e_stopped=0)
    wait(lambda: core.offline_reason == "robot reports drives off", what="drives off")
    fake.status.update(drives_powered=1)
    online(core, link)
    assert np.array_equal(core.state().q, stood)  # from where the robot is, not where the motion was
    fake.follow = True
    sent = len(fake.points)
    motion, _ = ptp(core, [0.0] * 6)
    assert motion.wait(20) and motion.ok
    assert motion.final is not None and link.settle(motion.final.q) == ""
    assert np.array_equal(fake.points[sent].q, stood)  # the new stream starts there: no jump
    kinds = [e.event for e in events]
    assert "fault" in kinds and kinds[-1] == "back"


def test_a_controller_error_and_a_refused_point_end_the_motion_with_their_own_words(rig: Rig) -> None:
    fake, core, link, events = rig
    motion = moving(rig, 20.0, 5)
    fake.status.update(error_code=1107, in_error=1)
    assert motion.wait(10) and motion.error == "robot reports controller error 1107"
    fake.status.update(error_code=0, in_error=0)
    online(core, link)
    fake.reply_code = 2  # like adept-sm-sim for a point it cannot move to; STATUS says nothing
    motion, _ = ptp(core, [0.0] * 6)
    assert motion.wait(10) and motion.error == "robot refused a point (reply code 2)"
    assert link.refused >= 1
    fake.reply_code = 1
    online(core, link)  # resynchronized once the robot is at rest
    motion, _ = ptp(core, [0.0] * 6)
    assert motion.wait(20) and motion.ok
    assert motion.final is not None and link.settle(motion.final.q) == ""
    assert "refused" in [e.event for e in events]


def test_no_acknowledgement_is_a_lost_link_that_comes_back(rig: Rig) -> None:
    fake, core, link, events = rig
    link.start()
    online(core, link)
    port = fake.settings["motion_port"]
    fake.ack_delay = 2.0
    motion, _ = ptp(core, [10.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert motion.wait(10)
    assert motion.error == f"simple_message link lost: no acknowledgement from the controller at 127.0.0.1:{port} " \
                           "for 500 ms"
    assert link.state == "lost"
    refused = core.execute([core.state().q.tolist()] * 2, core.dt)
    assert refused.error.startswith("simple_message link lost: ")
    fake.ack_delay = 0.0
    wait(lambda: fake.connections["motion"] == 2, what="a new motion connection")
    online(core, link)
    assert np.allclose(core.state().q, from_wire(fake.position), atol=1e-9)
    motion, _ = ptp(core, [5.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert motion.wait(20) and motion.ok
    assert motion.final is not None and link.settle(motion.final.q) == ""
    assert [e.event for e in events].count("back") >= 1


def test_a_late_acknowledgement_while_the_arm_moves_is_no_lost_link(rig: Rig) -> None:
    """The program answers a point when the MOVE before it has begun: at a low monitor speed
    that is a whole MOVE of the arm, longer than the deadline. While STATUS says the arm is
    in motion, waiting on is right; the motion arrives on the first connection."""
    fake, core, link, events = rig
    link.start()
    online(core, link)
    fake.in_motion = 1
    fake.ack_delay = 1.2  # more than twice the 0.5 s deadline, every time
    motion, _ = ptp(core, [3.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert motion.wait(60) and motion.ok, motion.error
    wait(lambda: fake.points and fake.points[-1].sequence == -3 and link.packets == len(fake.points),
         timeout=30, what="the last point answered")
    fake.in_motion = 0  # the arm at its point
    assert motion.final is not None and link.settle(motion.final.q) == ""
    assert (link.state, link.runs, fake.connections["motion"]) == ("connected", 1, 1)
    assert "lost" not in [e.event for e in events]
    assert link.status().latency_us[2] > 1e6  # the answers did come late


def test_a_silent_state_port_is_a_lost_link(rig: Rig) -> None:
    fake, core, link, events = rig
    link.start()
    online(core, link)
    fake.silent = True
    wait(lambda: core.offline_reason.startswith("simple_message link lost: no state message from the controller "
                                                "at 127.0.0.1:"), what="the link lost")
    assert core.offline_reason.endswith(" for 300 ms")
    fake.silent = False
    online(core, link)
    fake.drop()  # both connections closed by the controller
    wait(lambda: fake.connections == {"motion": 2, "state": 3}, what="both ports connected again")
    online(core, link)
    lost = [e.message for e in events if e.event == "lost"]
    assert any(m.startswith("simple_message link lost: the controller at 127.0.0.1:") and
               m.endswith(" closed the state connection") for m in lost), lost


def test_late_acknowledgements_merge_points_and_keep_the_timing(rig: Rig) -> None:
    fake, core, link, _ = rig
    link.start()
    online(core, link)
    fake.ack_delay = 0.15  # three periods: the points made meanwhile go as one
    motion, samples = ptp(core, [8.0, 0.0, 4.0, 0.0, 0.0, 0.0])
    assert motion.wait(20) and motion.ok
    assert motion.final is not None and link.settle(motion.final.q) == ""
    assert link.late > 0 and len(fake.points) + link.late == link.late + link.packets
    # rob6 slowed its plan to the acknowledgements' pace, and the durations say so
    assert core.held_back_s > 0.5
    assert sum(p.duration for p in fake.points) == pytest.approx(
        (samples - 1) * core.dt + core.held_back_s + link.period_s + link.lead_s + core.dt, abs=core.dt + 1e-6)
    assert link.longest_segment_s <= 2 * link.period_s + 1e-9
    assert np.allclose(fake.points[-1].q, [8.0, 0.0, 4.0, 0.0, 0.0, 0.0], atol=1e-4)


def test_segments_stay_within_their_degrees_when_a_client_raises_the_speed_limits(rig: Rig) -> None:
    """SetJointsMaxSpeed and SetJointsMaxAcceleration up to the protocol's bounds (ten and
    four times the defaults): the core moves several times as far per period, yet no point goes farther than MAX_SEGMENT_DEG on any joint
    from the one before it, late acknowledgements or not (the program runs every MOVE it has
    taken, a stop halts none)."""
    fake, core, link, _ = rig
    link.start()
    online(core, link)
    fastest = [ROBOT.max_accel_bound] * 6
    assert core.set_limits(max_speed=ROBOT.speed_bound, max_accel=fastest) == (True, "")
    config = MotionSettings(ROBOT)
    config.speed, config.accel = list(ROBOT.speed_bound), fastest
    fake.ack_delay = 0.05  # a period: points made meanwhile wait, and may merge
    target = [120.0, -30.0, 40.0, 100.0, -40.0, 180.0]
    motion, _ = ptp(core, target, config)
    assert motion.wait(30) and motion.ok
    assert motion.final is not None and link.settle(motion.final.q) == ""
    assert link.late > 0
    steps = [np.abs(b.q - a.q) for a, b in itertools.pairwise(fake.points)]
    assert np.all(np.max(steps, axis=0) <= MAX_SEGMENT_DEG + 1e-3)
    assert np.max(np.max(steps, axis=0) / MAX_SEGMENT_DEG) >= 0.9  # the bound is what held them
    assert np.allclose(fake.points[-1].q, target, atol=1e-4)


def test_a_robot_that_stops_short_fails_the_motion_and_is_taken_where_it_is(rig: Rig) -> None:
    fake, core, link, _ = rig
    link.start()
    online(core, link)
    fake.follow = False
    motion, _ = ptp(core, [3.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert motion.wait(10) and motion.ok  # the setpoints are done ...
    assert motion.final is not None
    failed = link.settle(motion.final.q)  # ... the robot is not there
    assert failed == "robot stopped short of the target (joint 1 at 0.000, target 3.000)"
    assert core.offline_reason == failed
    online(core, link)
    assert core.state().q.tolist() == [0.0] * 6


def test_motions_beyond_the_arms_range_are_refused_before_anything_is_sent() -> None:
    """The Viper's range in its own joint angles (the URDF's limits: J3 up to 256 deg, rob6's
    169 maps to 259) bounds the core, whatever limits a client sets: a motion leaving it is
    refused before it starts, and the link would not send such a point anyway."""
    config = MotionSettings(ROBOT)
    fake = FakeController()
    core = MotionCore(ROBOT)
    link = AdeptLink(core, ROBOT, AdeptSettings(**fake.settings), lambda s: None, retry_s=0.1)
    try:
        link.start()
        fake.position = to_wire([165.0, 0, 160.0, 0, 0, 0])
        online(core, link)
        # limits wider than the arm's (a client's SetTurnLimits): the core alone would allow 175
        config.turn_min[0], config.turn_max[0] = -200.0, 200.0
        assert core.set_limits(turn_min=config.turn_min, turn_max=config.turn_max)[0]
        assert core.limits().turn_max[0] == 170.0 and core.limits().turn_max[2] == 166.0  # 256 - 90
        for target, joint in (([175.0, 0.0, 160.0, 0.0, 0.0, 0.0], 1), ([165.0, 0.0, 167.0, 0.0, 0.0, 0.0], 3)):
            motion, _ = ptp(core, target, config)
            assert motion.wait(20) and not motion.ok and motion.error == ""
            assert motion.reason.startswith(f"joint {joint} sample ") and motion.reason.endswith(" breaks its turn limits")
        assert fake.points == []
        with link._cond:
            assert link._outside_range(np.array([0.0, 0.0, 166.5, 0.0, 0.0, 0.0])) == (
                "joint 3 at 166.500, range -119 .. 166")
        motion, _ = ptp(core, [160.0, 0.0, 165.5, 0.0, 0.0, 0.0], config)  # inside: it moves
        assert motion.wait(20) and motion.ok
    finally:
        link.stop()
        fake.close()


def test_stopping_the_link_mid_motion_sends_a_stop() -> None:
    fake = FakeController()
    core = MotionCore(ROBOT)
    link = AdeptLink(core, ROBOT, AdeptSettings(**fake.settings), lambda s: None, retry_s=0.1)
    try:
        link.start()
        online(core, link)
        ptp(core, [30.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        wait(lambda: len(fake.points) > 3, what="points")
    finally:
        link.stop()
        fake.close()
    assert fake.points[-1].sequence == -4


def test_only_the_adept_and_sensible_settings() -> None:
    with pytest.raises(ValueError, match=r"drives the Adept Viper s850 \(ad850\), not kr16"):
        AdeptLink(MotionCore("kr16"), get_robot("kr16"), AdeptSettings(), lambda s: None)
    for settings, text in ((AdeptSettings(motion_port=0), "ROB6_SM_MOTION_PORT=0"),
                           (AdeptSettings(byte_order="middle"), "ROB6_SM_BYTE_ORDER='middle'"),
                           (AdeptSettings(period_s=0.0), "ROB6_SM_PERIOD=0.0"),
                           (AdeptSettings(host=" "), "ROB6_SM_HOST is empty"),
                           (AdeptSettings(outputs="1-600"), "ROB6_SM_OUTPUTS='1-600': 1-600 is not a range of V"),
                           (AdeptSettings(outputs="5,x"), "ROB6_SM_OUTPUTS='5,x': expected ranges")):
        with pytest.raises(ValueError, match=text):
            settings.check()
