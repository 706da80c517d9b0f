"""rob6.as's streaming as a controller would run it, on a simulated clock (no wall time): the
stand-in's interpreter and arm, lines arriving from a client at set times. Points every 48 ms
blend (the arm never slows towards a point), the final one is reached exactly, a state line
carries a joint below -100 deg; and each single-line mistake a real controller would punish
fails one of these checks: a name over 15 characters, CP OFF, a fine accuracy for every
point, a state format too narrow, a branch or a wait between two motion instructions."""

from __future__ import annotations

from pathlib import Path

import pytest

from kawasaki_as_sim.aslang import AsSyntaxError, load
from kawasaki_as_sim.simclock import SimCell

SOURCE = (Path(__file__).resolve().parents[2] / "deploy/kawasaki/rob6.as").read_text()
PORT, STATE_PORT = 49200, 49201  # the program's kport and kport + 1
PERIOD_S = 0.048
SPEED_DEG_S = 50.0  # JT1 in the stream


def started(source: str, pose: tuple[float, ...] = (0.0, 90.0, 0.0, 0.0, 0.0, 0.0)) -> SimCell:
    """The controller with rob6.as started as its README says, a client on both ports."""
    cell = SimCell(source, pose)
    cell.start(("pc1", "rob6_pc"), ("robot", "rob6_motion"))
    cell.connect(PORT, cell.t)
    cell.connect(STATE_PORT, cell.t)
    return cell


def stream(source: str, points: int = 40) -> SimCell:
    """JT1 at 50 deg/s, a point every 48 ms, sent as rob6 sends them; the last one final."""
    cell = started(source)
    t0 = cell.t + 0.1
    for n in range(1, points + 1):
        jt1 = SPEED_DEG_S * PERIOD_S * n
        cell.send(PORT, t0 + PERIOD_S * (n - 1),
                  f"P {n} {jt1:.3f} 90.000 0.000 0.000 0.000 0.000 48 {int(n == points)}\n")
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
    cell = started(source, pose=(-120.0, 90.0, 0.0, 0.0, 0.0, -359.5))
    cell.run(0.3)
    assert not cell.errors, cell.errors
    states = [line.split() for line in cell.port(STATE_PORT).sent if line.startswith("S ")]
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


# ---- the PC side within a controller's means: a step budget per tick, one socket at a time

def check_keeps_up(source: str) -> None:
    """Under the stand-in's default step budget every point is answered before the next one
    arrives, and the queue never runs dry."""
    points = 40
    cell = stream(source, points)
    assert not cell.errors, cell.errors
    port = cell.port(PORT)
    answers = [t for text, t in zip(port.sent, port.sent_at, strict=True) if text.startswith("A ")]
    arrivals = [cell.t - 0.1 - PERIOD_S * points - 1.5 + 0.1 + PERIOD_S * n for n in range(points)]
    assert len(answers) == points
    late = [round(a - b, 3) for a, b in zip(answers, arrivals, strict=True) if a - b >= PERIOD_S]
    assert not late, late
    assert cell.value("kunder") == 0 and cell.value("kdone") == points


def test_the_shipped_program_keeps_up_with_a_point_every_48_ms_under_the_default_budget() -> None:
    check_keeps_up(SOURCE)


def test_a_line_that_costs_too_many_steps_under_runs() -> None:
    # 200 more steps a point: over the budget's 12 ticks of 48 ms with the state task beside it
    expensive = _mutated("  .code = 0\n.END\n\n.PROGRAM rob6_state", "  FOR .z = 1 TO 200\n  END\n  .code = 0\n"
                                                                  ".END\n\n.PROGRAM rob6_state")
    with pytest.raises(AssertionError):
        check_keeps_up(expensive)
    cell = stream(expensive)
    under = cell.value("kunder")
    assert isinstance(under, float) and under > 0  # the arm ran dry between points


def test_the_state_stream_keeps_its_rate_while_rob6_pc_waits_to_receive() -> None:
    cell = started(SOURCE)
    cell.run(2.0)  # the driver sends nothing: rob6_pc waits in TCP_RECV (120 s)
    states = cell.port(STATE_PORT).sent
    # a line every 50 ms plus the ~55 steps that make it (three ticks at the default budget)
    assert len(states) >= 30 and all(line.startswith("S ") for line in states)


SHARED_SOCKET = """
.PROGRAM srv()
  TCP_LISTEN .ret, 49200
  TCP_ACCEPT sock, 49200, 10
  PCEXECUTE 2: sender
10
  TCP_RECV .ret, sock, .$in[1], .n, 1, 120
  GOTO 10
.END
.PROGRAM sender()
10
  TCP_SEND .ret, sock, "S", 1, 1
  TWAIT 0.05
  GOTO 10
.END
"""


def test_one_sockets_instructions_are_serialised() -> None:
    # rob6.as before issue 58: the state sent on the socket rob6_pc receives on; a TCP_RECV
    # waiting (1 s) holds the socket, the sender gets it each time the receive times out
    cell = SimCell(SHARED_SOCKET.replace('"S"', '.$s[1]').replace("10\n  TCP_SEND", '  .$s[1] = "S"\n10\n  TCP_SEND')
                   .replace("1, 120", "1, 1"))
    cell.connect(PORT, 0.0)
    cell.start(("pc1", "srv"), settle_s=3.0)
    assert not cell.errors, cell.errors
    assert 2 <= len(cell.port(PORT).sent) <= 4  # one a second, not twenty


def test_points_are_refused_while_rob6_motion_is_not_running() -> None:
    cell = SimCell(SOURCE)
    cell.start(("pc1", "rob6_pc"))  # the operator never typed EXECUTE rob6_motion
    cell.connect(PORT, cell.t)
    cell.connect(STATE_PORT, cell.t)
    cell.send(PORT, cell.t + 0.01, "P 1 1.000 90.000 0.000 0.000 0.000 0.000 48 1\n")
    cell.run(0.5)
    assert cell.port(PORT).sent[1:] == ["A 1 4 0\n"]  # not ready
    assert cell.port(STATE_PORT).sent[-1].split()[-1] == "0"  # the state says: not running
    cell.interp.start("robot", "rob6_motion")
    cell.send(PORT, cell.t + 0.01, "P 2 1.000 90.000 0.000 0.000 0.000 0.000 48 1\n")
    cell.run(0.5)
    # accepted (the queued count in the answer depends on whether rob6_motion took the point
    # in the ticks rob6_pc needed to answer: not this test's matter) and done
    assert [a.split()[:3] for a in cell.port(PORT).sent[2:]] == [["A", "2", "0"]] and cell.value("kdone") == 2
    assert cell.port(STATE_PORT).sent[-1].split()[-1] == "1"
    cell.interp.held = True  # HOLD
    cell.send(PORT, cell.t + 0.01, "P 3 2.000 90.000 0.000 0.000 0.000 0.000 48 1\n")
    cell.run(0.5)
    assert cell.port(PORT).sent[3:] == ["A 3 4 0\n"] and cell.port(STATE_PORT).sent[-1].split()[-1] == "0"
