"""The AS interpreter: the robot program and the PC programs stepping in time, sharing globals.

Each task (the robot program, PC programs 1..5) runs its program's steps until one has to
wait (TWAIT, a TCP instruction, a JMOVE while the motion queue is full, BREAK); the
controller calls ``tick`` every few milliseconds and the waiting steps are retried then.
Values are reals (TRUE is -1), strings (at most 255 characters) and joint positions;
globals are shared by every task, ``.name`` locals belong to one program call, and a
program's parameters are copied in and back out (by reference, as CALL passes
variables). The controller's side (switches, the arm, the TCP/IP option) is the
``Machine``.

AS is strict and so is this: an undefined variable, an index out of range, a name used
as scalar and array, a value too long for its string or its ``$ENCODE`` format, an
unknown switch, a wrong argument count at CALL stop the task with an ``AsError`` (the
controller's error display; its code where a public source gives one), and the
controller goes into its error state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from .aslang import Binary, Call, Expr, Fmt, Name, Num, Program, Step, Str, Unary, Var

TRUE = -1.0
MAX_STRING = 255
MAX_INDEX = 9999
#: steps a task may run in one tick before the others get their turn
STEPS_PER_TICK = 5000
#: CP when the robot program starts: the switch keeps what the cell's last program left, here OFF
CP_AT_START = False
#: the accuracy (mm) when no ACCURACY ... ALWAYS has set one
DEFAULT_ACCURACY_MM = 1.0
#: steps of the robot program after which the controller cannot plan the next motion ahead
#: (motion type 1): a conditional branch, a loop and a wait; a plain GOTO is none of them
NO_LOOK_AHEAD_STEPS = ("if", "ifgoto", "for", "next")
NO_LOOK_AHEAD_INSTRUCTIONS = ("twait", "break", "tcp_listen", "tcp_accept", "tcp_recv", "tcp_send", "tcp_close",
                              "tcp_end_listen")

Value = float | str | tuple[float, ...]


#: the numeric operators but / and MOD (which check their divisor); comparisons and logic give TRUE or 0
ARITHMETIC: dict[str, Callable[[float, float], float]] = {
    "+": lambda x, y: x + y, "-": lambda x, y: x - y, "*": lambda x, y: x * y,
    "^": lambda x, y: x ** y,
    "and": lambda x, y: TRUE if x and y else 0.0, "or": lambda x, y: TRUE if x or y else 0.0,
    "==": lambda x, y: TRUE if x == y else 0.0, "<>": lambda x, y: TRUE if x != y else 0.0,
    "!=": lambda x, y: TRUE if x != y else 0.0, "<": lambda x, y: TRUE if x < y else 0.0,
    ">": lambda x, y: TRUE if x > y else 0.0, "<=": lambda x, y: TRUE if x <= y else 0.0,
    ">=": lambda x, y: TRUE if x >= y else 0.0,
}


class AsError(Exception):
    """A run-time error: the task stops and the controller shows it (``code`` may be "")."""

    def __init__(self, code: str, text: str):
        super().__init__(f"({code}) {text}" if code else text)
        self.code = code
        self.text = text


def not_defined(name: str) -> AsError:
    # khi_robot_py src/khi_telnet_lib.py: "(E0102) Variable is not defined."
    return AsError("E0102", f"Variable is not defined: {name}")


class Machine(Protocol):
    """What the programs reach of the controller."""

    def now(self) -> float: ...
    def switch(self, name: str) -> bool: ...
    def error_code(self) -> int: ...
    def here(self) -> tuple[float, ...]: ...
    def motion_room(self) -> bool: ...
    def move(self, q: tuple[float, ...], seconds: float, accuracy_mm: float, stop: bool, after_rest: bool) -> None:
        """A motion: ``stop`` it ends at rest (CP OFF, FINE); ``after_rest`` the one before ends at rest."""
    def settled(self) -> bool: ...
    def print_line(self, task: str, text: str) -> None: ...
    def tcp(self, op: str, args: list[Value], started: float) -> tuple[Value, ...] | None: ...
    def program_error(self, task: str, error: AsError) -> None: ...


@dataclass
class Frame:
    program: Program
    pc: int = 0
    locals: dict[str, Value | dict[int, Value]] = field(default_factory=dict)
    out: list[tuple[str, Var]] = field(default_factory=list)  # (parameter, caller's variable) to copy back


@dataclass
class Task:
    name: str  # "robot" or "pc1".."pc5"
    frames: list[Frame]
    state: str = "running"  # running, waiting, completed, halted, aborted, error
    message: str = ""
    started: float = 0.0  # when the waiting step began
    waiting: bool = False
    speed_s: float | None = None  # SPEED ... S for the next JMOVE
    speed_always_s: float | None = None
    look_ahead_lost: bool = False  # a step since the last motion that the controller cannot look past

    @property
    def alive(self) -> bool:
        return self.state in ("running", "waiting")


class Interpreter:
    def __init__(self, programs: dict[str, Program], machine: Machine):
        self.programs = programs
        self.machine = machine
        self.globals: dict[str, Value | dict[int, Value]] = {}
        self.tasks: dict[str, Task] = {}
        self.accuracy = DEFAULT_ACCURACY_MM  # ACCURACY ... ALWAYS
        self.fine = False  # ACCURACY ... FINE ALWAYS
        self.accuracy_next: tuple[float, bool] | None = None  # ACCURACY without ALWAYS: the next motion only
        self.cp = CP_AT_START

    # ---------------------------------------------------------------- tasks
    def start(self, task: str, program: str) -> str:
        """Start ``program`` as ``task`` ("robot", "pc1".."pc5"); "" or why not."""
        prog = self.programs.get(program.lower())
        if prog is None:
            return "Program does not exist."
        if task in self.tasks and self.tasks[task].alive:
            return "PC program is running." if task != "robot" else "Robot control program is already running."
        if prog.params:
            return f"{program} takes parameters"
        self.tasks[task] = Task(task, [Frame(prog)], started=self.machine.now())
        self._run(self.tasks[task])  # it starts at once, up to its first wait
        return ""

    def abort(self, task: str, why: str) -> None:
        t = self.tasks.get(task)
        if t is not None and t.alive:
            t.state, t.message = "aborted", why

    def tick(self) -> None:
        for task in list(self.tasks.values()):
            if task.alive:
                self._run(task)

    def _run(self, task: Task) -> None:
        for _ in range(STEPS_PER_TICK):
            if not task.alive:
                return
            frame = task.frames[-1]
            if frame.pc >= len(frame.program.steps):
                self._return(task)
                continue
            step = frame.program.steps[frame.pc]
            try:
                done = self._execute(task, frame, step)
            except AsError as exc:
                task.state = "error"
                task.message = f"{exc} ({frame.program.name} line {step.line}: {step.text})"
                self.machine.program_error(task.name, exc)
                return
            if not done:
                task.state = "waiting"
                return
            task.state = "running" if task.alive else task.state

    def _return(self, task: Task) -> None:
        frame = task.frames.pop()
        if not task.frames:
            task.state = "completed"
            return
        caller = task.frames[-1]
        for param, var in frame.out:
            value = frame.locals.get(param)
            if value is not None and not isinstance(value, dict):
                self._assign(caller, var, value)
        caller.pc += 1

    # ---------------------------------------------------------------- steps
    def _execute(self, task: Task, frame: Frame, step: Step) -> bool:
        kind = step.kind
        if task.name == "robot" and (kind in NO_LOOK_AHEAD_STEPS
                                     or kind == "instr" and step.name in NO_LOOK_AHEAD_INSTRUCTIONS):
            task.look_ahead_lost = True
        if kind == "assign":
            assert step.target is not None and step.expr is not None
            self._assign(frame, step.target, self.eval(frame, step.expr))
        elif kind == "if":
            assert step.expr is not None
            if not self._truth(frame, step.expr):
                frame.pc = step.jump
                return True
        elif kind == "else":
            frame.pc = step.jump
            return True
        elif kind == "ifgoto":
            assert step.expr is not None
            if self._truth(frame, step.expr):
                frame.pc = frame.program.labels[step.name]
                return True
        elif kind == "goto":
            frame.pc = frame.program.labels[step.name]
            return True
        elif kind == "for":
            assert step.target is not None
            start, stop, by = (self._real(frame, e) for e in step.args)
            self._assign(frame, step.target, start)
            if (start > stop) if by >= 0 else (start < stop):
                frame.pc = step.jump
                return True
        elif kind == "next":
            head = frame.program.steps[step.jump]
            assert head.target is not None
            stop, by = (self._real(frame, e) for e in head.args[1:])
            value = self._as_real(self._read(frame, head.target)) + by
            self._assign(frame, head.target, value)
            if (value <= stop) if by >= 0 else (value >= stop):
                frame.pc = step.jump + 1
                return True
        elif kind == "call":
            self._call(task, frame, step)
            return True
        elif kind == "return":
            self._return(task)
            return True
        elif kind == "halt":
            task.state, task.message = "halted", f"HALT in {frame.program.name}"
            return True
        elif kind == "print":
            self.machine.print_line(task.name, "".join(_text(self.eval(frame, e)) for e in step.args))
        elif kind == "instr" and not self._instruction(task, frame, step):
            return False
        frame.pc += 1
        return True

    def _call(self, task: Task, frame: Frame, step: Step) -> None:
        prog = self.programs.get(step.name)
        if prog is None:
            raise AsError("", f"Program does not exist: {step.name}")
        if len(step.args) != len(prog.params):
            raise AsError("", f"CALL {step.name}: {len(step.args)} arguments for {len(prog.params)} parameters")
        callee = Frame(prog)
        for param, arg in zip(prog.params, step.args, strict=True):
            if isinstance(arg, Var):
                value = self._read(frame, arg, missing_ok=True)
                if value is not None:
                    self._assign(callee, param, value)
                callee.out.append((param.name, arg))
            else:
                self._assign(callee, param, self.eval(frame, arg))
        task.frames.append(callee)

    # ---------------------------------------------------------------- instructions
    def _instruction(self, task: Task, frame: Frame, step: Step) -> bool:
        name, m = step.name, self.machine
        if not task.waiting:
            task.waiting, task.started = True, m.now()
        done = self._instruction_once(task, frame, step, name, m)
        if done:
            task.waiting = False
        return done

    def _instruction_once(self, task: Task, frame: Frame, step: Step, name: str, m: Machine) -> bool:
        if name == "twait":
            seconds = self._real(frame, step.args[0])
            return m.now() - task.started >= seconds
        if name.startswith("tcp_"):
            return self._tcp(task, frame, step)
        if name == "here":
            target = step.args[0]
            if not isinstance(target, Var) or target.kind != "joints":
                raise AsError("", "HERE needs a joint variable (#name)")
            self._assign(frame, target, m.here())
        elif name == "decompose":
            assert step.target is not None
            q = self._read(frame, step.args[0])  # type: ignore[arg-type]
            if not isinstance(q, tuple):
                raise AsError("", "DECOMPOSE needs a position")
            base = self._index(frame, step.target) if step.target.index is not None else 0
            for j, x in enumerate(q):
                self._assign(frame, Var(step.target.name, Num(float(base + j))), x)
        elif name == "speed":
            value = self._real(frame, step.args[0])
            if "s" not in step.words:
                raise AsError("", "rob6's stand-in models SPEED in seconds (S) only")
            if value <= 0:
                raise AsError("", f"SPEED {value:g} S: not a time")
            task.speed_s = value
            if "always" in step.words:
                task.speed_always_s = value
        elif name == "accuracy":
            mm = self._real(frame, step.args[0])
            if mm < 0:
                raise AsError("", f"ACCURACY {mm:g}: not a distance")
            if "always" in step.words:
                self.accuracy, self.fine, self.accuracy_next = mm, "fine" in step.words, None
            else:
                self.accuracy_next = (mm, "fine" in step.words)
        elif name == "cp":
            self.cp = step.words == ["on"]
        elif name == "jmove":
            if task.name != "robot":
                raise AsError("", "a motion instruction in a PC program")
            q = self.eval(frame, step.args[0])
            if not isinstance(q, tuple):
                raise AsError("", "JMOVE needs a joint position")
            if not m.motion_room():
                return False
            seconds = task.speed_s if task.speed_s is not None else 0.0
            task.speed_s = task.speed_always_s
            mm, fine = self.accuracy_next or (self.accuracy, self.fine)
            self.accuracy_next = None
            m.move(q, seconds, mm, fine or not self.cp, task.look_ahead_lost)
            task.look_ahead_lost = False
        elif name == "break":
            return m.settled()
        elif name == "pcexecute":
            number = self._real(frame, step.args[0])
            if number not in (1, 2, 3, 4, 5):
                raise AsError("", f"PCEXECUTE {number:g}: PC programs run as tasks 1 to 5")
            why = self.start(f"pc{int(number)}", step.words[0])
            if why:
                raise AsError("", f"PCEXECUTE {int(number)}: {step.words[0]}: {why}")
        return True

    def _tcp(self, task: Task, frame: Frame, step: Step) -> bool:
        """The TCP instructions: the first argument receives the result, the others are read
        (TCP_RECV's string array and count are written too)."""
        name = step.name
        values: list[Value] = []
        for i, e in enumerate(step.args[1:], start=1):
            if name == "tcp_recv" and i in (2, 3) or name == "tcp_accept" and i == 3:
                values.append(0.0)
            elif name == "tcp_send" and i == 2:
                if not isinstance(e, Var) or e.kind != "string":
                    raise AsError("", "TCP_SEND sends a string array")
                count = int(self._real(frame, step.args[3]))
                values.append("".join(self._element(frame, e, k) for k in range(count)))
            else:
                values.append(self.eval(frame, e))
        result = self.machine.tcp(name, values, task.started)
        if result is None:
            return False
        result_var = step.args[0]
        if not isinstance(result_var, Var):
            raise AsError("", f"{name.upper()}: the result goes into a variable")
        self._assign(frame, result_var, result[0])
        if name == "tcp_recv":
            array, counter = step.args[2], step.args[3]
            assert isinstance(array, Var) and isinstance(counter, Var)
            if array.kind != "string":
                raise AsError("", "TCP_RECV receives into a string array")
            elements = result[1:]
            base = self._index(frame, array) if array.index is not None else 0
            for k, piece in enumerate(elements):
                self._assign(frame, Var(array.name, Num(float(base + k))), piece)
            self._assign(frame, counter, float(len(elements)))
        elif name == "tcp_accept" and len(result) > 1:
            ip = step.args[3]
            assert isinstance(ip, Var)
            base = self._index(frame, ip) if ip.index is not None else 0
            for k, byte in enumerate(result[1:]):
                self._assign(frame, Var(ip.name, Num(float(base + k))), byte)
        return True

    def _element(self, frame: Frame, array: Var, k: int) -> str:
        base = self._index(frame, array) if array.index is not None else 0
        value = self._read(frame, Var(array.name, Num(float(base + k))))
        assert isinstance(value, str)
        return value

    # ---------------------------------------------------------------- variables
    def _scope(self, frame: Frame, var: Var) -> dict[str, Value | dict[int, Value]]:
        return frame.locals if var.local else self.globals

    def _index(self, frame: Frame, var: Var) -> int:
        assert var.index is not None
        x = self._real(frame, var.index)
        if x != int(x) or not 0 <= x <= MAX_INDEX:
            raise AsError("", f"index {x:g} of {var.name} out of range 0..{MAX_INDEX}")
        return int(x)

    def _read(self, frame: Frame, var: Var, missing_ok: bool = False) -> Value | None:
        scope = self._scope(frame, var)
        if var.name not in scope:
            if missing_ok:
                return None
            raise not_defined(var.name if var.index is None else f"{var.name}[]")
        slot = scope[var.name]
        if var.index is None:
            if isinstance(slot, dict):
                raise AsError("", f"{var.name} is an array, used without an index")
            return slot
        if not isinstance(slot, dict):
            raise AsError("", f"{var.name} is not an array")
        index = self._index(frame, var)
        if index not in slot:
            if missing_ok:
                return None
            raise not_defined(f"{var.name}[{index}]")
        return slot[index]

    def _assign(self, frame: Frame, var: Var, value: Value) -> None:
        kind = var.kind
        if kind == "string" and not isinstance(value, str):
            raise AsError("", f"a number assigned to the string variable {var.name}")
        if kind == "real" and not isinstance(value, float):
            raise AsError("", f"{'a string' if isinstance(value, str) else 'a position'} assigned to {var.name}")
        if kind == "joints" and not isinstance(value, tuple):
            raise AsError("", f"not a position assigned to {var.name}")
        if isinstance(value, str) and len(value) > MAX_STRING:
            raise AsError("", f"a string of {len(value)} characters for {var.name} (at most {MAX_STRING})")
        scope = self._scope(frame, var)
        if var.index is None:
            if isinstance(scope.get(var.name), dict):
                raise AsError("", f"{var.name} is an array, assigned without an index")
            scope[var.name] = value
            return
        index = self._index(frame, var)
        slot = scope.setdefault(var.name, {})
        if not isinstance(slot, dict):
            raise AsError("", f"{var.name} is not an array")
        slot[index] = value

    # ---------------------------------------------------------------- expressions
    def eval(self, frame: Frame, e: Expr) -> Value:
        if isinstance(e, Num):
            return e.value
        if isinstance(e, Str):
            return e.value
        if isinstance(e, Var):
            value = self._read(frame, e)
            assert value is not None
            return value
        if isinstance(e, Unary):
            x = self._real(frame, e.operand)
            return -x if e.op == "-" else (0.0 if x else TRUE)
        if isinstance(e, Binary):
            return self._binary(frame, e)
        if isinstance(e, Call):
            return self._function(frame, e)
        raise AsError("", f"{e} is not a value")

    def _binary(self, frame: Frame, e: Binary) -> Value:
        a, b = self.eval(frame, e.left), self.eval(frame, e.right)  # AS evaluates both sides
        op = e.op
        if isinstance(a, str) or isinstance(b, str):
            if not (isinstance(a, str) and isinstance(b, str)):
                raise AsError("", f"a string and a number in {op.upper()}")
            if op == "+":
                return a + b
            if op in ("==", "<>", "!="):
                return TRUE if (a == b) == (op == "==") else 0.0
            raise AsError("", f"{op.upper()} between strings")
        if not isinstance(a, float) or not isinstance(b, float):
            raise AsError("", "a position in arithmetic")
        if op in ("/", "mod"):
            if b == 0:
                raise AsError("", "division by zero")
            return a / b if op == "/" else math.fmod(a, b)
        return ARITHMETIC[op](a, b)

    def _function(self, frame: Frame, e: Call) -> Value:
        name, args = e.name, e.args
        if name in ("true", "on"):
            return TRUE
        if name in ("false", "off"):
            return 0.0
        if name == "error":
            return float(self.machine.error_code())
        if name == "switch":
            word = args[0]
            assert isinstance(word, Name)
            try:
                return TRUE if self.machine.switch(word.word) else 0.0
            except KeyError:
                raise AsError("", f"SWITCH({word.word.upper()}): no such switch") from None
        if name == "#ppoint":
            return tuple(self._real(frame, a) for a in args)
        if name == "$decode":
            return self._decode(frame, args)
        if name == "$encode":
            return self._encode(frame, args)
        if name == "maxval":
            return max(self._real(frame, a) for a in args)
        if name == "abs":
            return abs(self._real(frame, args[0]))
        if name == "$chr":
            code = self._real(frame, args[0])
            if code != int(code) or not 0 <= code <= 255:
                raise AsError("", f"$CHR({code:g}): not a character code")
            return chr(int(code))
        s = self._string(frame, args[1 if name == "instr" and len(args) == 3 else 0])
        if name == "len":
            return float(len(s))
        if name == "val":
            return _val(s)
        if name == "$mid":
            # $MID($s, start[, count]): without a count, the rest of the text
            start = self._real(frame, args[1])
            count = self._real(frame, args[2]) if len(args) == 3 else float(MAX_STRING)
            if start < 1 or count < 0:
                raise AsError("", f"$MID({start:g}, {count:g}): out of range")
            return s[int(start) - 1:int(start) - 1 + int(count)]
        if name == "instr":
            # INSTR([start,] $s, $find): from the text's start without one; 0 and 1 both the first character
            start = self._real(frame, args[0]) if len(args) == 3 else 1.0
            if start < 0:
                raise AsError("", f"INSTR({start:g}, ...): out of range")
            return float(s.find(self._string(frame, args[-1]), max(int(start), 1) - 1) + 1)
        raise AsError("", f"unknown function {name.upper()}")

    def _decode(self, frame: Frame, args: tuple[Expr, ...]) -> str:
        """``$DECODE($var, $separators, mode)``: takes from the front of ``$var`` what comes before
        a separator (mode 0) or the separators themselves (mode 1), and removes it from ``$var``."""
        source = args[0]
        if not isinstance(source, Var) or source.kind != "string":
            raise AsError("", "$DECODE takes its text from a string variable")
        text, seps = self._string(frame, source), self._string(frame, args[1])
        mode = self._real(frame, args[2])
        if mode not in (0, 1):
            raise AsError("", f"$DECODE mode {mode:g}: 0 or 1")
        i = 0
        while i < len(text) and ((text[i] in seps) == (mode == 1)):
            i += 1
        self._assign(frame, source, text[i:])
        return text[:i]

    def _encode(self, frame: Frame, args: tuple[Expr, ...]) -> str:
        out, fmt = [], Fmt("d", 0, 0)
        for a in args:
            if isinstance(a, Fmt):
                fmt = a
                continue
            x = self.eval(frame, a)
            if isinstance(x, str):
                out.append(x)
                continue
            if not isinstance(x, float):
                raise AsError("", "$ENCODE of a position")
            if fmt.kind in ("l", "d"):
                text = f"{round(x)}"
            elif fmt.kind == "f":
                text = f"{x:{fmt.width}.{fmt.decimals}f}"
            else:
                text = f"{x:g}"
            if fmt.width and len(text) > fmt.width:
                raise AsError("", f"$ENCODE: {x:g} does not fit /{fmt.kind.upper()}{fmt.width}")
            out.append(text)
        return "".join(out)

    def _truth(self, frame: Frame, e: Expr) -> bool:
        return self._real(frame, e) != 0

    def _real(self, frame: Frame, e: Expr) -> float:
        return self._as_real(self.eval(frame, e))

    @staticmethod
    def _as_real(x: Value | None) -> float:
        if not isinstance(x, float):
            raise AsError("", "a number expected")
        return x

    def _string(self, frame: Frame, e: Expr) -> str:
        x = self.eval(frame, e)
        if not isinstance(x, str):
            raise AsError("", "a string expected")
        return x

    def type_expr(self, e: Expr) -> Value:
        """``TYPE expr`` at the terminal: an expression over the globals."""
        return self.eval(Frame(Program("type", [], [], {})), e)


def _val(s: str) -> float:
    """VAL: the number at the start of the text (after spaces), 0 when there is none."""
    text = s.lstrip(" ")
    end, seen_digit, seen_dot = 0, False, False
    if text[:1] in "+-" and text[:1]:
        end = 1
    while end < len(text):
        ch = text[end]
        if ch.isdigit():
            seen_digit = True
        elif ch == "." and not seen_dot:
            seen_dot = True
        else:
            break
        end += 1
    return float(text[:end]) if seen_digit else 0.0


def _text(x: Value) -> str:
    if isinstance(x, str):
        return x
    if isinstance(x, tuple):
        return " ".join(f"{v:.3f}" for v in x)
    return f"{x:g}"
