"""Test helper: the stand-in KUKA KR C4 (kuka-rsi-sim) as a subprocess, running the shipped files.

    with RsiController(rob6=("127.0.0.1", port), robot="kr16rt", kss="8.6") as kuka:
        kuka.status()["aipos"]                 # see controllers/kuka_rsi/README.md
        kuka.fault(lose_s=0.3); kuka.clear()
        kuka.restart(start=[0, -90, 90, 0, 45, 0]); kuka.vanish(2.0)
        kuka.wait_for(lambda st: st["state"] == "running")

Each controller gets the files of deploy/kuka installed as deploy/kuka/README.md tells a
lab (``install``): the program and its settings, the Ethernet configuration and the
context of the controller's RSI generation. ``ROB6_KUKA_DEPLOY`` names another folder to
install from (e.g. the files of another commit, to see which tests they fail).
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from tests.controllers.sim_process import SimProcess, Status

DEPLOY = Path(os.environ.get("ROB6_KUKA_DEPLOY", Path(__file__).resolve().parents[2] / "deploy" / "kuka"))
#: the KSS releases running RSI 3.x
RSI3_KSS = ("8.3", "8.4")
#: the KSS release running RSI 4.0 (its own .rsix format: deploy/kuka/rsi40)
RSI40_KSS = "8.5"
#: RSI's Timeout (``--timeout``) for tests of the whole system: a CI machine is no real-time
#: PC, and the late packets it makes would add up to the shipped Timeout (100 a run) over a
#: long session. The Timeout rule is tested in test_kuka_rsi_sim, the shipped value read there.
SYSTEM_TIMEOUT = 1_000_000


class RsiControllerError(RuntimeError):
    pass


def edit(path: Path, pattern: str, replacement: str) -> None:
    """Replace the one match of ``pattern`` in ``path`` (an installation step: it must be there)."""
    text = path.read_bytes().decode("ascii")
    new, count = re.subn(pattern, replacement, text)
    assert count >= 1, f"{path.name}: {pattern!r} not found"
    path.write_bytes(new.encode("ascii"))


def install(dest: Path, kss: str = "8.6", robot: str = "kr16rt", deploy: Path = DEPLOY) -> tuple[Path, Path]:
    """Install deploy/kuka on a controller as its README says; (program .src, SensorInterface).

    KRC:\\R1\\Program gets rob6_rsi.src/.dat (rob6IpoFast FALSE for kr3/kr16); SensorInterface
    the Ethernet configuration and the context: rob6_rsi.rsix (RSI 4.1, 5.x), rsi40/rob6_rsi.rsix
    (RSI 4.0), or on RSI 3.x the three files of rsi3/ with rob6Context[]="rob6_rsi.rsi"."""
    program, sensor = dest / "Program", dest / "SensorInterface"
    program.mkdir(parents=True)
    sensor.mkdir(parents=True)
    for name in ("rob6_rsi.src", "rob6_rsi.dat"):
        shutil.copy(deploy / name, program / name)
    shutil.copy(deploy / "rob6_rsi_ethernet.xml", sensor)
    dat = program / "rob6_rsi.dat"
    if not robot.endswith("rt"):
        edit(dat, r"rob6IpoFast=TRUE", "rob6IpoFast=FALSE")
    if kss in RSI3_KSS:
        for path in sorted((deploy / "rsi3").iterdir()):
            shutil.copy(path, sensor)
        edit(dat, r'rob6Context\[\]="rob6_rsi"', 'rob6Context[]="rob6_rsi.rsi"')
    elif kss == RSI40_KSS:
        shutil.copy(deploy / "rsi40" / "rob6_rsi.rsix", sensor)
    else:
        shutil.copy(deploy / "rob6_rsi.rsix", sensor)
    return program / "rob6_rsi.src", sensor


class RsiController(SimProcess):
    """Starts ``python -m kuka_rsi_sim`` on freshly installed files, sending to ``rob6``; more
    CLI flags via ``args`` (e.g. ``"--cycle-ms", "40"``). ``files``: an installation to use
    instead (``install``'s result, e.g. after a test changed a file). ``timeout`` replaces
    the context's Timeout (``--timeout``)."""

    module = "kuka_rsi_sim"
    label = "kuka-rsi-sim"
    ready_line = re.compile(r"kuka-rsi-sim ready: control ([\d.]+):(\d+), KSS (\S+) \((.+)\), program (\S+)$")
    quit_request = {"cmd": "quit"}
    failure = closed_failure = wait_failure = RsiControllerError
    wait_timeout = 10.0

    def __init__(self, *args: str, rob6: tuple[str, int] | None, robot: str = "kr16rt", kss: str = "8.6",
                 timeout: int | None = None, files: tuple[Path, Path] | None = None,
                 start_timeout: float = 20.0) -> None:
        self._dir: tempfile.TemporaryDirectory[str] | None = None
        if files is None:
            self._dir = tempfile.TemporaryDirectory(prefix="kr-c4-")
            files = install(Path(self._dir.name), kss, robot)
        self.files = files
        target = [] if rob6 is None else ["--rob6", f"{rob6[0]}:{rob6[1]}"]
        limit = [] if timeout is None else ["--timeout", str(timeout)]
        super().__init__(["--program", str(files[0]), "--sensor-interface", str(files[1]), "--kss", kss,
                          "--robot", robot, *target, *limit, "--control", "127.0.0.1:0", *args], start_timeout)
        cycle = [int(args[i + 1]) for i, a in enumerate(args[:-1]) if a == "--cycle-ms"]
        self.cycle_ms = cycle[0] if cycle else 4 if robot.endswith("rt") else 12

    def _ready(self, groups: tuple[str, ...]) -> tuple[str, int]:
        return groups[0], int(groups[1])

    def stop(self, timeout: float = 10.0) -> int | None:
        code = super().stop(timeout)
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None
        return code

    def fault(self, **kw: Any) -> Status:
        """lose_s=, drop_every=, delay_ms= (for_s=), duplicate_every=, reorder_every="""
        return self._ok({"cmd": "fault", **kw})

    def clear(self) -> Status:
        return self._ok({"cmd": "clear"})

    def restart(self, start: Iterable[float] | None = None, line: int | None = None) -> Status:
        """The operator: stop, jog to ``start``, reset and start the program (at ``line``)."""
        req: Status = {"cmd": "restart"}
        if start is not None:
            req["start"] = list(start)
        if line is not None:
            req["line"] = line
        return self._ok(req)

    def confirm(self) -> Status:
        return self._ok({"cmd": "confirm"})

    def vanish(self, for_s: float | None = None) -> Status:
        return self._ok({"cmd": "vanish", "for_s": for_s})
