"""adept-sm-sim against a tiny simple_message client written here from the protocol.

The client packs and unpacks frames by hand (struct, no code of the simulator), so
these tests check the wire format as well as the behaviour. Each behaviour of the
published V+ program the stand-in plays has a test here, named after it, with the
program's lines (``adept_ros.v2`` in BenjaminSchellenbeck/adept_experimental,
``adept_driver/V+/``) as controllers/adept_sm/README.md cites them. Assertions are about
behaviour, never about how fast the (shared, slow) machine is; the only time figures
are lower bounds the simulator must respect whatever the load, and the arm's own clock.
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
    """The motion port: send a point, read its reply. The four bytes the program discards
    on a new connection (line 539) go first, unless ``discarded`` is False."""

    def __init__(self, addr: tuple[str, int], e: str, discarded: bool = True) -> None:
        self.e = e
        self.sock = socket.create_connection(addr, timeout=20)
        if discarded:
            self.sock.sendall(b"\xde\xad\xbe\xef")

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


def task_ended(ctl: AdeptController, task: str) -> dict[str, Any]:
    return ctl.wait_for(lambda s: not s["tasks"][task], what=f"the {task} task ended")


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
    """Lines 576-588: a service request answered at once (JOINT_TRAJ_PT, reply, code 1, one
    int32 0); lines 597-599: then a MOVE to its joints. State port (lines 136-164):
    JOINT_POSITION then STATUS."""
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
        assert st["points_received"] == 3 and st["points_acknowledged"] == 3 and st["moves_issued"] == 3
        assert st["queue_length"] == 0
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
    ctl = AdeptController("--start-pose", "0 0 167 0 0 0")  # the controller's J3 at 257 (URDF: 256)
    with pytest.raises(RuntimeError, match="exited with code 2.*outside the controller range"):
        ctl.start()
    assert ctl.proc is not None and ctl.proc.returncode == 2


@pytest.mark.parametrize("connect_read", ["client", "notice"])
def test_the_first_four_bytes_of_a_connection_are_discarded(connect_read: str) -> None:
    """Line 539: ``ros.read.4bytes`` once before the server loop, its value unused. As the
    client's first bytes (``--connect-read client``, the default) a client must send four
    bytes first, or its first frame is read four bytes off: its reply code taken as the
    comm type, so nothing is answered. As V+'s own (``notice``) nothing of the client's is lost."""
    with AdeptController("--connect-read", connect_read) as ctl:
        if connect_read == "client":
            motion = Motion(ctl.motion, ">")  # four bytes first
            assert motion.point(0, (3, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
            motion.close()
            ctl.wait_for(lambda s: s["tasks"]["motion"] and not s["clients"]["motion"], what="the port free")
            bare = Motion(ctl.motion, ">", discarded=False)
            bare.send(traj_pt(">", 1, (0, 0, 0, 0, 0, 0)))
            bare.sock.settimeout(1.0)
            with pytest.raises(TimeoutError):
                bare.reply()
        else:
            bare = Motion(ctl.motion, ">", discarded=False)
            assert bare.point(0, (3, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        assert ctl.status()["points_acknowledged"] == 1


def test_a_stop_is_answered_and_halts_nothing() -> None:
    """Lines 577-581 and 590-595: a -4 is answered (body -4) and issues no MOVE, but
    nothing halts the arm: the MOVEs already issued run to their end."""
    with moving_sim() as ctl:
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (30, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        assert motion.point(1, (40, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 5, what="J1 under way")
        assert motion.point(-4) == (SUCCESS, -4)
        st = ctl.wait_for(lambda s: not s["in_motion"], what="standstill")
        assert close_to(st["position_rob6_deg"], (40, 0, 0, 0, 0, 0), 1e-4)  # both ran out
        assert st["points_executed"] == 2 and st["moves_issued"] == 2
        assert 0 < st["ran_on_s"]  # on the arm's clock, from the stop's arrival to rest
        # the program goes on reading points
        assert motion.point(2, (0, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 3 and not s["in_motion"])


def test_a_move_returns_when_its_motion_begins_and_the_next_point_is_read_only_then() -> None:
    """V+'s forward processing (V+ Language User's Guide, Motion Control Instructions): a MOVE
    is planned behind the running motion and returns when that one is done; the program
    reads its next point only after MOVE returned (lines 551-602), so that point is answered
    only when the arm has moved on."""
    with moving_sim() as ctl:
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (20, 0, 0, 0, 0, 0)) == (SUCCESS, 0)  # runs at once
        assert motion.point(1, (40, 0, 0, 0, 0, 0)) == (SUCCESS, 0)  # planned behind it: its MOVE holds the program
        motion.send(traj_pt(">", -3, (60, 0, 0, 0, 0, 0)))
        st = ctl.status()
        assert st["queue_length"] == 1 and st["moves_issued"] == 2 and st["points_acknowledged"] == 2
        assert st["points_executed"] == 0
        assert motion.reply() == (SUCCESS, 0)  # once the first motion is done and the second began
        assert ctl.status()["points_executed"] >= 1
        assert ctl.wait_for(lambda s: s["points_executed"] == 3 and not s["in_motion"])["underruns"] == 0


def test_a_late_move_stops_the_arm_at_its_point_then_goes() -> None:
    """Continuous path only while the next MOVE is issued in time: issued after the path
    has ended, the arm comes to rest at the point first (an underrun), then goes."""
    with moving_sim("--state-period", "0.01") as ctl:
        state = State(ctl.state, ">")
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (10, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        assert motion.point(1, (20, 0, 0, 0, 0, 0)) == (SUCCESS, 0)  # in time: blended
        st = ctl.wait_for(lambda s: s["points_executed"] == 2 and not s["in_motion"])
        assert st["underruns"] == 1  # the stream ran dry after point 1 (nothing followed)
        mark = state.count()
        assert motion.point(2, (30, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        state.wait("status", lambda s: s["in_motion"] == 1, since=mark)
        time.sleep(0.05)
        assert motion.point(3, (40, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        st = ctl.wait_for(lambda s: s["points_executed"] == 4 and not s["in_motion"])
        assert close_to(st["position_rob6_deg"], (40, 0, 0, 0, 0, 0), 1e-4)


def test_the_monitor_speed_stretches_time() -> None:
    """SPEED 100 ALWAYS and ACCEL (1) 100, 100 (lines 546-547) plan every MOVE at 100 %; the
    monitor speed s is time scaling (V+ Operating System Reference, SPEED): the same motion,
    every part of it 1/s as long, so speeds fall with s and accelerations with s² (250 deg/s
    and 1000 deg/s² for J1 at 100). A short MOVE, its ramps dominating, lasts 1/s as long on
    the arm's clock; a long one reaches the speed's share, never more."""
    short: dict[float, float] = {}
    for monitor in (100.0, 30.0):
        with AdeptController("--monitor-speed", str(monitor)) as ctl:
            motion = Motion(ctl.motion, ">")
            share = monitor / 100.0
            assert motion.point(0, (2.4, 0, 0, 0, 0, 0), dur=0.01, vel=1.0) == (SUCCESS, 0)  # both ignored
            st = ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"], timeout=30)
            short[monitor] = st["last_motion_s"]
            t0 = time.monotonic()
            assert motion.point(1, (92.4, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
            st = ctl.wait_for(lambda s: s["points_executed"] == 2 and not s["in_motion"], timeout=30)
            assert time.monotonic() - t0 >= 90 / (250 * share)  # never faster than its speed
            assert 0.95 * 250 * share <= st["peak_speed_deg_s"][0] <= 250 * share + 1e-6
            assert 0.9 * 1000 * share**2 <= st["peak_accel_deg_s2"][0] <= 1000 * share**2 + 1e-3
            assert st["longest_segment_s"] == pytest.approx(90 / (250 * share), rel=1e-3)
    # ramps included: at 100 % a 2.4 deg MOVE lasts about 0.1 s, at 30 % 1/0.3 of that
    assert 0.08 <= short[100.0] <= 0.2, short
    assert short[30.0] == pytest.approx(short[100.0] / 0.3, rel=0.05), short


def test_the_acceleration_and_the_minimum_motion_time_are_options() -> None:
    """The two figures a first session measures (deploy/adept/README.md section 6): the
    Viper's acceleration at 100 % (``--accel-time``, seconds to full speed) and V+'s shortest
    joint motion (``--min-move-s``). A short MOVE, all ramps, lasts √2 as long with half the
    acceleration, and never less than the minimum (on the arm's clock)."""
    lasted: dict[tuple[str, ...], float] = {}
    for options in ((), ("--accel-time", "0.5"), ("--min-move-s", "0.4")):
        with AdeptController(*options) as ctl:
            motion = Motion(ctl.motion, ">")
            assert motion.point(0, (2.4, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
            st = ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"], timeout=30)
            lasted[options] = st["last_motion_s"]
            if options == ("--accel-time", "0.5"):
                assert st["peak_accel_deg_s2"][0] <= 250 / 0.5 + 1e-3
    assert lasted[("--accel-time", "0.5")] == pytest.approx(math.sqrt(2) * lasted[()], rel=0.1), lasted
    assert lasted[("--min-move-s", "0.4")] >= 0.4, lasted


def test_a_lower_monitor_speed_takes_effect_at_once_mid_motion() -> None:
    """The monitor speed changed on the pendant applies at once (V+ Operating System
    Reference, SPEED: "takes effect immediately"), also to the motion under way."""
    with AdeptController("--monitor-speed", "100", "--state-period", "0.02") as ctl:
        state = State(ctl.state, ">")
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (150, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        state.wait("joints", lambda j: j[0] < math.radians(-20))  # the controller's J1 is -q1
        ctl.monitor_speed(5)
        mark = state.count()
        st = ctl.status()
        assert st["monitor_speed"] == 5.0 and st["in_motion"]
        # at 5 % J1 moves at most 12.5 deg/s: the arm is far from its point a second later
        state.wait("joints", lambda _j: True, since=mark)
        # a quiet window of a negative check, not a wait for something to happen: at 5 % the
        # 130 deg left take over ten seconds, so a correct stand-in is still moving a second
        # later, at the slow pace, on any machine; one that ignored the change has arrived
        time.sleep(1.0)
        later = ctl.status()
        assert later["in_motion"] and later["points_executed"] == 0
        assert abs(later["velocity_controller_deg_s"][0]) <= 250 * 0.05 + 1e-6
        ctl.monitor_speed(100)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"], timeout=30)


def test_a_point_the_arm_cannot_reach_is_answered_then_its_move_ends_the_task() -> None:
    """The program has no failure reply (lines 584-586: code 1 for every point) and no error
    handler: MOVE to a point outside a joint range, or to no number, is a V+ error that ends
    the motion task and closes its connection; task.controll (lines 192-201) starts it again."""
    with AdeptController("--restart-s", "0.3") as ctl:
        for seq, q, rad in ((0, (0, 0, 167, 0, 0, 0), None),  # the controller's J3 at 257 (URDF: 256)
                            (1, (0, 0, 0, 0, 0, 0), [0, math.radians(50), math.radians(90), 0, 0, 0]),
                            (2, (0, 0, 0, 0, 0, 0), [float("nan"), 0, math.radians(90), 0, 0, 0])):
            ctl.wait_for(lambda s: s["tasks"]["motion"], what="the motion task running")
            motion = Motion(ctl.motion, ">")
            assert motion.point(seq, q, rad=rad) == (SUCCESS, 0)
            assert closed_by_peer(motion.sock)
            st = task_ended(ctl, "motion")
            assert st["position_rob6_deg"] == [0.0] * 6 and not st["in_motion"]
            refused = socket.create_connection(ctl.motion, timeout=10)  # nobody serves the port meanwhile
            assert closed_by_peer(refused)
        st = ctl.wait_for(lambda s: s["tasks"]["motion"], what="the motion task restarted")
        assert st["task_errors"] == 3 and st["points_acknowledged"] == 3 and st["moves_issued"] == 0
        motion = Motion(ctl.motion, ">")  # just inside the range is fine
        assert motion.point(3, (0, 45, 166, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"])


def test_estop_mid_motion_brakes_the_arm_and_the_next_move_ends_the_task() -> None:
    with moving_sim() as ctl:
        state = State(ctl.state, ">")
        motion = Motion(ctl.motion, ">")
        assert motion.point(0, (150, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] > 5, what="J1 under way")
        mark = state.count()
        ctl.estop()
        st = state.wait("status", lambda s: s["e_stopped"] == 1, since=mark)
        assert st["drives_powered"] == 0
        st = ctl.wait_for(lambda s: not s["in_motion"], what="standstill")
        assert st["e_stopped"] and not st["drives_powered"] and st["queue_length"] == 0
        stopped_at = st["position_rob6_deg"]
        assert 5 < stopped_at[0] < 140
        assert motion.point(1, (0, 0, 0, 0, 0, 0)) == (SUCCESS, 0)  # answered, then MOVE fails
        assert closed_by_peer(motion.sock)
        task_ended(ctl, "motion")
        ctl.release()
        assert ctl.request({"cmd": "drives", "on": True})["ok"]
        assert ctl.status()["position_rob6_deg"] == stopped_at
        ctl.wait_for(lambda s: s["tasks"]["motion"], what="the motion task restarted")
        motion = Motion(ctl.motion, ">")
        assert motion.point(2, (0, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"])


def test_drives_cannot_come_on_during_an_estop(sim: AdeptController) -> None:
    sim.estop()
    reply = sim.request({"cmd": "drives", "on": True})
    assert not reply["ok"] and "e-stop" in reply["error"]


def test_drives_off_while_a_move_waits_ends_the_task() -> None:
    with moving_sim() as ctl:
        motion = Motion(ctl.motion, ">")
        for seq, j1 in enumerate((-150, -140)):  # the second holds the program in its MOVE
            assert motion.point(seq, (j1, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["position_rob6_deg"][0] < -5, what="J1 under way")
        ctl.drives(False)
        assert closed_by_peer(motion.sock)
        st = ctl.wait_for(lambda s: not s["in_motion"], what="standstill")
        assert -140 < st["position_rob6_deg"][0] < -5 and st["task_errors"] == 1


def test_status_every_period_only_with_the_fields_the_program_fills() -> None:
    """Lines 136-164 and 327-371: a STATUS after each JOINT_POSITION, then WAIT.EVENT 0.1 s;
    nothing between (a fault shows with the next one). error_code and in_error are never
    set, motion_possible is "not in motion", mode 2 (AUTO)."""
    with AdeptController() as ctl:
        state = State(ctl.state, ">")
        state.wait("status", lambda s: True)
        ctl.drives(False)
        mark = state.count()
        st = state.wait("status", lambda s: s["drives_powered"] == 0, since=mark)
        assert (st["error_code"], st["in_error"], st["motion_possible"], st["mode"]) == (0, 0, 1, 2)
        state.wait("status", lambda s: True, since=state.count())
        with state.lock:
            times = [t for t, kind, _ in state.frames if kind == "status"]
        assert all(b - a >= 0.09 for a, b in zip(times, times[1:], strict=False))
        assert len(times) >= 3


def test_a_dropped_connection_ends_the_task_which_is_restarted(sim: AdeptController) -> None:
    motion = Motion(sim.motion, ">")
    state = State(sim.state, ">")
    state.wait("joints", lambda j: True)
    sim.wait_for(lambda s: s["clients"]["motion"], what="the motion client taken")
    assert sim.drop_connection("motion") is True
    assert closed_by_peer(motion.sock)
    task_ended(sim, "motion")
    assert sim.drop_connection("motion") is False  # nobody connected now
    sim.wait_for(lambda s: s["tasks"]["motion"], what="the motion task restarted")
    motion = Motion(sim.motion, ">")
    assert motion.point(0, (5, 0, 0, 0, 0, 0)) == (SUCCESS, 0)
    assert sim.drop_connection("state") is True
    assert closed_by_peer(state.sock)
    task_ended(sim, "state")
    sim.wait_for(lambda s: s["tasks"]["state"], what="the state task restarted")
    state = State(sim.state, ">")
    state.wait("joints", lambda j: True)
    assert sim.status()["clients"] == {"motion": True, "state": True, "io": 0}


def test_a_second_client_is_refused_and_the_first_keeps_working(sim: AdeptController) -> None:
    """``/CLIENTS 1`` on the motion and state ports (lines 128 and 530)."""
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
    # once it leaves, its task ends and is restarted, and the port takes a new client
    s1.close()
    sim.wait_for(lambda s: not s["clients"]["state"] and s["tasks"]["state"], what="state client gone")
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


def test_records_of_fixed_length_whatever_a_frame_says() -> None:
    """Lines 558-573 read 68 bytes per point and check neither the length nor the message
    type: a 64-byte request of another type is a point like any other, and a shorter frame
    shifts everything after it, so joints are read from the wrong bytes (here the next
    frame's header: the controller's zero angles, a motion of its own)."""
    e = ">"
    with moving_sim() as ctl:
        motion = Motion(ctl.motion, e)
        motion.send(frame(e, 99, REQUEST, 0, struct.pack(e + "i10fff", 0, *to_controller_rad((5, 0, 0, 0, 0, 0)),
                                                         0, 0, 0, 0, 0.0, 0.0)))
        assert motion.reply() == (SUCCESS, 0)
        st = ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"])
        assert close_to(st["position_rob6_deg"], (5, 0, 0, 0, 0, 0), 1e-4)
        motion.send(frame(e, JOINT_TRAJ_PT, REQUEST, 0, struct.pack(e + "ii", 7, 0)))  # 20 bytes, not 68
        motion.send(traj_pt(e, 8, (10, 0, 0, 0, 0, 0)))
        assert motion.reply() == (SUCCESS, 0)  # the short frame's record, completed by the next one
        st = ctl.wait_for(lambda s: s["points_executed"] == 2 and not s["in_motion"])
        assert close_to(st["position_controller_deg"], (0, 0, 0, 0, 0, 0), 1e-3)  # not (-10, 0, 90, ...)
        assert st["points_received"] == 2


def test_topic_points_are_executed_without_a_reply(sim: AdeptController) -> None:
    """Only a service request is answered (line 576), but every record is a MOVE (line 597),
    and a stop is answered also as a topic (lines 590-595)."""
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
    motion.send(traj_pt(e, -4, comm=TOPIC))
    assert motion.reply() == (SUCCESS, -4)


def test_duration_and_velocity_are_ignored() -> None:
    """Lines 570-573 read them; nothing uses them: a 10 deg move given 30 s is over long before."""
    with AdeptController() as ctl:
        motion = Motion(ctl.motion, ">")
        t0 = time.monotonic()
        assert motion.point(0, (10, 0, 0, 0, 0, 0), dur=30.0, vel=0.01) == (SUCCESS, 0)
        ctl.wait_for(lambda s: s["points_executed"] == 1 and not s["in_motion"], timeout=15)
        assert time.monotonic() - t0 < 15


def test_control_channel_rejects_bad_requests_and_stays_up(sim: AdeptController) -> None:
    reply = sim.request("this is not json")
    assert reply["ok"] is False and "JSON" in reply["error"]
    assert sim.request("[1, 2]")["ok"] is False
    reply = sim.request({"cmd": "fly"})
    assert reply["ok"] is False and "unknown cmd" in reply["error"]
    assert sim.request({"cmd": "drives"})["ok"] is False
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
    """Lines 447-472: SIG(n) answered -1 or 0, SIGNAL(n) answered 1 (``/N``: no line end)."""
    assert sim.io is not None
    io = socket.create_connection(sim.io, timeout=10)
    assert io_ask(io, 1, 5) == "0"
    assert io_ask(io, 2, 5) == "1"
    assert io_ask(io, 1, 5) == "-1"  # V+ TRUE
    assert io_ask(io, 0, -6) == "1"  # any mode but 1 writes
    assert io_ask(io, 2, 2001) == "1"  # a software signal
    assert io_ask(io, 1, 1003) == "0"  # an installed input can be read
    assert sim.status()["outputs"] == [5, -6, 2001]
    assert io_ask(io, 2, -5) == "1"
    assert io_ask(io, 1, 5) == "0"
    st = sim.status()
    assert st["outputs"] == [-5, -6, 2001] and st["io_requests"] == 8 and st["clients"]["io"] == 1
    io.close()


@pytest.mark.parametrize("mode, number", [(2, 9), (2, 1001), (1, 97)])
def test_a_signal_the_controller_lacks_ends_the_io_task_for_good(sim: AdeptController, mode: int, number: int) -> None:
    """SIGNAL or SIG of a signal that is not installed (or SIGNAL of an input) is a V+ error
    (lines 463, 470); ``ros.io`` has no handler and nothing restarts task 4 (a.ros line 34
    starts it once, task.controll restarts tasks 0 and 1 only): nothing is answered any more."""
    assert sim.io is not None
    io = socket.create_connection(sim.io, timeout=10)
    assert io_ask(io, 2, 5) == "1"
    io.sendall(struct.pack(">i", mode))
    time.sleep(0.1)
    io.sendall(struct.pack(">i", number))
    assert not task_ended(sim, "io")["tasks"]["io"]
    io.settimeout(0.5)
    with pytest.raises(TimeoutError):
        io_ask(io, 2, 6)
    other = socket.create_connection(sim.io, timeout=10)
    other.settimeout(0.5)
    with pytest.raises(TimeoutError):
        io_ask(other, 2, 6)
    assert sim.status()["outputs"] == [5]


def test_io_port_reads_one_record_per_number_like_v_plus(sim: AdeptController) -> None:
    """Both numbers in one write are one record: the program takes the mode from its first
    four bytes, loses the rest and reads the number from the next record (lines 450-458);
    a record shorter than LNGB's four bytes is a V+ error that ends the task."""
    assert sim.io is not None
    io = socket.create_connection(sim.io, timeout=10)
    io.sendall(struct.pack(">ii", 2, 7))  # mode and number at once: 7 is lost
    time.sleep(0.1)
    io.sendall(struct.pack(">i", 8))  # taken as the number
    assert io.recv(64) == b"1"
    assert sim.status()["outputs"] == [8]
    io.sendall(b"\x00\x00")
    st = task_ended(sim, "io")
    assert st["io_errors"] == 1 and st["outputs"] == [8]


def test_a_port_in_use_is_a_clear_error() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        ctl = AdeptController("--motion-port", str(busy.getsockname()[1]))
        with pytest.raises(RuntimeError, match="exited with code 1.*cannot listen.*in use"):
            ctl.start()
