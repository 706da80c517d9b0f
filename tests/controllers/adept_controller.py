"""Test helper: the simulated Adept controller (adept-sm-sim) as a subprocess.

    with AdeptController() as ctl:
        ctl.motion, ctl.state, ctl.io  # (host, port) of the simple_message ports and the I/O port
        ctl.status()["position_rob6_deg"]
        ctl.estop(); ctl.release(); ctl.drives(True)
"""

from __future__ import annotations

import io
import json
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

#: a request to or reply of the control channel (JSON object)
Json = dict[str, Any]

READY = re.compile(
    r"adept-sm-sim ready: motion ([\d.]+):(\d+), state ([\d.]+):(\d+), "
    r"control ([\d.]+):(\d+)(?:, io ([\d.]+):(\d+))?$"
)


class AdeptController:
    """Starts ``python -m adept_sm_sim`` on free ports; extra CLI flags via ``args``."""

    def __init__(self, *args: str, byte_order: str = "big", start_timeout: float = 20.0) -> None:
        self.args = ["--motion-port", "0", "--state-port", "0", "--io-port", "0", "--control", "127.0.0.1:0",
                     "--byte-order", byte_order, *args]
        self.start_timeout = start_timeout
        self.proc: subprocess.Popen[str] | None = None
        # (host, port) of the simple_message ports and the control channel: set by start()
        self.motion: tuple[str, int]
        self.state: tuple[str, int]
        self.control: tuple[str, int]
        self.io: tuple[str, int] | None = None
        self.stderr_lines: list[str] = []
        self._ctl: socket.socket | None = None
        self._stderr_thread: threading.Thread | None = None
        self._ctl_file: io.BufferedRWPair | None = None

    # ---- lifecycle -----------------------------------------------------------
    def start(self) -> AdeptController:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "adept_sm_sim", *self.args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        self._stderr_thread = threading.Thread(target=self._drain_stderr, daemon=True)
        self._stderr_thread.start()
        line = self._read_ready()
        m = READY.match(line)
        if not m:
            self.stop()
            raise RuntimeError(f"adept-sm-sim printed {line!r} instead of its ready line; "
                               f"stderr: {self.stderr_lines}")
        g = m.groups()
        self.motion, self.state = (g[0], int(g[1])), (g[2], int(g[3]))
        self.control = (g[4], int(g[5]))
        self.io = (g[6], int(g[7])) if g[6] else None
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
            raise RuntimeError(f"adept-sm-sim did not get ready within {self.start_timeout} s; "
                               f"stderr: {self.stderr_lines}")
        if not box[0]:
            code = proc.wait(10)
            stderr_thread.join(5)
            raise RuntimeError(f"adept-sm-sim exited with code {code} before its ready line; "
                               f"stderr: {self.stderr_lines}")
        return box[0].rstrip("\n")

    def _drain_stderr(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None, "not started"
        for line in self.proc.stderr:
            self.stderr_lines.append(line.rstrip("\n"))

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGTERM, then the exit code (SIGKILL if it does not exit in time)."""
        if self._ctl is not None:
            self._ctl.close()
            self._ctl = None
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        assert self._stderr_thread is not None  # started right after proc
        self._stderr_thread.join(5)
        return self.proc.returncode

    def __enter__(self) -> AdeptController:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---- control channel ---------------------------------------------------------
    def request(self, req: Json | str) -> Json:
        """One request (a dict, or a raw line to test bad input) and its reply."""
        line = req if isinstance(req, str) else json.dumps(req)
        assert self._ctl_file is not None, "not started"
        self._ctl_file.write(line.encode() + b"\n")
        self._ctl_file.flush()
        reply = self._ctl_file.readline()
        if not reply:
            raise ConnectionError(f"control channel closed; stderr: {self.stderr_lines}")
        answer: Json = json.loads(reply)
        return answer

    def _ok(self, req: Json) -> Json:
        reply = self.request(req)
        if not reply.get("ok"):
            raise RuntimeError(f"{req} refused: {reply.get('error')}")
        return reply

    def status(self) -> Json:
        return self._ok({"cmd": "status"})

    def estop(self) -> None:
        self._ok({"cmd": "estop"})

    def release(self) -> None:
        self._ok({"cmd": "estop_release"})

    def drives(self, on: bool) -> None:
        self._ok({"cmd": "drives", "on": on})

    def error(self, code: int) -> None:
        self._ok({"cmd": "error", "code": code})

    def clear_error(self) -> None:
        self._ok({"cmd": "clear_error"})

    def drop_connection(self, port: str) -> bool:
        dropped: bool = self._ok({"cmd": "drop_connection", "port": port})["dropped"]
        return dropped

    def slow_ack(self, ms: float) -> None:
        self._ok({"cmd": "slow_ack", "ms": ms})

    def wait_for(self, predicate: Callable[[Json], object], timeout: float = 15.0, what: str = "condition") -> Json:
        """Poll status() until predicate(status) holds; the last status."""
        deadline = time.monotonic() + timeout
        while True:
            st = self.status()
            if predicate(st):
                return st
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out waiting for {what}; last status {st}")
            time.sleep(0.02)
