"""The FMI 2.0 modelDescription.xml of an lsc FMU, written in one place.

`model_description` takes the variables as plain dicts (in value-reference
order within each type) and decides units, ``ModelStructure`` (outputs with
their dependencies, derivatives, initial unknowns) and the element order the
standard prescribes.
"""

from xml.etree import ElementTree as ET

__all__ = ["model_description", "model_structure", "unit_definitions"]

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
    _shared_blocks(root, variables, log_categories, experiment)
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

    model_structure(ET.SubElement(root, "ModelStructure"), variables, index, model_exchange is not None)
    for v in variables:
        v.pop("_element", None)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _shared_blocks(root, variables, log_categories, experiment):
    """``<UnitDefinitions>``, ``<LogCategories>`` and ``<DefaultExperiment>``: the same in FMI 2.0 and 3.0."""
    units = unit_definitions(variables)
    if units is not None:
        root.append(units)
    if log_categories:
        cats = ET.SubElement(root, "LogCategories")
        for name, text in log_categories:
            ET.SubElement(cats, "Category", name=name, description=text)
    if experiment:
        ET.SubElement(root, "DefaultExperiment", **{k: _text(v) for k, v in experiment.items()})


def unit_definitions(variables):
    """The ``<UnitDefinitions>`` element of the units the variables use (sorted), or None if they use none."""
    units = sorted({v["unit"] for v in variables if v.get("unit")})
    if not units:
        return None
    defs = ET.Element("UnitDefinitions")
    for u in units:
        ET.SubElement(defs, "Unit", name=u)
    return defs


def _dependencies(v, key):
    """The ``dependencies`` attribute of an unknown (`key` maps a name to its index or value reference),
    or None when the variable states none."""
    deps = v.get("dependencies")
    return None if deps is None else " ".join(str(j) for j in sorted(key[d] for d in deps))


def _initial_unknowns(variables, model_exchange):
    """The variables listed as initial unknowns: outputs, calculated parameters and, with Model Exchange,
    states and derivatives, whose ``initial`` (given, or the default of their causality) is calculated."""
    derivatives = [v for v in variables if v.get("derivative")] if model_exchange else []
    states = {v["derivative"] for v in derivatives}
    out = []
    for v in variables:
        default = "calculated" if v["causality"] in ("output", "local", "calculatedParameter") \
            and v["variability"] not in ("constant", "fixed", "tunable") else None
        if (v.get("initial") or default) in ("approx", "calculated") and (
                v["causality"] in ("output", "calculatedParameter") or v["name"] in states
                or any(v is d for d in derivatives)):
            out.append(v)
    return out


def model_structure(structure, variables, index, model_exchange):
    """Fill ``<ModelStructure>``: outputs and derivatives with their dependencies, and the initial unknowns.

    `index` maps a variable's name to its 1-based index; `model_exchange` says whether the
    FMU has that interface (only then are derivatives listed).
    """
    def unknown(parent, v):
        attrs = {"index": str(index[v["name"]])}
        deps = _dependencies(v, index)
        if deps is not None:
            attrs["dependencies"] = deps
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
    initial = _initial_unknowns(variables, model_exchange)
    if initial:
        el = ET.SubElement(structure, "InitialUnknowns")
        for v in initial:
            ET.SubElement(el, "Unknown", index=str(index[v["name"]]))
