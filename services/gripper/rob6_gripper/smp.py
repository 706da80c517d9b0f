"""Schunk Motion Protocol (SMP) without I/O: constants, CRC, frames, decoder, payloads, errors.

Schunk Motion Protocol (SMP) over RS232: constants, CRC, frames (encoder and an
incremental decoder), payloads and errors. No I/O here: the serial client that speaks it
to a real module is :class:`rob6_gripper.schunk.SchunkGripper`, the fake module of the
tests is :mod:`rob6_gripper.fake_device`.

Sources (public; read 2026)
---------------------------
[M] SCHUNK "Motion Protocol" manual 1.41 (2010), HTML edition mirrored at
    www.cs.unc.edu/Research/stc/FAQs/Schunk/SMP_v_1_41/Doc/HTML_Eng/: data frame
    (docu10), RS232 frame (docu11), fragmentation (docu14, FRAG START docu108,
    FRAG ACK docu107), CMD REFERENCE (docu35), MOVE CUR (docu45), CMD MOVE BLOCKED
    (docu58), CMD POS REACHED (docu59), error commands incl. CMD ACK (docu112),
    GET DETAILED ERROR INFO (docu117), worked RS232 examples with CRCs (docu304-307).
[S] SCHUNK STM 48V assembly manual (2011) ch. 11 "SCHUNK Motion protocol" (MOVE POS,
    MOVE CUR, CMD STOP, CMD FAST STOP, CMD ACK examples).
[G] spatialaudio/schunk (M. Geier, MIT): schunk.py -- a Python SMP client: CRC table,
    GET STATE layout, state bits, error-code names.
[P] SmartRoboticSystems/schunk_grippers (BSD): schunk_pg70/ -- PG 70 over RS232 at
    9600 baud, module id 12, positions 0-69 mm, GET STATE usage.

RS232 frame ([M] docu10/docu11, byte-checked against the docu304-307 examples)::

    group | module id | D-Len | command | parameters ... | CRC16 (2 bytes, low first)

* group: 0x05 master -> module, 0x07 module -> master, 0x03 module -> master error
  message (e.g. ``03 01 02 88 74 82 1B``: CMD ERROR, MOTOR VOLTAGE LOW).
* D-Len counts the command byte plus parameters (<= 255).  A response with D-Len 2
  is a failure: its single parameter is the error code ([M] docu10).
* CRC16 over group .. last parameter: CRC-16/ARC (reflected polynomial 0xA001,
  initial value 0, no final XOR), transmitted little-endian.  Verified against all
  13 CRCs printed in [M] docu304-307 (see tests/gripper/test_gripper_smp.py).
* Numbers are little-endian; positions/velocities are IEEE float32 in the module's
  unit system (default mm, mm/s -- ``units_per_metre=1000``), currents float32 A.

Commands used: CMD REFERENCE 0x92 (reply "OK"), MOVE POS 0xB0 (float position; reply
"OK" or float estimated time), MOVE CUR 0xB3 (float current; reply "OK"), CMD STOP
0x91 ("OK"), GET STATE 0x95 (params: float period s -- 0 = once --, uint8 mode
1|2|4 = position|velocity|current; reply: the selected floats, state byte, error
byte), CMD ACK 0x8B ("OK", then an INFO NO ERROR message).  Impulse (spontaneous)
messages understood: CMD POS REACHED 0x94 and CMD MOVE BLOCKED 0x93 (float
position), CMD ERROR 0x88 / CMD WARNING 0x89 / CMD INFO 0x8A (error code).
State byte bits ([G]): 0 referenced, 1 moving, 2 program mode, 3 warning, 4 error,
5 brake, 6 move end, 7 position reached.

Assumptions where the public material is unclear
------------------------------------------------
* Fragmentation ([M] docu14) is meant for CAN/Profibus ("normally not necessary");
  the marker follows D-Len and is not counted in it.  Only FRAG START = 0x84 and
  FRAG ACK = 0x87 are confirmed; FRAG MIDDLE = 0x85 and FRAG END = 0x86 are assumed
  (the codes in between).  RS232 has no per-message length other than D-Len, so we
  assume a fragment frame is ``group | id | D-Len | marker | D-Len bytes | CRC``
  with D-Len counting this fragment's bytes, the CRC covering the marker, and the
  first fragment's data starting with the command code.  The decoder reassembles
  such frames; the master never sends fragments (every command fits one frame).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass

from rob6.errors import LinkError

# ---------------------------------------------------------------- constants
GROUP_TO_MODULE = 0x05
GROUP_FROM_MODULE = 0x07
GROUP_ERROR = 0x03

GET_CONFIG = 0x80
SET_CONFIG = 0x81
FRAG_START = 0x84
FRAG_MIDDLE = 0x85  # assumed, see module docstring
FRAG_END = 0x86  # assumed, see module docstring
FRAG_ACK = 0x87
CMD_ERROR = 0x88
CMD_WARNING = 0x89
CMD_INFO = 0x8A
CMD_ACK = 0x8B
CMD_FAST_STOP = 0x90
CMD_STOP = 0x91
CMD_REFERENCE = 0x92
CMD_MOVE_BLOCKED = 0x93
CMD_POS_REACHED = 0x94
GET_STATE = 0x95
GET_DETAILED_ERROR_INFO = 0x96
MOVE_POS = 0xB0
MOVE_CUR = 0xB3
MOVE_VEL = 0xB5
MOVE_GRIP = 0xB7
CMD_TOGGLE_IMPULSE_MESSAGE = 0xE7

FRAGMENT_MARKERS = (FRAG_START, FRAG_MIDDLE, FRAG_END)
OK = b"OK"

# GET STATE mode bits and state byte bits
STATE_MODE_POSITION, STATE_MODE_VELOCITY, STATE_MODE_CURRENT = 0x01, 0x02, 0x04
ST_REFERENCED, ST_MOVING, ST_PROGRAM, ST_WARNING = 0x01, 0x02, 0x04, 0x08
ST_ERROR, ST_BRAKE, ST_MOVE_END, ST_POS_REACHED = 0x10, 0x20, 0x40, 0x80

#: Error / info codes of [M] (names as in [G]).
ERROR_CODES = {
    0x00: "NO ERROR", 0x01: "INFO BOOT", 0x02: "INFO NO FREE SPACE", 0x03: "INFO NO RIGHTS",
    0x04: "INFO UNKNOWN COMMAND", 0x05: "INFO FAILED", 0x06: "NOT REFERENCED",
    0x07: "INFO SEARCH SINE VECTOR", 0x08: "INFO NO ERROR", 0x09: "INFO COMMUNICATION ERROR",
    0x10: "INFO TIMEOUT", 0x16: "INFO WRONG BAUDRATE", 0x19: "INFO CHECKSUM",
    0x1D: "INFO MESSAGE LENGTH", 0x1E: "INFO WRONG PARAMETER", 0x1F: "INFO PROGRAM END",
    0x40: "INFO TRIGGER", 0x41: "INFO READY", 0x42: "INFO GUI CONNECTED",
    0x43: "INFO GUI DISCONNECTED", 0x44: "INFO PROGRAM CHANGED",
    0x70: "ERROR TEMP LOW", 0x71: "ERROR TEMP HIGH", 0x72: "ERROR LOGIC LOW",
    0x73: "ERROR LOGIC HIGH", 0x74: "ERROR MOTOR VOLTAGE LOW", 0x75: "ERROR MOTOR VOLTAGE HIGH",
    0x76: "ERROR CABLE BREAK", 0x78: "ERROR MOTOR TEMP", 0xC8: "ERROR WRONG RAMP TYPE",
    0xD2: "ERROR CONFIG MEMORY", 0xD3: "ERROR PROGRAM MEMORY", 0xD4: "ERROR INVALID PHRASE",
    0xD5: "ERROR SOFT LOW", 0xD6: "ERROR SOFT HIGH", 0xD7: "ERROR PRESSURE",
    0xD8: "ERROR SERVICE", 0xD9: "ERROR EMERGENCY STOP", 0xDA: "ERROR TOW",
    0xDB: "ERROR VPC3", 0xDC: "ERROR FRAGMENTATION", 0xDD: "ERROR COMMUTATION",
    0xDE: "ERROR CURRENT", 0xDF: "ERROR I2T", 0xE0: "ERROR INITIALIZE", 0xE1: "ERROR INTERNAL",
    0xE2: "ERROR HARD LOW", 0xE3: "ERROR HARD HIGH", 0xE4: "ERROR TOO FAST", 0xEC: "ERROR MATH",
}

COMMAND_NAMES = {
    CMD_REFERENCE: "CMD REFERENCE", MOVE_POS: "MOVE POS", MOVE_CUR: "MOVE CUR",
    CMD_STOP: "CMD STOP", GET_STATE: "GET STATE", CMD_ACK: "CMD ACK",
    CMD_ERROR: "CMD ERROR", CMD_WARNING: "CMD WARNING", CMD_INFO: "CMD INFO",
    CMD_POS_REACHED: "CMD POS REACHED", CMD_MOVE_BLOCKED: "CMD MOVE BLOCKED",
}


def error_name(code: int) -> str:
    return f"{ERROR_CODES.get(code, 'UNKNOWN ERROR')} (0x{code:02X})"


def command_name(code: int) -> str:
    return COMMAND_NAMES.get(code, f"command 0x{code:02X}")


# ---------------------------------------------------------------- CRC
def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: Iterable[int], crc: int = 0) -> int:
    """SMP CRC16 (CRC-16/ARC) of ``data``; send it little-endian."""
    for b in data:
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ b) & 0xFF]
    return crc


# ---------------------------------------------------------------- frames
@dataclass(frozen=True)
class Frame:
    group: int
    module_id: int
    command: int
    payload: bytes = b""

    @property
    def dlen(self) -> int:
        return 1 + len(self.payload)

    @property
    def is_failure(self) -> bool:
        """D-Len 2: the single parameter is an error code ([M] docu10)."""
        return self.dlen == 2

    @property
    def error_code(self) -> int | None:
        return self.payload[0] if self.is_failure else None

    def encode(self) -> bytes:
        if not 0 <= self.module_id <= 255 or self.dlen > 255:
            raise ValueError("module id or D-Len out of range")
        body = bytes((self.group, self.module_id, self.dlen, self.command)) + self.payload
        return body + crc16(body).to_bytes(2, "little")

    def encode_fragments(self, size: int) -> list[bytes]:
        """The frame as RS232 fragments of at most ``size`` data bytes (assumed layout,
        see the module docstring).  Used by the fake device."""
        if size < 1:
            raise ValueError("fragment size must be >= 1")
        data = bytes((self.command,)) + self.payload
        chunks = [data[i:i + size] for i in range(0, len(data), size)]
        out = []
        for i, chunk in enumerate(chunks):
            marker = FRAG_START if i == 0 else FRAG_END if i == len(chunks) - 1 else FRAG_MIDDLE
            body = bytes((self.group, self.module_id, len(chunk), marker)) + chunk
            out.append(body + crc16(body).to_bytes(2, "little"))
        if len(chunks) == 1:  # a single chunk still needs an end: send an empty FRAG END
            body = bytes((self.group, self.module_id, 0, FRAG_END))
            out.append(body + crc16(body).to_bytes(2, "little"))
        return out


def encode(module_id: int, command: int, payload: bytes = b"",
           group: int = GROUP_TO_MODULE) -> bytes:
    return Frame(group, module_id, command, payload).encode()


class FrameDecoder:
    """Incremental RS232 frame parser: feed it any byte chunks, get whole frames.

    Resynchronises after garbage and bad CRCs (skips one byte and searches again),
    keeps partial frames until the rest arrives, and -- if a partial "frame" never
    completes but a complete, CRC-valid frame follows it -- treats the former as
    garbage.  Fragments are reassembled.
    """

    def __init__(self, groups: Iterable[int] = (GROUP_FROM_MODULE, GROUP_ERROR),
                 module_id: int | None = None, max_buffer: int = 4096) -> None:
        self.groups = frozenset(groups)
        self.module_id = module_id
        self.max_buffer = max_buffer
        self.buf = bytearray()
        self.crc_errors = 0
        self.garbage_bytes = 0
        self.fragment_errors = 0
        self._frag: tuple[int, int, bytearray] | None = None

    def reset(self) -> None:
        self.buf.clear()
        self._frag = None

    # frame at buf[i:]: None = incomplete, False = not a frame start, else (length)
    def _length_at(self, i: int) -> int | None | bool:
        buf = self.buf
        if buf[i] not in self.groups:
            return False
        if len(buf) < i + 2:
            return None
        if self.module_id is not None and buf[i + 1] != self.module_id:
            return False
        if len(buf) < i + 4:
            return None
        dlen = buf[i + 2]
        if buf[i + 3] in FRAGMENT_MARKERS:
            return 4 + dlen + 2
        if dlen == 0:
            return False
        return 3 + dlen + 2

    def _valid_at(self, i: int, n: int) -> bool:
        body = self.buf[i:i + n - 2]
        return crc16(body) == int.from_bytes(self.buf[i + n - 2:i + n], "little")

    def feed(self, data: bytes) -> list[Frame]:
        self.buf += data
        out: list[Frame] = []
        while self.buf:
            n = self._length_at(0)
            if n is False:
                del self.buf[0]
                self.garbage_bytes += 1
                continue
            if n is None or len(self.buf) < n:
                # incomplete: is there a complete valid frame further on?
                j = self._later_valid_frame()
                if j is None:
                    break
                del self.buf[:j]
                self.garbage_bytes += j
                continue
            if not self._valid_at(0, n):
                self.crc_errors += 1
                del self.buf[0]
                self.garbage_bytes += 1
                continue
            raw = bytes(self.buf[:n])
            del self.buf[:n]
            frame = self._parse(raw)
            if frame is not None:
                out.append(frame)
        if len(self.buf) > self.max_buffer:
            drop = len(self.buf) - self.max_buffer
            del self.buf[:drop]
            self.garbage_bytes += drop
        return out

    def _later_valid_frame(self) -> int | None:
        for j in range(1, len(self.buf)):
            n = self._length_at(j)
            if n and len(self.buf) >= j + n and self._valid_at(j, n):
                return j
        return None

    def _parse(self, raw: bytes) -> Frame | None:
        group, mid, dlen, code = raw[0], raw[1], raw[2], raw[3]
        if code not in FRAGMENT_MARKERS:
            return Frame(group, mid, code, raw[4:3 + dlen])
        chunk = raw[4:4 + dlen]
        if code == FRAG_START:
            if self._frag is not None:
                self.fragment_errors += 1  # previous message never ended
            self._frag = (group, mid, bytearray(chunk))
            return None
        if self._frag is None or self._frag[:2] != (group, mid):
            self.fragment_errors += 1  # middle/end without a start
            return None
        self._frag[2].extend(chunk)
        if code == FRAG_MIDDLE:
            return None
        data = bytes(self._frag[2])
        self._frag = None
        if not data:
            self.fragment_errors += 1
            return None
        return Frame(group, mid, data[0], data[1:])


# ---------------------------------------------------------------- payloads
def f32(value: float) -> bytes:
    return struct.pack("<f", value)


@dataclass(frozen=True)
class ModuleState:
    """A decoded GET STATE reply (device units)."""

    position: float | None
    velocity: float | None
    current: float | None
    state: int
    error: int

    @property
    def referenced(self) -> bool:
        return bool(self.state & ST_REFERENCED)

    @property
    def moving(self) -> bool:
        return bool(self.state & ST_MOVING)

    @property
    def in_error(self) -> bool:
        return bool(self.state & ST_ERROR)

    @property
    def position_reached(self) -> bool:
        return bool(self.state & ST_POS_REACHED)


def get_state_payload(mode: int = 0x07, period: float = 0.0) -> bytes:
    return f32(period) + bytes((mode,))


def parse_state(payload: bytes, mode: int = 0x07) -> ModuleState:
    fields = [bit for bit in (STATE_MODE_POSITION, STATE_MODE_VELOCITY, STATE_MODE_CURRENT)
              if mode & bit]
    if len(payload) != 4 * len(fields) + 2:
        raise SmpProtocolError(
            f"GET STATE reply has {len(payload)} data bytes, expected {4 * len(fields) + 2}")
    values = dict(zip(fields, struct.unpack_from(f"<{len(fields)}f", payload), strict=True))
    return ModuleState(values.get(STATE_MODE_POSITION), values.get(STATE_MODE_VELOCITY),
                       values.get(STATE_MODE_CURRENT), payload[-2], payload[-1])


def state_payload(state: ModuleState, mode: int = 0x07) -> bytes:
    """Build a GET STATE reply payload (for the fake device)."""
    out = b""
    for bit, value in ((STATE_MODE_POSITION, state.position),
                       (STATE_MODE_VELOCITY, state.velocity),
                       (STATE_MODE_CURRENT, state.current)):
        if mode & bit:
            out += f32(value or 0.0)
    return out + bytes((state.state & 0xFF, state.error & 0xFF))


# ---------------------------------------------------------------- errors
class SmpError(LinkError):
    """Any failure talking to the module; the text is the user-facing reason."""


class SmpTimeout(SmpError):
    pass


class SmpPortError(SmpError):
    pass


class SmpProtocolError(SmpError):
    pass


class SmpDeviceError(SmpError):
    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code
