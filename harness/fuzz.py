"""The gateway fuzzing's building blocks: input generators, reply checks and the fuzzers.

The in-process checks of the framer, the argument parser and the command dispatch, and the
TCP fuzzer that drives a real system.

The invariants (every fuzzed input):

* in process: ``Framer`` output is independent of how the byte stream is chunked and equals a
  simple reference split (line too long iff it exceeds ``max_line``); ``Args`` never raises
  anything but ``ParseError``, never returns nan/inf, its cursor only moves forward;
  ``Gateway.execute`` of any line (with a bus whose every call fails) returns a well-formed
  reply (see ``reply_problem``) and never raises (``Close`` only for Quit/Shutdown);
* through TCP: each fuzzed line is followed by a ``CM_PING`` sentinel and the reply read up to
  ``PONG`` (bounded timeouts: a missing reply is a hang); the reply is well formed; the gateway
  pid stays the same and alive; the connection stays up (except after ``Quit``); its memory
  (VmRSS) stays bounded; the joint state stays inside the widest turn limits ever configured.

The fast suite (``tests/reliability/``) runs them with small budgets; the larger campaign of
RELIABILITY.md (``python -m bench.reliability``) imports them from here.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import random
import socket
import threading
import time
from dataclasses import dataclass, field
from itertools import pairwise
from typing import NoReturn, cast

from hypothesis import strategies as st

from harness.system import System
from rob6.bus import Bus
from rob6.robots import get_robot
from rob6.status import STATUS_WORDS as _CATEGORIES
from rob6_gateway.args import Args, ParseError
from rob6_gateway.commands import COMMANDS, GRIPPER_REPLY_LINES, Close, Gateway, Options, _split_command
from rob6_gateway.framing import Framer, _clean
from rob6_gateway.state import Session

COMMAND_NAMES = sorted(COMMANDS)
STATUS_WORDS = [word for category in _CATEGORIES for word in category]
NUMBER_TOKENS = ["0", "-0", "-0.0", "1", "-1", "10", "90", "-170", "180", "360", "1e1", ".5", "2.5",
                 "1e308", "-1e308", "1e309", "1e400", "nan", "NaN", "inf", "-inf", "Infinity",
                 "4.9e-324", "10abc", "+5", "--5", "1e", "0x10", "999999999999999999999", "3", "4"]
ODD_TOKENS = ["", "\t", "\x0b", "\x0c", "\r", "é", "\xff", "\x80", "ü", "\x00", "true", "false",
              "CM_PING", "Hello Robot"]
PONG = b"PONG"
EXTREMES_TCP = ["nan", "inf", "-inf", "1e308", "-1e308", "1e309", "-0", "4.9e-324", "10abc"]


# ============================================================== reply checking
def reply_problem(line_text: str, reply: str | None) -> str | None:
    """None if ``reply`` is one well-formed reply to the command line ``line_text``."""
    lines = [] if not reply else reply.split("\n")
    if lines:
        if lines[-1] != "":
            return f"reply does not end with a newline: {reply!r}"
        lines = lines[:-1]
    if line_text == "":
        return None if not lines else f"empty line answered: {reply!r}"
    name = _split_command(line_text)[0]
    if not lines:
        return None if name == "SetAllowedStatus" else "no reply"
    if len(lines) == 1:
        return None
    if len(lines) == GRIPPER_REPLY_LINES.get(name):  # the gripper's fixed counts (docs/COMPATIBILITY.md)
        info, last = lines[:-1], lines[-1]
        if last in ("true", "false") and not {"true", "false"} & set(info):
            return None
    if len(lines) == 2:
        if lines[0].startswith("ERROR:") and lines[1] == "false":
            return None
        if name in ("ForwardCalc", "Shutdown"):
            return None
    return f"{len(lines)} lines for {name!r}: {reply!r}"


# ============================================================== input generators
def _args_strategy() -> st.SearchStrategy[str]:
    token = st.one_of(st.sampled_from(NUMBER_TOKENS), st.sampled_from(STATUS_WORDS),
                      st.sampled_from(ODD_TOKENS),
                      st.floats(allow_nan=True, allow_infinity=True).map(repr),
                      st.floats(allow_nan=False, allow_infinity=False).map(lambda x: "%g" % x),
                      st.integers(-10**30, 10**30).map(str),
                      st.text(st.characters(min_codepoint=1, max_codepoint=255, blacklist_characters="\n"),
                              max_size=8))
    sep = st.sampled_from([" ", "  ", "\t", " \r", ""])
    return st.lists(st.tuples(sep, token), max_size=16).map(lambda ts: "".join(s + t for s, t in ts))


def command_line_strategy() -> st.SearchStrategy[str]:
    """A text line (latin-1, no newline): mostly a known command with random arguments."""
    name = st.one_of(st.sampled_from(COMMAND_NAMES),
                     st.sampled_from(COMMAND_NAMES).map(str.lower),
                     st.sampled_from(COMMAND_NAMES).map(lambda n: n[:-1]),
                     st.text(st.characters(min_codepoint=1, max_codepoint=255, blacklist_characters="\n"),
                             max_size=12))
    lead = st.sampled_from(["", "", "", " ", "\t", "\r"])
    plain = st.builds(lambda lead_, n, a: lead_ + n + a, lead, name, _args_strategy())
    truncated = st.builds(lambda s, f: s[:int(len(s) * f)], plain, st.floats(0, 1))
    with_nul = st.builds(lambda s, i: s[:i] + "\x00" + s[i:], plain, st.integers(0, 40))
    raw = st.binary(max_size=64).map(lambda b: b.replace(b"\n", b"").decode("latin-1"))
    move = st.builds(lambda n, q: n + "".join(" %.3f" % x for x in q), st.sampled_from(MOVES),
                     st.lists(st.floats(-120, 120), min_size=6, max_size=6))
    return st.one_of(plain, plain, plain, truncated, with_nul, raw, move)


MOVES = ("MovePTPJoints", "RoutetestJoints", "MoveRTJoints", "DoAlterJoint")


def _plausible_move(rng: random.Random) -> str:
    """A joint move that may well succeed (so the limit invariant is exercised)."""
    return rng.choice(MOVES) + "".join(" %.3f" % rng.uniform(-120, 120) for _ in range(6))


def _random_line(rng: random.Random) -> str:
    """The same distribution without hypothesis (for bulk volume)."""
    r = rng.random()
    if r > 0.9:
        return _plausible_move(rng)
    if r < 0.1:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(64))).replace(b"\n", b"").decode("latin-1")
    name = rng.choice(COMMAND_NAMES)
    if r < 0.15:
        name = name.lower()
    elif r < 0.2:
        name = name[:rng.randrange(len(name) + 1)]
    tokens = []
    for _ in range(rng.choice([0, 1, 2, 5, 6, 7, 12, 13, 14, 15, 20])):
        k = rng.random()
        if k < 0.45:
            tokens.append(rng.choice(NUMBER_TOKENS))
        elif k < 0.65:
            tokens.append("%.6g" % rng.uniform(-400, 400))
        elif k < 0.85:
            tokens.append(rng.choice(STATUS_WORDS))
        else:
            tokens.append(rng.choice(ODD_TOKENS))
    line = name + "".join(rng.choice([" ", "\t", "  "]) + t for t in tokens)
    if rng.random() < 0.1:
        line = line[:rng.randrange(len(line) + 1)]
    if rng.random() < 0.05:
        i = rng.randrange(len(line) + 1)
        line = line[:i] + "\x00" + line[i:]
    return line.replace("\n", "")


# ============================================================== in-process: framer
def reference_lines(stream: bytes, max_line: int) -> list[tuple[str, int]]:
    """How the stream must be framed, whatever the chunking: (text, too_long) per line."""
    parts = stream.split(b"\n")
    out = []
    for i, seg in enumerate(parts):
        last = i == len(parts) - 1
        if last and not seg:
            break
        if len(seg) > max_line:
            out.append(("", len(seg) + (0 if last else 1)))
        else:
            out.append((_clean(seg), 0))
    return out


def check_framer(stream: bytes, cuts: list[int], max_line: int) -> None:
    framer = Framer(max_line)
    got = []
    points = sorted({min(max(c, 0), len(stream)) for c in cuts} | {0, len(stream)})
    for a, b in pairwise(points):
        got += framer.feed(stream[a:b])
        assert len(framer._buffer) <= max_line, "framer buffer above max_line"
    got += framer.flush()
    assert not framer.pending()
    assert [(line.text, line.too_long) for line in got] == reference_lines(stream, max_line), \
        (stream, cuts, max_line)


# ============================================================== in-process: args
def check_args(text: str) -> None:
    methods = ("double", "integer", "word", "status", "joints", "matrix", "value", "index",
               "leading_doubles", "at_end")
    for method in methods:
        args = Args(text)
        last = 0
        for _ in range(4):
            try:
                result = getattr(args, method)(6) if method == "leading_doubles" else getattr(args, method)()
            except ParseError:
                result = None
            assert 0 <= last <= args.pos <= len(text)
            last = args.pos
            values = result if isinstance(result, list) else [result]
            for v in values:
                if isinstance(v, float):
                    assert math.isfinite(v), (text, method, v)


# ============================================================== in-process: command dispatch
class _Nothing:
    """A subscription that never receives anything."""

    def take(self) -> list[bytes]:
        return []


class _DeadBus:
    """Every request fails like a missing service; subscriptions are ignored."""

    #: the gateway names its sessions with its own instance id (a move carries it)
    instance = "fuzz-gateway"

    def __init__(self) -> None:
        from rob6.bus import BusError
        self._error = BusError
        self.closed = threading.Event()
        self.closed.set()  # closed from the start: no thread of the gateway waits on it

    def subscribe(self, *a: object, **k: object) -> None:
        pass

    def subscribe_latest(self, *a: object, **k: object) -> _Nothing:
        return _Nothing()

    def on_liveliness(self, *a: object, **k: object) -> None:
        pass

    def publish(self, *a: object, **k: object) -> None:
        pass

    def instances(self, *a: object, **k: object) -> list[str]:
        return []

    def request(self, service: str, op: str, body: object, **kwargs: object) -> NoReturn:
        raise self._error("unavailable", f"{service} unavailable")


#: a gateway whose every bus call fails, and a session of it
DeadGateway = tuple[Gateway, Session]


def make_dead_gateway(robot: str = "kr16") -> DeadGateway:
    logging.getLogger("rob6").setLevel(logging.CRITICAL)  # every call fails: thousands of warnings
    gateway = Gateway(cast(Bus, _DeadBus()), get_robot(robot), Options())  # the part of a Bus it uses
    return gateway, Session(number=1, peer="fuzz")


def check_execute(gateway: Gateway, session: Session, text: str) -> None:
    if text == "":
        return  # the server answers empty lines itself (with nothing); they never reach execute
    try:
        reply = gateway.execute(session, text)
    except Close as exc:
        assert _split_command(text)[0] in ("Quit", "Shutdown"), text
        reply = exc.reply
    problem = reply_problem(text, reply)
    assert problem is None, (text, problem)
    reply.encode("latin-1") if reply else None  # the server encodes replies as latin-1


# ============================================================== through TCP
class FuzzClient:
    def __init__(self, port: int, timeout: float = 15.0) -> None:
        self.port, self.timeout = port, timeout
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buffer = b""
        assert self.read_line() == b"welcome to rob6server 0.1.01 !"
        self.sock.sendall(b"Hello Robot\n")
        assert self.read_line() == b"accepted"

    def read_line(self) -> bytes:
        deadline = time.monotonic() + self.timeout
        while b"\n" not in self.buffer:
            if time.monotonic() > deadline:
                raise TimeoutError("no complete line (hang)")
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise ConnectionError("connection closed by the gateway")
            self.buffer += chunk
        line, _, self.buffer = self.buffer.partition(b"\n")
        return line

    def until_pong(self, pongs: int = 1) -> list[bytes]:
        """Every line before the ``pongs``-th ``PONG`` line."""
        lines: list[bytes] = []
        while True:
            line = self.read_line()
            if line == PONG:
                pongs -= 1
                if pongs == 0:
                    return lines
            lines.append(line)

    def close(self) -> None:
        self.sock.close()


def vm_rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


TURN_COMMANDS = ("SetJointsMaxTurnMax", "SetJointsMaxTurnMin", "SetSingleJointMaxTurnMax",
                 "SetSingleJointMaxTurnMin", "ResetJointsMaxTurn")


def _blocking_ping(text: str) -> bool:
    """PingRobot n wait blocks the session n*wait ms by design (up to 1000 s): not a fuzz target."""
    name, _, rest = _split_command(_clean(text.encode("latin-1")))
    if name != "PingRobot":
        return False
    args = Args(rest)
    n = args.integer() if not args.at_end() else 10
    wait = args.double() if not args.at_end() else 0.0
    return n is not None and wait is not None and n * max(wait, 0) > 2000 or (n or 0) > 200


@dataclass
class TcpFuzzer:
    """Drives one session of a running system; counts and checks everything it sends."""

    system: System
    _client: FuzzClient | None = None
    gateway_pid: int = 0
    inputs: int = 0
    hangs: int = 0
    problems: list[tuple[object, ...]] = field(default_factory=list)
    reconnects: int = 0
    turn_lo: list[float] = field(default_factory=list)
    turn_hi: list[float] = field(default_factory=list)
    limit_violations: int = 0
    moves_ok: int = 0
    rss0: int = 0  # the gateway's VmRSS (KiB) before the fuzzing, for the caller to set

    @property
    def client(self) -> FuzzClient:
        assert self._client is not None, "start() first"
        return self._client

    def start(self) -> None:
        self.gateway_pid = self.system.pids()["gateway"]
        self._client = FuzzClient(self.system.port)
        self._update_envelope()

    def ask(self, command: str) -> list[bytes]:
        self.client.sock.sendall(command.encode() + b"\nCM_PING\n")
        return self.client.until_pong()

    def _numbers(self, command: str) -> list[float]:
        self.client.sock.sendall(command.encode() + b"\nCM_PING\n")
        lines = self.client.until_pong()
        return [float(x) for x in lines[0].split()]

    def _update_envelope(self) -> None:
        lo, hi = self._numbers("GetJointsMaxTurnMin"), self._numbers("GetJointsMaxTurnMax")
        self.turn_lo = lo if not self.turn_lo else [min(a, b) for a, b in zip(self.turn_lo, lo, strict=True)]
        self.turn_hi = hi if not self.turn_hi else [max(a, b) for a, b in zip(self.turn_hi, hi, strict=True)]

    def check_position(self) -> None:
        q = self._numbers("GetPositionJoints")
        if not all(lo - 1e-6 <= x <= hi + 1e-6 for lo, x, hi in zip(self.turn_lo, q, self.turn_hi, strict=True)):
            self.limit_violations += 1
            self.problems.append(("limit", q, self.turn_lo, self.turn_hi))

    def narrowed_limit_moves(self, count: int, seed: int = 7) -> int:
        """Narrow the turn limits, then ``count`` random joint moves around them: each must be
        accepted iff strictly inside, and the robot must stay inside. Returns moves done."""
        rng = random.Random(seed)
        for command in ("DisableAlter", "DisableLin", "DisableRoutetest", "ResetJointsMaxTurn"):
            self.ask(command)
        assert self.ask("MovePTPJoints 0 -90 90 0 0 0") == [b"true"]
        lo, hi = [-40.0, -130.0, 40.0, -40.0, -40.0, -40.0], [40.0, -50.0, 130.0, 40.0, 40.0, 40.0]
        assert self.ask("SetJointsMaxTurnMin " + " ".join(map(str, lo))) == [b"true"]
        assert self.ask("SetJointsMaxTurnMax " + " ".join(map(str, hi))) == [b"true"]
        moved = 0
        for _ in range(count):
            self.inputs += 1
            q = [rng.uniform(a - 8, b + 8) for a, b in zip(lo, hi, strict=True)]
            reply = self.ask("MovePTPJoints " + " ".join("%.3f" % x for x in q))
            inside = all(a < x < b for a, x, b in zip(lo, q, hi, strict=True))
            if reply != ([b"true"] if inside else [b"false"]):
                self.problems.append(("narrowed move", q, reply))
            moved += reply == [b"true"]
            position = self._numbers("GetPositionJoints")
            if not all(a - 1e-6 <= x <= b + 1e-6 for a, x, b in zip(lo, position, hi, strict=True)):
                self.limit_violations += 1
                self.problems.append(("limit", position, lo, hi))
        self.moves_ok += moved
        assert self.ask("ResetJointsMaxTurn") == [b"true"]
        return moved

    def alive(self) -> bool:
        try:
            os.kill(self.gateway_pid, 0)
        except ProcessLookupError:
            return False
        return self.system.pids().get("gateway") == self.gateway_pid

    def line(self, text: str) -> None:
        """One fuzzed command line (no newline inside), then the sentinel."""
        if _blocking_ping(text):
            text = "PingRobot 3 0"
        self.inputs += 1
        raw = text.encode("latin-1")
        name = _split_command(_clean(raw))[0]
        self.client.sock.sendall(raw + b"\nCM_PING\n")
        try:
            if name == "Quit":
                bye = self.client.read_line()
                if bye != b"bye!":
                    self.problems.append((text, "Quit reply", bye))
                self.client.close()
                self._client = FuzzClient(self.system.port)
                self.reconnects += 1
                return
            lines = self.client.until_pong(2 if name == "CM_PING" else 1)
        except TimeoutError:
            self.hangs += 1
            self.problems.append((text, "hang"))
            self._reconnect()
            return
        except ConnectionError as exc:
            self.problems.append((text, f"connection lost: {exc}"))
            self._reconnect()
            return
        reply = "".join(line.decode("latin-1") + "\n" for line in lines)
        problem = reply_problem(_clean(raw), reply)
        if problem:
            self.problems.append((text, problem))
        if name in TURN_COMMANDS:
            self._update_envelope()
        if (name.startswith(("Move", "DoAlter")) and lines == [b"true"]):
            self.moves_ok += 1
            self.check_position()

    def _reconnect(self) -> None:
        with contextlib.suppress(OSError):
            self.client.close()
        time.sleep(0.2)
        self._client = FuzzClient(self.system.port)
        self.reconnects += 1

    def oversized(self, size: int = 1 << 20, terminated: bool = True) -> None:
        self.inputs += 1
        payload = b"x" * size + (b"\n" if terminated else b"")
        self.client.sock.sendall(payload)
        if not terminated:
            time.sleep(0.05)  # the pause ends the unterminated line
        self.client.sock.sendall(b"CM_PING\n")
        lines = self.client.until_pong()
        expected = f"ERROR: line too long ({size + (1 if terminated else 0)} bytes, limit 65536)".encode()
        if lines != [expected]:
            self.problems.append(("oversized", size, lines[:3]))

    def flood(self, count: int = 2000, command: bytes = b"GetVersion") -> None:
        self.inputs += count
        self.client.sock.sendall((command + b"\n") * count + b"CM_PING\n")
        lines = self.client.until_pong()
        if len(lines) != count or set(lines) != {b"0.1.01"}:
            self.problems.append(("flood", count, len(lines)))

    def split(self, text: str, cuts: list[int]) -> None:
        """A line sent in several TCP segments (no pause between: reassembled or, if the pause
        elapsed, answered in pieces; either way every piece is answered, nothing hangs)."""
        if _split_command(_clean(text.encode("latin-1")))[0] == "Quit" or _blocking_ping(text):
            return self.line(text)  # closes the session / blocks by design
        self.inputs += 1
        raw = text.encode("latin-1") + b"\n"
        points = sorted({min(max(c, 0), len(raw)) for c in cuts} | {0, len(raw)})
        for a, b in pairwise(points):
            self.client.sock.sendall(raw[a:b])
        self.client.sock.sendall(b"CM_PING\n")
        try:
            self.client.until_pong(2 if _split_command(text)[0] == "CM_PING" else 1)
        except (TimeoutError, ConnectionError) as exc:
            self.problems.append((text, f"split: {exc}"))
            self._reconnect()
