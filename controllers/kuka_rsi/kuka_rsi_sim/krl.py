"""A strict KRL interpreter for the statements an RSI program uses: the controller runs the shipped .src/.dat.

The program is parsed when it is selected: a statement outside this small set is an error
(as a program with an error cannot be selected on the controller), so a typo or a new
statement in the shipped program fails here instead of being ignored. Running it is a
generator: each statement that takes time (a motion, RSI_MOVECORR, an operator's
confirmation) yields a ``Wait`` that the controller's loop resolves, so the program's own
control flow decides what the controller does after a Stop, a HALT or an error.

Statements: DECL INT/BOOL/REAL, the BASISTECH INI lines (GLOBAL INTERRUPT DECL ... IR_STOPM,
INTERRUPT ON, BAS), PTP ($AXIS_ACT, an E6AXIS variable or aggregate), WAIT SEC,
``x = RSI_CREATE(name, id, TRUE|FALSE)``, ``x = RSI_ON(#ABSOLUTE|#RELATIVE[, #IPO_FAST|#IPO])``
(the sensor mode defaults to #IPO_FAST),
``RSI_MOVECORR()``, ``x = RSI_OFF()``, ``x = RSI_DELETE(id)``, IF/ELSE/ENDIF, LOOP/ENDLOOP,
HALT. The .dat: DECL BOOL/INT/REAL/E6AXIS with a value, DECL CHAR x[n] then x[]="...".
"""

from __future__ import annotations

import re
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
RSIOK = "RSIOK"  # the return value of a successful RSI command (its number is not modelled)
IPO_CYCLES = {"#IPO_FAST": 4, "#IPO": 12}
#: RSI_ON's sensor mode when the call names none (rsi-pi RSIPI_Minimal.src, quoting the RSI 3.3 manual)
DEFAULT_IPO_MODE = "#IPO_FAST"


class KrlError(ValueError):
    """The program or its data list cannot be selected (line and reason in the message)."""


class ProgramStop(Exception):
    """The controller stops the program with a message (e.g. KSS01443)."""


@dataclass(frozen=True)
class Wait:
    """What the running program waits for: ``ptp`` (target), ``movecorr``, ``confirm``,
    ``sec`` (seconds), ``rsi_off`` (takes effect with the next IPO cycle)."""

    kind: str
    value: Any = None


class Controller(Protocol):
    """What the program asks of the controller it runs on."""

    def axis_act(self) -> list[float]: ...
    def rsi_create(self, name: str, permanent: bool) -> tuple[str, int]: ...
    def rsi_on(self, mode: str, ipo_mode: str) -> str: ...
    def rsi_off(self) -> str: ...
    def rsi_delete(self, cont_id: int) -> str: ...
    def needs_confirm(self) -> bool: ...


@dataclass
class Stmt:
    line: int
    text: str
    kind: str
    args: tuple[Any, ...] = ()
    body: list[Stmt] = field(default_factory=list)
    orelse: list[Stmt] = field(default_factory=list)


_IDENT = r"[A-Za-z_$][\w$]*"
_SIMPLE = [
    ("decl", re.compile(rf"DECL\s+(INT|BOOL|REAL)\s+({_IDENT})$", re.I)),
    ("nop", re.compile(r"GLOBAL\s+INTERRUPT\s+DECL\s+3\s+WHEN\s+\$STOPMESS\s*==\s*TRUE\s+DO\s+IR_STOPM\s*\(\s*\)$",
                       re.I)),
    ("nop", re.compile(r"INTERRUPT\s+ON\s+3$", re.I)),
    ("nop", re.compile(r"BAS\s*\(\s*#INITMOV\s*,\s*0\s*\)$", re.I)),
    ("bas_vel", re.compile(rf"BAS\s*\(\s*#VEL_PTP\s*,\s*({_IDENT}|\d+)\s*\)$", re.I)),
    ("ptp", re.compile(r"PTP\s+(.+)$", re.I)),
    ("wait_sec", re.compile(r"WAIT\s+SEC\s+(\d+(?:\.\d*)?)$", re.I)),
    ("rsi_create", re.compile(rf"({_IDENT})\s*=\s*RSI_CREATE\s*\(\s*(\"[^\"]*\"|{_IDENT}\[\])\s*,\s*({_IDENT})"
                              r"\s*,\s*(TRUE|FALSE)\s*\)$", re.I)),
    ("rsi_on", re.compile(rf"({_IDENT})\s*=\s*RSI_ON\s*\(\s*(#ABSOLUTE|#RELATIVE)\s*(?:,\s*(#IPO_FAST|#IPO))?\s*\)$",
                          re.I)),
    ("movecorr", re.compile(r"RSI_MOVECORR\s*\(\s*\)$", re.I)),
    ("rsi_off", re.compile(rf"({_IDENT})\s*=\s*RSI_OFF\s*\(\s*\)$", re.I)),
    ("rsi_delete", re.compile(rf"({_IDENT})\s*=\s*RSI_DELETE\s*\(\s*({_IDENT})\s*\)$", re.I)),
    ("halt", re.compile(r"HALT$", re.I)),
]
_IF = re.compile(r"IF\s+(.+?)\s+THEN$", re.I)
_COND_RET = re.compile(rf"\(?\s*({_IDENT})\s*(<>|==)\s*RSIOK\s*\)?$", re.I)
_COND_BOOL = re.compile(rf"\(?\s*(NOT\s+)?({_IDENT})\s*\)?$", re.I)
_AGGREGATE = re.compile(r"\{(.*)\}$")


@dataclass
class Program:
    name: str
    body: list[Stmt]
    data: dict[str, Any]  # the .dat's variables (names upper-case: KRL is case-insensitive)


def parse_program(src: str, dat: str, name: str) -> Program:
    data = _parse_dat(dat, name)
    lines = _lines(src)
    i = _opening(lines, rf"DEF\s+{re.escape(name)}\s*\(\s*\)", f"{name}.src: the program must start with DEF {name}( )")
    body, i, end = _block(lines, i + 1, ("END",))
    if end != "END":
        raise KrlError(f"{name}.src: no END")
    if i < len(lines):
        raise KrlError(f"{name}.src line {lines[i][0]}: {lines[i][1]!r} after END")
    _check_names(body, data, name)
    return Program(name, body, data)


def _lines(text: str) -> list[tuple[int, str]]:
    out = []
    for number, raw in enumerate(text.splitlines(), 1):
        code = raw.split(";", 1)[0].strip()
        if code:
            out.append((number, code))
    return out


def _block(lines: list[tuple[int, str]], i: int, ends: tuple[str, ...]) -> tuple[list[Stmt], int, str]:
    body: list[Stmt] = []
    while i < len(lines):
        number, text = lines[i]
        word = text.split()[0].upper()
        if word in ends and text.upper() == word:
            return body, i + 1, word
        m = _IF.fullmatch(text)
        if m:
            cond = _condition(m.group(1), number)
            then, i, end = _block(lines, i + 1, ("ELSE", "ENDIF"))
            orelse: list[Stmt] = []
            if end == "ELSE":
                orelse, i, end = _block(lines, i, ("ENDIF",))
            if end != "ENDIF":
                raise KrlError(f"line {number}: IF without ENDIF")
            body.append(Stmt(number, text, "if", cond, then, orelse))
            continue
        if text.upper() == "LOOP":
            loop, i, end = _block(lines, i + 1, ("ENDLOOP",))
            if end != "ENDLOOP":
                raise KrlError(f"line {number}: LOOP without ENDLOOP")
            body.append(Stmt(number, text, "loop", (), loop))
            continue
        for kind, pattern in _SIMPLE:
            m = pattern.fullmatch(text)
            if m:
                body.append(Stmt(number, text, kind, m.groups()))
                break
        else:
            raise KrlError(f"line {number}: {text!r} is not a statement the stand-in's KRL knows")
        i += 1
    return body, i, ""


def _condition(text: str, number: int) -> tuple[str, ...]:
    m = _COND_RET.fullmatch(text)
    if m:
        return ("ret", m.group(1).upper(), m.group(2))
    m = _COND_BOOL.fullmatch(text)
    if m:
        return ("bool", m.group(2).upper(), "not" if m.group(1) else "")
    raise KrlError(f"line {number}: condition {text!r} is not one the stand-in's KRL knows")


def _opening(lines: list[tuple[int, str]], pattern: str, error: str) -> int:
    """The index of a file's opening line (after the editor's ``&`` header lines), which must
    match ``pattern``; else ``error``."""
    i = 0
    while i < len(lines) and lines[i][1].startswith("&"):
        i += 1
    if i >= len(lines) or not re.fullmatch(pattern, lines[i][1], re.I):
        raise KrlError(error)
    return i


def _parse_dat(text: str, name: str) -> dict[str, Any]:
    lines = _lines(text)
    i = _opening(lines, rf"DEFDAT\s+{re.escape(name)}(\s+PUBLIC)?", f"{name}.dat: the data list must start with DEFDAT {name}")
    data: dict[str, Any] = {}
    chars: dict[str, int] = {}
    for number, code in lines[i + 1:]:
        if code.upper() == "ENDDAT":
            return data
        m = re.fullmatch(rf"DECL\s+(BOOL|INT|REAL|E6AXIS)\s+({_IDENT})\s*=\s*(.+)", code, re.I)
        if m:
            data[m.group(2).upper()] = _value(m.group(1).upper(), m.group(3), f"{name}.dat line {number}")
            continue
        m = re.fullmatch(rf"DECL\s+CHAR\s+({_IDENT})\[(\d+)\]", code, re.I)
        if m:
            chars[m.group(1).upper()] = int(m.group(2))
            continue
        m = re.fullmatch(rf"({_IDENT})\[\]\s*=\s*\"([^\"]*)\"", code)
        if m and m.group(1).upper() in chars:
            if len(m.group(2)) > chars[m.group(1).upper()]:
                raise KrlError(f"{name}.dat line {number}: {m.group(2)!r} is longer than {m.group(1)}")
            data[m.group(1).upper()] = m.group(2)
            continue
        raise KrlError(f"{name}.dat line {number}: {code!r} is not a declaration the stand-in's KRL knows")
    raise KrlError(f"{name}.dat: no ENDDAT")


def _value(kind: str, text: str, where: str) -> Any:
    text = text.strip()
    try:
        if kind == "BOOL":
            if text.upper() not in ("TRUE", "FALSE"):
                raise ValueError
            return text.upper() == "TRUE"
        if kind == "INT":
            return int(text)
        if kind == "REAL":
            return float(text)
        return _aggregate(text)
    except ValueError:
        raise KrlError(f"{where}: {text!r} is not a {kind}") from None


def _aggregate(text: str) -> list[float]:
    m = _AGGREGATE.fullmatch(text.strip())
    if not m:
        raise ValueError(text)
    values = {}
    for part in m.group(1).split(","):
        key, _, value = part.strip().partition(" ")
        values[key.upper()] = float(value)
    if any(a not in values for a in AXES) or set(values) - set(AXES) - {f"E{n}" for n in range(1, 7)}:
        raise ValueError(text)
    return [values[a] for a in AXES]


def _check_names(body: Sequence[Stmt], data: dict[str, Any], name: str) -> None:
    """Every variable used is declared (a typo is a compile error on the controller)."""
    declared = set(data)
    for stmt in _walk(body):
        if stmt.kind == "decl":
            declared.add(stmt.args[1].upper())
    for stmt in _walk(body):
        used: list[str] = []
        if stmt.kind in ("rsi_create",):
            used = [stmt.args[0], stmt.args[2]] + ([stmt.args[1][:-2]] if stmt.args[1].endswith("[]") else [])
        elif stmt.kind in ("rsi_on", "rsi_off"):
            used = [stmt.args[0]]
        elif stmt.kind == "rsi_delete":
            used = [stmt.args[0], stmt.args[1]]
        elif stmt.kind == "if":
            used = [stmt.args[1]]
        elif stmt.kind == "bas_vel" and not stmt.args[0].isdigit():
            used = [stmt.args[0]]
        elif stmt.kind == "ptp" and not stmt.args[0].strip().startswith(("{", "$")):
            used = [stmt.args[0].strip()]
        for var in used:
            if var.upper() not in declared:
                raise KrlError(f"{name}.src line {stmt.line}: {var} is not declared")


def _walk(body: Sequence[Stmt]) -> Generator[Stmt, None, None]:
    for stmt in body:
        yield stmt
        yield from _walk(stmt.body)
        yield from _walk(stmt.orelse)


#: a block selection's way to its line: (statement index, branch it goes on into: "body", "orelse", or None)
Path = list[tuple[int, str | None]]


def run(program: Program, ctl: Controller, start_line: int | None = None) -> Generator[Wait, None, str]:
    """Execute the program (from ``start_line``: a block selection); yields what it waits for
    and returns how it ended: ``"END"`` or ``"HALT at line N"``. Raises ProgramStop."""
    variables: dict[str, Any] = dict(program.data)
    path = None
    if start_line is not None:
        path = _path_to(program.body, start_line)
        if path is None:
            raise ProgramStop(f"block selection: line {start_line} holds no statement")
    result = yield from _exec(program.body, variables, ctl, path)
    return result or "END"


def _path_to(body: Sequence[Stmt], line: int) -> Path | None:
    for k, stmt in enumerate(body):
        if stmt.line == line:
            return [(k, None)]
        for branch in ("body", "orelse"):
            inner = _path_to(getattr(stmt, branch), line)
            if inner is not None:
                return [(k, branch), *inner]
    return None


def _exec(body: Sequence[Stmt], v: dict[str, Any], ctl: Controller,
          path: Path | None) -> Generator[Wait, None, str | None]:
    first, into = path[0] if path else (0, None)
    for k in range(first, len(body)):
        stmt, a = body[k], body[k].args
        inner = path[1:] if path and k == first and into else None
        kind = stmt.kind
        if kind == "decl":
            v[a[1].upper()] = None
        elif kind == "bas_vel":
            if not a[0].isdigit():
                _read(v, a[0], stmt)
        elif kind == "ptp":
            yield Wait("ptp", _target(a[0].strip(), v, ctl, stmt))
        elif kind == "wait_sec":
            yield Wait("sec", float(a[0]))
        elif kind == "rsi_create":
            name = a[1][1:-1] if a[1].startswith('"') else _read(v, a[1][:-2], stmt)
            ret, cont_id = ctl.rsi_create(str(name), a[3].upper() == "TRUE")
            v[a[0].upper()], v[a[2].upper()] = ret, cont_id
        elif kind == "rsi_on":
            if ctl.needs_confirm():
                yield Wait("confirm", stmt.line)
            v[a[0].upper()] = ctl.rsi_on(a[1].upper(), (a[2] or DEFAULT_IPO_MODE).upper())
        elif kind == "movecorr":
            yield Wait("movecorr")
        elif kind == "rsi_off":
            v[a[0].upper()] = ctl.rsi_off()
            yield Wait("rsi_off")
        elif kind == "rsi_delete":
            v[a[0].upper()] = ctl.rsi_delete(_read(v, a[1], stmt))
        elif kind == "halt":
            return f"HALT at line {stmt.line}"
        elif kind == "if":
            if inner is not None:  # a block selection into this IF: that branch, no condition
                branch = stmt.body if into == "body" else stmt.orelse
            else:
                branch = stmt.body if _true(a, v, stmt) else stmt.orelse
            result = yield from _exec(branch, v, ctl, inner)
            if result:
                return result
        elif kind == "loop":
            while True:
                result = yield from _exec(stmt.body, v, ctl, inner)
                inner = None
                if result:
                    return result
    return None


def _read(v: dict[str, Any], name: str, stmt: Stmt) -> Any:
    value = v.get(name.upper())
    if value is None:
        raise ProgramStop(f"line {stmt.line}: variable {name} has no value")
    return value


def _true(cond: tuple[str, ...], v: dict[str, Any], stmt: Stmt) -> bool:
    if cond[0] == "ret":
        ok = _read(v, cond[1], stmt) == RSIOK
        return not ok if cond[2] == "<>" else ok
    value = _read(v, cond[1], stmt)
    if not isinstance(value, bool):
        raise ProgramStop(f"line {stmt.line}: {cond[1]} is not a BOOL")
    return not value if cond[2] == "not" else value


def _target(text: str, v: dict[str, Any], ctl: Controller, stmt: Stmt) -> list[float]:
    if text.upper() == "$AXIS_ACT":
        return ctl.axis_act()
    if text.startswith("{"):
        try:
            return _aggregate(text)
        except ValueError:
            raise ProgramStop(f"line {stmt.line}: {text!r} is not an E6AXIS") from None
    value = _read(v, text, stmt)
    if not isinstance(value, list):
        raise ProgramStop(f"line {stmt.line}: {text} is not an E6AXIS")
    return list(value)
