"""The gripper backend of a real Schunk PG/PR/PRL module on a serial port (SMP over pyserial).

The serial client of a real Schunk PG/PR/PRL module: :class:`SchunkGripper`, the
gripper backend that speaks the Schunk Motion Protocol (:mod:`rob6_gripper.smp`, whose
docstring gives the sources [M], [G], [P] and the frame format) on a serial port (pyserial).

Assumptions where the public material is unclear
------------------------------------------------
* Sign: positive current / larger position = opening (PG 70 positions are the
  jaw opening, 0-69 mm [P]); so ``GripperMove`` amps go to MOVE CUR unchanged.
* A failure reply may carry the failed command's code or CMD ERROR/WARNING/INFO
  ([G] accepts all four); any D-Len 2 reply in group 0x07 is taken as the pending
  command's failure.  Group 0x03 messages (the periodic error reports) are never
  taken as a reply; they only record the module's error.
* "gripping" is not an SMP state: we report it when the module stands, still draws
  current (> 0.05 A) and is more than 1 mm inside both stroke ends.
* ``go_home`` is CMD REFERENCE; where the module then stands depends on its
  configuration.  Pass ``home_position=0.04`` to add a MOVE POS to 4 cm afterwards.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from .backend import (
    DEFAULT_TIMEOUT,
    ERROR,
    GRIPPING,
    IDLE,
    MOVING,
    GripperBackend,
    GripperStatus,
    Result,
    check_number,
    check_timeout,
    fail,
)
from .smp import (
    CMD_ACK,
    CMD_ERROR,
    CMD_INFO,
    CMD_MOVE_BLOCKED,
    CMD_POS_REACHED,
    CMD_REFERENCE,
    CMD_STOP,
    CMD_WARNING,
    GET_STATE,
    GROUP_FROM_MODULE,
    MOVE_CUR,
    MOVE_POS,
    OK,
    Frame,
    FrameDecoder,
    ModuleState,
    SmpDeviceError,
    SmpError,
    SmpPortError,
    SmpProtocolError,
    SmpTimeout,
    command_name,
    encode,
    error_name,
    f32,
    get_state_payload,
    parse_state,
)


class SerialPort(Protocol):
    """What :class:`SchunkGripper` uses of a port: pyserial's ``Serial``, or a test's fake."""

    timeout: float | None

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes, /) -> int | None: ...

    def reset_input_buffer(self) -> None: ...

    def close(self) -> None: ...


def _default_serial_factory(**kwargs: Any) -> SerialPort:
    import serial  # pyserial

    return serial.Serial(**kwargs)


class SchunkGripper(GripperBackend):
    """A Schunk module (PG 70 class) on a serial port, spoken to in SMP.

    ``port``/``baudrate``/``module_id``: the module's RS232 settings ([P]: 9600 baud,
    id 12).  ``response_timeout``: how long one command waits for its reply;
    ``retries``: resends after a timeout or bad CRC (all commands used here are
    idempotent).  ``poll_interval``: GET STATE period while waiting for a motion.
    ``units_per_metre``: the module's unit system (1000 = mm).  ``stroke``: allowed
    targets in m.  ``settle_time``: how long a motion may show "not moving" before we
    believe it never started (modules that stand still at once).

    Time bound: a motion call returns within ``timeout`` plus at most two commands'
    worth of ``(retries + 1) * response_timeout`` (the last state poll and the stop
    sent on a timeout); a missing device fails after ``(retries + 1) *
    response_timeout``, an unplugged port at once.
    """

    def __init__(self, port: str, baudrate: int = 9600, module_id: int = 12, *,
                 response_timeout: float = 0.3, retries: int = 1, poll_interval: float = 0.05,
                 units_per_metre: float = 1000.0, stroke: tuple[float, float] = (0.0, 0.070),
                 home_position: float | None = None, settle_time: float = 0.3,
                 serial_factory: Callable[..., SerialPort] | None = None) -> None:
        if not 0 <= module_id <= 255:
            raise ValueError("module id must be 0..255")
        self.port_name = port
        self.baudrate = baudrate
        self.module_id = module_id
        self.response_timeout = response_timeout
        self.retries = max(0, retries)
        self.command_bound_s = (self.retries + 1) * response_timeout
        self.poll_interval = poll_interval
        self.units = units_per_metre
        self.stroke = stroke
        self.home_position = home_position
        self.settle_time = settle_time
        self._factory = serial_factory or _default_serial_factory
        self._port: SerialPort | None = None
        self._io = threading.RLock()
        self._decoder = FrameDecoder(module_id=module_id)
        self._queue: deque[Frame] = deque()
        self._impulses: deque[Frame] = deque()
        self._stop_gen = 0
        self._wake = threading.Event()
        self._last_position = 0.0
        self.last_device_error: int | None = None

    # ------------------------------------------------------------ serial
    def _open(self) -> SerialPort:
        if self._port is None:
            try:
                self._port = self._factory(port=self.port_name, baudrate=self.baudrate,
                                           timeout=0.02, write_timeout=self.response_timeout)
            except Exception as e:  # SerialException, OSError, ValueError
                raise SmpPortError(f"cannot open serial port {self.port_name}: {e}") from e
        return self._port

    def _drop_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(Exception):  # closing a dead port: whatever it raises
                port.close()

    def close(self) -> None:
        with self._io:
            self._drop_port()

    def _io_error(self, what: str, e: Exception) -> SmpPortError:
        self._drop_port()
        return SmpPortError(f"serial port {self.port_name} failed during {what}: {e}")

    def _handle_unsolicited(self, frame: Frame) -> None:
        if frame.command in (CMD_ERROR, CMD_WARNING) and frame.payload:
            self.last_device_error = frame.payload[0]
        self._impulses.append(frame)

    def _transact(self, command: int, payload: bytes = b"", timeout: float | None = None) -> Frame:
        """Send one command, return its (successful) reply frame."""
        timeout = self.response_timeout if timeout is None else timeout
        last: SmpError | None = None
        for _attempt in range(self.retries + 1):
            try:
                return self._transact_once(command, payload, timeout)
            except (SmpTimeout, SmpProtocolError) as e:
                last = e
        assert last is not None
        raise last

    def _transact_once(self, command: int, payload: bytes, timeout: float) -> Frame:
        with self._io:
            port = self._open()
            name = command_name(command)
            # forget stale bytes (late replies of an earlier, timed-out command)
            try:
                port.reset_input_buffer()
            except Exception as e:  # SerialException, OSError
                raise self._io_error(f"{name} (flush)", e) from e
            for f in self._queue:
                if f.command != command:
                    self._handle_unsolicited(f)
            self._queue.clear()
            self._decoder.reset()
            crc_before = self._decoder.crc_errors
            try:
                port.write(encode(self.module_id, command, payload))
            except Exception as e:  # SerialException, SerialTimeoutException, OSError
                raise self._io_error(f"{name} (write)", e) from e
            deadline = time.monotonic() + timeout
            while True:
                while self._queue:
                    frame = self._queue.popleft()
                    if frame.group == GROUP_FROM_MODULE and (frame.command == command or (
                            frame.is_failure and frame.command in (CMD_ERROR, CMD_WARNING, CMD_INFO))):
                        return self._check_reply(frame, name)
                    self._handle_unsolicited(frame)
                left = deadline - time.monotonic()
                if left <= 0:
                    bad = self._decoder.crc_errors - crc_before
                    if bad:
                        raise SmpProtocolError(
                            f"no valid reply to {name} within {timeout:.3f} s "
                            f"({bad} frame(s) with bad CRC received)")
                    if self._decoder.buf:
                        raise SmpTimeout(f"incomplete reply to {name} within {timeout:.3f} s "
                                         f"({len(self._decoder.buf)} byte(s) of a partial frame)")
                    raise SmpTimeout(f"no reply to {name} within {timeout:.3f} s "
                                     f"(module {self.module_id} on {self.port_name})")
                try:
                    port.timeout = min(left, 0.05)
                    data = port.read(max(1, port.in_waiting))
                except Exception as e:  # SerialException, OSError
                    raise self._io_error(f"{name} (read)", e) from e
                if data:
                    self._queue.extend(self._decoder.feed(data))

    def _check_reply(self, frame: Frame, name: str) -> Frame:
        if frame.is_failure:
            code = frame.payload[0]
            if frame.command in (CMD_ERROR, CMD_WARNING):
                self.last_device_error = code
            raise SmpDeviceError(f"module refused {name}: {error_name(code)}", code)
        return frame

    def _expect_ok(self, command: int, payload: bytes = b"") -> None:
        reply = self._transact(command, payload)
        if not reply.payload.startswith(OK):
            raise SmpProtocolError(f"unexpected reply to {command_name(command)}: "
                                   f"{reply.payload.hex(' ')}")

    def read_state(self, timeout: float | None = None) -> ModuleState:
        reply = self._transact(GET_STATE, get_state_payload(0x07), timeout)
        st = parse_state(reply.payload, 0x07)
        if st.position is not None:
            self._last_position = st.position / self.units
        return st

    # ------------------------------------------------------------ motion
    def _motion(self, what: str, command: int, payload: bytes, timeout: float,
                kind: str) -> Result:
        start = time.monotonic()
        deadline = start + timeout
        gen = self._stop_gen
        self._impulses.clear()
        try:
            self._transact(command, payload)
        except (SmpTimeout, SmpProtocolError) as e:
            self._quiet_stop()  # the command may have arrived even though its reply did not
            return fail(f"{what}: {e}")
        except SmpError as e:
            return fail(f"{what}: {e}")
        seen_moving = False
        while True:
            if self._stop_gen != gen:
                return fail(f"{what}: stopped by a stop command at {self._last_position:.4f} m",
                            self._last_position)
            impulse = None
            while self._impulses:
                f = self._impulses.popleft()
                if f.command in (CMD_POS_REACHED, CMD_MOVE_BLOCKED):
                    impulse = f.command
            try:
                st = self.read_state()
            except SmpError as e:
                return fail(f"{what}: {e}")
            pos = self._last_position
            if st.in_error:
                self.last_device_error = st.error
                return fail(f"{what}: module error {error_name(st.error)} at {pos:.4f} m", pos)
            settled = seen_moving or impulse is not None or time.monotonic() - start > self.settle_time
            if not st.moving and settled:
                if kind == "position":
                    if st.position_reached or impulse == CMD_POS_REACHED:
                        return Result(True, "", pos)
                    return fail(f"{what}: blocked at {pos:.4f} m before reaching the target", pos)
                if kind == "reference":
                    if not st.referenced:
                        return fail(f"{what}: reference run ended but the module is not referenced",
                                    pos)
                    return Result(True, "", pos)
                return Result(True, "", pos)  # current move: blocked by object or stroke end
            seen_moving = seen_moving or st.moving
            now = time.monotonic()
            if now >= deadline:
                self._quiet_stop()
                return fail(f"{what}: not finished within {timeout:.3f} s; stopped at {pos:.4f} m",
                            pos)
            self._wake.wait(min(self.poll_interval, deadline - now))
            self._wake.clear()

    def _quiet_stop(self) -> None:
        with contextlib.suppress(SmpError):
            self._transact(CMD_STOP)

    # ------------------------------------------------------------ interface
    def has_gripper(self) -> bool:
        try:
            self.read_state()
            return True
        except SmpError:
            return False

    def go_home(self, timeout: float = DEFAULT_TIMEOUT) -> Result:
        err = check_timeout(timeout)
        if err:
            return fail(f"GripperGoHome: {err}")
        start = time.monotonic()
        result = self._motion("GripperGoHome", CMD_REFERENCE, b"", timeout, "reference")
        if not result or self.home_position is None:
            return result
        left = timeout - (time.monotonic() - start)
        if left <= 0:
            return fail(f"GripperGoHome: referenced, but no time left to move to "
                        f"{self.home_position:.4f} m", result.position)
        return self._motion("GripperGoHome", MOVE_POS, f32(self.home_position * self.units),
                            left, "position")

    def move_current(self, amps: float, timeout: float = DEFAULT_TIMEOUT) -> Result:
        err = check_number("current", amps, "A") or check_timeout(timeout)
        if err:
            return fail(f"GripperMove: {err}")
        return self._motion("GripperMove", MOVE_CUR, f32(float(amps)), timeout, "current")

    def move_to_position(self, metres: float, timeout: float = DEFAULT_TIMEOUT) -> Result:
        err = check_number("position", metres, "m") or check_timeout(timeout)
        if err:
            return fail(f"GripperMoveToPosition: {err}")
        lo, hi = self.stroke
        if not lo - 1e-9 <= metres <= hi + 1e-9:
            return fail(f"GripperMoveToPosition: position {metres:.4f} m is outside the stroke "
                        f"{lo:.3f}..{hi:.3f} m")
        return self._motion("GripperMoveToPosition", MOVE_POS, f32(metres * self.units),
                            timeout, "position")

    def stop(self) -> Result:
        self._stop_gen += 1
        self._wake.set()
        try:
            self._expect_ok(CMD_STOP)
        except SmpError as e:
            return fail(f"stop: {e}")
        return Result(True, "", self._last_position)

    def acknowledge(self) -> Result:
        try:
            self._expect_ok(CMD_ACK)
        except SmpError as e:
            return fail(f"acknowledge: {e}")
        self.last_device_error = None
        return Result(True, "", self._last_position)

    def state(self) -> GripperStatus:
        try:
            st = self.read_state()
        except SmpError as e:
            return GripperStatus(self._last_position, 0.0, 0.0, ERROR, str(e))
        pos = self._last_position
        vel = (st.velocity or 0.0) / self.units
        cur = st.current or 0.0
        if st.in_error:
            return GripperStatus(pos, vel, cur, ERROR, error_name(st.error))
        if st.moving:
            mode = MOVING
        elif abs(cur) > 0.05 and self.stroke[0] + 1e-3 < pos < self.stroke[1] - 1e-3:
            mode = GRIPPING
        else:
            mode = IDLE
        return GripperStatus(pos, vel, cur, mode, "")

