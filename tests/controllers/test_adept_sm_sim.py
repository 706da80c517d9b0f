"""adept-sm-sim against a tiny simple_message client written here from the protocol.

The client packs and unpacks frames by hand (struct, no code of the simulator), so
these tests check the wire format as well as the behaviour. Assertions are about
behaviour, never about how fast the (shared, slow) machine is; the only time figures
are lower bounds the simulator must respect whatever the load.
"""

from __future__ import annotations

import math
import signal
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import pytest
from pytest import FixtureRequest

from tests.controllers.adept_controller import AdeptController

ORDER = {"big": ">", "little": "<"}
JOINT_POSITION, JOINT_TRAJ_PT, STATUS = 10, 11, 13
TOPIC, REQUEST, REPLY = 1, 2, 3
SUCCESS, FAILURE = 1, 2
STATUS_FIELDS = ("drives_powered", "e_stopped", "error_code", "in_error", "in_motion", "mode",
                 "motion_possible")


def to_controller_rad(q_rob6_deg: Sequence[float]) -> list[float]:
    """rob6 joints (deg) -> the controller's joints on the wire (rad), as documented in
    deploy/adept/README.md: (-q1, q2, q3 + 90, -q4, q5, -q6)."""
    q1, q2, q3, q4, q5, q6 = q_rob6_deg
    return [math.radians(x) for x in (-q1, q2, q3 + 90.0, -q4, q5, -q6)]


def frame(e: str, msg_type: int, comm: int, reply: int, body: bytes) -> bytes:
    header = struct.pack(e + "3i", msg_type, comm, reply)
    return struct.pack(e + "i", 12 + len(body)) + header + body


def traj_pt(e: str, seq: int, q_rob6_deg: Sequence[float] = (0, 0, 0, 0, 0, 0), vel: float = 0.5, dur: float = 0.0,
            comm: int = REQUEST, rad: Sequence[float] | None = None) -> bytes:
    joints = list(rad if rad is not None else to_controller_rad(q_rob6_deg)) + [0.0] * 4
    return frame(e, JOINT_TRAJ_PT, comm, 0, struct.pack(e + "i10fff", seq, *joints, vel, dur))


def recv_exact(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        if not chunk:
            raise ConnectionError("closed by the controller")
        data += chunk
    return data


def read_frame(sock: socket.socket, e: str) -> tuple[int, int, int, int, bytes]:
    length: int
    msg_type: int
    comm: int
    reply: int
    (length,) = struct.unpack(e + "i", recv_exact(sock, 4))
    payload = recv_exact(sock, length)
    msg_type, comm, reply = struct.unpack_from(e + "3i", payload)
    return length, msg_type, comm, reply, payload[12:]


def closed_by_peer(sock: socket.socket, timeout: float = 10.0) -> bool:
    sock.settimeout(timeout)
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True


class Motion:
    """The motion port: send a point, read its reply."""

    def __init__(self, addr: tuple[str, int], e: str) -> None:
        self.e = e
        self.sock = socket.create_connection(addr, timeout=20)

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def reply(self) -> tuple[int, int]:
        length, msg_type, comm, code, body = read_frame(self.sock, self.e)
        assert (length, msg_type, comm) == (16, JOINT_TRAJ_PT, REPLY), (length, msg_type, comm)
        seq: int
        (seq,) = struct.unpack(self.e + "i", body)
        return code, seq

    def point(self, seq: int, q_rob6_deg: Sequence[float] = (0, 0, 0, 0, 0, 0), **kw: Any) -> tuple[int, int]:
        self.send(traj_pt(self.e, seq, q_rob6_deg, **kw))
        return self.reply()

    def close(self) -> None:
        self.sock.close()


class State:
    """The state port, read in the background: every JOINT_POSITION and STATUS."""

    def __init__(self, addr: tuple[str, int], e: str) -> None:
        self.e = e
        self.sock = socket.create_connection(addr, timeout=20)
        self.frames: list[tuple[float, str, tuple[float, ...] | dict[str, int]]] = []
        self.lock = threading.Lock()
        self.error: Exception | None = None
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        try:
            while True:
                length, msg_type, comm, reply, body = read_frame(self.sock, self.e)
                assert comm == TOPIC and reply == 0, (comm, reply)
                item: tuple[str, tuple[float, ...] | dict[str, int]]
                if msg_type == JOINT_POSITION:
                    assert length == 56
                    seq, *joints = struct.unpack(self.e + "i10f", body)
                    item = ("joints", tuple(joints))
                elif msg_type == STATUS:
                    assert length == 40
                    item = ("status", dict(zip(STATUS_FIELDS, struct.unpack(self.e + "7i", body), strict=True)))
                else:
                    raise AssertionError(f"unexpected message type {msg_type} on the state port")
                with self.lock:
                    self.frames.append((time.monotonic(), *item))
        except Exception as exc:  # whatever it is: reported by wait()
            self.error = exc

    def count(self) -> int:
        with self.lock:
            return len(self.frames)

    def wait(self, kind: str, pred: Callable[[Any], object], since: int = 0, timeout: float = 15.0) -> Any:
        """The first frame of this kind from index `since` on that satisfies pred."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                for _, k, value in self.frames[since:]:
                    if k == kind and pred(value):
                        return value
            if self.error is not None and not isinstance(self.error, ConnectionError):
                raise self.error
            time.sleep(0.01)
        raise AssertionError(f"no {kind} frame matching within {timeout} s (error: {self.error})")

    def close(self) -> None:
        self.sock.close()


def close_to(a: Sequence[float], b: Sequence[float], tol: float) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


@pytest.fixture
def sim(request: FixtureRequest) -> Iterator[AdeptController]:
    args = getattr(request, "param", ())
    with AdeptController("--state-period", "0.02", *args) as ctl:
        yield ctl


def moving_sim(*extra: str) -> AdeptController:
    # J1 at 10 % monitor speed: 25 deg/s, so a long move leaves time to interfere
    return AdeptController("--state-period", "0.02", "--monitor-speed", "10", *extra)


# ---------------------------------------------------------------------------------


def test_ready_line_and_clean_exit_on_sigterm_and_sigint() -> None:
    for sig in (signal.SIGTERM, signal.SIGINT):
        ctl = AdeptController().start()
        assert ctl.motion is not None and ctl.state is not None and ctl.control is not None and ctl.proc is not None
        assert ctl.motion[1] > 0 and ctl.state[1] > 0 and ctl.control[1] > 0
        assert ctl.io is not None and ctl.io[1] > 0
        # with clients connected and a motion under way
        motion, state = Motion(ctl.motion, ">"), State(ctl.state, ">")
        assert motion.point(0, (90, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.proc.send_signal(sig)
        assert ctl.proc.wait(10) == 0
        ctl.stop()
        assert ctl.stderr_lines[-1] == "adept-sm-sim: stopped"
        assert not [line for line in ctl.stderr_lines if "Traceback" in line]
        assert closed_by_peer(motion.sock) and closed_by_peer(state.sock)


@pytest.mark.parametrize("byte_order", ["big", "little"])
def test_streamed_points_are_acknowledged_and_executed(byte_order: str) -> None:
    e = ORDER[byte_order]
    targets = [(10, -10, 20, 5, 10, -15), (20, -20, 30, 10, 20, -30), (25, -15, 35, 0, 30, -45)]
    with AdeptController("--state-period", "0.02", byte_order=byte_order) as ctl:
        state = State(ctl.state, e)
        motion = Motion(ctl.motion, e)
        first = state.wait("joints", lambda j: True)
        assert close_to(first[:6], to_controller_rad((0, 0, 0, 0, 0, 0)), 1e-6)
        assert first[6:] == (0.0,) * 4
        state.wait("status", lambda s: s["in_motion"] == 0 and s["drives_powered"] == 1
                   and s["e_stopped"] == 0 and s["mode"] == 2 and s["motion_possible"] == 1)
        mark = state.count()
        for seq, q in zip((0, 1, -3), targets, strict=True):
            assert motion.point(seq, q) == (SUCCESS, 0)
        state.wait("status", lambda s: s["in_motion"] == 1, since=mark)
        st = ctl.wait_for(lambda s: s["points_executed"] == 3 and not s["in_motion"],
                          what="three points executed")
        assert st["points_received"] == 3 and st["points_acknowledged"] == 3
        assert st["underruns"] == 0 and st["queue_length"] == 0
        assert close_to(st["position_rob6_deg"], targets[-1], 1e-4)
        assert st["ack_latency_ms"]["count"] == 3
        mark = state.count()
        state.wait("status", lambda s: s["in_motion"] == 0, since=mark)
        final = state.wait("joints", lambda j: True, since=mark)
        assert close_to(final[:6], to_controller_rad(targets[-1]), 1e-5)
        motion.close()
        state.close()


def test_start_pose_follows_the_documented_joint_convention() -> None:
    with AdeptController("--start-pose", "10,-20,30,40,50,60") as ctl:
        st = ctl.status()
        assert close_to(st["position_controller_deg"], (-10, -20, 120, -40, 50, -60), 1e-9)
        assert close_to(st["position_rob6_deg"], (10, -20, 30, 40, 50, 60), 1e-9)
        state = State(ctl.state, ">")
        joints = state.wait("joints", lambda j: True)
        assert close_to(joints[:6], to_controller_rad((10, -20, 30, 40, 50, 60)), 1e-6)
        state.close()


def test_start_pose_outside_the_limits_is_refused() -> None:
    ctl = AdeptController("--start-pose", "0 0 200 0 0 0")
    with pytest.raises(RuntimeError, match="exited with code 2.*outside the controller range"):
        ctl.start()
    assert ctl.proc is not None and ctl.proc.returncode == 2


def test_stop_decelerates_and_clears_the_queue() -> None:
    with moving_sim() as ctl:
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (150, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        assert motion.point(1, (0, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 5, what="J1 under way")
        assert ctl.status()["queue_length"] == 1
        assert motion.point(-4) == (SUCCESS, -4)
        st = ctl.wait_for(lambda s: not s["in_motion"], what="standstill")
        assert 5 < st["position_rob6_deg"][0] < 140
        assert st["queue_length"] == 0 and st["points_executed"] == 0
        time.sleep(0.3)  # and it stays where it stopped
        assert ctl.status()["position_rob6_deg"] == st["position_rob6_deg"]
        # the next trajectory is accepted as usual
        assert motion.point(2, (0, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"])


def test_point_outside_a_joint_limit_is_refused_and_does_not_move(sim: AdeptController) -> None:
    motion = Motion(sim.motion, ">")
    # rob6 q3 = 180 is 270 deg on the controller's J3 (range -29..259)
    assert motion.point(0, (0, 0, 180, 0, 0, 0)) == (FAILURE, 0)
    # a controller J2 of 50 deg (range -190..45), given straight in radians
    assert motion.point(1, rad=[0, math.radians(50), math.radians(90), 0, 0, 0]) == (FAILURE, 0)
    assert motion.point(2, rad=[float("nan"), 0, math.radians(90), 0, 0, 0]) == (FAILURE, 0)
    st = sim.status()
    assert st["points_refused"] == 3 and st["points_acknowledged"] == 0
    assert st["position_rob6_deg"] == [0.0] * 6 and not st["in_motion"]
    assert st["queue_length"] == 0 and st["points_executed"] == 0
    # just inside the limits is fine
    assert motion.point(3, (0, 45, 169, 0, 0, 0)) == (SUCCESS, 0)
    sim.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"])


def test_estop_mid_motion_stops_the_arm_and_refuses_points_until_released() -> None:
    with moving_sim() as ctl:
        state = State(ctl.state, ">")
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (150, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        assert motion.point(1, (150, -30, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 5, what="J1 under way")
        mark = state.count()
        ctl.estop()
        st = state.wait("status", lambda s: s["e_stopped"] == 1, since=mark)
        assert st["drives_powered"] == 0 and st["motion_possible"] == 0
        state.wait("status", lambda s: s["in_motion"] == 0, since=mark)
        st = ctl.status()
        assert st["e_stopped"] and not st["drives_powered"] and st["queue_length"] == 0
        stopped_at = st["position_rob6_deg"]
        assert 5 < stopped_at[0] < 140
        assert motion.point(2, (0, 0, 0, 0, 0, 0)) == (FAILURE, 0)
        ctl.release()
        assert motion.point(3, (0, 0, 0, 0, 0, 0)) == (FAILURE, 0)  # drives still off
        assert ctl.request({"cmd": "drives", "on": True})["ok"]
        assert ctl.status()["position_rob6_deg"] == stopped_at
        state.wait("status", lambda s: s["e_stopped"] == 0 and s["drives_powered"] == 1,
                   since=mark)
        assert motion.point(4, (0, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"])


def test_drives_cannot_come_on_during_an_estop(sim: AdeptController) -> None:
    sim.estop()
    reply = sim.request({"cmd": "drives", "on": True})
    assert not reply["ok"] and "e-stop" in reply["error"]


def test_drives_off_mid_motion() -> None:
    with moving_sim() as ctl:
        state = State(ctl.state, ">")
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (-150, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] < -5, what="J1 under way")
        mark = state.count()
        ctl.drives(False)
        st = state.wait("status", lambda s: s["drives_powered"] == 0, since=mark)
        assert st["e_stopped"] == 0 and st["motion_possible"] == 0
        st = ctl.wait_for(lambda s: not s["in_motion"], what="standstill")
        assert -140 < st["position_rob6_deg"][0] < -5
        assert motion.point(1, (0, 0, 0, 0, 0, 0)) == (FAILURE, 0)
        ctl.drives(True)
        assert motion.point(2, (0, 0, 0, 0, 0, 0)) == (SUCCESS, 0)


def test_status_is_sent_at_once_on_a_fault_not_only_every_period() -> None:
    with AdeptController("--state-period", "60") as ctl:
        state = State(ctl.state, ">")
        state.wait("status", lambda s: True)  # the one sent on connection
        mark = state.count()
        ctl.estop()
        # the next periodic STATUS is 60 s away
        state.wait("status", lambda s: s["e_stopped"] == 1, since=mark, timeout=10)


def test_injected_error_is_reported_and_refuses_points(sim: AdeptController) -> None:
    state = State(sim.state, ">")
    motion = Motion(sim.motion, ">")
    sim.error(-1021)
    st = state.wait("status", lambda s: s["in_error"] == 1)
    assert st["error_code"] == -1021 and st["motion_possible"] == 0
    assert sim.status()["error_code"] == -1021
    assert motion.point(0, (10, 0, 0, 0, 0, 0)) == (FAILURE, 0)
    sim.clear_error()
    mark = state.count()
    state.wait("status", lambda s: s["in_error"] == 0 and s["error_code"] == 0, since=mark)
    assert motion.point(1, (10, 0, 0, 0, 0, 0)) == (SUCCESS, 0)


def test_vplus_status_fields_send_what_the_v_plus_program_sends() -> None:
    with AdeptController("--state-period", "0.02", "--status-fields", "vplus") as ctl:
        state = State(ctl.state, ">")
        ctl.error(-1021)
        ctl.drives(False)
        mark = state.count()
        st = state.wait("status", lambda s: s["drives_powered"] == 0, since=mark)
        # no error reporting, motion_possible is just "not in motion"
        assert st["error_code"] == 0 and st["in_error"] == 0 and st["motion_possible"] == 1
        assert ctl.status()["error_code"] == -1021


def test_a_dropped_connection_is_accepted_again(sim: AdeptController) -> None:
    motion = Motion(sim.motion, ">")
    state = State(sim.state, ">")
    state.wait("joints", lambda j: True)
    sim.wait_for(lambda s: s["clients"]["motion"], what="the motion client taken")
    assert sim.drop_connection("motion") is True
    assert closed_by_peer(motion.sock)
    assert sim.drop_connection("motion") is False  # nobody connected now
    motion = Motion(sim.motion, ">")
    assert motion.point(0, (5, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    assert sim.drop_connection("state") is True
    assert closed_by_peer(state.sock)
    state = State(sim.state, ">")
    state.wait("joints", lambda j: True)
    assert sim.status()["clients"] == {"motion": True, "state": True, "io": 0}


def test_a_second_client_is_refused_and_the_first_keeps_working(sim: AdeptController) -> None:
    first = Motion(sim.motion, ">")
    assert first.point(0, (1, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    second = socket.create_connection(sim.motion, timeout=10)
    assert closed_by_peer(second)
    assert first.point(1, (2, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    s1 = State(sim.state, ">")
    s1.wait("joints", lambda j: True)
    s2 = socket.create_connection(sim.state, timeout=10)
    assert closed_by_peer(s2)
    # the first state client goes on receiving
    mark = s1.count()
    s1.wait("joints", lambda j: True, since=mark)
    # once it leaves, the port takes a new client
    s1.close()
    sim.wait_for(lambda s: not s["clients"]["state"], what="state client gone")
    s3 = State(sim.state, ">")
    s3.wait("joints", lambda j: True)


def test_slow_ack_delays_every_acknowledgement(sim: AdeptController) -> None:
    motion = Motion(sim.motion, ">")
    sim.slow_ack(300)
    t0 = time.monotonic()
    assert motion.point(0, (3, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    assert time.monotonic() - t0 >= 0.3
    assert sim.status()["ack_latency_ms"]["max"] >= 300
    sim.slow_ack(0)
    assert sim.status()["slow_ack_ms"] == 0


def test_malformed_frames_close_the_connection_or_fail_and_never_crash(sim: AdeptController) -> None:
    e = ">"
    # a request of the right size but another message type: failure reply, still connected
    motion = Motion(sim.motion, e)
    motion.send(frame(e, 99, REQUEST, 0, b"\0" * 52))
    assert motion.reply() == (FAILURE, 0)
    # a topic of another type: ignored; the next real point is answered
    motion.send(frame(e, JOINT_POSITION, TOPIC, 0, b"\0" * 52))
    assert motion.point(0, (1, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    # a wrong length: the V+ program would lose its framing; the simulator hangs up
    motion.send(frame(e, JOINT_TRAJ_PT, REQUEST, 0, b"\0" * 8))
    assert closed_by_peer(motion.sock)
    for length in (0, -5, 0x7FFFFFFF):
        m = Motion(sim.motion, e)
        m.send(struct.pack(e + "i", length))
        assert closed_by_peer(m.sock)
    # half a frame, then gone
    m = Motion(sim.motion, e)
    m.send(traj_pt(e, 7)[:30])
    sim.wait_for(lambda s: s["clients"]["motion"], what="the half-frame client taken")
    m.close()
    st = sim.wait_for(lambda s: not s["clients"]["motion"], what="the half-frame client gone")
    assert st["malformed_frames"] == 6
    assert st["points_received"] == 1 and st["points_executed"] <= 1
    assert sim.proc is not None and sim.proc.poll() is None
    assert Motion(sim.motion, e).point(1, (2, 0, 0, 0, 0, 0)) == (SUCCESS, 0)


def test_underrun_counted_when_the_stream_runs_dry_but_not_after_the_end(sim: AdeptController) -> None:
    motion = Motion(sim.motion, ">")
    assert motion.point(0, (5, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    sim.wait_for(lambda s: s["points_executed"] == 1, what="first point")
    assert sim.wait_for(lambda s: s["underruns"] == 1)["underruns"] == 1
    assert motion.point(1, (10, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    assert motion.point(-3, (15, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    st = sim.wait_for(lambda s: s["points_executed"] == 3 and not s["in_motion"])
    assert st["underruns"] == 1 or st["underruns"] == 2  # 2 if point 1 itself came late
    time.sleep(0.2)
    assert sim.status()["underruns"] == st["underruns"]  # the -3 ended the trajectory


def test_topic_points_are_executed_without_a_reply(sim: AdeptController) -> None:
    e = ">"
    motion = Motion(sim.motion, e)
    motion.send(traj_pt(e, -1, (5, 0, 0, 0, 0, 0), comm=TOPIC))
    motion.send(traj_pt(e, 1, (10, 0, 0, 0, 0, 0), comm=TOPIC))
    motion.send(traj_pt(e, -3, (15, 0, 0, 0, 0, 0), comm=TOPIC))
    # the first thing to come back is the reply to this request
    assert motion.point(5, (20, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    st = sim.wait_for(lambda s: s["points_executed"] == 4 and not s["in_motion"])
    assert st["points_received"] == 4 and st["points_acknowledged"] == 1
    assert close_to(st["position_rob6_deg"], (20, 0, 0, 0, 0, 0), 1e-4)
    # a stop is answered even as a topic, as the V+ program does
    motion.send(traj_pt(e, -4, comm=TOPIC))
    assert motion.reply() == (SUCCESS, -4)


def test_duration_is_ignored_like_v_plus_unless_asked_for() -> None:
    # V+ moves at SPEED 100: a 10 deg move given 30 s is over long before that
    with AdeptController() as ctl:
        motion = Motion(ctl.motion, ">")
        t0 = time.monotonic()
        assert motion.point(0, (10, 0, 0, 0, 0, 0), dur=30.0) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"], timeout=15)
        assert time.monotonic() - t0 < 15
    with AdeptController("--timing", "duration") as ctl:
        motion = Motion(ctl.motion, ">")
        t0 = time.monotonic()
        assert motion.point(0, (10, 0, 0, 0, 0, 0), dur=1.5) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"])
        assert time.monotonic() - t0 >= 1.5
        # neither a duration nor a velocity: nothing to time the move by
        assert motion.point(1, (0, 0, 0, 0, 0, 0), vel=0.0, dur=0.0) == (FAILURE, 0)
        assert motion.point(2, (0, 0, 0, 0, 0, 0), dur=float("inf")) == (FAILURE, 0)


def test_control_channel_rejects_bad_requests_and_stays_up(sim: AdeptController) -> None:
    reply = sim.request("this is not json")
    assert reply["ok"] is False and "JSON" in reply["error"]
    assert sim.request("[1, 2]")["ok"] is False
    reply = sim.request({"cmd": "fly"})
    assert reply["ok"] is False and "unknown cmd" in reply["error"]
    assert sim.request({"cmd": "drives"})["ok"] is False
    assert sim.request({"cmd": "error", "code": 0})["ok"] is False
    assert sim.request({"cmd": "drop_connection", "port": "x"})["ok"] is False
    assert sim.request({"cmd": "slow_ack", "ms": -1})["ok"] is False
    assert sim.status()["ok"] is True
    assert sim.request({"cmd": "quit"}) == {"ok": True}
    assert sim.proc is not None and sim.proc.wait(10) == 0


def io_ask(io: socket.socket, mode: int, number: int) -> str:
    """One request as the V+ program needs it: the mode and the number as two records (the
    ROS node pauses 1/socket_rate = 0.1 s between them), then its answer."""
    io.sendall(struct.pack(">i", mode))
    time.sleep(0.1)
    io.sendall(struct.pack(">i", number))
    return io.recv(64).decode()


def test_io_port_reads_and_writes_signals(sim: AdeptController) -> None:
    assert sim.io is not None
    io = socket.create_connection(sim.io, timeout=10)
    assert io_ask(io, 1, 5) == "0"
    assert io_ask(io, 2, 5) == "1"
    assert io_ask(io, 1, 5) == "-1"  # V+ TRUE
    assert io_ask(io, 0, -6) == "1"  # any mode but 1 writes
    assert io_ask(io, 2, 2001) == "1"  # a software signal
    assert sim.status()["outputs"] == [5, -6, 2001]
    assert io_ask(io, 2, -5) == "1"
    assert io_ask(io, 1, 5) == "0"
    assert io_ask(io, 2, 1001) == "0"  # an input cannot be written
    st = sim.status()
    assert st["outputs"] == [-5, -6, 2001] and st["io_requests"] == 8 and st["clients"]["io"] == 1
    io.close()


def test_io_port_reads_one_record_per_number_like_v_plus(sim: AdeptController) -> None:
    """Both numbers in one write are one record: the program takes the mode from its first
    four bytes, loses the rest and reads the number from the next record."""
    assert sim.io is not None
    io = socket.create_connection(sim.io, timeout=10)
    io.sendall(struct.pack(">ii", 2, 7))  # mode and number at once: 7 is lost
    time.sleep(0.1)
    io.sendall(struct.pack(">i", 8))  # taken as the number
    assert io.recv(64) == b"1"
    assert sim.status()["outputs"] == [8]
    io.sendall(b"\x00\x00")  # a record shorter than LNGB's four bytes ends the connection
    assert closed_by_peer(io)
    st = sim.status()
    assert st["io_errors"] == 1 and st["clients"]["io"] == 0 and st["outputs"] == [8]


def test_a_port_in_use_is_a_clear_error() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        ctl = AdeptController("--motion-port", str(busy.getsockname()[1]))
        with pytest.raises(RuntimeError, match="exited with code 1.*cannot listen.*in use"):
            ctl.start()
