"""Test helper: the simulated KUKA KR C4 with RSI (kuka-rsi-sim) as a subprocess.

    with RsiController(rob6=("127.0.0.1", port), robot="kr16rt") as kuka:
        kuka.status()["aipos"]                 # see controllers/kuka_rsi/README.md
        kuka.fault(lose_s=0.3); kuka.clear()
        kuka.restart(start=[0, -90, 90, 0, 45, 0]); kuka.vanish(2.0)
        kuka.wait_for(lambda st: st["state"] == "running")

From any test module: ``from tests.controllers.rsi_controller import RsiController``.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

#: a request to or reply of the control channel (JSON object)
Json = dict[str, Any]

READY = re.compile(r"kuka-rsi-sim ready: control ([\d.]+):(\d+), sending to (\S+):(\d+) every (\d+) ms$")


class RsiControllerError(RuntimeError):
    pass


class RsiController:
    """Starts ``python -m kuka_rsi_sim`` sending to ``rob6``; more CLI flags via ``args``
    (e.g. ``"--timeout", "20"``, ``"--cycle-ms", "12"``)."""

    def __init__(self, *args: str, rob6: tuple[str, int], robot: str = "kr16rt", start_timeout: float = 20.0) -> None:
        self.args = ["--robot", robot, "--rob6", f"{rob6[0]}:{rob6[1]}", "--control", "127.0.0.1:0", *args]
        self.start_timeout = start_timeout
        self.proc: subprocess.Popen[str] | None = None
        self.control: tuple[str, int] | None = None
        self.cycle_ms: int | None = None
        self.stderr_lines: list[str] = []
        self._ctl: socket.socket | None = None
        self._ctl_file: io.BufferedRWPair | None = None
        self._stderr_thread: threading.Thread | None = None

    # ---- lifecycle -----------------------------------------------------------
    def start(self) -> RsiController:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "kuka_rsi_sim", *self.args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        # stderr is read all the time: a full pipe would block the simulator's loop
        self._stderr_thread = threading.Thread(target=self._drain_stderr, daemon=True)
        self._stderr_thread.start()
        line = self._read_ready()
        m = READY.match(line)
        if not m:
            self.stop()
            raise RsiControllerError(f"kuka-rsi-sim printed {line!r} instead of its ready line; "
                                     f"stderr: {self.stderr_lines}")
        self.control = (m.group(1), int(m.group(2)))
        self.cycle_ms = int(m.group(5))
        self._ctl = socket.create_connection(self.control, timeout=10)
        self._ctl_file = self._ctl.makefile("rwb")
        return self

    def _read_ready(self) -> str:
        proc, stderr_thread = self.proc, self._stderr_thread
        assert proc is not None and proc.stdout is not None and stderr_thread is not None, "not started"
        stdout = proc.stdout
        box: list[str] = []
        t = threading.Thread(target=lambda: box.append(stdout.readline()), daemon=True)
        t.start()
        t.join(self.start_timeout)
        if not box:
            self.stop()
            raise RsiControllerError(f"kuka-rsi-sim did not get ready within {self.start_timeout} s; "
                                     f"stderr: {self.stderr_lines}")
        if not box[0]:
            code = proc.wait(10)
            stderr_thread.join(5)
            raise RsiControllerError(f"kuka-rsi-sim exited with code {code} before its ready line; "
                                     f"stderr: {self.stderr_lines}")
        return box[0].rstrip("\n")

    def _drain_stderr(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None, "not started"
        for line in self.proc.stderr:
            self.stderr_lines.append(line.rstrip("\n"))

    def stop(self, timeout: float = 10.0) -> int | None:
        """Ask it to quit; SIGTERM, then SIGKILL if it does not. Returns the exit code."""
        if self.proc is None:
            return None
        if self.proc.poll() is None and self._ctl_file is not None:
            with contextlib.suppress(OSError, RsiControllerError, ValueError):
                self.request({"cmd": "quit"})
        self._close_control()
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.terminate()
            try:
                code = self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                code = self.proc.wait(timeout)
        if self._stderr_thread is not None:
            self._stderr_thread.join(5)
        for f in (self.proc.stdout, self.proc.stderr):
            if f is not None:
                f.close()
        return code

    def _close_control(self) -> None:
        for f in (self._ctl_file, self._ctl):
            if f is not None:
                with contextlib.suppress(OSError):
                    f.close()
        self._ctl_file = self._ctl = None

    def __enter__(self) -> RsiController:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---- control channel -----------------------------------------------------
    def send_line(self, line: bytes) -> Json:
        """One raw request line (no newline inside), its JSON reply."""
        if self._ctl_file is None:
            raise RsiControllerError("not started")
        self._ctl_file.write(line + b"\n")
        self._ctl_file.flush()
        reply = self._ctl_file.readline()
        if not reply:
            raise RsiControllerError(f"control channel closed; stderr: {self.stderr_lines[-20:]}")
        answer: Json = json.loads(reply)
        return answer

    def request(self, req: Json) -> Json:
        return self.send_line(json.dumps(req).encode())

    def _ok(self, req: Json) -> Json:
        reply = self.request(req)
        if not reply.get("ok"):
            raise RsiControllerError(f"{req} refused: {reply.get('error')}")
        return reply

    def status(self) -> Json:
        return self._ok({"cmd": "status"})

    def fault(self, **kw: float) -> Json:
        """lose_s=, drop_every=, delay_ms= (for_s=), duplicate_every=, reorder_every="""
        return self._ok({"cmd": "fault", **kw})

    def clear(self) -> Json:
        return self._ok({"cmd": "clear"})

    def restart(self, start: Sequence[float] | None = None) -> Json:
        req: dict[str, object] = {"cmd": "restart"}
        if start is not None:
            req["start"] = list(start)
        return self._ok(req)

    def vanish(self, for_s: float | None = None) -> Json:
        return self._ok({"cmd": "vanish", "for_s": for_s})

    def wait_for(self, predicate: Callable[[Json], object], timeout: float = 10.0, what: str = "condition") -> Json:
        """Poll the status until predicate(status) is true; the last status."""
        deadline = time.monotonic() + timeout
        while True:
            st = self.status()
            if predicate(st):
                return st
            if time.monotonic() > deadline:
                raise RsiControllerError(f"{what} not reached within {timeout} s; last status {st}; "
                                         f"stderr: {self.stderr_lines[-20:]}")
            time.sleep(0.02)
