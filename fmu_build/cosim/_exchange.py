"""One FMU instance (FMI 2.0 or 3.0 Co-Simulation) and typed access to its variables.

Every read and write goes through the getter and setter of the variable's own FMI type (`_fmi`): FMI
2.0 value references are unique per type only (a Real and a Boolean may share reference 7), FMI 3.0
has a getter per type (Float32 ... UInt64, Binary). The master groups variables by kind (Real,
Integer, Boolean, String, Binary); a value is converted to the variable's type by rules that refuse
what they cannot interpret (``"false"`` is False, ``0.3`` is no Boolean, ``2.5`` no Integer, 300 no
Int8) and never passes an integer through a float beyond 2^53.

A connection between variables of different units carries an affine map (`_units`): the master's
coupling values stay in the source output's unit, and every value or input derivative set on the
connected input is converted to the input's unit here (`Component.set`); start values are in the
variable's own unit (`Component.set_start`).
"""

import math
import os
import zipfile

import numpy as np

from .._values import EXACT_IN_DOUBLE, FLOAT32_MAX
from . import _fmi, _units
from ._fmi import convert  # noqa: F401 (the rules of values, re-exported)
from ._system import IDENTIFIER, unzip

# pythonfmu FMUs import their model module by name into the one Python of the process, where the
# first module of a name stays: a second FMU with another module of that name would run the first's code
_PYTHON_MODELS = {}


def _check_python_model(name, path, unzipdir):
    import hashlib

    resources = os.path.join(unzipdir, "resources")
    marker = os.path.join(resources, "slavemodule.txt")
    if not os.path.isfile(marker):
        return
    with open(marker, encoding="utf-8", errors="replace") as f:
        module = f.read().strip()
    digest = hashlib.sha256()
    for root, dirs, files in os.walk(resources):
        dirs.sort()
        for file in sorted(files):
            if file.endswith(".py"):
                full = os.path.join(root, file)
                digest.update(os.path.relpath(full, resources).encode())
                with open(full, "rb") as f:
                    digest.update(f.read())
    known = _PYTHON_MODELS.setdefault(module, (digest.hexdigest(), path))
    if known[0] != digest.hexdigest():
        raise ValueError(f"component {name!r} ({os.path.basename(path)}): its pythonfmu model module {module!r} "
                         f"differs from the one of the same name already loaded in this process (from {known[1]}); "
                         "pythonfmu would run the first one's code. Run it in another process.")


class Component:
    """One FMU, what the master knows of it, and typed get/set by value reference.

    Built in two steps: the constructor reads and checks the FMU and loads its library; `start`
    instantiates it. ``fmu`` is the
    slave of `_fmi.slave_class`: fmpy's, under the names of the FMI 2.0 interface.
    """

    def __init__(self, name, path, unzipdir, max_unpacked):
        from fmpy import read_model_description

        self.name, self.path, self.started, self.initialized = name, path, False, False
        self.early_return = False  # instantiated with earlyReturnAllowed (`start`)
        where = self.where = f"component {name!r} ({path})"
        if not os.path.isfile(path):
            raise ValueError(f"{where}: no such FMU file.")
        if not zipfile.is_zipfile(path):
            raise ValueError(f"{where}: not an FMU (an FMU is a zip archive).")
        try:
            self.md = read_model_description(path)
        except Exception as exc:  # noqa: BLE001 -- fmpy raises bare Exceptions for invalid descriptions
            raise ValueError(f"{where}: invalid modelDescription.xml ({exc}).") from None
        version = str(self.md.fmiVersion)
        if not version.startswith(("2.", "3.")):
            raise ValueError(f"{where}: FMI {version}; this master runs FMI 2.0 and FMI 3.0 Co-Simulation FMUs.")
        self.is_fmi3 = _fmi.fmi3(self.md)
        cs = self.md.coSimulation
        if cs is None:
            offers = [k for k, i in (("Model Exchange", self.md.modelExchange),
                                     ("Scheduled Execution", getattr(self.md, "scheduledExecution", None))) if i]
            raise ValueError(f"component {name!r}: {path} is not a Co-Simulation FMU"
                             + (f" (it offers {' and '.join(offers)} only)" if offers else "") + ".")
        if not IDENTIFIER.match(cs.modelIdentifier or ""):
            raise ValueError(f"component {name!r} ({os.path.basename(path)}): modelIdentifier "
                             f"{cs.modelIdentifier!r} is not a plain identifier; it names the binary inside the "
                             "FMU and is never a path.")
        self.variables = {v.name: v for v in self.md.modelVariables}
        clocks = [v.name for v in self.md.modelVariables if v.type == "Clock"]
        if clocks:
            raise ValueError(f"{where}: it has clocks ({', '.join(clocks[:5])}{' ...' if len(clocks) > 5 else ''}); "
                             "FMI 3.0 Co-Simulation with clocks needs Event Mode (eventModeUsed = true), which this "
                             "master does not run; refused.")
        os.makedirs(unzipdir, exist_ok=True)
        self.unzipdir = unzip(path, unzipdir, max_unpacked, where=f"component {name!r} ({os.path.basename(path)})")
        folder, library, found = _fmi.binary_folder(self.unzipdir, self.md)
        if library is None:
            raise ValueError(f"{where}: no binary {cs.modelIdentifier} for this platform in binaries/{folder}/ (FMI "
                             f"{version}); the FMU has binaries/{found}.")
        _check_python_model(name, path, self.unzipdir)
        self.terminals = _fmi.terminals(self.unzipdir) if self.is_fmi3 else {}
        # FMI 3.0 Co-Simulation has no input derivatives (canInterpolateInputs is FMI 2.0 only)
        self.can_interpolate = bool(cs.canInterpolateInputs) and not self.is_fmi3
        self.max_derivative = int(cs.maxOutputDerivativeOrder or 0)
        self.can_rollback = bool(cs.canGetAndSetFMUstate)
        self.provides_partials = _fmi.provides_directional_derivatives(self.md, self.unzipdir)
        self.units = _units.fmu_units(self.md)
        # (kind, value reference) -> variable: FMI 2.0 references are unique per type (an Enumeration shares
        # the Integers'), FMI 3.0 references over all types
        self.by_ref = {(self._kind(v), v.valueReference): v for v in self.md.modelVariables}
        self.maps, self.map_names = {}, {}  # connected Real input reference -> _units.Affine from its source's unit
        self.coupled = set()  # value references of the connected outputs (their values travel as doubles)
        try:
            self.fmu = _fmi.slave_class(self.is_fmi3)(guid=self.md.guid, unzipDirectory=self.unzipdir,
                                                      modelIdentifier=cs.modelIdentifier, instanceName=name)
        except Exception as exc:  # noqa: BLE001 -- fmpy raises a bare Exception when the library does not load
            raise RuntimeError(f"{where}: its binary does not load ({exc}).") from None
        # output -> inputs it depends on directly (None in the XML: every input)
        inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]
        self.feedthrough = {}
        for unknown in self.md.outputs:
            deps = unknown.dependencies
            self.feedthrough[unknown.variable.name] = (
                list(inputs) if deps is None else [d.name for d in deps if d.causality == "input"])

    def start(self, callbacks, logger, early_return=False):
        """Instantiate the FMU: FMI 2.0 with ``callbacks`` (the process-wide structure), FMI 3.0 with
        ``logger(status, message)`` (without Event Mode or intermediate update; with early return if
        ``early_return``)."""
        self.early_return = bool(early_return)
        try:
            # logging on: pythonfmu FMUs pass their messages (errors included) to the logger only then
            self.fmu.start(callbacks, logger, early_return=self.early_return)
        except Exception as exc:  # noqa: BLE001 -- fmpy raises a bare Exception when instantiation fails
            raise RuntimeError(f"{self.where}: {self.fmu.prefix}Instantiate"
                               f"{'CoSimulation' if self.is_fmi3 else ''} failed ({exc}).") from None
        self.started = True

    def free(self):
        """Terminate and free the instance (or unload the library of one never instantiated); never raises."""
        fmu = getattr(self, "fmu", None)
        if fmu is None:
            return
        if self.started:
            if self.initialized:  # (fmi2Terminate / fmi3Terminate are refused before initialization)
                try:
                    fmu.terminate()
                except Exception:  # noqa: BLE001 -- a failed FMU may refuse; freeing it is what matters
                    pass
            try:
                fmu.freeInstance()
            except Exception:  # noqa: BLE001
                pass
        else:
            try:
                fmu.freeLibrary()
            except Exception:  # noqa: BLE001
                pass
        self.started, self.initialized, self.fmu = False, False, None

    def _kind(self, v):
        return _fmi.KINDS.get(_fmi.access_type(v, self.is_fmi3), v.type)

    def variable(self, name, causality=None):
        """The variable ``name`` (refused: none, another causality, an array)."""
        v = self.variables.get(name)
        if v is None and name in self.terminals:
            members = self.terminals[name]
            raise ValueError(f"{self.name}.{name} is a terminal of the FMU (terminalsAndIcons.xml), a group of "
                             f"variables ({', '.join(members[:5]) or 'none'}{' ...' if len(members) > 5 else ''}); "
                             "this master connects, sets and records variables, not terminals: name its member "
                             "variables; refused.")
        if v is None:
            raise ValueError(f"component {self.name!r} has no variable {name!r}.")
        if causality and v.causality != causality:
            raise ValueError(f"{self.name}.{name} must be an {causality}; it is a {v.causality}.")
        check_scalar(self.name, v)
        return v

    def wire(self, name):
        """The kind a variable travels as: Real, Integer (an Enumeration too), Boolean, String or Binary."""
        return self._kind(self.variable(name))

    def access(self, name):
        """The FMI type of the getter and setter of variable ``name`` (`_fmi.access_type`)."""
        return _fmi.access_type(self.variable(name), self.is_fmi3)

    def dtype(self, name):
        """The NumPy type of the result field of variable ``name``."""
        return _fmi.dtype(self.access(name))

    def function(self, verb, kind, refs=()):
        """The FMI function(s) a get or set of ``refs`` of ``kind`` calls, for messages."""
        if not self.is_fmi3:
            return f"fmi2{verb}{kind}"
        types = sorted({self._type_of(kind, r) for r in refs}) or [kind]
        return "/".join(f"fmi3{verb}{t}" for t in types)

    def _type_of(self, kind, ref):
        v = self.by_ref.get((kind, ref))
        return _fmi.access_type(v, True) if v is not None else kind

    def _groups(self, kind, refs):
        """``{access type: [positions in refs]}`` (FMI 2.0: one group, the kind)."""
        if not self.is_fmi3:
            return {kind: list(range(len(refs)))}
        groups = {}
        for i, r in enumerate(refs):
            groups.setdefault(self._type_of(kind, r), []).append(i)
        return groups

    def get(self, kind, refs):
        """Values of the value references ``refs`` of one kind, each through the getter of its type."""
        refs, out = list(refs), [None] * len(refs)
        for fmi_type, where in self._groups(kind, refs).items():
            chunk = [refs[i] for i in where]
            getter = getattr(self.fmu, "get" + fmi_type)
            for i, r, x in zip(where, chunk, getter(chunk)):
                out[i] = self._read(kind, fmi_type, r, x)
        return out

    def _read(self, kind, fmi_type, ref, x):
        if kind == "Real":
            return float(x)
        if kind == "String":
            return x.decode(errors="replace") if isinstance(x, bytes) else x
        if kind == "Binary":
            return bytes(x) if x is not None else b""
        x = int(x)
        if kind == "Integer" and ref in self.coupled and abs(x) > EXACT_IN_DOUBLE:
            name = self.by_ref[(kind, ref)].name
            raise _fmi.refused(f"{self.fmu.prefix}Get{fmi_type}",
                               f"{self.name}.{name} = {x} is beyond 2^53: a connected integer travels through the "
                               "master's coupling values, doubles exact to 2^53; refused rather than rounded")
        return x

    def set(self, kind, refs, values):
        """Set values of one kind; a connected Real input's value is in its source's unit (converted)."""
        refs, values = list(refs), list(values)
        if kind == "Real" and self.maps:
            values = [self._converted(r, v, False) for r, v in zip(refs, values)]
        self._set(kind, refs, values)

    def set_start(self, kind, refs, values):
        """Like `set`, with values in the variables' own units (start values, not connection values)."""
        self._set(kind, list(refs), list(values))

    def set_input_derivatives(self, refs, order, values):
        """``fmi2SetRealInputDerivatives`` of order ``order``, each scaled into its input's unit."""
        refs = list(refs)
        if self.maps:
            values = [self._converted(r, v, True) for r, v in zip(refs, values)]
        self.fmu.setRealInputDerivatives(refs, [order] * len(refs), [float(v) for v in values])

    def directional(self, unknowns, knowns, seed):
        """``fmi2GetDirectionalDerivative`` / ``fmi3GetDirectionalDerivative``: the change of the outputs
        ``unknowns`` for the change ``seed`` of the inputs ``knowns`` (value references; each in its variable's
        own unit)."""
        return [float(x) for x in self.fmu.getDirectionalDerivative(list(unknowns), list(knowns),
                                                                    [float(v) for v in seed])]

    def _converted(self, ref, v, derivative):
        m = self.maps.get(ref)
        if m is None:
            return v
        x = m.scale * v if derivative else m(v)
        if math.isfinite(v) and not math.isfinite(x):
            raise _fmi.refused(f"{self.fmu.prefix}SetReal", f"the {'derivative' if derivative else 'value'} {v!r} "
                               f"converted to the unit of the input {self.map_names.get(ref, ref)} is {x!r}, beyond "
                               "the range of a double")
        return x

    def _set(self, kind, refs, values):
        for fmi_type, where in self._groups(kind, refs).items():
            chunk = [refs[i] for i in where]
            typed = [self._typed(kind, fmi_type, refs[i], values[i]) for i in where]
            getattr(self.fmu, "set" + fmi_type)(chunk, typed)

    def _typed(self, kind, fmi_type, ref, v):
        """``v`` as the setter of ``fmi_type`` takes it; what ctypes would wrap or make infinite is refused."""
        if kind == "Real":
            v = float(v)
            if fmi_type == "Float32" and math.isfinite(v) and abs(v) > FLOAT32_MAX:
                raise _fmi.refused("fmi3SetFloat32", f"{self._name(kind, ref)}: {v!r} is beyond the range of a "
                                   f"Float32 (magnitudes up to {FLOAT32_MAX!r})")
            return v  # non-finite values are passed on: the FMU must reject them
        if kind == "Integer":
            if isinstance(v, (float, np.floating)) and math.isfinite(v) and v == int(v):
                v = int(v)  # a coupling value (exact: connected integers are checked within 2^53 when read)
            try:
                return convert(v, fmi_type, self._name(kind, ref))
            except ValueError as exc:
                raise _fmi.refused(f"{self.fmu.prefix}Set{fmi_type}", str(exc)) from None
        if kind == "Boolean":
            return bool(v)
        if kind == "Binary":
            return bytes(v)
        return str(v)

    def _name(self, kind, ref):
        v = self.by_ref.get((kind, ref))
        return f"{self.name}.{v.name if v is not None else ref}"


def check_scalar(component, v):
    """Refuse an array variable (FMI 3.0 ``<Dimension>``): the master exchanges, records and sets scalars."""
    if getattr(v, "dimensions", None):
        shape = "x".join(str(d.start) if d.start is not None else (d.variable.name if d.variable else "?")
                         for d in v.dimensions)
        raise ValueError(f"{component}.{v.name} is an array ({v.type}[{shape}]); this master exchanges, records and "
                         "sets scalar variables only; refused.")


_SSP_KINDS = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean", "String": "String"}


def ssp_type_matches(ssp_type, variable):
    """Whether an SSP connector or parameter type fits an FMU variable: SSP 1.0 names kinds (a Real is a
    Float32 or Float64 of FMI 3.0, an Integer any integer type, an Enumeration an Enumeration), an FMI 3.0
    type name must be the variable's own."""
    if ssp_type in _SSP_KINDS and variable.type != "Enumeration":
        return _fmi.KINDS.get(variable.type) == ssp_type
    return ssp_type == variable.type


def check_types(comps, connections, connectors=None, where="`system`", system=None):
    """Causality, type and unit agreement of every connection and SSD connector (before anything runs).

    Units (``system``: the `System` read, for its unit definitions, connector units and connections with
    ``suppressUnitConversion``): each connector's unit must convert to its FMU variable's; each connection
    between different units gets the affine map from the source's unit to the input's (`_units.conversion`),
    installed on the input's FMU; one that cannot be converted is refused naming both units.
    """
    for (c, name), kind in (connectors or {}).items():
        v = comps[c].variables.get(name)
        if v is not None and not ssp_type_matches(kind, v):
            raise ValueError(f"{where}: connector {c}.{name} is declared {kind} in the SSD; the FMU's {name} is "
                             f"{v.type}.")
    for a, y, b, u in connections:
        src, dst = comps[a].variable(y, "output"), comps[b].variable(u, "input")
        kind_src, kind_dst = comps[a].wire(y), comps[b].wire(u)
        if kind_src != kind_dst:
            raise ValueError(f"connection {a}.{y} -> {b}.{u}: a {src.type} output cannot feed a {dst.type} input; "
                             "connected variables must be of one kind (Real: Float32, Float64; Integer: the integer "
                             "types and Enumeration; Boolean).")
        if src.type == "Enumeration" and dst.type == "Enumeration":
            ta, tb = (v.declaredType.name if v.declaredType is not None else None for v in (src, dst))
            if ta != tb:
                raise ValueError(f"connection {a}.{y} -> {b}.{u}: enumeration type {ta!r} cannot feed enumeration "
                                 f"type {tb!r}; their items mean different things.")
        if kind_src in ("String", "Binary"):
            raise ValueError(f"connection {a}.{y} -> {b}.{u}: {src.type} connections are not exchanged by this "
                             "master (set and record them instead).")
        comps[a].coupled.add(src.valueReference)
    _check_units(comps, connections, where, system)


def _check_time(c, definitions, where):
    """The master steps in seconds and input derivatives are per second: an FMU whose independent variable is
    in another unit (FMI 2.0 allows one) is refused."""
    for v in c.md.modelVariables:
        name = _units.variable_unit(v) if v.causality == "independent" else None
        if name is None:
            continue
        unit = definitions.lookup(name)
        if (unit is None and name != "s") or (unit is not None and not unit.same(_units.SECOND)):
            found = "no file defines it" if unit is None else unit.describe()
            raise ValueError(f"{where}: component {c.name!r}: its time {v.name!r} is in unit {name!r} ({found}); "
                             "the master steps in seconds (s); refused.")


def _check_units(comps, connections, where, system):
    """Connector units against their variables', the time of every FMU, and the map of every connection (see
    `check_types`)."""
    ssp_units = getattr(system, "units", {}) or {}
    connector_units = getattr(system, "connector_units", {}) or {}
    unconverted = getattr(system, "unconverted", set()) or set()
    transformations = getattr(system, "transformations", {}) or {}

    def definitions(*names):
        return _units.Definitions((where, ssp_units), *((f"the FMU of {n}", comps[n].units) for n in names))

    for n, c in comps.items():
        _check_time(c, definitions(n), where)

    for (c, name), unit in connector_units.items():
        v = comps[c].variables.get(name)
        if v is not None:  # a connector of no variable is refused where it is used
            _units.conversion(unit, _units.variable_unit(v), definitions(c),
                              f"{where}: connector {c}.{name}", _units.is_relative(v))
    for c in comps.values():
        c.maps, c.map_names = {}, {}
    for a, y, b, u in connections:
        src, dst = comps[a].variable(y, "output"), comps[b].variable(u, "input")
        what = f"{where}: connection {a}.{y} -> {b}.{u}"
        if comps[a].wire(y) != "Real":
            if (b, u) in transformations:
                raise ValueError(f"{what}: a LinearTransformation applies to Real values; this connection is "
                                 f"{src.type}; refused.")
            continue
        defs = definitions(a, b)
        unit_src, unit_dst = _units.variable_unit(src), _units.variable_unit(dst)
        at_src, at_dst = connector_units.get((a, y), unit_src), connector_units.get((b, u), unit_dst)
        # the value leaves the output in its unit, is presented in the start connector's, arrives in the end
        # connector's (unconverted with suppressUnitConversion: the numbers pass as they are), is transformed
        # there by the connection's LinearTransformation (SSP 1.0: after the conversion, in the end connector's
        # unit) and is set in the input's unit
        steps = [(unit_src, at_src), (at_dst, unit_dst)]
        if (b, u) not in unconverted:
            steps.insert(1, (at_src, at_dst))
        else:
            # "the environment will not perform any automatic unit conversions": a connector in another unit than
            # its variable's would need one; which the file means cannot be told
            for (c, v), unit, own in (((a, y), at_src, unit_src), ((b, u), at_dst, unit_dst)):
                if unit is not None and own is not None and unit != own:
                    raise ValueError(f"{what}: suppressUnitConversion, but connector {c}.{v} is in unit {unit!r} and "
                                     f"its variable in unit {own!r}: that conversion would be done although the file "
                                     "suppresses conversions; refused.")
        transformation = transformations.get((b, u), _units.IDENTITY)

        def through(relative):
            maps = [_units.conversion(frm, to, defs, what, relative) for frm, to in steps]
            return _units.compose(maps[:-1] + [transformation] + maps[-1:], what)

        rel_src, rel_dst = _units.is_relative(src), _units.is_relative(dst)
        total = through(rel_src and rel_dst)
        if rel_src != rel_dst and through(True) != through(False):
            raise ValueError(f"{what}: one side is a relative quantity (a difference), the other not, and their "
                             f"units {unit_src!r} and {unit_dst!r} differ by an offset; refused.")
        if not total.is_identity:
            ref = comps[b].variables[u].valueReference
            comps[b].maps[ref], comps[b].map_names[ref] = total, f"{b}.{u}"
