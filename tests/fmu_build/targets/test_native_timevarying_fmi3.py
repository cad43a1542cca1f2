"""FMI 3.0 native FMUs of DAEs with time-varying A(t), B(t): the FMI 3.0 layer over the time-varying core.

The problems and the library reference are those of test_native_timevarying.py (exact solutions,
index 1 to 3, rotating constraints). The FMI 2.0 build of the same spec is the reference of the
layer: one core, so fmpy's Co-Simulation and Model Exchange runs agree to 1e-12. Every FMU runs in
a subprocess (tests/support/native3_tv_runner.py, tests/support/native3_runner.py, tests/support/native3_master.c).
"""
import json
import os
import shutil
import subprocess
import sys
import zipfile
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import sympy as sp

import lsc
from fmu_build import build_fmu, parse_spec
from fmu_build.targets import _native_tv
from tests.fmu_build.targets.test_native import rel_err
from tests.fmu_build.targets.test_native import run as run2
from tests.fmu_build.targets.test_native_timevarying import BLOCK, DT, PROBLEMS, PROBLEMS_SOURCES, STOP, T, _exact, _library, _names

from tests.support import SUPPORT
NAMES = ("Tv1", "Rot2", "Rot3")
HORIZON = STOP * (1 + _native_tv.HORIZON_MARGIN)  # 2.2: the tables reach 10 % past the experiment's stop


def run(scenario, runner="native3_tv_runner.py", timeout=300):
    proc = subprocess.run([sys.executable, str(SUPPORT / runner)], input=json.dumps(scenario), capture_output=True,
                          text=True, timeout=timeout, cwd=SUPPORT)
    assert proc.returncode == 0, proc.stderr[-3000:]  # the host exits cleanly, whatever the FMU refused
    return json.loads(proc.stdout.strip().splitlines()[-1])  # (fmpy's CVode prints its failures on stdout)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tv3")
    return {(name, v): build_fmu(PROBLEMS[name][0], folder / f"v{v}", target="native", fmi_version=v)
            for name in NAMES for v in (2, 3)}


def _hex(rows):
    return np.array([[float.fromhex(v) for v in row] for row in rows]).T


def test_validates_clean_and_describes_the_tables(built):
    from fmpy.validation import validate_fmu

    for name in NAMES:
        fmu = built[name, 3]
        assert validate_fmu(str(fmu)) == []
        with zipfile.ZipFile(fmu) as zf:
            root = ET.fromstring(zf.read("modelDescription.xml"))
            header = zf.read("sources/model.h").decode()
        assert root.get("fmiVersion") == "3.0" and "#define LSC_TIME_VARYING 1" in header
        assert "native C, FMI 3.0, time-varying A and B tabulated on [0, 2.2]" in root.get("description")
        assert "early return" in root.get("description")
        assert root.find("DefaultExperiment").attrib == {"startTime": "0.0", "stopTime": "2.0", "stepSize": "0.01"}
        assert root.find("CoSimulation").get("maxOutputDerivativeOrder") == "4"  # from the tables' derivatives
        assert root.find("CoSimulation").get("mightReturnEarlyFromDoStep") == "true"  # at the horizon's end
        assert root.find("ModelExchange") is not None
        n = len(PROBLEMS[name][0]["states"])
        assert len(root.find("ModelStructure").findall("ContinuousStateDerivative")) == n


@pytest.mark.parametrize("fmi_type", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("name", ["Tv1", "Rot3"])
def test_simulate_equals_fmi2_build(built, name, fmi_type):
    outputs = _names(PROBLEMS[name][0]) + ["constraint_residual"]
    results = [run({"kind": "simulate", "fmu": str(built[name, v]), "fmi_type": fmi_type, "stop": STOP, "dt": DT,
                    "outputs": outputs, "start_values": {"lambda": 3.0}}) for v in (2, 3)]
    fmi2, fmi3 = results
    assert fmi2["error"] is None and fmi3["error"] is None
    assert fmi3["time"] == fmi2["time"] and len(fmi3["time"]) == 201
    for key in outputs:
        a, b = np.array(fmi2[key]), np.array(fmi3[key])
        assert np.all(np.isfinite(b))
        assert np.abs(a - b).max() <= 1e-12 * max(np.abs(a).max(), 1.0), key
    if fmi_type == "ModelExchange":  # and it is the solution: CVode at rtol 1e-10 on the completion
        exact = _exact(name, fmi3["time"])
        assert rel_err(np.array([fmi3[k] for k in outputs[:-1]]), exact) < 1e-6


@pytest.mark.parametrize("name", NAMES)
def test_cosimulation_matches_exact_solution_with_python_libraries_blocked(built, name):
    d = PROBLEMS[name][0]
    r = run({"kind": "steps", "fmu": str(built[name, 3]), "dt": DT, "steps": int(round(STOP / DT)),
             "outputs": _names(d), "block": BLOCK})
    assert all(r["blocked"].values()), r["blocked"]
    steps = r["steps"]
    assert [s["status"] for s in steps] == [0] * 200 and not any(s["terminateSimulation"] for s in steps)
    assert not any(s["earlyReturn"] or s["eventHandlingNeeded"] for s in steps)
    t = np.array([s["lastSuccessfulTime"] for s in steps])
    np.testing.assert_allclose(t, DT * np.arange(1, 201), rtol=1e-14)
    assert rel_err(_hex([s["values"] for s in steps]), _exact(name, t)) < 1e-8
    assert r["logs"] == []


def test_output_derivatives_are_the_exact_solution_s(built):
    d = PROBLEMS["Rot2"][0]
    r = run({"kind": "steps", "fmu": str(built["Rot2", 3]), "dt": DT, "steps": 50, "outputs": _names(d),
             "derivative_orders": [1, 2, 5]})
    xe = sp.Matrix(PROBLEMS_SOURCES["Rot2"]["xe"])
    for k in (1, 2):  # x' = G x + g and x'' = G' x + G x' + g' from the tables (maxOutputDerivativeOrder 4)
        expected = np.array(xe.diff(T, k).subs(T, r["steps"][-1]["lastSuccessfulTime"]).evalf(), dtype=float).ravel()
        assert r["derivatives"][str(k)]["status"] == 0
        assert rel_err(np.array(r["derivatives"][str(k)]["values"]), expected) < 1e-8, k
    assert r["derivatives"]["5"]["status"] == 3  # beyond maxOutputDerivativeOrder: refused with the reason
    assert any("fmi3GetOutputDerivatives: order 5 must be 1..4" in m for m in r["logs"])


def test_lambda_changed_mid_run_equals_fmi2_build_and_piecewise_library_run(built):
    d = PROBLEMS["Rot3"][0]
    x0 = np.array([s["start"] for s in parse_spec(d).states]) + np.array([0, 0, 0, 0, 1e-3])  # off the manifold
    start = {f"{k}_0": float(v) for k, v in zip(_names(d), x0)}
    r3 = run({"kind": "steps", "fmu": str(built["Rot3", 3]), "dt": DT, "steps": 100, "outputs": _names(d),
              "start_values": start, "set_at": {"50": {"lambda": 7.0}}})
    r2 = run2({"fmu": str(built["Rot3", 2]), "dt": DT, "steps": 100, "outputs": _names(d), "start_values": start,
               "set_at": {"50": {"lambda": 7.0}}})
    got = _hex([s["values"] for s in r3["steps"]])
    assert np.array_equal(got, np.array(r2["values"]).T[:, 1:])  # the same core: bit for bit
    t = np.concatenate([[0.0], [s["lastSuccessfulTime"] for s in r3["steps"]]])
    X1 = _library(d, t[:51], x0=x0)
    X2 = _library(d, t[50:], lam=7.0, x0=X1[:, -1])
    assert rel_err(got[:, :50], X1[:, 1:]) < 1e-8 and rel_err(got[:, 49:], X2) < 1e-8
    assert np.abs(got[:, -1] - _library(d, t, x0=x0)[:, -1]).max() > 1e-7  # lambda did something


@pytest.mark.parametrize("serialize", [False, True])
def test_rollback_bit_for_bit(built, serialize):
    out = run({"kind": "rollback", "fmu": str(built["Rot3", 3]), "dt": DT, "steps": 30, "at": 20,
               "serialize": serialize, "outputs": _names(PROBLEMS["Rot3"][0]) + ["constraint_residual"]},
              runner="native3_runner.py")
    assert out["first"] == out["again"] and len(out["first"]) == 30
    assert out["logs"] == []


def test_discarded_step_leaves_the_fmu_unchanged_and_terminates_on_the_same_retry(built):
    """lambda h = 1e6 is beyond the Magnus steps' range: discarded (FMU unchanged, lastSuccessfulTime the step's
    start); the same step again cannot succeed (terminateSimulation); after a change of lambda it does."""
    d = PROBLEMS["Rot3"][0]
    r = run({"kind": "discard_twice", "fmu": str(built["Rot3", 3]), "dt": DT, "start_values": {"lambda": 1e8},
             "outputs": _names(d)})
    first, again, after = r["steps"]
    for s in (first, again):
        assert s["status"] == 2 and s["lastSuccessfulTime"] == 0.0 and not s["earlyReturn"]
    assert not first["terminateSimulation"] and again["terminateSimulation"]
    assert r["values"][0] == r["values"][1] == r["values"][2]  # bit for bit the state before the step
    assert after["status"] == 0 and after["lastSuccessfulTime"] == DT and not after["terminateSimulation"]
    assert rel_err(_hex([r["values"][3]]), _exact("Rot3", [DT])) < 1e-8
    logs = "\n".join(r["logs"])
    assert "lambda = 1e+08" in logs and "terminateSimulation is now true" in logs and "fmi2" not in logs


def test_step_past_the_horizon_is_discarded_with_a_logged_reason(built):
    d = PROBLEMS["Rot2"][0]
    r = run({"kind": "steps", "fmu": str(built["Rot2", 3]), "dt": 0.3, "steps": 12, "outputs": _names(d),
             "block": BLOCK})
    steps = r["steps"]
    assert [s["status"] for s in steps] == [0] * 7 + [2]  # 2.1 + 0.3 leaves [0, 2.2]
    last = steps[-1]
    assert last["terminateSimulation"] and not last["earlyReturn"] and not last["eventHandlingNeeded"]
    # the FMU is where it was: the state bit for bit, its time too (2.1, the importer's point is 2.0999999999999996)
    assert last["values"] == steps[-2]["values"] and last["lastSuccessfulTime"] == steps[-2]["lastSuccessfulTime"]
    assert any("leaves the horizon [0, 2.2000000000000002]" in m for m in r["logs"])
    assert any("terminateSimulation is now true" in m for m in r["logs"])


def test_step_past_the_horizon_returns_early_at_its_end_where_allowed(built):
    d = PROBLEMS["Rot2"][0]
    r = run({"kind": "steps", "fmu": str(built["Rot2", 3]), "dt": 0.3, "steps": 12, "outputs": _names(d),
             "early_return_allowed": True, "block": BLOCK})
    steps = r["steps"]
    assert [s["status"] for s in steps] == [0] * 7 + [1]  # fmi3Warning, the status of the logged reason
    last = steps[-1]
    assert last["earlyReturn"] and last["terminateSimulation"] and not last["eventHandlingNeeded"]
    assert last["lastSuccessfulTime"] == HORIZON
    assert rel_err(_hex([last["values"]]), _exact("Rot2", [HORIZON])) < 1e-8
    assert any("returned early at its end, terminateSimulation is true" in m for m in r["logs"])


def test_early_return_at_the_horizon_keeps_the_other_refusals(built):
    """Where early return is allowed, a step past the horizon is still refused for what the core refuses: past the
    stop time set in fmi3EnterInitializationMode (fmi3Error), an invalid value (fmi3Discard, then terminateSimulation
    on the same step again); neither returns early."""
    d = PROBLEMS["Rot2"][0]
    sc = {"kind": "steps", "fmu": str(built["Rot2", 3]), "dt": 0.3, "steps": 12, "outputs": _names(d),
          "early_return_allowed": True}
    r = run(dict(sc, stop_time=2.3))  # a stop time past the horizon 2.2 is refused at set-up
    assert "fmi3EnterInitializationMode" in r["init_error"] and r["steps"] == []
    assert any("horizon" in m for m in r["logs"])
    r = run(dict(sc, stop_time=2.0))  # 1.8 + 0.3 ends after the stop time 2.0 (and before the horizon's end)
    assert [s["status"] for s in r["steps"]] == [0] * 6 + [3, 3]
    assert not any(s["earlyReturn"] for s in r["steps"])
    assert any("ends after the stop time 2" in m for m in r["logs"])
    r = run(dict(sc, set_at={"7": {"lambda": -1.0}}))
    steps = r["steps"]
    assert [s["status"] for s in steps] == [0] * 7 + [2, 2]
    assert not any(s["earlyReturn"] for s in steps) and [s["terminateSimulation"] for s in steps[7:]] == [False, True]
    assert steps[8]["values"] == steps[6]["values"] and steps[8]["lastSuccessfulTime"] == steps[6]["lastSuccessfulTime"]
    assert any("was set to an invalid value" in m for m in r["logs"])


@pytest.mark.parametrize("early", [False, True])
def test_fmpy_simulation_past_the_horizon(built, early):
    """fmpy's own loop with a stop time past the horizon: refused at set-up (fmpy passes its stop time to
    fmi3EnterInitializationMode), with or without early return; the host reports it and exits cleanly."""
    d = PROBLEMS["Tv1"][0]
    r = run({"kind": "simulate", "fmu": str(built["Tv1", 3]), "fmi_type": "CoSimulation", "stop": 3.0, "dt": 0.3,
             "outputs": _names(d), "early_return_allowed": early})
    assert "fmi3EnterInitializationMode" in r["error"] and "time" not in r
    assert any("stopTime 3 is outside the horizon" in m for m in r["logs"]), r["logs"]


def test_fmpy_simulation_stops_where_a_step_lands_on_the_horizon_end(built):
    d = PROBLEMS["Tv1"][0]
    r = run({"kind": "simulate", "fmu": str(built["Tv1", 3]), "fmi_type": "CoSimulation", "stop": HORIZON, "dt": DT,
             "outputs": _names(d)})
    assert r["error"] is None and abs(r["time"][-1] - HORIZON) < 1e-12 and len(r["time"]) == 221
    assert rel_err(np.array([r[k] for k in _names(d)]), _exact("Tv1", r["time"])) < 1e-8
    assert any("the end of the horizon" in m and "terminateSimulation is true" in m for m in r["logs"])


def test_c_master_under_address_and_ub_sanitizers(built, tmp_path):
    """Three instances interleaved, refused calls, then the horizon: stepped to its end, and an early return."""
    if shutil.which("cc") is None:
        pytest.skip("no C compiler")
    name = "Rot3"
    with zipfile.ZipFile(built[name, 3]) as zf:
        zf.extractall(tmp_path)
        root = ET.fromstring(zf.read("modelDescription.xml"))
    vrs = {v.get("name"): v.get("valueReference") for v in root.find("ModelVariables")}
    names = _names(PROBLEMS[name][0])
    san = ["-fsanitize=address,undefined", "-fno-sanitize-recover=undefined", "-fno-omit-frame-pointer", "-g"]
    src = tmp_path / "sources"
    for cmd in (["cc", "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", *san, "-shared", "-fPIC", "-I", str(src),
                 "-o", str(tmp_path / "san.so"), str(src / "fmi3Functions.c"), "-lm"],
                ["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", *san, "-D_POSIX_C_SOURCE=200809L",
                 "-I", str(src / "fmi3" / "headers"), "-o", str(tmp_path / "master"), str(SUPPORT / "native3_master.c"),
                 "-ldl"]):
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
    proc = subprocess.run([str(tmp_path / "master"), str(tmp_path / "san.so"), root.get("instantiationToken"), "200",
                           str(DT), str(len(names)), *[vrs[n] for n in names], "--horizon"], capture_output=True,
                          text=True, timeout=600,
                          env=dict(os.environ, ASAN_OPTIONS="detect_leaks=1", UBSAN_OPTIONS="halt_on_error=1"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "runtime error" not in proc.stderr and "AddressSanitizer" not in proc.stderr
    lines = proc.stdout.split("\n")
    rows = np.array([[float(v) for v in line.split()] for line in lines if line and line[0].isdigit()])
    assert rows.shape == (200, 1 + len(names))
    assert rel_err(rows[:, 1:].T, _exact(name, rows[:, 0])) < 1e-8
    horizon = next(line for line in lines if line.startswith("horizon")).split()
    assert abs(float(horizon[1]) - HORIZON) < 1e-12 and horizon[2:] == ["1", "1"]  # Warning, terminateSimulation
    early = next(line for line in lines if line.startswith("early")).split()
    assert float(early[1]) == HORIZON and early[2:5] == ["1", "1", "1"]  # Warning, earlyReturn, terminateSimulation
    assert rel_err(np.array([float(v) for v in early[5:]]), _exact(name, [HORIZON]).ravel()) < 1e-8
    me = np.array([float(v) for v in next(line for line in lines if line.startswith("me")).split()[1:]])
    # the master's explicit Euler on the Model Exchange derivatives is explicit Euler on the library's G(t) x + g(t)
    comp = lsc.complete(parse_spec(PROBLEMS[name][0]).linear_dae(), "alternative", lam=2.0)
    x = np.array([s["start"] for s in parse_spec(PROBLEMS[name][0]).states])
    for k in range(200):
        G, g = comp.matrices(k * DT)
        x = x + DT * (G @ x + g)
    assert rel_err(me, x) < 1e-9
    assert "leaves the horizon" in proc.stderr and "returned early at its end" in proc.stderr


def test_model_exchange_event_mode_and_the_horizon(built):
    """The FMI 3.0 Model Exchange state machine on the time-varying FMU: no events, no time events; the derivatives
    are G(t) x + g(t); at the horizon's end fmi3CompletedIntegratorStep asks to stop, past it the derivatives are
    refused with the reason."""
    d = PROBLEMS["Tv1"][0]
    r = run({"kind": "me_sequence", "fmu": str(built["Tv1", 3]), "t": 0.5, "t_end": [HORIZON, HORIZON + 0.05]})
    calls = r["calls"]
    no_event = [0, False, False, False, False, False, 0.0]  # need update, terminate, nominals, values, next time
    assert calls["updateDiscreteStates"] == calls["updateDiscreteStates_again"] == no_event
    assert calls["completedIntegratorStep"] == [0, False, False]
    comp = lsc.complete(parse_spec(d).linear_dae(), "alternative", lam=2.0)
    G, g = comp.matrices(0.5)
    x0 = np.array([s["start"] for s in parse_spec(d).states])
    assert rel_err(np.array(calls["derivatives"]), G @ x0 + g) < 1e-10
    for k, derivatives in ((0, 0), (1, 3)):  # at the horizon's end: derivatives; past it: fmi3Error
        assert calls[f"completedIntegratorStep_end{k}"] == [0, False, True]  # (fmpy: OK or fmi3Warning)
        assert calls[f"getContinuousStateDerivatives_end{k}"] == derivatives
    logs = "\n".join(r["logs"])
    assert "fmi3CompletedIntegratorStep: reached 2.2000000000000002, the end of the horizon" in logs
    assert "fmi3GetContinuousStateDerivatives: t = 2.25 is outside the horizon" in logs


def _toml(d):
    """The spec dict as TOML text (strings, numbers and lists of them are all it holds)."""
    def value(v):
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(float(v))

    lines = []
    for section, body in d.items():
        if section == "states":
            for name, attrs in body.items():
                lines += [f"[states.{name}]", *[f"{k} = {value(v)}" for k, v in attrs.items()]]
        else:
            lines += [f"[{section}]", *[f"{k} = {value(v)}" for k, v in body.items()]]
    return "\n".join(lines) + "\n"


def test_command_line_builds_a_time_varying_fmi3_fmu(tmp_path, capsys):
    from fmu_build.__main__ import main

    spec = tmp_path / "rot2.toml"
    spec.write_text(_toml(PROBLEMS["Rot2"][0]))
    assert main(["build", str(spec), "-o", str(tmp_path / "out"), "--native", "--fmi-version", "3"]) == 0
    assert "native C, FMI 3.0, time-varying A and B tabulated on [0, 2.2]" in capsys.readouterr().err
    with zipfile.ZipFile(tmp_path / "out" / "Rot2.fmu") as zf:
        assert 'fmiVersion="3.0"' in zf.read("modelDescription.xml").decode()
        assert "#define LSC_TIME_VARYING 1" in zf.read("sources/model.h").decode()
