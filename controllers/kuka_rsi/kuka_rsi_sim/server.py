"""The simulated KR C4's main loop: the KRL program, the IPO clock, the RSI UDP client, the control channel.

The controller runs the selected KRL program (krl.py) with the files installed on it: the
program decides when RSI is created, switched on and off; while RSI is on, the IPO clock
sends a packet every cycle and settles the answer to the last one. A TCP control channel
serves tests and operators (status, faults, restart, confirm).

One thread: every tick sleeps (in select) until the absolute deadline on the monotonic
clock; replies and control requests are handled as they arrive in between.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import selectors
import socket
import sys
import time
from array import array
from collections.abc import Generator, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import krl
from .context import RSI_NAMES, ContextError, SignalFlow, load_context
from .link import FaultError, Link
from .machine import Machine
from .rsi import Rsi
from .wire import Sen, SenError, parse_sen

RTT_WINDOW = 2048  # replies kept for the percentiles of the status
SENT_RING = 256  # packets remembered for matching late replies (RTT, stale counts)
MAX_LINE = 65536  # control channel request size limit
MESSAGES_KEPT = 100
#: how fast a PTP between runs moves the axes, as a share of their rated speed
PTP_SPEED = 0.2


@dataclass
class Options:
    machine: Machine
    kss: str
    generation: str  # the RSI generation of that KSS
    program: Path  # KRC:\R1\Program\<name>.src (its .dat beside it)
    sensor_dir: Path  # C:\KRC\ROBOTER\Config\User\Common\SensorInterface
    rob6: tuple[str, int] | None  # replaces IP_NUMBER/PORT of the Ethernet configuration
    bind: tuple[str, int]
    control: tuple[str, int]
    start_pose: tuple[float, ...]
    timeout: int | None  # replaces the ETHERNET object's Timeout
    cycle_ms: int | None  # replaces RSI_ON's #IPO_FAST / #IPO cycle
    t1: bool  # T1: each RSI_ON waits for the operator to confirm its warning
    auto_ack: float | None
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
        src = opts.program
        self.program = krl.parse_program(src.read_text("ascii"), src.with_suffix(".dat").read_text("ascii"),
                                         src.stem)
        self.rsi = Rsi(opts.machine, opts.generation, opts.start_pose, log, opts.t1)
        self.cycle_ms = opts.cycle_ms or 12
        self.period = self.cycle_ms / 1000.0
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
        self.vanished = False
        self.vanish_until: float | None = None  # None while vanished: until restart/clear
        self.quit = False

        # the KRL program and what it waits for
        self.run: Generator[krl.Wait, None, str] | None = None
        self.waiting: krl.Wait | None = None
        self.program_state = "not started"
        self.resume_at: float | None = None  # a PTP or WAIT SEC ends
        self.restart_at: float | None = None  # the operator starts the program again (auto-ack)
        self.ptp: tuple[list[float], list[float], float, float] | None = None  # start, target, t0, t1
        self.bco = False  # a motion since the program started: RSI_ON may run
        self.programmed: list[float] = list(opts.start_pose)  # the last motion's target
        self.contexts: dict[str, tuple[int, SignalFlow, bool]] = {}  # name -> (id, flow, permanent)
        self.active: int | None = None  # the context RSI_ON switched on
        self.next_id = 1
        self.rsi_off_pending = False
        self.messages: list[str] = []

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
            self._start_program(time.monotonic())  # the operator selected the program and pressed Start
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
        times = [t for t in (self.next_tick, self.resume_at, self.restart_at, self.link.next_due()) if t is not None]
        if self.vanished and self.vanish_until is not None:
            times.append(self.vanish_until)
        return min(times) if times else None

    def _timers(self, now: float) -> None:
        if self.vanished and self.vanish_until is not None and now >= self.vanish_until:
            self._end_vanish(now, "back on")
        if self.restart_at is not None and now >= self.restart_at:
            self.restart_at = None
            log("the operator acknowledges and starts the program again")
            self._start_program(now)
        if self.resume_at is not None and now >= self.resume_at:
            self.resume_at = None
            if self.ptp is not None:
                self.rsi.move_to(self.ptp[1])
                self.ptp = None
            self._advance(now)

    # ------------------------------------------------------------------ the KRL program
    def _start_program(self, now: float, line: int | None = None) -> None:
        """Reset the program and start it (at ``line``: a block selection, no BCO yet)."""
        self._stop_program()
        self.contexts = {k: c for k, c in self.contexts.items() if c[2]}  # RSI_CREATE(..., TRUE) survives
        self.bco = False
        self.run = krl.run(self.program, self, line)
        self.program_state = "running"
        log(f"program {self.program.name} started" + (f" at line {line}" if line else ""))
        self._advance(now)

    def _stop_program(self) -> None:
        self.run = None
        self.waiting = None
        self.resume_at = None
        self.ptp = None
        self.rsi_off_pending = False

    def _message(self, text: str) -> None:
        self.messages.append(text)
        del self.messages[:-MESSAGES_KEPT]
        log(f"message: {text}")

    def _advance(self, now: float) -> None:
        """Run the program until it waits for something or ends."""
        while self.run is not None:
            try:
                wait = next(self.run)
            except StopIteration as end:
                self._stop_program()
                self.program_state = "ended" if end.value == "END" else str(end.value)
                log(f"program {self.program.name}: {self.program_state}")
                self._after_stop(now)
                return
            except krl.ProgramStop as e:
                self._fault_stop(now, str(e))
                return
            self.waiting = wait
            if wait.kind == "ptp":
                target = [float(v) for v in wait.value]
                problem = self.rsi.within_limits(target)
                if problem:
                    self._fault_stop(now, f"PTP: {problem} (software limit switch)")
                    return
                self.bco = True
                self.programmed = target
                start = list(self.rsi.aipos)
                duration = max(abs(t - s) / (r * PTP_SPEED)
                               for t, s, r in zip(target, start, self.opts.machine.rated, strict=True))
                if duration > 0:
                    self.ptp = (start, target, now, now + duration)
                    self.resume_at = now + duration
                    return
                self.rsi.move_to(target)
            elif wait.kind == "sec":
                self.resume_at = now + float(wait.value)
                return
            elif wait.kind == "confirm":
                self.program_state = "waiting for confirmation"
                log(f"T1: RSI_ON at line {wait.value}: confirm 'Attention - sensor correction goes active'")
                return
            elif wait.kind == "movecorr":
                if not self.rsi.running:
                    self._fault_stop(now, "RSI_MOVECORR: RSI is not on")
                    return
                self.rsi.in_movecorr = True
                return
            elif wait.kind == "rsi_off" and self.rsi.running:
                self.rsi_off_pending = True  # takes effect with the next IPO cycle
                return

    def _fault_stop(self, now: float, message: str) -> None:
        """The controller stops the program with a message; the operator must act."""
        self._message(message)
        self.rsi.end_run(message, "fault")
        self.next_tick = None
        self._stop_program()
        self.program_state = f"stopped: {message}"
        self._after_stop(now)

    def _after_stop(self, now: float) -> None:
        self.pending_ipoc = None
        self.answer = None
        if self.opts.auto_ack is not None:
            self.restart_at = now + self.opts.auto_ack
            log(f"auto-acknowledge: the program starts again in {self.opts.auto_ack:g} s")

    # what the program asks of the controller (krl.Controller)
    def axis_act(self) -> list[float]:
        return list(self.rsi.aipos)

    def needs_confirm(self) -> bool:
        return self.opts.t1

    def rsi_create(self, name: str, permanent: bool) -> tuple[str, int]:
        if name in self.contexts:
            return krl.RSIOK, self.contexts[name][0]
        try:
            flow = load_context(name, self.opts.sensor_dir, self.opts.generation)
        except ContextError as e:
            self._message(f"RSI_CREATE({name!r}) on {RSI_NAMES[self.opts.generation]}: {e}")
            return "RSI_CREATE failed", 0
        cont_id = self.next_id
        self.next_id += 1
        self.contexts[name] = (cont_id, flow, permanent)
        log(f"RSI_CREATE({name!r}): context {cont_id}, {flow.ethernet_id} Timeout {flow.timeout}, "
            f"SENTYPE {flow.ethernet.sentype}")
        return krl.RSIOK, cont_id

    def rsi_on(self, mode: str, ipo_mode: str) -> str:
        if not self.bco:
            raise krl.ProgramStop("KSS01443 Impermissible start motion: RSI_ON needs a motion first (BCO run)")
        if self.rsi.running:
            self._message("RSI_ON: RSI is already on")
            return "RSI_ON failed"
        if not self.contexts:
            self._message("RSI_ON: no context created")
            return "RSI_ON failed"
        cont_id, flow, _ = max(self.contexts.values(), key=lambda c: c[0])
        if self.opts.timeout is not None:
            flow = dataclasses.replace(flow, timeout=self.opts.timeout)
        if not self._resolve(flow):
            return "RSI_ON failed"
        self.active = cont_id
        self.cycle_ms = self.opts.cycle_ms or krl.IPO_CYCLES[ipo_mode]
        self.period = self.cycle_ms / 1000.0
        self.rsi.set_flow(flow, self.cycle_ms, mode, ipo_mode)
        self.rsi.start_run(self.programmed)
        self._reset_run_stats()
        now = time.monotonic()
        self.t0 = now
        self.tick_n = 0
        stamp = self.epoch_ms + int((now - self.epoch) * 1000)
        self.ipoc_base = max(stamp, self.rsi.ipoc + self.cycle_ms)
        self._tick(now)
        return krl.RSIOK

    def rsi_off(self) -> str:
        if not self.rsi.running:
            self._message("RSI_OFF: RSI is not on")
            return "RSI_OFF failed"
        return krl.RSIOK

    def rsi_delete(self, cont_id: int) -> str:
        for name, (cid, _, _) in list(self.contexts.items()):
            if cid == cont_id and not (self.rsi.running and self.active == cid):
                del self.contexts[name]
                return krl.RSIOK
        self._message(f"RSI_DELETE({cont_id}): no such context, or RSI is on")
        return "RSI_DELETE failed"

    # ------------------------------------------------------------------ the IPO clock
    def _tick(self, now: float) -> None:
        rsi = self.rsi
        if self.rsi_off_pending:  # RSI_OFF: no more packets
            self.rsi_off_pending = False
            rsi.end_run("RSI_OFF", "program")
            self.next_tick = None
            self.pending_ipoc = None
            self.answer = None
            self._advance(now)
            return
        ipoc = self.ipoc_base + self.tick_n * self.cycle_ms
        if rsi.running:
            answer, self.answer = self.answer, None
            packet = rsi.step(answer, ipoc)
            if packet is not None:
                self.pending_ipoc = ipoc
                i = (ipoc // self.cycle_ms) % SENT_RING
                self.sent_ipoc[i] = ipoc
                self.sent_t[i] = 0.0  # set when it really leaves (it may be delayed)
                self.sent_answered[i] = 0
                self.link.transmit(packet, ipoc, now)
            else:  # a monitor stopped RSI: the program stops with its message
                self.next_tick = None
                self._fault_stop(now, rsi.stop_reason)
                return
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
        if rsi.movecorr_done:  # the Stop object ended RSI_MOVECORR: the program goes on
            rsi.movecorr_done = False
            self._advance(now)

    def _resolve(self, flow: SignalFlow) -> bool:
        host, port = self.opts.rob6 or (flow.ethernet.ip_number, flow.ethernet.port)
        try:
            info = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)
        except OSError as e:
            self._message(f"RSI_ON: cannot reach the PC {host}: {e}")
            return False
        address, resolved_port = info[0][4][:2]  # AF_INET: (host, port)
        self.link.dest = (str(address), int(resolved_port))
        return True

    # ------------------------------------------------------------------ replies
    def _on_sent(self, ipoc: int, t: float) -> None:
        i = (ipoc // self.cycle_ms) % SENT_RING
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
            flow = self.rsi.flow
            if flow is None:  # no context: nobody reads
                continue
            try:
                sen = parse_sen(data, flow.ethernet)
                if sen.type != flow.ethernet.sentype:
                    raise SenError(f"Sen Type {sen.type!r} is not SENTYPE {flow.ethernet.sentype!r}")
            except SenError as e:
                self.counters["bad_replies"] += 1
                self.rsi.not_taken += 1
                if self._bad_logged_run != self.rsi.runs:
                    self._bad_logged_run = self.rsi.runs
                    log(f"answer not taken (counted late; logged once per run): {e}")
                continue
            i = (sen.ipoc // self.cycle_ms) % SENT_RING
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
        """The operator: stop the program (RSI ends), jog the arm to ``start`` if given, reset
        the program and start it, from its first line or from ``line`` (a block selection)."""
        _only_fields("restart", req, {"start", "line"})
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
        line = req.get("line")
        if line is not None and (isinstance(line, bool) or not isinstance(line, int) or line < 1):
            raise ValueError(f"line must be a line number of the program, got {line!r}")
        self.rsi.end_run("restart requested", "operator")
        self._stop_program()
        self.next_tick = None
        self.pending_ipoc = None
        self.answer = None
        self.restart_at = None
        if self.vanished:
            self.vanished = False
            self.vanish_until = None
            log("switched on again (restart)")
        if start is not None:  # jogged there with RSI off
            self.rsi.move_to(start)
        self._start_program(now, line)
        return {"ok": True, "start": [round(v, 6) for v in self.rsi.aipos], "program": self.program_state}

    def _cmd_confirm(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        """The operator confirms RSI_ON's warning in T1."""
        _no_fields("confirm", req)
        if self.waiting is None or self.waiting.kind != "confirm":
            raise ValueError("nothing to confirm")
        self.program_state = "running"
        self.waiting = None
        self._advance(now)
        return {"ok": True, "program": self.program_state}

    def _cmd_vanish(self, req: dict[str, Any], now: float) -> dict[str, Any]:
        _only_fields("vanish", req, {"for_s"})
        for_s = req.get("for_s")
        if for_s is not None and (
            isinstance(for_s, bool) or not isinstance(for_s, (int, float)) or not math.isfinite(for_s) or for_s <= 0
        ):
            raise ValueError(f"for_s must be a number > 0 or null (until restart), got {for_s!r}")
        self.rsi.end_run("vanished", "off")
        self._stop_program()
        self.program_state = "off"
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
        "confirm": _cmd_confirm,
        "vanish": _cmd_vanish,
        "quit": _cmd_quit,
    }

    def _end_vanish(self, now: float, why: str) -> None:
        """Switched on again: the operator starts the program."""
        self.vanished = False
        self.vanish_until = None
        log(f"switched on again ({why})")
        self._start_program(now)

    def status(self, now: float) -> dict[str, Any]:
        rsi = self.rsi
        state = "vanished" if self.vanished else "running" if rsi.running else "stopped"
        n = min(self.rtt_n, RTT_WINDOW)
        rtts = sorted(self.rtt[:n]) if n else []
        aipos = rsi.aipos
        if self.ptp is not None:  # a PTP between runs: where the axes are now
            start, target, t0, t1 = self.ptp
            f = min(1.0, max(0.0, (now - t0) / (t1 - t0)))
            aipos = [s + (t - s) * f for s, t in zip(start, target, strict=True)]
        flow = rsi.flow

        def ms(v: float) -> float:
            return round(v * 1000.0, 3)

        return {
            "ok": True,
            "state": state,
            "program": self.program_state,
            "robot": rsi.machine.name,
            "kss": self.opts.kss,
            "rsi": RSI_NAMES[self.opts.generation],
            "cycle_ms": self.cycle_ms if rsi.runs else None,  # RSI_ON's cycle
            "cycle": rsi.cycle,
            "ipoc": rsi.ipoc,
            "aipos": _r(aipos),
            "aspos": _r(rsi.aspos),
            "ak": _r(rsi.corr),
            "delay": rsi.delay,
            "late_total": rsi.late_total,
            "packets_sent": self.link.packets_sent,
            "replies_ok": rsi.replies_ok,
            "runs": rsi.runs,
            "stop_reason": rsi.stop_reason,
            "trips": list(rsi.trips),
            "messages": list(self.messages),
            "max_ak_step": _r(rsi.max_ak_step),
            "rtt_ms": {
                "p50": ms(rtts[(n - 1) // 2]) if n else None,
                "p99": ms(rtts[min(n - 1, math.ceil(0.99 * n) - 1)]) if n else None,
                "max": ms(self.rtt_max) if n else None,
                "n": self.rtt_n,
            },
            "sentype": flow.ethernet.sentype if flow else None,
            "timeout": flow.timeout if flow else None,
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
