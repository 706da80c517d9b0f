"""RSI's XML datagrams as the KR C4 writes and reads them, shaped by the Ethernet configuration.

Controller -> PC every cycle: the SEND elements in the configuration's order, numbers with
the ETHERNET object's Precision, then the IPOC (always appended)::

    <Rob TYPE="KUKA"><RIst X=".." Y=".." Z=".." A=".." B=".." C=".."/><RSol .../>
    <AIPos A1=".." .. A6=".."/><ASPos .../><Delay D="n"/><IPOC>n</IPOC></Rob>

PC -> controller, the answer to one packet: ``<Sen Type="SENTYPE">`` holding every RECEIVE
element (``AK.A1`` is attribute A1 of ``<AK>``, ``Stop`` the text of ``<Stop>``) and the
IPOC it answers. An answer the configuration cannot read (not well-formed, no IPOC, a
RECEIVE element missing or not of its TYPE) is not taken (``SenError``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

from .ethernet import EthernetConfig, Received

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
_CART = ("X", "Y", "Z", "A", "B", "C")


class RobWriter:
    """Formats the controller's packet; the template is built once, each cycle is one `%`."""

    def __init__(self, send: Sequence[str], precision: int) -> None:
        f = f"%.{precision}f"
        cart = " ".join(f'{k}="{f}"' for k in _CART)
        axes = " ".join(f'{k}="{f}"' for k in AXES)
        ext = " ".join(f'E{i}="{0.0:.{precision}f}"' for i in range(1, 7))  # no external axes: 0
        parts = {"RIst": f"<RIst {cart}/>", "RSol": f"<RSol {cart}/>", "AIPos": f"<AIPos {axes}/>",
                 "ASPos": f"<ASPos {axes}/>", "EIPos": f"<EIPos {ext}/>", "Delay": '<Delay D="%d"/>'}
        self._send = tuple(send)
        self._template = '<Rob TYPE="KUKA">' + "".join(parts[s] for s in send) + "<IPOC>%d</IPOC></Rob>"

    def packet(self, rist: Sequence[float], rsol: Sequence[float], aipos: Sequence[float], aspos: Sequence[float],
               delay: int, ipoc: int) -> bytes:
        values: list[float | int] = []
        for s in self._send:
            if s == "RIst":
                values += rist
            elif s == "RSol":
                values += rsol
            elif s == "AIPos":
                values += aipos
            elif s == "ASPos":
                values += aspos
            elif s == "Delay":
                values.append(delay)
        values.append(ipoc)
        return (self._template % tuple(values)).encode("ascii")


class SenError(ValueError):
    """A datagram the controller cannot take as an answer."""


@dataclass(slots=True)
class Sen:
    type: str | None  # the Type attribute (None: missing)
    ipoc: int
    values: dict[int, float | str]  # ETHERNET output (RECEIVE INDX) -> value


def parse_sen(data: bytes, config: EthernetConfig) -> Sen:
    """Read a PC answer with the configuration's RECEIVE elements."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise SenError(f"not well-formed XML: {e}") from None
    if root.tag != "Sen":
        raise SenError(f"root element is <{root.tag}>, expected <Sen>")
    ipoc_el = root.find("IPOC")
    if ipoc_el is None or ipoc_el.text is None:
        raise SenError("no <IPOC>")
    try:
        ipoc = int(ipoc_el.text.strip())
    except ValueError:
        raise SenError(f"IPOC {ipoc_el.text.strip()!r} is not an integer") from None
    values = {r.indx: _value(root, r) for r in config.receive}
    return Sen(root.get("Type"), ipoc, values)


def _value(root: ET.Element, r: Received) -> float | str:
    element = root.find(r.element)
    if element is None:
        raise SenError(f"no <{r.element}> (RECEIVE element {r.tag})")
    attr = r.attribute
    text = element.get(attr) if attr is not None else element.text
    if text is None:
        raise SenError(f"<{r.element}> has no {attr if attr else 'value'} (RECEIVE element {r.tag})")
    text = text.strip()
    try:
        if r.type == "DOUBLE":
            value = float(text)
            if not math.isfinite(value):
                raise ValueError
            return value
        if r.type == "LONG":
            return float(int(text))
        if r.type == "BOOL":
            if text not in ("0", "1"):
                raise ValueError
            return float(text)
        return text
    except ValueError:
        raise SenError(f"{r.tag} {text!r} is not a {r.type}") from None
