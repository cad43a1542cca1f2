"""Native FMUs with time-varying A(t), B(t) and inputs in f: the exact solution with the input a known function.

Two problems with manufactured exact solutions whose forcing is fed partly through an input ``u`` with a
time-dependent coefficient ``b(t)`` (``f = f_rest(t) + b(t) u``, ``u = u*(t)`` known): positions and
velocities on a rotating line driven by a force along the line and through the constraint (index 3), and
the gallery's `rotating_canonical` (written in sympy, tests/test_native_timevarying.py) with one of its
rotated forcing components through the input (index 2). Each FMU runs in a subprocess
(tests/native_runner.py, fmpy) with lsc, sympy, scipy and fmu_build blocked.
"""
import zipfile

import numpy as np
import pytest
import sympy as sp

import lsc
from fmu_build import build_fmu, parse_spec
from fmu_build._model import _numeric_dae
from fmu_build.targets.native import NativeTargetError
from test_native import rel_err, run
from test_native_timevarying import BLOCK, T, _spec, rotating_canonical_sympy

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
    # line (-sin t, cos t) and moves the constraint n(t).q = f5 (so u'' enters the multiplier)
    out["RotForce3"] = _with_input(
        "RotForce3", np.diag([1, 1, 1, 1, 0]).tolist(),
        [[0, 0, -1, 0, 0], [0, 0, 0, -1, 0], [0, 0, 0, 0, -c], [0, 0, 0, 0, -s], [c, s, 0, 0, 0]],
        [c + 2, sp.sin(2 * T), -s, 2 * sp.cos(2 * T), sp.cos(T / 3)],
        [0, 0, -s, c, sp.Rational(1, 10)], sp.sin(sp.Rational(3, 2) * T) + sp.Rational(3, 10))
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
    P = sp.Matrix(A * 0)
    P = sp.eye(n)
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


def _library(name, times):
    """lsc with the input substituted by its exact function (DOP853 at rtol 1e-12)."""
    d, _, u_exact = PROBLEMS[name]
    spec = parse_spec(d)
    f = sp.Matrix(spec.f).subs(spec.input_symbols["u"], u_exact.subs(T, spec.t))
    dae = _numeric_dae(spec)
    dae = lsc.LinearDAE(np.array(spec.A.tolist(), dtype=object) if False else sp.Matrix(spec.A), sp.Matrix(spec.B), f)
    c = lsc.complete(dae, spec.method, lam=spec.lam)
    x0 = np.array([s["start"] for s in spec.states])
    res = lsc.solve_completion(c, (times[0], times[-1]), x0, method="DOP853", t_eval=times, rtol=1e-12, atol=1e-13)
    assert res.success
    return res.x


@pytest.mark.parametrize("name", list(PROBLEMS))
def test_cosimulation_with_exact_input_derivatives_matches_exact_solution(built, name):
    t, V = _cs(built[name], name)
    assert rel_err(V[:-1], _exact(name, t)) < 1e-8
    assert rel_err(V[:-1], _library(name, t)) < 1e-8
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
