"""The RSI part of the KR C4, one IPO cycle at a time, without any I/O.

Signal flow as configured in deploy/kuka (RSI_ON(#ABSOLUTE)): ETHERNET (late packets,
Timeout, HOLDON) -> AXISCORR (absolute axis correction from the start pose, clamped to its
window) with AXISCORRMON watching the requested correction, then the motion system: the
command ASPos + AK must stay inside the software limit switches and must not step faster
than an axis can move; the axes follow the command at most at rated speed.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

from .kinematics import Kinematics, Pose
from .machine import Machine
from .wire import AXES, RobWriter, Sen

# The command-velocity monitor allows 2 % over the rated speed, plus 0.0002 deg for the
# 4-decimal rounding of two successive AK values (the PC may send with any precision).
VEL_TOLERANCE = 0.02
VEL_ABS_TOLERANCE = 2e-4

MAX_TRIPS_KEPT = 100


class Rsi:
    def __init__(
        self,
        machine: Machine,
        cycle_ms: int,
        *,
        sentype: str,
        timeout: int,
        timeout_counts: str,
        corr_window: tuple[float, ...],
        start_pose: tuple[float, ...],
        writer: RobWriter,
        log: Callable[[str], None],
    ) -> None:
        self.machine = machine
        self.cycle_ms = cycle_ms
        self.sentype = sentype
        self.timeout = timeout
        self.count_consecutive = timeout_counts == "consecutive"
        self.window = tuple(corr_window)
        self._kin = Kinematics(machine)
        self._writer = writer
        self._log = log
        dt = cycle_ms / 1000.0
        self._servo_step = tuple(r * dt for r in machine.rated)
        self.vel_limit = tuple(r * dt * (1.0 + VEL_TOLERANCE) + VEL_ABS_TOLERANCE for r in machine.rated)
        self._lower, self._upper = machine.lower, machine.upper

        self.running = False
        self.runs = 0
        self.stop_reason = ""
        self.stop_kind: str | None = None  # "pc", "fault", "operator", "off"
        self.trips: list[str] = []
        self.aipos = list(start_pose)
        self.aspos = list(start_pose)
        self.ak = [0.0] * 6
        self.cmd = list(start_pose)
        self.cycle = 0  # packets of this run
        self.delay = 0  # late packets of this run (the Delay element)
        self.late_consecutive = 0
        self.late_total = 0
        self.replies_ok = 0
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
        """A PTP between runs (RSI off): the robot is simply there afterwards."""
        assert not self.running
        self.aipos = [float(v) for v in pose]
        self.cmd = list(self.aipos)

    def start_run(self) -> None:
        """RSI_ON + RSI_MOVECORR: the start pose is where the robot stands now."""
        self.runs += 1
        self.running = True
        self.stop_reason = ""
        self.stop_kind = None
        self.aspos = list(self.aipos)
        self.cmd = list(self.aipos)
        self.ak = [0.0] * 6
        self.cycle = 0
        self.delay = 0
        self.late_consecutive = 0
        self.max_ak_step = [0.0] * 6
        self._log(f"run {self.runs} started at {_fmt(self.aspos)}")

    def end_run(self, reason: str, kind: str) -> None:
        if not self.running:
            return
        self.running = False
        self.stop_reason = reason
        self.stop_kind = kind
        if kind == "pc":
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
        move the axes, and return this cycle's packet; None when the run ended."""
        if not self.running:
            return None
        if self.cycle > 0:
            # servo: the axes follow the command of the previous cycle
            for n in range(6):
                d = self.cmd[n] - self.aipos[n]
                s = self._servo_step[n]
                self.aipos[n] += s if d > s else -s if d < -s else d
            if answer is None:
                self._late()
            else:
                self._apply(answer)
            if not self.running:
                return None
        self.cycle += 1
        self.ipoc = ipoc
        return self._writer.packet(
            self._pose("rist", self.aipos), self._pose("rsol", self.cmd), self.aipos, self.aspos, self.delay, ipoc
        )

    def _late(self) -> None:
        """No valid answer in time: count it, hold the previous correction (HOLDON)."""
        self.delay += 1
        self.late_total += 1
        self.late_consecutive += 1
        count = self.late_consecutive if self.count_consecutive else self.delay
        if count >= self.timeout:
            kind = "consecutive " if self.count_consecutive else ""
            self._trip(
                f"RSI timeout: {count} {kind}late packets (Timeout {self.timeout})",
                f"no answer with the right IPOC for {count} {kind}cycles",
            )

    def _apply(self, sen: Sen) -> None:
        if sen.type != self.sentype:
            self._trip(
                f"Sen Type {sen.type!r} does not match SENTYPE {self.sentype!r}",
                "the PC answers with another Sen Type than the Ethernet configuration's SENTYPE",
            )
            return
        ak = [self.ak[n] if v is None else v for n, v in enumerate(sen.ak)]  # HOLDON per element
        for n in range(6):
            step = abs(ak[n] - self.ak[n])
            self.max_ak_step[n] = max(self.max_ak_step[n], step)
        cmd = [0.0] * 6
        for n in range(6):  # AXISCORR clamps to its window, AXISCORRMON stops beyond it
            w = self.window[n]
            if not -w <= ak[n] <= w:
                self._trip(f"Correction limit {AXES[n]}", f"AK {AXES[n]} = {ak[n]:.4f} outside +-{w:g}")
                return
            cmd[n] = self.aspos[n] + ak[n]
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
        self.ak = ak
        self.cmd = cmd
        self.replies_ok += 1
        self.late_consecutive = 0
        if sen.stop:
            self.end_run("Stop from the PC", "pc")

    def _pose(self, which: str, q: Sequence[float]) -> Pose:
        key = tuple(q)
        cached_q, cached_pose = self._fk_cache[which]
        if cached_q != key or cached_pose is None:  # a robot standing still costs no FK
            cached_pose = self._kin.pose(key)
            self._fk_cache[which] = (key, cached_pose)
        return cached_pose


def _fmt(q: Iterable[float]) -> str:
    return " ".join(f"{v:.4f}" for v in q)
