"""The simulated KR C4's main loop: IPO clock, RSI UDP client, KRL run loop, control channel.

The controller's main loop: its own IPO clock, the RSI UDP client, the KRL program's
run loop, and a TCP control channel for tests and operators.

One thread: every tick sleeps (in select) until the absolute deadline on the monotonic
clock; replies and control requests are handled as they arrive in between.
"""

from __future__ import annotations

import contextlib
import json
import math
import selectors
import socket
import sys
import time
from array import array
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from .link import FaultError, Link
from .machine import Machine
from .rsi import Rsi
from .wire import RobWriter, Sen, SenError, parse_sen

RTT_WINDOW = 2048  # replies kept for the percentiles of the status
SENT_RING = 256  # packets remembered for matching late replies (RTT, stale counts)
MAX_LINE = 65536  # control channel request size limit


@dataclass
class Options:
    machine: Machine
    cycle_ms: int
    rob6: tuple[str, int]
    bind: tuple[str, int]
    control: tuple[str, int]
    sentype: str
    timeout: int
    timeout_counts: str
    corr_window: tuple[float, ...]
    start_pose: tuple[float, ...]
    restart_delay: float
    auto_ack: float | None
    eipos: bool
    faults: dict[str, float]
    vanish_s: float | None


class Shutdown(Exception):
    pass


def log(msg: str) -> None:
    stamp = time.strftime("%H:%M:%S")
    print(f"{stamp} kuka-rsi-sim: {msg}", file=sys.stderr, flush=True)


class Simulator:
    def __init__(self, opts: Options) -> None:
        self.opts = opts
        self.period = opts.cycle_ms / 1000.0
        self.rsi = Rsi(
            opts.machine,
            opts.cycle_ms,
            sentype=opts.sentype,
            timeout=opts.timeout,
            timeout_counts=opts.timeout_counts,
            corr_window=opts.corr_window,
            start_pose=opts.start_pose,
            writer=RobWriter(precision=4, eipos=opts.eipos),
            log=log,
        )
        # select(): microsecond timeouts (epoll and poll round up to whole milliseconds)
        self.sel = selectors.SelectSelector()
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.udp.bind(opts.bind)
        self.udp.setblocking(False)
        self.sel.register(self.udp, selectors.EVENT_READ, self._on_udp)
        self.ctl = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.ctl.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.ctl.bind(opts.control)
        self.ctl.listen(8)
        self.ctl.setblocking(False)
        self.sel.register(self.ctl, selectors.EVENT_READ, self._on_accept)
        self.link = Link(self.udp, self._on_sent, log)

        # the IPO clock, started with each run: tick n is due at t0 + n * period and carries
        # IPOC ipoc_base + n * cycle_ms, a millisecond time stamp that only grows
        self.epoch = time.monotonic()
        self.epoch_ms = int(time.time() * 1000) % 1_000_000_000
        self.t0 = self.epoch
        self.ipoc_base = self.epoch_ms
        self.tick_n = 0
        self.next_tick: float | None = None  # None: nothing to do every cycle (RSI off)
        self.restart_at: float | None = None  # the KRL loop's next RSI_ON
        self.vanished = False
        self.vanish_until: float | None = None  # None while vanished: until restart/clear
        self.quit = False

        # the packet waiting for its answer
        self.pending_ipoc: int | None = None
        self.answer: Sen | None = None
        self.sent_ipoc = array("q", [-1] * SENT_RING)
        self.sent_t = array("d", [0.0] * SENT_RING)
        self.sent_answered = bytearray(SENT_RING)
        self.counters = dict(bad_replies=0, stale_replies=0, wrong_ipoc_replies=0, duplicate_replies=0, overruns=0)
        self.rtt = array("d", [0.0] * RTT_WINDOW)
        self.rtt_n = 0
        self.rtt_max = 0.0
        self._bad_logged_run = -1

        now = time.monotonic()
        if opts.faults:
            self.link.set_faults(opts.faults, now)
        if opts.vanish_s is not None:
            self.vanished = True
            self.vanish_until = now + opts.vanish_s

    @property
    def control_address(self) -> tuple[str, int]:
        host: str
        port: int
        host, port = self.ctl.getsockname()[:2]
        return host, port

    # ------------------------------------------------------------------ the loop
    def serve(self) -> None:
        if not self.vanished:
            self._start_run(time.monotonic())  # the KRL program is running: first RSI_ON
        while not self.quit:
            wake = self._next_wake()
            timeout = None if wake is None else max(0.0, wake - time.monotonic())
            for key, _ in self.sel.select(timeout):
                key.data(key.fileobj)
                if self.quit:
                    return
            now = time.monotonic()
            self.link.flush_due(now)
            self._timers(now)
            if self.next_tick is not None and now >= self.next_tick:
                self._on_udp(self.udp)  # an answer already in the buffer is still on time
                self._tick(time.monotonic())

    def close(self) -> None:
        for key in list(self.sel.get_map().values()):
            sock = key.fileobj
            assert isinstance(sock, socket.socket)  # only sockets are registered
            sock.close()
        self.sel.close()

    def _next_wake(self) -> float | None:
        times = [t for t in (self.next_tick, self.restart_at, self.link.next_due()) if t is not None]
        if self.vanished and self.vanish_until is not None:
            times.append(self.vanish_until)
        return min(times) if times else None

    def _timers(self, now: float) -> None:
        if self.vanished and self.vanish_until is not None and now >= self.vanish_until:
            self._end_vanish(now, "back on")
        if self.restart_at is not None and now >= self.restart_at:
            self.restart_at = None
            self._start_run(now)

    def _start_run(self, now: float) -> None:
        """The KRL program reaches RSI_ON and RSI_MOVECORR: the first packet leaves now."""
        if self.rsi.running or not self._resolve():
            return
        self.rsi.start_run()
        self._reset_run_stats()
        self.t0 = now
        self.tick_n = 0
        stamp = self.epoch_ms + int((now - self.epoch) * 1000)
        self.ipoc_base = max(stamp, self.rsi.ipoc + self.opts.cycle_ms)
        self._tick(now)

    def _tick(self, now: float) -> None:
        rsi = self.rsi
        ipoc = self.ipoc_base + self.tick_n * self.opts.cycle_ms
        if rsi.running:
            answer, self.answer = self.answer, None
            packet = rsi.step(answer, ipoc)
            if packet is not None:
                self.pending_ipoc = ipoc
                i = (ipoc // self.opts.cycle_ms) % SENT_RING
                self.sent_ipoc[i] = ipoc
                self.sent_t[i] = 0.0  # set when it really leaves (it may be delayed)
                self.sent_answered[i] = 0
                self.link.transmit(packet, ipoc, now)
            else:
                self._run_ended(now)
        if rsi.running:
            n = self.tick_n + 1
            behind = math.floor((time.monotonic() - self.t0) / self.period) + 1
            if behind > n:  # woke too late for whole cycles: a controller never sends bursts
                self.counters["overruns"] += behind - n
                n = behind
            self.tick_n = n
            self.next_tick = self.t0 + n * self.period
        else:
            self.next_tick = None

    def _run_ended(self, now: float) -> None:
        self.pending_ipoc = None
        self.answer = None
        if self.rsi.stop_kind == "pc":  # RSI_MOVECORR returned: the KRL loop turns RSI on again
            self.restart_at = now + self.opts.restart_delay
        elif self.rsi.stop_kind == "fault" and self.opts.auto_ack is not None:
            self.restart_at = now + self.opts.auto_ack  # the operator acknowledges and restarts
            log(f"auto-acknowledge: new run in {self.opts.auto_ack:g} s")

    def _resolve(self) -> bool:
        host, port = self.opts.rob6
        try:
            info = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)
        except OSError as e:
            log(f"cannot resolve the rob6 PC {host}: {e}; retrying in 1 s")
            self.rsi.stop_reason = f"cannot resolve {host}"
            self.restart_at = time.monotonic() + 1.0
            return False
        address, resolved_port = info[0][4][:2]  # AF_INET: (host, port)
        self.link.dest = (str(address), int(resolved_port))
        return True

    # ------------------------------------------------------------------ replies
    def _on_sent(self, ipoc: int, t: float) -> None:
        i = (ipoc // self.opts.cycle_ms) % SENT_RING
        if self.sent_ipoc[i] == ipoc and self.sent_t[i] == 0.0:
            self.sent_t[i] = t

    def _on_udp(self, sock: socket.socket) -> None:
        while True:
            try:
                data, _ = sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. an ICMP error reported on the socket
                continue
            now = time.monotonic()
            if self.vanished or self.link.losing(now):
                self.link.stats["lost_in"] += 1
                continue
            try:
                sen = parse_sen(data)
            except SenError as e:
                self.counters["bad_replies"] += 1
                if self._bad_logged_run != self.rsi.runs:
                    self._bad_logged_run = self.rsi.runs
                    log(f"unreadable answer (counted late; logged once per run): {e}")
                continue
            i = (sen.ipoc // self.opts.cycle_ms) % SENT_RING
            known = self.sent_ipoc[i] == sen.ipoc
            if known and not self.sent_answered[i]:
                self.sent_answered[i] = 1
                if self.sent_t[i] > 0.0:
                    self._record_rtt(now - self.sent_t[i])
            if self.rsi.running and sen.ipoc == self.pending_ipoc and self.answer is None and known:
                self.answer = sen
            elif known:
                if sen.ipoc == self.pending_ipoc:
                    self.counters["duplicate_replies"] += 1
                else:
                    self.counters["stale_replies"] += 1
            else:
                self.counters["wrong_ipoc_replies"] += 1

    def _record_rtt(self, dt: float) -> None:
        self.rtt[self.rtt_n % RTT_WINDOW] = dt
        self.rtt_n += 1
        self.rtt_max = max(self.rtt_max, dt)

    def _reset_run_stats(self) -> None:
        self.rtt_n = 0
        self.rtt_max = 0.0

    # ------------------------------------------------------------------ control channel
    def _on_accept(self, sock: socket.socket) -> None:
        try:
            conn, _ = sock.accept()
        except (BlockingIOError, InterruptedError):
            return
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buf = bytearray()
        self.sel.register(conn, selectors.EVENT_READ, lambda c: self._on_control(c, buf))

    def _on_control(self, conn: socket.socket, buf: bytearray) -> None:
        try:
            data = conn.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self.sel.unregister(conn)
            conn.close()
            return
        buf += data
        while True:
            nl = buf.find(b"\n")
            if nl < 0:
                if len(buf) > MAX_LINE:
                    buf.clear()
                    self._reply(conn, {"ok": False, "error": f"request longer than {MAX_LINE} bytes"})
                return
            line = bytes(buf[:nl]).strip()
            del buf[: nl + 1]
            if not line:
                continue
            reply = self.handle(line)
            self._reply(conn, reply)
            if self.quit:
                return

    def _reply(self, conn: socket.socket, reply: dict[str, Any]) -> None:
        data = (json.dumps(reply) + "\n").encode()
        try:
            conn.setblocking(True)  # replies are small; a client that reads nothing is its problem
            conn.settimeout(1.0)
            conn.sendall(data)
        except OSError:
            pass
        finally:
            with contextlib.suppress(OSError):
                conn.setblocking(False)

    def handle(self, line: bytes) -> dict[str, Any]:
        try:
            req = json.loads(line)
        except (ValueError, UnicodeDecodeError) as e:
            return {"ok": False, "error": f"bad JSON: {e}"}
        if not isinstance(req, dict):
            return {"ok": False, "error": 'a request is a JSON object like {"cmd": "status"}'}
        cmd = req.pop("cmd", None)
        handler = self._commands.get(cmd) if isinstance(cmd, str) else None
        if handler is None:
            return {"ok": False, "error": f"unknown cmd {cmd!r}; expected one of {sorted(self._commands)}"}
        try:
            return handler(self, req, time.monotonic())
        except (FaultError, ValueError) as e:
            return {"ok": False, "error": str(e)}

    def _cmd_status(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        _no_fields("status", req)
        return self.status(now)

    def _cmd_fault(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        self.link.set_faults(req, now)
        log(f"fault injected: {req}")
        return {"ok": True, "faults": self.link.describe(now)}

    def _cmd_clear(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        _no_fields("clear", req)
        self.link.clear()
        if self.vanished:
            self._end_vanish(now, "cleared")
        log("faults cleared")
        return {"ok": True, "faults": self.link.describe(now)}

    def _cmd_restart(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        _only_fields("restart", req, {"start"})
        start = req.get("start")
        if start is not None:
            if (
                not isinstance(start, list)
                or len(start) != 6
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in start)
            ):
                raise ValueError(f"start must be a list of 6 axis angles in degrees, got {start!r}")
            problem = self.rsi.within_limits(start)
            if problem:
                raise ValueError(f"start pose outside the software limits: {problem}")
        self.rsi.end_run("restart requested", "operator")
        self.pending_ipoc = None
        self.answer = None
        if self.vanished:
            self.vanished = False
            self.vanish_until = None
            log("switched on again (restart)")
        if start is not None:  # the KRL program's PTP to the new start pose, RSI off
            self.rsi.move_to(start)
        self.restart_at = None
        self._start_run(now)
        return {"ok": True, "start": [round(v, 6) for v in self.rsi.aipos]}

    def _cmd_vanish(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        _only_fields("vanish", req, {"for_s"})
        for_s = req.get("for_s")
        if for_s is not None and (
            isinstance(for_s, bool) or not isinstance(for_s, (int, float)) or not math.isfinite(for_s) or for_s <= 0
        ):
            raise ValueError(f"for_s must be a number > 0 or null (until restart), got {for_s!r}")
        self.rsi.end_run("vanished", "off")
        self.pending_ipoc = None
        self.answer = None
        self.link.reset()
        self.vanished = True
        self.vanish_until = None if for_s is None else now + for_s
        self.restart_at = None
        self.next_tick = None
        log("vanished " + ("until restart" if for_s is None else f"for {for_s:g} s"))
        return {"ok": True}

    def _cmd_quit(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        _no_fields("quit", req)
        self.quit = True
        log("quit requested")
        return {"ok": True}

    _commands = {
        "status": _cmd_status,
        "fault": _cmd_fault,
        "clear": _cmd_clear,
        "restart": _cmd_restart,
        "vanish": _cmd_vanish,
        "quit": _cmd_quit,
    }

    def _end_vanish(self, now: float, why: str) -> None:
        """Switched on again: the KRL program starts a new run from where the robot stands."""
        self.vanished = False
        self.vanish_until = None
        log(f"switched on again ({why})")
        self._start_run(now)

    def status(self, now: float) -> dict[str, Any]:
        rsi = self.rsi
        state = "vanished" if self.vanished else "running" if rsi.running else "stopped"
        n = min(self.rtt_n, RTT_WINDOW)
        rtts = sorted(self.rtt[:n]) if n else []

        def ms(v: float) -> float:
            return round(v * 1000.0, 3)

        return {
            "ok": True,
            "state": state,
            "robot": rsi.machine.name,
            "cycle_ms": self.opts.cycle_ms,
            "cycle": rsi.cycle,
            "ipoc": rsi.ipoc,
            "aipos": _r(rsi.aipos),
            "aspos": _r(rsi.aspos),
            "ak": _r(rsi.ak),
            "delay": rsi.delay,
            "late_total": rsi.late_total,
            "late_consecutive": rsi.late_consecutive,
            "packets_sent": self.link.packets_sent,
            "replies_ok": rsi.replies_ok,
            "runs": rsi.runs,
            "stop_reason": rsi.stop_reason,
            "trips": list(rsi.trips),
            "max_ak_step": _r(rsi.max_ak_step),
            "rtt_ms": {
                "p50": ms(rtts[(n - 1) // 2]) if n else None,
                "p99": ms(rtts[min(n - 1, math.ceil(0.99 * n) - 1)]) if n else None,
                "max": ms(self.rtt_max) if n else None,
                "n": self.rtt_n,
            },
            "sentype": rsi.sentype,
            "timeout": rsi.timeout,
            "faults": self.link.describe(now),
            "fault_stats": dict(self.link.stats),
            "replies": dict(self.counters),
            "send_errors": self.link.send_errors,
        }


def _r(q: Iterable[float]) -> list[float]:
    return [round(v, 6) for v in q]


def _no_fields(cmd: str, req: dict[str, Any]) -> None:
    _only_fields(cmd, req, set())


def _only_fields(cmd: str, req: dict[str, Any], allowed: set[str]) -> None:
    extra = sorted(set(req) - allowed)
    if extra:
        raise ValueError(f"{cmd}: unexpected field(s) {extra}" + (f"; allowed: {sorted(allowed)}" if allowed else ""))
