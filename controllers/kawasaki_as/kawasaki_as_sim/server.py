"""The controller: the PC program's TCP port, the robot program's arm and the fault switches.

One client at a time, as the PC program serves one (a second connection is closed at
once). On accept the program says hello; it then answers every line in order (``A``) and
sends the state every ``state_period`` seconds. When the client goes, the program drops
the queue (the segment under way runs out) and waits for the next client.
"""

from __future__ import annotations

import asyncio
import json
import math
import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from . import wire
from .arm import Arm, Target, outside_range, too_fast
from .convention import to_rob6

TICK_S = 0.004
LATENCY_WINDOW = 10000


def event(msg: str) -> None:
    print(f"kawasaki-as-sim: {msg}", file=sys.stderr, flush=True)


@dataclass(frozen=True)
class Config:
    host: str = "127.0.0.1"
    port: int = 49200
    control_host: str = "127.0.0.1"
    control_port: int = 0
    start_pose_ctrl: tuple[float, ...] = (0.0, 90.0, 0.0, 0.0, 0.0, 0.0)
    state_period: float = 0.05
    capacity: int = 64


class Controller:
    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.arm = Arm(cfg.start_pose_ctrl, time.monotonic(), cfg.capacity)
        self.estop = False
        self.motor = True
        self.teach = False
        self.error = 0
        self.slow_ack_ms = 0.0
        self.last_sequence = 0
        self.received = self.accepted = self.malformed = 0
        self.refused: dict[int, int] = {}
        self.connections = 0
        self.states_sent = 0
        self.latencies_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.client: asyncio.StreamWriter | None = None
        self.done = asyncio.Event()

    # ---- time and faults ---------------------------------------------------------
    def advance(self) -> None:
        self.arm.advance(time.monotonic())

    def not_ready(self) -> str:
        if self.estop:
            return "E-stop"
        if not self.motor:
            return "motor power off"
        if self.teach:
            return "teach mode"
        if self.error:
            return f"error {self.error}"
        return ""

    def halt(self, why: str) -> None:
        self.advance()
        moving = self.arm.moving
        self.arm.stop()
        event(f"{why}: the arm {'brakes' if moving else 'stands'} at {_joints(self.arm.q)}")

    # ---- the PC program ------------------------------------------------------------
    def take(self, text: str) -> tuple[int, int]:
        """One line from the client -> (sequence, answer code)."""
        self.received += 1
        try:
            msg = wire.read(text)
        except wire.Malformed as exc:
            self.malformed += 1
            event(f"malformed line {text[:60]!r}: {exc}")
            return wire.sequence_of(text), wire.MALFORMED
        self.advance()
        if msg.sequence <= self.last_sequence:
            return msg.sequence, self._refuse(wire.SEQUENCE, f"sequence {msg.sequence} after {self.last_sequence}")
        self.last_sequence = msg.sequence
        if isinstance(msg, wire.CancelMsg):
            self.arm.cancel()
            return msg.sequence, wire.OK
        why = self.not_ready()
        if why:
            return msg.sequence, self._refuse(wire.NOT_READY, f"point {msg.sequence} while {why}")
        why = outside_range(msg.joints)
        if why:
            return msg.sequence, self._refuse(wire.RANGE, f"point {msg.sequence}: {why}")
        seconds = msg.ms / 1000.0
        why = too_fast(self.arm.last_queued(), msg.joints, seconds)
        if why:
            return msg.sequence, self._refuse(wire.TOO_FAST, f"point {msg.sequence}: {why}")
        if len(self.arm.queue) >= self.arm.capacity:
            return msg.sequence, self._refuse(wire.QUEUE_FULL, f"point {msg.sequence}: queue full")
        self.arm.enqueue(Target(msg.joints, seconds, msg.final, msg.sequence))
        self.accepted += 1
        return msg.sequence, wire.OK

    def _refuse(self, code: int, why: str) -> int:
        self.refused[code] = self.refused.get(code, 0) + 1
        event(f"refused (code {code}): {why}")
        return code

    def state_line(self) -> bytes:
        self.advance()
        self.states_sent += 1
        arm = self.arm
        return wire.state(self.states_sent, arm.q, self.motor, self.estop, self.teach, arm.moving,
                          len(arm.queue), arm.done, self.error, arm.underruns)

    async def serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self.client is not None:  # the program serves one client
            event(f"refused a second client {_peer(writer)}")
            writer.close()
            return
        self.client = writer
        self.connections += 1
        self.last_sequence = 0
        event(f"client {_peer(writer)} connected")
        sender = asyncio.create_task(self._send_states(writer))
        try:
            writer.write(wire.hello(self.arm.capacity))
            await writer.drain()
            while True:
                try:
                    raw = await reader.readuntil(b"\n")
                except asyncio.LimitOverrunError:
                    self.malformed += 1
                    event("a line without its end: the client is dropped")
                    break
                except asyncio.IncompleteReadError:
                    break
                t_in = time.perf_counter()
                text = raw[:-1].decode("ascii", "replace").rstrip("\r")
                if len(raw) > wire.MAX_LINE:
                    self.malformed += 1
                    writer.write(wire.answer(wire.sequence_of(text), wire.MALFORMED, len(self.arm.queue)))
                    await writer.drain()
                    continue
                if self.slow_ack_ms:
                    await asyncio.sleep(self.slow_ack_ms / 1000.0)
                sequence, code = self.take(text)
                writer.write(wire.answer(sequence, code, len(self.arm.queue)))
                await writer.drain()
                self.latencies_ms.append((time.perf_counter() - t_in) * 1000.0)
        except (ConnectionError, OSError):
            pass
        finally:
            sender.cancel()
            if self.client is writer:
                self.client = None
                self.arm.cancel()
                event(f"client {_peer(writer)} gone: queue dropped, the segment under way runs out")
            writer.close()

    async def _send_states(self, writer: asyncio.StreamWriter) -> None:
        try:
            while True:
                writer.write(self.state_line())
                await writer.drain()
                await asyncio.sleep(self.cfg.state_period)
        except (ConnectionError, OSError):
            return

    def drop(self) -> bool:
        writer = self.client
        if writer is None:
            return False
        transport = writer.transport
        if transport is not None:
            transport.abort()
        self.client = None
        self.arm.cancel()
        event("connection dropped (fault injection)")
        return True

    async def tick(self) -> None:
        while True:
            self.advance()
            await asyncio.sleep(TICK_S)

    # ---- the control channel -------------------------------------------------------
    def status(self) -> dict[str, Any]:
        self.advance()
        lat = sorted(self.latencies_ms)
        return {
            "ok": True,
            "position_ctrl_deg": [round(x, 6) for x in self.arm.q],
            "position_rob6_deg": [round(x, 6) for x in to_rob6(self.arm.q)],
            "moving": self.arm.moving, "queued": len(self.arm.queue), "done": self.arm.done,
            "estop": self.estop, "motor": self.motor, "teach": self.teach, "error": self.error,
            "client": self.client is not None, "connections": self.connections,
            "points_received": self.received, "points_accepted": self.accepted,
            "points_executed": self.arm.executed, "malformed": self.malformed,
            "refused": {str(k): v for k, v in sorted(self.refused.items())},
            "underruns": self.arm.underruns, "max_speed_ratio": round(self.arm.max_speed_ratio, 4),
            "ack_ms": [_pct(lat, 0.5), _pct(lat, 0.99), lat[-1] if lat else 0.0],
        }

    def command(self, req: Any) -> dict[str, Any]:
        if not isinstance(req, dict) or not isinstance(req.get("cmd"), str):
            return {"ok": False, "error": "expected a JSON object with a string 'cmd'"}
        cmd = req["cmd"]
        if cmd == "status":
            return self.status()
        if cmd == "estop":
            self.estop, self.motor = True, False
            self.halt("E-stop")
        elif cmd == "estop_release":
            self.estop = False  # the motor power stays off until switched on
        elif cmd in ("motor", "teach"):
            on = req.get("on")
            if not isinstance(on, bool):
                return {"ok": False, "error": f"{cmd}: 'on' must be true or false"}
            if cmd == "motor":
                if on and self.estop:
                    return {"ok": False, "error": "motor power cannot come on during an E-stop"}
                self.motor = on
                if not on:
                    self.halt("motor power off")
            else:
                self.teach = on
                if on:
                    self.halt("teach mode")
        elif cmd == "error":
            code = req.get("code")
            if not isinstance(code, int) or isinstance(code, bool) or code <= 0:
                return {"ok": False, "error": "error: 'code' must be a positive integer"}
            self.error = code
            self.halt(f"error {code}")
        elif cmd == "clear_error":
            self.error = 0
        elif cmd == "drop_connection":
            return {"ok": True, "dropped": self.drop()}
        elif cmd == "slow_ack":
            ms = req.get("ms")
            if not isinstance(ms, int | float) or isinstance(ms, bool) or not math.isfinite(ms) or ms < 0:
                return {"ok": False, "error": "slow_ack: 'ms' must be a number >= 0"}
            self.slow_ack_ms = float(ms)
        else:
            return {"ok": False, "error": f"unknown command {cmd!r}"}
        event(f"control: {json.dumps(req)}")
        return {"ok": True}

    async def serve_control(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while line := await reader.readline():
                try:
                    reply = self.command(json.loads(line))
                except json.JSONDecodeError as exc:
                    reply = {"ok": False, "error": f"not JSON: {exc}"}
                writer.write(json.dumps(reply).encode() + b"\n")
                await writer.drain()
        except (ConnectionError, OSError):
            pass
        finally:
            writer.close()


def _peer(writer: asyncio.StreamWriter) -> str:
    peer = writer.get_extra_info("peername")
    return f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)


def _pct(values: list[float], p: float) -> float:
    if not values:
        return 0.0
    return round(values[min(len(values) - 1, max(0, math.ceil(p * len(values)) - 1))], 3)


def _joints(q: list[float]) -> str:
    return " ".join(f"{x:.3f}" for x in q)


async def run(cfg: Config, ready: Callable[[tuple[str, int], tuple[str, int], Controller], None]) -> None:
    ctl = Controller(cfg)
    server = await asyncio.start_server(ctl.serve, cfg.host, cfg.port, limit=wire.MAX_LINE * 4)
    control = await asyncio.start_server(ctl.serve_control, cfg.control_host, cfg.control_port)
    ticker = asyncio.create_task(ctl.tick())
    addr = server.sockets[0].getsockname()[:2]
    caddr = control.sockets[0].getsockname()[:2]
    ready((addr[0], addr[1]), (caddr[0], caddr[1]), ctl)
    try:
        await ctl.done.wait()
    finally:
        ticker.cancel()
        server.close()
        control.close()
        if ctl.client is not None:
            ctl.client.close()
