"""The FMI 3.0 modelDescription.xml and buildDescription.xml of a native lsc FMU.

`model_description3` takes the same variable dicts as the FMI 2.0 writer
(`fmu_build._description.model_description`) and writes them in the FMI 3.0
schema: typed elements (``<Float64>``, ``<Boolean>``), value references unique
over all types, an independent variable ``time``, and a ``ModelStructure`` of
``<Output>``, ``<ContinuousStateDerivative>`` and ``<InitialUnknown>`` whose
dependencies are value references.
"""

from xml.etree import ElementTree as ET

from ._description import _dependencies, _initial_unknowns, _shared_blocks, _text

__all__ = ["model_description3", "build_description3"]

_TYPES3 = {"Real": "Float64", "Boolean": "Boolean"}


def model_description3(*, model_name, token, description, model_identifier, variables, co_simulation=None,
                       model_exchange=None, experiment=None, log_categories=(), generation_tool="lsc fmu_build"):
    """FMI 3.0 modelDescription.xml as bytes.

    Parameters
    ----------
    model_name, token, description, model_identifier : str
        ``token`` is the ``instantiationToken``.
    variables : list of dict
        As for `fmu_build._description.model_description`; ``vr`` must be
        unique over all variables (FMI 3.0). A variable with causality
        ``independent`` (``time``) must be among them.
    co_simulation, model_exchange : dict or None
        Capability flags of each interface (attribute name -> value).
    experiment : dict or None
        ``startTime``, ``stopTime``, ``stepSize``.
    log_categories : sequence of (name, description)

    Returns
    -------
    bytes

    Examples
    --------
    >>> xml = model_description3(model_name="M", token="{0}", description="", model_identifier="M",
    ...     variables=[{"name": "time", "type": "Real", "vr": 1, "causality": "independent", "variability": "continuous"},
    ...                {"name": "x", "type": "Real", "vr": 0, "causality": "output", "variability": "continuous"}],
    ...     co_simulation={})
    >>> b'<Output valueReference="0"' in xml
    True
    """
    vrs = [v["vr"] for v in variables]
    if len(set(vrs)) != len(vrs):
        raise ValueError(f"`variables`: value references must be unique in FMI 3.0; found {sorted(vrs)}")
    root = ET.Element("fmiModelDescription", fmiVersion="3.0", modelName=model_name, instantiationToken=token,
                      description=description, generationTool=generation_tool, variableNamingConvention="structured")
    for tag, flags in (("ModelExchange", model_exchange), ("CoSimulation", co_simulation)):
        if flags is not None:
            ET.SubElement(root, tag, modelIdentifier=model_identifier, **{k: _text(v) for k, v in flags.items()})
    _shared_blocks(root, variables, log_categories, experiment)
    model_vars = ET.SubElement(root, "ModelVariables")
    vr_of = {v["name"]: v["vr"] for v in variables}
    for v in variables:
        attrs = {"name": v["name"], "valueReference": str(v["vr"])}
        if v.get("description"):
            attrs["description"] = v["description"]
        attrs["causality"] = v["causality"]
        attrs["variability"] = v["variability"]
        if v.get("initial"):
            attrs["initial"] = v["initial"]
        if v.get("unit"):
            attrs["unit"] = v["unit"]
        if "start" in v and v["start"] is not None:
            attrs["start"] = _text(v["start"])
        if v.get("derivative"):
            attrs["derivative"] = str(vr_of[v["derivative"]])
        ET.SubElement(model_vars, _TYPES3[v["type"]], **attrs)
    _model_structure3(ET.SubElement(root, "ModelStructure"), variables, vr_of, model_exchange is not None)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _model_structure3(structure, variables, vr_of, model_exchange):
    """Outputs, state derivatives (with Model Exchange) and initial unknowns, in the schema's order."""
    def unknown(tag, v):
        attrs = {"valueReference": str(v["vr"])}
        deps = _dependencies(v, vr_of)
        if deps is not None:
            attrs["dependencies"] = deps
        ET.SubElement(structure, tag, **attrs)

    for v in variables:
        if v["causality"] == "output":
            unknown("Output", v)
    for v in variables:
        if model_exchange and v.get("derivative"):
            unknown("ContinuousStateDerivative", v)
    for v in _initial_unknowns(variables, model_exchange):
        ET.SubElement(structure, "InitialUnknown", valueReference=str(v["vr"]))


def build_description3(model_identifier, source_file):
    """``sources/buildDescription.xml`` (FMI 3.0): the one C file to compile.

    Examples
    --------
    >>> b'SourceFile name="fmi3Functions.c"' in build_description3("M", "fmi3Functions.c")
    True
    """
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    conf = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model_identifier)
    files = ET.SubElement(conf, "SourceFileSet", language="C99")
    ET.SubElement(files, "SourceFile", name=source_file)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
