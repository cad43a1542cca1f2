"""Native FMUs with time-varying A(t), B(t) and inputs in f: the exact solution with the input a known function.

Problems with manufactured exact solutions whose forcing is fed partly through an input ``u`` with a
time-dependent coefficient ``b(t)`` (``f = f_rest(t) + b(t) u``, ``u = u*(t)`` known): positions and
velocities on a rotating line driven by a force along the line and through the constraint (index 3; also
with a row and an unknown scaled by 1e4, so that the library equilibrates both), and the gallery's
`rotating_canonical` (written in sympy, tests/fmu_build/targets/test_native_timevarying.py) with one of its rotated forcing
components through the input (index 2). Each FMU runs in a subprocess (tests/support/native_runner.py, fmpy;
the accuracy runs with lsc, sympy, scipy and fmu_build blocked).
"""
import zipfile

import numpy as np
import pytest
import sympy as sp

import lsc
from fmu_build import build_fmu, parse_spec
from fmu_build.targets.native import NativeTargetError
from tests.fmu_build.targets.test_native import rel_err, run
from tests.fmu_build.targets.test_native_timevarying import BLOCK, T, _spec, rotating_canonical_sympy

STOP, DT = 2.0, 0.01
U = sp.Symbol("u")


def _with_input(name, A, B, xe, b, u_exact, f=None):
    """The spec with ``f = A xe' + B xe - b u* + b u`` (input u, exact values u*) and the exact solution."""
    A, B, xe, b = sp.Matrix(A), sp.Matrix(B), sp.Matrix(xe), sp.Matrix(b)
    f = (A * xe.diff(T) + B * xe if f is None else f) - b * u_exact + b * U
    d, exact = _spec(name, A, B, xe, f=f)
    d["inputs"] = {"u": {"start": float(u_exact.subs(T, 0))}}
    return d, exact, u_exact


def _problems():
    c, s = sp.cos(T), sp.sin(T)
    out = {}
    # index 3: positions q, velocities v, force mu along n(t) = (cos t, sin t); the input pushes along the
    # line (-sin t, cos t) and moves the constraint n(t).q = f5 by cos(t) u / 10 (so (cos(t) u)'' enters the
    # multiplier: the Leibniz terms of the input maps with their binomial factors)
    out["RotForce3"] = _with_input(
        "RotForce3", np.diag([1, 1, 1, 1, 0]).tolist(),
        [[0, 0, -1, 0, 0], [0, 0, 0, -1, 0], [0, 0, 0, 0, -c], [0, 0, 0, 0, -s], [c, s, 0, 0, 0]],
        [c + 2, sp.sin(2 * T), -s, 2 * sp.cos(2 * T), sp.cos(T / 3)],
        [0, 0, -s, c, c / 10], sp.sin(sp.Rational(3, 2) * T) + sp.Rational(3, 10))
    # the same with the constraint's row times 1e4 and mu / 1e4 as unknown: the library equilibrates rows and
    # columns, and the input maps are those of the given f and unknowns
    R, Cs = sp.diag(1, 1, 1, 1, 10 ** 4), sp.diag(1, 1, 1, 1, sp.Rational(1, 10 ** 4))
    A3, B3 = sp.Matrix(np.diag([1, 1, 1, 1, 0]).tolist()), sp.Matrix(
        [[0, 0, -1, 0, 0], [0, 0, 0, -1, 0], [0, 0, 0, 0, -c], [0, 0, 0, 0, -s], [c, s, 0, 0, 0]])
    out["RotForce3Scaled"] = _with_input(
        "RotForce3Scaled", R * A3 * Cs, R * B3 * Cs,
        Cs.inv() * sp.Matrix([c + 2, sp.sin(2 * T), -s, 2 * sp.cos(2 * T), sp.cos(T / 3)]),
        R * sp.Matrix([0, 0, -s, c, c / 10]), sp.sin(sp.Rational(3, 2) * T) + sp.Rational(3, 10))
    # the gallery's rotating canonical form: the oscillator's second forcing component, turned by P(t) into
    # the rows 1 and 2, comes through the input
    A, B, xe, f = rotating_canonical_sympy(2)
    n = A.shape[0]
    E, Ab = sp.zeros(n, n), sp.zeros(n, n)
    E[0, 0] = E[1, 1] = 1
    E[2, 3] = 1
    Ab[:2, :2] = sp.Matrix([[sp.Rational(1, 2), 1], [-1, sp.Rational(1, 2)]])
    Ab[2:, 2:] = sp.eye(2)
    y = sp.Matrix([sp.sin((1 + sp.Rational(3, 10) * j) * T + j) + sp.Rational(1, 2) for j in range(n)])
    w = (E * y.diff(T) + Ab * y)[1]  # f = P (E y' + Ab y): component 1 of the unturned forcing
    P = sp.eye(n)  # the plane rotation of rows 1 and 2 (rotating_canonical_sympy's P)
    P[1, 1] = P[2, 2] = sp.cos(T)
    P[1, 2], P[2, 1] = -sp.sin(T), sp.sin(T)
    out["RotCanonIn2"] = _with_input("RotCanonIn2", A, B, xe, P[:, 1], w, f=f)
    return out


PROBLEMS = _problems()


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tvin")
    return {name: build_fmu(d, folder, target="native") for name, (d, _, _) in PROBLEMS.items()}


def _names(name):
    return list(PROBLEMS[name][0]["states"])


def _exact(name, times):
    return np.array(PROBLEMS[name][1](np.asarray(times)), dtype=float).reshape(len(_names(name)), -1)


def _define(fmu, macro):
    with zipfile.ZipFile(fmu) as zf:
        header = zf.read("sources/model.h").decode()
    return int(next(line.split()[2] for line in header.splitlines() if line.startswith(f"#define {macro} ")))


def _jets(name, times, orders):
    """[u, u', ..., u^(orders - 1)] of the exact input at each time."""
    u = PROBLEMS[name][2]
    fns = [sp.lambdify(T, u.diff(T, j) if j else u, "numpy") for j in range(orders)]
    return [[float(fn(t)) for fn in fns] for t in times]


def _cs(fmu, name, dt=DT, stop=STOP, send=True, **extra):
    steps = int(round(stop / dt))
    nud = _define(fmu, "NF")  # the master may send orders 1 .. NF - 1
    r = run({"fmu": str(fmu), "dt": dt, "steps": steps, "outputs": _names(name) + ["constraint_residual"],
             "inputs": {"u": _jets(name, [i * dt for i in range(steps)], nud if send else 1)},
             "send_derivatives": send, "block": BLOCK, **extra})
    assert all(r["blocked"].values()), r["blocked"]
    assert set(r["status"]) == {"ok"}, r["status"][-3:]
    return np.array(r["time"]), np.array(r["values"]).T


def _library(name, times, u=None, x0=None):
    """lsc with the input substituted by its exact function (or the sympy expression `u`), DOP853 at rtol 1e-12."""
    d, _, u_exact = PROBLEMS[name]
    spec = parse_spec(d)
    u = u_exact if u is None else sp.sympify(u)
    f = sp.Matrix(spec.f).subs(spec.input_symbols["u"], u.subs(T, spec.t))
    c = lsc.complete(lsc.LinearDAE(sp.Matrix(spec.A), sp.Matrix(spec.B), f), spec.method, lam=spec.lam)
    x0 = np.array([s["start"] for s in spec.states]) if x0 is None else x0
    res = lsc.solve_completion(c, (times[0], times[-1]), x0, method="DOP853", t_eval=times, rtol=1e-12, atol=1e-13)
    assert res.success
    return res.x, c


def test_the_scaled_problem_is_equilibrated():
    c = lsc.complete(parse_spec(PROBLEMS["RotForce3Scaled"][0]).linear_dae(), "alternative", lam=2.0)
    assert c._scaling.r is not None and c._scaling.c is not None


@pytest.mark.parametrize("name", list(PROBLEMS))
def test_cosimulation_with_exact_input_derivatives_matches_exact_solution(built, name):
    t, V = _cs(built[name], name)
    assert rel_err(V[:-1], _exact(name, t)) < 1e-8
    assert rel_err(V[:-1], _library(name, t)[0]) < 1e-8
    # the residual with the input terms in its Gram form (at t = 0, read before the master sent the input's
    # derivatives, the FMU knows u only: there the residual is that of u' = u'' = ... = 0, as for constant A, B)
    assert np.abs(V[-1, 1:]).max() < 1e-6


def test_input_enters_the_forcing(built):
    # the same FMU with the input held at its start value is far off: the input is not ignored
    name = "RotForce3"
    fmu, steps = built[name], 100
    r = run({"fmu": str(fmu), "dt": DT, "steps": steps, "outputs": _names(name), "block": BLOCK})
    assert set(r["status"]) == {"ok"}
    assert rel_err(np.array(r["values"]).T, _exact(name, r["time"])) > 1e-3


def _estimated(name, fmu, H, startup):
    """Relative error over [0, 2] with the master sending values only; `startup`: exact derivatives for the
    first UDEG + 1 steps (until the FMU's history polynomial has its points), values only after."""
    steps = int(round(STOP / H))
    nud, udeg = _define(fmu, "NF"), _define(fmu, "UDEG")
    jets = _jets(name, [i * H for i in range(steps)], nud)
    jets = [j if (startup and i <= udeg) else j[:1] for i, j in enumerate(jets)]
    r = run({"fmu": str(fmu), "dt": H, "steps": steps, "outputs": _names(name), "inputs": {"u": jets},
             "send_derivatives": True, "block": BLOCK})
    assert set(r["status"]) == {"ok"}
    return rel_err(np.array(r["values"]).T, _exact(name, r["time"]))


def test_estimated_input_derivatives_converge_at_the_order_of_the_history_polynomial(built):
    # exact samples: derivatives from the polynomial through the last UDEG + 1 = 9 values: u^(j) errs by
    # O(H^(9 - j)); the index-3 multiplier reads u^(3) (through the constraint n(t).q = ... + cos(t) u / 10).
    # Down to a floor near 2e-10 relative: there the least-squares check over the window, whose uncertainty
    # the fourth derivative's rounding outgrows at some steps, gives that derivative (9.8e-9, 2.1e-10, 1.8e-10
    # measured; the interpolant alone reaches 2.3e-11 at H = 0.01)
    name = "RotForce3"
    err = [_estimated(name, built[name], H, startup=True) for H in (0.04, 0.02, 0.01)]
    orders = np.log2(np.array(err[:-1]) / np.array(err[1:]))
    assert orders[0] > 4.3 and err[-1] <= err[-2] and err[-1] < 3e-10, (err, orders)


def test_values_only_from_the_start_err_at_first_order(built):
    # a master that never sends derivatives: in the first steps the history has one, two, ... points (u' = 0
    # in the first step), and the index-3 problem keeps that start-up error O(H) (it does not decay: the
    # motion along the line is undamped); the same rule as for constant A and B
    name = "RotForce3"
    err = [_estimated(name, built[name], H, startup=False) for H in (0.02, 0.01)]
    assert 0.9 < np.log2(err[0] / err[1]) < 1.2 and err[1] < 5e-3, err


@pytest.mark.parametrize("name", list(PROBLEMS))
def test_model_exchange_with_an_input_held_constant_equals_the_library(built, name):
    # Model Exchange has no input derivatives: they are the history's (zero for an input held constant), so
    # with u = 0.75 throughout the FMU's right-hand side is G(t) x + g(t, 0.75) exactly, and the run is the
    # library's solution of f(t, 0.75) to the integrator's tolerance
    r = run({"fmu": str(built[name]), "interface": "me", "dt": DT, "steps": 100, "outputs": _names(name),
             "rtol": 1e-10, "input_table": {"time": [0.0, 1.0], "u": [0.75, 0.75]}, "block": BLOCK})
    assert all(r["blocked"].values())
    t, first = np.unique(r["time"], return_index=True)  # fmpy reports the time of a step event twice
    X, _ = _library(name, t, u=0.75)
    assert rel_err(np.array(r["values"])[first].T, X) < 1e-6
    assert rel_err(X, _exact(name, t)) > 1e-3  # and the input mattered


def test_model_exchange_with_a_varying_input_follows_the_estimate(built):
    # a varying input: the history estimate (points at least the experiment's step apart) limits the
    # accuracy, as for constant A and B (prefer Co-Simulation for inputs in f)
    name = "RotCanonIn2"
    tt = np.linspace(0.0, 1.0, 1001)
    r = run({"fmu": str(built[name]), "interface": "me", "dt": DT, "steps": 100, "outputs": _names(name),
             "rtol": 1e-10, "input_table": {"time": tt.tolist(), "u": [j[0] for j in _jets(name, tt, 1)]},
             "block": BLOCK})
    err = rel_err(np.array(r["values"]).T, _exact(name, r["time"]))
    assert 1e-8 < err < 2e-3, err


def test_residual_off_the_manifold_with_the_input_terms(built):
    # started 1e-3 off the position constraint: the residual |Z2^T (F x - g(t, u))| the FMU reports (the
    # Gram form with C^T V, V^T c_g0, V^T V) against the library's at the FMU's states, exact input
    name = "RotForce3"
    d = PROBLEMS[name][0]
    steps = 100
    r = run({"fmu": str(built[name]), "dt": DT, "steps": steps, "outputs": _names(name) + ["constraint_residual"],
             "inputs": {"u": _jets(name, [i * DT for i in range(steps)], _define(built[name], "NF"))},
             "send_derivatives": True, "start_values": {"x1_0": d["states"]["x1"]["start"] + 1e-3}})
    assert set(r["status"]) == {"ok"}
    t, V = np.array(r["time"]), np.array(r["values"])
    _, c = _library(name, t[:2])
    expected = np.array([np.linalg.norm(c.constraint_residual(ti, xi)) for ti, xi in zip(t, V[:, :-1])])
    assert expected[1] > 5e-4 and expected[-1] < expected[1] * np.exp(-2.0 * 0.9)  # off, and decaying at lam = 2
    assert np.abs(V[1:, -1] - expected[1:]).max() < 1e-8


@pytest.mark.parametrize("serialize", [False, True])
def test_rollback_with_inputs_bit_for_bit(built, serialize):
    name = "RotForce3"
    r = run({"fmu": str(built[name]), "dt": DT, "steps": 40, "outputs": _names(name), "rollback_at": 20,
             "serialize": serialize, "inputs": {"u": _jets(name, [i * DT for i in range(40)], 1)}})
    assert r["rollback"]["values"] == r["rollback"]["original"]


def test_compiles_warning_free_and_declares_input_derivatives(built, tmp_path):
    from fmpy import read_model_description

    from tests.fmu_build.targets.test_native_accuracy import _compile_strict

    proc = _compile_strict(built["RotForce3"], tmp_path)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    md = read_model_description(str(built["RotForce3"]))
    assert md.coSimulation.canInterpolateInputs  # fmi2SetRealInputDerivatives, as for constant A and B
    u = next(v for v in md.modelVariables if v.name == "u")
    assert u.causality == "input" and u.variability == "continuous"


@pytest.mark.parametrize("term, where, match", [
    ("u**2", "f", "not affine in the input"),
    ("sin(u)", "f", "not affine in the input"),
    ("u", "B", "B depends on the input"),
])
def test_refusals_name_what_cannot_be_tabulated(tmp_path, term, where, match):
    d = dict(PROBLEMS["RotCanonIn2"][0])
    d["equations"] = dict(d["equations"])
    if where == "f":
        d["equations"]["f"] = [d["equations"]["f"][0] + f" + {term}"] + d["equations"]["f"][1:]
    else:
        B = [list(row) for row in d["equations"]["B"]]
        B[0][0] = f"{B[0][0]} + {term}"
        d["equations"]["B"] = B
    with pytest.raises(NativeTargetError, match=match):
        build_fmu(d, tmp_path, target="native")
    assert not list(tmp_path.glob("*.fmu*"))


def test_lambda_and_the_inputs_maps_affine_part(built):
    # off the manifold at lambda = 7 (not a fitting rate): U0 + 7 U1 acts on the input's jets; the library at 7
    name = "RotForce3"
    d = PROBLEMS[name][0]
    x0 = np.array([s["start"] for s in parse_spec(d).states]) + np.array([1e-3, 0, 0, 0, 0])
    steps = 100
    r = run({"fmu": str(built[name]), "dt": DT, "steps": steps, "outputs": _names(name),
             "inputs": {"u": _jets(name, [i * DT for i in range(steps)], _define(built[name], "NF"))},
             "send_derivatives": True, "start_values": {"lambda": 7.0, "x1_0": float(x0[0])}, "block": BLOCK})
    assert set(r["status"]) == {"ok"}
    t = np.array(r["time"])
    spec = parse_spec(d)
    f = sp.Matrix(spec.f).subs(spec.input_symbols["u"], PROBLEMS[name][2].subs(T, spec.t))
    c = lsc.complete(lsc.LinearDAE(sp.Matrix(spec.A), sp.Matrix(spec.B), f), "alternative", lam=7.0)
    X = lsc.solve_completion(c, (0.0, t[-1]), x0, method="DOP853", t_eval=t, rtol=1e-12, atol=1e-13).x
    got = np.array(r["values"]).T
    assert rel_err(got, X) < 1e-8
    assert np.abs(got[:, -1] - _exact(name, t)[:, -1]).max() > 1e-6  # the start was off: lambda mattered


def test_output_derivatives_are_G_x_plus_g_with_the_input(built):
    name = "RotCanonIn2"
    steps = 50
    r = run({"fmu": str(built[name]), "dt": DT, "steps": steps, "outputs": _names(name),
             "output_derivatives": _names(name), "send_derivatives": True,
             "inputs": {"u": _jets(name, [i * DT for i in range(steps)], _define(built[name], "NF"))}})
    xe = sp.Matrix(rotating_canonical_sympy(2)[2])
    expected = np.array(xe.diff(T).subs(T, r["time"][-1]).evalf(), dtype=float).ravel()
    assert rel_err(r["derivatives"][0], expected) < 1e-8


def test_c_master_under_address_and_ub_sanitizers(built, tmp_path):
    # the C master sets no input: u stays at its start value, so the run is the library's with f(t, u(0))
    import os
    import subprocess

    from tests.fmu_build.targets.test_native import _master, _sanitized_library, _unpacked

    name = "RotForce3"
    guid, vrs = _unpacked(built[name], tmp_path)
    lib = _sanitized_library(tmp_path)
    exe = _master(tmp_path, sanitize=True)
    names = _names(name)
    proc = subprocess.run([str(exe), str(lib), guid, "100", "0.01", str(len(names)), *[str(vrs[n]) for n in names]],
                          capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, ASAN_OPTIONS="detect_leaks=1", UBSAN_OPTIONS="halt_on_error=1"))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "runtime error" not in proc.stderr and "AddressSanitizer" not in proc.stderr
    rows = np.array([[float(v) for v in line.split()] for line in proc.stdout.split("\n") if line.strip()])
    X, _ = _library(name, np.concatenate([[0.0], rows[:, 0]]), u=PROBLEMS[name][2].subs(T, 0))  # rows: step ends
    assert rel_err(rows[:, 1:].T, X[:, 1:]) < 1e-8


@pytest.mark.parametrize("method", ["standard", "stabilized"])
def test_other_completions_with_an_input(tmp_path, method):
    # fixed lambda: U1 = 0, the maps checked against the library's g at the build; exact input derivatives
    d = dict(PROBLEMS["RotCanonIn2"][0])
    d["completion"] = {"method": method, "lam": 2.0} if method == "stabilized" else {"method": method}
    d["model"] = {"name": "RotCanonIn2" + method.capitalize()}
    fmu = build_fmu(d, tmp_path, target="native")
    t, V = _cs(fmu, "RotCanonIn2", stop=1.0)
    assert rel_err(V[:-1], _exact("RotCanonIn2", t)) < 1e-8


def test_model_exchange_refuses_a_derivative_the_input_makes_infinite(built, tmp_path):
    # u = 1e308 is a finite value; U u overflows: fmi2GetDerivatives says so (fmi2Error), and the host exits cleanly
    import subprocess
    import sys

    script = f"""
from fmpy import extract, read_model_description
from ctypes import c_double
from fmpy.fmi2 import FMU2Model
md = read_model_description({str(built['RotForce3'])!r})
fmu = FMU2Model(guid=md.guid, unzipDirectory=extract({str(built['RotForce3'])!r}),
                modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
fmu.instantiate()
fmu.setupExperiment(startTime=0.0)
fmu.enterInitializationMode()
fmu.exitInitializationMode()
fmu.enterContinuousTimeMode()
vr = next(v.valueReference for v in md.modelVariables if v.name == "u")
dx = (c_double * 5)()
fmu.getDerivatives(dx, 5)
print("finite", all(abs(d) < 1e300 for d in dx))
fmu.setReal([vr], [1e308])
try:
    fmu.getDerivatives(dx, 5)
    print("no error", list(dx))
except Exception as exc:
    print("refused", exc)
fmu.terminate()
fmu.freeInstance()
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "finite True" in proc.stdout and "refused" in proc.stdout, proc.stdout


def test_the_build_checks_every_column_of_the_input_maps(tmp_path, monkeypatch):
    # input maps without the Leibniz rule's binomial factors (wrong where b(t) varies in a row whose derivatives
    # the completion uses): the build's check against the library, on an input polynomial of degree p, refuses
    from fmu_build.targets import _native_tv

    def without_binomials(X, b, p):
        n = b.shape[2]
        out = np.zeros((X.shape[0], b.shape[0] * (p + 1)))
        for i in range(b.shape[0]):
            for j in range(p + 1):
                out[:, i * (p + 1) + j] = sum(X[:, d * n:(d + 1) * n] @ b[i, d - j] for d in range(j, p + 1))
        return out

    monkeypatch.setattr(_native_tv, "_input_columns", without_binomials)
    with pytest.raises(NativeTargetError, match="does not reproduce g"):
        build_fmu(PROBLEMS["RotForce3"][0], tmp_path, target="native")
    assert not list(tmp_path.glob("*.fmu*"))


def test_fmpy_simulate_fmu_with_an_input_table(built, tmp_path):
    # fmpy's own Co-Simulation loop with `input=` (values at the communication points, no derivatives): the
    # history estimate, as with values only from the start (6.5e-5 at steps of 0.01)
    import json
    import subprocess
    import sys

    name = "RotCanonIn2"
    tt = np.linspace(0.0, 2.0, 2001)
    np.savez(tmp_path / "u.npz", t=tt, u=[j[0] for j in _jets(name, tt, 1)])
    script = f"""
import json, numpy as np
from fmpy import simulate_fmu
d = np.load({str(tmp_path / "u.npz")!r})
table = np.array(list(zip(d["t"], d["u"])), dtype=[("time", float), ("u", float)])
r = simulate_fmu({str(built[name])!r}, fmi_type="CoSimulation", stop_time=2.0, output_interval=0.01, input=table,
                 output={_names(name)!r})
print(json.dumps([r["time"].tolist(), [[float(x[n]) for n in {_names(name)!r}] for x in r]]))
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    t, V = json.loads(proc.stdout)
    err = rel_err(np.array(V).T, _exact(name, np.array(t)))
    assert 1e-6 < err < 2e-4, err
