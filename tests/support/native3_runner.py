"""Run native FMI 3.0 (and FMI 2.0) FMUs in this fresh process with fmpy; report JSON. Used by test_native_fmi3.py.

Reads a scenario from stdin, {"kind": ..., ...}:
  simulate: {"fmus": [paths], "fmi_type", "stop", "dt", "start_values", "outputs", "input_table", "rtol"}
            -> {"results": [{"time": [...], name: [...]}, ...]} (fmpy's simulate_fmu on each FMU)
  rollback: {"fmu", "dt", "steps", "at", "serialize", "outputs"}
            -> {"first": [...], "again": [...]} (values as float.hex after each step past `at`)
  bad:      {"fmu", "outputs"} -> {"calls": {name: status}, "logs": [...]} (hostile calls, Co-Simulation)
  bad_me:   {"fmu"} -> the same on a Model Exchange instance
  discard:  {"fmu", "dt", "steps"} -> fmi3DoStep's status and output flags at each step (raw calls)
  couple:   {"plant", "fmu", "fmu2", "dt", "steps"}: the plant's output x drives our input p; the same x
            sequence drives the FMI 2.0 build -> {"t", "x", "y3", "y2", "res3"}
"""
import json
import sys
from ctypes import byref, c_bool, c_double, c_int32, c_size_t, c_uint32

import numpy as np


def _table(spec):
    if not spec:
        return None
    names = [k for k in spec if k != "time"]
    return np.array(list(zip(*[spec[k] for k in ["time", *names]])), dtype=[(k, float) for k in ["time", *names]])


def simulate(sc):
    from fmpy import simulate_fmu

    results = []
    for path in sc["fmus"]:
        res = simulate_fmu(path, fmi_type=sc["fmi_type"], stop_time=sc["stop"], output_interval=sc["dt"],
                           relative_tolerance=sc.get("rtol", 1e-10), start_values=sc.get("start_values", {}),
                           output=sc["outputs"], input=_table(sc.get("input_table")))
        results.append({name: res[name].tolist() for name in ("time", *sc["outputs"])})
    return {"results": results}


def _slave(path, logs):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(path)
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="lsc3")
    fmu.instantiate(logMessage=lambda env, status, category, message: logs.append(message.decode()))
    return fmu, {v.name: v.valueReference for v in md.modelVariables}


def rollback(sc):
    logs = []
    fmu, vr = _slave(sc["fmu"], logs)
    vrs = [vr[n] for n in sc["outputs"]]
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    t, dt = 0.0, sc["dt"]
    for _ in range(sc["at"]):
        fmu.doStep(t, dt)
        t += dt
    state = fmu.getFMUState()
    if sc["serialize"]:
        data = fmu.serializeFMUState(state)
        fmu.freeFMUState(state)
        state = fmu.deserializeFMUState(data)
    runs = []
    for _ in range(2):
        fmu.setFMUState(state)
        tt, values = t, []
        for _ in range(sc["steps"]):
            fmu.doStep(tt, dt)
            tt += dt
            values.append([v.hex() for v in fmu.getFloat64(vrs)])
        runs.append(values)
    fmu.freeFMUState(state)
    fmu.terminate()
    fmu.freeInstance()
    return {"first": runs[0], "again": runs[1], "logs": logs}


def bad(sc):
    """Each hostile call on a fresh, initialized Co-Simulation instance; its status (0 OK .. 4 Fatal)."""
    from fmpy.fmi1 import FMICallException

    logs, calls = [], {}
    vr_lambda = 0

    def status(name, f):
        try:
            out = f()
            calls[name] = 0 if out is None or not isinstance(out, int) else out
        except FMICallException as exc:
            calls[name] = exc.status

    fmu, vr = _slave(sc["fmu"], logs)
    # wrong order: a step before initialization, Model Exchange calls on a Co-Simulation instance
    status("doStep_before_init", lambda: fmu.doStep(0.0, 0.1))
    status("setTime_on_cs", lambda: fmu.fmi3SetTime(fmu.component, 0.0))
    fmu.enterInitializationMode(startTime=0.0)
    status("enterInitializationMode_twice", lambda: fmu.fmi3EnterInitializationMode(fmu.component, False, 0.0, 0.0,
                                                                                     False, 0.0))
    fmu.exitInitializationMode()
    x = vr[sc["outputs"][0]]
    status("get_unknown_vr", lambda: fmu.getFloat64([100000]))
    status("get_nvalues_mismatch", lambda: fmu.fmi3GetFloat64(fmu.component, (c_uint32 * 1)(x), 1,
                                                              (c_double * 2)(), 2))
    status("set_nan_lambda", lambda: fmu.setFloat64([vr_lambda], [float("nan")]))
    status("step_after_nan", lambda: fmu.doStep(0.0, 0.1))
    fmu.setFloat64([vr_lambda], [2.0])
    status("negative_step", lambda: fmu.doStep(0.0, -0.1))
    status("wrong_communication_point", lambda: fmu.doStep(5.0, 0.1))
    status("enterStepMode", lambda: fmu.fmi3EnterStepMode(fmu.component))
    status("set_time_variable", lambda: fmu.setFloat64([vr["time"]], [1.0]))
    status("getInt32", lambda: fmu.getInt32([x]))
    status("getDirectionalDerivative", lambda: fmu.fmi3GetDirectionalDerivative(
        fmu.component, (c_uint32 * 1)(x), 1, (c_uint32 * 1)(x), 1, (c_double * 1)(1.0), 1, (c_double * 1)(), 1))
    status("setFMUState_null", lambda: fmu.fmi3SetFMUState(fmu.component, None))
    n = c_size_t()
    status("getNumberOfContinuousStates_on_cs", lambda: fmu.fmi3GetNumberOfContinuousStates(fmu.component, byref(n)))
    status("good_step", lambda: fmu.doStep(0.0, 0.1))
    calls["time_after_good_step"] = fmu.getFloat64([vr["time"]])[0]
    first = (c_double * 1)()
    status("outputDerivative_order1", lambda: fmu.fmi3GetOutputDerivatives(fmu.component, (c_uint32 * 1)(x), 1,
                                                                           (c_int32 * 1)(1), first, 1))
    calls["outputDerivative_minus_der"] = first[0] - fmu.getFloat64([vr["der(" + sc["outputs"][0] + ")"]])[0]
    status("outputDerivative_order5", lambda: fmu.fmi3GetOutputDerivatives(fmu.component, (c_uint32 * 1)(x), 1,
                                                                           (c_int32 * 1)(5), first, 1))
    fmu.terminate()
    fmu.freeInstance()
    return {"calls": calls, "logs": logs}


def bad_me(sc):
    """Hostile calls on a Model Exchange instance; their status (0 OK .. 4 Fatal)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import FMU3Model

    logs, calls = [], {}

    def status(name, f):
        try:
            f()
            calls[name] = 0
        except FMICallException as exc:
            calls[name] = exc.status

    md = read_model_description(sc["fmu"])
    fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(sc["fmu"]), modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="lsc3me")
    fmu.instantiate(logMessage=lambda env, status, category, message: logs.append(message.decode()))
    n = len(md.derivatives)
    status("completedIntegratorStep_before_init", lambda: fmu.completedIntegratorStep())
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    status("updateDiscreteStates", lambda: fmu.updateDiscreteStates())
    flags, last = [c_bool() for _ in range(3)], c_double()
    status("doStep_on_me", lambda: fmu.fmi3DoStep(fmu.component, 0.0, 0.1, False, *map(byref, flags), byref(last)))
    fmu.enterContinuousTimeMode()
    status("setContinuousStates_nan", lambda: fmu.setContinuousStates((c_double * n)(*([float("nan")] * n)), n))
    status("setContinuousStates_wrong_n", lambda: fmu.setContinuousStates((c_double * (n + 1))(), n + 1))
    status("getEventIndicators_one", lambda: fmu.fmi3GetEventIndicators(fmu.component, (c_double * 1)(), 1))
    status("getEventIndicators_none", lambda: fmu.fmi3GetEventIndicators(fmu.component, None, 0))
    status("setTime_nan", lambda: fmu.setTime(float("nan")))
    status("set_lambda_in_continuous_time", lambda: fmu.setFloat64([0], [3.0]))
    nx = c_size_t()
    status("getNumberOfContinuousStates", lambda: fmu.fmi3GetNumberOfContinuousStates(fmu.component, byref(nx)))
    calls["nx"] = nx.value
    fmu.setTime(0.5)
    der = (c_double * n)()
    status("getDerivatives", lambda: fmu.fmi3GetContinuousStateDerivatives(fmu.component, der, n))
    calls["derivatives_finite"] = all(np.isfinite(list(der)))
    fmu.terminate()
    fmu.freeInstance()
    return {"calls": calls, "logs": logs}


def discard(sc):
    """Raw fmi3DoStep calls (fmpy's wrapper raises on a discard before the flags can be read)."""
    logs = []
    fmu, _ = _slave(sc["fmu"], logs)
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    step = fmu._functions["fmi3DoStep"]
    t, steps = 0.0, []
    for _ in range(sc["steps"]):
        flags, last = [c_bool(True) for _ in range(3)], c_double(-1.0)
        status = step(fmu.component, t, sc["dt"], False, *map(byref, flags), byref(last))
        steps.append({"t": t, "status": status, "eventHandlingNeeded": flags[0].value,
                      "terminateSimulation": flags[1].value, "earlyReturn": flags[2].value,
                      "lastSuccessfulTime": last.value})
        t = last.value
    fmu.terminate()
    fmu.freeInstance()
    return {"steps": steps, "logs": logs}


def couple(sc):
    """A plain fmpy master: plant (the Reference FMUs' Dahlquist, FMI 3.0) -> our FMI 3.0 FMU, and the FMI 2.0 build."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    logs = []
    plant, pvr = _slave(sc["plant"], logs)
    ours, vr = _slave(sc["fmu"], logs)
    md2 = read_model_description(sc["fmu2"])
    vr2 = {v.name: v.valueReference for v in md2.modelVariables}
    ours2 = FMU2Slave(guid=md2.guid, unzipDirectory=extract(sc["fmu2"]), modelIdentifier=md2.coSimulation.modelIdentifier,
                      instanceName="lsc2")
    ours2.instantiate()
    ours2.setupExperiment(startTime=0.0)
    for fmu in (plant, ours):
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
    ours2.enterInitializationMode()
    ours2.exitInitializationMode()
    out = {"t": [], "x": [], "y3": [], "y2": [], "res3": [], "logs": logs}
    t, dt = 0.0, sc["dt"]
    for _ in range(sc["steps"]):
        x = plant.getFloat64([pvr["x"]])[0]
        ours.setFloat64([vr["p"]], [x])
        ours2.setReal([vr2["p"]], [x])
        for fmu in (plant, ours):
            fmu.doStep(t, dt)
        ours2.doStep(t, dt)
        t += dt
        out["t"].append(t)
        out["x"].append(plant.getFloat64([pvr["x"]])[0])
        y, res = ours.getFloat64([vr["y"], vr["constraint_residual"]])
        out["y3"].append(y)
        out["res3"].append(res)
        out["y2"].append(ours2.getReal([vr2["y"]])[0])
    for fmu in (plant, ours, ours2):
        fmu.terminate()
        fmu.freeInstance()
    return out


if __name__ == "__main__":
    scenario = json.load(sys.stdin)
    print(json.dumps({"simulate": simulate, "rollback": rollback, "bad": bad, "bad_me": bad_me, "couple": couple, "discard": discard}[scenario["kind"]](scenario)))
