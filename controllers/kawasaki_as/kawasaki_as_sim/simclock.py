"""A controller on a simulated clock: the interpreter, the arm and clients' lines arriving at
set times, with no wall time and no sockets, so that a test or a benchmark measures what the
program does and never how loaded the machine is.

A client connects to a program's port at a set time (``connect``) and its lines arrive at
set times (``send``); what the program sends is kept per port (``sent``). The switches,
``ERROR``, HOLD/RUN and the monitor speed are the controller's (``power``, ``repeat``,
``error``, ``interp.held``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .arm import Arm, Segment, outside_range
from .aslang import load
from .asrun import PC_STEPS_PER_TICK, AsError, Interpreter, Value

TICK_S = 0.004  # as server.TICK_S


@dataclass
class Port:
    connect_at: float | None = None  # when a client connects
    socket: int = -1  # the number TCP_ACCEPT gave it
    inbox: list[tuple[float, str]] = field(default_factory=list)  # (arrival, text)
    sent: list[str] = field(default_factory=list)
    sent_at: list[float] = field(default_factory=list)


class SimCell:
    """The Machine of the interpreter, on a simulated clock."""

    def __init__(self, source: str, pose: tuple[float, ...] = (0.0, 90.0, 0.0, 0.0, 0.0, 0.0),
                 pc_steps_per_tick: int = PC_STEPS_PER_TICK) -> None:
        self.t = 0.0
        self.arm = Arm(pose, 0.0)
        self.power = self.repeat = True
        self.error = 0
        self.ports: dict[int, Port] = {}
        self.errors: list[str] = []
        self.speeds: list[tuple[float, float]] = []  # (t, JT1 speed)
        self.interp = Interpreter(load(source), self, pc_steps_per_tick)
        self._next_socket = 1

    def port(self, number: int) -> Port:
        return self.ports.setdefault(number, Port())

    def connect(self, number: int, at: float) -> Port:
        p = self.port(number)
        p.connect_at = at
        return p

    def send(self, number: int, at: float, text: str) -> None:
        self.port(number).inbox.append((at, text))

    # ---- the Machine
    def now(self) -> float:
        return self.t

    def switch(self, name: str) -> bool:
        return {"power": self.power, "repeat": self.repeat}[name]

    def error_code(self) -> int:
        return self.error

    def here(self) -> tuple[float, ...]:
        return tuple(self.arm.q)

    def motion_room(self) -> bool:
        return self.arm.room()

    def move(self, q: tuple[float, ...], seconds: float, accuracy_mm: float, stop: bool, after_rest: bool,
             speed_pct: float) -> None:
        why = outside_range(q)
        if why:
            raise AsError("E1088", f"Destination is out of motion range: {why}")
        self.arm.move(Segment(q, seconds, accuracy_mm, stop, after_rest, speed_pct))

    def settled(self) -> bool:
        return not self.arm.moving

    def print_line(self, task: str, text: str) -> None:
        pass

    def _by_socket(self, number: Value) -> Port | None:
        return next((p for p in self.ports.values() if p.socket == number), None)

    def tcp(self, op: str, args: list[Value], started: float) -> tuple[Value, ...] | None:
        if op == "tcp_accept":
            assert isinstance(args[0], float) and isinstance(args[1], float)
            p = self.port(int(args[0]))
            if p.connect_at is None or p.connect_at > self.t or p.socket >= 0:
                return (-34024.0,) if self.t - started >= args[1] else None
            p.socket = self._next_socket
            self._next_socket += 1
            return (float(p.socket), 127.0, 0.0, 0.0, 1.0)
        if op in ("tcp_send", "tcp_recv"):
            conn = self._by_socket(args[0])
            if conn is None:
                return (-34025.0,)
            p = conn
            if op == "tcp_send":
                assert isinstance(args[1], str)
                p.sent.append(args[1])
                p.sent_at.append(self.t)
                return (0.0,)
            due = [text for at, text in p.inbox if at <= self.t]
            if not due:
                timeout = args[3]
                assert isinstance(timeout, float)
                return (-34024.0,) if self.t - started >= timeout else None
            p.inbox = p.inbox[len(due):]
            text = "".join(due)
            return (0.0, *(text[i:i + 120] for i in range(0, len(text), 120)))
        return (0.0,)  # TCP_LISTEN, TCP_CLOSE, TCP_END_LISTEN

    def program_error(self, task: str, error: AsError) -> None:
        self.errors.append(f"{task}: {self.interp.tasks[task].message}")

    # ---- time
    def run(self, seconds: float) -> None:
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.t += TICK_S
            self.arm.advance(self.t)
            self.interp.tick()
            self.speeds.append((self.t, abs(self.arm.v[0])))

    def start(self, *commands: tuple[str, str], settle_s: float = 0.5) -> None:
        """The operator's start commands ((task, program)), ``settle_s`` of the clock after each
        (an operator types the next one seconds later)."""
        for task, program in commands:
            why = self.interp.start(task, program)
            if why:
                raise RuntimeError(f"{task}: {program}: {why}")
            self.run(settle_s)

    def value(self, name: str) -> Value:
        value = self.interp.globals[name]
        assert not isinstance(value, dict)
        return value
