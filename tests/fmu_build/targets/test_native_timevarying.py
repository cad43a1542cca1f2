"""Native FMUs of DAEs with time-varying A(t), B(t): the exact solution, the library, lambda, rollback, horizon.

Four problems of index 1 to 3 with exact solutions (manufactured: f = A x*' + B x*
in sympy), among them two rotating constraints and the gallery's
`rotating_canonical` written in sympy; each FMU runs in a subprocess
(tests/support/native_runner.py, fmpy) with lsc, sympy, scipy and fmu_build blocked.
"""
import os
import subprocess
import zipfile

import numpy as np
import pytest
import sympy as sp

import lsc
from fmu_build import build_fmu, parse_spec
from fmu_build.targets import _native_tv
from fmu_build.targets.native import NativeTargetError
from tests.fmu_build.targets.test_native import rel_err, run
from tests.fmu_build.targets.test_native_accuracy import _compile_strict

BLOCK = ["lsc", "sympy", "scipy", "fmu_build"]
T = sp.Symbol("t")
STOP, DT = 2.0, 0.01


XE = {}  # the exact solutions in sympy, by model name


def _spec(name, A, B, xe, lam=2.0, stop=STOP, method="alternative", f=None):
    A, B, xe = sp.Matrix(A), sp.Matrix(B), sp.Matrix(xe)
    XE[name] = xe
    f = A * xe.diff(T) + B * xe if f is None else f
    n = A.shape[0]
    rows = lambda M: [[str(e) for e in M.row(i)] for i in range(n)]  # noqa: E731
    d = {"model": {"name": name}, "states": {f"x{i + 1}": {"start": float(xe[i].subs(T, 0))} for i in range(n)},
         "equations": {"A": rows(A), "B": rows(B), "f": [str(e) for e in f]},
         "completion": {"method": method, "lam": lam}, "experiment": {"start": 0.0, "stop": stop, "step": DT}}
    return d, sp.lambdify(T, xe, "numpy")


def _plane_rotation(n, i, j, angle):
    R = sp.eye(n)
    R[i, i] = R[j, j] = sp.cos(angle)
    R[i, j], R[j, i] = -sp.sin(angle), sp.sin(angle)
    return R


def rotating_canonical_sympy(index=2):
    """The construction of `lsc.gallery.rotating_canonical` with one plane rotation on each side.

    ``A = P E Q^T``, ``B = P (Ab - E Q^T Q') Q^T``, ``x = Q y``: a damped oscillator and one nilpotent chain
    of length `index`, equations turned by ``P(t)`` (mixing the oscillator with the chain's head) and unknowns
    by ``Q(t)`` (mixing the oscillator with the chain's tail), so the constraints rotate. (The gallery's
    products of n - 1 rotations exceed the spec's expression limits once differentiated.)
    """
    n = 2 + index
    E, Ab = sp.zeros(n, n), sp.zeros(n, n)
    E[0, 0] = E[1, 1] = 1
    for i in range(index - 1):
        E[2 + i, 3 + i] = 1
    Ab[:2, :2] = sp.Matrix([[sp.Rational(1, 2), 1], [-1, sp.Rational(1, 2)]])
    Ab[2:, 2:] = sp.eye(index)
    P, Q = _plane_rotation(n, 1, 2, T), _plane_rotation(n, 0, n - 1, sp.Rational(7, 10) * T)
    A = P * E * Q.T
    B = P * (Ab - E * sp.simplify(Q.T * Q.diff(T))) * Q.T
    y = sp.Matrix([sp.sin((1 + sp.Rational(3, 10) * j) * T + j) + sp.Rational(1, 2) for j in range(n)])
    return A, B, Q * y, P * (E * y.diff(T) + Ab * y)  # f = A x' + B x = P (E y' + Ab y)


PROBLEMS_SOURCES = {"Rot2": dict(A=[[1, 0, 0], [0, 1, 0], [0, 0, 0]],
                                 B=[[0, 0, -sp.cos(T)], [0, 0, -sp.sin(T)], [sp.cos(T), sp.sin(T), 0]],
                                 xe=[sp.cos(2 * T) + 1, sp.sin(T), sp.exp(-T)])}


def _problems():
    c, s = sp.cos(T), sp.sin(T)
    out = {}
    # index 1, A(t) time-varying
    out["Tv1"] = _spec("Tv1", [[2 + c, 0], [0, 0]], [[1, 1], [s, 1]], [sp.exp(-T / 2) + s, sp.cos(2 * T)])
    # index 2: a point pushed along a direction n(t) that rotates, kept on the rotating line n(t).x = f3
    out["Rot2"] = _spec("Rot2", **PROBLEMS_SOURCES["Rot2"])
    # index 3: positions q, velocities v, force mu along n(t); the constraint n(t).q = f5 rotates
    out["Rot3"] = _spec("Rot3", np.diag([1, 1, 1, 1, 0]).tolist(),
                        [[0, 0, -1, 0, 0], [0, 0, 0, -1, 0], [0, 0, 0, 0, -c], [0, 0, 0, 0, -s], [c, s, 0, 0, 0]],
                        [c + 2, sp.sin(2 * T), -s, 2 * sp.cos(2 * T), sp.cos(T / 3)])
    A, B, xe, f = rotating_canonical_sympy(2)
    out["RotCanon2"] = _spec("RotCanon2", A, B, xe, f=f)
    return out


PROBLEMS = _problems()
INDEX = {"Tv1": 1, "Rot2": 2, "Rot3": 3, "RotCanon2": 2}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tv")
    return {name: build_fmu(d, folder, target="native") for name, (d, _) in PROBLEMS.items()}


def _names(d):
    return list(d["states"])


def _exact(name, times):
    return np.array(PROBLEMS[name][1](np.asarray(times)), dtype=float).reshape(len(PROBLEMS[name][0]["states"]), -1)


def _library(d, times, lam=None, x0=None, t0=None):
    spec = parse_spec(d)
    c = lsc.complete(spec.linear_dae(), spec.method, lam=lam or spec.lam)
    x0 = np.array([s["start"] for s in spec.states]) if x0 is None else x0
    times = np.asarray(times)
    res = lsc.solve_completion(c, (times[0] if t0 is None else t0, times[-1]), x0, method="DOP853", t_eval=times,
                               rtol=1e-12, atol=1e-13)
    assert res.success
    return res.x


def test_rotating_canonical_problem_is_exact():
    A, B, xe, f = rotating_canonical_sympy(2)
    for t in (0.3, 1.7):
        r = (A * xe.diff(T) + B * xe - f).subs(T, t)
        assert np.abs(np.array(r.evalf(), dtype=float)).max() < 1e-13


@pytest.mark.parametrize("name", list(PROBLEMS))
def test_cosimulation_matches_exact_solution_and_library(built, name):
    d = PROBLEMS[name][0]
    assert lsc.complete(parse_spec(d).linear_dae(), "alternative", lam=2.0).k >= INDEX[name] - 1
    steps = int(round(STOP / DT))
    r = run({"fmu": str(built[name]), "dt": DT, "steps": steps, "outputs": _names(d) + ["constraint_residual"],
             "block": BLOCK})
    assert all(r["blocked"].values()), r["blocked"]
    assert set(r["status"]) == {"ok"}
    got = np.array(r["values"]).T
    exact = _exact(name, r["time"])
    assert rel_err(got[:-1], exact) < 1e-8
    assert rel_err(got[:-1], _library(d, r["time"])) < 1e-8
    # the residual's Gram form x^T M x - 2 m^T x + s loses half the digits near zero: ~ sqrt(eps) |x|
    assert np.abs(got[-1]).max() < 1e-6


@pytest.mark.parametrize("name", list(PROBLEMS))
def test_model_exchange_returns_G_x_plus_g(built, name):
    d = PROBLEMS[name][0]
    r = run({"fmu": str(built[name]), "interface": "me", "dt": DT, "steps": int(round(STOP / DT)),
             "outputs": _names(d), "rtol": 1e-10, "block": BLOCK})
    assert all(r["blocked"].values())
    got = np.array(r["values"]).T
    assert rel_err(got, _exact(name, r["time"])) < 1e-6  # CVode at rtol 1e-10 on the drift-free completion


def test_lambda_changed_mid_run_equals_piecewise_library_run(built):
    d = PROBLEMS["Rot3"][0]
    x0 = np.array([s["start"] for s in parse_spec(d).states]) + np.array([0, 0, 0, 0, 1e-3])  # off the manifold
    start = {name: float(v) for name, v in zip(_names(d), x0)}
    r = run({"fmu": str(built["Rot3"]), "dt": DT, "steps": 100, "outputs": _names(d),
             "start_values": {f"{k}_0": v for k, v in start.items()}, "set_at": {"50": {"lambda": 7.0}}})
    assert set(r["status"]) == {"ok"}
    t = np.array(r["time"])
    X1 = _library(d, t[:51], x0=x0)
    X2 = _library(d, t[50:], lam=7.0, x0=X1[:, -1])
    got = np.array(r["values"]).T
    assert rel_err(got[:, :51], X1) < 1e-8 and rel_err(got[:, 50:], X2) < 1e-8
    # and lambda did something: the run at 2 only differs
    assert np.abs(got[:, -1] - _library(d, t, x0=x0)[:, -1]).max() > 1e-7


@pytest.mark.parametrize("serialize", [False, True])
def test_rollback_bit_for_bit(built, serialize):
    d = PROBLEMS["RotCanon2"][0]
    r = run({"fmu": str(built["RotCanon2"]), "dt": DT, "steps": 60, "outputs": _names(d), "rollback_at": 20,
             "serialize": serialize})
    assert r["rollback"]["values"] == r["rollback"]["original"]


def test_refuses_steps_past_the_horizon_with_a_logged_reason(built):
    d = PROBLEMS["Rot2"][0]
    steps = int(round(STOP * (1 + _native_tv.HORIZON_MARGIN) / DT)) + 5
    r = run({"fmu": str(built["Rot2"]), "dt": DT, "steps": steps, "outputs": _names(d)})
    assert r["status"][-1].startswith(f"step {steps - 5}")  # 220 steps reach 2.2, the next one leaves it
    assert any("leaves the horizon" in m for m in r["logs"])
    assert sum(s == "ok" for s in r["status"]) == steps - 5


def test_compiles_warning_free(built, tmp_path):
    proc = _compile_strict(built["Rot3"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    with zipfile.ZipFile(built["Rot3"]) as zf:
        header = zf.read("sources/model.h").decode()
        names = zf.namelist()
    assert "sources/model_timevarying.c" in names and "sources/model_constant.c" not in names  # its backend only
    assert "#define LSC_TIME_VARYING 1" in header


def test_refuses_inputs_and_tunable_parameters(tmp_path):
    d, _ = PROBLEMS["Tv1"]
    with_input = dict(d, inputs={"u": {}})
    with_input["equations"] = dict(d["equations"], f=[d["equations"]["f"][0] + " + u**2", d["equations"]["f"][1]])
    with pytest.raises(NativeTargetError, match="not affine in the input"):  # affine inputs: test_native_timevarying_inputs.py
        build_fmu(with_input, tmp_path, target="native")
    with_par = dict(d, parameters={"a": {"value": 1.0, "tunable": True}})
    with_par["equations"] = dict(d["equations"], f=[d["equations"]["f"][0] + " + a", d["equations"]["f"][1]])
    with pytest.raises(NativeTargetError, match="fix_parameters"):
        build_fmu(with_par, tmp_path, target="native")


def test_refuses_tables_beyond_the_piece_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(_native_tv, "DEGREES", (8,))
    monkeypatch.setattr(_native_tv, "MAX_PIECES", 4)
    with pytest.raises(NativeTargetError, match="limit of 4 pieces"):
        build_fmu(PROBLEMS["Rot2"][0], tmp_path, target="native")
    assert not list(tmp_path.glob("*.fmu*"))


def test_tables_beyond_the_fast_budget_take_higher_degrees(tmp_path, monkeypatch):
    # no room to split pieces to the lowest degree: they keep the degrees of the first fit (up to the highest)
    monkeypatch.setattr(_native_tv, "FAST_COEFFICIENTS", 0)
    d = PROBLEMS["Rot3"][0]
    fmu = build_fmu(d, tmp_path, target="native")
    with zipfile.ZipFile(fmu) as zf:
        description = zf.read("modelDescription.xml").decode()
    assert f"-{_native_tv.DEGREES[-1]}, coefficient tail" in description  # pieces up to the highest degree
    r = run({"fmu": str(fmu), "dt": DT, "steps": 200, "outputs": _names(d), "block": BLOCK})
    assert set(r["status"]) == {"ok"}
    assert rel_err(np.array(r["values"]).T, _exact("Rot3", r["time"])) < 1e-8


@pytest.mark.parametrize("method", ["standard", "stabilized"])
def test_other_completions_fixed_lambda(tmp_path, method):
    d, _ = _spec("Rot2" + method.capitalize(), *[PROBLEMS_SOURCES["Rot2"][k] for k in ("A", "B", "xe")], method=method)
    fmu = build_fmu(d, tmp_path, target="native")
    r = run({"fmu": str(fmu), "dt": DT, "steps": 100, "outputs": _names(d)})
    assert set(r["status"]) == {"ok"}
    exact = np.array(PROBLEMS["Rot2"][1](np.asarray(r["time"])), dtype=float).reshape(3, -1)
    assert rel_err(np.array(r["values"]).T, exact) < 1e-8


def test_validates_clean(built):
    from fmpy.validation import validate_fmu

    for fmu in built.values():
        assert validate_fmu(str(fmu)) == []


def test_c_master_under_address_and_ub_sanitizers(built, tmp_path):
    from tests.fmu_build.targets.test_native import _master, _sanitized_library, _unpacked

    guid, vrs = _unpacked(built["Rot3"], tmp_path)
    lib = _sanitized_library(tmp_path)
    exe = _master(tmp_path, sanitize=True)
    names = _names(PROBLEMS["Rot3"][0])
    proc = subprocess.run([str(exe), str(lib), guid, "200", "0.01", str(len(names)), *[str(vrs[n]) for n in names],
                           "--twice"], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, ASAN_OPTIONS="detect_leaks=1", UBSAN_OPTIONS="halt_on_error=1"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "runtime error" not in proc.stderr and "AddressSanitizer" not in proc.stderr
    rows = np.array([[float(v) for v in line.split()] for line in proc.stdout.split("\n") if line.strip()])
    # the second instance (lambda doubled, stepped in between) did not disturb the first
    assert rel_err(rows[:, 1:].T, _exact("Rot3", rows[:, 0])) < 1e-8


def test_long_communication_steps_are_subdivided_to_the_tolerance(built):
    # one sixth-order Magnus step of 0.25 errs by ~1e-5 here: the error estimate must ask for sub-steps
    d = PROBLEMS["Rot3"][0]
    r = run({"fmu": str(built["Rot3"]), "dt": 0.25, "steps": 8, "outputs": _names(d), "block": BLOCK})
    assert set(r["status"]) == {"ok"}
    assert rel_err(np.array(r["values"]).T, _exact("Rot3", r["time"])) < 1e-8


@pytest.mark.parametrize("name", ["Rot3", "RotCanon2"])
def test_short_communication_steps_take_the_fourth_order_step_within_the_tolerance(built, name):
    # steps of 0.001: the norm bound of |y6 - y4| (~ h^5) is below the tolerance, so each step is one fourth-order
    # Magnus step (one commutator; steps of 0.01 and 0.25 above take the sixth-order one, with sub-steps)
    d = PROBLEMS[name][0]
    r = run({"fmu": str(built[name]), "dt": 0.001, "steps": 2000, "outputs": _names(d), "block": BLOCK})
    assert set(r["status"]) == {"ok"}
    got = np.array(r["values"]).T
    assert rel_err(got, _exact(name, r["time"])) < 1e-8
    assert rel_err(got[:, ::50], _library(d, r["time"][::50])) < 1e-8


# x^(d) carries the state's error times |G| and the (d-1)-th derivative of the tables, whose error grows
# ~ k^(2(d-1)) over the coefficients' ~ 1e-12: measured on the four problems at t = 0.73 and 1.5, at most 6e-12,
# 3e-12, 1e-10, 7.6e-9 for d = 1..4
DERIVATIVE_RTOL = {1: 1e-10, 2: 1e-9, 3: 1e-8, 4: 1e-6}


@pytest.mark.parametrize("name", list(PROBLEMS))
def test_output_derivatives_up_to_the_declared_order_are_exact(built, name):
    # x^(d) = sum_j binomial(d - 1, j) G^(j) x^(d-1-j) + g^(d-1), against the exact solution's derivatives
    d = PROBLEMS[name][0]
    with zipfile.ZipFile(built[name]) as zf:
        assert 'maxOutputDerivativeOrder="4"' in zf.read("modelDescription.xml").decode()
    r = run({"fmu": str(built[name]), "dt": DT, "steps": 73, "outputs": _names(d), "output_derivatives": _names(d),
             "block": BLOCK})
    assert len(r["derivatives"]) == 4, r.get("derivatives_error")
    xe = XE[name]
    for order, got in enumerate(r["derivatives"], start=1):
        expected = np.array(xe.diff(T, order).subs(T, r["time"][-1]).evalf(), dtype=float).ravel()
        assert rel_err(got, expected) < DERIVATIVE_RTOL[order], (order, got, expected)


@pytest.mark.parametrize("lam", [1e2, 1e4])
def test_fast_rates_within_the_stepping_range(built, lam):
    # lambda h up to 100: the exponential is the Pade one and sub-steps bring lambda H below about pi
    d = PROBLEMS["Rot3"][0]
    r = run({"fmu": str(built["Rot3"]), "dt": DT, "steps": 100, "outputs": _names(d), "start_values": {"lambda": lam}})
    assert set(r["status"]) == {"ok"}
    assert rel_err(np.array(r["values"]).T, _exact("Rot3", r["time"])) < 1e-8


def test_rate_beyond_the_stepping_range_is_discarded_with_a_reason(built):
    # lambda h = 1e6: 2^14 sub-steps are not enough for the Magnus series; the FMU says so at once
    d = PROBLEMS["Rot3"][0]
    r = run({"fmu": str(built["Rot3"]), "dt": DT, "steps": 3, "outputs": _names(d), "start_values": {"lambda": 1e8}},
            timeout=60)
    assert r["status"][-1].startswith("step 0") and "discard" in r["status"][-1]
    assert any("lambda = 1e+08" in m and "sub-steps" in m for m in r["logs"])


def _near_singular(digits):
    """``x1' + x1 = f1``, ``b(t) x2 = f2`` with ``b = (t - 1)^2 + 10^-digits`` (index 1; the algebraic equation
    nearly degenerates at t = 1), exact solution ``x = (sin t + 1, cos t)``. A perturbation of x2 at t0 grows
    like ``b(t0) / b(t)`` towards t = 1: up to ``10^digits`` times the local errors."""
    b = (T - 1) ** 2 + sp.Rational(1, 10 ** digits)
    return _spec(f"NearSingular{digits}", [[1, 0], [0, 0]], [[1, 0], [0, b]], [sp.sin(T) + 1, sp.cos(T)])


@pytest.mark.filterwarnings("ignore::lsc.RankDecisionWarning")  # the margins near t = 1 are small, as they are
def test_build_refuses_a_near_singular_point_as_the_library_does(tmp_path):
    """b(1) = 1e-6: the library's solvability check over the experiment's horizon refuses t = 1 ([J, F] loses
    full row rank there); the build runs the same check and refuses with the same reason, leaving no file
    (an FMU built anyway ran with 350 to 1e5 times the host's tolerance, with status OK)."""
    d, _ = _near_singular(6)
    with pytest.raises(lsc.IndexDeterminationError) as library:
        lsc.complete(parse_spec(d).linear_dae(), "alternative", lam=2.0, t_span=(0.0, STOP))
    with pytest.raises(lsc.IndexDeterminationError) as build:
        build_fmu(d, tmp_path, target="native")
    assert "t=1:" in str(build.value) and str(build.value) == str(library.value)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("tol", [1e-6, 1e-10])
def test_near_singular_point_the_library_accepts_is_as_accurate_as_the_library(tmp_path, tol):
    """b(1) = 1e-3 passes the check. The amplification b(t0) / b(t) (up to 1e3) of local errors is the
    problem's: the FMU at the host's tolerance (fmi2SetupExperiment) is within the library's error at the
    same tolerance (DOP853, atol = rtol / 100) and the tolerance itself, in a fresh fmpy process."""
    d, exact_at = _near_singular(3)
    fmu = build_fmu(d, tmp_path, target="native")
    steps = int(round(STOP / DT))
    r = run({"fmu": str(fmu), "dt": DT, "steps": steps, "outputs": _names(d), "tolerance": tol, "block": BLOCK})
    assert set(r["status"]) == {"ok"}
    exact = np.array(exact_at(np.array(r["time"])), dtype=float).reshape(2, -1)
    err_fmu = np.abs(np.array(r["values"]).T - exact).max()
    c = lsc.complete(parse_spec(d).linear_dae(), "alternative", lam=2.0, t_span=(0.0, STOP))
    res = lsc.solve_completion(c, (0.0, STOP), exact[:, 0], method="DOP853", t_eval=r["time"], rtol=tol,
                               atol=tol / 100)
    err_lib = np.abs(res.x - exact).max()
    assert err_fmu <= 2 * err_lib + tol, (err_fmu, err_lib)


def _rot2_in(eps, start):
    """Rot2 in the time unit `eps` from t = `start`: ``(eps A(t/eps), B(t/eps), f(t/eps))``, exact ``x(t/eps)``."""
    src = PROBLEMS_SOURCES["Rot2"]
    sub = {T: T / eps}
    xe = sp.Matrix(src["xe"]).subs(sub)
    name = f"Rot2_{'micro' if eps < 1 else 'unit'}_{int(start)}"
    d, _ = _spec(name, (eps * sp.Matrix(src["A"])).subs(sub), sp.Matrix(src["B"]).subs(sub), xe, lam=2.0 / eps,
                 stop=start + STOP * eps)
    d["experiment"].update(start=start, step=DT * eps)
    for i, state in enumerate(d["states"].values()):
        state["start"] = float(xe[i].subs(T, start))
    return name, d


@pytest.mark.parametrize("eps, start", [(1e-6, 0.0), (1.0, 1e5), (1.0, 1e6)], ids=["microseconds", "1e5", "1e6"])
def test_a_time_scaled_or_late_horizon_is_tabulated_like_the_unit_one(built, tmp_path, eps, start):
    """Rot2 on [0, 2e-6] (in microseconds) was refused as 'not solvable'; from t = 1e5 its tables took 8x the
    pieces and lost the margin past the stop time that Model Exchange hosts use, from t = 1e6 it was refused
    naming '[1e+06, 1e+06]'. Each is Rot2 on [0, 2]: the same tables, and the exact solution in CS and ME."""
    def pieces(description):
        return int(description.split("piecewise Chebyshev, ")[1].split(" piece")[0])

    from fmpy import read_model_description

    base = read_model_description(str(built["Rot2"])).description
    name, d = _rot2_in(eps, start)
    fmu = build_fmu(d, tmp_path, target="native")
    description = read_model_description(str(fmu)).description
    assert pieces(description) == pieces(base), description
    assert "margin past the stop time shortened" not in description
    assert f"tabulated on [{start:.12g}, {start + STOP * eps * 1.1:.12g}]" in description
    steps = int(round(STOP / DT))
    for interface, tol in (("cs", 1e-8), ("me", 1e-6)):
        r = run({"fmu": str(fmu), "interface": interface, "dt": DT * eps, "steps": steps, "t0": start,
                 "outputs": _names(d), "rtol": 1e-10, "block": BLOCK})
        got = np.array(r["values"]).T
        exact = np.array(sp.lambdify(T, sp.Matrix(PROBLEMS_SOURCES["Rot2"]["xe"]), "numpy")(
            (np.array(r["time"]) - 0.0) / eps), dtype=float).reshape(3, -1)
        assert rel_err(got, exact) < tol, (interface, rel_err(got, exact))
