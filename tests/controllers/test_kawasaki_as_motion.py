"""rob6.as's streaming as a controller would run it, on a simulated clock (no wall time): the
stand-in's interpreter and arm, lines arriving from a client at set times. Points every 48 ms
blend (the arm never slows towards a point), the final one is reached exactly, a state line
carries a joint below -100 deg; and each single-line mistake a real controller would punish
fails one of these checks: a name over 15 characters, CP OFF, a fine accuracy for every
point, a state format too narrow, a branch or a wait between two motion instructions."""

from __future__ import annotations

from pathlib import Path

import pytest

from kawasaki_as_sim.arm import Arm, Segment
from kawasaki_as_sim.aslang import AsSyntaxError, load
from kawasaki_as_sim.asrun import AsError, Interpreter, Value

SOURCE = (Path(__file__).resolve().parents[2] / "deploy/kawasaki/rob6.as").read_text()
TICK_S = 0.004  # the stand-in's (server.TICK_S)
PERIOD_S = 0.048
SPEED_DEG_S = 50.0  # JT1 in the stream


class Cell:
    """The controller running a program: tasks every tick, the arm, one client's lines."""

    def __init__(self, source: str, pose: tuple[float, ...] = (0.0, 90.0, 0.0, 0.0, 0.0, 0.0)) -> None:
        self.t = 0.0
        self.arm = Arm(pose, 0.0)
        self.inbox: list[tuple[float, str]] = []
        self.sent: list[str] = []
        self.errors: list[str] = []
        self.speeds: list[tuple[float, float]] = []  # (t, JT1 speed)
        self.interp = Interpreter(load(source), self)
        assert self.interp.start("pc1", "rob6_pc") == ""
        assert self.interp.start("robot", "rob6_motion") == ""

    # ---- the Machine
    def now(self) -> float:
        return self.t

    def switch(self, name: str) -> bool:
        return {"power": True, "repeat": True}[name]

    def error_code(self) -> int:
        return 0

    def here(self) -> tuple[float, ...]:
        return tuple(self.arm.q)

    def motion_room(self) -> bool:
        return self.arm.room()

    def move(self, q: tuple[float, ...], seconds: float, accuracy_mm: float, stop: bool, after_rest: bool) -> None:
        self.arm.move(Segment(q, seconds, accuracy_mm, stop, after_rest))

    def settled(self) -> bool:
        return not self.arm.moving

    def print_line(self, task: str, text: str) -> None:
        pass

    def tcp(self, op: str, args: list[Value], started: float) -> tuple[Value, ...] | None:
        if op == "tcp_accept":
            return (1.0, 127.0, 0.0, 0.0, 1.0)
        if op == "tcp_send":
            assert isinstance(args[1], str)
            self.sent.append(args[1])
        if op == "tcp_recv":
            due = [line for t, line in self.inbox if t <= self.t]
            if not due:
                timeout = args[3]
                assert isinstance(timeout, float)
                return (-34024.0,) if self.t - started >= timeout else None
            self.inbox = self.inbox[len(due):]
            text = "".join(due)
            return (0.0, *(text[i:i + 120] for i in range(0, len(text), 120)))
        return (0.0,)

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

    def value(self, name: str) -> Value:
        value = self.interp.globals[name]
        assert not isinstance(value, dict)
        return value


def stream(source: str, points: int = 40) -> Cell:
    """JT1 at 50 deg/s, a point every 48 ms, sent as rob6 sends them; the last one final."""
    cell = Cell(source)
    for n in range(1, points + 1):
        jt1 = SPEED_DEG_S * PERIOD_S * n
        cell.inbox.append((0.1 + PERIOD_S * (n - 1),
                           f"P {n} {jt1:.3f} 90.000 0.000 0.000 0.000 0.000 48 {int(n == points)}\n"))
    cell.run(0.1 + PERIOD_S * points + 1.5)
    return cell


def check_streams_smoothly(source: str) -> None:
    points = 40
    cell = stream(source, points)
    assert not cell.errors, cell.errors
    assert cell.value("kdone") == points and cell.value("kunder") == 0
    assert cell.arm.q == [SPEED_DEG_S * PERIOD_S * points, 90.0, 0.0, 0.0, 0.0, 0.0] and not cell.arm.moving
    # from 0.3 s after the first motion began until 0.3 s before the last ended, the arm
    # keeps its speed: it never brakes towards a point it passes
    moving = [t for t, v in cell.speeds if v > 1.0]
    middle = [v for t, v in cell.speeds if moving[0] + 0.3 < t < moving[-1] - 0.3]
    assert len(middle) > 100 and min(middle) > 0.9 * SPEED_DEG_S, min(middle)


def check_states_below_minus_100(source: str) -> None:
    cell = Cell(source, pose=(-120.0, 90.0, 0.0, 0.0, 0.0, -359.5))
    cell.run(0.3)
    assert not cell.errors, cell.errors
    states = [line.split() for line in cell.sent if line.startswith("S ")]
    assert len(states) >= 5
    assert [float(x) for x in states[-1][2:8]] == [-120.0, 90.0, 0.0, 0.0, 0.0, -359.5]


def test_points_every_48_ms_blend_and_the_final_one_is_exact() -> None:
    check_streams_smoothly(SOURCE)


def test_a_state_line_carries_joints_below_minus_100() -> None:
    check_states_below_minus_100(SOURCE)


def _mutated(old: str, new: str) -> str:
    assert SOURCE.count(old) == 1, old
    return SOURCE.replace(old, new)


@pytest.mark.parametrize("old, new, check", [
    # a local name of 16 characters: the controller refuses the step (15 at most)
    ("  .fin = .has * kfin[.r]\n", "  .the_final_point1 = .has * kfin[.r]\n", load),
    # CP OFF where the motion task starts: every JMOVE ends at a standstill
    ("  CP ON\n", "  CP OFF\n", check_streams_smoothly),
    # CP left as the cell had it (OFF)
    ("  CP ON\n", "\n", check_streams_smoothly),
    # a fine accuracy for every point
    ("  ACCURACY 50 - 49 * .fin\n", "  ACCURACY 1 FINE\n", check_streams_smoothly),
    # a joint's format too narrow for -120.000
    ("$ENCODE(/F9.3, .j[.k])", "$ENCODE(/F7.3, .j[.k])", check_states_below_minus_100),
    # a wait between two motion instructions
    ("  GOTO 10\n.END\n", "  TWAIT 0.004\n  GOTO 10\n.END\n", check_streams_smoothly),
    # a branch between two motion instructions
    ("  GOTO 10\n.END\n", "  IF kin < 0 GOTO 10\n  GOTO 10\n.END\n", check_streams_smoothly),
])
def test_a_single_line_mistake_fails(old: str, new: str, check: object) -> None:
    assert callable(check)
    with pytest.raises((AssertionError, AsSyntaxError)):
        check(_mutated(old, new))
