"""deploy/kawasaki/rob6.as against what rob6 and the simulator assume of it: the four programs,
their blocks closed, every GOTO target present, the AS instructions the README names, the
globals (port, queue size, the FS03N's ranges and rated speeds) equal to the link's and the
simulator's values, the answer codes and the 120-character line limit as PROTOCOL.md says.
A check of the text, not of AS semantics: the program is tested against rob6's simulator
only (README)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from kawasaki_as_sim import arm
from rob6_driver.links import kawasaki, kawasaki_codec

ROOT = Path(__file__).resolve().parents[2]
SOURCE = (ROOT / "deploy/kawasaki/rob6.as").read_text()
PROTOCOL = (ROOT / "deploy/kawasaki/PROTOCOL.md").read_text()


def programs() -> dict[str, list[str]]:
    """Program name -> its lines (comments and blank lines removed)."""
    out: dict[str, list[str]] = {}
    current = None
    for raw in SOURCE.splitlines():
        line = raw.split(";", 1)[0].strip() if not raw.strip().startswith('$') else raw.strip()
        if not line:
            continue
        if m := re.fullmatch(r"\.PROGRAM (\w+)\(\)", line):
            assert current is None, f"{m.group(1)} starts inside {current}"
            current = m.group(1)
            out[current] = []
        elif line == ".END":
            assert current is not None, ".END outside a program"
            current = None
        else:
            assert current is not None, f"a line outside every program: {line!r}"
            out[current].append(line)
    assert current is None, f"{current} has no .END"
    return out


def test_the_four_programs_and_their_blocks() -> None:
    progs = programs()
    assert sorted(progs) == ["rob6_init", "rob6_line", "rob6_motion", "rob6_pc", "rob6_state"]
    for name, lines in progs.items():
        depth = 0
        for line in lines:
            if re.match(r"(IF .* THEN|FOR .*)$", line):
                depth += 1
            elif line == "END":
                depth -= 1
                assert depth >= 0, f"{name}: END without IF/FOR"
        assert depth == 0, f"{name}: {depth} blocks not closed"
        labels = {line for line in lines if line.isdigit()}
        for target in re.findall(r"GOTO (\d+)", "\n".join(lines)):
            assert target in labels, f"{name}: GOTO {target} has no label"


def test_the_instructions_the_readme_names() -> None:
    for word in ("TCP_LISTEN", "TCP_ACCEPT", "TCP_RECV", "TCP_SEND", "TCP_CLOSE", "$DECODE", "$MID", "VAL(",
                 "JMOVE #PPOINT(", "ACCURACY", "CP ON", "SPEED", "BREAK", "HERE", "DECOMPOSE", "TWAIT"):
        assert word in SOURCE, word
    readme = (ROOT / "deploy/kawasaki/README.md").read_text()
    for word in ("LOAD rob6.as", "PCEXECUTE 1: rob6_pc", "PCEXECUTE 2: rob6_state", "EXECUTE rob6_motion",
                 "TCP/IP option", "TCP_END_LISTEN", "not yet on a real\n> controller", "Teach mode"):
        assert word in readme, word


def _globals() -> dict[str, float]:
    values = {}
    for line in programs()["rob6_init"]:
        if m := re.fullmatch(r"(\w+(?:\[\d\])?) = (-?[\d.]+)", line):
            values[m.group(1)] = float(m.group(2))
    return values


def test_the_globals_are_what_the_link_and_the_simulator_assume() -> None:
    g = _globals()
    assert g["kport"] == kawasaki.DEFAULT_PORT == 49200
    assert g["kcap"] == 64  # the simulator's default --capacity
    assert g["kstart"] == arm.START_POINTS == 3
    for j in range(6):
        assert g[f"kmin[{j + 1}]"] == kawasaki_codec.CONTROLLER_MIN_DEG[j] == arm.RANGE_MIN[j]
        assert g[f"kmax[{j + 1}]"] == kawasaki_codec.CONTROLLER_MAX_DEG[j] == arm.RANGE_MAX[j]
        assert g[f"krated[{j + 1}]"] == kawasaki_codec.RATED_SPEED_DEG_S[j] == arm.RATED_SPEED[j]
    assert "* 1.05" in SOURCE and arm.SPEED_TOLERANCE == 1.05


def test_the_protocol_document_and_the_codes() -> None:
    for code, meaning in kawasaki_codec.ACK_CODES.items():
        assert f"`{code}` " in PROTOCOL, (code, meaning)
    assert "at most **120 characters**" in PROTOCOL and kawasaki_codec.MAX_LINE == 120
    assert "LEN($kbuf) > 120" in SOURCE
    for code in range(7):
        assert re.search(rf"kcode = {code}\b", SOURCE) or code == 1, code  # 1 is the default


@pytest.mark.parametrize("q", [[0, 0, 0, 0, 0, 0], [-159.999, -60, 119.999, -359.999, -134.999, 359.999]])
def test_the_longest_point_fits_a_line(q: list[float]) -> None:
    line = kawasaki_codec.point(999_999, np.array(q, float), 99.999, True)
    assert len(line) <= kawasaki_codec.MAX_LINE
