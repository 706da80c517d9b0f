"""The AS language as the controller loads it: a program file read into programs of steps.

The subset rob6's program uses (deploy/kawasaki/REFERENCES.md gives each construct's
source): ``.PROGRAM name(params)`` ... ``.END``; numeric (``10``) and named (``name:``)
labels; assignments to real, string (``$``), local (``.``) and array variables; ``IF
... THEN``/``ELSE``/``END``, ``IF cond GOTO label``, ``FOR v = a TO b [STEP s]``/``END``,
``GOTO``, ``CALL name(args)``, ``RETURN``, ``HALT``, ``PRINT``; the instructions of
``INSTRUCTIONS`` and the functions of ``FUNCTIONS`` with their argument counts; ``;``
comments. Anything else is a syntax error at load, as the controller reports a step it
cannot read ("STEP syntax error") instead of running it.

A program becomes a flat list of steps: blocks are resolved to jumps here, so the
interpreter (asrun.py) only follows indices.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cached_property

# ---------------------------------------------------------------------- tokens
TOKEN = re.compile(r"""
    (?P<ws>[ \t]+)
  | (?P<num>\d+\.\d*|\.\d+|\d+)
  | (?P<str>"[^"]*")
  | (?P<fmt>/[A-Za-z](?:\d+(?:\.\d+)?)?(?![A-Za-z0-9_]))
  | (?P<name>[.]?[$#]?[A-Za-z_][A-Za-z0-9_.]*)
  | (?P<op><>|==|<=|>=|!=|[-+*/()\[\],=<>:^])
""", re.VERBOSE)


class AsSyntaxError(ValueError):
    """A step the controller refuses at load ("STEP syntax error")."""


@dataclass(frozen=True)
class Tok:
    kind: str  # num str fmt name op end
    text: str


def tokenize(text: str) -> list[Tok]:
    out: list[Tok] = []
    pos = 0
    while pos < len(text):
        m = TOKEN.match(text, pos)
        if not m:
            raise AsSyntaxError(f"unreadable character {text[pos]!r}")
        kind = m.lastgroup or ""
        if kind != "ws":
            value = m.group()
            if kind == "name" and len(value.lstrip(".").lstrip("$#")) > MAX_NAME:
                raise AsSyntaxError(f"the name {value.upper()} is longer than {MAX_NAME} characters")
            out.append(Tok(kind, value if kind in ("str", "num") else value.lower()))
        pos = m.end()
    out.append(Tok("end", ""))
    return out


# ---------------------------------------------------------------------- expressions
@dataclass(frozen=True)
class Num:
    value: float


@dataclass(frozen=True)
class Str:
    value: str


@dataclass(frozen=True)
class Var:
    """A variable: ``name`` with its prefixes (``.`` local, ``$`` string, ``#`` joints)."""

    name: str
    index: Expr | None = None

    @cached_property
    def local(self) -> bool:
        return self.name.startswith(".")

    @cached_property
    def kind(self) -> str:
        bare = self.name.lstrip(".")
        return "string" if bare.startswith("$") else "joints" if bare.startswith("#") else "real"


@dataclass(frozen=True)
class Call:
    name: str
    args: tuple[Expr, ...]


@dataclass(frozen=True)
class Unary:
    op: str
    operand: Expr


@dataclass(frozen=True)
class Binary:
    op: str
    left: Expr
    right: Expr


@dataclass(frozen=True)
class Fmt:
    """A ``$ENCODE`` format: ``/F9.3`` (fixed, width 9, 3 decimals), ``/L`` and ``/D`` (a whole
    number, as wide as it is)."""

    kind: str
    width: int
    decimals: int


@dataclass(frozen=True)
class Name:
    """A bare word where one is expected: a switch name, ``ON``/``OFF``, ``S``, ``ALWAYS``."""

    word: str


Expr = Num | Str | Var | Call | Unary | Binary | Fmt | Name

#: the ``$ENCODE`` formats public AS code shows (deploy/kawasaki/REFERENCES.md); ``/In`` is none of them
FORMATS = ("f", "l", "d")
#: the longest name of a variable (without its ``.``, ``$``, ``#``), a program or a label
MAX_NAME = 15
#: functions: name -> (least, most) arguments. ERROR and the constants take none.
FUNCTIONS: dict[str, tuple[int, int]] = {
    "val": (1, 1), "len": (1, 1), "$mid": (2, 3), "instr": (2, 3), "$decode": (3, 3),
    "$encode": (1, 20), "$chr": (1, 1), "maxval": (2, 20), "abs": (1, 1), "switch": (1, 1),
    "error": (0, 0), "true": (0, 0), "false": (0, 0), "on": (0, 0), "off": (0, 0), "#ppoint": (6, 6),
}
#: binary operators by precedence, loosest first
LEVELS = (("or",), ("and",), ("==", "<>", "!=", "<", ">", "<=", ">="), ("+", "-"), ("*", "/", "mod"), ("^",))


class _Parser:
    def __init__(self, toks: list[Tok]):
        self.toks = toks
        self.i = 0

    def peek(self, ahead: int = 0) -> Tok:
        return self.toks[min(self.i + ahead, len(self.toks) - 1)]

    def take(self) -> Tok:
        tok = self.peek()
        self.i += 1
        return tok

    def accept(self, text: str) -> bool:
        if self.peek().text == text and self.peek().kind in ("op", "name"):
            self.i += 1
            return True
        return False

    def expect(self, text: str) -> None:
        if not self.accept(text):
            raise AsSyntaxError(f"expected {text.upper()!r}, found {self.peek().text.upper() or 'the end'!r}")

    def at_end(self) -> bool:
        return self.peek().kind == "end"

    def done(self) -> None:
        if not self.at_end():
            raise AsSyntaxError(f"unexpected {self.peek().text.upper()!r}")

    # ---- expressions
    def expr(self, level: int = 0) -> Expr:
        if level == len(LEVELS):
            return self.unary()
        left = self.expr(level + 1)
        while self.peek().kind in ("op", "name") and self.peek().text in LEVELS[level]:
            op = self.take().text
            left = Binary("==" if op == "=" else op, left, self.expr(level + 1))
        return left

    def unary(self) -> Expr:
        if self.accept("-"):
            return Unary("-", self.unary())
        if self.accept("not"):
            return Unary("not", self.unary())
        return self.atom()

    def atom(self) -> Expr:
        tok = self.take()
        if tok.kind == "num":
            return Num(float(tok.text))
        if tok.kind == "str":
            return Str(tok.text[1:-1])
        if tok.kind == "fmt":
            m = re.fullmatch(r"/([a-z])(\d+)?(?:\.(\d+))?", tok.text)
            assert m is not None
            kind, width = m.group(1), int(m.group(2) or 0)
            if kind not in FORMATS or (kind == "f") != (m.group(3) is not None) or kind != "f" and width:
                raise AsSyntaxError(f"unknown format {tok.text.upper()}")
            return Fmt(kind, width, int(m.group(3) or 0))
        if tok.text == "(":
            inner = self.expr()
            self.expect(")")
            return inner
        if tok.kind != "name":
            raise AsSyntaxError(f"unexpected {tok.text.upper() or 'end of step'!r}")
        word = tok.text
        bare = word.lstrip(".")
        if bare in FUNCTIONS and not word.startswith("."):
            return self.call(bare)
        if bare.startswith("$") and self.peek().text == "(":
            raise AsSyntaxError(f"unknown function {word.upper()}")
        if self.peek().text == "(" and not bare.startswith(("$", "#")):
            raise AsSyntaxError(f"unknown function {word.upper()}")
        if self.accept("["):
            index = self.expr()
            self.expect("]")
            return Var(word, index)
        return Var(word)

    def call(self, name: str) -> Expr:
        least, most = FUNCTIONS[name]
        args: list[Expr] = []
        if self.accept("("):
            if name == "switch":
                tok = self.take()
                if tok.kind != "name":
                    raise AsSyntaxError("SWITCH needs a switch name")
                args.append(Name(tok.text))
            elif not self.accept(")"):
                args.append(self.expr())
                while self.accept(","):
                    args.append(self.expr())
                self.expect(")")
                return self._checked(name, args, least, most)
            self.expect(")")
        return self._checked(name, args, least, most)

    @staticmethod
    def _checked(name: str, args: list[Expr], least: int, most: int) -> Expr:
        if not least <= len(args) <= most:
            want = str(least) if least == most else f"{least} to {most}"
            raise AsSyntaxError(f"{name.upper()} takes {want} arguments, given {len(args)}")
        return Call(name, tuple(args))

    def variable(self) -> Var:
        target = self.atom()
        if not isinstance(target, Var):
            raise AsSyntaxError("a variable expected")
        return target

    def args(self) -> list[Expr]:
        if self.at_end():
            return []
        out = [self.expr()]
        while self.accept(","):
            out.append(self.expr())
        return out


# ---------------------------------------------------------------------- steps
@dataclass
class Step:
    kind: str  # assign if else endif ifgoto for next goto call return halt print instr
    line: int  # the step's line in the file (1-based), for error messages
    text: str
    target: Var | None = None
    expr: Expr | None = None
    args: list[Expr] = field(default_factory=list)
    name: str = ""  # call/instr name, goto label
    jump: int = -1  # if/else: where to go; next: its FOR
    words: list[str] = field(default_factory=list)  # an instruction's trailing words (ALWAYS, S, FINE, ON)


#: instruction -> (least, most) expressions; words they may end with
INSTRUCTIONS: dict[str, tuple[int, int]] = {
    "twait": (1, 1), "tcp_listen": (2, 2), "tcp_accept": (4, 4), "tcp_recv": (6, 6), "tcp_send": (5, 5),
    "tcp_close": (2, 2), "tcp_end_listen": (2, 2), "here": (1, 1), "jmove": (1, 1), "speed": (1, 1),
    "accuracy": (1, 1), "cp": (0, 0), "break": (0, 0), "pcexecute": (1, 1),
}
WORDS = {"speed": ("s", "always"), "accuracy": ("fine", "always"), "cp": ("on", "off")}


@dataclass
class Program:
    name: str
    params: list[Var]
    steps: list[Step]
    labels: dict[str, int]


def _step(text: str, line: int) -> Step:
    p = _Parser(tokenize(text))
    first = p.peek()
    word = first.text
    if word == "if":
        p.take()
        cond = p.expr()
        if p.accept("then"):
            p.done()
            return Step("if", line, text, expr=cond)
        p.expect("goto")
        label = p.take().text
        p.done()
        return Step("ifgoto", line, text, expr=cond, name=label)
    if word in ("else", "end", "return", "halt") and p.peek(1).kind == "end":
        return Step({"end": "endif"}.get(word, word), line, text)
    if word == "for":
        p.take()
        var = p.variable()
        p.expect("=")
        start = p.expr()
        p.expect("to")
        stop = p.expr()
        step: Expr = Num(1.0)
        if p.accept("step"):
            step = p.expr()
        p.done()
        return Step("for", line, text, target=var, args=[start, stop, step])
    if word == "goto":
        p.take()
        label = p.take().text
        p.done()
        return Step("goto", line, text, name=label)
    if word == "call":
        p.take()
        name = p.take().text
        args: list[Expr] = []
        if p.accept("(") and not p.accept(")"):
            args = p.args()
            p.expect(")")
        p.done()
        return Step("call", line, text, name=name, args=args)
    if word == "print":
        p.take()
        return Step("print", line, text, args=p.args())
    if word == "decompose":
        p.take()
        target = p.variable()
        p.expect("=")
        source = p.variable()
        p.done()
        return Step("instr", line, text, name="decompose", target=target, args=[source])
    if word == "pcexecute":
        p.take()
        task = p.expr()
        p.expect(":")
        name = p.take().text
        p.done()
        return Step("instr", line, text, name="pcexecute", args=[task], words=[name])
    if word in INSTRUCTIONS and first.kind == "name":
        p.take()
        allowed = WORDS.get(word, ())
        args = []
        words: list[str] = []
        if word in ("here", "jmove"):
            args = [p.expr()]
        elif word == "cp":
            words = [p.take().text]
        elif not p.at_end():
            args = [p.expr()]
            while p.accept(","):
                args.append(p.expr())
        while p.peek().kind == "name" and p.peek().text in allowed:
            words.append(p.take().text)
        p.done()
        least, most = INSTRUCTIONS[word]
        if not least <= len(args) <= most or (word == "cp" and words not in (["on"], ["off"])):
            raise AsSyntaxError(f"{word.upper()}: wrong arguments")
        return Step("instr", line, text, name=word, args=args, words=words)
    if first.kind == "name" and (p.peek(1).text in ("=", "[")):
        target = p.variable()
        p.expect("=")
        value = p.expr()
        p.done()
        return Step("assign", line, text, target=target, expr=value)
    raise AsSyntaxError(f"unknown instruction {word.upper() or text!r}")


def _label(text: str) -> tuple[str, str]:
    """(label, rest of the step): ``10 step``, ``10``, ``name:``."""
    if m := re.match(r"(\d+)(?:\s+|$)(.*)", text):
        return m.group(1), m.group(2)
    if m := re.fullmatch(r"([A-Za-z_][A-Za-z0-9_.]*):\s*(.*)", text):
        return m.group(1).lower(), m.group(2)
    return "", text


def load(source: str) -> dict[str, Program]:
    """The programs of an AS file (``.PROGRAM`` ... ``.END``); AsSyntaxError names the line."""
    programs: dict[str, Program] = {}
    current: Program | None = None
    blocks: list[tuple[str, int]] = []
    for number, raw in enumerate(source.splitlines(), start=1):
        text = _strip_comment(raw).strip()
        if not text:
            continue
        try:
            if m := re.fullmatch(r"\.PROGRAM\s+([A-Za-z_][A-Za-z0-9_.]*)\s*\(([^)]*)\)\s*(?:#\d+)?", text,
                                 re.IGNORECASE):
                if current is not None:
                    raise AsSyntaxError(f".PROGRAM inside {current.name}")
                if len(m.group(1)) > MAX_NAME:
                    raise AsSyntaxError(f"the program name {m.group(1)} is longer than {MAX_NAME} characters")
                params = [_param(p) for p in m.group(2).split(",") if p.strip()]
                current = Program(m.group(1).lower(), params, [], {})
                blocks = []
                continue
            if text.upper() == ".END":
                if current is None:
                    raise AsSyntaxError(".END outside a program")
                if blocks:
                    raise AsSyntaxError(f"{blocks[-1][0].upper()} without END in {current.name}")
                _check_labels(current)
                programs[current.name] = current
                current = None
                continue
            if current is None:
                raise AsSyntaxError("a step outside every program")
            label, rest = _label(text)
            if label:
                if label in current.labels:
                    raise AsSyntaxError(f"label {label} twice")
                current.labels[label] = len(current.steps)
            if rest:
                _add(current, _step(rest, number), blocks)
        except AsSyntaxError as exc:
            raise AsSyntaxError(f"line {number}: {exc}: {raw.strip()}") from None
    if current is not None:
        raise AsSyntaxError(f"{current.name} has no .END")
    return programs


def _add(prog: Program, step: Step, blocks: list[tuple[str, int]]) -> None:
    index = len(prog.steps)
    prog.steps.append(step)
    if step.kind in ("if", "for"):
        blocks.append((step.kind, index))
    elif step.kind == "else":
        if not blocks or blocks[-1][0] != "if":
            raise AsSyntaxError("ELSE without IF")
        prog.steps[blocks[-1][1]].jump = index + 1
        blocks[-1] = ("else", index)
    elif step.kind == "endif":
        if not blocks:
            raise AsSyntaxError("END without IF or FOR")
        kind, opened = blocks.pop()
        if kind == "for":
            step.kind = "next"
            step.jump = opened
            prog.steps[opened].jump = index + 1
        else:
            prog.steps[opened].jump = index + 1 if kind == "if" else index + 1


def _check_labels(prog: Program) -> None:
    for step in prog.steps:
        if step.kind in ("goto", "ifgoto") and step.name not in prog.labels:
            raise AsSyntaxError(f"GOTO {step.name}: no such label in {prog.name}")


def _param(text: str) -> Var:
    toks = tokenize(text.strip())
    if len(toks) != 2 or toks[0].kind != "name" or not toks[0].text.startswith("."):
        raise AsSyntaxError(f"a parameter must be a local variable: {text.strip()!r}")
    return Var(toks[0].text)


def _strip_comment(raw: str) -> str:
    """The step without its ``;`` comment (a ``;`` inside a string stays)."""
    quoted = False
    for i, ch in enumerate(raw):
        if ch == '"':
            quoted = not quoted
        elif ch == ";" and not quoted:
            return raw[:i]
    return raw
