"""Test helper: a controller simulator as a subprocess, and its JSON control channel.

A subclass names the module and the ready line; the base starts the process (its stderr
read all the time: a full pipe would block the simulator's loop), waits for the ready
line, connects to the control port it names and sends requests over it."""

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
from collections.abc import Callable
from typing import Any, Self

Status = dict[str, Any]


class SimProcess:
    """``python -m <module> <args>``; ``_ready`` takes the ready line's groups."""

    #: the simulator's module and the name it calls itself
    module = ""
    label = ""
    #: its ready line (the groups go to ``_ready``)
    ready_line: re.Pattern[str] = re.compile("$^")
    #: sent to ask it to quit before SIGTERM (None: SIGTERM at once)
    quit_request: Status | None = None
    #: raised when the simulator fails to start or refuses a request
    failure: type[Exception] = RuntimeError
    #: raised when the control channel closes
    closed_failure: type[Exception] = ConnectionError
    #: raised when ``wait_for`` times out, and its default timeout
    wait_failure: type[Exception] = AssertionError
    wait_timeout = 15.0

    def __init__(self, args: list[str], start_timeout: float = 20.0) -> None:
        self.args = args
        self.start_timeout = start_timeout
        self.proc: subprocess.Popen[str] | None = None
        self.control: tuple[str, int] | None = None
        self.stderr_lines: list[str] = []
        self._ctl: socket.socket | None = None
        self._ctl_file: io.BufferedRWPair | None = None
        self._stderr_thread: threading.Thread | None = None

    def _ready(self, groups: tuple[str, ...]) -> tuple[str, int]:
        """Take in the ready line's groups; the control port's address."""
        raise NotImplementedError

    # ---- lifecycle -----------------------------------------------------------
    def start(self) -> Self:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", self.module, *self.args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        self._stderr_thread = threading.Thread(target=self._drain_stderr, daemon=True)
        self._stderr_thread.start()
        line = self._read_ready()
        m = self.ready_line.match(line)
        if not m:
            self.stop()
            raise self.failure(f"{self.label} printed {line!r} instead of its ready line; "
                               f"stderr: {self.stderr_lines}")
        self.control = self._ready(m.groups())
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
            raise self.failure(f"{self.label} did not get ready within {self.start_timeout} s; "
                               f"stderr: {self.stderr_lines}")
        if not box[0]:
            code = proc.wait(10)
            stderr_thread.join(5)
            raise self.failure(f"{self.label} exited with code {code} before its ready line; "
                               f"stderr: {self.stderr_lines}")
        return box[0].rstrip("\n")

    def _drain_stderr(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None, "not started"
        for line in self.proc.stderr:
            self.stderr_lines.append(line.rstrip("\n"))

    def stop(self, timeout: float = 10.0) -> int | None:
        """Ask it to quit (``quit_request``) or SIGTERM, then SIGKILL if it does not exit
        in time; the exit code."""
        proc = self.proc
        if proc is None:
            self._close_control()
            return None
        asked = False
        if self.quit_request is not None and proc.poll() is None and self._ctl_file is not None:
            asked = True
            with contextlib.suppress(OSError, ValueError, self.failure, self.closed_failure):
                self.request(self.quit_request)
        self._close_control()
        code = _wait(proc, timeout) if asked else None
        if code is None:
            if proc.poll() is None:
                proc.terminate()
            code = _wait(proc, timeout)
        if code is None:
            proc.kill()
            code = proc.wait(timeout)
        if self._stderr_thread is not None:
            self._stderr_thread.join(5)
        for f in (proc.stdout, proc.stderr):
            if f is not None:
                f.close()
        return code

    def _close_control(self) -> None:
        for f in (self._ctl_file, self._ctl):
            if f is not None:
                with contextlib.suppress(OSError):
                    f.close()
        self._ctl_file = self._ctl = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---- control channel -----------------------------------------------------
    def send_line(self, line: bytes) -> Status:
        """One raw request line (no newline inside), its JSON reply."""
        if self._ctl_file is None:
            raise self.failure("not started")
        self._ctl_file.write(line + b"\n")
        self._ctl_file.flush()
        reply = self._ctl_file.readline()
        if not reply:
            raise self.closed_failure(f"control channel closed; stderr: {self.stderr_lines[-20:]}")
        result: Status = json.loads(reply)
        return result

    def request(self, req: Status | str) -> Status:
        """One request (a dict, or a raw line to test bad input) and its reply."""
        return self.send_line((req if isinstance(req, str) else json.dumps(req)).encode())

    def _ok(self, req: Status) -> Status:
        reply = self.request(req)
        if not reply.get("ok"):
            raise self.failure(f"{req} refused: {reply.get('error')}")
        return reply

    def status(self) -> Status:
        return self._ok({"cmd": "status"})

    def wait_for(self, predicate: Callable[[Status], bool], timeout: float | None = None,
                 what: str = "condition") -> Status:
        """Poll the status until predicate(status) holds; the last status."""
        timeout = self.wait_timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        while True:
            st = self.status()
            if predicate(st):
                return st
            if time.monotonic() > deadline:
                raise self.wait_failure(f"{what} not reached within {timeout} s; last status {st}; "
                                        f"stderr: {self.stderr_lines[-20:]}")
            time.sleep(0.02)  # a poll: the simulator tells its status only when asked


class PointsControllerProcess(SimProcess):
    """The control commands the simulators of controllers rob6 streams points to (Adept,
    Kawasaki) share: E-stop, controller errors, slow acknowledgements."""

    def estop(self) -> None:
        self._ok({"cmd": "estop"})

    def release(self) -> None:
        self._ok({"cmd": "estop_release"})

    def error(self, code: int) -> None:
        self._ok({"cmd": "error", "code": code})

    def clear_error(self) -> None:
        self._ok({"cmd": "clear_error"})

    def slow_ack(self, ms: float) -> None:
        self._ok({"cmd": "slow_ack", "ms": ms})


def _wait(proc: subprocess.Popen[str], timeout: float) -> int | None:
    """The exit code, or None when the process is still running after ``timeout``."""
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        return None
