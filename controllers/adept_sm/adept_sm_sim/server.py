"""The controller: the V+ server's TCP ports, the simulated arm and the fault switches.

Motion port: JOINT_TRAJ_PT in; every service request is answered like the V+ program
answers it (JOINT_TRAJ_PT service reply, body one int32: 0, or -4 for a stop), topics
are executed without a reply. The reader takes the next point only when the queue has
room, so acknowledgements pace the client (the V+ program reads the next point only
when its previous MOVE was accepted). State port: JOINT_POSITION and STATUS topics
every period. I/O port (optional): the program's digital-signal protocol.
One client at a time on the motion and state ports (V+ ``/CLIENTS 1``), five on I/O.
"""

from __future__ import annotations

import asyncio
import json
import math
import sys
import time
from collections import deque
from collections.abc import Awaitable, Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from . import codec as sm
from .arm import Arm, Point
from .convention import (
    ESTOP_DECEL_DEG_S2,
    MAX_ACCEL_DEG_S2,
    controller_to_rob6,
    limit_violation,
)

TICK_S = 0.004  # how often the arm is advanced between requests while it moves
IDLE_TICK_S = 0.05
IO_MAX_CLIENTS = 5  # V+ "/CLIENTS 5" on the I/O port
IO_BUFFER = 1024  # V+ "/BUFFER_SIZE 1024" on the I/O port
VPLUS_CYCLE_S = 0.016  # a V+ task's READ returns what arrived within about one system cycle
MODE_AUTO = 2  # simple_message RobotMode AUTO (the V+ program's mapping of STATE(5) = 1)
LATENCY_WINDOW = 10000


def event(msg: str) -> None:
    print(f"adept-sm-sim: {msg}", file=sys.stderr, flush=True)


@dataclass(frozen=True)
class Config:
    host: str = "127.0.0.1"
    motion_port: int = 11000
    state_port: int = 11002
    io_port: int | None = 11001
    control_host: str = "127.0.0.1"
    control_port: int = 0
    byte_order: str = "big"
    start_pose_ctrl: tuple[float, ...] = (0.0, 0.0, 90.0, 0.0, 0.0, 0.0)
    state_period: float = 0.1
    timing: str = "vplus"
    monitor_speed: float = 100.0
    queue_depth: int = 1
    status_fields: str = "full"


class Controller:
    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.codec = sm.Codec(cfg.byte_order)
        self.arm = Arm(cfg.start_pose_ctrl, time.monotonic(), timing=cfg.timing,
                       monitor_speed=cfg.monitor_speed)
        self.e_stopped = False
        self.drives_powered = True
        self.error_code = 0
        self.slow_ack_ms = 0.0
        self.received = self.acknowledged = self.refused = self.malformed = 0
        self.latencies_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.motion_client: asyncio.StreamWriter | None = None
        self.state_client: asyncio.StreamWriter | None = None
        self.io_clients: set[asyncio.StreamWriter] = set()
        self.signals: dict[int, bool] = {}
        self.io_requests = self.io_errors = 0
        self.room = asyncio.Event()  # set whenever the queue shrinks or is flushed
        self.generation = 0  # bumped by every stop: points waiting for room are void
        self.done = asyncio.Event()
        self._underruns_logged = 0

    # ---- the arm ------------------------------------------------------------
    def advance(self) -> None:
        before = len(self.arm.queue)
        self.arm.advance(time.monotonic())
        if len(self.arm.queue) < before:
            self.room.set()
        if self.arm.underruns > self._underruns_logged:
            self._underruns_logged = self.arm.underruns
            event(f"queue underrun (the path reached the last queued point before the next "
                  f"point came); {self.arm.underruns} so far")

    async def tick(self) -> None:
        while True:
            self.advance()
            # at rest nothing happens until a request, which advances the arm itself
            await asyncio.sleep(TICK_S if self.arm.in_motion else IDLE_TICK_S)

    def refusal(self) -> str | None:
        if self.e_stopped:
            return "e-stop is active"
        if not self.drives_powered:
            return "drives are off"
        if self.error_code:
            return f"controller error {self.error_code}"
        return None

    def halt(self, why: str, decel: Iterable[float]) -> None:
        self.advance()
        dropped = len(self.arm.queue)
        self.arm.stop(decel)
        self.generation += 1
        self.room.set()
        event(f"{why}: stopping, {dropped} queued point(s) discarded")

    async def accept(self, pt: sm.TrajPoint, client: asyncio.StreamWriter) -> str | None:
        """Queue a point (waiting for room); why it was refused, or None."""
        q = tuple(math.degrees(x) for x in pt.joints_rad[:6])
        reason = self.refusal() or limit_violation(q)
        if reason is None and self.cfg.timing == "duration" and not _timed(pt):
            reason = "no usable duration or velocity to time the move by"
        if reason:
            return reason
        gen = self.generation
        while len(self.arm.queue) >= self.cfg.queue_depth:
            self.room.clear()
            await self.room.wait()
            if self.generation != gen:
                return "the motion was stopped while the point waited for room in the queue"
            if client is not self.motion_client:
                return "the connection was dropped"
        self.advance()  # the path starts from where it is now
        self.arm.enqueue(Point(q, pt.velocity, pt.duration, pt.sequence))
        return None

    # ---- faults ---------------------------------------------------------------
    def estop(self) -> None:
        if not self.e_stopped:
            self.e_stopped = True
            self.drives_powered = False  # an Adept E-stop drops high power
            self.halt("E-stop", ESTOP_DECEL_DEG_S2)
        self.push_status()

    def estop_release(self) -> None:
        if self.e_stopped:
            self.e_stopped = False
            event("E-stop released (drives stay off until switched on)")
        self.push_status()

    def set_drives(self, on: bool) -> None:
        if on and self.e_stopped:
            raise ValueError("e-stop is active: release it before switching the drives on")
        if on != self.drives_powered:
            self.drives_powered = on
            if on:
                event("drives on")
            else:
                self.halt("drives off", MAX_ACCEL_DEG_S2)
        self.push_status()

    def set_error(self, code: int) -> None:
        self.error_code = code
        if code:
            self.halt(f"controller error {code}", MAX_ACCEL_DEG_S2)
        else:
            event("error cleared")
        self.push_status()

    # ---- wire: state port ------------------------------------------------------
    def status_frame(self) -> bytes:
        moving = int(self.arm.in_motion)
        if self.cfg.status_fields == "vplus":
            # exactly what the V+ program fills in: no error reporting, and "motion
            # possible" is just "not in motion"
            return self.codec.status(int(self.drives_powered), int(self.e_stopped), 0, 0,
                                     moving, MODE_AUTO, 1 - moving)
        possible = int(self.refusal() is None)
        return self.codec.status(int(self.drives_powered), int(self.e_stopped), self.error_code,
                                 int(bool(self.error_code)), moving, MODE_AUTO, possible)

    def state_frames(self) -> bytes:
        self.advance()
        joints = [math.radians(x) for x in self.arm.q]
        return self.codec.joint_position(joints) + self.status_frame()

    def push_status(self) -> None:
        """A STATUS at once, between the periodic ones."""
        w = self.state_client
        if w is not None and not w.is_closing():
            self.advance()
            w.write(self.status_frame())

    async def serve_state(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if not self._claim("state", writer):
            return
        watcher = asyncio.ensure_future(_until_eof(reader))
        try:
            next_t = time.monotonic()
            while not watcher.done():
                writer.write(self.state_frames())
                await writer.drain()
                next_t += self.cfg.state_period
                delay = next_t - time.monotonic()
                if delay < 0:  # fell behind (machine busy): keep the period, skip the backlog
                    next_t, delay = time.monotonic(), 0
                await asyncio.wait([watcher], timeout=delay)
        except (ConnectionError, OSError):
            pass
        finally:
            watcher.cancel()
            self._release("state", writer)

    # ---- wire: motion port ------------------------------------------------------
    async def serve_motion(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if not self._claim("motion", writer):
            return
        try:
            while True:
                prefix = await reader.readexactly(4)
                length = self.codec.length(prefix)
                if length != sm.JOINT_TRAJ_PT_LEN:
                    # the V+ program reads a fixed JOINT_TRAJ_PT layout and would lose
                    # its framing; closing is the deterministic equivalent
                    self.malformed += 1
                    event(f"motion: frame length {length}, a JOINT_TRAJ_PT has "
                          f"{sm.JOINT_TRAJ_PT_LEN}: closing the connection")
                    break
                payload = await reader.readexactly(length)
                t_recv = time.monotonic()
                hdr = self.codec.header(payload)
                if hdr.msg_type != sm.JOINT_TRAJ_PT or hdr.comm_type not in (
                    sm.TOPIC, sm.SERVICE_REQUEST
                ):
                    self.malformed += 1
                    event(f"motion: message type {hdr.msg_type}, comm type {hdr.comm_type}: "
                          "not a JOINT_TRAJ_PT topic or request, not executed")
                    if hdr.comm_type == sm.SERVICE_REQUEST:
                        await self._reply(writer, sm.FAILURE, 0, t_recv)
                    continue
                pt = self.codec.traj_point(payload)
                self.received += 1
                if pt.sequence == sm.STOP_TRAJECTORY:
                    self.halt("stop (-4) received", MAX_ACCEL_DEG_S2)
                    code, seq = sm.SUCCESS, sm.STOP_TRAJECTORY
                else:
                    reason = await self.accept(pt, writer)
                    code, seq = (sm.FAILURE, 0) if reason else (sm.SUCCESS, 0)
                    if reason:
                        self.refused += 1
                        event(f"point {pt.sequence} refused: {reason}")
                # the V+ program answers a stop even when it came as a topic
                if hdr.comm_type == sm.SERVICE_REQUEST or seq == sm.STOP_TRAJECTORY:
                    await self._reply(writer, code, seq, t_recv)
        except (asyncio.IncompleteReadError, ConnectionError, OSError):
            pass
        finally:
            if self.motion_client is writer:
                self.arm.close_trajectory()
            self._release("motion", writer)

    async def _reply(self, writer: asyncio.StreamWriter, code: int, seq: int, t_recv: float) -> None:
        if self.slow_ack_ms > 0:
            await asyncio.sleep(self.slow_ack_ms / 1000.0)
        writer.write(self.codec.traj_reply(code, seq))
        await writer.drain()
        self.latencies_ms.append((time.monotonic() - t_recv) * 1000.0)
        if code == sm.SUCCESS:
            self.acknowledged += 1

    # ---- wire: I/O port ------------------------------------------------------------
    async def serve_io(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """The program's own I/O protocol (``ros.io``): two V+ READs per request, each
        taking what has arrived as one record, and a big-endian int32 (LNGB) from the first
        four bytes of each: the mode (1 read, anything else write), then the signal
        (negative: switch off). The answer is ASCII without a line end: SIG(n) as $ENCODE
        writes it (-1 on, 0 off) for a read, ``1`` after SIGNAL(n) for a write."""
        if len(self.io_clients) >= IO_MAX_CLIENTS:
            event(f"io: {IO_MAX_CLIENTS} clients already connected, refusing another")
            writer.close()
            return
        self.io_clients.add(writer)
        try:
            while (mode := await self._io_record(reader)) is not None:
                number = await self._io_record(reader)
                if number is None:
                    break
                self.io_requests += 1
                writer.write(self._io(mode, number).encode())
                await writer.drain()
        except (ConnectionError, OSError):
            pass
        finally:
            self.io_clients.discard(writer)
            writer.close()

    async def _io_record(self, reader: asyncio.StreamReader) -> int | None:
        """One V+ READ: the bytes that arrived within one V+ cycle of the first (at most the
        port's 1024-byte buffer; a record's bytes beyond the first four are lost), as LNGB
        reads them; None at the end of the connection, or for a record shorter than four
        bytes (V+ LNGB fails: the program's task would end)."""
        record = await reader.read(IO_BUFFER)
        if not record:
            return None
        await asyncio.sleep(VPLUS_CYCLE_S)
        while len(record) < IO_BUFFER:
            try:
                more = await asyncio.wait_for(reader.read(IO_BUFFER - len(record)), 0.001)
            except TimeoutError:
                break
            if not more:
                break
            record += more
        if len(record) < 4:
            self.io_errors += 1
            event(f"io: a record of {len(record)} byte(s); LNGB needs 4 (V+ would end the I/O "
                  "server with an error): closing the connection")
            return None
        if len(record) > 4:
            event(f"io: a record of {len(record)} bytes, the V+ program reads the first 4 "
                  "(send the mode and the number as separate records)")
        return int.from_bytes(record[:4], "big", signed=True)

    def _io(self, mode: int, number: int) -> str:
        n = abs(number)
        valid = 1 <= n <= 512 or 1001 <= n <= 1512 or 2001 <= n <= 2512
        if mode == 1:
            if not valid:
                event(f"io: read of signal {number}: no such signal")
                return "0"
            return "-1" if self.signals.get(n, False) else "0"  # V+ TRUE is -1
        if not valid or 1001 <= n <= 1512:
            event(f"io: write of signal {number}: not an output or soft signal")
            return "0"
        self.signals[n] = number > 0
        event(f"io: SIGNAL {number}")
        return "1"

    # ---- connections ----------------------------------------------------------------
    def _claim(self, port: str, writer: asyncio.StreamWriter) -> bool:
        if getattr(self, f"{port}_client") is not None:
            event(f"{port}: a client is already connected, refusing another")
            writer.close()
            return False
        setattr(self, f"{port}_client", writer)
        event(f"{port}: client connected from {_peer(writer)}")
        return True

    def _release(self, port: str, writer: asyncio.StreamWriter) -> None:
        if getattr(self, f"{port}_client") is writer:
            setattr(self, f"{port}_client", None)
            event(f"{port}: client disconnected")
        writer.close()

    def drop(self, port: str) -> bool:
        if port == "io":
            dropped = bool(self.io_clients)
            for w in list(self.io_clients):
                w.close()
            return dropped
        writer = getattr(self, f"{port}_client")
        if writer is None:
            return False
        setattr(self, f"{port}_client", None)  # the port takes a new client at once
        writer.close()
        self.room.set()  # a reader waiting for room notices it lost its connection
        if port == "motion":
            self.arm.close_trajectory()
        event(f"{port}: connection dropped on request")
        return True

    # ---- control channel --------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        self.advance()
        q = [round(x, 6) for x in self.arm.q]
        lat = sorted(self.latencies_ms)
        return {
            "ok": True,
            "position_rob6_deg": [round(x, 6) for x in controller_to_rob6(self.arm.q)],
            "position_controller_deg": q,
            "velocity_controller_deg_s": [round(x, 4) for x in self.arm.v],
            "queue_length": len(self.arm.queue),
            "points_received": self.received,
            "points_acknowledged": self.acknowledged,
            "points_refused": self.refused,
            "points_executed": self.arm.executed,
            "underruns": self.arm.underruns,
            "malformed_frames": self.malformed,
            "in_motion": self.arm.in_motion,
            "e_stopped": self.e_stopped,
            "drives_powered": self.drives_powered,
            "error_code": self.error_code,
            "ack_latency_ms": {
                "count": len(lat),
                "p50": round(_pct(lat, 0.50), 3),
                "p99": round(_pct(lat, 0.99), 3),
                "max": round(lat[-1], 3) if lat else 0.0,
            },
            "slow_ack_ms": self.slow_ack_ms,
            "outputs": [n if on else -n for n, on in sorted(self.signals.items())],
            "io_requests": self.io_requests,
            "io_errors": self.io_errors,
            "clients": {
                "motion": self.motion_client is not None,
                "state": self.state_client is not None,
                "io": len(self.io_clients),
            },
        }

    def command(self, req: object) -> dict[str, Any]:
        if not isinstance(req, dict):
            raise ValueError("a request is a JSON object like {\"cmd\": \"status\"}")
        cmd = req.get("cmd")
        if cmd == "status":
            return self.status()
        if cmd == "estop":
            self.estop()
        elif cmd == "estop_release":
            self.estop_release()
        elif cmd == "drives":
            on = req.get("on")
            if not isinstance(on, bool):
                raise ValueError('"drives" needs "on": true or false')
            self.set_drives(on)
        elif cmd == "error":
            code = req.get("code")
            if not isinstance(code, int) or isinstance(code, bool) or code == 0:
                raise ValueError('"error" needs a non-zero integer "code"')
            self.set_error(code)
        elif cmd == "clear_error":
            self.set_error(0)
        elif cmd == "drop_connection":
            port = req.get("port")
            if port not in ("motion", "state", "io"):
                raise ValueError('"drop_connection" needs "port": "motion", "state" or "io"')
            return {"ok": True, "dropped": self.drop(port)}
        elif cmd == "slow_ack":
            ms = req.get("ms")
            if not isinstance(ms, (int, float)) or isinstance(ms, bool) or not 0 <= ms <= 60000:
                raise ValueError('"slow_ack" needs "ms" between 0 and 60000')
            self.slow_ack_ms = float(ms)
            event(f"acknowledgements delayed by {ms} ms")
        elif cmd == "quit":
            self.done.set()
        else:
            raise ValueError(
                f"unknown cmd {cmd!r}; known: status, estop, estop_release, drives, error, "
                "clear_error, drop_connection, slow_ack, quit"
            )
        return {"ok": True}

    async def serve_control(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while line := await reader.readline():
                if not line.strip():
                    continue
                try:
                    reply = self.command(json.loads(line))
                except json.JSONDecodeError as exc:
                    reply = {"ok": False, "error": f"bad JSON: {exc}"}
                except ValueError as exc:
                    reply = {"ok": False, "error": str(exc)}
                writer.write(json.dumps(reply).encode() + b"\n")
                await writer.drain()
        except (ConnectionError, OSError, asyncio.LimitOverrunError, ValueError):
            pass
        finally:
            writer.close()


def _timed(pt: sm.TrajPoint) -> bool:
    if not (math.isfinite(pt.duration) and math.isfinite(pt.velocity)):
        return False
    return pt.duration > 0 or pt.velocity > 0


async def _until_eof(reader: asyncio.StreamReader) -> None:
    """The state port is write-only; reading tells when the client has gone."""
    while await reader.read(4096):
        pass


def _peer(writer: asyncio.StreamWriter) -> str:
    peer = writer.get_extra_info("peername")
    return f"{peer[0]}:{peer[1]}" if peer else "?"


def _pct(sorted_values: Sequence[float], p: float) -> float:
    if not sorted_values:
        return 0.0
    return sorted_values[min(len(sorted_values) - 1, int(p * len(sorted_values)))]


#: a connection handler of asyncio.start_server
Serve = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


def _handler(serve: Serve) -> Serve:
    """A connection handler that ends quietly when shutdown cancels it (Python 3.11's
    streams would otherwise print the cancellation as an error)."""

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            await serve(reader, writer)
        except asyncio.CancelledError:
            writer.close()

    return handle


async def run(cfg: Config, ready: Callable[[dict[str, tuple[str, int]], Controller], None]) -> None:
    """Serve until quit or a signal; ready(addresses) is called once everything listens."""
    ctl = Controller(cfg)
    servers = {
        "motion": await asyncio.start_server(_handler(ctl.serve_motion), cfg.host,
                                             cfg.motion_port),
        "state": await asyncio.start_server(_handler(ctl.serve_state), cfg.host, cfg.state_port),
        "control": await asyncio.start_server(_handler(ctl.serve_control), cfg.control_host,
                                              cfg.control_port),
    }
    if cfg.io_port is not None:
        servers["io"] = await asyncio.start_server(_handler(ctl.serve_io), cfg.host, cfg.io_port)
    ticker = asyncio.ensure_future(ctl.tick())
    try:
        ready({name: s.sockets[0].getsockname()[:2] for name, s in servers.items()}, ctl)
        await ctl.done.wait()
    finally:
        ticker.cancel()
        for s in servers.values():
            s.close()
        for w in [ctl.motion_client, ctl.state_client, *ctl.io_clients]:
            if w is not None:
                w.close()
