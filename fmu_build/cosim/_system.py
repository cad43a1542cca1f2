"""Reading a system (.ssp, .ssd or dict) into one validated object.

Rules checked before anything runs (each error names the element, the file and the rule):

- component names are plain identifiers (``[A-Za-z_][A-Za-z0-9_]*``) and unique; they are
  never used as paths: FMUs are unpacked into folders the master names;
- every connection joins two listed components, with one source per input;
- a packed ``.ssp`` refers only to FMUs inside the archive unless the caller passes
  ``allow_external=True``; only the SSD and the referenced FMUs are extracted, and extraction
  stops beyond ``max_unpacked`` bytes (archive members' real sizes, not their headers);
- every temporary folder is removed on every exit path (a failed read included).

Units are read, not applied: the SSD's unit definitions (``ssd:Units``), each connector's unit, each
inline parameter value's unit with its parameter set's definitions (``ssv:Units``), each connection's
``suppressUnitConversion`` and ``LinearTransformation``. The master converts them to the FMUs' units, or
refuses (``_units``). What the master would drop is refused here: a Boolean, Integer or Enumeration
mapping on a connection, parameter values of another format, a connector declared twice.
"""

import math
import os
import posixpath
import re
import shutil
import stat
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import NamedTuple

from ._units import Affine, parse_units, xs_double

SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
FMU_TYPE = "application/x-fmu-sharedlibrary"
CONNECTOR_TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration")
PARAMETER_SET = "application/x-ssp-parameter-set"
IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
MAX_UNPACKED = 1 << 30  # bytes one archive may unpack to (SSP or FMU)


class Binding(NamedTuple):
    """A value an SSD binds to a component's variable: its type and text, and for a Real its unit (None: the
    variable's own) with the definitions of the parameter set it comes from."""

    kind: str
    text: str
    unit: str = None
    units: dict = None


class System:
    """Components, connections and the temporary folder of a system read by :func:`read_system`.

    Iterating gives ``(components, connections, workdir)``; ``close()`` (or leaving a ``with``
    block) removes the folder.

    Examples
    --------
    >>> s = read_system({"components": {"a": "a.fmu", "b": "b.fmu"}, "connections": [("a.y", "b.u")]})
    >>> s.connections
    [('a', 'y', 'b', 'u')]
    """

    def __init__(self, components, connections, workdir=None, origin="`system`"):
        self.components, self.connections, self.workdir, self.origin = components, connections, workdir, origin
        self.connectors = {}  # (component, connector) -> type declared in the SSD
        self.parameters = {}  # "component.variable" -> Binding in the SSD (applied as a start value)
        self.units = {}  # unit name -> _units.Unit defined by the SSD (ssd:Units)
        self.connector_units = {}  # (component, connector) -> unit name the SSD gives a Real connector
        self.unconverted = set()  # (component, input) of connections with suppressUnitConversion="true"
        self.transformations = {}  # (component, input) -> _units.Affine of a connection's LinearTransformation

    def __iter__(self):
        return iter((self.components, self.connections, self.workdir))

    def close(self):
        if self.workdir:
            shutil.rmtree(self.workdir, ignore_errors=True)
            self.workdir = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def read_system(system, *, allow_external=False, max_unpacked=MAX_UNPACKED):
    """Read and validate a system description.

    Parameters
    ----------
    system : str, Path or dict
        An ``.ssp`` file, an ``.ssd`` file (FMU sources relative to its
        folder), or ``{"components": {name: fmu_path}, "connections":
        [("a.y", "b.u"), ...]}``.
    allow_external : bool
        Let a packed ``.ssp`` refer to FMUs outside the archive (relative to
        its folder, or absolute). Refused by default.
    max_unpacked : int
        Bytes the SSP's extracted members may occupy.

    Returns
    -------
    System
        ``components`` (name -> FMU path), ``connections`` (tuples
        ``(source_component, source_variable, destination_component,
        destination_variable)``) and ``workdir`` (the extracted FMUs, or None).

    Examples
    --------
    >>> comps, conns, _ = read_system({"components": {"a": "a.fmu", "b": "b.fmu"},
    ...                                "connections": [("a.y", "b.u")]})
    >>> conns
    [('a', 'y', 'b', 'u')]
    >>> read_system({"components": {"../x": "a.fmu"}, "connections": []})
    Traceback (most recent call last):
    ...
    ValueError: `system`: component name '../x' is not a plain identifier ([A-Za-z_][A-Za-z0-9_]*); names are never paths.
    """
    if isinstance(system, dict):
        return _from_dict(system)
    if not isinstance(allow_external, bool):
        raise TypeError(f"`allow_external` must be True or False; found {allow_external!r}.")
    if not isinstance(system, (str, Path)):
        raise TypeError(f"`system` must be an .ssp/.ssd path or a dict; found {type(system).__name__}.")
    path = Path(system)
    if not path.is_file():
        raise ValueError(f"`system`: no such file {str(path)!r}.")
    if path.suffix.lower() == ".ssd":
        return _from_ssd(path.read_bytes(), f"`system` {path}", lambda src, index: _outside(src, path.parent))
    return _from_ssp(path, allow_external, int(max_unpacked))


def _from_dict(system):
    unknown = set(system) - {"components", "connections"}
    if unknown or "components" not in system:
        raise ValueError(f"`system` as a dict must have the keys 'components' and 'connections'; found {sorted(system)}.")
    if not isinstance(system["components"], dict):
        raise TypeError(f"`system`['components'] must be a dict {{name: fmu_path}}; found "
                        f"{type(system['components']).__name__}.")
    components = {}
    for name, fmu in system["components"].items():
        _check_name(name, "`system`")
        if not isinstance(fmu, (str, os.PathLike)):
            raise TypeError(f"`system`: component {name!r} must be an FMU path; found {type(fmu).__name__} {fmu!r}.")
        components[name] = os.fspath(fmu)
    pairs = []
    for pair in system.get("connections", []):
        if len(pair) != 2:
            raise ValueError(f"a connection must be a pair ('comp.out', 'comp.in'); found {pair!r}.")
        pairs.append((*_split(pair[0], components), *_split(pair[1], components)))
    return System(components, _check_connections(pairs, "`system`"), None)


def _from_ssp(path, allow_external, max_unpacked):
    where = f"`system` {path}"
    workdir = tempfile.mkdtemp(prefix="lsc_cosim_ssp_")
    try:
        try:
            archive = zipfile.ZipFile(path)
        except zipfile.BadZipFile:
            raise ValueError(f"{where}: not an SSP archive (a zip holding SystemStructure.ssd); a plain "
                             "SystemStructure.ssd is read from a file ending in .ssd.") from None
        with archive as zf:
            members = set(zf.namelist())
            if "SystemStructure.ssd" not in members:
                raise ValueError(f"{where}: no SystemStructure.ssd at the archive's root.")
            budget = [max_unpacked]
            ssd = _read_member(zf, "SystemStructure.ssd", budget, where)

            def locate(source, index):
                member = _member(source)
                if member is None:
                    if not allow_external:
                        raise ValueError(f"{where}: component source {source!r} points outside the archive; "
                                         "refused (pass allow_external=True to allow it).")
                    return _outside(source, path.parent)
                if member not in members:
                    raise ValueError(f"{where}: component source {source!r} is not in the archive.")
                dest = Path(workdir) / f"component{index}.fmu"
                dest.write_bytes(_read_member(zf, member, budget, where))
                return str(dest)

            system = _from_ssd(ssd, where, locate)
        system.workdir = workdir
        return system
    except BaseException:
        shutil.rmtree(workdir, ignore_errors=True)
        raise


def _read_member(zf, member, budget, where):
    """The bytes of ``member``, counting what is really inflated against ``budget[0]``."""
    chunks = []
    with zf.open(member) as f:
        while True:
            chunk = f.read(1 << 20)
            if not chunk:
                break
            budget[0] -= len(chunk)
            if budget[0] < 0:
                raise ValueError(f"{where}: unpacking {member!r} exceeds the size limit (max_unpacked); refused.")
            chunks.append(chunk)
    return b"".join(chunks)


def _member(source):
    """The archive member a component source names, or None if it points outside the archive."""
    if re.match(r"[A-Za-z][A-Za-z0-9+.-]*:", source) or source.startswith(("/", "\\")):
        return None  # a URI with a scheme (file:, http:, a drive letter) or an absolute path
    norm = posixpath.normpath(source.replace("\\", "/"))
    if norm == ".." or norm.startswith("../"):
        return None
    return norm


def _outside(source, base):
    if source.startswith("file:"):
        from urllib.parse import unquote, urlparse

        return str(Path(unquote(urlparse(source).path)).resolve())
    return str((Path(base) / source).resolve())


def _from_ssd(data, where, locate):
    """Components and connections of an SSD document; ``locate(source, index)`` gives an FMU path."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise ValueError(f"{where}: SystemStructure.ssd is not valid XML ({exc}).") from None
    if not root.tag.startswith("{" + SSD_NS + "}") or _local(root.tag) != "SystemStructureDescription":
        raise ValueError(f"{where}: the root element {root.tag!r} is not a SystemStructureDescription in the SSP "
                         f"namespace {SSD_NS!r}; refused (a document of another namespace means something else).")
    system = _child(root, "System")
    if system is None:
        raise ValueError(f"{where}: the SSD has no System element.")
    if _child(system, "ParameterBindings") is not None:
        raise ValueError(f"{where}: the System has ParameterBindings; only a Component's inline ParameterBindings "
                         "are applied (a run without them would be another model). Give the values as "
                         "`start_values`.")
    parameters = {}
    components, connectors, connector_units = {}, {}, {}
    elements = _child(system, "Elements")
    for index, element in enumerate(list(elements) if elements is not None else []):
        kind, name = _local(element.tag), element.get("name")
        if kind != "Component":
            raise ValueError(f"{where}: element {name!r} is a {kind}; only Component elements (FMUs) are supported.")
        _check_name(name, where)
        if name in components:
            raise ValueError(f"{where}: two components are named {name!r}; component names must be unique.")
        source = element.get("source")
        if not source:
            raise ValueError(f"{where}: component {name!r} has no source.")
        kind = element.get("type", FMU_TYPE)
        if kind != FMU_TYPE:
            raise ValueError(f"{where}: component {name!r} is of type {kind!r}; only FMUs ({FMU_TYPE}) are "
                             "supported (a nested SSP is not).")
        components[name] = locate(source, index)
        types, units = _connectors(element, name, where)
        connectors.update(types)
        connector_units.update(units)
        parameters.update(_bindings(element, name, where))
    connections, unconverted, transformations = [], set(), {}
    links = _child(system, "Connections")
    for c in list(links) if links is not None else []:
        a, y, b, u = (c.get(k) for k in ("startElement", "startConnector", "endElement", "endConnector"))
        for k, v in (("startConnector", y), ("endConnector", u)):
            if not v:
                raise ValueError(f"{where}: connection {a}.{y} -> {b}.{u} has no {k} attribute; a Connection "
                                 "names its startConnector and endConnector.")
        if not a or not b:
            raise ValueError(f"{where}: connection {a}.{y} -> {b}.{u}: connections to the system's own connectors "
                             "are not supported.")
        transformation = _transformation(c, f"{where}: connection {a}.{y} -> {b}.{u}")
        if transformation is not None:
            transformations[(b, u)] = transformation
        for comp in (a, b):
            if comp not in components:
                raise ValueError(f"{where}: connection {a}.{y} -> {b}.{u}: no component {comp!r}.")
        suppress = (c.get("suppressUnitConversion") or "false").strip()
        if suppress not in ("true", "false", "1", "0"):
            raise ValueError(f"{where}: connection {a}.{y} -> {b}.{u}: suppressUnitConversion must be true or "
                             f"false; found {suppress!r}.")
        if suppress in ("true", "1"):
            unconverted.add((b, u))
        connections.append((a, y, b, u))
    system = System(components, _check_connections(connections, where), None, where)
    system.connectors, system.parameters = connectors, parameters
    system.units = parse_units(_one(root, "Units", where), where)
    system.connector_units, system.unconverted = connector_units, unconverted
    system.transformations = transformations
    return system


def _transformation(connection, what):
    """The `Affine` map of a connection's ``ssc:LinearTransformation`` (None: none). A Boolean, Integer or
    Enumeration mapping is refused: without it the input would get the unmapped value."""
    found = None
    for e in connection:
        kind = _local(e.tag)
        if kind == "LinearTransformation":
            if found is not None:
                raise ValueError(f"{what} has two LinearTransformations; a connection has at most one.")
            factor, offset = (xs_double(e.get(k), f"{what}: the LinearTransformation's {k}") if e.get(k) is not None
                              else default for k, default in (("factor", 1.0), ("offset", 0.0)))
            if not (math.isfinite(factor) and math.isfinite(offset)) or factor == 0.0:
                raise ValueError(f"{what}: the LinearTransformation's factor and offset must be finite, the factor "
                                 f"other than 0 (the input would be a constant); found {factor!r} and {offset!r}.")
            found = Affine(factor, offset)
        elif kind.endswith("Transformation"):
            raise ValueError(f"{what} has a {kind}, which this master does not apply; refused (the input would get "
                             "the unmapped value).")
    return found


def _bindings(element, name, where):
    """``{"component.parameter": Binding}`` of a component's inline ParameterBindings; what this master
    cannot apply exactly (an external .ssv, a prefix, a mapping, an Enumeration item) is refused."""
    found = {}
    block = _child(element, "ParameterBindings")
    for binding in list(block) if block is not None else []:
        what = f"{where}: component {name!r}: a ParameterBinding"
        if binding.get("source") or binding.get("prefix") or _child(binding, "ParameterMapping") is not None:
            raise ValueError(f"{what} with a source file, a prefix or a ParameterMapping is not applied by this "
                             "master; refused. Give the values inline or as `start_values`.")
        kind = binding.get("type", PARAMETER_SET).strip()
        if kind != PARAMETER_SET:
            raise ValueError(f"{what} is of type {kind!r}; only SSP parameter sets ({PARAMETER_SET}) are read; "
                             "refused (a run without its values would be another model).")
        values = _child(binding, "ParameterValues")
        sets = list(values) if values is not None else []
        if values is not None and (len(sets) != 1 or _local(sets[0].tag) != "ParameterSet"):
            raise ValueError(f"{what}'s ParameterValues must hold one ParameterSet; found "
                             f"{[_local(e.tag) for e in sets]}; refused (a run without its values would be another "
                             "model).")
        for ps in sets:
            units = parse_units(_one(ps, "Units", f"{what}'s ParameterSet"), f"{what}'s ParameterSet")
            parameters = _child(ps, "Parameters")
            for parameter in list(parameters) if parameters is not None else []:
                kinds = [e for e in parameter if _local(e.tag) in ("Real", "Integer", "Boolean", "String")]
                if not parameter.get("name") or len(kinds) != 1 or kinds[0].get("value") is None:
                    raise ValueError(f"{what}: parameter {parameter.get('name')!r} must have a name and one "
                                     "Real, Integer, Boolean or String value; refused.")
                kind, unit = _local(kinds[0].tag), kinds[0].get("unit")
                if unit is not None and kind != "Real":
                    raise ValueError(f"{what}: parameter {parameter.get('name')!r} is a {kind} with a unit; only a "
                                     "Real has one (SSP); refused.")
                found[f"{name}.{parameter.get('name')}"] = Binding(kind, kinds[0].get("value"), unit, units)
    return found


def _connectors(element, name, where):
    """``{(component, connector): declared type}`` of a component's Connectors (the types given), and
    ``{(component, connector): unit}`` of its Real connectors that name one."""
    types, units, seen = {}, {}, set()
    block = _child(element, "Connectors")
    for connector in list(block) if block is not None else []:
        kinds = [e for e in connector if _local(e.tag) in CONNECTOR_TYPES]
        if _local(connector.tag) == "Connector" and (name, connector.get("name")) in seen:
            raise ValueError(f"{where}: connector {name}.{connector.get('name')} is declared twice; a connector's "
                             "name is unique in its component.")
        seen.add((name, connector.get("name")))
        if kinds and connector.get("name"):
            types[(name, connector.get("name"))] = _local(kinds[0].tag)
            unit = kinds[0].get("unit")
            if unit is not None:
                if _local(kinds[0].tag) != "Real":
                    raise ValueError(f"{where}: connector {name}.{connector.get('name')} is a "
                                     f"{_local(kinds[0].tag)} with a unit; only a Real has one (SSP); refused.")
                units[(name, connector.get("name"))] = unit
    return types, units


def _local(tag):
    return tag.rsplit("}", 1)[-1]


def _child(element, name):
    return next((e for e in element if _local(e.tag) == name), None)


def _one(element, name, where):
    """The child ``name`` of ``element`` (None: none); two are refused (the second would be ignored)."""
    found = [e for e in element if _local(e.tag) == name]
    if len(found) > 1:
        raise ValueError(f"{where}: {len(found)} {name} elements where the SSP allows one; refused (the second "
                         "would be ignored).")
    return found[0] if found else None


def _check_name(name, where):
    if not isinstance(name, str) or not IDENTIFIER.match(name):
        raise ValueError(f"{where}: component name {name!r} is not a plain identifier ([A-Za-z_][A-Za-z0-9_]*); "
                         "names are never paths.")


def _check_connections(connections, where):
    sources = {}
    for a, y, b, u in connections:
        if (b, u) in sources:
            raise ValueError(f"{where}: input {b}.{u} has two sources ({sources[(b, u)]} and {a}.{y}); "
                             "an input takes one connection.")
        sources[(b, u)] = f"{a}.{y}"
    return list(connections)


def _split(name, components):
    comp, dot, var = str(name).partition(".")
    if not dot or comp not in components:
        raise ValueError(f"a variable must be named 'component.variable' with a component in {sorted(components)}; found {name!r}.")
    return comp, var


def unzip(path, dest, max_unpacked=MAX_UNPACKED, where=None):
    """Extract the archive ``path`` into the folder ``dest`` (members inside it only, size-limited).

    Examples
    --------
    >>> import io, tempfile
    >>> buf = io.BytesIO()
    >>> with zipfile.ZipFile(buf, "w") as zf:
    ...     zf.writestr("../evil.txt", "x")
    >>> unzip(buf, tempfile.mkdtemp())
    Traceback (most recent call last):
    ...
    ValueError: archive: member '../evil.txt' would be written outside its folder; refused.
    """
    where = where or "archive"
    # a one-item list is a budget shared by several archives (the FMUs of one run)
    budget = max_unpacked if isinstance(max_unpacked, list) else [int(max_unpacked)]
    dest = os.path.realpath(dest)
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            member = _member(info.filename)
            if member is None or member.startswith("./") or member == ".":
                raise ValueError(f"{where}: member {info.filename!r} would be written outside its folder; refused.")
            if stat.S_ISLNK(info.external_attr >> 16):
                raise ValueError(f"{where}: member {info.filename!r} is a symlink; refused (an archive's members "
                                 "are files and folders only).")
            target = os.path.join(dest, member)
            if info.is_dir():
                os.makedirs(target, exist_ok=True)
                continue
            os.makedirs(os.path.dirname(target), exist_ok=True)
            with open(target, "wb") as f:
                f.write(_read_member(zf, info.filename, budget, where))
    return dest
