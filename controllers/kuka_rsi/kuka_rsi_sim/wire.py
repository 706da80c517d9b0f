"""RSI's XML datagrams as the KR C4 writes and reads them.

Controller -> PC every cycle (numbers with the ETHERNET object's Precision, 4 decimals):

    <Rob TYPE="KUKA"><RIst X=".." Y=".." Z=".." A=".." B=".." C=".."/><RSol .../>
    <AIPos A1=".." .. A6=".."/><ASPos .../>[<EIPos E1=".." .. E6=".."/>]<Delay D="n"/>
    <IPOC>n</IPOC></Rob>

PC -> controller, the answer to one packet:

    <Sen Type="ImFree"><AK A1=".." .. A6=".."/>[<Stop>1</Stop>]<IPOC>same</IPOC></Sen>
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")


class RobWriter:
    """Formats the controller's packet; the template is built once, each cycle is one `%`."""

    def __init__(self, precision: int = 4, eipos: bool = False) -> None:
        f = f"%.{precision}f"
        cart = " ".join(f'{k}="{f}"' for k in "XYZABC")
        axes = " ".join(f'{k}="{f}"' for k in AXES)
        ext = ""
        if eipos:  # no external axes: the controller reports them at 0
            ext = "<EIPos " + " ".join(f'E{i}="{0.0:.{precision}f}"' for i in range(1, 7)) + "/>"
        self._template = (
            f'<Rob TYPE="KUKA"><RIst {cart}/><RSol {cart}/><AIPos {axes}/><ASPos {axes}/>'
            f'{ext}<Delay D="%d"/><IPOC>%d</IPOC></Rob>'
        )

    def packet(self, rist: Sequence[float], rsol: Sequence[float], aipos: Sequence[float], aspos: Sequence[float],
               delay: int, ipoc: int) -> bytes:
        return (self._template % (*rist, *rsol, *aipos, *aspos, delay, ipoc)).encode("ascii")


class SenError(ValueError):
    """A datagram the controller cannot read as a Sen answer."""


@dataclass(slots=True)
class Sen:
    type: str | None  # the Type attribute (None: missing)
    ipoc: int
    ak: list[float | None]  # six floats, None where the answer has no value for that axis
    stop: bool


def parse_sen(data: bytes) -> Sen:
    """Read a PC answer the way the controller's XML reader does: any attribute order and
    spacing, `Type` or `TYPE`, elements it was not configured for are ignored."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        raise SenError(f"not well-formed XML: {e}") from None
    if root.tag != "Sen":
        raise SenError(f"root element is <{root.tag}>, expected <Sen>")
    sen_type = None
    for key, value in root.attrib.items():
        if key.lower() == "type":
            sen_type = value
            break
    ipoc_el = root.find("IPOC")
    if ipoc_el is None or ipoc_el.text is None:
        raise SenError("no <IPOC>")
    try:
        ipoc = int(ipoc_el.text.strip())
    except ValueError:
        raise SenError(f"IPOC {ipoc_el.text.strip()!r} is not an integer") from None
    ak: list[float | None] = [None] * 6
    ak_el = root.find("AK")
    if ak_el is not None:
        for key, value in ak_el.attrib.items():
            name = key.upper()
            if name in AXES:
                try:
                    ak[AXES.index(name)] = float(value)
                except ValueError:
                    raise SenError(f"AK {key}={value!r} is not a number") from None
    stop = False
    stop_el = root.find("Stop")
    if stop_el is not None:
        text = (stop_el.text or "").strip().lower()
        if text in ("1", "true"):
            stop = True
        elif text not in ("0", "false", ""):
            raise SenError(f"Stop {stop_el.text!r} is not a BOOL")
    if any(v is not None and not math.isfinite(v) for v in ak):
        raise SenError("AK holds a non-finite number")
    return Sen(sen_type, ipoc, ak, stop)
