"""One FMU instance and typed access to its variables.

FMI 2.0 value references are unique per type only (a Real and a Boolean may
share reference 7): every read and write goes through the getter and setter of
the variable's type, and a value is converted to that type by rules that
refuse what they cannot interpret (``"false"`` is False, ``0.3`` is no
Boolean, ``2.5`` is no Integer).

A connection between variables of different units carries an affine map (`_units`): the master's
coupling values stay in the source output's unit, and every value or input derivative set on the
connected input is converted to the input's unit there (`_slave_class`); start values are in the variable's
own unit (`Component.set_start`).
"""

import os
import zipfile

from .._values import FMIValueError, fmi_value
from . import _units
from ._system import IDENTIFIER, unzip

# types a connection may join (Enumeration values are Integers on the wire, as in libcosim)
WIRE = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer", "Boolean": "Boolean", "String": "String"}


def convert(value, kind, what):
    """``value`` as an FMI ``kind`` value (the rules of `fmu_build._values.fmi_value`), or ValueError naming ``what``.

    Examples
    --------
    >>> convert("false", "Boolean", "x"), convert(1, "Boolean", "x"), convert("3", "Integer", "x")
    (False, True, 3)
    >>> convert(0.3, "Boolean", "b")
    Traceback (most recent call last):
    ...
    ValueError: b: a Boolean must be True/False, 1/0 or 'true'/'false'; found 0.3.
    """
    try:
        return fmi_value(value, kind)
    except FMIValueError as exc:
        raise ValueError(f"{what}: {exc}; found {value!r}.") from None


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


def _slave_class():
    """fmpy's FMI 2.0 Co-Simulation slave whose connected Real inputs take values in the source's unit."""
    import math

    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    class ConversionOverflow(FMICallException):
        """A finite value that a connection's unit map takes beyond the range of a double (the master stops
        there, as on a failed call, rather than set inf)."""

        def __init__(self, function, text):
            Exception.__init__(self, text)
            self.function, self.status = function, 3

    class FMU2SlaveWithUnits(FMU2Slave):  # (fmpy picks the FMI version's functions by the name's prefix)
        """Values and input derivatives set on a value reference of ``wire`` (an input -> `_units.Affine` from
        its connection's source unit) are converted: a value by the map, a derivative by its scale."""

        wire, wire_names = {}, {}

        def _converted(self, function, vr, value, derivative):
            wire, out = self.wire, []
            for r, v in zip(vr, value):
                m = wire.get(r)
                x = v if m is None else m.scale * v if derivative else m(v)
                if m is not None and math.isfinite(v) and not math.isfinite(x):
                    raise ConversionOverflow(function, f"the {'derivative' if derivative else 'value'} {v!r} "
                                             f"converted to the unit of the input {self.wire_names.get(r, r)} is "
                                             f"{x!r}, beyond the range of a double")
                out.append(x)
            return out

        def setReal(self, vr, value):
            if self.wire:
                value = self._converted("fmi2SetReal", vr, value, False)
            return super().setReal(vr, value)

        def setRealInputDerivatives(self, vr, order, value):
            if self.wire:
                value = self._converted("fmi2SetRealInputDerivatives", vr, value, True)
            return super().setRealInputDerivatives(vr, order, value)

        def set_own(self, vr, value):
            """Values in the variables' own units (start values)."""
            return super().setReal(vr, value)

    return FMU2SlaveWithUnits


class Component:
    """One FMU instance, what the master knows of it, and typed get/set by value reference."""

    def __init__(self, name, path, unzipdir, callbacks, max_unpacked):
        from fmpy import read_model_description

        self.name, self.path = name, path
        where = f"component {name!r} ({path})"
        if not os.path.isfile(path):
            raise ValueError(f"{where}: no such FMU file.")
        if not zipfile.is_zipfile(path):
            raise ValueError(f"{where}: not an FMU (an FMU is a zip archive).")
        try:
            self.md = read_model_description(path)
        except Exception as exc:  # noqa: BLE001 -- fmpy raises bare Exceptions for invalid descriptions
            raise ValueError(f"{where}: invalid modelDescription.xml ({exc}).") from None
        cs = self.md.coSimulation
        if cs is None:
            raise ValueError(f"component {name!r}: {path} is not a Co-Simulation FMU.")
        os.makedirs(unzipdir, exist_ok=True)
        self.unzipdir = unzip(path, unzipdir, max_unpacked, where=f"component {name!r} ({os.path.basename(path)})")
        self.variables = {v.name: v for v in self.md.modelVariables}
        _check_python_model(name, path, self.unzipdir)
        self.can_interpolate = bool(cs.canInterpolateInputs)
        self.max_derivative = int(cs.maxOutputDerivativeOrder or 0)
        self.can_rollback = bool(cs.canGetAndSetFMUstate)
        if not IDENTIFIER.match(cs.modelIdentifier or ""):
            raise ValueError(f"component {name!r} ({os.path.basename(path)}): modelIdentifier "
                             f"{cs.modelIdentifier!r} is not a plain identifier; it names the binary inside the "
                             "FMU and is never a path.")
        self.units = _units.fmu_units(self.md)
        self.fmu = _slave_class()(guid=self.md.guid, unzipDirectory=self.unzipdir, modelIdentifier=cs.modelIdentifier,
                                  instanceName=name)
        # logging on: pythonfmu FMUs pass their messages (errors included) to the logger only then
        try:
            self.fmu.instantiate(callbacks=callbacks, loggingOn=True)
        except Exception as exc:  # noqa: BLE001 -- fmpy raises a bare Exception when fmi2Instantiate fails
            self.fmu = None
            raise RuntimeError(f"{where}: fmi2Instantiate failed ({exc}).") from None
        # output -> inputs it depends on directly (None in the XML: every input)
        inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]
        self.feedthrough = {}
        for unknown in self.md.outputs:
            deps = unknown.dependencies
            self.feedthrough[unknown.variable.name] = (
                list(inputs) if deps is None else [d.name for d in deps if d.causality == "input"])

    def variable(self, name, causality=None):
        v = self.variables.get(name)
        if v is None:
            raise ValueError(f"component {self.name!r} has no variable {name!r}.")
        if causality and v.causality != causality:
            raise ValueError(f"{self.name}.{name} must be an {causality}; it is a {v.causality}.")
        return v

    def wire(self, name):
        """The type a variable travels as (Enumeration as Integer)."""
        return WIRE[self.variable(name).type]

    def get(self, kind, refs):
        """Values of the value references ``refs`` of one wire type."""
        fmu = self.fmu
        getter = {"Real": fmu.getReal, "Integer": fmu.getInteger, "Boolean": fmu.getBoolean,
                  "String": fmu.getString}[kind]
        values = getter(list(refs))
        if kind == "String":
            return [v.decode(errors="replace") if isinstance(v, bytes) else v for v in values]
        return [float(v) if kind == "Real" else int(v) for v in values]

    def set(self, kind, refs, values):
        """Set values of one wire type; a connected Real input's value is in its source's unit (converted)."""
        fmu = self.fmu
        if kind == "Real":
            fmu.setReal(list(refs), [float(v) for v in values])
        elif kind == "Integer":
            fmu.setInteger(list(refs), [int(v) for v in values])
        elif kind == "Boolean":
            fmu.setBoolean(list(refs), [bool(v) for v in values])
        else:
            fmu.setString(list(refs), [str(v) for v in values])

    def set_start(self, kind, refs, values):
        """Like `set`, with values in the variables' own units (start values, not connection values)."""
        if kind == "Real":
            self.fmu.set_own(list(refs), [float(v) for v in values])
        else:
            self.set(kind, refs, values)


def check_types(comps, connections, connectors=None, where="`system`", system=None):
    """Causality, type and unit agreement of every connection and SSD connector (before anything runs).

    Units (``system``: the `System` read, for its unit definitions, connector units and connections with
    ``suppressUnitConversion``): each connector's unit must convert to its FMU variable's; each connection
    between different units gets the affine map from the source's unit to the input's (`_units.conversion`),
    installed on the input's FMU; one that cannot be converted is refused naming both units.
    """
    for (c, name), kind in (connectors or {}).items():
        v = comps[c].variables.get(name)
        if v is not None and v.type != kind:
            raise ValueError(f"{where}: connector {c}.{name} is declared {kind} in the SSD; the FMU's {name} is "
                             f"{v.type}.")
    for a, y, b, u in connections:
        src, dst = comps[a].variable(y, "output"), comps[b].variable(u, "input")
        if WIRE[src.type] != WIRE[dst.type]:
            raise ValueError(f"connection {a}.{y} -> {b}.{u}: a {src.type} output cannot feed a {dst.type} input; "
                             "connected variables must have the same type.")
        if src.type == "Enumeration" and dst.type == "Enumeration":
            ta, tb = (v.declaredType.name if v.declaredType is not None else None for v in (src, dst))
            if ta != tb:
                raise ValueError(f"connection {a}.{y} -> {b}.{u}: enumeration type {ta!r} cannot feed enumeration "
                                 f"type {tb!r}; their items mean different things.")
        if src.type == "String":
            raise ValueError(f"connection {a}.{y} -> {b}.{u}: String connections are not exchanged by this master.")
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
        c.fmu.wire, c.fmu.wire_names = {}, {}
    for a, y, b, u in connections:
        src, dst = comps[a].variable(y, "output"), comps[b].variable(u, "input")
        what = f"{where}: connection {a}.{y} -> {b}.{u}"
        if src.type != "Real":
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
            comps[b].fmu.wire[ref], comps[b].fmu.wire_names[ref] = total, f"{b}.{u}"
