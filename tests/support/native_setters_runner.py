"""Every setter on every variable in every state of an instance, on the FMI 2.0 and 3.0 builds of one spec.

Used by test_native_fmi3_setters.py; reads {"fmus": {"2": path, "3": path}, "interface": "CS" | "ME"} from
stdin and prints one JSON object {"2": trace, "3": trace}. A trace maps "variable|value|state" to what
followed on a fresh instance: the setter's status in that state, every variable read back, and the rest of
the instance's life (initialization, one step or one derivative evaluation, every variable again,
termination), each with its status. Values are float.hex strings, so the two traces compare bit for bit.
"empty|<type>|<state>" is the status of a setter called with no value references (the state check
alone); an FMI 3.0 trace also has it for every FMI 3.0 setter ("fmi3 only|<type>|<state>"), and the status
of every setter of another type on every variable ("fmi3 only|foreign|<variable>|<type>").
"""
import json
import math
import sys
from ctypes import (c_bool, c_char_p, c_double, c_float, c_int, c_int8, c_int16, c_int32, c_int64, c_size_t,
                    c_uint8, c_uint16, c_uint32, c_uint64)

CS_STATES = ("instantiated", "initialization", "step", "terminated")
ME_STATES = ("instantiated", "initialization", "event", "continuous", "terminated")
FMI3_SETTERS = ("Float64", "Float32", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
                "Boolean", "String")
CTYPES3 = {"Float64": c_double, "Float32": c_float, "Int8": c_int8, "UInt8": c_uint8, "Int16": c_int16,
           "UInt16": c_uint16, "Int32": c_int32, "UInt32": c_uint32, "Int64": c_int64, "UInt64": c_uint64,
           "Boolean": c_bool, "String": c_char_p}


def _hex(x):
    return "nan" if math.isnan(x) else float(x).hex()


class Api:
    """Raw calls (status codes, no exceptions) on one instance of one FMI version."""

    def __init__(self, path, version, interface):
        from fmpy import extract, read_model_description

        self.version, self.interface = version, interface
        self.md = read_model_description(path)
        self.unzipped = extract(path)
        self.logs = []
        mi = (self.md.coSimulation if interface == "CS" else self.md.modelExchange).modelIdentifier
        self.kw = dict(guid=self.md.guid, unzipDirectory=self.unzipped, modelIdentifier=mi, instanceName="setters")
        self.nx = len(self.md.derivatives)

    def new(self):
        if self.version == 2:
            from fmpy.fmi2 import FMU2Model, FMU2Slave

            fmu = (FMU2Slave if self.interface == "CS" else FMU2Model)(**self.kw)
            fmu.instantiate(loggingOn=False)
        else:
            from fmpy.fmi3 import FMU3Model, FMU3Slave

            fmu = (FMU3Slave if self.interface == "CS" else FMU3Model)(**self.kw)
            fmu.instantiate(logMessage=lambda env, status, category, message: self.logs.append(message))
        self.fmu, self.f, self.c = fmu, fmu._functions, fmu.component
        return self

    def call(self, name, *args):
        return int(self.f[f"fmi{self.version}{name}"](self.c, *args))

    def free(self):
        self.f[f"fmi{self.version}FreeInstance"](self.c)
        self.fmu.freeLibrary()

    # -- life cycle
    def enter_init(self):
        if self.version == 2:
            s = self.call("SetupExperiment", False, 0.0, 0.0, False, 0.0)
            return s if s > 1 else self.call("EnterInitializationMode")
        return self.call("EnterInitializationMode", False, 0.0, 0.0, False, 0.0)

    def exit_init(self):
        return self.call("ExitInitializationMode")

    def to_continuous(self):
        if self.version == 2:
            from fmpy.fmi2 import fmi2EventInfo

            from ctypes import byref

            info = fmi2EventInfo()
            s = self.call("NewDiscreteStates", byref(info))
        else:
            from ctypes import byref

            flags, t = [c_bool() for _ in range(5)], c_double()
            s = self.call("UpdateDiscreteStates", *map(byref, flags), byref(t))
        return s if s > 1 else self.call("EnterContinuousTimeMode")

    def step(self):
        """One step of 0.1 (Co-Simulation) or the derivatives at t = 0.1 (Model Exchange): status and values."""
        from ctypes import byref

        if self.interface == "CS":
            if self.version == 2:
                return [self.call("DoStep", 0.0, 0.1, True)]
            flags, last = [c_bool() for _ in range(3)], c_double()
            return [self.call("DoStep", 0.0, 0.1, True, *map(byref, flags), byref(last))]
        der = (c_double * self.nx)()
        s = self.call("SetTime", 0.1)
        name = "GetDerivatives" if self.version == 2 else "GetContinuousStateDerivatives"
        return [s, self.call(name, der, self.nx), [_hex(v) for v in der]]

    def terminate(self):
        return self.call("Terminate")

    # -- get and set
    def set(self, kind, vr, value):
        refs = (c_uint32 * 1)(vr)
        if kind == "Real":
            name = "SetReal" if self.version == 2 else "SetFloat64"
            values = (c_double * 1)(value)
        else:
            name = "SetBoolean"
            values = (c_int * 1)(int(value)) if self.version == 2 else (c_bool * 1)(bool(value))
        return self.call(name, refs, 1, values) if self.version == 2 else self.call(name, refs, 1, values, 1)

    def read(self, variables):
        out = {}
        for name, kind, vr in variables:
            refs = (c_uint32 * 1)(vr)
            if kind == "Real":
                v = (c_double * 1)(-1.0)
                s = (self.call("GetReal", refs, 1, v) if self.version == 2 else self.call("GetFloat64", refs, 1, v, 1))
                out[name] = [s, _hex(v[0]) if s <= 1 else None]
            else:
                v = (c_int * 1)(7) if self.version == 2 else (c_bool * 1)(True)
                s = self.call("GetBoolean", refs, 1, v) if self.version == 2 else self.call("GetBoolean", refs, 1, v, 1)
                out[name] = [s, bool(v[0]) if s <= 1 else None]
        return out

    def foreign_set(self, setter, vr):
        """fmi3Set<setter> of one value on ``vr`` (a variable of another type): its status."""
        refs = (c_uint32 * 1)(vr)
        if setter == "Binary":
            from ctypes import cast

            from fmpy.fmi3 import fmi3Binary

            data = (c_uint8 * 1)(120)
            values = (fmi3Binary * 1)(cast(data, fmi3Binary))
            return int(self.f["fmi3SetBinary"](self.c, refs, 1, (c_size_t * 1)(1), values, 1))
        values = (CTYPES3[setter] * 1)()
        if setter == "String":
            values[0] = b"x"
        return int(self.f[f"fmi3Set{setter}"](self.c, refs, 1, values, 1))

    def empty_set(self, setter):
        """A setter with no value references: the state check alone."""
        name = {"Real": "Real" if self.version == 2 else "Float64"}.get(setter, setter)
        args = (None, 0, None) if self.version == 2 else (None, 0, None, 0)
        return int(self.f[f"fmi{self.version}Set{name}"](self.c, *args))


def variables(md):
    """(name, kind, value reference) of every variable but the independent variable, Real or Boolean."""
    out = []
    for v in md.modelVariables:
        if v.causality == "independent":
            continue
        kind = {"Real": "Real", "Float64": "Real", "Boolean": "Boolean"}[v.type]
        out.append((v.name, kind, v.valueReference))
    return sorted(out)


def values_for(name, kind, start):
    if kind == "Boolean":
        return [True, False]
    return [(0.0 if start is None else float(start)) + 0.75, math.nan, -1.0]


def transition(api, state):
    """The call that enters ``state`` from the one before it; its status."""
    return {"initialization": api.enter_init, "step": api.exit_init, "event": api.exit_init,
            "continuous": api.to_continuous, "terminated": api.terminate}[state]()


def trace(path, version, interface):
    api = Api(path, version, interface)
    states = CS_STATES if interface == "CS" else ME_STATES
    vars_ = variables(api.md)
    starts = {v.name: v.start for v in api.md.modelVariables}
    out = {}
    for name, kind, vr in vars_:
        for value in values_for(name, kind, starts.get(name)):
            for k, state in enumerate(states):
                api.new()
                events = [[s, transition(api, s)] for s in states[1:k + 1]]
                events.append(["set", api.set(kind, vr, value)])
                events.append(["read", api.read(vars_)])
                for s in states[k + 1:]:
                    if s == "terminated":  # the rest of the life: one step, every variable again
                        events.append(["step", api.step()])
                        events.append(["read", api.read(vars_)])
                    events.append([s, transition(api, s)])
                api.free()
                out[f"{name}|{value}|{state}"] = events
    for k, state in enumerate(states):
        api.new()
        for s in states[1:k + 1]:
            transition(api, s)
        for setter in ("Real", "Boolean"):
            out[f"empty|{setter}|{state}"] = api.empty_set(setter)
        if version == 3:
            out.update({f"fmi3 only|{setter}|{state}": api.empty_set(setter) for setter in FMI3_SETTERS})
        api.free()
    if version == 3:  # every setter of another type on every variable: refused, nothing changed
        api.new()
        before = api.read(vars_)
        for name, kind, vr in vars_:
            own = "Float64" if kind == "Real" else "Boolean"
            for setter in (*FMI3_SETTERS, "Binary"):
                if setter != own:
                    out[f"fmi3 only|foreign|{name}|{setter}"] = api.foreign_set(setter, vr)
        out["fmi3 only|foreign|unchanged"] = api.read(vars_) == before
        api.free()
    return out


def main():
    sc = json.loads(sys.stdin.read())
    out, sys.stdout = sys.stdout, sys.stderr  # fmpy's FMI 2.0 logger prints: the messages go to stderr
    result = {v: trace(path, int(v), sc["interface"]) for v, path in sc["fmus"].items()}
    out.write(json.dumps(result) + "\n")


if __name__ == "__main__":
    main()
