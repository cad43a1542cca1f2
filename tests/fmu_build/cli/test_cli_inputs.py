"""`lsc-fmu simulate --input`: a table fitted smoothly, the input's derivatives sent from the start.

The model is ``examples/specs/rlc_source.toml``: an RLC circuit in MNA form (index 2) driven by a voltage
source u = sin t (``examples/inputs/rlc_source.csv``, rows 0.01 apart), its start consistent with that
input (the source current iV(0) = -C1 u'(0)). Its exact solution is known in closed form. A run that
takes u'(0) = u''(0) = 0 carries that start error along the circuit's own dynamics (decaying like
exp(-t)); a run given the input's derivatives does not.
"""
import csv
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg

from tests.support import ROOT
SPEC = ROOT / "examples" / "specs" / "rlc_source.toml"
TABLE = ROOT / "examples" / "inputs" / "rlc_source.csv"
R, L, C1, C2 = 1.0, 0.5, 0.2, 0.25
STATES = ("e1", "e2", "e3", "iL", "iV")


def exact(t):
    """[e1, e2, e3, iL, iV] at times t for u = sin t and the spec's start (e3 = iL = 0 at t = 0)."""
    t = np.asarray(t, dtype=float)
    # z = [e3, iL]: C2 e3' = iL, L iL' = e2 - e3 = u - R iL - e3
    M = np.array([[0.0, 1.0 / C2], [-1.0 / L, -R / L]])
    b = np.array([0.0, 1.0 / L])
    w = np.linalg.solve(1j * np.eye(2) - M, b)  # particular solution Im(w exp(i t))
    particular = np.imag(np.outer(w, np.exp(1j * t)))
    z0 = -np.imag(w)
    z = particular + np.array([scipy.linalg.expm(M * s) @ z0 for s in t]).T
    e3, iL = z
    u, du = np.sin(t), np.cos(t)
    return np.array([u, u - R * iL, e3, iL, -C1 * du - iL])


def test_exact_solution_solves_the_dae():
    # A x' + B x = f with the spec's matrices, by central differences (the reference checked before use)
    A = np.array([[C1, 0, 0, 0, 0], [0, 0, 0, 0, 0], [0, 0, C2, 0, 0], [0, 0, 0, L, 0], [0, 0, 0, 0, 0]])
    B = np.array([[1 / R, -1 / R, 0, 0, 1], [-1 / R, 1 / R, 0, 1, 0], [0, 0, 0, -1, 0], [0, -1, 1, 0, 0],
                  [1, 0, 0, 0, 0]])
    t, h = np.linspace(0.5, 5.5, 11), 1e-5
    dx = (exact(t + h) - exact(t - h)) / (2 * h)
    residual = A @ dx + B @ exact(t) - np.outer([0, 0, 0, 0, 1], np.sin(t))
    assert np.abs(residual).max() < 1e-9
    assert np.abs(exact([0.0])[:, 0] - [0, 0, 0, 0, -C1]).max() < 1e-15  # the spec's start values


def _lsc_fmu(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "fmu_build", *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=cwd, env=env)


def _states(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    names = [n.strip().strip('"') for n in rows[0]]
    data = np.array([[float(v) for v in row] for row in rows[1:] if row])
    return data[:, 0], np.array([data[:, names.index(n)] for n in STATES])


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    pytest.importorskip("fmpy")
    from fmu_build import build_fmu

    return build_fmu(SPEC, tmp_path_factory.mktemp("rlc"), target="native")


def test_simulate_sends_the_input_derivatives_from_the_start(native, tmp_path):
    proc = _lsc_fmu("simulate", native, "--input", TABLE, "-o", tmp_path / "run.csv", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    t, X = _states(tmp_path / "run.csv")
    assert abs(t[-1] - 6.0) < 1e-9
    late = t >= 2.0
    err = np.abs(X - exact(t))[:, late].max()
    assert err < 1e-5, err  # with u'(0) = u''(0) = 0 taken: 4.4e-4


def test_linear_input_is_fmpys_values_only(native, tmp_path):
    # the table interpolated linearly, values only: the FMU guesses u'(0) = u''(0) = 0 and that start stays
    proc = _lsc_fmu("simulate", native, "--input", TABLE, "--linear-input", "-o", tmp_path / "run.csv", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    t, X = _states(tmp_path / "run.csv")
    err = np.abs(X - exact(t))[:, t >= 2.0].max()
    assert 1e-4 < err < 1e-3, err  # 4.4e-4


def test_a_pythonfmu_fmu_gets_values_and_the_run_says_the_start_was_guessed(tmp_path):
    pytest.importorskip("pythonfmu")
    from fmu_build import build_fmu

    fmu = build_fmu(SPEC, tmp_path / "py")
    proc = _lsc_fmu("simulate", fmu, "--input", TABLE, "--stop-time", "3", "-o", tmp_path / "run.csv", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "u: values only (the FMU does not declare canInterpolateInputs)" in proc.stderr
    assert "2 of the derivatives 1..2 at t = 0 guessed" in proc.stderr and "--native" in proc.stderr
    t, X = _states(tmp_path / "run.csv")
    assert np.abs(X - exact(t))[:, t >= 2.0].max() < 1e-3  # the guessed start, decaying like exp(-t)


def test_the_native_start_report_says_guessed_or_given(native):
    pytest.importorskip("fmpy")
    # the FMU runs in a subprocess: a native FMU's fault must not take the test process down
    code = f"""
import json
import numpy as np
from fmpy import simulate_fmu
from fmu_build import fit_inputs, simulate_with_inputs

fit = fit_inputs({str(TABLE)!r})
messages = []

def logger(env, instance, status, category, message):
    messages.append(message.decode())

simulate_fmu({str(native)!r}, stop_time=0.1, output_interval=0.01, input=fit.sample(np.linspace(0, 0.1, 11)),
             logger=logger, debug_logging=True)
notes = []
simulate_with_inputs({str(native)!r}, fit, stop_time=0.1, notes=notes)
print(json.dumps({{"messages": messages, "notes": notes}}))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    messages, notes = out["messages"], out["notes"]
    assert any("input u: 2 of the derivatives 1..2 at t = 0 guessed, not given (fmi2SetRealInputDerivatives)" in m
               for m in messages), messages
    assert notes == ["u: derivatives 1..6 sent at every communication point, the start included"]


def test_fit_and_run_refuse_what_they_cannot_use(native, tmp_path):
    from fmu_build import fit_inputs, simulate_with_inputs

    with pytest.raises(ValueError, match="strictly increasing"):
        fit_inputs({"time": [0.0, 0.0], "u": [1.0, 2.0]})
    with pytest.raises(ValueError, match="column `u` must hold 2 finite numbers"):
        fit_inputs({"time": [0.0, 1.0], "u": [1.0, float("nan")]})
    with pytest.raises(ValueError, match="no `time` column"):
        fit_inputs({"t": [0.0, 1.0], "u": [1.0, 2.0]})
    with pytest.raises(ValueError, match="the fit does not extrapolate"):
        fit_inputs({"time": [0.0, 1.0], "u": [1.0, 2.0]}).sample([1.5])
    with pytest.raises(ValueError, match="column `v` is not a Real input of the FMU"):
        simulate_with_inputs(native, {"time": [0.0, 6.0], "v": [0.0, 1.0]})
    with pytest.raises(ValueError, match="must lie in the table's times"):
        simulate_with_inputs(native, {"time": [0.0, 1.0], "u": [0.0, 1.0]}, stop_time=2.0)
