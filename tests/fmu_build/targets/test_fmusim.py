"""fmusim, the Modelica Reference FMUs' simulator, as an independent FMI 2.0 and 3.0 host of the native FMUs.

fmusim (modelica/Reference-FMUs) hosts Co-Simulation and Model Exchange FMUs of FMI 1.0, 2.0 and 3.0;
in Model Exchange it integrates with forward Euler (one step per output interval) or CVODE. Here it
runs native FMUs without inputs, built as FMI 2.0 and as FMI 3.0: one with constant ``A``, ``B``
(examples/specs/prescribed_path.toml, index 3) and one with time-varying ones (test_native_timevarying's
Rot3, index 3, its constraint rotating with ``t``). Every run is a subprocess that must exit 0, and its
output is compared with the exact solution: Co-Simulation at the FMU's own accuracy, Euler at its first
order, CVODE at its tolerance, and an inconsistent start forgotten like ``exp(-lambda t)`` with
``lambda`` set by the host.

fmusim is not built here. ``LSC_FMUSIM`` names the executable, else one on ``PATH``; without either the
tests skip with that reason (with ``CI=true`` that skip is a failure: tests/conftest.py).
"""
import csv
import os
import shutil
import subprocess

import numpy as np
import pytest

from lsc import gallery
from tests.fmu_build.targets.test_native_timevarying import PROBLEMS, _exact, _names

from tests.support import ROOT

SPECS = ROOT / "examples" / "specs"
STOP, DT = 2.0, 0.01
MODELS = ("constant", "timevarying")
VERSIONS = (2, 3)


def _find_fmusim():
    given = os.environ.get("LSC_FMUSIM")
    if given:
        if not (os.path.isfile(given) and os.access(given, os.X_OK)):
            pytest.fail(f"LSC_FMUSIM={given!r} is not an executable file")
        return given
    found = shutil.which("fmusim")
    if found:
        return found
    pytest.skip("fmusim not found: set LSC_FMUSIM to the Reference FMUs' fmusim (modelica/Reference-FMUs)")


@pytest.fixture(scope="module")
def fmusim():
    return _find_fmusim()


@pytest.fixture(scope="module")
def fmus(fmusim, tmp_path_factory):
    """(model, FMI version): the FMU, built once for the module."""
    from fmu_build import build_fmu

    folder = tmp_path_factory.mktemp("fmusim")
    built = {}
    for v in VERSIONS:
        built["constant", v] = build_fmu(SPECS / "prescribed_path.toml", folder / f"constant{v}", target="native",
                                         fix_parameters=True, fmi_version=v)
        built["timevarying", v] = build_fmu(PROBLEMS["Rot3"][0], folder / f"timevarying{v}", target="native",
                                            fmi_version=v)
    return built


_PATH = gallery.prescribed_path()


def states(model):
    return ["y", "v", "u"] if model == "constant" else _names(PROBLEMS["Rot3"][0])


def exact(model, t):
    """The exact solution at the times `t`, one row per state (in `states(model)` order)."""
    return _PATH.exact(t) if model == "constant" else _exact("Rot3", t)


def simulate(fmusim, fmu, folder, interface, solver="euler", step=DT, options=()):
    """Run `fmu` in fmusim in a subprocess up to STOP; the output file's columns by name."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{interface}-{solver}-{step!r}.csv"
    cmd = [fmusim, "--interface-type", interface, "--solver", solver, "--output-interval", repr(step),
           "--stop-time", repr(STOP), "--output-file", str(out), *options, str(fmu)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"{' '.join(cmd)}: exit {proc.returncode}\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}"
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    data = np.array(rows[1:], dtype=float)
    cols = {name: data[:, j] for j, name in enumerate(rows[0])}
    assert cols["time"][0] == 0.0 and cols["time"][-1] == pytest.approx(STOP, abs=1e-12)
    return cols


def max_error(model, cols):
    """Largest error of any state against the exact solution, relative to 1 + |exact|."""
    X = exact(model, cols["time"])
    return max(float(np.max(np.abs(cols[name] - X[i]) / (1 + np.abs(X[i])))) for i, name in enumerate(states(model)))


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS)
def test_cosimulation_is_exact(fmusim, fmus, model, version, tmp_path):
    """The FMU steps itself (matrix exponential, or its own error control for time-varying tables)."""
    cols = simulate(fmusim, fmus[model, version], tmp_path, "cs")
    assert len(cols["time"]) == round(STOP / DT) + 1
    assert max_error(model, cols) < 1e-8  # measured 3.2e-10 (constant) and 1.7e-13 (time-varying)
    # time-varying: the residual's Gram form loses half the digits near zero (docs/native_fmu.md), measured 9.4e-8
    assert np.max(cols["constraint_residual"]) < (1e-8 if model == "constant" else 1e-6)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS)
def test_model_exchange_euler_converges_at_first_order(fmusim, fmus, model, version, tmp_path):
    """Forward Euler on x' = G x + g: the error halves with the step iff the FMU's derivatives are exact."""
    errors = [max_error(model, simulate(fmusim, fmus[model, version], tmp_path, "me", "euler", step=h))
              for h in (0.004, 0.002)]
    assert errors[1] < 0.02, errors  # measured 9.3e-3 and 1.0e-2
    assert 1.8 < errors[0] / errors[1] < 2.2, errors  # measured 2.00


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS)
def test_model_exchange_cvode_reaches_its_tolerance(fmusim, fmus, model, version, tmp_path):
    loose, tight = (max_error(model, simulate(fmusim, fmus[model, version], tmp_path / tol, "me", "cvode",
                                              options=["--tolerance", tol]))
                    for tol in ("1e-6", "1e-10"))
    assert loose < 1e-4  # measured 1.2e-5 and 1.4e-5
    assert tight < 1e-7 and tight < loose / 100, (loose, tight)  # measured 1.8e-9 and 9.2e-9


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("interface", ["cs", "me"])
def test_inconsistent_start_decays_at_the_rate_the_host_sets(fmusim, fmus, model, version, interface, tmp_path):
    """The host sets lambda = 5 and a first state's start 0.01 off the manifold: the alternative completion's
    constraint residual ||Z2^T (F x - g)|| decays exactly like exp(-5 t)."""
    first = states(model)[0]
    start = float(exact(model, np.array([0.0]))[0, 0]) + 0.01
    options = ["--start-value", "lambda", "5", "--start-value", f"{first}_0", repr(start)]
    if interface == "me":
        options += ["--solver", "cvode", "--tolerance", "1e-10"]
    cols = simulate(fmusim, fmus[model, version], tmp_path, interface, options=options)
    t, r = cols["time"], cols["constraint_residual"]
    assert r[0] > 1e-3  # the start is off the manifold (measured 1.5e-2 and 1.1e-2)
    early = t <= 1.0  # exp(-5) r(0) ~ 1e-4: well above the integration error
    assert np.max(np.abs(r[early] / r[0] - np.exp(-5.0 * t[early]))) < 1e-6  # measured 3e-9 to 6e-9 (CS), 7e-8 to 8e-8 (ME)


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_build_equals_fmi2_build(fmusim, fmus, model, tmp_path):
    """One C core under two FMI layers: the same numbers in both interfaces."""
    for interface in ("cs", "me"):
        fmi2, fmi3 = (simulate(fmusim, fmus[model, v], tmp_path / f"v{v}", interface) for v in VERSIONS)
        for name in states(model):
            np.testing.assert_allclose(fmi3[name], fmi2[name], rtol=0, atol=1e-12)


def test_a_value_the_fmu_refuses_ends_the_run_with_its_reason(fmusim, fmus, tmp_path):
    """Setting an output is refused by the FMU (fmi2Error); fmusim stops and exits non-zero with the reason."""
    out = tmp_path / "r.csv"
    proc = subprocess.run([fmusim, "--interface-type", "cs", "--stop-time", "1", "--start-value", "y", "1",
                           "--output-file", str(out), str(fmus["constant", 2])],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert "is not a parameter or an input" in proc.stdout + proc.stderr
