"""Partial derivatives of a native FMU (FMI 2.0 or 3.0, ME or CS) in this fresh process with fmpy; JSON out.

Reads {"fmu", "version", "interface" ('me'|'cs'), "p" (the input's value), "lam" (or null), "start" (optional:
other values set before initialization), "phase"
('init': in Initialization Mode, knowns the states' start values; 'run': after `steps` steps of `dt`),
"unknowns", "knowns" (names), "x" (ME 'run': the states set), "bad" (optional: calls that must be refused)}
from stdin and prints {"J": rows of the unknowns by unit seeds, "JT": the same by adjoint products (FMI 3.0),
"combined": J applied to the seed 1, 2, ..., "x" (the states), "after" (the states after the
refused calls), "errors": [{"refused", "logs"} of each bad call], "logs": [...]}.
"""
import json
import sys


def _open(sc, logs):
    from fmpy import extract, read_model_description

    md = read_model_description(sc["fmu"])
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(sc["fmu"])
    me = sc["interface"] == "me"
    ident = (md.modelExchange if me else md.coSimulation).modelIdentifier
    if sc["version"] == 3:
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        fmu = (FMU3Model if me else FMU3Slave)(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=ident,
                                               instanceName="dd")
        fmu.instantiate(logMessage=lambda env, status, category, message: logs.append(message.decode()))
    else:
        from ctypes import byref

        from fmpy.fmi2 import FMU2Model, FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        from fmpy.logging import addLoggerProxy

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, instance, status, category, message: logs.append(message.decode()))
        callbacks.allocateMemory = defaultCallbacks.allocateMemory
        callbacks.freeMemory = defaultCallbacks.freeMemory
        addLoggerProxy(byref(callbacks))
        fmu = (FMU2Model if me else FMU2Slave)(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=ident,
                                               instanceName="dd")
        fmu._callbacks = callbacks  # kept alive as long as the instance
        fmu.instantiate(callbacks=callbacks)
    return fmu, vr


def _setreal(fmu, vrs, values):
    (fmu.setFloat64 if hasattr(fmu, "setFloat64") else fmu.setReal)(vrs, values)


def _getreal(fmu, vrs):
    return list((fmu.getFloat64 if hasattr(fmu, "getFloat64") else fmu.getReal)(vrs))


def main():
    sc = json.load(sys.stdin)
    logs, errors = [], []
    fmu, vr = _open(sc, logs)
    v3 = sc["version"] == 3
    if not v3:
        fmu.setupExperiment(startTime=0.0)
    if sc.get("lam") is not None:
        _setreal(fmu, [vr["lambda"]], [sc["lam"]])
    _setreal(fmu, [vr["p"]], [sc["p"]])
    for name, value in sc.get("start", {}).items():
        _setreal(fmu, [vr[name]], [value])
    fmu.enterInitializationMode(**({"startTime": 0.0} if v3 else {}))
    states = ["y", "v", "u"]
    if sc["phase"] == "run":
        fmu.exitInitializationMode()
        if sc["interface"] == "cs":
            for i in range(sc["steps"]):
                _setreal(fmu, [vr["p"]], [sc["p"]])
                fmu.doStep(i * sc["dt"], sc["dt"])
        else:
            if v3:
                fmu.updateDiscreteStates()
            else:
                fmu.newDiscreteStates()
            fmu.enterContinuousTimeMode()
            fmu.setTime(sc["steps"] * sc["dt"])
            from ctypes import c_double

            fmu.setContinuousStates((c_double * len(sc["x"]))(*sc["x"]), len(sc["x"]))
    unknowns = [vr[n] for n in sc["unknowns"]]
    knowns = [vr[n] for n in sc["knowns"]]
    out = {"x": _getreal(fmu, [vr[s] for s in states])}

    def forward(seed):
        return fmu.getDirectionalDerivative(unknowns, knowns, seed)

    out["J"] = [list(col) for col in zip(*[forward([float(i == j) for i in range(len(knowns))])
                                          for j in range(len(knowns))])]
    out["combined"] = forward([float(i + 1) for i in range(len(knowns))])
    if v3:
        out["JT"] = [fmu.getAdjointDerivative(unknowns, knowns, [float(i == j) for i in range(len(unknowns))],
                                              nSensitivity=len(knowns)) for j in range(len(unknowns))]
    for call in sc.get("bad", []):  # each must be refused with a logged reason, the instance usable after
        before = len(logs)
        try:
            fmu.getDirectionalDerivative([vr[n] for n in call["unknowns"]], [vr[n] for n in call["knowns"]],
                                         [1.0] * len(call["knowns"]))
            errors.append({"refused": False, "logs": logs[before:]})
        except Exception as exc:  # fmpy raises on fmi2Error / fmi3Error
            errors.append({"refused": True, "what": str(exc), "logs": logs[before:]})
    out["after"] = _getreal(fmu, [vr[s] for s in states])
    out["errors"], out["logs"] = errors, logs
    if sc["phase"] == "run":  # fmi2Terminate is not allowed in Initialization Mode
        fmu.terminate()
    fmu.freeInstance()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
