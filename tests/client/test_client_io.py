"""Robot and AsyncRobot against a scripted stand-in of the original rob6server.

The stand-in behaves the way rob6 does *not*: each recv() is one message, every reply line
goes out in its own send() some milliseconds after the previous one, `false` after an
error may come late, commands with missing replies leave the client waiting. Every
scenario runs with both the blocking and the asyncio client.
"""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractAsyncContextManager
from typing import Any

import pytest
from pytest import FixtureRequest

from rob6_client import AsyncRobot, Rob6ConnectionError, Rob6Error, Rob6ProtocolError, Rob6Timeout, Robot

GREETING = "welcome to rob6server 0.1.01 !"
HOME = "0.0 0.0 0.0 0.0 0.0 0.0"
FK_LINES = ["0.000000 -0.000000 -1.000000 1768.000000 0.000000 -1.000000 0.000000 -0.000000 "
            "-1.000000 -0.000000 -0.000000 640.000000", "noflip up lefty"]


#: message -> reply lines (a float is a pause in seconds, None silence, "CLOSE" hangs up)
Script = dict[str, list[str | float | None]]


class FakeOriginal:
    """Serves one session from a script: message -> reply lines (a float is a pause in
    seconds, None is silence). Unscripted messages get the original's `ERROR: <message>`."""

    def __init__(self, script: Script, *, greeting: str | None = GREETING, accept: bool = True,
                 line_gap: float = 0.03) -> None:
        self.script = script
        self.greeting, self.accept, self.line_gap = greeting, accept, line_gap
        self.messages: list[str] = []  # what each recv() brought, as the original saw it
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        conn, _ = self.server.accept()
        with conn:
            if self.greeting is not None:
                conn.sendall(self.greeting.encode() + b"\n")
            handshake = True
            while data := conn.recv(1024):
                message = data.decode("latin-1")
                self.messages.append(message)
                if handshake:
                    handshake = False
                    conn.sendall(b"accepted\n" if self.accept else b"failed\n")
                    if not self.accept:
                        return
                    continue
                for item in self.script.get(message.rstrip("\n"), [f"ERROR: {message.rstrip()}"]):
                    if item is None:
                        break
                    if item == "CLOSE":
                        return
                    if isinstance(item, float):
                        time.sleep(item)
                        continue
                    time.sleep(self.line_gap)  # the original writes line by line
                    conn.sendall(item.encode("latin-1") + b"\n")

    def commands(self) -> list[str]:
        return self.messages[1:]  # after the handshake

    def close(self) -> None:
        self.server.close()


class BlockingTwin:
    """An AsyncRobot driven from blocking test code, so one scenario tests both clients."""

    def __init__(self, host: str, port: int, **kwargs: float) -> None:
        self.loop = asyncio.new_event_loop()
        self.robot = AsyncRobot(host, port, **kwargs)
        try:
            self.loop.run_until_complete(self.robot.connect())
        except BaseException:
            self.loop.close()
            raise

    def __getattr__(self, name: str) -> Any:  # any AsyncRobot attribute, its methods made blocking
        attr = getattr(self.robot, name)
        if not callable(attr):
            return attr
        return lambda *args, **kwargs: self.loop.run_until_complete(attr(*args, **kwargs))

    def alter(self, *, adept: bool = False, timeout: float | None = None) -> _SyncAlter:
        return _SyncAlter(self.loop, self.robot.alter(adept=adept, timeout=timeout))


class _SyncAlter:
    def __init__(self, loop: asyncio.AbstractEventLoop, manager: AbstractAsyncContextManager[AsyncRobot]) -> None:
        self.loop, self.manager = loop, manager

    def __enter__(self) -> AsyncRobot:
        return self.loop.run_until_complete(self.manager.__aenter__())

    def __exit__(self, *exc: Any) -> bool | None:
        return self.loop.run_until_complete(self.manager.__aexit__(*exc))


#: the fixture: connect(script, **options) -> (a client, sync or async, and its fake server)
Connect = Callable[..., tuple["Robot | BlockingTwin", FakeOriginal]]


@pytest.fixture(params=["sync", "async"])
def connect(request: FixtureRequest) -> Iterator[Connect]:
    servers: list[FakeOriginal] = []
    robots: list[Robot | BlockingTwin] = []

    def connect(script: Script | None = None, **kwargs: Any) -> tuple[Robot | BlockingTwin, FakeOriginal]:
        server_options = {k: kwargs.pop(k) for k in ("greeting", "accept", "line_gap") if k in kwargs}
        server = FakeOriginal(script or {}, **server_options)
        servers.append(server)
        robot = (Robot if request.param == "sync" else BlockingTwin)("127.0.0.1", server.port, **kwargs)
        robots.append(robot)
        return robot, server

    yield connect
    for robot in robots:
        robot.close()
        if isinstance(robot, BlockingTwin):
            robot.loop.close()
    for server in servers:
        server.close()


def test_multi_line_replies_arriving_line_by_line(connect: Connect) -> None:
    robot, server = connect({"ForwardCalc 0.0 0.0 0.0 0.0 0.0 0.0": FK_LINES, "GetRobot": ["kr16"]},
                            line_gap=0.05)
    fk = robot.forward_calc([0, 0, 0, 0, 0, 0])
    assert fk is not None
    pose, status = fk
    assert pose.position == (1768.0, -0.0, 640.0) and str(status) == "noflip up lefty"
    assert robot.get_robot() == "kr16"
    # one command per write, the next only after the reply: the original runs one per read
    assert server.commands() == ["ForwardCalc 0.0 0.0 0.0 0.0 0.0 0.0\n", "GetRobot\n"]


def test_parse_error_with_a_late_false_keeps_the_session_in_step(connect: Connect) -> None:
    robot, _ = connect({f"MovePTPJoints {HOME}": ["ERROR: incorrect joints", 0.2, "false"],
                        "GetRobot": ["kr16"]})
    with pytest.raises(Rob6Error) as caught:
        robot.move_ptp_joints([0] * 6)
    assert (caught.value.command, caught.value.message) == ("MovePTPJoints", "incorrect joints")
    assert robot.get_robot() == "kr16"


def test_error_without_false_does_not_wait(connect: Connect) -> None:
    """rob6's `ERROR: <service> unavailable` has no `false` line after it."""
    robot, _ = connect({"GetPositionJoints": ["ERROR: driver unavailable"], "GetRobot": ["kr16"]})
    began = time.monotonic()
    with pytest.raises(Rob6Error, match="driver unavailable"):
        robot.get_position_joints()
    assert time.monotonic() - began < 1.0
    assert robot.get_robot() == "kr16"


def test_gripper_reply_lines_before_true(connect: Connect) -> None:
    robot, _ = connect({"GripperMove -1.0": ["Start moving with amperage -1.000", "true"],
                        "GripperGoHome": ["ERROR: gripper blocked", "false"], "HasGripper": ["true"]})
    assert robot.gripper_move(-1) is True
    with pytest.raises(Rob6Error, match="gripper blocked"):
        robot.gripper_go_home()
    assert robot.has_gripper() is True


def test_set_allowed_status_learns_the_silent_outcome_from_a_ping(connect: Connect) -> None:
    robot, server = connect({"SetAllowedStatus noflip up toggleArm": [None], "CM_PING": ["PONG"],
                             "SetAllowedStatus flip down righty": ["ERROR: incorrect status"],
                             "GetAllowedStatus": ["noflip up toggleArm"]})
    assert robot.set_allowed_status("up noflip") is None
    assert robot.get_allowed_status() == ("noflip", "up", "toggleArm")
    with pytest.raises(Rob6Error, match="incorrect status"):
        robot.set_allowed_status(["flip", "down", "righty"])
    assert robot.cm_ping() == "PONG"
    assert server.commands() == ["SetAllowedStatus noflip up toggleArm\n", "CM_PING\n", "GetAllowedStatus\n",
                                 "SetAllowedStatus flip down righty\n", "CM_PING\n", "CM_PING\n"]


def test_no_reply_times_out_and_closes_the_connection(connect: Connect) -> None:
    robot, _ = connect({f"MovePTPJoints {HOME}": [None]}, timeout=5.0)
    began = time.monotonic()
    with pytest.raises(Rob6Timeout) as caught:
        robot.move_ptp_joints([0] * 6, timeout=0.3)
    assert 0.3 <= time.monotonic() - began < 2.0
    assert isinstance(caught.value, TimeoutError) and isinstance(caught.value, ConnectionError)
    assert not robot.connected
    with pytest.raises(Rob6ConnectionError, match="closed"):
        robot.get_robot()


def test_default_timeouts_short_for_queries_long_for_moves(connect: Connect) -> None:
    robot, _ = connect({"GetRobot": [0.5, "kr16"], f"MovePTPJoints {HOME}": [0.5, "true"]},
                       timeout=0.3, move_timeout=2.0)
    assert robot.move_ptp_joints([0] * 6) is True  # move_timeout
    with pytest.raises(Rob6Timeout, match="GetRobot"):
        robot.get_robot()  # timeout


def test_server_closing_mid_reply(connect: Connect) -> None:
    robot, _ = connect({"ForwardCalc 0.0 0.0 0.0 0.0 0.0 0.0": [FK_LINES[0], "CLOSE"]})
    with pytest.raises(Rob6ConnectionError, match="closed the connection"):
        robot.forward_calc([0] * 6)
    assert not robot.connected


def test_unintelligible_reply_closes_the_connection(connect: Connect) -> None:
    robot, _ = connect({"GetPositionJoints": ["1 2 3"]})
    with pytest.raises(Rob6ProtocolError, match="unexpected reply '1 2 3'"):
        robot.get_position_joints()
    assert not robot.connected


def test_bad_arguments_are_refused_before_anything_is_sent(connect: Connect) -> None:
    """The original would wait for missing arguments and swallow the next command."""
    robot, server = connect({"GetRobot": ["kr16"]})
    with pytest.raises(ValueError, match="expected 6 numbers, got 5"):
        robot.move_ptp_joints([0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="finite"):
        robot.forward_calc([float("nan"), 0, 0, 0, 0, 0])
    with pytest.raises(TypeError):
        robot.move_ptp_joints("10 0 0 0 0 0")  # type: ignore[arg-type]  # the wrong type on purpose
    with pytest.raises(ValueError, match="unknown status word 'Noflip'"):
        robot.backward_calc([0] * 12, "Noflip up lefty")
    with pytest.raises(ValueError, match="one category"):
        robot.backward_calc([0] * 12, "flip noflip")
    with pytest.raises(ValueError, match="12 numbers"):
        robot.move_ptp_hom_row_wise([0] * 11)
    with pytest.raises(TypeError):
        robot.set_single_joint_max_speed(1.5, 0.1)  # type: ignore[arg-type]  # a joint index is an int
    with pytest.raises(ValueError, match="single line"):
        robot.direct_adept_cmd("jmove 0\nQuit")
    with pytest.raises(TypeError):
        robot.set_verbosity()  # type: ignore[call-arg]  # no command without its arguments
    assert robot.get_robot() == "kr16"
    assert server.commands() == ["GetRobot\n"]


def test_no_greeting_means_another_client_is_connected(connect: Connect) -> None:
    with pytest.raises(Rob6ConnectionError, match="no greeting"):
        connect(greeting=None, connect_timeout=0.3)


def test_busy_server_and_failed_handshake(connect: Connect) -> None:
    with pytest.raises(Rob6ConnectionError, match="server busy"):
        connect(greeting="ERROR: server busy, another client is connected")
    with pytest.raises(Rob6ConnectionError, match="handshake failed"):
        connect(accept=False)


def test_quit_on_close(connect: Connect) -> None:
    robot, server = connect({"Quit": ["bye!", "CLOSE"]})
    assert robot.greeting == GREETING
    robot.close()
    robot.close()
    assert not robot.connected and server.commands() == ["Quit\n"]


def test_alter_is_disabled_even_when_the_block_fails(connect: Connect) -> None:
    robot, server = connect({"EnableAlter": ["true"], "DisableAlter": ["true"],
                             f"MoveRTJoints {HOME}": ["true"], "EnableAdeptAlter": ["false"]})
    with pytest.raises(KeyError), robot.alter():
        assert robot.move_rt_joints([0] * 6) is True
        raise KeyError("the client's own bug")
    assert server.commands()[-1] == "DisableAlter\n"
    with pytest.raises(Rob6Error, match="refused"), robot.alter(adept=True):
        pass
    assert server.commands()[-1] == "EnableAdeptAlter\n"


def test_connection_refused() -> None:
    port = socket.create_server(("127.0.0.1", 0))
    free = port.getsockname()[1]
    port.close()
    with pytest.raises(Rob6ConnectionError, match="cannot connect"):
        Robot("127.0.0.1", free)
    with pytest.raises(Rob6ConnectionError, match="cannot connect"):
        asyncio.run(AsyncRobot("127.0.0.1", free).connect())
