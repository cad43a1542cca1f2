"""What a time-varying native FMU says, and with which status, where it stops: the sub-step cap's reason in both
regimes (lambda H large: the rate; lambda H small: the error estimate and the tolerance), the logger's status equal
to the status the call returns, and Model Exchange asked to stop at the end of the tables.

The FMU (x1' + x1 - x2 = 0, (1 + t) x2 = u: index 1, an input in f) runs in a fresh Python with fmpy's low-level
FMI 2.0 calls and a logger that records each call's status and message, or in a C master under valgrind.
"""
import json
import re
import shutil
import subprocess
import sys
import textwrap
import zipfile

import pytest

from fmu_build import build_fmu
from tests.support import SUPPORT

OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3
STOP = 1.0
T1 = 1.1  # the end of the tables: the experiment's stop plus the 10 % margin


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    d = {"model": {"name": "TvInput"}, "states": {"x1": {"start": 0.0}, "x2": {"start": 0.0}},
         "inputs": {"u": {"start": 0.0}},
         "equations": {"A": [["1", "0"], ["0", "0"]], "B": [["1", "-1"], ["0", "1 + t"]], "f": ["0", "u"]},
         "completion": {"method": "alternative", "lam": 2.0},
         "experiment": {"start": 0.0, "stop": STOP, "step": 0.01}}
    return build_fmu(d, tmp_path_factory.mktemp("tvstatus"), target="native")


_SCRIPT = textwrap.dedent("""
    import ctypes, json, sys
    from ctypes import byref
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, defaultCallbacks,
                           fmi2True, fmi2False)
    from fmpy.logging import addLoggerProxy

    path, kind = sys.argv[1], sys.argv[2]
    logs = []
    def logger(env, instance, status, category, message):
        logs.append([status, message.decode("utf-8", "replace")])
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    addLoggerProxy(byref(callbacks))
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    out = {}
    if kind == "cs":
        f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="cs")
        f.instantiate(callbacks=callbacks)
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode(); f.exitInitializationMode()
        f.setReal([vr["u"]], [float(sys.argv[3])])
        n = len(logs)
        out["step"] = f._functions["fmi2DoStep"](f.component, 0.0, 0.1, fmi2True)
        out["step_logs"] = logs[n:]
        f.terminate(); f.freeInstance()
    else:
        m = FMU2Model(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.modelExchange.modelIdentifier,
                      instanceName="me")
        m.instantiate(callbacks=callbacks)
        m.setupExperiment(startTime=0.0)
        m.enterInitializationMode(); m.exitInitializationMode()
        m.enterContinuousTimeMode()
        for label, t in (("inside", 0.5), ("end", float(sys.argv[3]))):
            m.setTime(t)
            event, stop = ctypes.c_int(7), ctypes.c_int(7)
            n = len(logs)
            status = m._functions["fmi2CompletedIntegratorStep"](m.component, fmi2True, byref(event), byref(stop))
            out[label] = [status, event.value, stop.value, logs[n:]]
        m.terminate(); m.freeInstance()
    print(json.dumps(out))
""")


def _run(fmu, kind, arg):
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, str(fmu), kind, repr(arg)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]  # the host exits cleanly after the refusals
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_sub_step_cap_with_lambda_h_small_names_the_error_estimate(fmu):
    # an input of 5e307 (finite, and so is x' at the step start; 1.7e308 makes x' overflow and is discarded at
    # once) overflows the Magnus step at every level: 2^14 sub-steps of 0.1 leave lambda H = 2 * 0.1 / 2^14 =
    # 1.2e-5, so the rate (the message blamed "lambda times the sub-step above about pi") is not the cause; the
    # error estimate (not finite) and the tolerance are
    r = _run(fmu, "cs", 5e307)
    assert r["step"] == DISCARD, r
    cap = [m for s, m in r["step_logs"] if "sub-steps" in m]
    assert len(cap) == 1 and "about pi" not in cap[0], r
    assert "the error estimate" in cap[0] and "stays above the tolerance 1e-11" in cap[0], cap
    assert "error estimate inf (not finite)" in cap[0] and "lambda times the sub-step is 1.2207e-05" in cap[0], cap
    # the logger's status is the status the step returns
    assert [s for s, _ in r["step_logs"]] == [DISCARD], r


def test_model_exchange_is_asked_to_stop_at_the_end_of_the_tables(fmu):
    # fmi2CompletedIntegratorStep never set terminateSimulation: an integrator went on to the horizon's end and
    # only learned from a refused fmi2GetDerivatives past it
    r = _run(fmu, "me", T1)
    assert r["inside"][0] == OK and r["inside"][2] == 0 and r["inside"][3] == [], r  # (an event: the input history)
    status, event, stop, logs = r["end"]
    assert status == WARNING and stop == 1, r
    assert len(logs) == 1 and logs[0][0] == WARNING, r
    assert "fmi2CompletedIntegratorStep: reached 1.1000000000000001, the end of the horizon" in logs[0][1], r
    assert "terminateSimulation is true" in logs[0][1], r


def test_failing_magnus_steps_read_no_uninitialized_value(fmu, tmp_path):
    # valgrind --track-origins=yes on a plain (unsanitized) build: ASan and UBSan do not see reads of uninitialized
    # values; the paths where a Magnus step fails early (an overflowing input, lambda = 1e300), the horizon's end
    if shutil.which("valgrind") is None or shutil.which("cc") is None:
        pytest.skip("valgrind or a C compiler not found")
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(tmp_path)
        xml = zf.read("modelDescription.xml").decode()
    guid = re.search(r'guid="([^"]+)"', xml).group(1)
    vr = {name: re.search(rf'name="{name}" valueReference="(\d+)"', xml).group(1) for name in ("u", "lambda")}
    src = tmp_path / "sources"
    for cmd in (["cc", "-g", "-O1", "-std=c99", "-shared", "-fPIC", "-I", str(src), "-o", str(tmp_path / "plain.so"),
                 str(src / "fmi2Functions.c"), "-lm"],
                ["cc", "-g", "-O1", "-std=c99", "-Wall", "-Wextra", "-Werror", "-I", str(src / "fmi2" / "headers"), "-o",
                 str(tmp_path / "master"), str(SUPPORT / "native_tv_valgrind_master.c"), "-ldl"]):
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
    proc = subprocess.run(["valgrind", "--track-origins=yes", "--error-exitcode=9", "-q", str(tmp_path / "master"),
                           str(tmp_path / "plain.so"), guid, vr["u"], vr["lambda"]], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr[-4000:]
    st = dict(line.split(maxsplit=1) for line in proc.stdout.splitlines() if not line.startswith("LOG "))
    assert st == {"step_overflow": "2", "step_lambda_1e300": "2", "step_ok": "0", "step_past": "2",
                  "derivatives_inside": "0", "completed_at_end": "1 1"}, proc.stdout
    logs = [line for line in proc.stdout.splitlines() if line.startswith("LOG ")]
    assert all(line.startswith("LOG 2 ") for line in logs[:-1]) and logs[-1].startswith("LOG 1 "), logs
