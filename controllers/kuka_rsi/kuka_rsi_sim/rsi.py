"""The RSI part of the KR C4, one IPO cycle at a time, without any I/O.

The loaded context decides the signal flow (RSI_ON(#ABSOLUTE)): ETHERNET (answers read with
the configuration's RECEIVE elements, HOLDON on a late answer, Timeout) -> STOP
(ExitMoveCorr: RSI_MOVECORR returns) and -> AXISCORR (each axis' correction clamped to its
LowerLim..UpperLim) with AXISCORRMON (a correction beyond Max stops RSI); then the motion
system: the command ASPos + correction must stay inside the software limit switches and
must not step faster than an axis can move; the axes follow the command at most at rated
speed. ASPos is the programmed position RSI_ON found (the last motion's target), never a
corrected one. Corrections move the axes only while RSI_MOVECORR runs.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

from .context import SignalFlow
from .kinematics import Kinematics, Pose
from .machine import Machine
from .wire import AXES, RobWriter, Sen

# The command-velocity monitor allows 2 % over the rated speed, plus 0.0002 deg for the
# 4-decimal rounding of two successive AK values (the PC may send with any precision).
VEL_TOLERANCE = 0.02
VEL_ABS_TOLERANCE = 2e-4

MAX_TRIPS_KEPT = 100
#: the message of the ETHERNET object stopping RSI after Timeout late packets, by generation
TIMEOUT_ERROR = {"3": "RSIBad", "4.1": "RSITimeout", "5.0": "RSITimeout"}


class Rsi:
    def __init__(self, machine: Machine, generation: str, start_pose: Sequence[float],
                 log: Callable[[str], None]) -> None:
        self.machine = machine
        self.generation = generation
        self.flow: SignalFlow | None = None  # the context RSI_ON switched on
        self.cycle_ms = 12
        self._kin = Kinematics(machine)
        self._writer: RobWriter | None = None
        self._log = log
        self._servo_step: tuple[float, ...] = ()
        self.vel_limit: tuple[float, ...] = ()
        self._lower, self._upper = machine.lower, machine.upper

        self.running = False  # RSI is on (RSI_ON .. RSI_OFF): a packet every cycle
        self.in_movecorr = False  # RSI_MOVECORR runs: corrections move the axes
        self.movecorr_done = False  # the Stop object ended RSI_MOVECORR this cycle
        self.runs = 0
        self.stop_reason = ""
        self.stop_kind: str | None = None  # "program" (RSI_OFF), "fault", "operator", "off"
        self.trips: list[str] = []
        self.aipos = [float(v) for v in start_pose]
        self.aspos = list(self.aipos)
        self.outputs: dict[int, float | str] = {}  # the ETHERNET object's outputs (RECEIVE INDX -> value)
        self.corr = [0.0] * 6  # AXISCORR's output: the correction applied
        self.cmd = list(self.aipos)
        self.cycle = 0  # packets of this run
        self.delay = 0  # late packets of this run (the Delay element)
        self.late_total = 0
        self.replies_ok = 0
        self.not_taken = 0  # answers of this run the configuration could not take
        self.max_ak_step = [0.0] * 6
        self.ipoc = 0  # IPOC of the last packet
        self._fk_cache: dict[str, tuple[tuple[float, ...] | None, Pose | None]] = {
            "rist": (None, None), "rsol": (None, None)}

    # ------------------------------------------------------------------ run control
    def within_limits(self, q: Sequence[float]) -> str | None:
        """None if q is inside the software limits, else what is wrong."""
        for n in range(6):
            if not self._lower[n] <= q[n] <= self._upper[n]:
                return f"{AXES[n]} = {q[n]:g} is outside {self._lower[n]:g} .. {self._upper[n]:g}"
        return None

    def move_to(self, pose: Sequence[float]) -> None:
        """A motion with RSI off (a PTP, or the operator jogging): the axes are there."""
        assert not self.running
        self.aipos = [float(v) for v in pose]
        self.cmd = list(self.aipos)

    def set_flow(self, flow: SignalFlow, cycle_ms: int) -> None:
        """The context and cycle of the next run (RSI_ON)."""
        assert not self.running
        self.flow = flow
        self.cycle_ms = cycle_ms
        self._writer = RobWriter(flow.ethernet.send, flow.precision)
        dt = cycle_ms / 1000.0
        self._servo_step = tuple(r * dt for r in self.machine.rated)
        self.vel_limit = tuple(r * dt * (1.0 + VEL_TOLERANCE) + VEL_ABS_TOLERANCE for r in self.machine.rated)

    def start_run(self, programmed: Sequence[float]) -> None:
        """RSI_ON: ASPos is the programmed position; the command starts where the axes stand."""
        self.runs += 1
        self.running = True
        self.in_movecorr = self.movecorr_done = False
        self.stop_reason = ""
        self.stop_kind = None
        self.aspos = [float(v) for v in programmed]
        self.cmd = list(self.aipos)
        self.outputs = {}
        self.corr = [0.0] * 6
        self.cycle = 0
        self.delay = 0
        self.not_taken = 0
        self.max_ak_step = [0.0] * 6
        self._log(f"run {self.runs}: RSI_ON, ASPos {_fmt(self.aspos)}, AIPos {_fmt(self.aipos)}")

    def end_run(self, reason: str, kind: str) -> None:
        if not self.running:
            return
        self.running = self.in_movecorr = False
        self.stop_reason = reason
        self.stop_kind = kind
        if kind == "program":
            self.aipos = list(self.cmd)  # RSI_OFF after the axes settled on the last command
        else:
            self.cmd = list(self.aipos)  # braked where it stood
        self._log(f"run {self.runs} ended: {reason} ({self.cycle} packets, {self.delay} late)")

    def _trip(self, message: str, detail: str) -> None:
        self.trips.append(message)
        del self.trips[:-MAX_TRIPS_KEPT]
        self._log(f"TRIP {message}: {detail} (run {self.runs}, IPOC {self.ipoc})")
        self.end_run(message, "fault")

    # ------------------------------------------------------------------ one IPO cycle
    def step(self, answer: Sen | None, ipoc: int) -> bytes | None:
        """One cycle: settle the answer to the previous packet (None: none came in time),
        move the axes, and return this cycle's packet; None when RSI stopped."""
        if not self.running:
            return None
        flow, writer = self.flow, self._writer
        assert flow is not None and writer is not None
        if self.cycle > 0:
            # servo: the axes follow the command of the previous cycle
            for n in range(6):
                d = self.cmd[n] - self.aipos[n]
                s = self._servo_step[n]
                self.aipos[n] += s if d > s else -s if d < -s else d
            if flow.ethernet.only_send:
                pass  # ONLYSEND: no answer expected, the outputs stay as they are
            elif answer is None:
                self._late()
            else:
                self._apply(answer)
            if not self.running:
                return None
        self.cycle += 1
        self.ipoc = ipoc
        return writer.packet(
            self._pose("rist", self.aipos), self._pose("rsol", self.cmd), self.aipos, self.aspos, self.delay, ipoc
        )

    def _late(self) -> None:
        """No answer taken in time: count it; each output holds its value (HOLDON 1) or drops to 0."""
        flow = self.flow
        assert flow is not None
        self.delay += 1
        self.late_total += 1
        for r in flow.ethernet.receive:
            if not r.holdon:
                self.outputs[r.indx] = 0.0
        if self.delay >= flow.timeout:
            error = TIMEOUT_ERROR.get(self.generation, "RSITimeout")
            self._trip(f"KSS29002 Signal flow (running): Object {flow.ethernet_id} returns error {error}",
                       f"{self.delay} packets of this run answered late or not at all (Timeout {flow.timeout})")
            return
        self._signal_flow()

    def _apply(self, sen: Sen) -> None:
        self.replies_ok += 1
        self.outputs.update(sen.values)
        self._signal_flow()

    def _signal_flow(self) -> None:
        flow = self.flow
        assert flow is not None
        corr = [0.0] * 6
        for n, indx in enumerate(flow.corr_outputs):  # AXISCORR clamps each axis to its window
            raw = self.outputs.get(indx, 0.0) if indx is not None else 0.0
            assert isinstance(raw, float)
            self.max_ak_step[n] = max(self.max_ak_step[n], abs(raw - self.corr[n]))
            corr[n] = min(max(raw, flow.lower[n]), flow.upper[n])
        if flow.monitor is not None:  # AXISCORRMON stops RSI beyond its window
            for n in range(6):
                if abs(corr[n]) > flow.monitor[n]:
                    self._trip(f"AXISCORRMON: correction limit {AXES[n]} exceeded",
                               f"correction {AXES[n]} = {corr[n]:.4f}, Max{AXES[n]} {flow.monitor[n]:g}")
                    return
        stop = flow.stop_output is not None and self.outputs.get(flow.stop_output, 0.0) not in (0.0, "")
        if not self.in_movecorr:
            return  # outside RSI_MOVECORR the axes do not move
        cmd = [self.aspos[n] + corr[n] for n in range(6)]
        for n in range(6):
            if cmd[n] > self._upper[n] or cmd[n] < self._lower[n]:
                sign = "+" if cmd[n] > self._upper[n] else "-"
                self._trip(
                    f"Software limit switch {sign}{AXES[n]}",
                    f"command {AXES[n]} = {cmd[n]:.4f} outside {self._lower[n]:g} .. {self._upper[n]:g}",
                )
                return
        for n in range(6):
            step = abs(cmd[n] - self.cmd[n])
            if step > self.vel_limit[n]:
                self._trip(
                    f"Command velocity {AXES[n]}",
                    f"step {step:.4f} deg in one {self.cycle_ms} ms cycle, "
                    f"limit {self.vel_limit[n]:.4f} ({self.machine.rated[n]:g} deg/s)",
                )
                return
        self.corr = corr
        self.cmd = cmd
        if stop:  # the Stop object, Mode ExitMoveCorr
            self.in_movecorr = False
            self.movecorr_done = True
            self._log(f"run {self.runs}: Stop from the PC: RSI_MOVECORR returns")

    def _pose(self, which: str, q: Sequence[float]) -> Pose:
        key = tuple(q)
        cached_q, cached_pose = self._fk_cache[which]
        if cached_q != key or cached_pose is None:  # a robot standing still costs no FK
            cached_pose = self._kin.pose(key)
            self._fk_cache[which] = (key, cached_pose)
        return cached_pose


def _fmt(q: Iterable[float]) -> str:
    return " ".join(f"{v:.4f}" for v in q)
