"""The files a lab installs on the KR C4 (deploy/kuka) agree with each other, with the
simulator that stands in for them, and with what the rob6 side expects.

No KR C4 in CI: these checks catch an edit that breaks the wiring (an index, a file name,
a window smaller than an axis range, a send element out of order)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from kuka_rsi_sim.machine import MACHINES

KUKA = Path(__file__).resolve().parents[2] / "deploy" / "kuka"
NS = {"c": "RsiContext", "d": "RsiDriver"}


@pytest.fixture(scope="module")
def ethernet() -> ET.Element:
    return ET.parse(KUKA / "rob6_rsi_ethernet.xml").getroot()


#: an RSI object of a signal-flow file: type, type id, parameters by name, inputs by index
#: (the object and output each comes from)
RsiObject = tuple[str, int, dict[str | None, ET.Element], dict[int, tuple[str | None, int]]]


def rsix_objects() -> dict[str | None, RsiObject]:
    root = ET.parse(KUKA / "rob6_rsi.rsix").getroot()
    assert root.tag == "{RsiContext}RsiContext"
    objects: dict[str | None, RsiObject] = {}
    for obj in root.iter("{RsiDriver}RsiObject"):
        params = {p.get("Name"): p for p in obj.iter("{RsiDriver}Parameter")}
        inputs = {int(i.attrib["InIdx"]): (i.get("OutObjId"), int(i.attrib["OutIdx"]))
                  for i in obj.iter("{RsiDriver}Input")}
        objects[obj.get("ObjId")] = (obj.attrib["ObjType"], int(obj.attrib["ObjTypeId"]), params, inputs)
    return objects


def rsi3_objects() -> dict[str | None, RsiObject]:
    root = ET.parse(KUKA / "rsi3" / "rob6_rsi.rsi.xml").getroot()
    objects: dict[str | None, RsiObject] = {}
    for obj in root.iter("RSIObject"):
        params = {p.get("Name"): p for p in obj.iter("Parameter")}
        inputs = {int(i.attrib["InIdx"]): (i.get("OutObjID"), int(i.attrib["OutIdx"])) for i in obj.iter("Input")}
        objects[obj.get("ObjID")] = (obj.attrib["ObjType"], int(obj.attrib["ObjTypeID"]), params, inputs)
    return objects


def _child(parent: ET.Element, tag: str) -> ET.Element:
    found = parent.find(tag)
    assert found is not None, f"no <{tag}> in <{parent.tag}>"
    return found


def _text(parent: ET.Element, tag: str) -> str:
    return (_child(parent, tag).text or "").strip()


def test_ethernet_configuration(ethernet: ET.Element) -> None:
    cfg = _child(ethernet, "CONFIG")
    assert _text(cfg, "PORT") == "49152"
    assert _text(cfg, "SENTYPE") == "ImFree"
    assert _text(cfg, "ONLYSEND").upper() == "FALSE"
    assert re.fullmatch(r"\d+\.\d+\.\d+\.\d+", _text(cfg, "IP_NUMBER"))
    sent = [e.get("TAG") for e in _child(ethernet, "SEND").iter("ELEMENT")]
    # the order of the simulator's packet (and of a KR C4's: the SEND order), IPOC appended
    assert sent == ["DEF_RIst", "DEF_RSol", "DEF_AIPos", "DEF_ASPos", "DEF_Delay"]
    received = {e.get("TAG"): e for e in _child(ethernet, "RECEIVE").iter("ELEMENT")}
    assert received["Stop"].get("TYPE") == "BOOL" and received["Stop"].get("HOLDON") == "0"
    for n in range(1, 7):
        e = received[f"AK.A{n}"]
        assert e.get("TYPE") == "DOUBLE" and e.get("HOLDON") == "1"  # late answer: hold


@pytest.mark.parametrize("fmt", ["rsix", "rsi3"])
def test_signal_flow_wiring(ethernet: ET.Element, fmt: str) -> None:
    objects = rsix_objects() if fmt == "rsix" else rsi3_objects()
    base = 0 if fmt == "rsix" else 1  # RSI 4.x counts from 0, RSI 3.x from 1
    by_type = {t.upper(): (oid, tid, params, inputs) for oid, (t, tid, params, inputs) in objects.items()}
    assert set(by_type) == {"ETHERNET", "STOP", "AXISCORR", "AXISCORRMON"}
    eth_id, tid, params, _ = by_type["ETHERNET"]
    assert tid == 64 and params["ConfigFile"].get("ParamValue") == "rob6_rsi_ethernet.xml"
    assert params["ConfigFile"].get("IsRuntime") == "false"
    assert params["Timeout"].get("ParamValue") == "100" and params["Precision"].get("ParamValue") == "4"
    # ETHERNET output k carries the RECEIVE element with INDX k (RSI 3.x) / k + 1 (RSI 4.x)
    indx = {int(e.attrib["INDX"]): e.get("TAG") for e in _child(ethernet, "RECEIVE").iter("ELEMENT")}
    out_tag = {k - 1 + base: tag for k, tag in indx.items()}
    _, tid, params, inputs = by_type["STOP"]
    assert tid == 18 and params["Mode"].get("ParamValue") == "4"  # leave RSI_MOVECORR
    assert inputs == {base: (eth_id, next(k for k, t in out_tag.items() if t == "Stop"))}
    _, tid, params, inputs = by_type["AXISCORR"]
    assert tid == 33
    for n in range(1, 7):
        src_obj, src_out = inputs[n - 1 + base]
        assert src_obj == eth_id and out_tag[src_out] == f"AK.A{n}"
    _, tid, mon, _ = by_type["AXISCORRMON"]
    assert tid == 82
    for n in range(1, 7):
        lo = float(params[f"LowerLimA{n}"].attrib["ParamValue"])
        hi = float(params[f"UpperLimA{n}"].attrib["ParamValue"])
        mx = float(mon[f"MaxA{n}"].attrib["ParamValue"])
        for machine in MACHINES.values():  # any correction inside the axis range, from any start
            width = machine.upper[n - 1] - machine.lower[n - 1]
            assert lo <= -width and hi >= width and mx >= width, (fmt, n, machine.name)
    # parameter ids: 0-based and contiguous in RSI 4.x; RSI 3.x keeps 7..12 for external axes
    upper_a1 = int(params["UpperLimA1"].attrib["ParamId" if fmt == "rsix" else "ParamID"])
    assert upper_a1 == (6 if fmt == "rsix" else 13)


def test_krl_program() -> None:
    src_bytes = (KUKA / "rob6_rsi.src").read_bytes()
    dat_bytes = (KUKA / "rob6_rsi.dat").read_bytes()
    for text in (src_bytes, dat_bytes):
        text.decode("ascii")  # the KRL editor reads a single-byte code page
        assert b"\r\n" in text and b"\n" not in text.replace(b"\r\n", b"")
    src, dat = src_bytes.decode(), dat_bytes.decode()
    assert re.search(r"^DEF rob6_rsi\( \)", src, re.M) and re.search(r"^DEFDAT rob6_rsi\b", dat, re.M)
    assert src.rstrip().endswith("END") and dat.rstrip().endswith("ENDDAT")
    code = "\n".join(line.split(";")[0] for line in src.splitlines())  # without comments
    order = [code.index(s) for s in ("PTP rob6Start", "RSI_CREATE(rob6Context[]", "LOOP",
                                     "RSI_ON(#ABSOLUTE, #IPO_FAST)", "RSI_ON(#ABSOLUTE, #IPO)",
                                     "RSI_MOVECORR()", "RSI_OFF()", "ENDLOOP")]
    assert order == sorted(order)
    assert code.count("IF (ret <> RSIOK) THEN") == 3  # RSI_CREATE, RSI_ON, RSI_OFF checked
    context_decl = re.search(r'rob6Context\[\]="([^"]+)"', dat)
    assert context_decl is not None
    context = context_decl.group(1)
    assert (KUKA / f"{context}.rsix").is_file()  # RSI 4.x: RSI_CREATE appends .rsix
    start = re.search(r"DECL E6AXIS rob6Start=\{A1 ([-\d.]+),A2 ([-\d.]+),A3 ([-\d.]+),"
                      r"A4 ([-\d.]+),A5 ([-\d.]+),A6 ([-\d.]+)", dat)
    assert start is not None
    pose = [float(v) for v in start.groups()]
    for machine in MACHINES.values():
        assert all(lo < q < hi for q, lo, hi in zip(pose, machine.lower, machine.upper, strict=True)), machine.name
