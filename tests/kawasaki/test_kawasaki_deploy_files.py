"""deploy/kawasaki against what rob6 and the stand-in assume of it: rob6.as loads as the
controller loads it (the stand-in's parser: programs, blocks, labels, instructions and
argument counts), its globals (port, queue size, the FS03N's ranges and rated speeds) equal
the link's and the stand-in's, every AS word it uses has its source in REFERENCES.md, the
answer codes and the 120-character line limit are PROTOCOL.md's, the README's steps are
there. What the program does is tested by executing it (tests/controllers, tests/kawasaki)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from kawasaki_as_sim import arm
from kawasaki_as_sim.aslang import FUNCTIONS, INSTRUCTIONS, load
from rob6_driver.links import kawasaki, kawasaki_codec

ROOT = Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy/kawasaki"
SOURCE = (DEPLOY / "rob6.as").read_text()
PROTOCOL = (DEPLOY / "PROTOCOL.md").read_text()
REFERENCES = (DEPLOY / "REFERENCES.md").read_text()


def test_the_programs_load() -> None:
    programs = load(SOURCE)
    assert sorted(programs) == ["rob6_line", "rob6_motion", "rob6_pc", "rob6_state"]


def _words() -> set[str]:
    """The AS instructions, functions and switches rob6.as uses."""
    code = "\n".join(line.split(";", 1)[0] for line in SOURCE.splitlines())
    code = re.sub(r'"[^"]*"', '""', code)
    used = {w.lower() for w in re.findall(r"[$#]?[A-Za-z_][A-Za-z0-9_]*", code)}
    known = set(INSTRUCTIONS) | set(FUNCTIONS) | {"decompose", "if", "then", "else", "end", "goto", "call",
                                                  "return", "halt", "print", "for", "to", "and", "or", "not",
                                                  "mod", "power", "repeat", "always", "fine", "s", "program"}
    return used & known


def test_every_construct_has_its_source_in_references() -> None:
    for word in sorted(_words()):
        assert re.search(rf"`[^`]*{re.escape(word.upper())}\b", REFERENCES), f"{word.upper()} not in REFERENCES.md"
    for fact in ("-34024", "-34025", "E0102", "8192", "255", "4096", "TRUE"):
        assert fact in REFERENCES, fact


def test_the_steps_the_readme_names() -> None:
    readme = (DEPLOY / "README.md").read_text()
    for word in ("USB_LOAD", "PCEXECUTE 1: rob6_pc", "EXECUTE rob6_motion", "DO TCP_END_LISTEN", "E4054",
                 "TCP/IP option", "not yet on a real\n> controller", "Teach mode", "10 %"):
        assert word in readme, word


def _globals() -> dict[str, float]:
    values = {}
    for line in SOURCE.split(".PROGRAM rob6_pc()", 1)[1].split(".END", 1)[0].splitlines():
        if m := re.fullmatch(r"\s*(\w+(?:\[\d\])?) = (-?[\d.]+)", line):
            values[m.group(1)] = float(m.group(2))
    return values


def test_the_globals_are_what_the_link_and_the_stand_in_assume() -> None:
    g = _globals()
    assert g["kport"] == kawasaki.DEFAULT_PORT == 49200
    assert g["kcap"] == 64 and g["kstart"] == 3
    for j in range(6):
        assert g[f"kmin[{j + 1}]"] == kawasaki_codec.CONTROLLER_MIN_DEG[j] == arm.RANGE_MIN[j]
        assert g[f"kmax[{j + 1}]"] == kawasaki_codec.CONTROLLER_MAX_DEG[j] == arm.RANGE_MAX[j]
        assert g[f"krated[{j + 1}]"] == kawasaki_codec.RATED_SPEED_DEG_S[j] == arm.RATED_SPEED[j]


def test_the_protocol_document_and_the_codes() -> None:
    for code in kawasaki_codec.ACK_CODES:
        assert f"`{code}` " in PROTOCOL, code
        assert re.search(rf"\.code = {code}\b", SOURCE), code
    assert "at most **120 characters**" in PROTOCOL and kawasaki_codec.MAX_LINE == 120
    assert f"H rob6-kas {kawasaki_codec.VERSION} " in SOURCE and "LEN(.$line) > 119" in SOURCE


@pytest.mark.parametrize("q", [[0, 0, 0, 0, 0, 0], [-159.999, -60, 119.999, -359.999, -134.999, 359.999]])
def test_the_longest_point_fits_a_line(q: list[float]) -> None:
    line = kawasaki_codec.point(999_999, np.array(q, float), 99.999, True)
    assert len(line) <= kawasaki_codec.MAX_LINE
