"""The controller: the V+ server's TCP ports, the simulated arm and the fault switches.

Each port is served as ``adept_ros.v2``'s task for it serves it (deploy/adept/README.md
section 4 and controllers/adept_sm/README.md give the program's lines):

* motion (task 0, ``ros.srv.cmd``): the connection's first four bytes discarded, then
  fixed 68-byte records read one by one, whatever their length word or message type says;
  a service request (comm type 2) answered at once (body 0, or -4 for a stop), a stop (-4)
  answered also as a topic and otherwise ignored (nothing halts), every other record a
  ``MOVE`` to its joints, planned behind the running motion and returning when it begins
  (V+'s forward processing): the next record is read only then.
  A MOVE that cannot run (outside a joint range, not a number, drives off, E-stop) is a V+
  error: the task ends and its connection closes; the supervisor (``task.controll``)
  restarts it after ``restart_s``, and the port refuses connections meanwhile;
* state (task 1, ``ros.srv.fdb``): JOINT_POSITION and STATUS, then ``state_period``; the
  STATUS fields as the program fills them. A client that leaves ends the task (its WRITE
  fails), restarted like task 0;
* I/O (task 4, ``ros.io``): the program's digital-signal protocol; a signal the
  controller has not installed is a V+ error that ends the task, which nothing restarts.

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
from dataclasses import dataclass, field
from typing import Any

from . import codec as sm
from .arm import Arm, Move
from .convention import (
    ACCEL_TIME_S,
    ESTOP_DECEL_DEG_S2,
    MAX_SPEED_DEG_S,
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
#: V+ signal numbers (V+ Language Reference, SIGNAL): outputs, inputs, soft signals
OUTPUT_NUMBERS = range(1, 513)
INPUT_NUMBERS = range(1001, 1513)
SOFT_SIGNALS = range(2001, 2513)


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
    monitor_speed: float = 100.0
    #: seconds from rest to full speed at 100 % (the Viper's acceleration, to be measured)
    accel_time_s: float = ACCEL_TIME_S
    #: V+'s shortest joint motion, seconds at 100 % (to be measured; 0: none)
    min_move_s: float = 0.0
    #: "client": the four bytes read on connecting are the client's first; "notice": V+'s own
    connect_read: str = "client"
    #: seconds the supervisor takes to restart an ended motion or state task
    restart_s: float = 0.5
    #: the digital signals the controller has (besides the soft signals 2001-2512)
    installed: tuple[range, ...] = field(default_factory=lambda: (range(1, 9), range(1001, 1013)))


class TaskEnds(Exception):
    """A V+ error in a program task: it stops (the message says why)."""


class Inbox:
    """What arrived on a connection, stamped with when (V+'s TCP buffer): the program
    takes it at its own pace."""

    def __init__(self, reader: asyncio.StreamReader, on_data: Callable[[], None] = lambda: None) -> None:
        self.on_data = on_data
        self.data = bytearray()
        self.taken = 0  # bytes taken so far
        self.stamps: deque[tuple[int, float]] = deque()  # (bytes received in all, when)
        self.more = asyncio.Event()
        self.eof = False
        self.pump = asyncio.ensure_future(self._pump(reader))

    async def _pump(self, reader: asyncio.StreamReader) -> None:
        try:
            while chunk := await reader.read(4096):
                self.data += chunk
                self.stamps.append((self.taken + len(self.data), time.monotonic()))
                self.on_data()
                self.more.set()
        except (ConnectionError, OSError):
            pass
        self.eof = True
        self.more.set()

    async def take(self, n: int) -> tuple[bytes, float]:
        """The next ``n`` bytes and when the last of them arrived; EOFError at the end."""
        while len(self.data) < n:
            if self.eof:
                raise EOFError
            self.more.clear()
            await self.more.wait()
        out = bytes(self.data[:n])
        del self.data[:n]
        self.taken += n
        while self.stamps and self.stamps[0][0] < self.taken:
            self.stamps.popleft()
        return out, self.stamps[0][1] if self.stamps else time.monotonic()

    def close(self) -> None:
        self.pump.cancel()


class Controller:
    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.codec = sm.Codec(cfg.byte_order)
        self.arm = Arm(cfg.start_pose_ctrl, time.monotonic(), monitor_speed=cfg.monitor_speed,
                       accel_time_s=cfg.accel_time_s, min_move_s=cfg.min_move_s)
        self.monitor_speed = cfg.monitor_speed
        self.e_stopped = False
        self.drives_powered = True
        self.slow_ack_ms = 0.0
        self.received = self.acknowledged = self.moves = self.task_errors = 0
        self.latencies_ms: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self.motion_client: asyncio.StreamWriter | None = None
        self.state_client: asyncio.StreamWriter | None = None
        self.io_clients: set[asyncio.StreamWriter] = set()
        # the program's tasks: running, or ended (the supervisor restarts motion and state)
        self.tasks = {"motion": True, "state": True, "io": cfg.io_port is not None}
        self.signals: dict[int, bool] = {}
        self.io_requests = self.io_errors = 0
        self.room = asyncio.Event()  # set whenever the arm takes a MOVE off its queue or halts
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
            event(f"the arm ran dry (the next MOVE came after the path had ended: it stops, then "
                  f"goes); {self.arm.underruns} so far")

    async def tick(self) -> None:
        while True:
            self.advance()
            # at rest nothing happens until a request, which advances the arm itself
            await asyncio.sleep(TICK_S if self.arm.in_motion else IDLE_TICK_S)

    def refusal(self) -> str | None:
        """Why a MOVE fails now, or None."""
        if self.e_stopped:
            return "E-stop is active"
        if not self.drives_powered:
            return "drives are off"
        return None

    def halt(self, why: str, decel: Iterable[float]) -> None:
        self.advance()
        dropped = self.arm.brake(decel, time.monotonic())
        self.room.set()
        event(f"{why}: the arm brakes, {dropped} issued MOVE(s) dropped")

    # ---- the program's tasks ----------------------------------------------------
    def task_ended(self, task: str, why: str) -> None:
        """A task stopped; the supervisor restarts motion and state after ``restart_s``."""
        self.tasks[task] = False
        event(f"{task} task ended: {why}")
        if task in ("motion", "state"):
            asyncio.get_running_loop().call_later(self.cfg.restart_s, self._restarted, task)

    def _restarted(self, task: str) -> None:
        self.tasks[task] = True
        event(f"{task} task restarted by task.controll")

    # ---- faults ---------------------------------------------------------------
    def estop(self) -> None:
        if not self.e_stopped:
            self.e_stopped = True
            self.drives_powered = False  # an Adept E-stop drops high power
            self.halt("E-stop", ESTOP_DECEL_DEG_S2)

    def estop_release(self) -> None:
        if self.e_stopped:
            self.e_stopped = False
            event("E-stop released (drives stay off until switched on)")

    def set_drives(self, on: bool) -> None:
        if on and self.e_stopped:
            raise ValueError("e-stop is active: release it before switching the drives on")
        if on != self.drives_powered:
            self.drives_powered = on
            if on:
                event("drives on")
            else:
                self.halt("drives off", [v / self.cfg.accel_time_s for v in MAX_SPEED_DEG_S])

    # ---- wire: state port (task 1) ----------------------------------------------
    def status_frame(self) -> bytes:
        """STATUS as ``ros.robot.state`` fills it (lines 327-371): drives and E-stop, error
        code and in_error always 0, in motion, mode AUTO, motion possible = not in motion."""
        moving = int(self.arm.in_motion)
        return self.codec.status(int(self.drives_powered), int(self.e_stopped), 0, 0, moving, MODE_AUTO,
                                 1 - moving)

    def state_frames(self) -> bytes:
        self.advance()
        joints = [math.radians(x) for x in self.arm.q]
        return self.codec.joint_position(joints) + self.status_frame()

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
            if self._release("state", writer):
                self.task_ended("state", "its client left (the WRITE failed)")

    # ---- wire: motion port (task 0) ------------------------------------------------
    async def serve_motion(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if not self._claim("motion", writer):
            return
        inbox = Inbox(reader, self._bytes_came)
        try:
            await self._motion_task(inbox, writer)
        except TaskEnds as exc:
            self.task_errors += 1
            if self._release("motion", writer):
                self.task_ended("motion", str(exc))
        except (EOFError, ConnectionError, OSError):
            if self._release("motion", writer):
                self.task_ended("motion", "the client closed the connection (IOSTAT -562)")
        finally:
            inbox.close()
            self.arm.close_stream()
            self._release("motion", writer)

    def _bytes_came(self) -> None:
        self.advance()
        self.arm.bytes_came()

    async def _motion_task(self, inbox: Inbox, writer: asyncio.StreamWriter) -> None:
        """``ros.srv.cmd`` from line 539 on: the discarded four bytes, then point after point."""
        if self.cfg.connect_read == "client":
            await inbox.take(4)
        while True:
            data, arrived = await inbox.take(sm.RECORD_LEN)
            record = self.codec.record(data)
            comm, seq = record.comm_type, record.sequence
            self.received += 1
            if comm == sm.SERVICE_REQUEST:
                await self._reply(writer, sm.STOP_TRAJECTORY if seq == sm.STOP_TRAJECTORY else 0, arrived)
            if seq == sm.STOP_TRAJECTORY:
                if comm != sm.SERVICE_REQUEST:
                    await self._reply(writer, sm.STOP_TRAJECTORY, arrived)
                self.arm.heard(arrived)
                self.arm.close_stream()
                event("stop (-4) answered; nothing halts: the issued MOVEs run out")
                continue
            await self._move(tuple(math.degrees(x) for x in record.joints_rad[:6]), seq, arrived)

    async def _move(self, q: tuple[float, ...], seq: int, arrived: float) -> None:
        """``MOVE #PPOINT(...)`` (lines 597-599), with V+'s forward processing: the motion is
        planned behind the running one and the instruction returns when it begins; TaskEnds
        when the controller cannot move there."""
        move = Move(q, arrived)
        issued = False
        while True:
            why = self.refusal() or limit_violation(q)  # also for a motion a brake dropped
            if why:
                raise TaskEnds(f"MOVE to point {seq} failed: {why}")
            self.advance()
            if not issued and self.arm.room:
                self.arm.issue(move)
                self.moves += 1
                issued = True
                continue
            if issued and not any(m is move for m in self.arm.queue):
                break
            self.room.clear()
            await self.room.wait()
        if seq == sm.END_TRAJECTORY:
            self.arm.close_stream()  # for the statistics only: the program treats -3 as a point

    async def _reply(self, writer: asyncio.StreamWriter, sequence: int, arrived: float) -> None:
        """The acknowledgement (lines 578-586): JOINT_TRAJ_PT, service reply, code 1, one int32."""
        if self.slow_ack_ms > 0:
            await asyncio.sleep(self.slow_ack_ms / 1000.0)
        writer.write(self.codec.traj_reply(sm.SUCCESS, sequence))
        await writer.drain()
        self.latencies_ms.append((time.monotonic() - arrived) * 1000.0)
        self.acknowledged += 1

    # ---- wire: I/O port (task 4) -------------------------------------------------------
    async def serve_io(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """The program's own I/O protocol (``ros.io``): two V+ READs per request, each
        taking what has arrived as one record, and a big-endian int32 (LNGB) from the first
        four bytes of each: the mode (1 read, anything else write), then the signal
        (negative: switch off). The answer is ASCII without a line end: SIG(n) as $ENCODE
        writes it (-1 on, 0 off) for a read, ``1`` after SIGNAL(n) for a write. Once the
        task has ended nothing is answered any more."""
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
                if not self.tasks["io"]:
                    continue  # the task has ended: the connection stays, nobody reads it
                answer = self._io(mode, number)
                if answer is None:
                    continue
                self.io_requests += 1
                writer.write(answer.encode())
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
        bytes (V+ LNGB fails: the program's task ends)."""
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
            if self.tasks["io"]:
                self.task_ended("io", f"LNGB of a record of {len(record)} byte(s)")
            return None
        if len(record) > 4:
            event(f"io: a record of {len(record)} bytes, the V+ program reads the first 4 "
                  "(send the mode and the number as separate records)")
        return int.from_bytes(record[:4], "big", signed=True)

    def _installed(self, n: int) -> bool:
        return n in SOFT_SIGNALS or any(n in r for r in self.cfg.installed)

    def _io(self, mode: int, number: int) -> str | None:
        """The answer to one request (lines 461-472), or None when it ended the task."""
        n = abs(number)
        if mode == 1:
            if not self._installed(n):
                self.task_ended("io", f"SIG({number}): no such signal is installed")
                return None
            return "-1" if self.signals.get(n, False) else "0"  # V+ TRUE is -1
        if not self._installed(n) or n in INPUT_NUMBERS:
            self.task_ended("io", f"SIGNAL({number}): not an installed output or soft signal")
            return None
        self.signals[n] = number > 0
        event(f"io: SIGNAL {number}")
        return "1"

    # ---- connections ----------------------------------------------------------------
    def _claim(self, port: str, writer: asyncio.StreamWriter) -> bool:
        if not self.tasks[port]:
            event(f"{port}: the {port} task is not running, the connection is refused")
            writer.close()
            return False
        if getattr(self, f"{port}_client") is not None:
            event(f"{port}: a client is already connected, refusing another")
            writer.close()
            return False
        setattr(self, f"{port}_client", writer)
        event(f"{port}: client connected from {_peer(writer)}")
        return True

    def _release(self, port: str, writer: asyncio.StreamWriter) -> bool:
        """The connection closed; True when it was this port's client until now."""
        writer.close()
        if getattr(self, f"{port}_client") is writer:
            setattr(self, f"{port}_client", None)
            event(f"{port}: client disconnected")
            if port == "motion":
                self.room.set()  # a MOVE waiting for room notices
            return True
        return False

    def drop(self, port: str) -> bool:
        if port == "io":
            dropped = bool(self.io_clients)
            for w in list(self.io_clients):
                w.close()
            return dropped
        writer = getattr(self, f"{port}_client")
        if writer is None:
            return False
        writer.close()  # the task sees its connection end (and ends, to be restarted)
        event(f"{port}: connection dropped on request")
        return True

    # ---- control channel --------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        self.advance()
        arm = self.arm
        q = [round(x, 6) for x in arm.q]
        lat = sorted(self.latencies_ms)
        return {
            "ok": True,
            "position_rob6_deg": [round(x, 6) for x in controller_to_rob6(arm.q)],
            "position_controller_deg": q,
            "velocity_controller_deg_s": [round(x * arm.rate, 4) for x in arm.v],
            "queue_length": len(arm.queue),
            "points_received": self.received,
            "points_acknowledged": self.acknowledged,
            "moves_issued": self.moves,
            "points_executed": arm.executed,
            "task_errors": self.task_errors,
            "underruns": arm.underruns,
            "longest_segment_s": round(arm.longest_segment_s, 4),
            "longest_segment_deg": [round(x, 4) for x in arm.longest_segment_deg],
            "ran_on_s": round(arm.ran_on_s, 4),
            "max_ran_on_s": round(arm.max_ran_on_s, 4),
            "ran_on_deg": round(arm.ran_on_deg, 4),
            "max_ran_on_deg": round(arm.max_ran_on_deg, 4),
            "last_motion_s": round(arm.last_motion_s, 4),
            "monitor_speed": self.monitor_speed,
            "peak_speed_deg_s": [round(x, 4) for x in arm.peak_speed],
            "peak_accel_deg_s2": [round(x, 3) for x in arm.peak_accel],
            "in_motion": arm.in_motion,
            "e_stopped": self.e_stopped,
            "drives_powered": self.drives_powered,
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
            "tasks": dict(self.tasks),
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
        elif cmd == "monitor_speed":
            percent = req.get("percent")
            if not isinstance(percent, (int, float)) or isinstance(percent, bool) or not 1 <= percent <= 100:
                raise ValueError('"monitor_speed" needs "percent" between 1 and 100')
            self.monitor_speed = float(percent)
            self.arm.set_monitor_speed(self.monitor_speed, time.monotonic())
            event(f"monitor speed {percent:g} %")
        elif cmd == "quit":
            self.done.set()
        else:
            raise ValueError(
                f"unknown cmd {cmd!r}; known: status, estop, estop_release, drives, drop_connection, "
                "slow_ack, monitor_speed, quit"
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
