"""Test helper: the simulated Kawasaki controller (kawasaki-as-sim) as a subprocess.

    with KawasakiController() as ctl:
        ctl.port  # (host, port) of the AS PC program
        ctl.status()["position_rob6_deg"]
        ctl.estop(); ctl.release(); ctl.motor(True); ctl.teach(True)
"""

from __future__ import annotations

import re

from tests.controllers.sim_process import PointsControllerProcess


class KawasakiController(PointsControllerProcess):
    """Starts ``python -m kawasaki_as_sim`` (on a free port unless ``args`` give one)."""

    module = "kawasaki_as_sim"
    label = "kawasaki-as-sim"
    ready_line = re.compile(r"kawasaki-as-sim ready: port ([\d.]+):(\d+), control ([\d.]+):(\d+)$")

    def __init__(self, *args: str, start_timeout: float = 20.0) -> None:
        super().__init__(["--port", "0", "--control", "127.0.0.1:0", *args], start_timeout)
        self.port: tuple[str, int]  # (host, port) of the AS program's server: set by start()

    def _ready(self, groups: tuple[str, ...]) -> tuple[str, int]:
        g = groups
        self.port = (g[0], int(g[1]))
        return g[2], int(g[3])

    def motor(self, on: bool) -> None:
        self._ok({"cmd": "motor", "on": on})

    def teach(self, on: bool) -> None:
        self._ok({"cmd": "teach", "on": on})

    def drop_connection(self) -> bool:
        dropped: bool = self._ok({"cmd": "drop_connection"})["dropped"]
        return dropped
