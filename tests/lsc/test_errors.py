"""Bad input: a clear error naming the argument, a warning before a costly run, a failed result that
keeps what was computed, or a correct answer; never a silent wrong answer.

`CASES` is the library layer's table ``(input, expected outcome, message fragment)``: the outcome is
an exception class (raised), a warning class (warned before any work is done), ``FAILED`` (a
CompletionResult with success=False whose message holds the fragment) or ``SOLVED`` (a result with
success=True and, with the fragment None, an error against the exact solution under 1e-6).
docs/reliability_library.md lists the same classes.
"""
import re
import warnings

import numpy as np
import pytest
import sympy

from lsc import (
    DimensionError, IndexDeterminationError, LinearDAE, StiffnessWarning, complete, derivative_array,
    differentiation_index, eigenanalysis, gallery, solve_completion, solve_dae, check_solvability,
)
from lsc import JetCallable

FAILED, SOLVED = "failed", "solved"

t = sympy.Symbol("t")
I2 = np.eye(2)
N2 = [[0.0, 1.0], [0.0, 0.0]]
CHAIN = LinearDAE(N2, I2, [sympy.sin(t), 0])
SINGULAR = LinearDAE([[1.0, 0.0], [0.0, 0.0]], [[0.0, 1.0], [0.0, 0.0]])


def bad_shape_f(s, d):
    return np.zeros(3)


def nan_after(t_bad):
    """f = (sin t, 0) until `t_bad`, NaN after: a forcing that breaks in the middle of a run."""
    def f(s, d):
        return [np.nan, 0.0] if s > t_bad else [np.sin(s + d * np.pi / 2), 0.0]
    return f


def chain_error(res):
    """Largest error of a CHAIN-type result (x = (f1 - f2', f2)) with f = (sin t, 0)."""
    return float(np.max(np.abs(res.x - np.vstack([np.sin(res.t), 0 * res.t]))))


def exact_error(p, res):
    X = p.exact(res.t)
    return float(np.max(np.abs(res.x - X) / (1 + np.abs(X))))


def scaled_chain(low):
    """``N x' + x = f`` (N the 4x4 shift, det(sN + I) = 1) with equations scaled by low..1/low."""
    n = 4
    rows = np.logspace(np.log10(low), -np.log10(low), n)
    fs = [sympy.sin(t), sympy.cos(t), t, sympy.Integer(1)]
    dae = LinearDAE(rows[:, None] * np.eye(n, k=1), np.diag(rows), [r * fi for r, fi in zip(rows, fs)])
    exact_f = sympy.lambdify(t, [fs[0] - sympy.diff(fs[1], t) + sympy.diff(fs[2], t, 2) - sympy.diff(fs[3], t, 3),
                                 fs[1] - sympy.diff(fs[2], t) + sympy.diff(fs[3], t, 2), fs[2] - sympy.diff(fs[3], t), fs[3]])
    exact = lambda s: np.array([np.broadcast_to(v, np.shape(s)) for v in exact_f(s)], dtype=float)  # noqa: E731
    res = solve_dae(dae, (0.0, 2.0), exact(0.0), lam=1.0, t_eval=np.linspace(0, 2, 11), rtol=1e-10, atol=1e-12)
    res.error = float(np.max(np.abs(res.x - exact(res.t))))
    return res


def column_scaled_chain(columns, method="alternative"):
    """``N D y' + D y = f`` (N the 4x4 shift): the unknowns ``y = D^-1 x`` scaled by `columns`, e.g. y2 = 1e12 x2.

    The error is relative to each component's largest exact value (the components differ by 1e24).
    """
    n, D = 4, np.asarray(columns, dtype=float)
    fs = [sympy.sin(t), sympy.cos(t), t, sympy.Integer(1)]
    exact_f = sympy.lambdify(t, [fs[0] - sympy.diff(fs[1], t) + sympy.diff(fs[2], t, 2) - sympy.diff(fs[3], t, 3),
                                 fs[1] - sympy.diff(fs[2], t) + sympy.diff(fs[3], t, 2), fs[2] - sympy.diff(fs[3], t), fs[3]])
    exact = lambda s: np.array([np.broadcast_to(v, np.shape(s)) for v in exact_f(s)], dtype=float) / (  # noqa: E731
        D[:, None] if np.ndim(s) else D)
    dae = LinearDAE(np.eye(n, k=1) * D, np.diag(D), fs)
    lam = None if method == "standard" else 1.0
    atol = 1e-12 * np.max(np.abs(exact(np.linspace(0, 2, 11))), axis=1)  # per component: they differ by 1e24
    res = solve_dae(dae, (0.0, 2.0), exact(0.0), completion=method, lam=lam, t_eval=np.linspace(0, 2, 11),
                    rtol=1e-10, atol=atol)
    X = exact(res.t)
    res.error = float(np.max(np.abs(res.x - X) / np.max(np.abs(X), axis=1, keepdims=True)))
    return res


def scaled_nilpotent_chain(low, high):
    p = gallery.nilpotent_chain(3, seed=0)
    rows = np.logspace(np.log10(low), np.log10(high), p.dae.n)
    f = JetCallable(lambda s, order: rows * p.dae.f_jet(s, order))
    dae = LinearDAE(rows[:, None] * p.dae.A.value, rows[:, None] * p.dae.B.value, f)
    res = solve_dae(dae, p.t_span, p.x0, lam=1.0, t_eval=np.linspace(*p.t_span, 11), rtol=1e-10, atol=1e-12)
    res.error = exact_error(p, res)
    return res


def with_k(k):
    p = gallery.prescribed_path()
    res = solve_completion(complete(p.dae, "alternative", lam=2.0, k=k), p.t_span, p.x0, method="expm",
                           max_step=0.01, t_eval=np.linspace(*p.t_span, 11))
    res.error = exact_error(p, res)
    return res


TWO_TS = [sympy.Symbol("t", real=True), sympy.sin(t)]


def time_scaled_pencil(s):
    """`gallery.random_pencil` (n = 10, index 3) in the time unit `s`: ``(s A, B, f(t / s))``, exact ``x(t / s)``."""
    p = gallery.random_pencil(n=10, blocks=(3,), seed=0)
    f = p.dae.f
    dae = LinearDAE(s * p.dae.A(0.0), p.dae.B(0.0),
                    JetCallable(lambda u, order: f.jet(u / s, order) / s ** np.arange(order + 1)[:, None]))
    ts = np.linspace(0.0, 2.0 * s, 11)
    res = solve_dae(dae, (0.0, 2.0 * s), p.exact(0.0), lam=2.0 / s, method="Radau", t_eval=ts, rtol=1e-10, atol=1e-12)
    res.error = float(np.max(np.abs(res.x - p.exact(ts / s)) / (1 + np.abs(p.exact(ts / s)))))
    return res


CASES = [
    # (callable, exception, fragment of the message)
    (lambda: LinearDAE([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], np.eye(3)), DimensionError, "`A` must be a square matrix: expected (n, n), got (2, 3)"),
    (lambda: LinearDAE(np.eye(2), np.eye(3)), DimensionError, "expected B of shape (2, 2), got (3, 3)"),
    (lambda: LinearDAE(np.eye(2), [1.0, 2.0]), DimensionError, "`B` must be a square matrix: expected (n, n), got (2,)"),
    (lambda: LinearDAE(N2, I2, [1.0, 2.0, 3.0]), DimensionError, "`f` has the wrong shape: expected (2,), got (3,)"),
    (lambda: LinearDAE(N2, I2, [sympy.sin(t)] * 3), DimensionError, "`f` has the wrong shape: expected (2,), got (3,)"),
    (lambda: complete(LinearDAE(N2, I2, bad_shape_f), "standard").rhs(0.0, np.zeros(2)), DimensionError, "`f(t, d)` must return shape (2,): expected (2,), got (3,)"),
    (lambda: LinearDAE([[np.nan, 0.0], [0.0, 1.0]], I2), ValueError, "`A` must be finite; found NaN or inf"),
    (lambda: LinearDAE(N2, [[np.inf, 0.0], [0.0, 1.0]]), ValueError, "`B` must be finite"),
    (lambda: LinearDAE(N2, I2, [np.nan, 1.0]), ValueError, "`f` must be finite"),
    (lambda: LinearDAE(N2, I2, [sympy.Symbol("s"), t]), ValueError, "`f` may depend on the symbol t only; found other symbols ['s']"),
    (lambda: LinearDAE("AB", I2), TypeError, "`A` must be array_like of real numbers"),
    (lambda: LinearDAE([[1j, 0], [0, 1]], I2), TypeError, "`A` must be real"),
    (lambda: complete(SINGULAR, "standard"), IndexDeterminationError, "pencil s*A + B is singular"),
    (lambda: differentiation_index(gallery.nilpotent_chain(5).dae, kmax=3), IndexDeterminationError, "no k in 0..3"),
    (lambda: complete(CHAIN, "least-squares"), ValueError, "`method` must be one of"),
    (lambda: complete(CHAIN, "stabilized"), ValueError, "`lam` is required for the 'stabilized' completion"),
    (lambda: complete(CHAIN, "alternative"), ValueError, "`lam` is required for the 'alternative' completion"),
    (lambda: complete(CHAIN, "stabilized", lam=np.nan), ValueError, "`lam` must be a positive finite real number; found nan"),
    (lambda: complete(CHAIN, "alternative", lam=np.inf), ValueError, "found inf"),
    (lambda: complete(CHAIN, "stabilized", lam=0.0), ValueError, "`lam` must be a positive finite real number; found 0.0"),
    (lambda: complete(CHAIN, "alternative", lam=-1.0), ValueError, "found -1.0"),
    (lambda: complete(CHAIN, "stabilized", lam="fast"), TypeError, "`lam` must be a positive finite real number; found 'fast'"),
    (lambda: complete(CHAIN, "standard", lam=2.0), ValueError, "`lam` must be None for the 'standard' completion"),
    (lambda: complete(CHAIN, "standard", k=-1), ValueError, "`k` must be a non-negative int; found -1"),
    (lambda: complete(CHAIN, "standard", k=1.5), TypeError, "`k` must be a non-negative int; found 1.5"),
    (lambda: complete(CHAIN, "standard", k=1), IndexDeterminationError, "`k`=1 is too small"),
    (lambda: complete(CHAIN, "standard", rcond=2.0), ValueError, "`rcond` must be None or a float in (0, 1); found 2.0"),
    (lambda: complete("dae", "standard"), TypeError, "`dae` must be an lsc.LinearDAE; found str"),
    (lambda: derivative_array(CHAIN, 2, lam=-1.0), ValueError, "`lam` must be a positive finite real number"),
    (lambda: solve_dae(CHAIN, (0.0, 1.0), [0.0, 0.0, 0.0], lam=1.0), DimensionError, "`x0` has the wrong shape: expected (2,), got (3,)"),
    (lambda: solve_dae(CHAIN, (0.0, 1.0), [np.nan, 0.0], lam=1.0), ValueError, "`x0` must be finite"),
    (lambda: solve_dae(CHAIN, (0.0, 0.0), [0.0, 0.0], lam=1.0), ValueError, "`t_span` must have t0 != t1"),
    (lambda: solve_dae(CHAIN, 1.0, [0.0, 0.0], lam=1.0), ValueError, "`t_span` must be a pair (t0, t1)"),
    (lambda: solve_completion(CHAIN, (0.0, 1.0), [0.0, 0.0]), TypeError, "`completion` must be an lsc Completion"),
    (lambda: complete(CHAIN, "standard").constraint_residual(0.0, np.zeros(3)), DimensionError, "expected (2,) or (2, m), got (3,)"),
    (lambda: complete(CHAIN, "standard").project(0.0, np.zeros(3)), DimensionError, "expected (2,), got (3,)"),
    (lambda: CHAIN.residual(0.0, np.zeros(2), np.zeros(3)), DimensionError, "`xdot` has the wrong shape: expected (2,), got (3,)"),
    (lambda: eigenanalysis("c"), TypeError, "`completion` must be an lsc Completion"),
    # time-varying input
    (lambda: complete(LinearDAE(lambda s, d: np.zeros((3, 3)), I2), "standard"), DimensionError, "`A(t, d)` must return shape (2, 2): expected (2, 2), got (3, 3)"),
    (lambda: complete(LinearDAE(N2, lambda s, d: np.full((2, 2), np.nan)), "standard"), ValueError, "`B(t, d)` returned non-finite values at t=0.0, d=0"),
    (lambda: LinearDAE(sympy.Matrix([[sympy.Symbol("s"), 0], [0, t]]), I2), ValueError, "`A` may depend on the symbol t only; found other symbols ['s']"),
    (lambda: complete(CHAIN, "alternative", lam=lambda s, d: np.ones(2)), DimensionError, "`lam(t, d)` must return shape ()"),
    (lambda: complete(CHAIN, "alternative", lam=1 + sympy.Symbol("a") * t), ValueError, "`lam` may depend on the symbol t only"),
    (lambda: complete(CHAIN, "alternative", lam=1 - t, t_span=(0.0, 2.0)), ValueError, "`lam` must be positive wherever the completion is evaluated"),
    (lambda: complete(CHAIN, "stabilized", lam=-1 + 0 * t), ValueError, "`lam` must be a positive finite real number; found -1.0"),
    (lambda: check_solvability(CHAIN, (0.0, 1.0), samples=1), ValueError, "`samples` must be an int >= 2; found 1"),
    # k far above the index: refused with the measured reason; index + 10 is accepted and accurate
    (lambda: complete(gallery.prescribed_path().dae, "alternative", lam=2.0, k=30), ValueError,
     "`k`=30 is 27 above the differentiation index 3 (at t=0); at most index + 10 = 13 is accepted"),
    (lambda: complete(gallery.prescribed_path().dae, "standard", k=60), ValueError, "so rounding grows"),
    (lambda: with_k(13), SOLVED, None),
    # a time-varying lam with constant A, B is checked on the run's interval
    (lambda: solve_completion(complete(LinearDAE(N2, I2, [0, sympy.sin(t)]), "alternative", lam=1 - 2 * t),
                              (0.0, 2.0), [0.0, 0.0]), ValueError,
     "`lam` must be positive wherever the completion is evaluated; lam(0.5) = 0.0"),
    # two different symbols named t in one coefficient
    (lambda: LinearDAE(N2, I2, TWO_TS), ValueError, "`f` contains 2 different sympy symbols named t"),
    (lambda: LinearDAE(sympy.Matrix([[0, sympy.Symbol("t", positive=True)], [0, t]]), I2), ValueError,
     "`A` contains 2 different sympy symbols named t"),
    # an explicit method on a very stiff completion: warned before the run, with its cost
    (lambda: solve_dae(CHAIN, (0.0, 1.0), [0.0, 0.0], lam=1e8, method="RK45"), StiffnessWarning,
     "stability alone needs about"),
    (lambda: solve_dae(CHAIN, (0.0, 1.0), [0.0, 0.0], lam=1e8, method="DOP853"), StiffnessWarning,
     "Use method='auto'"),
    # forcing that breaks during the run: a failed result naming the coefficient and t
    (lambda: solve_dae(LinearDAE(N2, I2, nan_after(0.3)), (0.0, 1.0), [0.0, 0.0], lam=1.0), FAILED,
     "`f(t, d)` returned non-finite values at t="),
    (lambda: solve_dae(LinearDAE(N2, I2, [sympy.sqrt(0.5 - t), 0]), (0.0, 1.0), [0.0, 0.0], lam=1.0), FAILED,
     "`f` cannot be evaluated at t="),
    (lambda: solve_dae(LinearDAE(N2, I2, [1 / (t - 0.5001) ** 2, 0]), (0.0, 1.0), [0.0, 0.0], lam=1.0), FAILED,
     "but the completion is not stiff"),
    (lambda: complete(LinearDAE(N2, I2, lambda s, d: ["a", "b"]), "standard").rhs(0.0, np.zeros(2)), TypeError,
     "`f(t, d)` must return real numbers of shape (2,); got list ['a', 'b'] at t=0.0, d=0"),
    (lambda: complete(LinearDAE(N2, I2, lambda s, d: "ab"), "standard").rhs(0.0, np.zeros(2)), TypeError,
     "`f(t, d)` must return real numbers"),
    # badly scaled rows are equilibrated, not refused (det(sA + B) = 1)
    (lambda: scaled_chain(1e-6), SOLVED, None),
    (lambda: scaled_chain(1e-12), SOLVED, None),
    (lambda: scaled_nilpotent_chain(1e-6, 1e6), SOLVED, None),
    (lambda: scaled_nilpotent_chain(1e-12, 1.0), SOLVED, None),
    # badly scaled unknowns (columns) are equilibrated too, and the solution scaled back
    (lambda: column_scaled_chain([1, 1e-12, 1, 1]), SOLVED, None),
    (lambda: column_scaled_chain([1, 1e-12, 1, 1], "standard"), SOLVED, None),
    (lambda: column_scaled_chain([1, 1e-12, 1, 1], "stabilized"), SOLVED, None),
    (lambda: column_scaled_chain([1e-12, 1, 1e12, 1]), SOLVED, None),
    (lambda: column_scaled_chain(np.logspace(-6, 6, 4)), SOLVED, None),
    # a pencil in another unit of time is solved in its own (it came out index 9 at 0.01, "not solvable" at 1e4)
    (lambda: time_scaled_pencil(1e-2), SOLVED, None),
    (lambda: time_scaled_pencil(1e4), SOLVED, None),
    # dense output does not extrapolate; complex sympy entries are named
    (lambda: solve_dae(CHAIN, (0.0, 1.0), [0.0, 0.0], lam=1.0, dense_output=True).sol(2.0), ValueError,
     "dense output asked for t=2, outside the interval [0, 1] that was integrated"),
    (lambda: LinearDAE(N2, I2, [sympy.I, sympy.sin(t)]), TypeError, "`f[0]` is complex: I"),
]


def _case_id(case):
    call, outcome, fragment = case
    name = outcome if isinstance(outcome, str) else outcome.__name__
    return f"{name}:{fragment[:40]}" if fragment else f"{name}:{call.__code__.co_firstlineno}"


@pytest.mark.parametrize("call, outcome, fragment", CASES, ids=[_case_id(c) for c in CASES])
def test_bad_input(call, outcome, fragment):
    if outcome == FAILED:
        res = call()
        assert not res.success and fragment in res.message, res.message
        assert "large lam" not in res.message
    elif outcome == SOLVED:
        res = call()
        assert res.success, res.message
        assert res.error < 1e-6, res.error
    elif issubclass(outcome, Warning):
        with warnings.catch_warnings():
            warnings.simplefilter("error", outcome)  # raised before any work: the run itself never starts
            with pytest.raises(outcome) as info:
                call()
        assert fragment in str(info.value)
    else:
        with pytest.raises(outcome) as info:
            call()
        assert fragment in str(info.value)


def test_a_run_that_fails_keeps_what_it_computed():
    """Like solve_ivp: the trajectory up to the failure is returned, and it is right."""
    dae = LinearDAE(N2, I2, nan_after(0.3))
    res = solve_dae(dae, (0.0, 1.0), [0.0, 0.0], lam=1.0, rtol=1e-10, atol=1e-12)
    assert not res.success and res.status == -2
    assert res.t.size >= 2 and res.t[0] == 0.0 and res.t[-1] <= 0.3
    assert chain_error(res) < 1e-8
    assert "computed before it" in res.message
    dense = solve_dae(dae, (0.0, 1.0), [0.0, 0.0], lam=1.0, t_eval=np.linspace(0, 1, 11), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(dense.t, [0.0, 0.1, 0.2, 0.3][: dense.t.size])
    assert dense.t.size >= 3 and chain_error(dense) < 1e-8


def test_time_varying_rate_on_constant_coefficients_is_evaluated_where_it_varies():
    """lam = 1 + t: the residual decays like exp(-int lam) = exp(-(t + t^2/2)), e^-4 over [0, 2]."""
    dae = LinearDAE(N2, I2, [0, sympy.sin(t)])
    c = complete(dae, "alternative", lam=1 + t)
    x0 = np.array([-1.0, 0.0]) + np.array([0.1, 0.2])  # off the manifold
    res = solve_completion(c, (0.0, 2.0), x0, t_eval=[0.0, 1.0, 2.0], rtol=1e-11, atol=1e-13)
    assert res.success
    np.testing.assert_allclose(res.residual[1:] / res.residual[0], np.exp([-1.5, -4.0]), rtol=1e-6)
    G0, _ = c.matrices(0.0)
    G1, _ = c.matrices(1.0)
    assert not np.allclose(G0, G1)  # G follows lam(t)


def test_a_constant_sympy_rate_is_a_constant():
    c = complete(CHAIN, "alternative", lam=sympy.Integer(2) + 0 * t)
    assert c.lam == 2.0 and c.dae.is_constant


def test_exceptions_subclass_builtins():
    assert issubclass(DimensionError, ValueError)
    assert issubclass(IndexDeterminationError, ValueError)


# -- a callable coefficient that misbehaves ---------------------------------------------------------
def raises_after(t_bad, exc):
    """f = (sin t, 0) until `t_bad`, then raises `exc` (any exception, not only ValueError)."""
    def f(s, d):
        if s > t_bad:
            raise exc
        return [np.sin(s + d * np.pi / 2), 0.0]
    return f


@pytest.mark.parametrize("exc", [ZeroDivisionError("division by zero"), KeyError("table"), RuntimeError("lookup")])
@pytest.mark.parametrize("solver", ["RK45", "Radau", "CVODE"])
def test_a_callable_raising_anything_mid_run_keeps_the_trajectory(exc, solver):
    dae = LinearDAE(N2, I2, raises_after(0.3, exc))
    res = solve_dae(dae, (0.0, 1.0), [0.0, 0.0], lam=1.0, method=solver, rtol=1e-10, atol=1e-12)
    assert not res.success and res.status == -2
    assert "`f(t, d)` raised " + type(exc).__name__ in res.message and "at t=" in res.message, res.message
    assert res.t.size >= 2 and res.t[0] == 0.0 and res.t[-1] <= 0.3 + 1e-12
    assert chain_error(res) < 1e-8


def turns_bad_after(t_bad, bad):
    """f = (sin t, 0) until `t_bad`, then `bad` (text, complex: a TypeError in the checks, not in the callable)."""
    def f(s, d):
        return bad if s > t_bad else [np.sin(s + d * np.pi / 2), 0.0]
    return f


@pytest.mark.parametrize("bad", [["a", "b"], [1j, 0.0]], ids=["text", "complex"])
@pytest.mark.parametrize("solver", ["RK45", "Radau", "CVODE"])
def test_a_callable_returning_the_wrong_type_mid_run_keeps_the_trajectory(bad, solver):
    res = solve_dae(LinearDAE(N2, I2, turns_bad_after(0.3, bad)), (0.0, 1.0), [0.0, 0.0], lam=1.0, method=solver,
                    rtol=1e-10, atol=1e-12)
    assert not res.success and res.status == -2
    assert "`f(t, d)` must return real numbers" in res.message and "failed at t=" in res.message, res.message
    assert res.t.size >= 2 and res.t[-1] <= 0.3 + 1e-12 and chain_error(res) < 1e-8


@pytest.mark.parametrize("name, make", [
    ("f", lambda h: LinearDAE(N2, I2, h)),
    ("B", lambda h: LinearDAE(N2, lambda s, d: np.eye(2) * (1 + 1j) if d == 0 else np.zeros((2, 2)))),
])
def test_complex_values_from_a_callable_are_refused(name, make):
    h = lambda s, d: np.array([np.sin(s + d * np.pi / 2) + 1j, 0.0])  # noqa: E731
    with pytest.raises(TypeError, match=rf"`{name}\(t, d\)` must return real numbers.*complex"):
        complete(make(h), "alternative", lam=1.0).rhs(0.0, np.zeros(2))


def test_complex_values_from_a_vectorized_callable_forcing_are_refused():
    """The forcing of a constant completion calls f on an array of times when it can: complex is refused there too."""
    def f(s, d):
        value = np.sin(s + d * np.pi / 2) + (1j if np.ndim(s) else 0)  # complex only when vectorized
        return np.array([value, 0.0 * s])
    c = complete(LinearDAE(N2, I2, f), "alternative", lam=1.0)
    with pytest.raises(TypeError, match=r"`f\(t, d\)` must return real numbers.*complex"):
        solve_completion(c, (0.0, 1.0), [0.0, 0.0], method="expm", max_step=0.05)


def test_a_complex_constant_array_is_refused():
    with pytest.raises(TypeError, match="`A` must be real"):
        LinearDAE(np.array([[1 + 0.5j, 0], [0, 1]]), I2)


@pytest.mark.parametrize("name, make", [
    ("f", lambda: LinearDAE(N2, I2, lambda s, d: [np.sin(s), 0.0])),            # f' given as f
    ("f", lambda: LinearDAE(N2, I2, lambda s, d: [1.0 + s, 2.0])),              # f' given as f (a line)
    ("f", lambda: LinearDAE(N2, I2, lambda s, d: [3.0, 0.0])),                  # a constant, d ignored: f' = 3?
    ("B", lambda: LinearDAE(N2, lambda s, d: np.array([[1.0, 0], [0, 1 + s]]), [0.0, 1.0])),
])
@pytest.mark.parametrize("solver", ["RK45", "expm", "CVODE"])
def test_a_callable_that_ignores_d_is_refused_at_set_up(name, make, solver):
    """Before the run (at `complete` for time-varying coefficients, before the first step for a forcing)."""
    with pytest.raises(ValueError, match=rf"`{name}\(t, d\)` must honour its derivative order `d`"):
        solve_dae(make(), (0.0, 1.0), [0.0, 0.0], lam=1.0, method=solver)


@pytest.mark.parametrize("f", [
    lambda s, d: [np.sin(1e3 * s + d * np.pi / 2) * 1e3 ** d, 0.0],         # fast
    lambda s, d: [1e-9 * np.exp(s), 0.0],                                    # tiny, and every derivative is f
    lambda s, d: [1e9 * np.cos(s + d * np.pi / 2), 0.0],                      # large
    lambda s, d: [np.exp(2 * s) * 2.0 ** d, 0.0],                             # steep
    lambda s, d: [s ** 3 if d == 0 else 3 * s ** 2 if d == 1 else 6 * s if d == 2 else 6.0 if d == 3 else 0.0, 0.0],
])
def test_a_callable_that_honours_d_is_accepted(f):
    for t0 in (0.0, 0.5, -3.0, 7.0, 300.0):
        dae = LinearDAE(N2, I2, f)
        dae.f.jet(t0, 2)  # the check runs on the first jet with derivatives
        assert dae.f._d_checked


# -- functions without derivatives where the completion needs them ---------------------------------
@pytest.mark.parametrize("expr", ["abs(t - 0.5)", "abs(sin(3*t))", "2 + abs(m*t)", "abs(p)"])
@pytest.mark.parametrize("entry, key", [("f[1]", "f"), ("B[0][1]", "B")])
def test_abs_in_a_spec_equation_is_refused_up_front(expr, entry, key):
    """The completion differentiates A, B, f up to order k + 2; abs(u) has no derivative where u = 0."""
    import tomllib

    from fmu_build import SpecError, parse_spec
    from tests.fmu_build.spec.test_spec_errors import BASE

    fragment = {"f": 'f = [0, "p + sin(t)"]', "B": 'B = [[0, -1], [0, 0]]'}[key]
    new = {"f": f'f = [0, "{expr}"]', "B": f'B = [[0, "{expr}"], [0, 0]]'}[key]
    data = tomllib.loads(BASE.replace(fragment, new))
    with pytest.raises(SpecError, match=rf"equations\.{re.escape(entry)}: abs\(\) is not allowed in the equations"):
        parse_spec(data)


def test_abs_in_a_spec_output_is_accepted():
    """Outputs are evaluated, never differentiated: abs is fine there."""
    import tomllib

    from fmu_build import parse_spec
    from tests.fmu_build.spec.test_spec_errors import BASE

    spec = parse_spec(tomllib.loads(BASE + '\n[outputs]\nspeed = "abs(v)"\n'))
    assert str(spec.outputs[0]["expr"]) == "Abs(v)"


@pytest.mark.parametrize("expr", [sympy.Abs(t - 0.5), sympy.sign(t), sympy.Heaviside(t - 1), sympy.Max(t, 1),
                                  sympy.floor(t)])
def test_a_sympy_coefficient_without_derivatives_is_refused(expr):
    with pytest.raises(ValueError, match=r"`f` contains .* which has no derivative where"):
        LinearDAE(N2, I2, [expr, 0])
    with pytest.raises(ValueError, match=r"`B` contains"):
        LinearDAE(N2, sympy.Matrix([[1, 0], [0, 1 + expr]]))


def test_column_equilibration_leaves_the_alternative_completion_unchanged():
    """y = D^-1 x: the alternative completion of the scaled DAE is exactly D^-1 G D (its constraints and its
    index-one part are the same subspaces in either unknowns); with D = 2^-12 on one column both are computed."""
    p = gallery.nilpotent_chain(3, seed=0)
    D = np.ones(p.dae.n)
    D[1] = 2.0 ** -12
    scaled = LinearDAE(p.dae.A.value * D, p.dae.B.value * D, JetCallable(lambda s, order: p.dae.f_jet(s, order)))
    c, c_scaled = complete(p.dae, "alternative", lam=2.0), complete(scaled, "alternative", lam=2.0)
    assert c_scaled._scaling.c is not None and c._scaling.c is None
    G, g = c.matrices(0.7)
    G_s, g_s = c_scaled.matrices(0.7)
    np.testing.assert_allclose(G_s, G * D[None, :] / D[:, None], rtol=1e-9, atol=1e-9 * np.abs(G).max())
    np.testing.assert_allclose(g_s, g / D, rtol=1e-9, atol=1e-9 * np.abs(g / D).max())
    x = p.exact(np.array([0.7]))[:, 0] + 0.01
    # the same constraints (Z2 is a basis of the same left null space, up to rotation): the same residual norm
    np.testing.assert_allclose(np.linalg.norm(c_scaled.constraint_residual(0.7, x / D)),
                               np.linalg.norm(c.constraint_residual(0.7, x)), rtol=1e-9)
    # the nearest consistent point is sought in the given unknowns y, so project agrees up to the scaling's metric:
    # both are consistent
    assert np.linalg.norm(c_scaled.constraint_residual(0.7, c_scaled.project(0.7, x / D))) < 1e-9


# -- complex sympy coefficients ------------------------------------------------------------------------
@pytest.mark.parametrize("make, fragment", [
    (lambda: LinearDAE(N2, sympy.Matrix([[1, 0], [0, 1 + sympy.I * t]])), "`B[1, 1]` is complex: I*t + 1"),
    (lambda: LinearDAE(N2, I2, [sympy.I, sympy.sin(t)]), "`f[0]` is complex: I"),
    (lambda: LinearDAE(sympy.Matrix([[0, sympy.sqrt(-2)], [0, 0]]), I2), "`A[0, 1]` is complex: sqrt(2)*I"),
])
def test_a_complex_sympy_coefficient_is_refused_naming_the_entry(make, fragment):
    with pytest.raises(TypeError) as info:
        make()
    assert fragment in str(info.value)


def test_a_sympy_coefficient_with_i_that_is_real_is_solved():
    """``exp(i t) + exp(-i t) = 2 cos t`` is real: taken as such, not refused."""
    dae = LinearDAE(N2, I2, [sympy.exp(sympy.I * t) + sympy.exp(-sympy.I * t), 0])
    res = solve_dae(dae, (0.0, 1.0), [2.0, 0.0], lam=1.0, rtol=1e-10, atol=1e-12, t_eval=[0.0, 0.5, 1.0])
    assert res.success
    np.testing.assert_allclose(res.x, [2 * np.cos(res.t), 0 * res.t], atol=1e-8)


@pytest.mark.parametrize("method", ["RK45", "expm"])
def test_a_sympy_coefficient_complex_at_run_time_names_the_entry_and_time(method):
    """``(0.4 - t)**0.3`` is complex for t > 0.4: the run fails there naming the entry, or the set-up does."""
    dae = LinearDAE(N2, I2, [0, (0.4 - t) ** 0.3 + 2])
    c = complete(dae, "alternative", lam=1.0)
    if method == "expm":
        with pytest.raises(ValueError, match=r"`f\[1\]`.*complex at t="):
            solve_completion(c, (0.0, 1.0), [0.0, 2.0 + 0.4**0.3], method=method)
        return
    res = solve_completion(c, (0.0, 1.0), [0.0, 2.0 + 0.4**0.3], method=method, interpolate=False)
    assert not res.success and "`f[1]`" in res.message and "complex at t=" in res.message, res.message
    assert res.t[-1] <= 0.4
