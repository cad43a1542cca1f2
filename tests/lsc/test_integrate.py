"""Integration: accuracy against exact solutions, and drift off the manifold."""
import numpy as np
import pytest
import scipy.linalg

from lsc import LinearDAE, complete, eigenanalysis, gallery, solve_completion, solve_dae

from tests.support.problems import METHOD_LAMS


@pytest.mark.parametrize("name", ["chain4-mixed", "pencil-3-2", "mechanical", "prescribed_path"])
@pytest.mark.parametrize("method, lam", METHOD_LAMS)
@pytest.mark.parametrize("solver", ["RK45", "Radau"])
def test_accuracy_from_consistent_start(name, method, lam, solver):
    from tests.support.problems import CONSTANT_PROBLEMS

    p = CONSTANT_PROBLEMS[name]()
    c = complete(p.dae, method, lam=lam)
    t_eval = np.linspace(*p.t_span, 21)
    res = solve_completion(c, p.t_span, p.x0, method=solver, t_eval=t_eval, rtol=1e-9, atol=1e-11)
    assert res.success, res.message
    exact = p.exact(t_eval)
    # tolerance-scaled error, as scipy's own tests do
    err = np.abs(res.x - exact) / (1e-11 + 1e-9 * np.abs(exact))
    assert err.max() < 1e4, err.max()
    assert res.residual.max() < 1e-6


def drift(p, method, lam, delta=1e-3, t_end=8.0):
    c = complete(p.dae, method, lam=lam)
    x0 = p.x0 + delta * np.linspace(1.0, -1.0, p.dae.n)
    t_eval = np.linspace(0.0, t_end, 9)
    res = solve_completion(c, (0.0, t_end), x0, method="Radau", t_eval=t_eval, rtol=1e-11, atol=1e-14)
    assert res.success, res.message
    c_num = c.constraint_residual(res.t, res.x)
    return c, res, c_num


@pytest.mark.parametrize("method, lam", METHOD_LAMS + [("stabilized", 0.7), ("alternative", 0.7)])
def test_residual_follows_added_dynamics_exactly(method, lam):
    """For constant coefficients c' = H c: c(t) = expm(H t) c(0), with H from eigenanalysis."""
    p = gallery.random_pencil(n=9, blocks=(3, 2), seed=11)
    c, res, c_num = drift(p, method, lam)
    H = eigenanalysis(c).H
    for j, t in enumerate(res.t):
        predicted = scipy.linalg.expm(H * t) @ c_num[:, 0]
        np.testing.assert_allclose(c_num[:, j], predicted, rtol=1e-6, atol=1e-8 * np.linalg.norm(c_num[:, 0]))


def test_standard_drifts_polynomially():
    p = gallery.prescribed_path()
    _, res, c_num = drift(p, "standard", None)
    norms = np.linalg.norm(c_num, axis=0)
    assert norms[-1] > 10 * norms[0]  # grows ...
    # ... like a polynomial of degree index - 1 = 2 in t, and not faster
    coeffs = np.polynomial.polynomial.polyfit(res.t, c_num.T, 2)
    np.testing.assert_allclose(np.polynomial.polynomial.polyval(res.t, coeffs), c_num, rtol=1e-6, atol=1e-9 * norms[0])
    assert np.abs(coeffs[2]).max() > 1e-3 * norms[0]


@pytest.mark.parametrize("method", ["stabilized", "alternative"])
def test_stabilized_methods_decay(method):
    p = gallery.prescribed_path()
    _, res, c_num = drift(p, method, 2.0)
    norms = np.linalg.norm(c_num, axis=0)
    assert norms[-1] < 1e-4 * norms[0]
    err = np.abs(res.x[:, -1] - p.exact(res.t[-1])).max()
    assert err < 1e-6  # back on the exact solution of the DAE


@pytest.mark.parametrize("lam", [0.3, 1.0, 4.0])
def test_alternative_residual_decays_exactly_like_exp(lam):
    p = gallery.mechanical()
    c = complete(p.dae, "alternative", lam=lam)
    x0 = p.x0 + 1e-2 * np.array([1.0, -0.5, 0.3, 0.2, -1.0])
    t_eval = np.arange(0.0, 4.0)
    res = solve_completion(c, (0.0, 3.0), x0, method="Radau", t_eval=t_eval, rtol=1e-12, atol=1e-15)
    ratios = res.residual[1:] / res.residual[:-1]
    np.testing.assert_allclose(ratios, np.exp(-lam), rtol=1e-6)


def test_project_starts_on_the_manifold():
    p = gallery.mechanical()
    c = complete(p.dae, "standard")
    res = solve_completion(c, (0.0, 1.0), p.x0 + 0.1, project=True, t_eval=[0.0, 1.0], rtol=1e-10, atol=1e-12)
    assert res.residual[0] < 1e-12
    assert res.residual[-1] < 1e-8  # on the manifold the standard LSC does not drift


def test_solve_dae_is_complete_then_solve():
    p = gallery.nilpotent_chain(2, seed=3)
    kw = dict(t_eval=np.linspace(0, 2, 5), rtol=1e-8, atol=1e-10)
    r1 = solve_dae(p.dae, (0.0, 2.0), p.x0, completion="stabilized", lam=1.5, **kw)
    r2 = solve_completion(complete(p.dae, "stabilized", lam=1.5), (0.0, 2.0), p.x0, **kw)
    np.testing.assert_array_equal(r1.x, r2.x)
    assert r1.x.shape == (p.dae.n, 5) and r1.nfev == r2.nfev


def test_forcing_failure_mid_run_returns_failed_result():
    def f(t, d):
        if t > 0.5:
            return np.array([np.nan, 0.0])
        return np.array([np.sin(t + d * np.pi / 2), 0.0])

    dae = LinearDAE([[0.0, 1.0], [0.0, 0.0]], np.eye(2), f)
    res = solve_dae(dae, (0.0, 1.0), [0.0, 0.0], lam=1.0)
    assert not res.success
    assert res.status == -2
    assert "non-finite" in res.message and "t=" in res.message


def test_result_reports_counts():
    p = gallery.nilpotent_chain(1)
    res = solve_dae(p.dae, p.t_span, p.x0, lam=1.0, method="BDF")
    assert res.success and res.nfev > 0 and res.nlu > 0 and res.njev == 0  # constant jac: never re-evaluated


# -- exact stepping with the matrix exponential (method='expm') -------------------------


def _polynomial_chain():
    import sympy

    t = sympy.Symbol("t")
    f = sympy.Matrix([t**2, 1 + t, t**3 / 6])
    N = sympy.Matrix(3, 3, lambda i, j: 1 if j == i + 1 else 0)
    x = sum(((-1) ** i * N**i * f.diff(t, i) for i in range(3)), sympy.zeros(3, 1))
    exact = sympy.lambdify(t, list(x))
    return LinearDAE(np.eye(3, k=1), np.eye(3), list(f)), lambda s: np.array(exact(s), dtype=float)


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
def test_expm_is_exact_for_polynomial_forcing(method, lam):
    dae, exact = _polynomial_chain()
    c = complete(dae, method, lam=lam)
    ts = np.linspace(0.0, 3.0, 4)  # steps of 1: only exactness can pass this
    res = solve_completion(c, (0.0, 3.0), exact(0.0), method="expm", t_eval=ts)
    assert res.success
    np.testing.assert_allclose(res.x, np.array([exact(s) for s in ts]).T, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("q", [1, 3])
def test_expm_order_is_taylor_degree_plus_one(q):
    p = gallery.random_pencil(n=8, blocks=(3, 1), seed=3)
    c = complete(p.dae, "stabilized", lam=2.0)
    hs = np.array([0.2, 0.1, 0.05])
    errors = []
    for h in hs:
        res = solve_completion(c, (0.0, 2.0), p.x0, method="expm", t_eval=np.arange(0.0, 2.0 + h / 2, h), taylor_degree=q,
                               max_step=h)
        errors.append(np.abs(res.x - p.exact(res.t)).max())
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert abs(slope - (q + 1)) < 0.2, (slope, errors)


def test_expm_computes_one_exponential_per_step_size(monkeypatch):
    # Equal output intervals from linspace differ in their last bits; they must share
    # one exponential (it is the expensive part: an n(q+2) matrix).
    import scipy.linalg

    calls = []
    real = scipy.linalg.expm
    monkeypatch.setattr(scipy.linalg, "expm", lambda M: calls.append(M.shape) or real(M))
    p = gallery.nilpotent_chain(3, seed=0)
    c = complete(p.dae, "alternative", lam=1.0)
    ts = np.linspace(0.0, 5.0, 51)
    res = solve_completion(c, (0.0, 5.0), p.x0, method="expm", t_eval=ts, max_step=0.05, taylor_degree=7)
    assert len(calls) == 1
    # and sharing costs nothing measurable: degree 7 at h = 0.05 reaches 1e-12 (measured 9e-14)
    np.testing.assert_allclose(res.x, p.exact(ts), rtol=0, atol=1e-12 * (1 + np.abs(p.exact(ts)).max()))


def test_expm_alternative_residual_decays_exactly():
    # polynomial forcing: the propagation is exact, so is the decay (steps of a whole unit)
    dae, exact = _polynomial_chain()
    c = complete(dae, "alternative", lam=1.5)
    res = solve_completion(c, (0.0, 3.0), exact(0.0) + 0.01, method="expm", t_eval=np.arange(0.0, 4.0))
    np.testing.assert_allclose(res.residual[1:] / res.residual[:-1], np.exp(-1.5), rtol=1e-10)


@pytest.mark.parametrize("kwargs, exception, fragment", [
    (dict(taylor_degree=-1), ValueError, "`taylor_degree` must be a non-negative int"),
    (dict(max_step=0.0), ValueError, "`max_step` must be positive"),
    (dict(t_eval=[0.5, 0.2]), ValueError, "`t_eval` must be sorted"),
    (dict(first_step=0.1), TypeError, "only `taylor_degree`, `max_step` and `dense_output`"),
])
def test_expm_bad_options(kwargs, exception, fragment):
    dae, exact = _polynomial_chain()
    with pytest.raises(exception, match=None) as info:
        solve_completion(complete(dae, "standard"), (0.0, 1.0), exact(0.0), method="expm", **kwargs)
    assert fragment in str(info.value)


def test_expm_refuses_time_varying():
    p = gallery.thesis_example3()
    with pytest.raises(ValueError, match="constant coefficients"):
        solve_completion(complete(p.dae, "standard"), p.t_span, p.x0, method="expm")


# -- a reversed t_span ------------------------------------------------------------------------------
BACKWARD_METHODS = ["RK45", "Radau", "expm", "CVODE"]


@pytest.mark.parametrize("solver", BACKWARD_METHODS)
@pytest.mark.parametrize("method", ["stabilized", "alternative"])
def test_a_reversed_t_span_is_refused_where_the_added_eigenvalues_are_minus_lam(method, solver):
    """Backward in time -lam is growth: from the exact x(2), x(0) came out 1e30 off with success=True."""
    p = gallery.prescribed_path()
    c = complete(p.dae, method, lam=10.0)
    with pytest.raises(ValueError, match=r"`t_span` = \(2\.0, 0\.0\) runs backward.*grow like exp\(lam"):
        solve_completion(c, (2.0, 0.0), p.exact(np.array([2.0]))[:, 0], method=solver, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("solver", ["RK45", "Radau", "expm"])
def test_the_standard_completion_integrates_backward(solver):
    """Added eigenvalues 0: off-manifold errors grow at most polynomially either way, so x(0) is reached."""
    p = gallery.prescribed_path()
    c = complete(p.dae, "standard")
    ts = np.linspace(2.0, 0.0, 5)
    res = solve_completion(c, (2.0, 0.0), p.exact(ts[:1])[:, 0], method=solver, t_eval=ts, rtol=1e-10, atol=1e-12)
    assert res.success, res.message
    exact = p.exact(ts)
    assert np.max(np.abs(res.x - exact) / (1 + np.abs(exact))) < 1e-7


# -- t_eval and tolerances: one check for every method ---------------------------------------------
ALL_SOLVERS = ["RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA", "expm", "CVODE"]
BAD_T_EVAL = {
    "outside": ([0.0, 0.5, 1.5], "lie within `t_span`"),
    "before": ([-0.5, 0.5], "lie within `t_span`"),
    "unsorted": ([0.0, 0.7, 0.3], "increasing"),
    "repeated": ([0.0, 0.5, 0.5], "increasing"),
    "nan": ([0.0, np.nan, 1.0], "finite"),
    "empty": ([], "empty"),
    "matrix": ([[0.0, 1.0]], "1-D"),
    "text": (["a"], "real numbers"),
}


@pytest.mark.parametrize("solver", ALL_SOLVERS)
@pytest.mark.parametrize("case", sorted(BAD_T_EVAL))
def test_a_bad_t_eval_is_refused_by_every_method(case, solver):
    p = gallery.nilpotent_chain(2)
    c = complete(p.dae, "alternative", lam=1.0)
    t_eval, fragment = BAD_T_EVAL[case]
    with pytest.raises((ValueError, TypeError), match="`t_eval`") as info:
        solve_completion(c, (0.0, 1.0), p.x0, method=solver, t_eval=t_eval)
    assert fragment in str(info.value)


@pytest.mark.parametrize("solver", ["RK45", "expm", "CVODE"])
def test_t_eval_at_the_ends_of_t_span_is_kept(solver):
    p = gallery.nilpotent_chain(2)
    c = complete(p.dae, "alternative", lam=1.0)
    res = solve_completion(c, p.t_span, p.x0, method=solver, t_eval=[p.t_span[0], p.t_span[1]], rtol=1e-8, atol=1e-10)
    assert res.success and res.t.tolist() == list(p.t_span)


BAD_TOL = [
    (dict(atol=0.0), "`atol` must be positive"),
    (dict(atol=-1e-8), "`atol` must be positive"),
    (dict(atol=np.nan), "`atol` must be positive"),
    (dict(atol="one zero"), "`atol` must be positive"),
    (dict(rtol=0.0), "`rtol` must be positive"),
    (dict(rtol=-1e-3), "`rtol` must be positive"),
    (dict(rtol=np.nan), "`rtol` must be positive"),
    (dict(rtol=np.inf), "`rtol` must be positive"),
    (dict(atol=["small"] * 3), "`atol` must be"),
    (dict(atol="one too many"), "`atol` must be a number or"),
    (dict(rtol=True), "`rtol` must be a positive finite number"),
    (dict(atol="1e-8"), "`atol` must be a positive finite number"),
]


@pytest.mark.parametrize("solver", ALL_SOLVERS)
@pytest.mark.parametrize("tol, fragment", BAD_TOL, ids=[f"{k}={v!r}" for (d, _) in BAD_TOL for k, v in d.items()])
def test_bad_tolerances_get_one_message_from_every_method(tol, fragment, solver):
    p = gallery.nilpotent_chain(1)
    c = complete(p.dae, "alternative", lam=1.0)
    shaped = {"one zero": [1e-8] * (c.n - 1) + [0.0], "one too many": [1e-8] * (c.n + 1)}
    tol = {k: shaped.get(v, v) if isinstance(v, str) else v for k, v in tol.items()}
    with pytest.raises((ValueError, TypeError)) as info:
        solve_completion(c, (0.0, 1.0), p.x0, method=solver, **tol)
    assert fragment in str(info.value)


# -- dense output: only on the interval integrated ---------------------------------------------------
@pytest.mark.parametrize("solver", ["RK45", "Radau", "expm"])
def test_dense_output_is_refused_outside_t_span(solver):
    """It extrapolated silently (2.9e4 at t = 20 where the solution is of size 1)."""
    p = gallery.prescribed_path()
    c = complete(p.dae, "alternative", lam=2.0)
    res = solve_completion(c, p.t_span, p.x0, method=solver, dense_output=True, rtol=1e-10, atol=1e-12)
    assert res.success, res.message
    inside = np.linspace(*p.t_span, 37)
    np.testing.assert_allclose(res.sol(inside), p.exact(inside), atol=1e-7)
    np.testing.assert_allclose(res.sol(p.t_span[1]), p.exact(p.t_span[1]), atol=1e-7)
    for outside in (p.t_span[1] + 10.0, p.t_span[0] - 1e-3, [0.5, p.t_span[1] + 1.0]):
        with pytest.raises(ValueError, match=r"outside the interval \[0, 10\] that was integrated"):
            res.sol(outside)


# -- a DAE that becomes singular inside t_span --------------------------------------------------------
def _singular_at_one_over_sqrt2():
    """``x1' = x2``, ``(1 - 2 t^2) x2 = 1 + sin t``: the rank of the derivative array drops at t = 1/sqrt(2),
    where x2 has a pole; exact ``x2 = (1 + sin t) / (1 - 2 t^2)``."""
    import sympy

    t = sympy.Symbol("t")
    return LinearDAE([[1, 0], [0, 0]], sympy.Matrix([[0, -1], [0, 1 - 2 * t**2]]), sympy.Matrix([0, 1 + sympy.sin(t)]))


@pytest.mark.parametrize("interpolate", [None, False])
def test_a_singular_time_inside_t_span_ends_the_run_there_and_keeps_the_trajectory(interpolate):
    """Found once: success=False naming t = 0.70710678..., the trajectory before it kept and right (it ran
    for minutes, then integrated again from the start and kept only the points of that second run)."""
    dae = _singular_at_one_over_sqrt2()
    c = complete(dae, "alternative", lam=2.0, t_span=(0.0, 2.0))
    calls = []  # every evaluation of the completion evaluates B's jet
    jet = dae.B.jet
    dae.B.jet = lambda s, order: calls.append(s) or jet(s, order)
    res = solve_completion(c, (0.0, 2.0), [1.0, 1.0], rtol=1e-6, atol=1e-9, interpolate=interpolate)
    assert not res.success
    assert "0.7071067811" in res.message, res.message
    ts = 1 / np.sqrt(2)
    assert ts - 1e-4 < res.t[-1] < ts and res.t[0] == 0.0 and np.all(np.diff(res.t) > 0)
    early = res.t < 0.69
    x2 = (1 + np.sin(res.t[early])) / (1 - 2 * res.t[early] ** 2)
    np.testing.assert_allclose(res.x[1, early], x2, rtol=1e-5)
    if interpolate is False:  # (the interpolant's set-up samples the whole interval first)
        assert max(calls) < ts + 1e-5  # the run did not go on after the singular time (the search for it did not)
    # one run: the evaluations are the run's, the interpolant's set-up (500) and the search for the time (~300)
    assert len(calls) < res.nfev + 1000, (len(calls), res.nfev)
