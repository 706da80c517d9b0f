"""The simulation link (the default): the driver's own real-time clock, perfect tracking.

Every ``robot.cycle_s`` the cycle runner steps the motion core and the setpoint is
where the robot is; nothing can be lost, so the link is always connected. The simulated
Adept's digital outputs switch at once (``signal``).
"""

from __future__ import annotations

from rob6.messages import LinkStatus

from ..loop import CycleRunner
from ..motion import CoreState, MotionCore
from . import Link, Outputs, Publish


class SimLink(Link):
    kind = "sim"

    def __init__(self, core: MotionCore, publish: Publish) -> None:
        self.core = core
        self._publish = publish
        self.runner = CycleRunner(core.step, core.dt, self._cycle_done, name="driver-cycle")
        self._outputs = Outputs()

    def _cycle_done(self, state: CoreState) -> None:
        self.missed = self.runner.stats.missed  # cycles the runner skipped (the machine was too busy)
        self._publish(state)

    def signal(self, signals: list[int]) -> str:
        for signal in signals:
            self._outputs.switched(signal)
        return ""

    def outputs(self) -> list[int]:
        return self._outputs.as_list()

    def start(self) -> None:
        self.runner.start()

    def stop(self) -> None:
        self.runner.stop()

    def status(self, reset: bool = False) -> LinkStatus:
        return LinkStatus(link="sim", state="connected", packets=self.runner.stats.cycles,
                          missed=self.runner.stats.missed)
