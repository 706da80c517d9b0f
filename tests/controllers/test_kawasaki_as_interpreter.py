"""The stand-in's AS interpreter is as strict as the controller: what it refuses at load (an
unknown instruction or function, a wrong argument count, an unclosed block, a GOTO without
its label, a name over 15 characters, a $ENCODE format no public AS code shows) and what stops a program at run time (an undefined variable, E0102; an index out
of range; a name used as scalar and array; an unknown switch; a string over 255 characters;
a number that overflows its $ENCODE format; a CALL with the wrong number of arguments); and
how its values behave (TRUE is -1, AND evaluates both sides, $DECODE consumes its text).
In process, with a machine that records what the program asks of the controller."""

from __future__ import annotations

import pytest

from kawasaki_as_sim.aslang import AsSyntaxError, load
from kawasaki_as_sim.asrun import AsError, Interpreter, Value


class Machine:
    def __init__(self) -> None:
        self.errors: list[AsError] = []
        self.moves: list[tuple[float, bool, bool]] = []
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def switch(self, name: str) -> bool:
        return {"power": True, "repeat": True}[name]

    def error_code(self) -> int:
        return 0

    def here(self) -> tuple[float, ...]:
        return (0.0, 90.0, 0.0, 0.0, 0.0, 0.0)

    def motion_room(self) -> bool:
        return True

    def move(self, q: tuple[float, ...], seconds: float, accuracy_mm: float, stop: bool, after_rest: bool) -> None:
        self.moves.append((accuracy_mm, stop, after_rest))

    def settled(self) -> bool:
        return True

    def print_line(self, task: str, text: str) -> None:
        pass

    def tcp(self, op: str, args: list[Value], started: float) -> tuple[Value, ...] | None:
        return (0.0,)

    def program_error(self, task: str, error: AsError) -> None:
        self.errors.append(error)


def run(body: str, *extra: str) -> tuple[Interpreter, Machine]:
    source = ".PROGRAM main()\n" + body + "\n.END\n" + "\n".join(extra)
    machine = Machine()
    interp = Interpreter(load(source), machine)
    assert interp.start("pc1", "main") == ""
    return interp, machine


def value(interp: Interpreter, name: str) -> Value:
    return interp.globals[name]  # type: ignore[return-value]


@pytest.mark.parametrize("body, error", [
    ("  FLY 3", "unknown instruction 'FLY'"),
    ("  a = NOSUCH(1)", "unknown function NOSUCH"),
    ("  a = $NOSUCH(1)", "unknown function $NOSUCH"),
    ("  a = $MID(\"x\")", "$MID takes 2 to 3 arguments, given 1"),
    ("  .abcdefghijklmnop = 1", "the name .ABCDEFGHIJKLMNOP is longer than 15 characters"),
    ("  $abcdefghijklmnop = \"\"", "the name $ABCDEFGHIJKLMNOP is longer than 15 characters"),
    ("  CALL abcdefghijklmnop()", "the name ABCDEFGHIJKLMNOP is longer than 15 characters"),
    ("  a = $ENCODE(/I6, 1)", "unknown format /I6"),
    ("  a = $ENCODE(/F9, 1)", "unknown format /F9"),
    ("  TCP_RECV a, b, $c[1], d, 1", "TCP_RECV: wrong arguments"),
    ("  IF a THEN", "IF without END in main"),
    ("  GOTO 10", "GOTO 10: no such label in main"),
    ("  a = $ENCODE(/X3, 1)", "unknown format /X3"),
])
def test_what_the_controller_refuses_to_load(body: str, error: str) -> None:
    with pytest.raises(AsSyntaxError) as exc:
        run(body)
    assert error in str(exc.value)


@pytest.mark.parametrize("body, code, text", [
    ("  a = b + 1", "E0102", "Variable is not defined: b"),
    ("  a[1] = 1\n  b = a[2]", "E0102", "Variable is not defined: a[2]"),
    ("  a[1] = 1\n  b = a[-1]", "", "index -1 of a out of range 0..9999"),
    ("  a = 1\n  a[1] = 2", "", "a is not an array"),
    ("  a[1] = 1\n  b = a", "", "a is an array, used without an index"),
    ("  a = SWITCH(EMERGENCY)", "", "SWITCH(EMERGENCY): no such switch"),
    ("  $a = $ENCODE(/F7.1, -34024)", "", "$ENCODE: -34024 does not fit /F7"),
    ("  $a = \"x\"\n  FOR i = 1 TO 8\n    $a = $a + $a\n  END", "", "a string of 256 characters for $a"),
    ("  CALL sub(1)", "", "CALL sub: 1 arguments for 2 parameters"),
    ("  a = 1 / 0", "", "division by zero"),
    ("  $a = 1", "", "a number assigned to the string variable $a"),
])
def test_what_stops_a_program(body: str, code: str, text: str) -> None:
    interp, machine = run(body, ".PROGRAM sub(.a, .b)\n.END")
    assert interp.tasks["pc1"].state == "error"
    assert len(machine.errors) == 1 and machine.errors[0].code == code and text in machine.errors[0].text


def test_true_is_minus_one_and_and_evaluates_both_sides() -> None:
    interp, _ = run("  a = SWITCH(POWER)\n  b = SWITCH(POWER) AND 1\n  c = NOT 0\n  d = 3 > 2")
    assert [value(interp, n) for n in "abcd"] == [-1.0, -1.0, -1.0, -1.0]
    interp, machine = run("  k = 0\n  f[0] = 1\n  IF (k > 0) AND (f[k - 1] == 1) THEN\n    x = 1\n  END")
    assert machine.errors and "index -1 of f" in machine.errors[0].text  # no short circuit


def test_decode_consumes_its_text_and_encode_pads() -> None:
    interp, _ = run('  $l = "P  12 x"\n  $a = $DECODE($l, " ", 0)\n  $s = $DECODE($l, " ", 1)\n'
                    '  $b = $DECODE($l, " ", 0)\n  $e = $ENCODE(/F9.3, -1.5)\n'
                    '  v = VAL("12x")\n  w = VAL("x")\n  i = INSTR(1, "abc", "c")\n  $m = $MID("abc", 2, 5)\n'
                    '  j = INSTR("abc", "b")\n  k = INSTR(0, "abc", "a")\n  $n = $MID("abc", 2)\n'
                    '  $o = $ENCODE(/L, -17, " ", /D, 3)')
    assert [value(interp, n) for n in ("$a", "$s", "$b", "$l")] == ["P", "  ", "12", " x"]
    assert [value(interp, n) for n in ("v", "w", "i", "$m", "j", "k", "$n")] == [12.0, 0.0, 3.0, "bc", 2.0, 1.0, "bc"]
    assert value(interp, "$o") == "-17 3"


def test_locals_belong_to_one_call_and_parameters_come_back() -> None:
    interp, _ = run("  x = 5\n  CALL sub(x, y)\n  z = x",
                    ".PROGRAM sub(.a, .b)\n  .a = .a + 1\n  .b = 7\n  .t = 1\n.END")
    assert (value(interp, "x"), value(interp, "y"), value(interp, "z")) == (6.0, 7.0, 6.0)
    assert ".t" not in interp.globals and ".a" not in interp.globals


def test_the_shipped_program_loads() -> None:
    from pathlib import Path
    programs = load((Path(__file__).resolve().parents[2] / "deploy/kawasaki/rob6.as").read_text())
    assert sorted(programs) == ["rob6_line", "rob6_motion", "rob6_num", "rob6_pc", "rob6_state"]
