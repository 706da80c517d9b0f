"""Test helper: the simulated KUKA KR C4 with RSI (kuka-rsi-sim) as a subprocess.

    with RsiController(rob6=("127.0.0.1", port), robot="kr16rt") as kuka:
        kuka.status()["aipos"]                 # see controllers/kuka_rsi/README.md
        kuka.fault(lose_s=0.3); kuka.clear()
        kuka.restart(start=[0, -90, 90, 0, 45, 0]); kuka.vanish(2.0)
        kuka.wait_for(lambda st: st["state"] == "running")

From any test module: ``from tests.controllers.rsi_controller import RsiController``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any

from tests.controllers.sim_process import SimProcess, Status


class RsiControllerError(RuntimeError):
    pass


class RsiController(SimProcess):
    """Starts ``python -m kuka_rsi_sim`` sending to ``rob6``; more CLI flags via ``args``
    (e.g. ``"--timeout", "20"``, ``"--cycle-ms", "12"``)."""

    module = "kuka_rsi_sim"
    label = "kuka-rsi-sim"
    ready_line = re.compile(r"kuka-rsi-sim ready: control ([\d.]+):(\d+), sending to (\S+):(\d+) every (\d+) ms$")
    quit_request = {"cmd": "quit"}
    failure = closed_failure = wait_failure = RsiControllerError
    wait_timeout = 10.0

    def __init__(self, *args: str, rob6: tuple[str, int], robot: str = "kr16rt", start_timeout: float = 20.0) -> None:
        super().__init__(["--robot", robot, "--rob6", f"{rob6[0]}:{rob6[1]}", "--control", "127.0.0.1:0", *args],
                         start_timeout)
        self.cycle_ms: int | None = None

    def _ready(self, groups: tuple[str, ...]) -> tuple[str, int]:
        self.cycle_ms = int(groups[4])
        return groups[0], int(groups[1])

    def fault(self, **kw: Any) -> Status:
        """lose_s=, drop_every=, delay_ms= (for_s=), duplicate_every=, reorder_every="""
        return self._ok({"cmd": "fault", **kw})

    def clear(self) -> Status:
        return self._ok({"cmd": "clear"})

    def restart(self, start: Iterable[float] | None = None) -> Status:
        req: Status = {"cmd": "restart"}
        if start is not None:
            req["start"] = list(start)
        return self._ok(req)

    def vanish(self, for_s: float | None = None) -> Status:
        return self._ok({"cmd": "vanish", "for_s": for_s})
