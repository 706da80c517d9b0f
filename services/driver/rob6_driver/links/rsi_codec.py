"""The KUKA RSI Ethernet XML codec: the controller's ``<Rob>`` packet in, ``<Sen>`` out.

Every cycle the controller sends::

    <Rob TYPE="KUKA">
      <RIst X=".." Y=".." Z=".." A=".." B=".." C=".."/>   Cartesian actual (ignored)
      <RSol X=".." .../>                                    Cartesian setpoint (ignored)
      <AIPos A1=".." A2=".." A3=".." A4=".." A5=".." A6=".."/>  actual axis angles, deg
      <ASPos A1=".." .../>                                  axis angles where RSI started, deg
      <Delay D="n"/>                                        late packets so far in this run
      <IPOC>4208105428</IPOC>                               time stamp, echoed in the answer
    </Rob>

and the PC answers, before the cycle ends::

    <Sen Type="ImFree"><AK A1=".." ... A6=".."/><Stop>0</Stop><IPOC>4208105428</IPOC></Sen>

``AK`` is the absolute axis correction from the start pose (``RSI_ON(#ABSOLUTE)``);
``<Stop>1</Stop>`` ends the correction run. Every answer carries every element the
controller's Ethernet configuration reads (RECEIVE: Stop, AK.A1..A6), as the references'
PC sides always send them (deploy/kuka/REFERENCES.md).

The parser is tolerant of what varies between RSI versions and configurations:
attribute order, ``Type``/``TYPE``, single or double quotes, spaces and new lines,
extra elements (``EIPos``, ``Tech``, digital I/O...), ``<X .../>`` or ``<X ...></X>``.
It works on the raw bytes with precompiled expressions (this runs on the 4 ms path)
and raises ``RsiParseError`` (a ``ValueError``) with a readable message for anything
it cannot use, never another exception.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from rob6.errors import LinkError

from .wire_numbers import finite_float

AXES = (b"A1", b"A2", b"A3", b"A4", b"A5", b"A6")

_ROB = re.compile(rb"<\s*Rob\b([^>]*)>")
_AIPOS = re.compile(rb"<\s*AIPos\b([^>]*)>")
_ASPOS = re.compile(rb"<\s*ASPos\b([^>]*)>")
_DELAY = re.compile(rb"<\s*Delay\b([^>]*)>")
_IPOC = re.compile(rb"<\s*IPOC\s*>\s*(\d+)\s*<\s*/\s*IPOC\s*>")
_ATTR = re.compile(rb"""([A-Za-z_][\w.-]*)\s*=\s*(?:"([^"]*)"|'([^']*)')""")
_PREVIEW = 60


class RsiParseError(LinkError, ValueError):
    """A packet that is not a usable RSI ``<Rob>`` packet (the message says why)."""


class RobPacket:
    """One parsed controller packet. ``ipoc`` is the stamp's text, echoed as it came."""

    __slots__ = ("ipoc", "stamp", "delay", "aipos", "aspos", "robot_type")

    def __init__(self, ipoc: bytes, delay: int, aipos: tuple[float, ...], aspos: tuple[float, ...],
                 robot_type: str = "") -> None:
        self.ipoc = ipoc
        self.stamp = int(ipoc)
        self.delay = delay
        self.aipos = aipos
        self.aspos = aspos
        self.robot_type = robot_type

    def __repr__(self) -> str:
        return (f"RobPacket(ipoc={self.ipoc.decode()}, delay={self.delay}, aipos={self.aipos}, "
                f"aspos={self.aspos})")


def _attributes(text: bytes) -> dict[bytes, bytes]:
    # names compared upper-case: TYPE/Type, a1/A1
    return {m.group(1).upper(): m.group(2) if m.group(2) is not None else m.group(3)
            for m in _ATTR.finditer(text)}


def _axes(match: re.Match[bytes] | None, element: str, data: bytes) -> tuple[float, ...]:
    if match is None:
        raise RsiParseError(f"no <{element}> element in {_preview(data)}")
    attrs = _attributes(match.group(1))
    values = []
    for axis in AXES:
        text = attrs.get(axis)
        if text is None:
            raise RsiParseError(f"<{element}> has no {axis.decode()} in {_preview(data)}")
        try:
            values.append(finite_float(text))
        except ValueError as why:
            raise RsiParseError(f"<{element}> {axis.decode()}={text.decode('latin-1')!r} {why}") from None
    return tuple(values)


def _preview(data: bytes) -> str:
    text = bytes(data[:_PREVIEW]).decode("latin-1")
    return repr(text + ("..." if len(data) > _PREVIEW else ""))


def parse_rob(data: bytes | memoryview) -> RobPacket:
    """Parse one controller packet; ``RsiParseError`` when it cannot be used."""
    data = bytes(data)
    rob = _ROB.search(data)
    if rob is None:
        raise RsiParseError(f"not an RSI packet (no <Rob> element): {_preview(data)}")
    ipoc = _IPOC.search(data, rob.end())
    if ipoc is None:
        raise RsiParseError(f"no <IPOC> time stamp in {_preview(data)}")
    aipos = _axes(_AIPOS.search(data, rob.end()), "AIPos", data)
    aspos = _axes(_ASPOS.search(data, rob.end()), "ASPos", data)
    delay = 0
    match = _DELAY.search(data, rob.end())
    if match is not None:
        text = _attributes(match.group(1)).get(b"D")
        if text is None or not text.strip().isdigit():
            raise RsiParseError(f"<Delay> without a count D in {_preview(data)}")
        delay = int(text)
    robot_type = _attributes(rob.group(1)).get(b"TYPE", b"").decode("latin-1")
    return RobPacket(ipoc.group(1), delay, aipos, aspos, robot_type)


def ipoc_of(data: bytes) -> int:
    """Just the time stamp (-1 without one): picks the newest of several waiting packets."""
    match = _IPOC.search(data)
    return int(match.group(1)) if match else -1


_SEN = (b'<Sen Type="%s"><AK A1="%.6f" A2="%.6f" A3="%.6f" A4="%.6f" A5="%.6f" A6="%.6f"/>'
        b"<Stop>%d</Stop><IPOC>%s</IPOC></Sen>")


def format_sen(sen_type: bytes, ak: Sequence[float], ipoc: bytes, stop: bool = False) -> bytes:
    """The answer: absolute axis correction ``ak`` (6 values, deg) for the packet ``ipoc``;
    ``stop``: ``<Stop>1</Stop>``, the program leaves RSI_MOVECORR (else ``<Stop>0</Stop>``)."""
    return _SEN % (sen_type, ak[0], ak[1], ak[2], ak[3], ak[4], ak[5], stop, ipoc)
