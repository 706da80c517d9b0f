"""The RSI part of the KR C4, one IPO cycle at a time, without any I/O.

The loaded context decides the signal flow (RSI_ON(#ABSOLUTE)): ETHERNET (answers read with
the configuration's RECEIVE elements, HOLDON on a late answer, Timeout) -> STOP
(ExitMoveCorr: RSI_MOVECORR returns on its input's rising edge) and -> AXISCORR (the overall
correction: each cycle's value itself with #ABSOLUTE, the sum of all with #RELATIVE, clamped
to LowerLim..UpperLim) with the overall correction monitor (AXISCORRMON's Max, else 6 deg:
beyond it RSI stops); on RSI 3.x with #IPO no correction moves the axes; then the motion
system: the command ASPos + correction must stay inside the software limit switches and
must not step faster than an axis can move; the axes follow the command at most at rated
speed. ASPos is the programmed position RSI_ON found (the last motion's target), never a
corrected one. Corrections move the axes only while RSI_MOVECORR runs.
"""

from __future__ import annotations

import math
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
TIMEOUT_ERROR = {"3": "RSIBad", "4.0": "RSITimeout", "4.1": "RSITimeout", "5.0": "RSITimeout"}
#: T1: the flange's Cartesian velocity is monitored at 250 mm/s (the ri README, Testing)
T1_VELOCITY_MM_S = 250.0


class Rsi:
    def __init__(self, machine: Machine, generation: str, start_pose: Sequence[float],
                 log: Callable[[str], None], t1: bool = False) -> None:
        self.machine = machine
        self.generation = generation
        self.t1 = t1  # operating mode T1: the flange's velocity is monitored
        self.relative = False  # RSI_ON(#RELATIVE): each cycle's correction adds to the overall one
        self.corrects = True  # False: RSI_ON's sensor mode applies no correction in RSI_MOVECORR
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
        self.corr = [0.0] * 6  # AXISCORR's output: the overall correction applied
        self._stop_input = 0.0  # the Stop object's input last cycle (it acts on a rising edge)
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

    def set_flow(self, flow: SignalFlow, cycle_ms: int, mode: str = "#ABSOLUTE", ipo_mode: str = "#IPO_FAST") -> None:
        """The context, cycle and modes of the next run (RSI_ON(mode, ipo_mode))."""
        assert not self.running
        self.flow = flow
        self.cycle_ms = cycle_ms
        self.relative = mode == "#RELATIVE"
        # RSI 3.x: in #IPO mode corrections act on LIN/CIRC path motions only, so none in
        # RSI_MOVECORR (rsi-pi RSIPI_Minimal.src, quoting the RSI 3.3 manual 4.1 and 7.1.4)
        self.corrects = not (self.generation == "3" and ipo_mode == "#IPO")
        if not self.corrects:
            self._log("RSI 3.x, RSI_ON(#IPO): corrections act on LIN/CIRC path motions only; "
                      "RSI_MOVECORR applies none")
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
        self._stop_input = 0.0
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
        stop_input = self.outputs.get(flow.stop_output, 0.0) if flow.stop_output is not None else 0.0
        stop = stop_input not in (0.0, "") and self._stop_input in (0.0, "")  # a rising edge
        self._stop_input = 0.0 if stop_input == "" else float(stop_input)
        if not self.in_movecorr or not self.corrects:
            if stop and self.in_movecorr:
                self._movecorr_returns()
            return  # outside RSI_MOVECORR (or in a mode without corrections) the axes do not move
        corr = [0.0] * 6
        for n, indx in enumerate(flow.corr_outputs):  # AXISCORR clamps each axis to its window
            raw = self.outputs.get(indx, 0.0) if indx is not None else 0.0
            assert isinstance(raw, float)
            step = raw if self.relative else raw - self.corr[n]
            self.max_ak_step[n] = max(self.max_ak_step[n], abs(step))
            overall = self.corr[n] + raw if self.relative else raw
            corr[n] = min(max(overall, flow.lower[n]), flow.upper[n])
        for n in range(6):  # the overall correction monitor (AXISCORRMON, or RSI's default)
            if abs(corr[n]) > flow.monitor[n]:
                self._trip("KSS29000 AXISCORR Permissible overall correction exceeded: RSI is stopped",
                           f"overall correction {AXES[n]} = {corr[n]:.4f}, limit {flow.monitor[n]:g} "
                           f"({flow.monitor_object or 'no AXISCORRMON: the default'})")
                return
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
        if self.t1:
            before, after = self._pose("rsol", self.cmd), self._kin.pose(tuple(cmd))
            speed = math.dist(before[:3], after[:3]) / (self.cycle_ms / 1000.0)
            if speed > T1_VELOCITY_MM_S * (1.0 + VEL_TOLERANCE):
                self._trip("T1: Cartesian velocity 250 mm/s exceeded",
                           f"flange {speed:.1f} mm/s in one {self.cycle_ms} ms cycle")
                return
        self.corr = corr
        self.cmd = cmd
        if stop:
            self._movecorr_returns()

    def _movecorr_returns(self) -> None:
        """The Stop object (Mode ExitMoveCorr) fired: RSI_MOVECORR returns."""
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
