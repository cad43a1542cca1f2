"""Exact partial derivatives of the native FMUs: fmi2GetDirectionalDerivative, fmi3GetDirectionalDerivative and
fmi3GetAdjointDerivative against lsc's own completion.

A constant-coefficient completion x' = G x + W [f; f'; ...] knows its Jacobian: d x'/d x = G,
d x'/d u = W d[f; f'; ...]/d u, and the outputs' formulas give theirs. Each FMU runs in a subprocess
(tests/support/native_directional_runner.py, fmpy) in FMI 2.0 and 3.0, Model Exchange and Co-Simulation, in
Initialization Mode (the knowns are the states' start values) and after steps; its products with unit seeds
must equal G, W's input column and the output map computed here from ``lsc.complete(...).maps()`` to 1e-12
relative. The capability is declared in the model descriptions; fmuCheck and fmusim run the FMUs clean.
"""
import csv
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

import lsc
from fmu_build import build_fmu

from tests.support import SUPPORT

RUNNER = SUPPORT / "native_directional_runner.py"
P, LAM, A = 0.3, 4.0, 1.5  # the input's value, lambda set at run time (the build's is 5), a in f
# y' = v, m v' = -k y - c v + u + a sin t, y = p + p^2/10 (index 3): f's last row is nonlinear in the input p
SPEC = {"model": {"name": "PathOut", "description": "a path as an input, outputs linear and not"},
        "states": {"y": {"unit": "m", "start": 0.1}, "v": {"unit": "m/s"}, "u": {"unit": "N"}},
        "parameters": {"m": {"value": 1.0}, "c": {"value": 0.5}, "k": {"value": 2.0}, "a": {"value": A}},
        "inputs": {"p": {"unit": "m", "start": 0.0}},
        "outputs": {"lin": {"expr": "2*y - 3*v + 0.5*p + a"}, "prod": {"expr": "y*p + v**2"}},
        "equations": {"A": [[1, 0, 0], [0, "m", 0], [0, 0, 0]], "B": [[0, -1, 0], ["k", "c", -1], [1, 0, 0]],
                      "f": [0, "a*sin(t)", "p + p**2/10"]},
        "completion": {"method": "alternative", "lam": 5.0},
        "experiment": {"start": 0.0, "stop": 2.0, "step": 0.01}}
DERS, STATES = ["der(y)", "der(v)", "der(u)"], ["y", "v", "u"]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("directional")
    return {v: build_fmu(SPEC, folder / f"v{v}", target="native", fix_parameters=True, fmi_version=v)
            for v in (2, 3)}


@pytest.fixture(scope="module")
def completion():
    A_ = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 0]])
    B_ = np.array([[0.0, -1, 0], [2, 0.5, -1], [1, 0, 0]])
    return lsc.complete(lsc.LinearDAE(A_, B_, lambda t, d=0: np.zeros(3)), "alternative", lam=LAM)


def run(scenario):
    proc = subprocess.run([sys.executable, str(RUNNER)], input=json.dumps(scenario), capture_output=True, text=True,
                          timeout=300, cwd=SUPPORT)
    assert proc.returncode == 0, proc.stderr[-3000:]  # the host process exits cleanly, refused calls included
    return json.loads(proc.stdout)


def jet(t, width):
    """[f; f'; ...] (`width` entries) at time `t` and its partial derivatives with respect to p and a."""
    fj, dp, da = np.zeros(width), np.zeros(width), np.zeros(width)
    fj[2], dp[2] = P + P ** 2 / 10, 1 + P / 5  # the input's derivatives (0: a constant input) held
    for d in range(width // 3):
        da[3 * d + 1] = np.sin(t + np.pi / 2 * d)  # the d-th derivative of sin at t
    return fj + A * da, dp, da


def reference(completion, x, t, columns, with_residual):
    """The rows of der(x), y, lin, prod (and constraint_residual) over the columns [x, p, lambda, a]."""
    maps, split = completion.maps(), completion.lam_affine()
    G, W = maps.G[0], maps.W[0]
    fj, dp, da = jet(t, W.shape[1])
    dlam = split.G1[0] @ x + split.W1[0] @ fj
    y, v, _ = x
    rows = [np.r_[G[i], (W @ dp)[i], dlam[i], (W @ da)[i]] for i in range(3)]
    rows += [np.r_[1.0, 0, 0, 0, 0, 0], np.r_[2.0, -3, 0, 0.5, 0, 1], np.r_[P, 2 * v, 0, y, 0, 0]]
    if with_residual:  # |r|, r = C x - W_c [f; f'; ...]; C and W_c do not depend on lambda
        C, Wc = maps.C[0], maps.Wc[0]
        fj, dp, da = jet(t, Wc.shape[1])
        r = C @ x - Wc @ fj
        rows.append(np.r_[r @ C, -(r @ Wc @ dp), 0.0, -(r @ Wc @ da)] / np.linalg.norm(r))
    return np.array(rows)[:, columns]


CASES = [(v, itf, phase) for v in (2, 3) for itf in ("me", "cs") for phase in ("init", "run")]


@pytest.mark.parametrize("version,interface,phase", CASES)
def test_partials_equal_the_completion(built, completion, version, interface, phase):
    init, me = phase == "init", interface == "me"
    # the knowns: Initialization Mode the states' start values, lambda and a too; after it the states (Model
    # Exchange only: Co-Simulation integrates them) and the input
    knowns = (["y_0", "v_0", "u_0"] if init else (STATES if me else [])) + ["p"] + (["lambda", "a"] if init else [])
    columns = ([0, 1, 2] if init or me else []) + [3] + ([4, 5] if init else [])
    unknowns = DERS + ["y", "lin", "prod"] + (["constraint_residual"] if init else [])
    steps, dt = 10, 0.05
    out = run({"fmu": str(built[version]), "version": version, "interface": interface, "p": P, "lam": LAM,
               "phase": phase, "steps": steps, "dt": dt, "x": [0.2, 0.1, -0.3], "unknowns": unknowns,
               "knowns": knowns})
    x = np.array(out["x"])
    if init or me:
        assert x.tolist() == ([0.1, 0.0, 0.0] if init else [0.2, 0.1, -0.3])
    ref = reference(completion, x, 0.0 if init else steps * dt, columns, init)
    J = np.array(out["J"])
    scale = np.abs(ref).max()
    assert np.abs(J - ref).max() <= 1e-12 * scale, (J, ref)
    # one call with a seed of all knowns at once is the same linear map
    assert np.allclose(out["combined"], J @ np.arange(1.0, J.shape[1] + 1), rtol=1e-13, atol=1e-13 * scale)
    if version == 3:  # the adjoint products with unit seeds on the unknowns give J's rows
        assert np.abs(np.array(out["JT"]) - J).max() <= 1e-13 * scale


def test_bad_calls_are_refused_with_a_reason(built):
    # after initialization lambda and a are no knowns (FMI: the states and the inputs)
    bad = [{"unknowns": ["lambda"], "knowns": ["p"]}, {"unknowns": ["der(y)"], "knowns": ["lambda"]},
           {"unknowns": ["der(y)"], "knowns": ["y"]}]
    for version in (2, 3):
        out = run({"fmu": str(built[version]), "version": version, "interface": "cs", "p": P, "lam": LAM,
                   "phase": "run", "steps": 40, "dt": 0.05, "unknowns": ["lin"], "knowns": ["p"], "bad": bad})
        assert [e["refused"] for e in out["errors"]] == [True] * 3
        logs = [" ".join(e["logs"]) for e in out["errors"]]
        assert "not an unknown" in logs[0] and "not a known" in logs[1]
        assert "in Co-Simulation the states are not knowns" in logs[2]
        assert out["after"] == out["x"]  # a refused call changes nothing


def test_residual_on_the_manifold_is_refused(built):
    """|r| has no derivative where r = 0 (its one-sided derivative is |C v|, not linear in the seed): refused with
    the reason, never a number. With a = p = 0 and a zero start r is exactly 0."""
    for version in (2, 3):
        out = run({"fmu": str(built[version]), "version": version, "interface": "me", "p": 0.0, "lam": LAM,
                   "start": {"a": 0.0, "y_0": 0.0}, "phase": "init", "unknowns": ["der(y)"], "knowns": ["y_0"],
                   "bad": [{"unknowns": ["constraint_residual"], "knowns": ["y_0", "p"]}]})
        assert out["errors"][0]["refused"], out["errors"]
        assert "is not differentiable here" in " ".join(out["errors"][0]["logs"])


def test_declared_in_both_descriptions(built):
    for version, flags in ((2, ['providesDirectionalDerivative="true"']),
                           (3, ['providesDirectionalDerivatives="true"', 'providesAdjointDerivatives="true"'])):
        with zipfile.ZipFile(built[version]) as zf:
            xml = zf.read("modelDescription.xml").decode()
        for flag in flags:
            assert xml.count(flag) == 2, flag  # Model Exchange and Co-Simulation
        assert "dependencies=" in xml


def test_time_varying_fmu_neither_declares_nor_gives_them(tmp_path):
    from tests.support.helpers import lag_spec

    spec = lag_spec(equations={"A": [["2 + sin(t)"]], "B": [[1]], "f": ["sin(t)"]},
                    experiment={"start": 0.0, "stop": 1.0, "step": 0.1})
    for version in (2, 3):
        fmu = build_fmu(spec, tmp_path / f"v{version}", target="native", fmi_version=version)
        with zipfile.ZipFile(fmu) as zf:
            xml = zf.read("modelDescription.xml").decode()
        assert "DirectionalDerivative" in xml and 'irectionalDerivative="true"' not in xml
        assert 'irectionalDerivatives="true"' not in xml and 'AdjointDerivatives="true"' not in xml
        code = f"""
import sys
sys.path.insert(0, {str(SUPPORT)!r})
from native_directional_runner import _open
logs = []
fmu, vr = _open({{"fmu": {str(fmu)!r}, "version": {version}, "interface": "cs"}}, logs)
{"fmu.setupExperiment(startTime=0.0)" if version == 2 else ""}
fmu.enterInitializationMode({"startTime=0.0" if version == 3 else ""})
fmu.exitInitializationMode()
try:
    fmu.getDirectionalDerivative([vr["der(x)"]], [vr["x"]], [1.0])
    print("NOT REFUSED")
except Exception:
    print("REFUSED", logs[-1])
fmu.doStep(0.0, 0.1)
fmu.terminate()
fmu.freeInstance()
"""
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert "REFUSED" in proc.stdout and "NOT REFUSED" not in proc.stdout
        assert "not provided by an FMU of time-varying coefficients" in proc.stdout


def _tool(name, what):
    given = os.environ.get(name)
    if not given:
        pytest.skip(f"{what} not found: set {name}")
    return given


@pytest.mark.parametrize("version", (2, 3))
def test_fmusim_runs_them_clean(built, version, tmp_path):
    """fmusim (Model Exchange with CVODE, Co-Simulation) with the capability declared: exit 0, no warning or
    error logged, the same states (fmusim 0.0.39 does not call the partials: its CVODE makes its own Jacobian)."""
    fmusim = _tool("LSC_FMUSIM", "fmusim (the Reference FMUs' simulator)")
    final = {}
    for interface, solver in (("me", "cvode"), ("cs", "euler")):
        out = tmp_path / f"{interface}.csv"
        cmd = [fmusim, "--interface-type", interface, "--solver", solver, "--tolerance", "1e-10",
               "--output-interval", "0.01", "--stop-time", "2", "--start-value", "p", "0.3", "--output-file", str(out), str(built[version])]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        assert "rror" not in proc.stdout + proc.stderr and "arning" not in proc.stdout + proc.stderr
        with open(out, newline="") as fh:
            rows = list(csv.reader(fh))
        final[interface] = np.array([float(rows[-1][rows[0].index(s)]) for s in STATES])
    assert np.allclose(final["me"], final["cs"], rtol=1e-5, atol=1e-6), final


def test_fmucheck_is_clean(built, tmp_path):
    """The FMU Compliance Checker reads the FMI 2.0 description with the capability and runs both interfaces."""
    fmucheck = _tool("LSC_FMUCHECK", "fmuCheck (modelica-tools/FMUComplianceChecker)")
    for kind in ("cs", "me"):
        unpack = Path(tempfile.mkdtemp(prefix="fc", dir="/tmp" if os.path.isdir("/tmp") else None))
        log = tmp_path / f"{kind}.log"
        cmd = [fmucheck, "-h", "0.01", "-s", "2", "-l", "3", "-k", kind, "-t", str(unpack), "-o",
               str(tmp_path / f"{kind}.csv"), "-e", str(log), str(built[2])]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        finally:
            shutil.rmtree(unpack, ignore_errors=True)
        text = log.read_text()
        assert proc.returncode == 0, text[-2000:]
        summary = re.search(r"FMU reported:\s*(\d+) warning\(s\) and error\(s\)\s*Checker reported:\s*(\d+) "
                            r"Warning\(s\)\s*(\d+) Error\(s\)", text)
        assert summary is not None and summary.groups() == ("0", "0", "0"), text[-2000:]


def test_fmpy_cvode_on_model_exchange_agrees_with_the_exact_steps(built):
    """fmpy's CVode integrates the ME FMU (it does not call the partials: this checks that declaring them left
    Model Exchange as it was) and ends where the Co-Simulation FMU's exact steps do."""
    code = f"""
import json
from fmpy import simulate_fmu
out = {{}}
for kind in ("ModelExchange", "CoSimulation"):
    r = simulate_fmu({str(built[2])!r}, fmi_type=kind, stop_time=2.0, output_interval=0.01, relative_tolerance=1e-10,
                     start_values={{"p": 0.3}}, output=["y", "v", "u"])
    out[kind] = [float(r[s][-1]) for s in ("y", "v", "u")]
print(json.dumps(out))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    assert np.allclose(out["ModelExchange"], out["CoSimulation"], rtol=1e-7, atol=1e-8), out
