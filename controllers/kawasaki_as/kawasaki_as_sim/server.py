"""The controller: the loaded AS program run by the interpreter, its arm, its TCP/IP option and the fault switches.

At start the operator's commands (``PCEXECUTE 1: rob6_pc``, ``EXECUTE rob6_motion``) run
the program; the controller is ready once the program listens on its port. Then every
``TICK_S`` the network is read, the arm moves on and the tasks step. The controller's
clock advances by at most ``TICK_S`` between two steps of the tasks: when this process was
held up (a loaded machine), the ticks missed are run one after the other to catch up, so
the arm never runs ahead of its program, as on a real controller, which is never held up
(up to ``MAX_CATCH_UP_S``; beyond that the time is skipped). The switches the program
reads are the controller's state: ``POWER`` (motor power on), ``REPEAT`` (repeat mode, not
teach); ``ERROR`` is the current error code. A stop (E-stop, motor power off,
teach mode, an error, a program's run-time error) brakes the arm and stops the robot
program; the operator starts it again (``execute``, the terminal's ``EXECUTE``).

A tap on the connections counts what crosses them for the status: lines received, the
answers (``A seq code ...``) the program sent by code, the time from a line's arrival to
its answer, and the underruns the last state line reported. It only watches; the program alone decides what is sent.
"""

from __future__ import annotations

import json
import math
import re
import selectors
import socket
import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import aslang
from .arm import Arm, Segment, outside_range
from .asrun import AsError, Interpreter, Value
from .astcp import Conn, TcpOption
from .convention import to_rob6

TICK_S = 0.004
MAX_CATCH_UP_S = 0.5
LATENCY_WINDOW = 10000
BOOT_TIMEOUT_S = 5.0
#: the operator's commands at start, as deploy/kawasaki/README.md has them
START = ("PCEXECUTE 1: rob6_pc", "EXECUTE rob6_motion")


def event(msg: str) -> None:
    print(f"kawasaki-as-sim: {msg}", file=sys.stderr, flush=True)


@dataclass(frozen=True)
class Config:
    program: Path
    host: str = "127.0.0.1"
    port: int = 49200  # where the program's port appears on this host (0: any free port)
    as_port: int = 49200  # the program's port (its kport)
    control_host: str = "127.0.0.1"
    control_port: int = 0
    start_pose_ctrl: tuple[float, ...] = (0.0, 90.0, 0.0, 0.0, 0.0, 0.0)
    start: tuple[str, ...] = START


@dataclass
class Tap:
    """What crosses a connection: lines in, answers out by code, arrival -> answer times."""

    lines: int = 0
    answers: dict[str, int] = field(default_factory=dict)
    underruns: int = 0  # as the last state line sent said
    latencies_ms: deque[float] = field(default_factory=lambda: deque(maxlen=LATENCY_WINDOW))
    _arrivals: dict[int, deque[float]] = field(default_factory=dict)
    _partial: dict[int, bytes] = field(default_factory=dict)

    def received(self, conn: Conn, data: bytes, now: float) -> None:
        for _ in range(data.count(b"\n")):
            self.lines += 1
            self._arrivals.setdefault(id(conn), deque()).append(now)

    def sent(self, conn: Conn, data: bytes, now: float) -> None:
        text = self._partial.pop(id(conn), b"") + data
        *lines, rest = text.split(b"\n")
        if rest:
            self._partial[id(conn)] = rest
        for line in lines:
            fields = line.split()
            if fields[:1] == [b"S"] and fields[-1].isdigit():
                self.underruns = int(fields[-1])
            if fields[:1] == [b"A"] and len(fields) > 2:
                code = fields[2].decode("ascii", "replace")
                self.answers[code] = self.answers.get(code, 0) + 1
                arrivals = self._arrivals.get(id(conn))
                if arrivals:
                    self.latencies_ms.append((now - arrivals.popleft()) * 1000.0)


class Controller:
    def __init__(self, cfg: Config):
        self.cfg = cfg
        self.source = cfg.program.read_text(encoding="latin-1")
        self.programs = aslang.load(self.source)  # AsSyntaxError: the controller refuses the file
        self.clock = time.monotonic()  # the controller's time: the arm's and the programs'
        self.arm = Arm(cfg.start_pose_ctrl, self.clock)
        self.estop = False
        self.motor = True
        self.teach = False
        self.error = 0
        self.tap = Tap()
        self.net = TcpOption(cfg.host, {cfg.as_port: cfg.port}, self._accepted, self.tap.received, self.tap.sent)
        self.interp = Interpreter(self.programs, self)
        self.robot_program = ""
        self.done = False

    # ---- the Machine the programs see ----------------------------------------------
    def now(self) -> float:
        return self.clock

    def switch(self, name: str) -> bool:
        return {"power": self.motor, "repeat": not self.teach}[name]

    def error_code(self) -> int:
        return self.error

    def here(self) -> tuple[float, ...]:
        self.arm.advance(self.clock)
        return tuple(round(x, 6) + 0.0 for x in self.arm.q)

    def motion_room(self) -> bool:
        return self.arm.room()

    def move(self, q: tuple[float, ...], seconds: float, accuracy_mm: float, stop: bool, after_rest: bool) -> None:
        why = outside_range(q)
        if why:
            # AS refuses a destination outside the motion range: "(E1088) Destination is out of motion range."
            raise AsError("E1088", f"Destination is out of motion range: {why}")
        self.arm.move(Segment(q, seconds, accuracy_mm, stop, after_rest))

    def settled(self) -> bool:
        self.arm.advance(self.clock)
        return not self.arm.moving

    def print_line(self, task: str, text: str) -> None:
        event(f"{task}: PRINT {text}")

    def tcp(self, op: str, args: list[Value], started: float) -> tuple[Value, ...] | None:
        return self.net.op(op, args, started, self.clock)

    def program_error(self, task: str, error: AsError) -> None:
        digits = re.sub(r"\D", "", error.code)
        self.halt(f"{task}: {self.interp.tasks[task].message}")
        self.error = int(digits) if digits else 1

    # ---- the operator --------------------------------------------------------------
    def command(self, line: str) -> str:
        """A terminal command: ``PCEXECUTE n: name`` or ``EXECUTE name``; "" or the refusal."""
        if m := re.fullmatch(r"PCEXECUTE\s+([1-5])\s*:\s*(\w+)", line.strip(), re.IGNORECASE):
            return self.interp.start(f"pc{m.group(1)}", m.group(2))
        if m := re.fullmatch(r"EXECUTE\s+(\w+)", line.strip(), re.IGNORECASE):
            self.robot_program = m.group(1)
            return self.execute()
        return f"unknown command {line!r}"

    def execute(self) -> str:
        """``EXECUTE`` the robot program: refused as the controller refuses it (khi_robot_py's texts)."""
        if self.error:
            return "(P1013)Cannot execute because in error now. Reset error."
        if self.teach:
            return "program in TEACH mode."
        if not self.motor:
            return "motor power is OFF."
        return self.interp.start("robot", self.robot_program)

    def halt(self, why: str) -> None:
        self.arm.advance(self.clock)
        moving = self.arm.moving
        self.arm.stop()
        self.interp.abort("robot", why)
        event(f"{why}: the robot program stops, the arm {'brakes' if moving else 'stands'} at "
              f"{' '.join(f'{x:.3f}' for x in self.arm.q)}")

    def _accepted(self, conn: Conn) -> None:
        event(f"client {conn.peer[0]}:{conn.peer[1]} accepted")

    # ---- time ----------------------------------------------------------------------
    def tick(self) -> None:
        """The controller's time up to now, a step of the tasks every ``TICK_S`` of it at most."""
        self.net.poll()
        now = time.monotonic()
        self.clock = max(self.clock, now - MAX_CATCH_UP_S)
        while True:
            self.clock = min(self.clock + TICK_S, now)
            self.arm.advance(self.clock)
            self.interp.tick()
            if self.clock >= now:
                break
        self.net.poll()

    def boot(self) -> tuple[str, int]:
        """The operator's start commands; the program's port once it listens."""
        for line in self.cfg.start:
            why = self.command(line)
            if why:
                raise RuntimeError(f"{line}: {why}")
            self.tick()
        deadline = time.monotonic() + BOOT_TIMEOUT_S
        while (addr := self.net.address(self.cfg.as_port)) is None:
            if time.monotonic() > deadline:
                raise RuntimeError(f"the program never listened on its port {self.cfg.as_port}; tasks: {self.tasks()}")
            self.tick()
            time.sleep(TICK_S)
        return addr

    def tasks(self) -> dict[str, str]:
        return {name: t.state + (f": {t.message}" if t.message else "") for name, t in self.interp.tasks.items()}

    # ---- the control channel -------------------------------------------------------
    def status(self) -> dict[str, Any]:
        self.arm.advance(self.clock)
        lat = sorted(self.tap.latencies_ms)
        return {
            "ok": True,
            "position_ctrl_deg": [round(x, 6) for x in self.arm.q],
            "position_rob6_deg": [round(x, 6) for x in to_rob6(self.arm.q)],
            "moving": self.arm.moving, "estop": self.estop, "motor": self.motor, "teach": self.teach,
            "error": self.error, "monitor_speed": self.arm.monitor_speed,
            "client": self.net.connected(), "connections": self.net.accepted,
            "lines_received": self.tap.lines, "answers": dict(sorted(self.tap.answers.items())),
            "underruns_reported": self.tap.underruns,
            "segments": self.arm.executed, "max_speed_ratio": round(self.arm.max_speed_ratio, 4),
            "ack_ms": [_pct(lat, 0.5), _pct(lat, 0.99), lat[-1] if lat else 0.0],
            "tasks": self.tasks(),
        }

    def control(self, req: Any) -> dict[str, Any]:
        if not isinstance(req, dict) or not isinstance(req.get("cmd"), str):
            return {"ok": False, "error": "expected a JSON object with a string 'cmd'"}
        cmd = req["cmd"]
        if cmd == "status":
            return self.status()
        if cmd == "type":
            return self._type(req.get("expr"))
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
        elif cmd == "execute":
            why = self.execute()
            if why:
                return {"ok": False, "error": why}
        elif cmd == "drop_connection":
            return {"ok": True, "dropped": self.net.drop()}
        elif cmd == "slow_ack":
            ms = req.get("ms")
            if not isinstance(ms, int | float) or isinstance(ms, bool) or not math.isfinite(ms) or ms < 0:
                return {"ok": False, "error": "slow_ack: 'ms' must be a number >= 0"}
            self.net.latency_s = float(ms) / 1000.0
        elif cmd == "monitor_speed":
            pct = req.get("percent")
            if not isinstance(pct, int | float) or isinstance(pct, bool) or not 1 <= pct <= 100:
                return {"ok": False, "error": "monitor_speed: 'percent' must be 1..100"}
            self.arm.advance(self.clock)
            self.arm.monitor_speed = float(pct)
        else:
            return {"ok": False, "error": f"unknown command {cmd!r}"}
        event(f"control: {json.dumps(req)}")
        return {"ok": True}

    def _type(self, text: Any) -> dict[str, Any]:
        if not isinstance(text, str):
            return {"ok": False, "error": "type: 'expr' must be a string"}
        try:
            p = aslang._Parser(aslang.tokenize(text))
            expr = p.expr()
            p.done()
            value = self.interp.type_expr(expr)
        except (aslang.AsSyntaxError, AsError) as exc:
            return {"ok": False, "error": str(exc)}
        return {"ok": True, "value": value if not isinstance(value, tuple) else list(value)}


def _pct(values: list[float], p: float) -> float:
    if not values:
        return 0.0
    return round(values[min(len(values) - 1, max(0, math.ceil(p * len(values)) - 1))], 3)


def run(cfg: Config, ready: Callable[[tuple[str, int], tuple[str, int]], None],
        stop: Callable[[Controller], None]) -> None:
    """Boot the controller, say ``ready``, and run until ``ctl.done``."""
    ctl = Controller(cfg)
    stop(ctl)
    control = socket.create_server((cfg.control_host, cfg.control_port))
    control.setblocking(False)
    sel = selectors.DefaultSelector()
    sel.register(control, selectors.EVENT_READ, None)
    clients: dict[socket.socket, bytearray] = {}
    try:
        addr = ctl.boot()
        ready(addr, control.getsockname()[:2])
        next_tick = time.monotonic()
        while not ctl.done:
            timeout = max(0.0, next_tick - time.monotonic())
            for key, _ in sel.select(timeout):
                sock = key.fileobj
                assert isinstance(sock, socket.socket)
                if sock is control:
                    client, _ = control.accept()
                    client.setblocking(False)
                    clients[client] = bytearray()
                    sel.register(client, selectors.EVENT_READ, None)
                    continue
                try:
                    data = sock.recv(65536)
                except OSError:
                    data = b""
                if not data:
                    sel.unregister(sock)
                    sock.close()
                    clients.pop(sock, None)
                    continue
                buffer = clients[sock]
                buffer += data
                while (end := buffer.find(b"\n")) >= 0:
                    line = bytes(buffer[:end])
                    del buffer[:end + 1]
                    try:
                        reply = ctl.control(json.loads(line))
                    except json.JSONDecodeError as exc:
                        reply = {"ok": False, "error": f"not JSON: {exc}"}
                    sock.setblocking(True)
                    sock.sendall(json.dumps(reply).encode() + b"\n")
                    sock.setblocking(False)
            if time.monotonic() >= next_tick:
                ctl.tick()
                next_tick = max(next_tick + TICK_S, time.monotonic() - TICK_S)
    finally:
        for client in clients:
            client.close()
        control.close()
        ctl.net.close_all()
