"""The FMI 2.0 modelDescription.xml of an lsc FMU, written in one place.

`model_description` takes the variables as plain dicts (in value-reference
order within each type) and decides units, ``ModelStructure`` (outputs with
their dependencies, derivatives, initial unknowns) and the element order the
standard prescribes.
"""

from xml.etree import ElementTree as ET

__all__ = ["model_description"]

_TYPE_ORDER = ("Real", "Integer", "Boolean", "String")


def _text(value):
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def model_description(*, model_name, guid, description, model_identifier, variables, source_files=(),
                      co_simulation=None, model_exchange=None, experiment=None, log_categories=(),
                      generation_tool="lsc fmu_build"):
    """modelDescription.xml as bytes.

    Parameters
    ----------
    model_name, guid, description, model_identifier : str
    variables : list of dict
        ``name``, ``type`` ('Real', 'Boolean', ...), ``vr`` (value reference),
        ``causality``, ``variability``, optional ``initial``, ``start``,
        ``unit``, ``description``, ``derivative`` (name of the state it is
        the derivative of), ``dependencies`` (names of the knowns an output
        or derivative depends on; None: all of them).
    source_files : sequence of str
        C files to compile (listed under ``<SourceFiles>`` of each interface).
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
    >>> xml = model_description(model_name="M", guid="{0}", description="", model_identifier="M",
    ...     variables=[{"name": "x", "type": "Real", "vr": 0, "causality": "output", "variability": "continuous"}],
    ...     co_simulation={})
    >>> b'<Unknown index="1"' in xml
    True
    """
    root = ET.Element("fmiModelDescription", fmiVersion="2.0", modelName=model_name, guid=guid,
                      description=description, generationTool=generation_tool, variableNamingConvention="structured",
                      numberOfEventIndicators="0")
    for tag, flags in (("ModelExchange", model_exchange), ("CoSimulation", co_simulation)):
        if flags is None:
            continue
        el = ET.SubElement(root, tag, modelIdentifier=model_identifier, **{k: _text(v) for k, v in flags.items()})
        if source_files:
            files = ET.SubElement(el, "SourceFiles")
            for name in source_files:
                ET.SubElement(files, "File", name=name)
    units = sorted({v["unit"] for v in variables if v.get("unit")})
    if units:
        defs = ET.SubElement(root, "UnitDefinitions")
        for u in units:
            ET.SubElement(defs, "Unit", name=u)
    if log_categories:
        cats = ET.SubElement(root, "LogCategories")
        for name, text in log_categories:
            ET.SubElement(cats, "Category", name=name, description=text)
    if experiment:
        ET.SubElement(root, "DefaultExperiment", **{k: _text(v) for k, v in experiment.items()})
    model_vars = ET.SubElement(root, "ModelVariables")
    index = {}
    for i, v in enumerate(variables, start=1):
        index[v["name"]] = i
        attrs = {"name": v["name"], "valueReference": str(v["vr"]), "causality": v["causality"],
                 "variability": v["variability"]}
        if v.get("description"):
            attrs["description"] = v["description"]
        if v.get("initial"):
            attrs["initial"] = v["initial"]
        sv = ET.SubElement(model_vars, "ScalarVariable", **attrs)
        typed = {}
        if v.get("derivative"):
            typed["derivative"] = None  # filled below, once every index is known
        if v.get("unit"):
            typed["unit"] = v["unit"]
        if "start" in v and v["start"] is not None:
            typed["start"] = _text(v["start"])
        v["_element"] = ET.SubElement(sv, v["type"], **{k: val for k, val in typed.items() if val is not None})
    for v in variables:
        if v.get("derivative"):
            v["_element"].set("derivative", str(index[v["derivative"]]))
            # attribute order: derivative first reads better, but XML does not care

    _model_structure(ET.SubElement(root, "ModelStructure"), variables, index, model_exchange is not None)
    for v in variables:
        v.pop("_element", None)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _model_structure(structure, variables, index, model_exchange):
    """Fill ``<ModelStructure>``: outputs and derivatives with their dependencies, and the initial unknowns.

    `index` maps a variable's name to its 1-based index; `model_exchange` says whether the
    FMU has that interface (only then are derivatives listed).
    """
    def unknown(parent, v):
        attrs = {"index": str(index[v["name"]])}
        deps = v.get("dependencies")
        if deps is not None:
            attrs["dependencies"] = " ".join(str(j) for j in sorted(index[d] for d in deps))
        ET.SubElement(parent, "Unknown", **attrs)

    outputs = [v for v in variables if v["causality"] == "output"]
    if outputs:
        el = ET.SubElement(structure, "Outputs")
        for v in outputs:
            unknown(el, v)
    derivatives = [v for v in variables if v.get("derivative")]
    if derivatives and model_exchange:
        el = ET.SubElement(structure, "Derivatives")
        for v in derivatives:
            unknown(el, v)
    states = {v["derivative"] for v in derivatives} if model_exchange else set()
    initial = []
    for v in variables:
        calculated = v.get("initial", "calculated" if v["causality"] in ("output", "local", "calculatedParameter")
                           and v["variability"] not in ("constant", "fixed", "tunable") else None) in ("approx", "calculated")
        if (v["causality"] in ("output", "calculatedParameter") and calculated) or \
                ((v["name"] in states or (v.get("derivative") and model_exchange)) and calculated):
            initial.append(v)
    if initial:
        el = ET.SubElement(structure, "InitialUnknowns")
        for v in initial:
            ET.SubElement(el, "Unknown", index=str(index[v["name"]]))
