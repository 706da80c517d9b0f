"""Helpers for the recording tests: a sample URDF, a scripted session, a fake
rob6 TCP server (asyncio, in a thread) answering from a dict or a transcript."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from typing import Any

from rob6_recorder.writer import Recorder

URDF = """<?xml version="1.0"?>
<robot name="mini6">
  <link name="base_link"/><link name="link1"/><link name="link2"/><link name="flange"/>
  <joint name="a1" type="revolute"><parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.675"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="a2" type="revolute"><parent link="link1"/><child link="link2"/>
    <origin xyz="0.26 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="link2"/><child link="flange"/>
    <origin xyz="0.68 0 0"/></joint>
</robot>
"""

GREETING = "welcome to rob6server 0.1.01 !\n"

#: command line -> reply of the fake kr16 (what the scripted session recorded)
REPLIES = {
    "Hello Robot\n": "accepted\n",
    "GetRobot\n": "kr16\n",
    "GetVersion\n": "0.1.01\n",
    "ForwardCalc 10 0 0 0 0 0\n": (
        "0.000000 -0.173648 -0.984808 1741.140107 0.000000 -0.984808 0.173648 -307.009978 "
        "-1.000000 -0.000000 -0.000000 640.000000\nnoflip up lefty\n"),
    "SetAllowedStatus flip toggleElbow toggleArm\n": "",
    "MovePTPJoints 5 -5 5 5 5 5\n": "true\n",
    "MovePTPJoints 0 20 0 0 0 0\n": "false\n",
    "GetPositionJoints\n": "5.000000 -5.000000 5.000000 5.000000 5.000000 5.000000\n",
    "Foo\n": "ERROR: Foo\n",
    "ForwardCalc x\n": "false\n",
    "MovePTPJoints 1 2 3\n": "ERROR: incorrect joints\nfalse\n",
    "GetTimestamp\n": "1795321511.114\n",
    "\n": "",
    "Quit\n": "bye!\n",
}

#: the session the tests record: every line with its reply, in order
SESSION_LINES = [
    "Hello Robot\n", "GetRobot\n", "GetVersion\n", "ForwardCalc 10 0 0 0 0 0\n",
    "SetAllowedStatus flip toggleElbow toggleArm\n", "MovePTPJoints 5 -5 5 5 5 5\n",
    "GetPositionJoints\n", "MovePTPJoints 0 20 0 0 0 0\n", "Foo\n", "ForwardCalc x\n",
    "MovePTPJoints 1 2 3\n", "GetTimestamp\n", "\n", "GetRobot\n", "Quit\n",
]


#: one record as submitted to the recorder: topic, log time (ns), payload
Submitted = tuple[str, int, dict[str, Any]]


def record_session(rec: Recorder, session: int = 3, t0: int | None = None, step_ns: int = 20_000_000,
                   joint_states_per_line: int = 2) -> list[Submitted]:
    """Feed ``rec`` (a Recorder) a scripted client session; return what was submitted."""
    t = time.time_ns() if t0 is None else t0
    submitted: list[Submitted] = []

    def put(topic: str, data: dict[str, Any]) -> None:
        nonlocal t
        t += step_ns // 4
        assert rec.submit(topic, t, data)
        submitted.append((topic, t, data))

    put(f"/session/{session}/event", {"session": session, "event": "open", "peer": "127.0.0.1:5555"})
    put(f"/session/{session}/client_out", {"session": session, "cid": "", "text": GREETING,
                                          "kind": "greeting"})
    cycle = 0
    for i, line in enumerate(SESSION_LINES):
        cid = f"c{i:03d}"
        put(f"/session/{session}/client_in", {"session": session, "cid": cid, "text": line})
        word = line.split()[0] if line.split() else ""
        if word.startswith("Move"):
            put("/bus/planner/move/request", {"cid": cid, "service": "planner", "op": "move",
                                              "body": {"kind": "ptp"}})
            put("/bus/planner/move/reply", {"cid": cid, "service": "planner", "op": "move",
                                            "ok": True, "body": {"ok": True}})
        for _ in range(joint_states_per_line):
            cycle += 1
            put("/driver/joint_state", {"t": cycle * 0.012, "cycle": cycle,
                                        "q": [5.0, -5.0, 5.0, 5.0, 5.0, 5.0], "qd": [0.0] * 6,
                                        "moving": False, "mode": "idle"})
        reply = REPLIES[line]
        if reply or line.strip():  # the gateway records a reply record even when empty
            put(f"/session/{session}/client_out", {"session": session, "cid": cid, "text": reply})
        if word == "Foo":
            put("/log", {"level": "WARNING", "name": "rob6.gateway", "service": "gateway",
                         "message": "unknown command Foo", "t": t / 1e9})
    put(f"/session/{session}/event", {"session": session, "event": "close", "reason": "quit"})
    return submitted


class FakeServer:
    """A rob6-like TCP server on 127.0.0.1 run by an asyncio loop in a thread.

    ``handler(connection_index, message_bytes) -> (reply_bytes, close_after)`` is
    called for each line (``per_line=True``) or each received chunk.
    """

    def __init__(self, handler: Callable[[int, bytes], tuple[bytes, bool]],
                 greeting: str = GREETING, per_line: bool = True) -> None:
        self.handler = handler
        self.greeting = greeting
        self.per_line = per_line
        self.connections = 0
        self.received: list[bytes] = []
        self.loop = asyncio.new_event_loop()
        self.port = 0
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.server = self.loop.run_until_complete(
            asyncio.start_server(self._client, "127.0.0.1", 0))
        self.port = self.server.sockets[0].getsockname()[1]
        self._ready.set()
        self.loop.run_forever()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        index = self.connections
        self.connections += 1
        writer.write(self.greeting.encode("latin-1"))
        await writer.drain()
        buf = b""
        try:
            while True:
                data = await reader.read(4096)
                if not data:
                    break
                messages = []
                if self.per_line:
                    buf += data
                    while b"\n" in buf:
                        line, buf = buf.split(b"\n", 1)
                        messages.append(line + b"\n")
                else:
                    messages.append(data)
                for msg in messages:
                    self.received.append(msg)
                    reply, close = self.handler(index, msg)
                    if reply:
                        writer.write(reply)
                        await writer.drain()
                    if close:
                        writer.close()
                        return
        except (asyncio.CancelledError, ConnectionError):
            pass
        finally:
            writer.close()

    def __enter__(self) -> FakeServer:
        self._thread.start()
        self._ready.wait(5)
        return self

    def __exit__(self, *exc: object) -> None:
        async def stop() -> None:
            self.server.close()
            await self.server.wait_closed()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self.loop.stop()
        asyncio.run_coroutine_threadsafe(stop(), self.loop)
        self._thread.join(5)
        self.loop.close()


#: a fake server's answer to one received chunk of connection n: (reply bytes, close after it)
Handler = Callable[[int, bytes], tuple[bytes, bool]]


def dict_handler(replies: dict[str, str], overrides: dict[str, str] | None = None) -> Handler:
    table = dict(replies)
    table.update(overrides or {})

    def handle(_conn: int, msg: bytes) -> tuple[bytes, bool]:
        line = msg.decode("latin-1")
        if line == "GetTimestamp\n":
            return f"{time.time():.3f}\n".encode(), False
        reply = table.get(line)
        if reply is None:
            reply = f"ERROR: {line.rstrip(chr(10))}\n"
        return reply.encode("latin-1"), line == "Quit\n"

    return handle
