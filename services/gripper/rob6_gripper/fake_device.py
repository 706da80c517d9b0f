"""A fake Schunk SMP module on a pseudo-terminal, for tests and bench runs.

``FakeSmpDevice().start()`` opens a pty pair (``os.openpty``); :attr:`port` is the
slave's path, which :class:`~rob6_gripper.schunk.SchunkGripper` (pyserial) opens like a
real ``/dev/ttyS0``.  A thread reads the master side, parses SMP frames addressed to
its module id, answers them and drives a :class:`~rob6_gripper.sim.GripperModel`
(in mm, like a module in its default unit system) in real time, optionally faster
(``time_scale``).  It sends CMD POS REACHED / CMD MOVE BLOCKED impulses when a
motion ends and CMD ERROR (group 0x03) when an error is injected.

Fault switches (plain attributes, change them any time):

* ``silent`` -- read and drop everything, answer nothing (a dead module)
* ``corrupt_crc`` -- every reply goes out with a wrong CRC
* ``delay`` -- seconds to wait before each reply
* ``split`` -- write replies in pieces of this many bytes, 2 ms apart
* ``garbage`` -- bytes sent before each reply
* ``fragment_size`` -- send replies as fragments of this many data bytes
* :meth:`unplug` -- close the master side: the port reads/writes fail (EIO)
* :meth:`inject_error` -- put the module into an error (e.g. 0xDA ERROR TOW)
"""

from __future__ import annotations

import contextlib
import os
import select
import struct
import threading
import time
import tty
from collections.abc import Callable

from . import smp
from .backend import ERROR, MOVING
from .sim import GripperError, GripperModel, GripperParams


class FakeSmpDevice:
    def __init__(self, module_id: int = 12, *, params: GripperParams | None = None,
                 object_width: float | None = None, referenced: bool = True,
                 position: float | None = None, time_scale: float = 1.0,
                 units_per_metre: float = 1000.0) -> None:
        self.module_id = module_id
        self.model = GripperModel(params, position=position, object_width=object_width,
                                  referenced=referenced)
        self.time_scale = time_scale
        self.units = units_per_metre
        # fault switches
        self.silent = False
        self.corrupt_crc = False
        self.delay = 0.0
        self.split: int | None = None
        self.garbage = b""
        self.fragment_size: int | None = None
        # bookkeeping
        self.received: list[smp.Frame] = []
        self.error_code = 0
        self._lock = threading.RLock()
        self._decoder = smp.FrameDecoder(groups=(smp.GROUP_TO_MODULE,), module_id=module_id)
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._running = False
        self._t = 0.0
        self._watch: tuple[int, str] | None = None  # (motion id, kind) awaiting an impulse
        self._pos_reached = False
        self.port = ""

    # ------------------------------------------------------------ life cycle
    def start(self) -> FakeSmpDevice:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self._t = time.monotonic()
        self._running = True
        self._thread = threading.Thread(target=self._loop, name="fake-smp", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=2)
            self._thread = None
        for name in ("_master", "_slave"):
            fd = getattr(self, name)
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
                setattr(self, name, None)

    def unplug(self) -> None:
        """Pull the cable: stop answering and hang up the pty (client I/O fails)."""
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=2)
            self._thread = None
        if self._master is not None:
            os.close(self._master)
            self._master = None

    def __enter__(self) -> FakeSmpDevice:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ controls
    def inject_error(self, code: int = 0xDA) -> None:
        with self._lock:
            self._sync()
            self.error_code = code
            self.model.fault(smp.error_name(code))
            self._watch = None
            self._send(smp.Frame(smp.GROUP_ERROR, self.module_id, smp.CMD_ERROR, bytes((code,))))

    def set_object(self, width: float | None) -> None:
        with self._lock:
            self._sync()
            self.model.set_object(width)

    # ------------------------------------------------------------ loop
    def _loop(self) -> None:
        master = self._master
        if master is None:  # closed before the thread ran
            return
        while self._running:
            try:
                ready, _, _ = select.select([master], [], [], 0.005)
            except (OSError, ValueError):
                return
            with self._lock:
                self._sync()
                if ready:
                    try:
                        data = os.read(master, 4096)
                    except OSError:
                        data = b""
                    if data and not self.silent:
                        for frame in self._decoder.feed(data):
                            self.received.append(frame)
                            self._sync()
                            self._handle(frame)

    def _sync(self) -> None:
        """Bring the model to now; report a motion that has just ended."""
        now = time.monotonic()
        self.model.advance((now - self._t) * self.time_scale)
        self._t = now
        self._check_impulse()

    def _check_impulse(self) -> None:
        if self._watch is None:
            return
        mid, kind = self._watch
        out = self.model.outcome(mid)
        if out is None:
            return
        self._watch = None
        pos = smp.f32(out.position * self.units)
        if out.status == "reached":
            self._pos_reached = True
            self._send(self._reply(smp.CMD_POS_REACHED, pos))
        elif out.status in ("blocked", "gripping", "end_stop"):
            self._send(self._reply(smp.CMD_MOVE_BLOCKED, pos))

    # ------------------------------------------------------------ protocol
    def _reply(self, command: int, payload: bytes = b"") -> smp.Frame:
        return smp.Frame(smp.GROUP_FROM_MODULE, self.module_id, command, payload)

    def _refuse(self, command: int, code: int) -> None:
        self._send(self._reply(command, bytes((code,))))

    def _module_state(self) -> smp.ModuleState:
        m = self.model
        bits = 0
        if m.referenced:
            bits |= smp.ST_REFERENCED
        if m.mode == MOVING:
            bits |= smp.ST_MOVING
        if m.mode == ERROR:
            bits |= smp.ST_ERROR
        if self._pos_reached:
            bits |= smp.ST_POS_REACHED | smp.ST_MOVE_END
        return smp.ModuleState(m.w * self.units, m.v * self.units, m.current, bits,
                               self.error_code if m.mode == ERROR else 0)

    def _start_motion(self, command: int, start: Callable[[], int]) -> None:
        if self.model.mode == ERROR:
            self._refuse(smp.CMD_ERROR, self.error_code)
            return
        try:
            mid = start()
        except GripperError as e:
            text = str(e)
            code = 0x06 if "referenced" in text else 0x1E  # NOT REFERENCED / WRONG PARAMETER
            self._refuse(command, code)
            return
        self._pos_reached = False
        self._watch = (mid, "motion")
        if command == smp.MOVE_POS:
            self._send(self._reply(command, smp.f32(self.model.time_to_completion())))
        else:
            self._send(self._reply(command, smp.OK))
        self._check_impulse()  # motions that end at once (already there / blocked)

    def _handle(self, frame: smp.Frame) -> None:
        cmd, data = frame.command, frame.payload
        m = self.model
        if cmd == smp.GET_STATE:
            mode = data[4] if len(data) >= 5 else 0x07
            self._send(self._reply(cmd, smp.state_payload(self._module_state(), mode)))
        elif cmd == smp.CMD_REFERENCE:
            self._start_motion(cmd, lambda: m.command_position(m.p.home_position, home=True))
        elif cmd == smp.MOVE_POS:
            if len(data) < 4:
                self._refuse(cmd, 0x1D)  # INFO MESSAGE LENGTH
                return
            target = struct.unpack_from("<f", data)[0] / self.units
            self._start_motion(cmd, lambda: m.command_position(target))
        elif cmd == smp.MOVE_CUR:
            if len(data) < 4:
                self._refuse(cmd, 0x1D)
                return
            amps = struct.unpack_from("<f", data)[0]
            self._start_motion(cmd, lambda: m.command_current(amps))
        elif cmd == smp.CMD_STOP:
            m.command_stop()
            self._watch = None
            self._send(self._reply(cmd, smp.OK))
        elif cmd == smp.CMD_ACK:
            m.acknowledge()
            self.error_code = 0
            self._send(self._reply(cmd, smp.OK))
            self._send(self._reply(smp.CMD_INFO, bytes((0x08, 0x00))))  # INFO NO ERROR
        else:
            self._refuse(cmd, 0x04)  # INFO UNKNOWN COMMAND

    def _send(self, frame: smp.Frame) -> None:
        if self.silent or self._master is None:
            return
        pieces = frame.encode_fragments(self.fragment_size) if self.fragment_size else [frame.encode()]
        if self.corrupt_crc:
            pieces = [p[:-1] + bytes((p[-1] ^ 0xFF,)) for p in pieces]
        data = self.garbage + b"".join(pieces)
        if self.delay:
            time.sleep(self.delay)
        try:
            if self.split:
                for i in range(0, len(data), self.split):
                    os.write(self._master, data[i:i + self.split])
                    time.sleep(0.002)
            else:
                os.write(self._master, data)
        except OSError:
            pass
