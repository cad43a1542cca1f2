"""Run a native FMU in this (fresh) process with fmpy and report JSON: used by test_native.py.

Reads a scenario from stdin:
  {"fmu": path, "interface": "cs" | "me", "dt": h, "steps": N, "t0": start (default 0), "start_values": {...},
   "outputs": [...], "set_at": {"i": {name: value}}, "inputs": {name: [[u, u', ...] at each step start]},
   "send_derivatives": bool, "rollback_at": i, "serialize": bool, "block": ["lsc", ...],
   "output_derivatives": [names], "bad_calls": bool, "tolerance": the host's relative tolerance}
and prints {"time", "values", "status", "logs", ...}.
"""
import json
import sys

from helpers import block_imports


def main():
    sc = json.load(sys.stdin)
    blocked = block_imports(sc.get("block", []))
    from ctypes import byref

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, defaultCallbacks
    from fmpy.logging import addLoggerProxy

    logs = []

    def logger(env, instance, status, category, message):
        logs.append(message.decode("utf-8", "replace"))

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    addLoggerProxy(byref(callbacks))

    md = read_model_description(sc["fmu"])
    var = {v.name: v for v in md.modelVariables}
    unzipped = extract(sc["fmu"])
    out = {"blocked": blocked, "logs": logs}
    if sc.get("interface", "cs") == "me":
        import numpy as np
        from fmpy import simulate_fmu

        table = None
        if sc.get("input_table"):  # {"time": [...], name: [...]}: fmpy's input table
            names = [k for k in sc["input_table"] if k != "time"]
            table = np.array(list(zip(*[sc["input_table"][k] for k in ["time", *names]])),
                             dtype=[(k, float) for k in ["time", *names]])
        t0 = sc.get("t0", 0.0)
        res = simulate_fmu(unzipped, fmi_type="ModelExchange", start_time=t0, stop_time=t0 + sc["dt"] * sc["steps"],
                           output_interval=sc["dt"], relative_tolerance=sc.get("rtol", 1e-10), input=table,
                           start_values=sc.get("start_values", {}), output=sc["outputs"], model_description=md)
        out["time"] = res["time"].tolist()
        out["values"] = [[float(r[name]) for name in sc["outputs"]] for r in res]
        print(json.dumps(out))
        return

    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="instance")
    fmu.instantiate(callbacks=callbacks, loggingOn=False)
    status = []

    def set_values(values):
        for name, value in values.items():
            v = var[name]
            try:
                if v.type == "Boolean":
                    fmu.setBoolean([v.valueReference], [bool(value)])
                else:
                    fmu.setReal([v.valueReference], [float(value)])
                status.append("ok")
            except Exception as exc:  # fmpy raises on fmi2Error: record it, the FMU must go on
                status.append(f"set {name}: {exc}")

    vrs = [var[name].valueReference for name in sc["outputs"]]
    t0 = sc.get("t0", 0.0)  # the experiment's start (the steps' times are t0 + i dt)
    fmu.setupExperiment(tolerance=sc.get("tolerance"), startTime=t0)
    set_values(sc.get("start_values", {}))
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    dt, steps = sc["dt"], sc["steps"]
    inputs = sc.get("inputs", {})

    def run(i0, t, record):
        times, values = [t], [list(fmu.getReal(vrs))]
        for i in range(i0, steps):
            if str(i) in sc.get("set_at", {}):
                set_values(sc["set_at"][str(i)])
            for name, jets in inputs.items():
                fmu.setReal([var[name].valueReference], [jets[i][0]])
                if sc.get("send_derivatives"):
                    for order in range(1, len(jets[i])):
                        fmu.setRealInputDerivatives([var[name].valueReference], [order], [jets[i][order]])
            if record and i == sc.get("rollback_at"):
                state = fmu.getFMUstate()
                if sc.get("serialize"):
                    blob = fmu.serializeFMUstate(state)
                    fmu.freeFMUstate(state)
                    state = fmu.deSerializeFMUstate(blob)
                out["rollback_state"] = state
                out["rollback_t"] = t
            try:
                fmu.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
                status.append("ok")
            except Exception as exc:
                status.append(f"step {i}: {exc}")
                break
            t = t0 + (i * dt + dt) if sc.get("grid_times", True) else t + dt
            times.append(t)
            values.append(list(fmu.getReal(vrs)))
        return times, values

    times, values = run(0, t0, True)
    out.update(time=times, values=values, status=status)
    if sc.get("output_derivatives"):
        dvrs = [var[name].valueReference for name in sc["output_derivatives"]]
        try:
            out["derivatives"] = [list(fmu.getRealOutputDerivatives(dvrs, [order] * len(dvrs)))
                                  for order in range(1, md.coSimulation.maxOutputDerivativeOrder + 1)]
        except Exception as exc:  # fmpy raises on fmi2Error: the FMU must go on
            out["derivatives_error"] = str(exc)
    if "rollback_state" in out:
        state = out.pop("rollback_state")
        fmu.setFMUstate(state)
        i0 = sc["rollback_at"]
        t2, v2 = run(i0, out.pop("rollback_t"), False)
        out["rollback"] = {"time": t2, "values": v2, "original": values[i0:]}
        fmu.freeFMUstate(state)
    if sc.get("bad_calls"):
        bad = {}
        for label, call in (("nan lambda", lambda: fmu.setReal([var["lambda"].valueReference], [float("nan")])),
                            ("negative lambda", lambda: fmu.setReal([var["lambda"].valueReference], [-1.0])),
                            ("step while invalid", lambda: fmu.doStep(times[-1], dt)),
                            ("fixed start value", lambda: fmu.setReal([var[sc["outputs"][0] + "_0"].valueReference], [1.0])
                             if sc["outputs"][0] + "_0" in var else None),
                            ("lambda ok again", lambda: fmu.setReal([var["lambda"].valueReference], [1.0])),
                            ("negative step", lambda: fmu.doStep(times[-1], -dt)),
                            ("wrong time", lambda: fmu.doStep(times[-1] + 1.0, dt)),
                            ("unknown vr", lambda: fmu.getReal([10 ** 6])),
                            ("short state", lambda: fmu.setFMUstate(fmu.deSerializeFMUstate(b"\0" * 16))),
                            ("corrupt state", lambda: fmu.setFMUstate(fmu.deSerializeFMUstate(
                                b"\xff" * 4 + bytes(fmu.serializeFMUstate(fmu.getFMUstate()))[4:]))),
                            ("good step", lambda: fmu.doStep(times[-1], dt)),
                            ("enter init again", lambda: fmu.enterInitializationMode())):
            try:
                call()
                bad[label] = "ok"
            except Exception as exc:
                bad[label] = str(exc)
        out["bad"] = bad
    fmu.terminate()
    fmu.freeInstance()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
