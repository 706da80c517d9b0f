"""kawasaki-as-sim executing deploy/kawasaki/rob6.as, over real TCP with lines written by hand
here (no rob6 code): the hello and the state at 10 Hz or more, the queue (a motion starts at
three points or a final one), a final point reached exactly and not before its time,
underruns, cancel, every answer code, a full queue, one client at a time, an idle client
kept, a client that closes and one that is dropped, E-stop / motor power / teach mode and
the operator's EXECUTE, and the control channel's errors. What the program keeps is read
as an operator would, with TYPE. Time is asserted as a lower bound (the arm is never faster
than the wall clock), once as a generous upper bound (the state's rate)."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.controllers.kawasaki_controller import KawasakiController
from tests.motion.link_session import wait_until

pytestmark = pytest.mark.slow

ZERO = "0.000 90.000 0.000 0.000 0.000 0.000"  # rob6's zero, the controller's joints
HELLO = "H rob6-kas 3 64"


class Client:
    """A client on the program's port (hello, answers) and its state port (states)."""

    def __init__(self, addr: tuple[str, int], state_addr: tuple[str, int] | None = None) -> None:
        self.sock = socket.create_connection(addr, timeout=10)
        self.state_sock = socket.create_connection(state_addr, timeout=10) if state_addr else None
        self.buffers: dict[socket.socket, bytes] = {}
        self.states: list[list[str]] = []

    def _line(self, sock: socket.socket, timeout: float) -> str:
        sock.settimeout(timeout)
        buffer = self.buffers.get(sock, b"")
        while b"\n" not in buffer:
            data = sock.recv(4096)
            if not data:
                raise ConnectionError("closed")
            buffer += data
        line, _, self.buffers[sock] = buffer.partition(b"\n")
        return line.decode()

    def line(self, timeout: float = 10.0) -> str:
        return self._line(self.sock, timeout)

    def answer(self) -> list[str]:
        """The next A line (its fields)."""
        fields = self.line().split()
        assert fields[0] == "A", fields
        return fields

    def state(self) -> list[str]:
        assert self.state_sock is not None, "no state connection"
        fields = self._line(self.state_sock, 10.0).split()
        assert fields[0] == "S", fields
        self.states.append(fields)
        return fields

    def send(self, text: str) -> list[str]:
        self.sock.sendall(text.encode() + b"\n")
        return self.answer()

    def close(self) -> None:
        self.sock.close()
        if self.state_sock is not None:
            self.state_sock.close()


@pytest.fixture
def sim() -> Iterator[KawasakiController]:
    with KawasakiController() as ctl:
        yield ctl


@pytest.fixture
def client(sim: KawasakiController) -> Iterator[Client]:
    c = Client(sim.port, sim.state_port)
    assert c.line() == HELLO
    yield c
    c.close()


def point(n: int, jt1: float, ms: int, final: bool = False) -> str:
    return f"P {n} {jt1:.3f} 90.000 0.000 0.000 0.000 0.000 {ms} {int(final)}"


def test_hello_and_the_state_at_ten_hertz_or_more(client: Client) -> None:
    first = client.state()
    began = time.monotonic()
    for _ in range(10):
        last = client.state()
    assert len(first) == 16 and first[2:8] == ZERO.split(" ")
    assert first[8:] == ["1", "0", "0", "0", "0", "0", "0", "1"]  # motor on, repeat, at rest, nothing queued, running
    assert int(last[1]) == int(first[1]) + 10  # numbered, none left out
    # ten states every 50 ms take 0.5 s; 5 s leaves a loaded machine ten times that and still
    # catches a state sent at 2 Hz or slower
    assert time.monotonic() - began < 5.0


def test_a_motion_starts_at_three_points_and_ends_exactly_on_the_final_one(sim: KawasakiController,
                                                                          client: Client) -> None:
    assert client.send(point(1, 10, 500)) == ["A", "1", "0", "1"]
    assert client.send(point(2, 15, 250)) == ["A", "2", "0", "2"]
    time.sleep(0.3)  # two blended points never start (whatever the wait): the program waits for a third
    assert sim.status()["position_ctrl_deg"][0] == 0.0
    began = time.monotonic()
    assert client.send(point(3, 20, 250, final=True)) == ["A", "3", "0", "3"]
    wait_until(lambda: sim.type("kdone") == 3 and not sim.status()["moving"], what="the final point")
    assert time.monotonic() - began >= 0.95  # 500 + 250 + 250 ms: never sooner
    st = sim.status()
    assert st["position_ctrl_deg"] == [20.0, 90.0, 0.0, 0.0, 0.0, 0.0]
    assert st["position_rob6_deg"] == [20.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert sim.type("kunder") == 0 and st["max_speed_ratio"] <= 1.0
    wait_until(lambda: client.state()[8:15] == ["1", "0", "0", "0", "3", "0", "0"], what="a state at rest, done 3")


def test_a_queue_that_runs_dry_before_a_final_point_is_an_underrun(sim: KawasakiController, client: Client) -> None:
    for n in (1, 2, 3):
        client.send(point(n, 2 * n, 100))
    wait_until(lambda: sim.type("kunder") == 1 and not sim.status()["moving"], what="the arm to stop at point 3")
    assert sim.status()["position_ctrl_deg"][0] == pytest.approx(6.0, abs=1e-6)
    assert client.send(point(4, 7, 100, final=True))[2] == "0"  # a final point alone starts
    # kdone is the point the program took, before its JMOVE starts the arm from rest: wait for the arm there
    wait_until(lambda: not (st := sim.status())["moving"] and st["position_ctrl_deg"][0] == 7.0,
               what="the arm to stop on point 4")
    assert sim.type("kdone") == 4 and sim.type("kunder") == 1


def test_a_point_is_in_time_while_the_motions_planned_still_run(sim: KawasakiController, client: Client) -> None:
    """The program takes a point one motion ahead of the arm: once point 3 is planned (point 2
    under way) the queue is empty, yet the arm has two seconds of path left; a point sent
    then is in time, no underrun, no stop."""
    for n in (1, 2, 3):
        assert client.send(point(n, 2 * n, 1000))[2] == "0"
    wait_until(lambda: sim.type("kout") == 3, what="point 3 planned")
    assert client.send(point(4, 8, 1000, final=True))[2] == "0"
    wait_until(lambda: sim.type("kdone") == 4 and not sim.status()["moving"], what="the final point")
    assert sim.status()["position_ctrl_deg"][0] == 8.0 and sim.type("kunder") == 0


def test_cancel_drops_the_queue_and_the_arm_stops_after_the_motion_under_way(sim: KawasakiController,
                                                                            client: Client) -> None:
    for n in range(1, 11):
        assert client.send(point(n, n * 3, 200, final=n == 10))[2] == "0"
    wait_until(lambda: sim.type("kdone") >= 1, what="the first point")
    assert client.send("C 11") == ["A", "11", "0", "0"]
    wait_until(lambda: not sim.status()["moving"], what="the arm to stop")
    done = sim.type("kdone")
    assert sim.queued() == 0 and done < 10 and sim.type("kunder") == 0
    assert sim.status()["position_ctrl_deg"][0] == pytest.approx(3.0 * done, abs=1e-6)


@pytest.mark.parametrize("line, code", [
    ("P 1 0 90 0 0 0 0 48", "1"),  # a field short
    ("P 1 0 90 0 0 0 0 48 0 7", "1"),  # a field too many
    ("P 1 0 90 0 0 0 x 48 0", "1"),  # not a number
    ("P 1 0 90 0 0 0 1x 48 0", "1"),  # not only a number
    ("P 1 0 90 0 0 0 1e1 48 0", "1"),  # no exponents
    ("P 1 0 90 0 0 0 0 0 0", "1"),  # no time
    ("P 1 0 90 0 0 0 0 48.5 0", "1"),  # whole milliseconds
    ("P 1 0 90 0 0 0 0 48 2", "1"),  # flag
    ("P 1.5 0 90 0 0 0 0 48 0", "1"),  # sequence
    ("Q 1", "1"),  # unknown type
    ("C 1 2", "1"),  # a cancel has one field
    ("P 1 0 90 0 0 0 0 48 0\r", "0"),  # a CR before the LF is no part of the line
    ("P 1 0  90  0 0 0 0 48 0", "0"),  # runs of spaces separate fields as one
    ("P 1 0 151 0 0 0 0 48 0", "2"),  # JT2 beyond +150
    ("P 1 0 90 -151 0 0 0 48 0", "2"),  # JT3 below -150
    ("P 1 0 90 121 0 0 0 48 0", "2"),  # JT3 beyond +120
    ("P 1 20 90 0 0 0 0 48 0", "3"),  # JT1 20 deg in 48 ms: 417 deg/s, rated 360
])
def test_what_the_program_answers(sim: KawasakiController, client: Client, line: str, code: str) -> None:
    # the answer carries the line's sequence number, read first: 0 only when it is not one
    readable = not line.startswith("P 1.5")
    assert client.send(line)[:3] == ["A", "1" if readable else "0", code]
    assert sim.status()["position_ctrl_deg"] == [0.0, 90.0, 0.0, 0.0, 0.0, 0.0]


def test_lines_too_long_and_sequence_numbers(sim: KawasakiController, client: Client) -> None:
    assert client.send("P 2 " + "0" * 130)[:3] == ["A", "0", "1"]  # a line over 120 characters, with its LF
    assert client.send("P 5 1.000 90.000 0.000 0.000 0.000 0.000 1000 0")[2] == "0"
    assert client.send("P 5 2.000 90.000 0.000 0.000 0.000 0.000 1000 0")[2] == "6"  # not above 5
    assert client.send("C 4")[2] == "6"
    client.sock.sendall(b"P 6 " + b"1" * 200)  # no line end within a line's length: not rob6
    with pytest.raises((ConnectionError, OSError)):
        while True:
            client.line()
    assert sim.status()["answers"] == {"0": 1, "1": 1, "6": 2}
    again = Client(sim.port)
    assert again.line() == HELLO  # the program serves the next client
    again.close()


def test_a_full_queue_refuses(sim: KawasakiController, client: Client) -> None:
    """64 points: three start the motion, one more is planned ahead; the queue then holds 64."""
    answers = [client.send(point(n, n * 0.01, 5000)) for n in range(1, 70)]
    codes = [a[2] for a in answers]
    assert "5" in codes and codes.index("5") >= 64 and set(codes[:64]) == {"0"}
    full = answers[codes.index("5")]
    assert full[3] == "64"
    assert sim.status()["answers"]["5"] == codes.count("5")


def test_one_client_at_a_time_and_a_dropped_connection(sim: KawasakiController, client: Client) -> None:
    second = Client(sim.port)  # waits in the backlog while the program serves the first
    with pytest.raises(TimeoutError):
        second.line(timeout=1.5)
    for n in range(1, 11):
        client.send(point(n, n * 5, 400, final=n == 10))
    wait_until(lambda: sim.status()["moving"], what="the motion")
    assert sim.drop_connection()
    with pytest.raises((ConnectionError, OSError)):
        while True:
            client.line()
    wait_until(lambda: not sim.status()["moving"], what="the arm to stop")
    done = sim.type("kdone")
    assert sim.queued() == 0 and done < 10  # the queue went with the client
    assert sim.status()["position_ctrl_deg"][0] == pytest.approx(5.0 * done, abs=1e-6)
    assert second.line() == HELLO  # then the program accepts the next
    here = sim.status()["position_ctrl_deg"][0]
    assert second.send(point(1, here, 100, final=True))[2] == "0"
    second.close()


def test_an_idle_client_is_kept_and_one_that_closes_is_replaced(sim: KawasakiController, client: Client) -> None:
    """Ten seconds without a line (ten receive timeouts of 1 s) keep the connection and the
    queue; a client that closes is noticed, its queue dropped, and the next one served."""
    assert client.send(point(1, 5, 1000)) == ["A", "1", "0", "1"]
    began = time.monotonic()
    while time.monotonic() - began < 10.0:
        client.state()
    assert client.send(point(2, 6, 1000)) == ["A", "2", "0", "2"]  # still the same connection
    assert (sim.status()["connections"], sim.status()["state_connections"]) == (1, 1)
    client.close()
    wait_until(lambda: sim.queued() == 0, what="the program to notice the client closed")
    again = Client(sim.port)
    assert again.line() == HELLO
    assert again.send(point(1, 1, 1000)) == ["A", "1", "0", "1"]  # a new connection counts anew
    assert (sim.status()["connections"], sim.status()["state_connections"]) == (2, 1)
    again.close()


def test_estop_brakes_refuses_and_wants_the_motor_on_and_the_program_started(sim: KawasakiController,
                                                                            client: Client) -> None:
    client.send(point(1, 30, 2000))
    client.send(point(2, 60, 2000, final=True))
    wait_until(lambda: sim.status()["position_ctrl_deg"][0] > 3.0, what="the arm to move")
    sim.estop()
    wait_until(lambda: not sim.status()["moving"], what="the arm to brake")
    st = sim.status()
    assert 3.0 < st["position_ctrl_deg"][0] < 60.0 and sim.queued() == 0
    assert (st["estop"], st["motor"], st["tasks"]["robot"]) == (True, False, "aborted: E-stop")
    assert client.send(point(3, 10, 2000, final=True))[2] == "4"
    wait_until(lambda: client.state()[8] == "0", what="a state with the motor power off")
    assert sim.request({"cmd": "motor", "on": True}) == {
        "ok": False, "error": "motor power cannot come on during an E-stop"}
    assert sim.request({"cmd": "execute"}) == {"ok": False, "error": "motor power is OFF."}
    sim.release()
    assert client.send(point(4, 10, 2000, final=True))[2] == "4"  # motor still off
    sim.motor(True)
    sim.execute()
    here = sim.status()["position_ctrl_deg"][0]
    assert client.send(point(5, here + 1, 100, final=True))[2] == "0"
    wait_until(lambda: sim.status()["position_ctrl_deg"][0] == pytest.approx(here + 1, abs=1e-3),
               what="the restarted program to move")


def test_teach_mode_stops_and_refuses(sim: KawasakiController, client: Client) -> None:
    client.send(point(1, 30, 2000, final=True))
    wait_until(lambda: sim.status()["moving"], what="the motion")
    sim.teach(True)
    wait_until(lambda: not sim.status()["moving"], what="the arm to stop")
    st = sim.status()
    assert st["teach"] and st["position_ctrl_deg"][0] < 30.0
    assert client.send(point(2, 1, 2000, final=True))[2] == "4"
    # the states sent before the switch wait unread on the state connection: the first in teach mode
    taught = wait_until(lambda: s if (s := client.state())[9] == "1" else None, what="a state in teach mode")
    assert (taught[11], taught[15]) == ("0", "0")  # the queue dropped, rob6_motion not running
    assert sim.request({"cmd": "execute"}) == {"ok": False, "error": "program in TEACH mode."}


@pytest.mark.parametrize("request_, error", [
    ("not json", "not JSON: Expecting value: line 1 column 1 (char 0)"),
    ('{"cmd": "fly"}', "unknown command 'fly'"),
    ('{"cmd": "motor"}', "motor: 'on' must be true or false"),
    ('{"cmd": "error", "code": -1}', "error: 'code' must be a positive integer"),
    ('{"cmd": "slow_ack", "ms": "x"}', "slow_ack: 'ms' must be a number >= 0"),
    ('{"cmd": "monitor_speed", "percent": 0}', "monitor_speed: 'percent' must be 1..100"),
    ('{"cmd": "type", "expr": "nosuch"}', "(E0102) Variable is not defined: nosuch"),
    ('{"cmd": "execute", "program": 1}', "execute: 'program' must be a program's name"),
    ("[1]", "expected a JSON object with a string 'cmd'"),
])
def test_the_control_channel_says_what_is_wrong(sim: KawasakiController, request_: str, error: str) -> None:
    assert sim.request(request_) == {"ok": False, "error": error}


def test_a_start_pose_outside_the_range_is_refused_in_one_line() -> None:
    with pytest.raises(RuntimeError, match="exited with code 2"):
        KawasakiController("--start-pose", "0 0 -130 0 0 0").start()


def test_a_program_the_controller_cannot_load_is_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad.as"
    bad.write_text(".PROGRAM rob6_pc()\n  TCP_LISTEN ret\n.END\n")
    ctl = KawasakiController("--program", str(bad))
    with pytest.raises(RuntimeError, match="exited with code 3") as exc:
        ctl.start()
    assert "line 2: TCP_LISTEN: wrong arguments" in str(exc.value)
