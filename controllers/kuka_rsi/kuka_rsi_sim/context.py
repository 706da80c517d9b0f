"""RSI contexts (signal flows) as each RSI generation stores them, loaded the way RSI_CREATE does.

* RSI 3.x (KSS 8.3, 8.4): ``RSI_CREATE("<name>.rsi")`` needs the three files RSIVisual writes:
  ``<name>.rsi`` (the diagram model), ``<name>.rsi.diagram`` (its layout) and
  ``<name>.rsi.xml`` (the objects the controller runs: ``<RSIObjects>``, ``ObjTypeID``,
  ``ObjID``, ``ParamID``, indices from 1).
* RSI 4.1 and 5.x (KSS 8.6, 8.7): ``RSI_CREATE("<name>")`` loads ``<name>.rsix``
  (``<RsiContext SchemaVersion="2.0.0">``, ``ObjTypeId``, ``ObjId``, ``ParamId``, indices from 0).
* RSI 4.0 (KSS 8.5): ``RSI_CREATE("<name>")`` loads ``<name>.rsix`` too, in its own format
  (kuka_experimental PR #155, "RobotSensorInterface 4.0 B3083", tested on KSS 8.5):
  ``<RsiContext Version="0.1.0">`` and ``<RsiObjects>`` with no namespace, the 4.1 names
  (``ObjTypeId``, ``ObjId``, ``ParamId``, indices from 0) and no ``IsPublic``, and an
  ``<Editor>`` section whose ``Node`` elements name each object. Each format is refused by
  the other generation.

A file of another generation's format, an attribute or a parameter that no reference file
shows, or an object the stand-in does not model makes RSI_CREATE fail (``ContextError``).
The signal flow the stand-in runs is ``ETHERNET -> STOP`` and ``ETHERNET -> AXISCORR``
with ``AXISCORRMON``; see controllers/kuka_rsi/README.md for each rule's source.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from .ethernet import ConfigError, EthernetConfig, load_ethernet

#: the RSI generation each KSS release runs
KSS_RSI = {"8.3": "3", "8.4": "3", "8.5": "4.0", "8.6": "4.1", "8.7": "5.0"}
RSI_NAMES = {"3": "RSI 3.x", "4.0": "RSI 4.0", "4.1": "RSI 4.1", "5.0": "RSI 5.x"}

# the parameters of each modelled object type: name -> (RSI 3.x ParamID, RSI 4.1+ ParamId, default)
_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
PARAMETERS: dict[int, dict[str, tuple[int, int, str | None]]] = {
    64: {"ConfigFile": (1, 0, None), "Timeout": (1, 0, "10"), "Flag": (4, 3, "-1"), "Precision": (8, 7, "1")},
    18: {"Mode": (1, 0, "4"), "Channel": (2, 1, "0")},
    33: {**{f"LowerLim{a}": (1 + n, n, "-5") for n, a in enumerate(_AXES)},
         **{f"UpperLim{a}": (13 + n, 6 + n, "5") for n, a in enumerate(_AXES)}},
    82: {**{f"Max{a}": (1 + n, n, "6") for n, a in enumerate(_AXES)},
         **{f"MaxE{n + 1}": (7 + n, 6 + n, "6") for n in range(6)}},
}
#: the inputs of each object type, as RSI_CREATE checks them: an Input's InIdx must be one of
#: them (counted from the format's base), each used once. STOP: its one input; AXISCORR:
#: CorrA1..CorrA6. ETHERNET's inputs (values sent with INDX n) and AXISCORRMON's are not
#: modelled: the stand-in refuses them.
INPUTS = {64: 0, 18: 1, 33: 6, 82: 0}
#: the overall correction RSI allows per axis when the context has no AXISCORRMON
DEFAULT_OVERALL_LIMIT = 6.0
TYPE_NAMES = {"3": {64: "ETHERNET", 18: "STOP", 33: "AXISCORR", 82: "AXISCORRMON"},
              "4": {64: "Ethernet", 18: "Stop", 33: "AxisCorr", 82: "AxisCorrMon"}}
#: the attributes each element carries in the reference files of a generation's format
ATTRIBUTES = {
    "3": {"RSIObject": {"ObjType", "ObjTypeID", "ObjID"}, "Input": {"InIdx", "OutObjID", "OutIdx"},
          "Parameter": {"Name", "ParamID", "ParamValue", "IsRuntime"}},
    "4": {"RsiObject": {"ObjTypeId", "ObjType", "ObjId"}, "Input": {"InIdx", "OutObjId", "OutIdx"},
          "Parameter": {"IsRuntime", "IsPublic", "Name", "ParamId", "ParamValue"}},
    "4.0": {"RsiObject": {"ObjTypeId", "ObjType", "ObjId"}, "Input": {"InIdx", "OutObjId", "OutIdx"},
            "Parameter": {"IsRuntime", "Name", "ParamId", "ParamValue"}},
}
TYPE_NAMES["4.0"] = TYPE_NAMES["4"]
#: the Version of an RSI 4.0 context (kuka_experimental PR #155)
RSIX40_VERSION = "0.1.0"
#: the sections of an RSI 4.0 context's <Editor> (kuka_experimental PR #155)
RSIX40_EDITOR = {"Comments", "Connectors", "FunctionBlocks", "Groups", "Links", "Nodes", "Toolboxes"}
STOP_EXIT_MOVECORR = 4  # the Stop object's Mode ExitMoveCorr: RSI_MOVECORR returns
RSI3_MODEL_NS = "{http://schemas.microsoft.com/dsltools/RSIVisual}"
RSIX_NS, RSIX_DRIVER = "{RsiContext}", "{RsiDriver}"
RSIX_SCHEMA = "2.0.0"


class ContextError(ValueError):
    """RSI_CREATE cannot load the context (the message says why)."""


@dataclass(frozen=True)
class SignalFlow:
    """What the loaded context makes the controller do each cycle."""

    ethernet_id: str
    ethernet: EthernetConfig
    timeout: int  # late packets of a run before the ETHERNET object stops RSI
    precision: int  # decimals of the numbers sent
    stop_output: int | None  # the ETHERNET output (1-based) feeding the Stop object (None: no Stop)
    corr_outputs: tuple[int | None, ...]  # per axis, the ETHERNET output feeding AXISCORR (None: 0)
    lower: tuple[float, ...]  # AXISCORR: each axis' correction is clamped to lower..upper
    upper: tuple[float, ...]
    monitor: tuple[float, ...]  # |overall correction| above this stops RSI (AXISCORRMON, else the default)
    monitor_object: str | None  # the AXISCORRMON object's id (None: the default monitor)


@dataclass
class _Object:
    obj_id: str
    type_id: int
    params: dict[str, str]  # name -> value
    inputs: dict[int, tuple[str, int]]  # input index (0-based) -> (object id, output index, 0-based)
    given: set[str]  # the parameters the file sets (the others have their default)


def generation(kss: str) -> str:
    if kss not in KSS_RSI:
        raise ValueError(f"KSS {kss!r}: the stand-in models KSS {', '.join(sorted(KSS_RSI))}")
    return KSS_RSI[kss]


def load_context(name: str, sensor_dir: Path, gen: str) -> SignalFlow:
    """RSI_CREATE(name) on a controller running RSI generation ``gen``."""
    if gen == "3":
        objects = _load_rsi3(name, sensor_dir)
        base, family = 1, "3"
    elif gen == "4.0":
        objects = _load_rsix40(name, sensor_dir)
        base, family = 0, "4.0"
    else:
        objects = _load_rsix(name, sensor_dir)
        base, family = 0, "4"
    return _signal_flow(objects, base, family, sensor_dir)


def _load_rsi3(name: str, sensor_dir: Path) -> dict[str, _Object]:
    if not name.endswith(".rsi"):
        raise ContextError(f"context {name!r}: RSI 3.x loads <name>.rsi (RSI_CREATE(\"{name}.rsi\")); "
                           f"{name}.rsix is the format of RSI 4.1 and later")
    for suffix in ("", ".diagram", ".xml"):
        if not (sensor_dir / f"{name}{suffix}").is_file():
            raise ContextError(f"context {name}: {name}{suffix} not found in SensorInterface "
                               f"(RSIVisual writes {name}, {name}.diagram and {name}.xml)")
    root = _parse(sensor_dir / f"{name}.xml")
    if root.tag != "RSIObjects":
        raise ContextError(f"{name}.xml: root <{root.tag}>, expected <RSIObjects> (RSI 3.x)")
    objects = {}
    for element in root:
        if element.tag != "RSIObject":
            raise ContextError(f"{name}.xml: unknown element <{element.tag}>")
        obj = _object(element, "3", f"{name}.xml", "ObjTypeID", "ObjID", "ParamID", "OutObjID", "")
        objects[obj.obj_id] = obj
    _check_rsi3_model(name, sensor_dir, objects)
    return objects


def _check_rsi3_model(name: str, sensor_dir: Path, objects: dict[str, _Object]) -> None:
    """The diagram model and its layout describe the same objects as the .rsi.xml."""
    model = _parse(sensor_dir / name)
    if model.tag != f"{RSI3_MODEL_NS}rSIModel":
        raise ContextError(f"{name}: root <{model.tag}>, expected RSIVisual's <rSIModel>")
    elements = {e.get("name"): e for e in model.iter(f"{RSI3_MODEL_NS}rSIElement")}
    if set(elements) != set(objects):
        raise ContextError(f"{name} and {name}.xml name different objects: {sorted(map(str, elements))} "
                           f"vs {sorted(objects)}")
    for obj_id, element in elements.items():
        obj = objects[str(obj_id)]
        if element.get("objTypeID") != str(obj.type_id):
            raise ContextError(f"{name}: {obj_id} has objTypeID {element.get('objTypeID')}, "
                               f"{name}.xml {obj.type_id}")
        values = {p.get("name"): p.get("value") for p in element.iter(f"{RSI3_MODEL_NS}rSIParameter")}
        for pname in obj.given:
            value = obj.params[pname]
            if pname == "Mode":  # the model names the enum (ExitMoveCorr), the .xml its number
                continue
            if pname not in values or _same_value(values[pname], value) is False:
                raise ContextError(f"{name}: {obj_id}.{pname} is {values.get(pname)!r} there, "
                                   f"{value!r} in {name}.xml: save the diagram again in RSIVisual")
    diagram = _parse(sensor_dir / f"{name}.diagram")
    if diagram.tag != "rSIObjectDiagram":
        raise ContextError(f"{name}.diagram: root <{diagram.tag}>, expected <rSIObjectDiagram>")
    shapes = {m.get("name") for m in diagram.iter("rSIElementMoniker")}
    missing = sorted(f"//{o}" for o in objects if f"//{o}" not in shapes)
    if missing:
        raise ContextError(f"{name}.diagram has no shape for {missing}")


def _same_value(a: str | None, b: str) -> bool:
    try:
        return a is not None and float(a) == float(b)
    except ValueError:
        return a == b


def _load_rsix(name: str, sensor_dir: Path) -> dict[str, _Object]:
    path = sensor_dir / f"{name}.rsix"
    if not path.is_file():
        hint = " (RSI 4.1 and later load <name>.rsix: RSI_CREATE(\"rob6_rsi\"), not \"rob6_rsi.rsi\")" \
            if name.endswith(".rsi") else ""
        raise ContextError(f"context {name}: {path.name} not found in SensorInterface{hint}")
    root = _parse(path)
    if root.tag == "RsiContext" and root.get("Version") is not None:
        raise ContextError(f"{path.name} is in RSI 4.0's format (Version {root.get('Version')!r}); RSI 4.1 and "
                           f"5.x read <RsiContext SchemaVersion=\"{RSIX_SCHEMA}\" xmlns=\"RsiContext\"> "
                           f"(deploy/kuka/README.md)")
    if root.tag != f"{RSIX_NS}RsiContext":
        raise ContextError(f"{path.name}: root <{root.tag}>, expected <RsiContext xmlns=\"RsiContext\">")
    if root.get("SchemaVersion") != RSIX_SCHEMA:
        raise ContextError(f"{path.name}: SchemaVersion {root.get('SchemaVersion')!r}, expected {RSIX_SCHEMA!r}")
    extra = sorted(set(root.attrib) - {"SchemaVersion", "{http://www.w3.org/2001/XMLSchema-instance}schemaLocation"})
    if extra:
        raise ContextError(f"{path.name}: <RsiContext> has unknown attribute(s) {extra}")
    lists = [c for c in root if c.tag == f"{RSIX_DRIVER}RsiObjects"]
    if len(lists) != 1:
        raise ContextError(f"{path.name}: expected one <RsiObjects xmlns=\"RsiDriver\">")
    objects = {}
    for element in lists[0]:
        if element.tag != f"{RSIX_DRIVER}RsiObject":
            raise ContextError(f"{path.name}: unknown element <{element.tag}> in <RsiObjects>")
        obj = _object(element, "4", path.name, "ObjTypeId", "ObjId", "ParamId", "OutObjId", RSIX_DRIVER)
        objects[obj.obj_id] = obj
    return objects


def _load_rsix40(name: str, sensor_dir: Path) -> dict[str, _Object]:
    path = sensor_dir / f"{name}.rsix"
    if not path.is_file():
        hint = " (RSI 4.0 loads <name>.rsix: RSI_CREATE(\"rob6_rsi\"), not \"rob6_rsi.rsi\")" \
            if name.endswith(".rsi") else ""
        raise ContextError(f"context {name}: {path.name} not found in SensorInterface{hint}")
    root = _parse(path)
    if root.tag == f"{RSIX_NS}RsiContext":
        raise ContextError(f"{path.name} is in RSI 4.1/5.x's format (SchemaVersion {root.get('SchemaVersion')!r}); "
                           f"RSI 4.0 reads <RsiContext Version=\"{RSIX40_VERSION}\"> with no namespace "
                           f"(deploy/kuka/rsi40)")
    if root.tag != "RsiContext":
        raise ContextError(f"{path.name}: root <{root.tag}>, expected <RsiContext Version=\"{RSIX40_VERSION}\">")
    if root.get("Version") != RSIX40_VERSION:
        raise ContextError(f"{path.name}: Version {root.get('Version')!r}, expected {RSIX40_VERSION!r}")
    extra = sorted(set(root.attrib) - {"Version"})
    if extra:
        raise ContextError(f"{path.name}: <RsiContext> has unknown attribute(s) {extra}")
    sections: dict[str, list[ET.Element]] = {}
    for child in root:
        if child.tag not in ("RsiObjects", "Editor"):
            raise ContextError(f"{path.name}: unknown element <{child.tag}> in <RsiContext>")
        sections.setdefault(child.tag, []).append(child)
    if len(sections.get("RsiObjects", [])) != 1 or len(sections.get("Editor", [])) > 1:
        raise ContextError(f"{path.name}: expected one <RsiObjects> and at most one <Editor>")
    objects = {}
    for element in sections["RsiObjects"][0]:
        if element.tag != "RsiObject":
            raise ContextError(f"{path.name}: unknown element <{element.tag}> in <RsiObjects>")
        obj = _object(element, "4.0", path.name, "ObjTypeId", "ObjId", "ParamId", "OutObjId", "")
        objects[obj.obj_id] = obj
    for editor in sections.get("Editor", []):
        unknown = sorted({c.tag for c in editor} - RSIX40_EDITOR)
        if unknown:
            raise ContextError(f"{path.name}: unknown element(s) {unknown} in <Editor>")
        nodes = {n.get("Name") for n in editor.iter("Node")}
        missing = sorted(o for o in objects if o not in nodes)
        if missing:
            raise ContextError(f"{path.name}: <Editor> has no Node for {missing}")
    return objects


def _parse(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as e:
        raise ContextError(f"{path.name} is not well-formed XML: {e}") from None


def _object(element: ET.Element, family: str, fname: str, type_attr: str, id_attr: str, param_attr: str,
            out_obj_attr: str, ns: str) -> _Object:
    allowed = ATTRIBUTES[family]
    tag = element.tag.removeprefix(ns)
    _attributes(element, allowed[tag], fname, tag)
    obj_id = element.get(id_attr, "")
    try:
        type_id = int(element.get(type_attr, ""))
    except ValueError:
        raise ContextError(f"{fname}: {obj_id}: {type_attr} {element.get(type_attr)!r} is not a number") from None
    if type_id not in PARAMETERS:
        raise ContextError(f"{fname}: {obj_id}: object type {element.get('ObjType')} ({type_id}) is not modelled "
                           f"by the stand-in (it runs ETHERNET, STOP, AXISCORR, AXISCORRMON)")
    if element.get("ObjType") != TYPE_NAMES[family][type_id]:
        raise ContextError(f"{fname}: {obj_id}: ObjType {element.get('ObjType')!r}; this format names type "
                           f"{type_id} {TYPE_NAMES[family][type_id]!r}")
    known = PARAMETERS[type_id]
    params: dict[str, str] = {}
    inputs: dict[int, tuple[str, int]] = {}
    for section in element:
        stag = section.tag.removeprefix(ns)
        if stag == "Parameters":
            for p in section:
                _attributes(p, allowed["Parameter"], fname, f"{obj_id} Parameter")
                pname = p.get("Name", "")
                if pname not in known:
                    raise ContextError(f"{fname}: {obj_id}: unknown parameter {pname!r}")
                pid = known[pname][0 if family == "3" else 1]
                if p.get(param_attr) != str(pid):
                    raise ContextError(f"{fname}: {obj_id}.{pname}: {param_attr} {p.get(param_attr)!r}, "
                                       f"expected {pid}")
                params[pname] = p.get("ParamValue", "")
        elif stag == "Inputs":
            base = 1 if family == "3" else 0
            for i in section:
                _attributes(i, allowed["Input"], fname, f"{obj_id} Input")
                try:
                    in_idx, out_idx = int(i.get("InIdx", "")) - base, int(i.get("OutIdx", "")) - base
                except ValueError:
                    raise ContextError(f"{fname}: {obj_id}: an Input's InIdx/OutIdx is not a number") from None
                if not 0 <= in_idx < INPUTS[type_id]:
                    have = f"{base}..{INPUTS[type_id] - 1 + base}" if INPUTS[type_id] else "none"
                    raise ContextError(f"{fname}: {obj_id}: Invalid index - signal input: InIdx {in_idx + base} "
                                       f"({TYPE_NAMES[family][type_id]} inputs: {have})")
                if in_idx in inputs:
                    raise ContextError(f"{fname}: {obj_id}: Invalid index - signal input: InIdx {in_idx + base} "
                                       f"is wired twice")
                inputs[in_idx] = (i.get(out_obj_attr, ""), out_idx)
        else:
            raise ContextError(f"{fname}: {obj_id}: unknown element <{stag}>")
    given = set(params)
    for pname, (_, _, default) in known.items():
        if pname not in params:
            if default is None:
                raise ContextError(f"{fname}: {obj_id}: parameter {pname} is missing")
            params[pname] = default
    return _Object(obj_id, type_id, params, inputs, given)


def _attributes(element: ET.Element, allowed: set[str], fname: str, what: str) -> None:
    unknown = sorted(set(element.attrib) - allowed)
    if unknown:
        raise ContextError(f"{fname}: {what} has attribute(s) {unknown} that no {fname.rsplit('.', 1)[-1]} "
                           f"file of this RSI generation has; expected {sorted(allowed)}")


def _signal_flow(objects: dict[str, _Object], base: int, family: str, sensor_dir: Path) -> SignalFlow:
    """The signal flow of the loaded objects; ``base`` is the format's first index (for messages)."""
    by_type: dict[int, list[_Object]] = {}
    for obj in objects.values():
        by_type.setdefault(obj.type_id, []).append(obj)
    for type_id, objs in by_type.items():
        if len(objs) > 1:
            raise ContextError(f"{len(objs)} {TYPE_NAMES[family][type_id]} objects: the stand-in models one")
    if 64 not in by_type:
        raise ContextError("the context has no ETHERNET object")
    eth = by_type[64][0]
    try:
        config = load_ethernet(sensor_dir / eth.params["ConfigFile"])
    except ConfigError as e:
        raise ContextError(f"{eth.obj_id}: {e}") from None
    timeout = _int(eth, "Timeout", 0)
    precision = _int(eth, "Precision", 1, 32)
    _int(eth, "Flag", -1, 999)

    def source(obj: _Object, index: int) -> int | None:
        """The ETHERNET output (1-based, as INDX) feeding ``obj``'s input ``index`` (0-based)."""
        wired = obj.inputs.get(index)
        if wired is None:
            return None
        src, out = wired
        if src not in objects:
            raise ContextError(f"{obj.obj_id}: input {index + base} comes from {src!r}, which is not in the context")
        if src != eth.obj_id:
            raise ContextError(f"{obj.obj_id}: input {index + base} comes from {src}: the stand-in models inputs "
                               f"fed by {eth.obj_id} only")
        indx = out + 1
        if config.output(indx) is None:
            raise ContextError(f"{obj.obj_id}: Invalid index - signal output: input {index + base} is "
                               f"{eth.obj_id} output {out + base}, which no RECEIVE element feeds (INDX {indx})")
        return indx

    stop_output = None
    if 18 in by_type:
        stop = by_type[18][0]
        mode = _int(stop, "Mode", 0, 4)
        if mode != STOP_EXIT_MOVECORR:
            raise ContextError(f"{stop.obj_id}: Mode {mode} is not modelled (only 4, ExitMoveCorr)")
        _int(stop, "Channel", 0)
        stop_output = source(stop, 0)
    if 33 not in by_type:
        raise ContextError("the context has no AXISCORR object: nothing would move the axes")
    corr = by_type[33][0]
    corr_outputs = tuple(source(corr, n) for n in range(6))
    lower = tuple(_real(corr, f"LowerLim{a}", None, 0.0) for a in _AXES)
    upper = tuple(_real(corr, f"UpperLim{a}", 0.0) for a in _AXES)
    monitor: tuple[float, ...] = (DEFAULT_OVERALL_LIMIT,) * 6
    monitor_object = None
    if 82 in by_type:
        mon = by_type[82][0]
        monitor, monitor_object = tuple(_real(mon, f"Max{a}", 0.0) for a in _AXES), mon.obj_id
        for n in range(6):
            _real(mon, f"MaxE{n + 1}", 0.0)
    for n, indx in enumerate(corr_outputs):
        element = None if indx is None else config.output(indx)
        if element is not None and element.type != "DOUBLE":
            raise ContextError(f"{corr.obj_id} input {n + base} is fed by {element.tag}, a {element.type}")
    return SignalFlow(eth.obj_id, config, timeout, precision, stop_output, corr_outputs, lower, upper, monitor,
                      monitor_object)


def _real(obj: _Object, name: str, lo: float | None = None, hi: float | None = None) -> float:
    """A parameter's value, checked against the range its blueprint allows."""
    text = obj.params[name]
    try:
        value = float(text)
    except ValueError:
        raise ContextError(f"{obj.obj_id}.{name}: {text!r} is not a number") from None
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ContextError(f"{obj.obj_id}.{name} = {text} is outside {lo}..{hi}")
    return value


def _int(obj: _Object, name: str, lo: int | None = None, hi: int | None = None) -> int:
    value = _real(obj, name, lo, hi)
    if value != int(value):
        raise ContextError(f"{obj.obj_id}.{name}: {obj.params[name]!r} is not an integer")
    return int(value)
