"""Replay a recorded client session against a server and compare the replies (``rob6-log replay``).

A *script* is what a client did on one connection: the greeting it got and, per
line it sent, the exact bytes, when (relative to the first line) and the reply it
got. Scripts come from a recording (``/session/<n>/client_in`` + ``client_out``
paired by ``cid``) or from a conformance transcript (``*.jsonl``, see
``/work/shared/conformance/README.md``; each ``connect`` starts a new script).

Reading a reply: the recorded reply says how many lines to expect. The replayer
reads until that many lines have arrived (or ``timeout`` passes / the server
closes). When no line is expected (``SetAllowedStatus`` on success, an empty line)
it waits ``quiet`` seconds for stray output instead. Output that arrives after a
complete reply and before the next line is sent is reported as extra output of that
reply.

Comparison (``compare_reply``): same number of lines, same whitespace, same words;
a number may differ by ``tolerance`` (absolute); for ``GetTimestamp`` and
``PingRobot`` only the shape counts (a number where a number was).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import re
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .inspect import command_word
from .reader import RecordingReader

SHAPE_ONLY = frozenset({"GetTimestamp", "PingRobot"})
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_SPLIT = re.compile(r"(\s+)")


@dataclass
class Exchange:
    send: bytes
    expected: str | None  # None: not judged (e.g. a transcript pair the original mishandled)
    t: float = 0.0  # seconds after the first line of the script
    cid: str = ""
    index: int = 0
    synthetic: bool = False  # added by the replayer (handshake)

    @property
    def command(self) -> str:
        return command_word(self.send.decode("latin-1"))


@dataclass
class Script:
    name: str
    greeting: str | None = None
    exchanges: list[Exchange] = field(default_factory=list)
    robot: str | None = None
    handshake_recorded: bool = True  # False: the recording starts after the handshake

    def __post_init__(self) -> None:
        self.refresh()

    def refresh(self) -> None:
        first = self.exchanges[0] if self.exchanges else None
        self.handshake_recorded = first is None or first.expected in ("accepted\n", "failed\n")


@dataclass
class Difference:
    script: str
    index: int
    sent: bytes
    expected: str | None
    got: str
    reason: str
    cid: str = ""
    t: float = 0.0


@dataclass
class ReplayResult:
    scripts: int = 0
    exchanges: int = 0
    judged: int = 0
    differences: list[Difference] = field(default_factory=list)
    elapsed: float = 0.0
    aborted: str = ""  # why a script stopped early (connection refused/closed...)
    robot_recorded: str | None = None
    robot_target: str | None = None

    @property
    def ok(self) -> bool:
        return not self.differences and not self.aborted


# --------------------------------------------------------------------------- loading
def load_script(path: str | os.PathLike[str], session: str | None = None,
                robot: str | None = None) -> list[Script]:
    """Scripts of a recording (one per session, or only ``session``) or a transcript."""
    p = Path(path)
    if p.suffix == ".jsonl":
        scripts = load_transcript(p)
        guessed = robot or p.parent.name
        for s in scripts:
            s.robot = guessed
        return scripts
    return load_recording(p, session)


def load_recording(path: str | os.PathLike[str], session: str | None = None) -> list[Script]:
    reader = RecordingReader(path)
    ins: dict[str, list[tuple[int, dict[str, Any]]]] = {}
    outs: dict[str, list[tuple[int, dict[str, Any]]]] = {}
    order: list[str] = []
    for rec in reader.records():
        parts = rec.topic.split("/")
        if len(parts) != 4 or parts[1] != "session" or not isinstance(rec.data, dict):
            continue
        sid, kind = parts[2], parts[3]
        if session is not None and sid != str(session):
            continue
        if sid not in ins:
            ins[sid], outs[sid] = [], []
            order.append(sid)
        if kind == "client_in":
            ins[sid].append((rec.log_time, rec.data))
        elif kind == "client_out":
            outs[sid].append((rec.log_time, rec.data))
    robot = reader.metadata.get("rob6", {}).get("robot")
    scripts = []
    for sid in order:
        script = Script(name=f"{Path(path).name}#session{sid}", robot=robot)
        by_cid: dict[str, list[str]] = {}
        sequential: list[tuple[int, str]] = []
        for t, data in outs[sid]:
            if data.get("kind") == "greeting":
                script.greeting = str(data.get("text", ""))
                continue
            cid = str(data.get("cid", "") or "")
            if cid:
                by_cid.setdefault(cid, []).append(str(data.get("text", "")))
            else:
                sequential.append((t, str(data.get("text", ""))))
        t0 = ins[sid][0][0] if ins[sid] else 0
        for i, (t, data) in enumerate(ins[sid]):
            cid = str(data.get("cid", "") or "")
            if cid:
                expected = "".join(by_cid.get(cid, []))
            else:  # no cid: the replies between this line and the next
                t_next = ins[sid][i + 1][0] if i + 1 < len(ins[sid]) else math.inf
                expected = "".join(txt for (to, txt) in sequential if t <= to < t_next)
            script.exchanges.append(Exchange(
                send=str(data.get("text", "")).encode("latin-1"), expected=expected,
                t=(t - t0) / 1e9, cid=cid, index=i + 1))
        script.refresh()
        scripts.append(script)
    return scripts


def load_transcript(path: str | os.PathLike[str]) -> list[Script]:
    """Conformance transcript (JSON Lines) -> one script per connection.

    A record with ``no_reply_within_ms`` and the record after it are not judged (the
    original swallowed the next line as missing arguments; rob6 answers at once), nor
    is a silent record after which the original closed the connection (a crash).
    """
    scripts: list[Script] = []
    current: Script | None = None
    skip_next = False
    name = Path(path).name
    with open(path, encoding="utf-8") as fh:
        for raw in fh:
            line = raw.strip()
            if not line:
                continue
            rec = json.loads(line)
            if rec.get("connect"):
                current = Script(name=f"{name}#{len(scripts) + 1}", greeting=rec.get("greeting"))
                scripts.append(current)
                skip_next = False
                continue
            if "send" not in rec or current is None:
                continue
            crashed = rec.get("reply", "") == "" and bool(rec.get("then_closed"))
            judged = not skip_next and "no_reply_within_ms" not in rec and not crashed
            skip_next = "no_reply_within_ms" in rec
            current.exchanges.append(Exchange(
                send=rec["send"].encode("latin-1"),
                expected=rec.get("reply", "") if judged else None,
                index=len(current.exchanges) + 1))
            if rec.get("then_closed") or rec.get("closed"):
                current = None
    for script in scripts:
        script.handshake_recorded = True  # a transcript holds the whole connection
    return scripts


# --------------------------------------------------------------------------- comparing
def _is_number(token: str) -> bool:
    return _NUMBER.fullmatch(token) is not None


def compare_reply(command: str, expected: str, got: str, tolerance: float = 1e-5) -> str | None:
    """None when ``got`` matches ``expected``; otherwise a one-line reason."""
    if expected == got:
        return None
    shape_only = command in SHAPE_ONLY
    exp_lines, got_lines = expected.split("\n"), got.split("\n")
    if len(exp_lines) != len(got_lines):
        return (f"expected {expected.count(chr(10))} line(s), got {got.count(chr(10))}"
                + ("" if got else " (no reply)"))
    for ln, (e, g) in enumerate(zip(exp_lines, got_lines, strict=True), 1):
        if e == g:
            continue
        et, gt = _SPLIT.split(e), _SPLIT.split(g)
        if len(et) != len(gt):
            return f"line {ln}: expected {e!r}, got {g!r}"
        for fi, (a, b) in enumerate(zip(et, gt, strict=True)):
            if a == b:
                continue
            if a.isspace() or b.isspace() or not a or not b:
                return f"line {ln}: whitespace differs: expected {e!r}, got {g!r}"
            if _is_number(a) and _is_number(b):
                if shape_only:
                    continue
                delta = abs(float(a) - float(b))
                if delta <= tolerance:
                    continue
                return (f"line {ln}, field {fi // 2 + 1}: expected {a}, got {b} "
                        f"(|diff| {delta:.3g} > {tolerance:g})")
            return f"line {ln}, field {fi // 2 + 1}: expected {a!r}, got {b!r}"
    return None


# --------------------------------------------------------------------------- replaying
class _Conn(asyncio.Protocol):
    """The client side of one connection: bytes collected as they arrive."""

    def __init__(self) -> None:
        self.buf = bytearray()
        self.eof = False
        self.transport: asyncio.Transport | None = None
        self._event = asyncio.Event()

    # protocol callbacks
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)  # a TCP connection
        self.transport = transport
        sock = transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def data_received(self, data: bytes) -> None:
        self.buf += data
        self._event.set()

    def eof_received(self) -> bool:
        self.eof = True
        self._event.set()
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self.eof = True
        self._event.set()

    # reading
    async def _wait(self, timeout: float) -> bool:
        """Wait for more data (True) until timeout or EOF (False)."""
        if self.eof:
            return False
        self._event.clear()
        try:
            await asyncio.wait_for(self._event.wait(), timeout)
        except TimeoutError:
            return False
        return True

    def _take(self, n: int | None = None) -> str:
        n = len(self.buf) if n is None else n
        out = bytes(self.buf[:n])
        del self.buf[:n]
        return out.decode("latin-1")

    async def lines(self, n: int, timeout: float) -> str:
        """``n`` complete lines (less on timeout/EOF: then whatever arrived)."""
        deadline = time.monotonic() + timeout
        while self.buf.count(b"\n") < n:
            left = deadline - time.monotonic()
            if left <= 0 or self.eof:
                return self._take()
            await self._wait(left)
        cut = -1
        for _ in range(n):
            cut = self.buf.index(b"\n", cut + 1)
        return self._take(cut + 1)

    async def quiet(self, quiet: float) -> str:
        """Everything that arrives until nothing came for ``quiet`` seconds."""
        while await self._wait(quiet):
            pass
        return self._take()

    async def pending(self) -> str:
        """Whatever already arrived (one loop turn, no waiting)."""
        await asyncio.sleep(0)
        return self._take()

    def send(self, data: bytes) -> None:
        if self.transport is None or self.transport.is_closing():
            raise ConnectionResetError("connection closed")
        self.transport.write(data)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()


async def replay_script(script: Script, host: str, port: int, *,
                        speed: float | None = 1.0, tolerance: float = 1e-5,
                        timeout: float = 5.0, quiet: float = 0.1,
                        auto_handshake: bool = True,
                        progress: Callable[[int], None] | None = None,
                        result: ReplayResult | None = None) -> ReplayResult:
    """Replay one script on a new connection. ``speed=None``: as fast as possible."""
    result = result if result is not None else ReplayResult()
    result.scripts += 1
    exchanges = list(script.exchanges)
    if auto_handshake and exchanges and not script.handshake_recorded:
        exchanges.insert(0, Exchange(send=b"Hello Robot\n", expected="accepted\n",
                                     t=exchanges[0].t, index=0, synthetic=True))

    def diff(ex: Exchange | None, got: str, reason: str, expected: str | None = None) -> None:
        result.differences.append(Difference(
            script=script.name, index=ex.index if ex else 0, sent=ex.send if ex else b"",
            expected=expected if ex is None else ex.expected, got=got, reason=reason,
            cid=ex.cid if ex else "", t=ex.t if ex else 0.0))

    loop = asyncio.get_running_loop()
    try:
        _, conn = await asyncio.wait_for(loop.create_connection(_Conn, host, port), timeout)
    except (TimeoutError, OSError) as exc:
        result.aborted = f"{script.name}: cannot connect to {host}:{port}: {exc!r}"
        return result
    try:
        greeting = await conn.lines(1, timeout)
        if script.greeting is not None and greeting != script.greeting:
            diff(None, greeting, f"greeting differs: expected {script.greeting!r}, "
                                 f"got {greeting!r}", script.greeting)
        elif not greeting:
            diff(None, "", "no greeting", script.greeting)
        start = time.monotonic()
        previous: Exchange | None = None
        for n, ex in enumerate(exchanges):
            if speed and ex.t > 0:
                delay = start + ex.t / speed - time.monotonic()
                if delay > 0:
                    await asyncio.sleep(delay)
            stray = await conn.pending()
            if stray and previous is not None:
                diff(previous, stray, f"extra output after the reply: {stray!r}", "")
            if conn.eof:
                result.aborted = (f"{script.name}: server closed the connection before line "
                                  f"{ex.index} ({len(exchanges) - n} lines not replayed)")
                break
            try:
                conn.send(ex.send)
            except (ConnectionError, OSError) as exc:
                result.aborted = (f"{script.name}: sending line {ex.index} failed: {exc!r} "
                                  f"({len(exchanges) - n} lines not replayed)")
                break
            expected = ex.expected
            want = expected.count("\n") if expected is not None else 0
            if want:
                got = await conn.lines(want, timeout)
            else:
                got = await conn.quiet(quiet)
            result.exchanges += 1
            if expected is not None:
                result.judged += 1
                reason = compare_reply(ex.command, expected, got, tolerance)
                if reason is not None:
                    diff(ex, got, reason)
            previous = ex
            if progress is not None and not ex.synthetic:
                progress(1)
        else:
            stray = await conn.quiet(quiet)
            if stray and previous is not None:
                diff(previous, stray, f"extra output after the last reply: {stray!r}", "")
    finally:
        conn.close()
    return result


async def replay(scripts: list[Script], host: str, port: int, **kwargs: Any) -> ReplayResult:
    result = ReplayResult()
    started = time.monotonic()
    for script in scripts:
        await replay_script(script, host, port, result=result, **kwargs)
        if result.aborted and "cannot connect" in result.aborted:
            break
    result.elapsed = time.monotonic() - started
    return result


def format_report(result: ReplayResult, limit: int = 50) -> str:
    lines = []
    for d in result.differences[:limit]:
        where = f"line {d.index}" if d.index else "greeting"
        sent = d.sent.decode("latin-1").rstrip("\r\n") if d.sent else ""
        lines.append(f"{d.script} {where}" + (f" cid={d.cid}" if d.cid else "")
                     + (f" t=+{d.t:.3f}s" if d.t else "") + (f"  > {sent!r}" if sent else ""))
        lines.append(f"    {d.reason}")
        if d.expected is not None and not d.reason.startswith("extra output"):
            lines.append(f"    expected: {d.expected!r}")
            lines.append(f"    got:      {d.got!r}")
    if len(result.differences) > limit:
        lines.append(f"... {len(result.differences) - limit} more differences")
    if result.robot_target and result.robot_recorded and result.robot_target != result.robot_recorded:
        lines.append(f"note: recorded with robot {result.robot_recorded}, replayed against "
                     f"{result.robot_target}: differences in robot-specific values are expected")
    rate = result.exchanges / result.elapsed if result.elapsed > 0 else 0.0
    lines.append(f"{result.scripts} connection(s), {result.exchanges} lines replayed, "
                 f"{result.judged} judged, {len(result.differences)} difference(s), "
                 f"{result.elapsed:.2f} s ({rate:.0f} lines/s)")
    if result.aborted:
        lines.append(f"ABORTED: {result.aborted}")
    return "\n".join(lines)
