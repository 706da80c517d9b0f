"""The ETHERNET object's configuration file: where the controller sends, what, and what it reads back.

The file (``SensorInterface/<ConfigFile>``, e.g. ``rob6_rsi_ethernet.xml``) is read as the
controller reads it: ``<ROOT>`` with ``<CONFIG>`` (IP_NUMBER, PORT, SENTYPE, ONLYSEND),
``<SEND>`` and ``<RECEIVE>``, each a list of ``<ELEMENT TAG TYPE INDX [HOLDON]/>``.
Anything else (an unknown element or attribute, ``Type`` for ``TYPE``, a type that is
not BOOL, STRING, LONG or DOUBLE, an index out of 1..64) is a configuration error, which
makes ``RSI_CREATE`` fail. A RECEIVE element with ``INDX="INTERNAL"`` (``DEF_EStr``, a text
for the smartHMI, ``DEF_Tech.T..``) feeds no ETHERNET output: it is accepted and not
modelled. Sources: controllers/kuka_rsi/README.md.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

TYPES = ("BOOL", "STRING", "LONG", "DOUBLE")
MAX_CHANNELS = 64
CONFIG_TAGS = ("IP_NUMBER", "PORT", "SENTYPE", "ONLYSEND")
#: the values the controller fills in itself (INDX="INTERNAL"), as the stand-in models them
INTERNAL = {"DEF_RIst": "RIst", "DEF_RSol": "RSol", "DEF_AIPos": "AIPos", "DEF_ASPos": "ASPos",
            "DEF_EIPos": "EIPos", "DEF_Delay": "Delay"}
ELEMENT_ATTRIBUTES = {"SEND": {"TAG", "TYPE", "INDX", "HOLDON"}, "RECEIVE": {"TAG", "TYPE", "INDX", "HOLDON"}}


class ConfigError(ValueError):
    """The configuration file cannot be used (the message says why)."""


@dataclass(frozen=True)
class Received:
    """One RECEIVE element: ``tag`` is ``Elem`` (its text) or ``Elem.Attr`` (an attribute)."""

    tag: str
    type: str
    indx: int  # the ETHERNET object's output it feeds, 1-based as in the file
    holdon: bool  # a late answer keeps the last value (else the output drops to 0)

    @property
    def element(self) -> str:
        return self.tag.split(".", 1)[0]

    @property
    def attribute(self) -> str | None:
        _, dot, attr = self.tag.partition(".")
        return attr if dot else None


@dataclass(frozen=True)
class EthernetConfig:
    ip_number: str
    port: int
    sentype: str
    only_send: bool
    send: tuple[str, ...]  # the internal values sent, in the file's order (RIst, AIPos, ...)
    receive: tuple[Received, ...]  # the elements feeding the ETHERNET object's outputs
    receive_internal: tuple[str, ...] = ()  # RECEIVE tags with INDX="INTERNAL" (not modelled)

    def output(self, indx: int) -> Received | None:
        """The RECEIVE element on output ``indx`` (1-based), if any."""
        return next((r for r in self.receive if r.indx == indx), None)


def load_ethernet(path: Path) -> EthernetConfig:
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise ConfigError(f"configuration file {path.name} not found") from None
    except ET.ParseError as e:
        raise ConfigError(f"{path.name} is not well-formed XML: {e}") from None
    if root.tag != "ROOT":
        raise ConfigError(f"{path.name}: root element <{root.tag}>, expected <ROOT>")
    sections = {child.tag: child for child in root}
    unknown = sorted(set(sections) - {"CONFIG", "SEND", "RECEIVE"})
    if unknown:
        raise ConfigError(f"{path.name}: unknown element(s) {unknown} in <ROOT>")
    if "CONFIG" not in sections:
        raise ConfigError(f"{path.name}: no <CONFIG>")
    config = _config(sections["CONFIG"], path.name)
    send = _send(sections.get("SEND"), path.name)
    receive, internal = _receive(sections.get("RECEIVE"), path.name)
    return EthernetConfig(config["IP_NUMBER"], _int(config["PORT"], "PORT", path.name), config["SENTYPE"],
                          _bool(config["ONLYSEND"], "ONLYSEND", path.name), send, receive, internal)


def _config(section: ET.Element, name: str) -> dict[str, str]:
    values: dict[str, str] = {}
    for child in section:
        if child.tag not in CONFIG_TAGS:
            raise ConfigError(f"{name}: unknown <CONFIG> element <{child.tag}>; expected {list(CONFIG_TAGS)}")
        values[child.tag] = (child.text or "").strip()
    missing = [t for t in CONFIG_TAGS if t not in values]
    if missing:
        raise ConfigError(f"{name}: <CONFIG> lacks {missing}")
    return values


def _elements(section: ET.Element | None, kind: str, name: str) -> list[dict[str, str]]:
    if section is None:
        return []
    wrappers = list(section)
    if len(wrappers) != 1 or wrappers[0].tag != "ELEMENTS":
        raise ConfigError(f"{name}: <{kind}> must hold one <ELEMENTS>")
    out = []
    for element in wrappers[0]:
        if element.tag != "ELEMENT":
            raise ConfigError(f"{name}: unknown element <{element.tag}> in <{kind}><ELEMENTS>")
        unknown = sorted(set(element.attrib) - ELEMENT_ATTRIBUTES[kind])
        if unknown:
            raise ConfigError(f"{name}: <{kind}> ELEMENT {element.get('TAG')!r} has unknown attribute(s) "
                              f"{unknown}; expected {sorted(ELEMENT_ATTRIBUTES[kind])}")
        for required in ("TAG", "TYPE", "INDX"):
            if required not in element.attrib:
                raise ConfigError(f"{name}: <{kind}> ELEMENT {element.get('TAG')!r} lacks {required}")
        if element.attrib["TYPE"] not in TYPES:
            raise ConfigError(f"{name}: <{kind}> ELEMENT {element.attrib['TAG']!r}: TYPE "
                              f"{element.attrib['TYPE']!r} is not one of {list(TYPES)}")
        out.append(dict(element.attrib))
    return out


def _send(section: ET.Element | None, name: str) -> tuple[str, ...]:
    sent = []
    for e in _elements(section, "SEND", name):
        tag = e["TAG"]
        if e["INDX"] != "INTERNAL" or tag not in INTERNAL:
            raise ConfigError(f"{name}: SEND element {tag!r} (INDX {e['INDX']}): the stand-in sends only the "
                              f"internal values {sorted(INTERNAL)} (INDX=\"INTERNAL\")")
        expected = "LONG" if tag == "DEF_Delay" else "DOUBLE"
        if e["TYPE"] != expected:
            raise ConfigError(f"{name}: SEND element {tag} must be TYPE {expected}, not {e['TYPE']}")
        if INTERNAL[tag] in sent:
            raise ConfigError(f"{name}: SEND element {tag} appears twice")
        sent.append(INTERNAL[tag])
    return tuple(sent)


def _receive(section: ET.Element | None, name: str) -> tuple[tuple[Received, ...], tuple[str, ...]]:
    received: list[Received] = []
    internal: list[str] = []
    for e in _elements(section, "RECEIVE", name):
        if e["INDX"] == "INTERNAL":
            if not e["TAG"].startswith("DEF_") or e["TAG"] in internal:
                raise ConfigError(f"{name}: RECEIVE element {e['TAG']!r} with INDX INTERNAL: only a DEF_ value, "
                                  f"once")
            internal.append(e["TAG"])
            continue
        indx = _int(e["INDX"], f"INDX of {e['TAG']}", name)
        if not 1 <= indx <= MAX_CHANNELS:
            raise ConfigError(f"{name}: RECEIVE element {e['TAG']}: INDX {indx} is outside 1..{MAX_CHANNELS}")
        holdon = e.get("HOLDON", "0")
        if holdon not in ("0", "1"):
            raise ConfigError(f"{name}: RECEIVE element {e['TAG']}: HOLDON {holdon!r} is not 0 or 1")
        r = Received(e["TAG"], e["TYPE"], indx, holdon == "1")
        if any(x.indx == indx for x in received):
            raise ConfigError(f"{name}: two RECEIVE elements on INDX {indx}")
        if any(x.tag == r.tag for x in received):
            raise ConfigError(f"{name}: RECEIVE element {r.tag} appears twice")
        received.append(r)
    return tuple(received), tuple(internal)


def _int(text: str, what: str, name: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ConfigError(f"{name}: {what} {text!r} is not an integer") from None


def _bool(text: str, what: str, name: str) -> bool:
    if text.upper() not in ("TRUE", "FALSE"):
        raise ConfigError(f"{name}: {what} {text!r} is not TRUE or FALSE")
    return text.upper() == "TRUE"
