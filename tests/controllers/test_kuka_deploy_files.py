"""What the stand-in cannot see in the files a lab installs on the KR C4 (deploy/kuka).

The stand-in runs the program and loads the contexts (test_kuka_rsi_sim); these checks
are about the files as files: the single-byte code page and CRLF the controller's editors
use, the two context formats carrying the same signal flow and the same wires, and windows
wide enough for every robot the README names."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import pytest

from kuka_rsi_sim.machine import MACHINES
from tests.controllers.rsi_controller import DEPLOY

FILES = ["rob6_rsi.src", "rob6_rsi.dat", "rob6_rsi_ethernet.xml", "rob6_rsi.rsix", "rsi40/rob6_rsi.rsix",
         "rsi3/rob6_rsi.rsi", "rsi3/rob6_rsi.rsi.diagram", "rsi3/rob6_rsi.rsi.xml"]


@pytest.mark.parametrize("name", FILES)
def test_plain_ascii_with_crlf(name: str) -> None:
    data = (DEPLOY / name).read_bytes()
    data.decode("ascii")  # the KRL editor reads a single-byte code page
    assert b"\r\n" in data and b"\n" not in data.replace(b"\r\n", b""), name


def parameters(fmt: str) -> dict[str, dict[str, str]]:
    """object type -> parameter name -> value, of the .rsix (RSI 4.1), RSI 4.0's .rsix or the RSI 3.x .rsi.xml"""
    if fmt == "rsi40":
        objects = ET.parse(DEPLOY / "rsi40" / "rob6_rsi.rsix").getroot().iter("RsiObject")
        param_tag = "Parameter"
    elif fmt == "rsix":
        root = ET.parse(DEPLOY / "rob6_rsi.rsix").getroot()
        objects = root.iter("{RsiDriver}RsiObject")
        param_tag = "{RsiDriver}Parameter"
    else:
        root = ET.parse(DEPLOY / "rsi3" / "rob6_rsi.rsi.xml").getroot()
        objects = root.iter("RSIObject")
        param_tag = "Parameter"
    return {obj.attrib["ObjType"].upper(): {p.attrib["Name"]: p.attrib["ParamValue"] for p in obj.iter(param_tag)}
            for obj in objects}


@pytest.mark.parametrize("fmt", ["rsi3", "rsi40"])
def test_every_format_carries_the_same_signal_flow(fmt: str) -> None:
    rsix, other_fmt = parameters("rsix"), parameters(fmt)
    assert set(rsix) == set(other_fmt) == {"ETHERNET", "STOP", "AXISCORR", "AXISCORRMON"}
    for obj, params in rsix.items():
        assert set(params) == set(other_fmt[obj]), obj
        for name, value in params.items():
            other = other_fmt[obj][name]
            assert value == other or float(value) == float(other), (obj, name, value, other)


def wires(fmt: str) -> dict[tuple[str, int], str]:
    """(object type, input from 0) -> the RECEIVE element's TAG feeding it, in one format"""
    receive = {int(e.attrib["INDX"]): e.attrib["TAG"]
               for e in ET.parse(DEPLOY / "rob6_rsi_ethernet.xml").getroot().iter("ELEMENT")
               if e.attrib["INDX"] != "INTERNAL"}
    if fmt == "rsi40":
        objects, base = ET.parse(DEPLOY / "rsi40" / "rob6_rsi.rsix").getroot().iter("RsiObject"), 0
        input_tag, out_obj = "Input", "OutObjId"
    elif fmt == "rsix":
        objects, base = ET.parse(DEPLOY / "rob6_rsi.rsix").getroot().iter("{RsiDriver}RsiObject"), 0
        input_tag, out_obj = "{RsiDriver}Input", "OutObjId"
    else:
        objects, base = ET.parse(DEPLOY / "rsi3" / "rob6_rsi.rsi.xml").getroot().iter("RSIObject"), 1
        input_tag, out_obj = "Input", "OutObjID"
    out: dict[tuple[str, int], str] = {}
    for obj in objects:
        for i in obj.iter(input_tag):
            assert i.attrib[out_obj].upper().replace("_", "") == "ETHERNET1", i.attrib
            out[(obj.attrib["ObjType"].upper(), int(i.attrib["InIdx"]) - base)] = \
                receive[int(i.attrib["OutIdx"]) - base + 1]
    return out


@pytest.mark.parametrize("fmt", ["rsix", "rsi40", "rsi3"])
def test_each_format_wires_stop_to_stop_and_ak_an_to_axis_n(fmt: str) -> None:
    """The wires by name: the Stop element to the Stop object's input, AK.A<n> to AXISCORR's
    input of axis n, nothing else (an index slipped by one in either format shows here)."""
    expected = {("STOP", 0): "Stop", **{("AXISCORR", n): f"AK.A{n + 1}" for n in range(6)}}
    assert wires(fmt) == expected


def test_the_rsi40_editor_draws_the_wires_the_objects_have() -> None:
    """RSI 4.0's <Editor> (kuka_experimental PR #155) draws each wire as a Link from an
    Ethernet port Out<n> (1-based) to an input port (Stop: In1 as in RSIVisual's RSI 3.x model;
    AxisCorr: CorrA<n>): the drawing must show the wiring the objects run."""
    root = ET.parse(DEPLOY / "rsi40" / "rob6_rsi.rsix").getroot()
    ports = {"Stop": ["In1"], "AxisCorr": [f"CorrA{n}" for n in range(1, 7)]}
    inputs = {(o.attrib["ObjId"], ports[o.attrib["ObjType"]][int(i.attrib["InIdx"])]):
              (i.attrib["OutObjId"], f"Out{int(i.attrib['OutIdx']) + 1}")
              for o in root.iter("RsiObject") for i in o.iter("Input")}
    links = {(k.attrib["To"], k.attrib["ToPort"]): (k.attrib["From"], k.attrib["FromPort"]) for k in root.iter("Link")}
    assert links == inputs
    nodes = {n.attrib["Name"]: n.attrib["Type"] for n in root.iter("Node")}
    assert nodes == {o.attrib["ObjId"]: o.attrib["ObjType"] for o in root.iter("RsiObject")}


def test_every_correction_holds_its_value_when_an_answer_is_late() -> None:
    """HOLDON 1 on each AK element: with 0 a late answer drops that axis' correction to 0,
    a jump the controller stops with Command velocity (test_kuka_rsi_sim shows both)."""
    receive = ET.parse(DEPLOY / "rob6_rsi_ethernet.xml").getroot().find("RECEIVE")
    assert receive is not None
    holdon = {e.attrib["TAG"]: e.attrib.get("HOLDON") for e in receive.iter("ELEMENT")}
    assert {tag: holdon[tag] for tag in holdon if tag.startswith("AK.")} == {f"AK.A{n}": "1" for n in range(1, 7)}


@pytest.mark.parametrize("name", ["rsi3/rob6_rsi.rsi.xml", "rsi3/rob6_rsi.rsi"])
def test_the_rsi3_stop_object_carries_no_channel(name: str) -> None:
    """Channel is left out of the RSI 3.x files: rsi-pi (a KR 16-2, KSS 8.3, RSI 3.x) found a
    Channel parameter on its STOP object disabling every correction; kx's RSI 3.x files carry
    one. The evidence is contested, so the files keep the default the object has without it.
    The stand-in does not model Channel: this test is what sees it."""
    text = (DEPLOY / name).read_bytes().decode("ascii")
    assert not re.search(r'(?i)name="Channel"', text), name


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_windows_let_every_correction_inside_the_axis_range_pass(machine: str) -> None:
    """AXISCORR's and AXISCORRMON's windows are relative to ASPos, which may be anywhere in
    the range: each must span the range width, so that the software limit switches (the
    robot's machine data) limit the motion and not RSI."""
    m = MACHINES[machine]
    for fmt in ("rsix", "rsi40", "rsi3"):
        params = parameters(fmt)
        for n in range(6):
            width = m.upper[n] - m.lower[n]
            assert float(params["AXISCORR"][f"LowerLimA{n + 1}"]) <= -width, (fmt, n)
            assert float(params["AXISCORR"][f"UpperLimA{n + 1}"]) >= width, (fmt, n)
            assert float(params["AXISCORRMON"][f"MaxA{n + 1}"]) >= width, (fmt, n)


def test_the_readme_names_the_files_and_settings_it_ships() -> None:
    readme = (DEPLOY / "README.md").read_text()
    for name in FILES:
        assert f"`{name}`" in readme, name
    dat = (DEPLOY / "rob6_rsi.dat").read_bytes().decode("ascii")
    for setting in re.findall(r"^DECL \w+ (\w+)", dat, re.M):
        assert f"`{setting}" in readme, setting
