"""Exact partial derivatives of the native FMUs: fmi2GetDirectionalDerivative, fmi3GetDirectionalDerivative and
fmi3GetAdjointDerivative against lsc's own completion.

A constant-coefficient completion x' = G x + W [f; f'; ...] knows its Jacobian: d x'/d x = G,
d x'/d u = W d[f; f'; ...]/d u, and the outputs' formulas give theirs. Each FMU runs in a subprocess
(tests/native_directional_runner.py, fmpy) in FMI 2.0 and 3.0, Model Exchange and Co-Simulation, in
Initialization Mode (the knowns are the states' start values) and after steps; its products with unit seeds
must equal G, W's input column and the output map computed here from ``lsc.complete(...).maps()`` to 1e-12
relative. The capability is declared in the model descriptions; fmuCheck and fmusim run the FMUs clean.
"""
import csv
import json
import os
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

HERE = Path(__file__).parent
RUNNER = HERE / "native_directional_runner.py"
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
                          timeout=300, cwd=HERE)
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


def test_declared_in_both_descriptions(built):
    for version, flags in ((2, ['providesDirectionalDerivative="true"']),
                           (3, ['providesDirectionalDerivatives="true"', 'providesAdjointDerivatives="true"'])):
        with zipfile.ZipFile(built[version]) as zf:
            xml = zf.read("modelDescription.xml").decode()
        for flag in flags:
            assert xml.count(flag) == 2, flag  # Model Exchange and Co-Simulation
        assert "dependencies=" in xml
