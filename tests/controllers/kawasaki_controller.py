"""Test helper: the simulated Kawasaki controller (kawasaki-as-sim, executing rob6.as) as a subprocess.

    with KawasakiController() as ctl:
        ctl.port  # (host, port) of the AS PC program
        ctl.status()["position_rob6_deg"]; ctl.type("kdone")
        ctl.estop(); ctl.release(); ctl.motor(True); ctl.execute(); ctl.teach(True)

``ROB6_KAS_AS_PROGRAM`` (a file) and ``ROB6_KAS_AS_START`` (operator commands separated by
``;``) make every test run another AS program, e.g. an older rob6.as.
"""

from __future__ import annotations

import os
import re
from typing import Any

from tests.controllers.sim_process import PointsControllerProcess


def _program_args() -> list[str]:
    args: list[str] = []
    if program := os.environ.get("ROB6_KAS_AS_PROGRAM"):
        args += ["--program", program]
    for command in filter(None, (c.strip() for c in os.environ.get("ROB6_KAS_AS_START", "").split(";"))):
        args += ["--start", command]
    return args


class KawasakiController(PointsControllerProcess):
    """Starts ``python -m kawasaki_as_sim`` (on a free port unless ``args`` give one)."""

    module = "kawasaki_as_sim"
    label = "kawasaki-as-sim"
    ready_line = re.compile(r"kawasaki-as-sim ready: port ([\d.]+):(\d+), state port (\d+), control ([\d.]+):(\d+)$")

    def __init__(self, *args: str, start_timeout: float = 20.0) -> None:
        super().__init__(["--port", "0", "--state-port", "0", "--control", "127.0.0.1:0", *_program_args(), *args],
                         start_timeout)
        self.port: tuple[str, int]  # (host, port) of the AS program's server: set by start()
        self.state_port: tuple[str, int]  # (host, port) of its state program

    def _ready(self, groups: tuple[str, ...]) -> tuple[str, int]:
        g = groups
        self.port = (g[0], int(g[1]))
        self.state_port = (g[0], int(g[2]))
        return g[3], int(g[4])

    def motor(self, on: bool) -> None:
        self._ok({"cmd": "motor", "on": on})

    def teach(self, on: bool) -> None:
        self._ok({"cmd": "teach", "on": on})

    def execute(self, program: str | None = None) -> None:
        """The operator's ``EXECUTE`` (after a stop the robot program is started anew; ``program``
        when none was executed before)."""
        self._ok({"cmd": "execute"} | ({"program": program} if program else {}))

    def hold(self, on: bool) -> None:
        """The pendant's HOLD (True) or RUN (False)."""
        self._ok({"cmd": "hold" if on else "run"})

    def monitor_speed(self, percent: float) -> None:
        self._ok({"cmd": "monitor_speed", "percent": percent})

    def type(self, expr: str) -> Any:
        """``TYPE expr`` at the controller's terminal: the value of the program's variables."""
        return self._ok({"cmd": "type", "expr": expr})["value"]

    def queued(self) -> int:
        return int(self.type("kin - MAXVAL(kout, kflush)"))

    def drop_connection(self) -> bool:
        dropped: bool = self._ok({"cmd": "drop_connection"})["dropped"]
        return dropped
