"""Run a native FMI 3.0 FMU with time-varying coefficients in this fresh process with fmpy; report JSON.

Used by test_native_timevarying_fmi3.py. Reads a scenario from stdin, {"kind": ..., "block": [modules], ...}:
  simulate: {"fmu", "fmi_type", "stop", "dt", "outputs", "start_values", "early_return_allowed", "rtol"}
            -> {"time", name: [...], "error", "logs"} (fmpy's simulate_fmu; an exception is reported, not raised)
  steps:    {"fmu", "dt", "steps", "outputs", "set_at": {"i": {name: value}}, "start_values": {name: value},
             "early_return_allowed", "derivative_orders": [orders], "stop_time"}: steps from the points i dt
            -> per raw fmi3DoStep call its status, flags, lastSuccessfulTime and the outputs after it (as
               float.hex), the outputs' derivatives at the end, "logs"; the host stops stepping at
               terminateSimulation or after the second refused step, then terminates and frees the instance.
  discard_twice: {"fmu", "dt", "start_values", "outputs"}: the first step twice (both discarded), then lambda
            set back and the step again -> the three steps and the outputs before, between and after.
  me_sequence: {"fmu", "t", "t_end": [times]}: the Model Exchange state machine call by call, right and wrong
            orders, and the Event Mode calls on a Co-Simulation instance -> {"calls": {name: status or [status, *flags]}}
"""
import json
import sys
from ctypes import byref, c_bool, c_double, c_int32, c_uint32

from helpers import block_imports


def _slave(path, logs, early_return_allowed=False):
    from fmpy import extract, read_model_description
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(path)
    fmu = FMU3Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="tv3")
    fmu.instantiate(earlyReturnAllowed=early_return_allowed,
                    logMessage=lambda env, status, category, message: logs.append(message.decode()))
    return fmu, {v.name: v.valueReference for v in md.modelVariables}


def simulate(sc, logs):
    from fmpy import simulate_fmu

    out = {"error": None}
    try:
        res = simulate_fmu(sc["fmu"], fmi_type=sc["fmi_type"], stop_time=sc["stop"], output_interval=sc["dt"],
                           relative_tolerance=sc.get("rtol", 1e-10), start_values=sc.get("start_values", {}),
                           output=sc["outputs"], early_return_allowed=sc.get("early_return_allowed", False),
                           logger=lambda env, status, category, message: logs.append(message.decode()))
        out.update({name: res[name].tolist() for name in ("time", *sc["outputs"])})
    except Exception as exc:  # the FMU refused: the host reports it and exits cleanly
        out["error"] = f"{type(exc).__name__}: {exc}"
    return out


def _do_step(fmu, t, dt):
    flags, last = [c_bool(True) for _ in range(3)], c_double(-1.0)
    status = fmu._functions["fmi3DoStep"](fmu.component, t, dt, False, *map(byref, flags), byref(last))
    return {"t": t, "status": status, "eventHandlingNeeded": flags[0].value, "terminateSimulation": flags[1].value,
            "earlyReturn": flags[2].value, "lastSuccessfulTime": last.value}


def _derivatives(fmu, vrs, order):
    n = len(vrs)
    values = (c_double * n)()
    status = fmu._functions["fmi3GetOutputDerivatives"](fmu.component, (c_uint32 * n)(*vrs), n,
                                                          (c_int32 * n)(*([order] * n)), values, n)
    return {"status": status, "values": list(values)}


def steps(sc, logs):
    fmu, vr = _slave(sc["fmu"], logs, sc.get("early_return_allowed", False))
    vrs = [vr[n] for n in sc["outputs"]]
    if sc.get("start_values"):
        fmu.setFloat64([vr[k] for k in sc["start_values"]], list(sc["start_values"].values()))
    try:
        fmu.enterInitializationMode(startTime=0.0, stopTime=sc.get("stop_time"))
    except Exception as exc:  # refused set-up (fmi3Error): recorded, the host goes on and frees the instance
        fmu.freeInstance()
        return {"steps": [], "derivatives": {}, "init_error": str(exc)}
    fmu.exitInitializationMode()
    t, out, refused = 0.0, [], 0
    for i in range(sc["steps"]):
        for name, value in sc.get("set_at", {}).get(str(i), {}).items():
            try:
                fmu.setFloat64([vr[name]], [value])
            except Exception as exc:  # a refused value (fmi3Error): recorded, the run goes on
                logs.append(f"runner: set {name} = {value} refused: {exc}")
        step = _do_step(fmu, t, sc["dt"])
        step["values"] = [v.hex() for v in fmu.getFloat64(vrs)]
        out.append(step)
        if step["status"] in (0, 1):  # on the grid i dt + dt, as the FMI 2.0 runner, unless it returned early
            t = step["lastSuccessfulTime"] if step["earlyReturn"] else i * sc["dt"] + sc["dt"]
        else:
            refused += 1
        if step["terminateSimulation"] or refused == 2:
            break
    ders = {str(k): _derivatives(fmu, vrs, k) for k in sc.get("derivative_orders", [])}
    fmu.terminate()
    fmu.freeInstance()
    return {"steps": out, "derivatives": ders}


def discard_twice(sc, logs):
    fmu, vr = _slave(sc["fmu"], logs)
    vrs = [vr[n] for n in sc["outputs"]]
    fmu.setFloat64([vr[k] for k in sc["start_values"]], list(sc["start_values"].values()))
    fmu.enterInitializationMode(startTime=0.0)
    fmu.exitInitializationMode()
    values = [[v.hex() for v in fmu.getFloat64(vrs)]]
    out = []
    for _ in range(2):
        out.append(_do_step(fmu, 0.0, sc["dt"]))
        values.append([v.hex() for v in fmu.getFloat64(vrs)])
    fmu.setFloat64([vr["lambda"]], [2.0])
    out.append(_do_step(fmu, 0.0, sc["dt"]))
    values.append([v.hex() for v in fmu.getFloat64(vrs)])
    fmu.terminate()
    fmu.freeInstance()
    return {"steps": out, "values": values}


def me_sequence(sc, logs):
    """The FMI 3.0 Model Exchange state machine, call by call: each call's status (0 OK, 3 Error) and the flags."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import FMU3Model

    calls = {}

    def call(name, f):
        try:
            out = f()
            calls[name] = 0 if out is None or not isinstance(out, tuple) else [0, *out]
        except FMICallException as exc:
            calls[name] = exc.status

    md = read_model_description(sc["fmu"])
    fmu = FMU3Model(guid=md.guid, unzipDirectory=extract(sc["fmu"]), modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="me3")
    fmu.instantiate(logMessage=lambda env, status, category, message: logs.append(message.decode()))
    n = len(md.derivatives)
    call("enterEventMode_instantiated", fmu.enterEventMode)
    call("enterInitializationMode", lambda: fmu.enterInitializationMode(startTime=0.0))
    call("enterContinuousTimeMode_initialization", fmu.enterContinuousTimeMode)
    call("exitInitializationMode", fmu.exitInitializationMode)
    call("completedIntegratorStep_event", fmu.completedIntegratorStep)
    call("enterEventMode_event", fmu.enterEventMode)
    call("setContinuousStates_event", lambda: fmu.setContinuousStates((c_double * n)(), n))
    call("updateDiscreteStates", fmu.updateDiscreteStates)
    call("enterContinuousTimeMode", fmu.enterContinuousTimeMode)
    call("updateDiscreteStates_continuous", fmu.updateDiscreteStates)
    call("enterContinuousTimeMode_continuous", fmu.enterContinuousTimeMode)
    call("setTime", lambda: fmu.setTime(sc["t"]))
    der = (c_double * n)()
    call("getContinuousStateDerivatives", lambda: fmu.getContinuousStateDerivatives(der, n))
    calls["derivatives"] = list(der)
    call("completedIntegratorStep", fmu.completedIntegratorStep)
    call("enterEventMode", fmu.enterEventMode)
    call("updateDiscreteStates_again", fmu.updateDiscreteStates)
    call("enterContinuousTimeMode_again", fmu.enterContinuousTimeMode)
    for k, t in enumerate(sc.get("t_end", [])):  # the end of the horizon of time-varying tables, and past it
        call(f"setTime_end{k}", lambda: fmu.setTime(t))
        call(f"completedIntegratorStep_end{k}", fmu.completedIntegratorStep)
        call(f"getContinuousStateDerivatives_end{k}", lambda: fmu.getContinuousStateDerivatives(der, n))
    call("terminate", fmu.terminate)
    fmu.freeInstance()
    cs, _ = _slave(sc["fmu"], logs)
    cs.enterInitializationMode(startTime=0.0)
    cs.exitInitializationMode()
    call("cs_enterEventMode", lambda: cs.fmi3EnterEventMode(cs.component))
    flags, when = [c_bool() for _ in range(5)], c_double()
    call("cs_updateDiscreteStates", lambda: cs.fmi3UpdateDiscreteStates(cs.component, *map(byref, flags), byref(when)))
    call("cs_step_after", lambda: cs.doStep(0.0, 0.01))  # the refused calls changed nothing
    cs.terminate()
    cs.freeInstance()
    return {"calls": calls}


def main():
    sc = json.load(sys.stdin)
    blocked = block_imports(sc.get("block", []))
    logs = []
    out = {"simulate": simulate, "steps": steps, "discard_twice": discard_twice,
           "me_sequence": me_sequence}[sc["kind"]](sc, logs)
    out.update(blocked=blocked, logs=logs)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
