"""FMI 3.0 native FMUs: the FMI 3.0 layer over the FMI 2.0 core gives the same numbers, and its own refusals.

Every FMU runs in a subprocess (tests/support/native3_runner.py with fmpy). The FMI 2.0 build of the same
spec is the reference: one core, two API layers, so Co-Simulation must agree to 1e-12 and Model
Exchange (fmpy's CVode on the same right-hand side) to the integrator's tolerance.
"""
import json
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from tests.support import helpers
from fmu_build import build_fmu

from tests.support import ROOT, SUPPORT
SPECS = ROOT / "examples" / "specs"
RUNNER = SUPPORT / "native3_runner.py"
OUTPUTS = ["y", "v", "u", "constraint_residual"]


def run(scenario, timeout=300):
    proc = subprocess.run([sys.executable, str(RUNNER)], input=json.dumps(scenario), capture_output=True, text=True,
                          timeout=timeout, cwd=SUPPORT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("native3")
    fmus = {}
    for name in ("prescribed_path", "path_input"):
        for version in (2, 3):
            fmus[name, version] = build_fmu(SPECS / f"{name}.toml", folder / f"v{version}", target="native",
                                            fix_parameters=True, fmi_version=version)
    return fmus


def test_validates_clean_and_is_fmi3(built):
    from fmpy.validation import validate_fmu

    for name in ("prescribed_path", "path_input"):
        fmu = built[name, 3]
        assert validate_fmu(str(fmu)) == []
        with zipfile.ZipFile(fmu) as zf:
            names = set(zf.namelist())
            xml = zf.read("modelDescription.xml").decode()
        assert f"binaries/x86_64-linux/{fmu.stem}.so" in names
        assert {"sources/fmi3Functions.c", "sources/buildDescription.xml", "sources/model.h"} <= names
        assert 'fmiVersion="3.0"' in xml and "instantiationToken=" in xml
        for tag in ("<ModelExchange", "<CoSimulation", "<Output ", "<ContinuousStateDerivative ", "<InitialUnknown ",
                    'causality="independent"', 'mightReturnEarlyFromDoStep="false"'):
            assert tag in xml, tag


@pytest.mark.skipif(shutil.which("nm") is None, reason="nm (binutils) not installed")
def test_library_exports_fmi3_functions_only(built, tmp_path):
    with zipfile.ZipFile(built["prescribed_path", 3]) as zf:
        zf.extract("binaries/x86_64-linux/PrescribedPath.so", tmp_path)
    out = subprocess.run(["nm", "-D", "--defined-only", str(tmp_path / "binaries/x86_64-linux/PrescribedPath.so")],
                         capture_output=True, text=True, check=True).stdout
    symbols = {line.split()[-1] for line in out.splitlines() if line.strip()}
    assert len(symbols) == 75  # every function of fmi3Functions.h, nothing of the FMI 2.0 core
    assert all(s.startswith("fmi3") for s in symbols)


def test_fmpy_compile_rebuilds_from_sources(built, tmp_path):
    """sources/buildDescription.xml names the one file to compile: `fmpy compile` rebuilds the binary."""
    fmpy_cli = shutil.which("fmpy")
    if fmpy_cli is None or shutil.which("cmake") is None:
        pytest.skip("needs the fmpy command and cmake")
    fmu = tmp_path / "PrescribedPath.fmu"
    with zipfile.ZipFile(built["prescribed_path", 3]) as src, zipfile.ZipFile(fmu, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    proc = subprocess.run([fmpy_cli, "compile", str(fmu)], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    with zipfile.ZipFile(fmu) as zf:
        assert "binaries/x86_64-linux/PrescribedPath.so" in zf.namelist()
    original, rebuilt = run({"kind": "simulate", "fmus": [str(built["prescribed_path", 3]), str(fmu)],
                             "fmi_type": "CoSimulation", "stop": 1.0, "dt": 0.01, "outputs": ["y"]})["results"]
    assert np.abs(np.array(original["y"]) - rebuilt["y"]).max() <= 1e-12


def _table(t):
    return {"time": t.tolist(), "p": (0.5 * np.sin(2 * t) + 0.1 * t).tolist()}


@pytest.mark.parametrize("fmi_type, tol", [("CoSimulation", 1e-12), ("ModelExchange", 1e-9)])
@pytest.mark.parametrize("name", ["prescribed_path", "path_input"])
def test_simulate_equals_fmi2_build(built, name, fmi_type, tol):
    sc = {"kind": "simulate", "fmus": [str(built[name, 2]), str(built[name, 3])], "fmi_type": fmi_type, "stop": 2.0,
          "dt": 0.01, "outputs": OUTPUTS}
    if name == "path_input":
        sc["input_table"] = _table(np.linspace(0.0, 2.0, 201))
    else:
        sc["start_values"] = {"lambda": 7.0, "y_0": 0.3}  # inconsistent start: the residual decays at lambda
    fmi2, fmi3 = run(sc)["results"]
    # (Model Exchange with an input also records the step events where the input history grows)
    assert fmi3["time"] == fmi2["time"] and len(fmi3["time"]) >= 201 and fmi3["time"][-1] == 2.0
    for key in OUTPUTS:
        a, b = np.array(fmi2[key]), np.array(fmi3[key])
        assert np.all(np.isfinite(b))
        assert np.abs(a - b).max() <= tol * max(np.abs(a).max(), 1.0), key


def test_start_report_names_fmi3_only(built):
    """The start report of an input whose derivatives are estimated says why they were not given in FMI 3.0's
    terms (FMI 3.0 has no function to send input derivatives), and names no FMI 2.0 function."""
    code = ("import json, sys\nfrom fmpy import simulate_fmu\nlogs = []\n"
            "simulate_fmu(sys.argv[1], fmi_type=sys.argv[2], stop_time=0.05, output_interval=0.01, debug_logging=True,"
            " logger=lambda *a: logs.append(a[-1].decode()))\nprint(json.dumps(logs))")
    for fmi_type in ("CoSimulation", "ModelExchange"):
        proc = subprocess.run([sys.executable, "-c", code, str(built["path_input", 3]), fmi_type], capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
        report = [m for m in json.loads(proc.stdout) if "guessed" in m]
        assert len(report) == 1 and report[0].startswith("fmi3ExitInitializationMode: input p: 3 of the derivatives"), report
        assert "fmi2" not in report[0] and "InputDerivatives" not in report[0], report
        assert ("FMI 3.0 interface takes no input derivatives" in report[0]) == (fmi_type == "CoSimulation"), report


def test_lambda_from_start_values_sets_the_decay(built):
    """The residual of an inconsistent start decays exactly like exp(-lambda t) (Co-Simulation)."""
    sc = {"kind": "simulate", "fmus": [str(built["prescribed_path", 3])], "fmi_type": "CoSimulation", "stop": 1.0,
          "dt": 0.01, "outputs": OUTPUTS}
    for lam in (7.0, 3.0):
        res = run(dict(sc, start_values={"lambda": lam, "y_0": 0.3}))["results"][0]
        t, r = np.array(res["time"]), np.array(res["constraint_residual"])
        assert r[0] > 0.1
        # to the step's own error: a consistent start leaves a residual near 1e-9 (the forcing's Taylor remainder)
        np.testing.assert_allclose(r / r[0], np.exp(-lam * t), rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("serialize", [False, True])
def test_rollback_is_bit_for_bit(built, serialize):
    out = run({"kind": "rollback", "fmu": str(built["path_input", 3]), "dt": 0.01, "steps": 20, "at": 10,
               "serialize": serialize, "outputs": ["y", "v", "u", "constraint_residual"]})
    assert out["first"] == out["again"] and len(out["first"]) == 20
    assert out["logs"] == []


def test_bad_calls_are_refused_with_a_reason(built):
    out = run({"kind": "bad", "fmu": str(built["prescribed_path", 3]), "outputs": ["y"]})
    error, discard, ok = 3, 2, 0
    calls = out["calls"]
    assert calls == {"doStep_before_init": error, "setTime_on_cs": error, "enterInitializationMode_twice": error,
                     "get_unknown_vr": error, "get_nvalues_mismatch": error, "set_nan_lambda": error,
                     "step_after_nan": discard, "negative_step": error, "wrong_communication_point": error,
                     "enterStepMode": error, "set_time_variable": error, "getInt32": error,
                     "getDirectionalDerivative": error, "setFMUState_null": error,
                     "getNumberOfContinuousStates_on_cs": error, "good_step": ok, "time_after_good_step": 0.1,
                     "outputDerivative_order1": ok, "outputDerivative_minus_der": 0.0, "outputDerivative_order5": error}
    logs = "\n".join(out["logs"])
    for reason in ("fmi3DoStep: not allowed", "unknown value reference 100000", "nValues = 2",
                   "rejected value nan for value reference 0", "h = -0.1", "differs from the FMU time",
                   "hasEventMode=false", "is time, the independent variable", "no Int32 variables",
                   "in Co-Simulation the states are not knowns", "FMUstate is NULL", "a Model Exchange function",
                   "fmi3GetOutputDerivatives: order 5 must be 1..4"):
        assert reason in logs, reason
    assert "fmi2" not in logs  # the core's messages name the FMI 3.0 functions


def test_bad_model_exchange_calls_are_refused(built):
    out = run({"kind": "bad_me", "fmu": str(built["prescribed_path", 3])})
    assert out["calls"] == {"completedIntegratorStep_before_init": 3, "updateDiscreteStates": 0, "doStep_on_me": 3,
                            "setContinuousStates_nan": 3, "setContinuousStates_wrong_n": 3,
                            "getEventIndicators_one": 3, "getEventIndicators_none": 0, "setTime_nan": 3,
                            "set_lambda_in_continuous_time": 3, "getNumberOfContinuousStates": 0, "nx": 3,
                            "getDerivatives": 0, "derivatives_finite": True}
    logs = "\n".join(out["logs"])
    for reason in ("x[0] = nan is not finite", "nx = 4, expected 3", "no event indicators", "time nan is not finite",
                   "in Event Mode only"):
        assert reason in logs, reason


def test_model_exchange_state_machine(built):
    """The FMI 3.0 Model Exchange state machine call by call (tests/support/native3_tv_runner.py): Event Mode after
    initialization, fmi3UpdateDiscreteStates without events or a next event time, Continuous-Time Mode and back by
    fmi3EnterEventMode from it only; every call out of order refused with the reason, and the Event Mode calls on
    a Co-Simulation instance (hasEventMode=false) too."""
    proc = subprocess.run([sys.executable, str(SUPPORT / "native3_tv_runner.py")], capture_output=True, text=True,
                          input=json.dumps({"kind": "me_sequence", "fmu": str(built["prescribed_path", 3]), "t": 0.5}),
                          timeout=300, cwd=SUPPORT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    no_event = [0, False, False, False, False, False, 0.0]  # need update, terminate, nominals, values, next time
    assert out["calls"] == {
        "enterEventMode_instantiated": 3, "enterInitializationMode": 0, "enterContinuousTimeMode_initialization": 3,
        "exitInitializationMode": 0, "completedIntegratorStep_event": 3, "enterEventMode_event": 3,
        "setContinuousStates_event": 3, "updateDiscreteStates": no_event, "enterContinuousTimeMode": 0,
        "updateDiscreteStates_continuous": 3, "enterContinuousTimeMode_continuous": 3, "setTime": 0,
        "getContinuousStateDerivatives": 0, "derivatives": out["calls"]["derivatives"],
        "completedIntegratorStep": [0, False, False], "enterEventMode": 0, "updateDiscreteStates_again": no_event,
        "enterContinuousTimeMode_again": 0, "terminate": 0, "cs_enterEventMode": 3, "cs_updateDiscreteStates": 3,
        "cs_step_after": [0, False, False, False, 0.01]}
    assert np.all(np.isfinite(out["calls"]["derivatives"]))
    logs = out["logs"]
    for f in ("fmi3EnterEventMode", "fmi3EnterContinuousTimeMode", "fmi3CompletedIntegratorStep",
              "fmi3SetContinuousStates", "fmi3UpdateDiscreteStates"):
        assert f"{f}: not allowed in the current state of the instance (FMI 3.0 call sequence)" in logs, f
    assert sum("not allowed in the current state" in m for m in logs) == 7  # one line per refused call
    for f in ("fmi3EnterEventMode", "fmi3UpdateDiscreteStates"):
        assert f"{f}: this FMU has no Event Mode in Co-Simulation (hasEventMode=false, eventModeUsed is false)" in logs


def test_do_step_contract_on_a_forcing_that_turns_infinite(tmp_path):
    """f = 1 / (1 - t) in steps of 0.25: the step from 0.75 to the pole is discarded, lastSuccessfulTime stays
    0.75, and terminateSimulation turns true when the same step is discarded again (no retry can succeed)."""
    spec = {"model": {"name": "Blowup"}, "states": {"x": {}},
            "equations": {"A": [[1]], "B": [[1]], "f": ["1/(1 - t)"]}, "experiment": {"stop": 2.0, "step": 0.25}}
    fmu = build_fmu(spec, tmp_path, target="native", fmi_version=3)
    out = run({"kind": "discard", "fmu": str(fmu), "dt": 0.25, "steps": 5})
    steps = out["steps"]
    assert [s["status"] for s in steps] == [0, 0, 0, 2, 2]
    assert [s["lastSuccessfulTime"] for s in steps] == [0.25, 0.5, 0.75, 0.75, 0.75]
    assert [s["terminateSimulation"] for s in steps] == [False, False, False, False, True]
    assert not any(s["eventHandlingNeeded"] or s["earlyReturn"] for s in steps)
    assert any("terminateSimulation is now true" in line for line in out["logs"]), out["logs"]


def test_fmi_version_is_checked(tmp_path):
    for bad in (1, 4, "3", True, 3.0):
        with pytest.raises(ValueError, match="fmi_version"):
            build_fmu(SPECS / "prescribed_path.toml", tmp_path, target="native", fix_parameters=True, fmi_version=bad)
    with pytest.raises(ValueError, match="fmi_version"):
        build_fmu(SPECS / "prescribed_path.toml", tmp_path, fmi_version=3)
    assert list(tmp_path.iterdir()) == []


def test_command_line_builds_fmi3(tmp_path, capsys):
    from fmu_build.__main__ import main

    assert main(["build", str(SPECS / "prescribed_path.toml"), "-o", str(tmp_path), "--native", "--fix-parameters",
                 "--fmi-version", "3"]) == 0
    with zipfile.ZipFile(tmp_path / "PrescribedPath.fmu") as zf:
        assert 'fmiVersion="3.0"' in zf.read("modelDescription.xml").decode()
    assert main(["build", str(SPECS / "prescribed_path.toml"), "-o", str(tmp_path / "py"), "--fmi-version", "3"]) == 2
    assert "--fmi-version" in capsys.readouterr().err


# -- coupled to the Modelica Reference FMUs' FMI 3.0 Dahlquist ----------------------------------------

def test_coupled_to_reference_dahlquist(built, tmp_path):
    """The plant's output x = 0.9^k (Dahlquist, explicit Euler) is our path input p: y follows it, as the FMI 2.0 build."""
    folder, reason = helpers.reference_fmus("3.0")
    if folder is None:
        pytest.skip(reason)
    out = run({"kind": "couple", "plant": str(folder / "Dahlquist.fmu"), "fmu": str(built["path_input", 3]),
               "fmu2": str(built["path_input", 2]), "dt": 0.1, "steps": 50})
    t, x, y3, y2 = (np.array(out[k]) for k in ("t", "x", "y3", "y2"))
    assert out["logs"] == []
    np.testing.assert_allclose(x, 0.9 ** np.arange(1, 51), rtol=1e-12)  # the plant ran as documented
    assert np.abs(y3 - y2).max() <= 1e-12  # the FMI 3.0 layer changes nothing
    # y(0) = 0 against p(0) = 1: the gap closes at lambda = 5 and then follows the estimated input
    assert abs(y3[-1] - x[-1]) < 1e-8 and abs(y3[9] - x[9]) > 1e-3


def test_c_master_under_address_and_ub_sanitizers(built, tmp_path):
    """Three instances interleaved (two Co-Simulation, one Model Exchange) and refused calls, ASan and UBSan clean."""
    import os
    from xml.etree import ElementTree as ET

    if shutil.which("cc") is None:
        pytest.skip("no C compiler")
    with zipfile.ZipFile(built["prescribed_path", 3]) as zf:
        zf.extractall(tmp_path)
        root = ET.fromstring(zf.read("modelDescription.xml"))
    vrs = {v.get("name"): v.get("valueReference") for v in root.find("ModelVariables")}
    san = ["-fsanitize=address,undefined", "-fno-sanitize-recover=undefined", "-fno-omit-frame-pointer", "-g"]
    src = tmp_path / "sources"
    for cmd in (["cc", "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", *san, "-shared", "-fPIC", "-I", str(src),
                 "-o", str(tmp_path / "san.so"), str(src / "fmi3Functions.c"), "-lm"],
                # the master without -pedantic: ISO C has no cast from dlsym's pointer to a function pointer
                ["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", *san, "-D_POSIX_C_SOURCE=200809L",
                 "-I", str(src / "fmi3" / "headers"), "-o", str(tmp_path / "master"), str(SUPPORT / "native3_master.c"),
                 "-ldl"]):
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
    proc = subprocess.run([str(tmp_path / "master"), str(tmp_path / "san.so"), root.get("instantiationToken"), "200",
                           "0.01", "3", vrs["y"], vrs["v"], vrs["u"]], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, ASAN_OPTIONS="detect_leaks=1", UBSAN_OPTIONS="halt_on_error=1"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "runtime error" not in proc.stderr and "AddressSanitizer" not in proc.stderr
    lines = proc.stdout.split("\n")
    rows = np.array([[float(v) for v in line.split()] for line in lines if line and not line.startswith("me")])
    me = np.array([float(v) for v in next(line for line in lines if line.startswith("me")).split()[1:]])
    ref = run({"kind": "simulate", "fmus": [str(built["prescribed_path", 3])], "fmi_type": "CoSimulation", "stop": 2.0,
               "dt": 0.01, "outputs": ["y", "v", "u"], "rtol": 1e-11})["results"][0]
    # the first instance, stepped among the others, equals fmpy's run of the optimized binary (rtol 1e-11: the
    # sub-step tolerance the master's instance has by default)
    for j, name in enumerate(("y", "v", "u")):
        assert np.abs(rows[:, 1 + j] - np.array(ref[name][1:])).max() <= 1e-12 * max(1.0, np.abs(ref[name]).max())
    # explicit Euler in steps of 0.01 on the Model Exchange derivatives: first order close to the exact stepping
    assert np.abs(me - rows[-1, 1:]).max() < 0.05 * max(1.0, np.abs(rows[-1, 1:]).max())
