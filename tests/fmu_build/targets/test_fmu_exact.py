"""Exact stepping inside the pythonfmu FMU (solver 4) and the Magnus step (solver 5), in subprocesses."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

import lsc  # noqa: E402
from fmu_build import build_fmu  # noqa: E402
from fmu_build.targets._runtime._inputs import _InputSignal  # noqa: E402
from fmu_build.targets._runtime._steppers import _expm_small  # noqa: E402
from lsc import gallery  # noqa: E402

from tests.support import ROOT, SUPPORT  # noqa: E402
SPECS = ROOT / "examples" / "specs"


def run(scenario):
    out = subprocess.run([sys.executable, str(SUPPORT / "fmu_runner.py")], input=json.dumps(scenario), capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return {name: build_fmu(SPECS / f"{name}.toml", tmp_path_factory.mktemp(name))
            for name in ("prescribed_path", "path_input", "path_damper")}


def _states(r):
    return np.array(r["time"]), np.array([r["values"][n] for n in ("y", "v", "u")])


def _expm_reference(c, t, x0):
    res = lsc.solve_completion(c, (t[0], t[-1]), x0, t_eval=t, method="expm", rtol=1e-14, atol=1e-16)
    assert res.success
    return res.x


@pytest.mark.parametrize("dt", [0.1, 0.01])
def test_exact_stepping_equals_the_library_expm(fmus, dt):
    # sin forcing: a Taylor polynomial of degree 5 per (sub)step; dt = 0.1 needs substeps
    p = gallery.prescribed_path()
    x0 = p.exact(0.0) + 1e-3
    steps = int(round(2.0 / dt))
    r = run({"fmu": str(fmus["prescribed_path"]), "dt": dt, "steps": steps, "outputs": ["y", "v", "u", "constraint_residual"],
             "start_values": {"y_0": x0[0], "v_0": x0[1], "u_0": x0[2]}})
    assert r["status"] == ["ok"] * steps and r["logs"] == []
    t, X = _states(r)
    ref = _expm_reference(lsc.complete(p.dae, "alternative", lam=2.0), t, x0)
    assert np.abs(X - ref).max() < 1e-10
    # off-manifold errors decay like exp(-lam h) per step, to rounding
    res = np.array(r["values"]["constraint_residual"])
    np.testing.assert_allclose(res[1:] / res[:-1], math.exp(-2.0 * dt), rtol=1e-7)


def _poly_input_dae(coef):
    """The path_input DAE with the input p given as the polynomial sum coef[j] t^j (sympy)."""
    import sympy

    t = sympy.Symbol("t")
    path = sum(c * t**j for j, c in enumerate(coef))
    A = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 0]])
    B = np.array([[0, -1.0, 0], [2.0, 0.5, -1.0], [1.0, 0, 0]])
    return lsc.LinearDAE(A, B, sympy.Matrix([0, 0, path]))


@pytest.mark.parametrize("degree", [3, 5])
def test_polynomial_input_up_to_the_estimators_degree_is_stepped_exactly(fmus, degree):
    # the estimator of p (it needs p''') fits degree 5 through the last 6 values: once it has
    # them, every step is the exact step of the DAE with that polynomial as its forcing
    coef = [0.2, -0.5, 0.3, 0.1, -0.05, 0.01][: degree + 1]
    dt, steps = 0.05, 30
    ts = dt * np.arange(steps)
    r = run({"fmu": str(fmus["path_input"]), "dt": dt, "steps": steps, "outputs": ["y", "v", "u"],
             "start_values": {"y_0": 0.2, "v_0": -0.5}, "input_series": {"p": np.polyval(coef[::-1], ts).tolist()}})
    assert r["status"] == ["ok"] * steps
    t, X = _states(r)
    c = lsc.complete(_poly_input_dae(coef), "alternative", lam=5.0)
    full = degree + 1  # from this step on the estimate is the polynomial itself
    ref = _expm_reference(c, t[full - 1:], X[:, full - 1])
    assert np.abs(X[:, full - 1:] - ref).max() < 1e-10


def test_rollback_is_bit_for_bit_with_exact_stepping(fmus):
    for name, extra in (("prescribed_path", {}), ("path_input", {"input_series": {"p": np.sin(0.1 * np.arange(9)).tolist()}})):
        r = run({"fmu": str(fmus[name]), "dt": 0.1, "steps": 9, "outputs": ["y", "v", "u"], "rollback_at": 6, **extra})
        assert r["status"] == ["ok"] * 9
        assert r["rollback"]["first"] == r["rollback"]["second"]


def test_lambda_change_mid_run_equals_a_piecewise_library_run(fmus):
    p = gallery.prescribed_path()
    x0 = p.exact(0.0) + 1e-3
    r = run({"fmu": str(fmus["prescribed_path"]), "dt": 0.05, "steps": 20, "outputs": ["y", "v", "u"],
             "start_values": {"y_0": x0[0], "v_0": x0[1], "u_0": x0[2]}, "set_at": {"8": {"lambda": 7.0}}})
    t, X = _states(r)
    first = _expm_reference(lsc.complete(p.dae, "alternative", lam=2.0), t[:9], x0)
    second = _expm_reference(lsc.complete(p.dae, "alternative", lam=7.0), t[8:], first[:, -1])
    assert np.abs(X - np.hstack([first, second[:, 1:]])).max() < 1e-10


def test_exact_stepping_is_the_default_for_constant_coefficients_and_needs_no_stiff_switch(fmus):
    # lambda = 1e8: the exponential is unconditionally stable; no solver switch, no warning
    p = gallery.prescribed_path()
    x0 = np.array([0.0, 2.5, 1.25])
    r = run({"fmu": str(fmus["prescribed_path"]), "dt": 0.01, "steps": 3, "outputs": ["y", "v", "u"],
             "start_values": {"lambda": 1e8}})
    assert r["status"] == ["ok"] * 3 and r["logs"] == []
    t, X = _states(r)
    ref = _expm_reference(lsc.complete(p.dae, "alternative", lam=1e8), t, x0)
    assert np.abs(X - ref).max() < 1e-9


def test_exact_stepping_is_refused_for_time_varying_coefficients(fmus):
    r = run({"fmu": str(fmus["path_damper"]), "dt": 0.01, "steps": 1, "outputs": ["y"], "set_at": {"0": {"solver": 4}}})
    assert r["status"] == ["discard"]
    assert any("solver 4 (exact) needs constant coefficients" in m for m in r["logs"]), r["logs"]


def _damper_exact(t):
    p, dp, ddp = np.sin(t) + 0.5 * np.sin(3 * t), np.cos(t) + 1.5 * np.cos(3 * t), -np.sin(t) - 4.5 * np.sin(3 * t)
    return np.array([p, dp, ddp + (0.5 + 0.2 * np.sin(t)) * dp + 2.0 * p])


def test_magnus_step_follows_the_damper_exactly_and_rolls_back_bit_for_bit(fmus):
    dt, steps = 0.01, 300
    ts = dt * np.arange(steps)
    series = {"c": (0.5 + 0.2 * np.sin(ts)).tolist()}
    r = run({"fmu": str(fmus["path_damper"]), "dt": dt, "steps": steps, "outputs": ["y", "v", "u"],
             "start_values": {"solver": 5}, "input_series": series, "rollback_at": 200})
    assert r["status"] == ["ok"] * steps
    assert r["rollback"]["first"] == r["rollback"]["second"]
    t, X = _states(r)
    late = t >= 2.0  # after the estimator's start-up error has decayed like exp(-lam t)
    assert np.abs(X - _damper_exact(t))[:, late].max() < 1e-6


def test_input_estimate_derivatives_are_exact_for_a_polynomial():
    signal = _InputSignal(3, 0.0, 9)
    u = np.polynomial.Polynomial([0.3, -1.0, 0.5, 2.0, -0.25, 0.125])  # degree 5 = order + 2
    for t in 0.7 + 0.1 * np.arange(6):  # (the 5th derivative from 6 values amplifies rounding by ~1e3 / h^5)
        signal.value = u(t)
        signal.record(t)
    t = signal.history[-1][0]
    want = [u.deriv(j)(t) if j else u(t) for j in range(10)]
    np.testing.assert_allclose(signal.taylor(t, 9), want, rtol=1e-7, atol=1e-8 * np.abs(want).max())
    s = t + 0.04  # extrapolated within the step
    np.testing.assert_allclose(signal.taylor(s, 5), [u.deriv(j)(s) if j else u(s) for j in range(6)], rtol=1e-7)
    assert np.all(signal.jet(t)[4:] == 0.0)  # the completion's jet: orders above 3 are never used


def test_small_expm_equals_scipy():
    import scipy.linalg

    rng = np.random.default_rng(1)
    for scale in (1e-3, 0.3, 5.0, 80.0):
        A = rng.standard_normal((4, 4)) * scale
        ref = scipy.linalg.expm(A)
        assert np.abs(_expm_small(A) - ref).max() <= 1e-13 * np.abs(ref).max()
