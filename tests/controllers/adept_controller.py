"""Test helper: the simulated Adept controller (adept-sm-sim) as a subprocess.

    with AdeptController() as ctl:
        ctl.motion, ctl.state, ctl.io  # (host, port) of the simple_message ports and the I/O port
        ctl.status()["position_rob6_deg"]
        ctl.estop(); ctl.release(); ctl.drives(True)
"""

from __future__ import annotations

import re

from tests.controllers.sim_process import PointsControllerProcess


class AdeptController(PointsControllerProcess):
    """Starts ``python -m adept_sm_sim`` on free ports; extra CLI flags via ``args``."""

    module = "adept_sm_sim"
    label = "adept-sm-sim"
    ready_line = re.compile(
        r"adept-sm-sim ready: motion ([\d.]+):(\d+), state ([\d.]+):(\d+), "
        r"control ([\d.]+):(\d+)(?:, io ([\d.]+):(\d+))?$"
    )

    def __init__(self, *args: str, byte_order: str = "big", start_timeout: float = 20.0) -> None:
        super().__init__(["--motion-port", "0", "--state-port", "0", "--io-port", "0", "--control", "127.0.0.1:0",
                          "--byte-order", byte_order, *args], start_timeout)
        # (host, port) of the simple_message ports: set by start()
        self.motion: tuple[str, int]
        self.state: tuple[str, int]
        self.io: tuple[str, int] | None = None

    def _ready(self, groups: tuple[str, ...]) -> tuple[str, int]:
        g = groups
        self.motion, self.state = (g[0], int(g[1])), (g[2], int(g[3]))
        self.io = (g[6], int(g[7])) if g[6] else None
        return g[4], int(g[5])

    def drives(self, on: bool) -> None:
        self._ok({"cmd": "drives", "on": on})

    def drop_connection(self, port: str) -> bool:
        dropped: bool = self._ok({"cmd": "drop_connection", "port": port})["dropped"]
        return dropped

    def monitor_speed(self, percent: float) -> None:
        """The pendant's monitor speed changes now (V+: at once, also mid-motion)."""
        self._ok({"cmd": "monitor_speed", "percent": percent})
