"""Run a built FMU in this (fresh) process and report JSON: used by test_fmu.py.

Reads a scenario from stdin:
  {"fmu": path, "start_values": {...}, "t0": 0, "dt": 0.1, "steps": N,
   "set_at": {"i": {name: value}}, "outputs": [...], "rollback_at": i,
   "block": ["lsc", "sympy"], "input_series": {name: [value at each step start]}}
and prints {"time", "values", "status", "logs", "rollback"}.
FMUs are exercised in a subprocess because a pythonfmu FMU loaded into a
process that already imported its modules silently runs the host's copy.
"""
import json
import sys

from helpers import ImportBlocker


def main():
    sc = json.load(sys.stdin)
    if sc.get("block"):
        sys.meta_path.insert(0, ImportBlocker(sc["block"]))
    from ctypes import byref

    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, defaultCallbacks
    from fmpy.logging import addLoggerProxy

    logs = []

    def logger(env, instance, status, category, message):
        logs.append(message.decode("utf-8", "replace"))
        statuses.append(status)

    statuses = []  # the fmi2Status of each message, in step with logs

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    addLoggerProxy(byref(callbacks))

    if sc.get("side_by_side"):
        return side_by_side(sc)
    md = read_model_description(sc["fmu"])
    var = {v.name: v for v in md.modelVariables}
    unzipped = extract(sc["fmu"])
    if sc.get("probe_module_refcount"):
        return probe_module_refcount(md, unzipped, sc["probe_module_refcount"])
    if sc.get("probe_exit_hook"):
        return probe_exit_hook(md, unzipped, sc["probe_exit_hook"])
    if "calls" in sc:
        return run_calls(sc, md, var, unzipped, callbacks, logs, statuses)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="instance")
    fmu.instantiate(callbacks=callbacks, loggingOn=True)

    def set_values(values):
        for name, value in values.items():
            v = var[name]
            if v.type == "Real":
                fmu.setReal([v.valueReference], [float(value)])
            elif v.type == "Integer":
                fmu.setInteger([v.valueReference], [int(value)])
            else:
                fmu.setBoolean([v.valueReference], [bool(value)])

    outputs = sc["outputs"]

    def read():
        return fmu.getReal([var[n].valueReference for n in outputs])

    t, dt = sc.get("t0", 0.0), sc["dt"]
    fmu.setupExperiment(startTime=t)
    fmu.enterInitializationMode()
    set_values(sc.get("start_values", {}))
    fmu.exitInitializationMode()
    times, values, status, rollback = [t], [read()], [], None
    for i in range(sc["steps"]):
        if str(i) in sc.get("set_at", {}):
            set_values(sc["set_at"][str(i)])
        for name, series in sc.get("input_series", {}).items():
            set_values({name: series[i]})  # the input's value at this communication point
        if sc.get("rollback_at") == i:
            state = fmu.getFMUstate()
            blob = fmu.serializeFMUstate(state)
            fmu.doStep(t, dt)
            first = read()
            fmu.doStep(t + dt, dt)
            first2 = read()
            fmu.setFMUstate(fmu.deSerializeFMUstate(blob))
            fmu.doStep(t, dt)
            second = read()
            fmu.doStep(t + dt, dt)
            second2 = read()
            fmu.setFMUstate(state)
            rollback = {"first": [first, first2], "second": [second, second2]}
        try:
            fmu.doStep(t, dt)
            status.append("ok")
            t += dt
        except FMICallException as exc:
            status.append("discard" if exc.status == 2 else f"status {exc.status}")
        times.append(t)
        values.append(read())
    fmu.terminate()
    fmu.freeInstance()  # and unload the library, as fmpy.simulate_fmu does
    print(json.dumps({"time": times, "values": {n: [row[j] for row in values] for j, n in enumerate(outputs)},
                      "status": status, "logs": logs, "rollback": rollback}), flush=True)


def _status(call):
    """Run one FMI call; its fmi2Status as a number (0 ok, 2 discard, 3 error, 4 fatal) and its result."""
    from fmpy.fmi1 import FMICallException

    try:
        return 0, call()
    except FMICallException as exc:
        return exc.status, None


def _other_state(path):
    """The serialized state of another FMU, instantiated in this same process."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="other")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    blob = fmu.serializeFMUstate(fmu.getFMUstate())
    return fmu, bytes(blob)


def _mutated(blob, how, other):
    """A serialized state spoilt in one way (the bad inputs of setFMUstate)."""
    if how == "truncated":
        return blob[: len(blob) // 2]
    if how == "garbage":
        return b"\x00\xff" * 40
    if how == "empty_json":
        return b"{}"
    if how == "wrong_length":  # one state value too many
        state = json.loads(blob)
        state["x"] = state["x"] + [0.0]
        return json.dumps(state).encode()
    if how == "nan_time":
        state = json.loads(blob)
        state["t"] = float("nan")
        return json.dumps(state).encode()
    if how == "other_model":
        return other
    return blob


def run_calls(sc, md, var, unzipped, callbacks, logs, statuses):
    """Set up an instance as the scenario says, then make the listed calls and report each status.

    Each call is [name, args...] with names as fmpy spells the FMI functions
    (variables by name or by a raw value reference number). Prints
    {"results": [[status, value], ...], "logs": [...]}.
    """
    from fmpy.fmi2 import FMU2Slave

    other = _other_state(sc["other_fmu"]) if sc.get("other_fmu") else (None, None)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="instance")
    fmu.instantiate(callbacks=callbacks, loggingOn=True)

    def ref(name):
        return var[name].valueReference if isinstance(name, str) else int(name)

    saved = {}
    calls = {
        "setupExperiment": lambda t=0.0: fmu.setupExperiment(startTime=t),
        "enterInitializationMode": fmu.enterInitializationMode,
        "exitInitializationMode": fmu.exitInitializationMode,
        "setReal": lambda name, value: fmu.setReal([ref(name)], [float(value)]),
        "setInteger": lambda name, value: fmu.setInteger([ref(name)], [int(value)]),
        "setBoolean": lambda name, value: fmu.setBoolean([ref(name)], [bool(value)]),
        "setString": lambda name, value: fmu.setString([ref(name)], [value]),
        "getReal": lambda *names: fmu.getReal([ref(n) for n in names]),
        "getInteger": lambda *names: fmu.getInteger([ref(n) for n in names]),
        "getBoolean": lambda *names: fmu.getBoolean([ref(n) for n in names]),
        "doStep": lambda t, h: fmu.doStep(float(t), float(h)),
        "save": lambda: saved.update(blob=bytes(fmu.serializeFMUstate(fmu.getFMUstate()))),
        "restore": lambda how="valid": fmu.setFMUstate(fmu.deSerializeFMUstate(_mutated(saved["blob"], how, other[1]))),
        "terminate": fmu.terminate,
    }
    results = []
    for name, *args in sc["calls"]:
        status, value = _status(lambda: calls[name](*args))
        results.append([status, value if isinstance(value, (list, float, int)) else None])
    _status(fmu.terminate)
    fmu.freeInstance()
    if other[0] is not None:
        other[0].terminate()
        other[0].freeInstance()
    print(json.dumps({"results": results, "logs": logs, "log_statuses": statuses}), flush=True)


def side_by_side(sc):
    """Instantiate every FMU of sc["side_by_side"] (same model names allowed) in this process, step them
    in turns and print each one's outputs {"values": [[first output at each step end] per FMU]}."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    fmus = []
    for i, (path, output) in enumerate(sc["side_by_side"]):
        md = read_model_description(path)
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=f"fmu{i}")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        ref = next(v.valueReference for v in md.modelVariables if v.name == output)
        fmus.append((fmu, ref))
    values = [[] for _ in fmus]
    for k in range(sc["steps"]):
        for (fmu, ref), out in zip(fmus, values):
            fmu.doStep(k * sc["dt"], sc["dt"])
            out.append(fmu.getReal([ref])[0])
    for fmu, _ in fmus:
        fmu.terminate()
        fmu.freeInstance()
    print(json.dumps({"values": values}), flush=True)


def _instances(md, unzipped, count):
    """`count` instantiated slaves of one unzipped FMU (the probes' common start)."""
    from fmpy.fmi2 import FMU2Slave

    for i in range(count):
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName=f"instance{i}")
        fmu.instantiate()
        yield fmu


def _free(fmus):
    for fmu in fmus:
        fmu.terminate()
        fmu.fmi2FreeInstance(fmu.component)


def probe_module_refcount(md, unzipped, instances):
    """Instantiate the FMU `instances` times; after each, print how far the slave
    module dict's reference count is above the number of objects holding it
    (negative: someone released a reference it did not own)."""
    import gc
    import os

    with open(os.path.join(unzipped, "resources", "slavemodule.txt")) as fh:
        module = fh.read().strip()
    surplus, keep = [], []
    for fmu in _instances(md, unzipped, instances):
        keep.append(fmu)
        owners = len(gc.get_referrers(sys.modules[module].__dict__))
        # getrefcount counts its own argument once
        surplus.append(sys.getrefcount(sys.modules[module].__dict__) - 1 - owners)
    _free(keep)
    print(json.dumps({"surplus": surplus}), flush=True)


def probe_exit_hook(md, unzipped, instances):
    """Instantiate the FMU `instances` times and report the libraries whose
    pythonfmu state the FMU runtime releases at exit, and how many atexit
    handlers the instantiations added."""
    import atexit

    before = atexit._ncallbacks()
    keep = list(_instances(md, unzipped, instances))
    added = atexit._ncallbacks() - before
    runtime = next(m for name, m in sys.modules.items() if name.endswith("_lsc._fmu_runtime._loader"))
    _free(keep)
    keep[0].freeLibrary()
    print(json.dumps({"hooks": sorted(runtime._EXIT_HOOKS), "atexit_added": added}), flush=True)


if __name__ == "__main__":
    main()
