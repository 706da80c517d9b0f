"""The RSI link: drives a KUKA KR C4 over RSI (Robot Sensor Interface, Ethernet XML).

The clock is the robot. The controller sends one ``<Rob>`` packet per interpolation
cycle (4 ms ``#IPO_FAST`` on kr3rt/kr16rt, 12 ms ``#IPO`` on kr3/kr16) to this PC,
which listens as the UDP server (``ROB6_RSI_LISTEN``). Each packet is one motion-core
cycle: the receive thread parses it, steps the core, and answers at once with the
setpoint as ``AK``, the absolute axis correction from the run's start pose
(``RSI_ON(#ABSOLUTE)``): ``AK = q - ASPos``. rob6's joint values are the KUKA axis
angles A1..A6 in degrees. Publishing the state and reporting events come after the
answer; events are logged and published by a separate thread.

Rules that keep the robot from jumping (the controller trips "Command velocity" on a
step faster than an axis can move, and stops RSI after ``Timeout`` late packets):

* A new run is recognised by what the controller changes at ``RSI_ON``: ``Delay``
  starts again from 0, and ``ASPos`` is the programmed pose, which the shipped program
  (deploy/kuka) sets to where the arm stands with ``PTP $AXIS_ACT`` before each
  ``RSI_ON``. (A controller keeps the old ASPos across RSI_OFF/RSI_ON without a motion;
  then nothing tells the runs apart, and nothing needs to: the arm stands where rob6
  commanded it.) The first packet of a run is answered with ``AK = AIPos - ASPos``: the
  core resumes where the arm stands, at rest, whatever ASPos the program left.
* No packet for ``LOST_AFTER_CYCLES`` cycles (25: 100 ms at 4 ms, 300 ms at 12 ms; far
  above Python's scheduling jitter on a loaded machine, well inside RSI's 100-packet
  timeout) means the link is lost: a running motion ends with ``false`` and an error
  naming the link, motion commands are refused. The controller holds its last
  correction meanwhile. When packets come back in the same run the core resumes from
  the robot's actual position ``AIPos`` (``AK = AIPos - ASPos``), never from where the
  interrupted motion would have been.
* A ``Delay`` increase that missing packets do not explain means our last answer came
  too late (or was lost) and the controller still applies the one before: the packet
  is answered with the same setpoint again instead of a new step, so the correction
  the controller sees never moves more than one cycle's step at once.
* Packets that queued up while the driver could not run are skipped: only the newest
  is answered (the others are late anyway). Duplicated and reordered (older) packets
  are not answered.
* A run whose packets come faster than the robot's cycle (``IPOC``, a millisecond time
  stamp, 4 ms on from the last packet while a 12 ms kr3/kr16 driver plans 12 ms steps:
  the program's ``rob6IpoFast`` is TRUE) is refused: rob6 would command three times its
  planned speeds. Every packet of that run is answered with the arm where it stands and
  ``<Stop>1</Stop>`` (RSI_MOVECORR returns, the program ends without a fault), motion
  commands are refused with one line saying both cycles and what to set, state
  ``refused``, then ``stopped`` once the packets stop; the next run (the operator's
  restart) is checked again.

Statistics: packet in (kernel receive time stamp) -> answer sent, as a histogram
(``status()``), and the ``late``/``missed`` counts published in every joint state.
"""

from __future__ import annotations

import gc
import logging
import math
import os
import queue
import select
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from rob6.messages import LinkEvent, LinkStatus
from rob6.robots import RobotModel
from rob6.units import speed_si

from ..motion import MotionCore
from . import Link, Publish
from .rsi_codec import RobPacket, RsiParseError, format_sen, ipoc_of, parse_rob

log = logging.getLogger("rob6.driver")

DEFAULT_LISTEN = "0.0.0.0:49152"
DEFAULT_SEN_TYPE = "ImFree"
#: cycles without a packet after which the link counts as lost
LOST_AFTER_CYCLES = 25
#: a time stamp this many cycles older than the last one starts a new run (a
#: controller restart), a smaller step back is a reordered packet
STALE_WINDOW_CYCLES = 1000
#: an arm reported this much (deg) beyond what its axes can travel since the last packet has
#: been moved by another program: a new run (AIPos has 4 decimals)
JUMP_TOL_DEG = 1e-3
#: consecutive unexplained late packets before saying that our answers do not arrive
NOT_ARRIVING = 10
LATENCY_BIN_US = 5
LATENCY_BINS = 4000  # 20 ms; slower answers land in the last bin (the max is exact)
#: how long ``stop()`` answers (with Stop) at most, waiting for the controller to switch RSI off
STOP_WAIT_S = 2.0
#: SCHED_FIFO priority of the receive thread (below the kernel's own threaded IRQs at 50)
RT_PRIORITY = 40
#: a bus worker holding the GIL would delay the receive thread by up to the switch
#: interval (5 ms by default): more than a 4 ms cycle
SWITCH_INTERVAL_S = 0.0005

MAX_PACKET = 8192

_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", None)
_TIMESPEC = struct.Struct("@qq")
_ANCILLARY = socket.CMSG_SPACE(_TIMESPEC.size)


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[v6]:PORT``) -> (host, port); ValueError with the expected form."""
    host, sep, port = text.strip().rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"RSI listen address {text!r}: expected HOST:PORT, e.g. {DEFAULT_LISTEN}")
    return host, int(port)


class RsiLink(Link):
    kind = "rsi"

    def __init__(self, core: MotionCore, robot: RobotModel, listen: str, publish: Publish,
                 on_event: Callable[[LinkEvent], None] | None = None, *,
                 sen_type: str = DEFAULT_SEN_TYPE, lost_after_s: float | None = None) -> None:
        if not robot.is_kuka:
            raise ValueError(f"RSI drives KUKA robots (kr3, kr16, kr3rt, kr16rt), not {robot.name}")
        self.core = core
        self.publish = publish
        self.on_event = on_event
        self.robot = robot
        self.sen_type = sen_type.encode("ascii")
        self.cycle_s = core.dt
        self._rated = speed_si(robot.speed_bound)  # deg/s: the fastest the axes go
        self.lost_after_s = lost_after_s if lost_after_s is not None else LOST_AFTER_CYCLES * core.dt
        host, port = parse_address(listen)
        family, kind, proto, _, sockaddr = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        self.sock = socket.socket(family, kind, proto)
        try:
            self.sock.bind(sockaddr)
        except OSError:
            self.sock.close()
            raise
        bound = self.sock.getsockname()
        self.address = f"[{bound[0]}]:{bound[1]}" if family == socket.AF_INET6 else f"{bound[0]}:{bound[1]}"
        self._stamped = False
        if _SO_TIMESTAMPNS is not None:
            try:
                self.sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self._stamped = True
            except OSError:
                pass
        self.sock.setblocking(False)
        # the plant's state (written by the receive thread only)
        self.state = "waiting"
        self.peer: tuple[str, int] | None = None
        self.q_actual: list[float] | None = None
        self.late = 0
        self.missed = 0
        self.packets = 0
        self.runs = 0
        self.garbage = 0
        self.foreign = 0
        self.stale = 0
        self.skipped = 0
        self._aspos: tuple[float, ...] | None = None
        self._aspos_arr = np.zeros(6)
        self._delay = 0
        self._stamp = 0
        self._stamp_step = max(1, round(self.cycle_s * 1000))  # IPOC counts ms
        self._expected_late = 0
        self._expected_age = 0
        self._unexplained = 0
        self._late_logged = 0.0
        self._setpoint = np.zeros(6)
        self._moving_when_lost = False
        self._hist = [0] * LATENCY_BINS
        self._max_us = 0.0
        self._stopping = False
        self._stop_sent = threading.Event()
        self._closing = False
        self._heard = 0.0  # monotonic time of the last answered packet
        self.realtime = False  # the receive thread got real-time scheduling
        self._reports = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._reporter: threading.Thread | None = None
        self.waiting_reason = f"robot not connected (waiting for RSI on {self.address})"
        core.offline(self.waiting_reason)

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        gc.freeze()  # what exists at start-up is never collected: collections stay short
        self._reporter = threading.Thread(target=self._report_loop, name="driver-rsi-events", daemon=True)
        self._reporter.start()
        self._report("waiting", f"driver: waiting for the robot: RSI on udp/{self.address}", logging.WARNING)
        self._thread = threading.Thread(target=self._run, name="driver-rsi", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """End the correction run: answer ``<Stop>1</Stop>`` until the controller has left
        RSI_MOVECORR and switched RSI off (no packet for ``lost_after_s``), then close. A
        packet left unanswered would count late, and the program's RSI_OFF comes a cycle
        after RSI_MOVECORR returns."""
        if self._thread is not None and self.state == "connected":
            self._stopping = True
            wait_s = max(STOP_WAIT_S, 2 * self.lost_after_s)
            deadline = time.monotonic() + wait_s
            self._stop_sent.wait(wait_s)
            while self.state == "connected" and time.monotonic() < deadline:
                time.sleep(self.cycle_s)
            if self.state == "connected":
                log.warning("driver: the controller still sends after %.1f s of <Stop>1</Stop>: is the Stop object "
                            "wired to the RECEIVE element Stop (deploy/kuka)?", wait_s)
        self._closing = True
        if self._thread is not None:
            self._thread.join(1.0)
        self.sock.close()
        self._reports.put(None)
        if self._reporter is not None:
            self._reporter.join(1.0)
        gc.unfreeze()  # let the interpreter's exit clean up as usual
        log.info("driver: RSI link closed: %d packets answered, %d late, %d missed, %d runs, %d unreadable",
                 self.packets, self.late, self.missed, self.runs, self.garbage)

    # ------------------------------------------------------------------ status
    def status(self, reset: bool = False) -> LinkStatus:
        hist, top = self._hist, self._max_us
        if reset:
            self._hist, self._max_us = [0] * LATENCY_BINS, 0.0
        total = sum(hist)
        latency = []
        if total:
            latency = [_percentile(hist, total, 0.50), _percentile(hist, total, 0.99), round(top, 1)]
        return LinkStatus(link="rsi", state=self.state, address=self.address,
                          peer=_peer(self.peer), packets=self.packets, late=self.late,
                          missed=self.missed, runs=self.runs, garbage=self.garbage,
                          start_pose=None if self._aspos is None else list(self._aspos),
                          latency_us=latency, realtime=self.realtime)

    # ------------------------------------------------------------------ the receive thread
    def _run(self) -> None:
        self.realtime = _realtime_priority()
        poller = select.poll()
        poller.register(self.sock, select.POLLIN)
        self._heard = time.monotonic()
        while not self._closing:
            try:
                # lost after lost_after_s without an answered packet (garbage does not count)
                remaining = self._heard + self.lost_after_s - time.monotonic()
                if remaining <= 0 or not poller.poll(math.ceil(remaining * 1000)):
                    if time.monotonic() >= self._heard + self.lost_after_s:
                        self._heard = time.monotonic()
                        self._on_silence()
                    continue
                batch = self._drain()
                if not batch:
                    continue
                if len(batch) > 1:  # they queued up while we could not run: only the newest cycle counts
                    own = [item for item in batch if item[1] == self.peer] if self.state == "connected" else []
                    self.skipped += len(own or batch) - 1
                    batch = sorted(own or batch, key=lambda item: ipoc_of(item[0]))
                data, addr, t_in = batch[-1]
                self._on_packet(data, addr, t_in)
            except OSError as exc:
                if self._closing:
                    break
                log.warning("driver: RSI socket error: %s", exc)
                time.sleep(self.cycle_s)
            except Exception:  # never let one packet end the link
                log.exception("driver: RSI packet handling failed")

    def _drain(self) -> list[tuple[bytes, tuple[str, int], int]]:
        """Every datagram waiting: (data, sender, kernel receive time in ns)."""
        batch = []
        while True:
            try:
                if self._stamped:
                    data, ancdata, _flags, addr = self.sock.recvmsg(MAX_PACKET, _ANCILLARY)
                    batch.append((data, addr, _kernel_time(ancdata)))
                else:
                    data, addr = self.sock.recvfrom(MAX_PACKET)
                    batch.append((data, addr, time.time_ns()))
            except BlockingIOError:
                return batch

    def _on_packet(self, data: bytes, addr: tuple[str, int], t_in: int) -> None:
        try:
            pkt = parse_rob(data)
        except RsiParseError as exc:
            self.garbage += 1
            if self.garbage <= 10 or self.garbage % 1000 == 0:
                self._report("garbage", f"driver: unreadable packet #{self.garbage} from {_peer(addr)}: {exc}",
                             logging.WARNING)
            return
        core = self.core
        if self.state == "connected" and addr != self.peer:
            self.foreign += 1
            if self.foreign <= 10 or self.foreign % 1000 == 0:
                self._report("garbage", f"driver: ignored an RSI packet from {_peer(addr)}: the robot is "
                             f"{_peer(self.peer)}", logging.WARNING)
            return
        stamp_gone_back = pkt.stamp < self._stamp - STALE_WINDOW_CYCLES * self._stamp_step
        new_run = (self._aspos is None or pkt.aspos != self._aspos or pkt.delay < self._delay or stamp_gone_back
                   or self._jumped(pkt))
        hold = False
        if new_run or self.state == "stopped":  # after a refused run: the operator's restart
            self._begin_run(pkt, addr)
        elif self.state == "refused":  # the rest of a refused run: Stop until RSI is off
            self._delay, self._stamp = pkt.delay, max(self._stamp, pkt.stamp)
            self._answer_refused(pkt, addr)
            return
        elif self.state != "connected":  # packets are back in the same run
            self.late += pkt.delay - self._delay
            self.missed += max(0, round((pkt.stamp - self._stamp) / self._stamp_step) - 1)
            self._expected_late = self._unexplained = 0
            self._moving_when_lost = False
            core.online(pkt.aipos)
            self.state, self.peer = "connected", addr
            self._report("back", f"driver: RSI link back after {pkt.delay - self._delay} late packets; "
                         f"continuing from the robot's actual position", logging.WARNING, pkt)
        else:
            if pkt.stamp <= self._stamp:  # duplicated or overtaken: that cycle is over
                self.stale += 1
                return
            diff = pkt.stamp - self._stamp
            if diff < self._stamp_step:  # the controller's cycle is finer than the robot's
                self._refuse(pkt, addr, diff)
                return
            gap = round(diff / self._stamp_step) - 1
            if gap > 0:
                self.missed += gap
                self._expected_late += gap
                self._expected_age = 0
            elif self._expected_late:
                self._expected_age += 1
                if self._expected_age > 2:  # that lateness was never counted
                    self._expected_late = 0
            d = pkt.delay - self._delay
            if d > 0:
                self.late += d
                explained = min(d, self._expected_late)
                self._expected_late -= explained
                hold = d > explained
                self._unexplained = self._unexplained + 1 if hold else 0
                self._on_late(pkt, d, hold)
            else:
                self._unexplained = 0
        self._delay = pkt.delay
        self._stamp = pkt.stamp
        state = None
        if not hold:  # else: the controller still applies the answer before ours: send ours again
            state = core.step()
            self._setpoint = state.q
        ak = (self._setpoint - self._aspos_arr).tolist()
        stop = self._stopping
        self.sock.sendto(format_sen(self.sen_type, ak, pkt.ipoc, stop), addr)
        latency_us = max(0.0, (time.time_ns() - t_in) / 1000.0)
        self._hist[min(int(latency_us) // LATENCY_BIN_US, LATENCY_BINS - 1)] += 1
        self._max_us = max(self._max_us, latency_us)
        self.packets += 1
        self._heard = time.monotonic()
        # after the answer: nothing here can make it late
        self.q_actual = list(pkt.aipos)
        if stop and not self._stop_sent.is_set():
            self._stop_sent.set()
            self._report("stop_sent", "driver: RSI Stop sent: the correction run ends", logging.INFO, pkt)
        if state is not None:
            self.publish(state)

    def _jumped(self, pkt: RobPacket) -> bool:
        """Has the arm moved farther since the last packet than its axes can (twice its rated
        speeds)? Then the controller ran another program in between (the operator jogged it
        and restarted RSI at the same start pose, with no late packet in the run before): a
        new run, not a correction to continue."""
        if not self.q_actual:
            return False
        seconds = max(1.0, (pkt.stamp - self._stamp) / self._stamp_step) * self.cycle_s
        return any(abs(a - b) > 2.0 * v * seconds + JUMP_TOL_DEG
                   for a, b, v in zip(pkt.aipos, self.q_actual, self._rated, strict=True))

    def _refuse(self, pkt: RobPacket, addr: tuple[str, int], step_ms: int) -> None:
        """This run's cycle is not the robot's: refuse the run in one line and stop it."""
        expected = self._stamp_step
        name = self.robot.name
        if name.endswith("rt"):
            advice = "make ROB6_ROBOT and rob6IpoFast in rob6_rsi.dat agree (deploy/kuka/README.md)"
        else:
            advice = (f"set ROB6_ROBOT={name}rt (4 ms, #IPO_FAST), or rob6IpoFast FALSE in rob6_rsi.dat "
                      f"(#IPO, 12 ms: KSS 8.5 and later only)")
        reason = (f"RSI run refused: ROB6_ROBOT={name} expects a packet every {expected} ms, the controller "
                  f"sends one every {step_ms} ms: {advice}")
        self._delay, self._stamp = pkt.delay, pkt.stamp
        self.state = "refused"
        self.core.offline(reason)
        self._report("wrong_cycle", f"driver: {reason}", logging.ERROR, pkt)
        self._answer_refused(pkt, addr)
        self.publish(self.core.state())

    def _answer_refused(self, pkt: RobPacket, addr: tuple[str, int]) -> None:
        """The arm held where the run found it, and Stop: RSI_MOVECORR returns."""
        ak = (self._setpoint - self._aspos_arr).tolist()
        self.sock.sendto(format_sen(self.sen_type, ak, pkt.ipoc, True), addr)
        self.packets += 1
        self._heard = time.monotonic()
        self.q_actual = list(pkt.aipos)

    def _begin_run(self, pkt: RobPacket, addr: tuple[str, int]) -> None:
        """A new RSI run: the core at rest where the arm stands (AIPos), AK = AIPos - ASPos."""
        previous = self._aspos
        was = self.state
        self.runs += 1
        self.late += pkt.delay
        self._aspos = pkt.aspos
        self._aspos_arr = np.array(pkt.aspos)
        self._expected_late = self._unexplained = 0
        moving = self._moving_when_lost or (was == "connected" and self.core.state().moving)
        self._moving_when_lost = False
        pose = " ".join(f"{a:.3f}" for a in pkt.aspos)
        self.core.online(pkt.aipos, reason="the controller restarted RSI during the motion")
        self.state, self.peer = "connected", addr
        if previous is None:
            self._report("run_start", f"driver: RSI run started by {_peer(addr)}, start pose {pose}",
                         logging.WARNING, pkt, start=True)
            return
        if moving:
            self._report("trip", "driver: the controller ended the previous RSI run during a motion "
                         "(a monitoring trip such as 'Command velocity', an E-stop, or its RSI timeout after "
                         "too many late packets): see the controller's messages", logging.ERROR, pkt)
        self._report("restart", f"driver: RSI restarted, new start pose {pose}; continuing from there",
                     logging.WARNING, pkt, start=True)

    def _on_late(self, pkt: RobPacket, count: int, ours: bool) -> None:
        """Every increase is published; the log says it at most once a second."""
        now = time.monotonic()
        level = logging.WARNING if now - self._late_logged >= 1.0 else logging.INFO
        if level == logging.WARNING:
            self._late_logged = now
        if self._unexplained == NOT_ARRIVING:
            self._report("late", f"driver: {NOT_ARRIVING} answers in a row came too late or did not reach the "
                         f"controller at {_peer(self.peer)} (firewall? the RSI configuration's IP and port?)",
                         logging.ERROR, pkt)
        elif self._unexplained < NOT_ARRIVING:
            what = "answer came too late or was lost" if ours else "packets did not reach the driver"
            self._report("late", f"driver: the controller counted {count} more late packet(s) "
                         f"({self.late} in all): {what}", level, pkt)

    def _on_silence(self) -> None:
        """No packet for ``lost_after_s``: the link is lost (or still not there), or after
        our Stop the controller switched RSI off."""
        if self.state == "refused":  # the controller left RSI_MOVECORR: a packet now is a new run
            self.state = "stopped"
            self._report("stopped", "driver: the controller left RSI_MOVECORR and switched RSI off (the run was "
                         "refused)", logging.INFO)
        elif self.state == "connected" and self._stopping:
            self.state = "stopped"
            self.core.offline("RSI stopped by the driver")
            self._report("stopped", "driver: the controller left RSI_MOVECORR and switched RSI off", logging.INFO)
        elif self.state == "connected":
            self.state = "lost"
            ms = round(self.lost_after_s * 1000)
            reason = f"RSI link lost: no packet from the controller at {_peer(self.peer)} for {ms} ms"
            self._moving_when_lost = self.core.state().moving
            self.core.offline(reason)
            self._report("lost", f"driver: {reason}", logging.WARNING)
        # the bus sees the link's state even without cycles
        self.publish(self.core.state())

    # ------------------------------------------------------------------ events
    def _report(self, event: str, message: str, level: int, pkt: RobPacket | None = None,
                start: bool = False) -> None:
        self._reports.put((level, LinkEvent(
            t=time.time(), event=event, message=message.removeprefix("driver: "), cycle=self.core.cycle,
            late=self.late, start_pose=list(pkt.aspos) if start and pkt is not None else None,
            q_actual=list(pkt.aipos) if pkt is not None else None)))


def _realtime_priority() -> bool:
    """Real-time scheduling for the calling thread where allowed (root, CAP_SYS_NICE, an
    rtprio limit): then no other process on the PC can make an answer late. The thread
    never spins (it sleeps in poll), so it cannot starve the machine."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except (AttributeError, OSError):
        log.info("driver: the RSI thread runs at normal priority (real-time scheduling not permitted)")
        return False
    return True


def _kernel_time(ancdata: list[tuple[int, int, bytes]]) -> int:
    for level, kind, data in ancdata:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size:
            sec: int
            nsec: int
            sec, nsec = _TIMESPEC.unpack_from(data)
            return sec * 1_000_000_000 + nsec
    return time.time_ns()


def _peer(addr: tuple[str, int] | None) -> str:
    if not addr:
        return "-"
    return f"[{addr[0]}]:{addr[1]}" if ":" in addr[0] else f"{addr[0]}:{addr[1]}"


def _percentile(hist: list[int], total: int, q: float) -> float:
    """Upper edge of the bin holding the q-quantile (microseconds)."""
    rank = math.ceil(q * total)
    seen = 0
    for i, count in enumerate(hist):
        seen += count
        if seen >= rank:
            return float((i + 1) * LATENCY_BIN_US)
    return float(len(hist) * LATENCY_BIN_US)
