"""Time-varying coefficients and rates: thesis chapters 5-6 against exact formulas."""
import numpy as np
import pytest
import sympy

from lsc import (
    IndexDeterminationError, LinearDAE, check_solvability, complete, gallery, solve_completion,
)

from tests.support.problems import METHOD_LAMS

t = sympy.Symbol("t")

TV_PROBLEMS = {
    "example1": gallery.thesis_example1,
    "example3": gallery.thesis_example3,
    "example4": gallery.thesis_example4,
    "example5": gallery.thesis_example5,
    "stiff_index1": gallery.stiff_index1,
    "rotating3": lambda: gallery.rotating_canonical(3),
    "rotating4": lambda: gallery.rotating_canonical(4),
}


@pytest.fixture(params=sorted(TV_PROBLEMS), scope="module")
def tv_problem(request):
    return TV_PROBLEMS[request.param]()


def test_gallery_exact_solutions(tv_problem):
    p = tv_problem
    assert not p.dae.is_constant
    for s in np.linspace(*p.t_span, 7):
        r = p.dae.residual(s, p.exact(s), p.exact(s, 1))
        np.testing.assert_allclose(r, 0, atol=1e-10 * (1 + np.abs(p.exact(s, 1)).max()))
    assert check_solvability(p.dae, p.t_span).k == p.index


LAMS = METHOD_LAMS + [("stabilized", 1 + t**2), ("alternative", lambda s, d: [2 + np.sin(s), np.cos(s), -np.sin(s), -np.cos(s), np.sin(s), np.cos(s)][d])]


@pytest.mark.parametrize("method, lam", LAMS, ids=["standard", "stabilized", "alternative", "stabilized-lam(t)", "alternative-lam(t)"])
def test_completions_contain_exact_solutions(tv_problem, method, lam):
    p = tv_problem
    c = complete(p.dae, method, lam=lam, t_span=p.t_span)
    for s in np.linspace(*p.t_span, 6):
        G, g = c.matrices(s)
        expected = p.exact(s, 1)
        np.testing.assert_allclose(G @ p.exact(s) + g, expected, rtol=1e-8, atol=1e-8 * (1 + np.abs(expected).max()))


def test_example1_standard_matches_closed_form():
    """Thesis (1.36)-(1.37) for f = (sin t, cos 2t)."""
    p = gallery.thesis_example1()
    c = complete(p.dae, "standard", t_span=p.t_span)
    for s in (-0.9, -0.3, 0.0, 0.4, 1.0):
        f1, f1d = np.sin(s), np.cos(s)
        f2d, f2dd = -2 * np.sin(2 * s), -4 * np.cos(2 * s)
        G_exact = np.array([[s, 0.0], [s, 0.0]]) / (s**2 + 1)
        g_exact = np.array([(s**2 + 1) * (-f1d - s * f2dd) + (s * f1 - f2d), s * f1 - f2d]) / (s**2 + 1)
        G, g = c.matrices(s)
        np.testing.assert_allclose(G, G_exact, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(g, g_exact, rtol=1e-12, atol=1e-12)


def test_example1_needs_the_interval_for_k():
    p = gallery.thesis_example1()
    c = complete(p.dae, "standard")  # k decided at t = 0 only: 1
    assert c.k == 1
    with pytest.raises(IndexDeterminationError, match=r"does not determine x' at t=0.5"):
        c.rhs(0.5, np.zeros(2))
    assert complete(p.dae, "standard", t_span=p.t_span).k == 2


@pytest.mark.parametrize("alpha, beta", [(2.0, -0.5), (-1.0, 0.3), (5.0, 1.0)])
def test_example3_added_eigenvalue(alpha, beta):
    """Standard LSC: {beta, -alpha}, the added one arbitrary. Both stabilized
    completions shift it by -lam: the residual c = e^{alpha t} (x1 - x2)
    decays like e^{-lam t}, so x1 - x2 decays like e^{-(alpha + lam) t}."""
    p = gallery.thesis_example3(alpha, beta)
    lam = 1.5
    expected = {"standard": -alpha, "stabilized": -alpha - lam, "alternative": -alpha - lam}
    for method, l in METHOD_LAMS:
        c = complete(p.dae, method, lam=None if l is None else lam, t_span=p.t_span)
        for s in (0.0, 1.3):
            G, _ = c.matrices(s)
            assert sorted(np.linalg.eigvals(G).real) == pytest.approx(sorted([beta, expected[method]]), abs=1e-10)
    G_std = complete(p.dae, "standard").matrices(0.7)[0]
    np.testing.assert_allclose(G_std, [[beta, 0.0], [alpha + beta, -alpha]], atol=1e-12)


@pytest.mark.parametrize("lam", [3.0, 1 + t], ids=["constant", "lam(t)=1+t"])
def test_example4_stabilized_formula(lam):
    """Thesis (5.67): x' = -(lam - 2) x + e^{2t} (f' + lam f), f = cos t."""
    p = gallery.thesis_example4()
    c = complete(p.dae, "stabilized", lam=lam, t_span=p.t_span)
    for s in (0.0, 0.8, 1.9):
        l = 3.0 if lam == 3.0 else 1 + s
        G, g = c.matrices(s)
        np.testing.assert_allclose(G, [[-(l - 2)]], rtol=1e-12)
        np.testing.assert_allclose(g, [np.exp(2 * s) * (-np.sin(s) + l * np.cos(s))], rtol=1e-12)


@pytest.mark.parametrize("alpha, lam", [(1.0, 2.5), (1.0, 0.5), (2.0, 1.0), (0.5, 3.0)])
def test_example5_convergence_iff_lam_above_alpha(alpha, lam):
    """Thesis (5.69)-(5.70): x2 decays like e^{-lam t}; y approaches a DAE solution iff lam > alpha."""
    # Horizon 4: coefficients grow like e^{alpha t}; at alpha = 2, t = 5 the rank
    # decisions of [J, F] come within the RankDecisionWarning margin.
    p = gallery.thesis_example5(alpha, t_span=(0.0, 4.0))
    c = complete(p.dae, "stabilized", lam=lam, t_span=p.t_span)
    for s in (0.0, 2.0):
        np.testing.assert_allclose(c.matrices(s)[0], [[-1.0, np.exp(alpha * s)], [0.0, -lam]], rtol=1e-12, atol=1e-14)
    c1, c2 = 1.0, 0.1
    T = 4.0
    ts = np.linspace(0, T, 11)
    res = solve_completion(c, (0, T), [c1 + c2 / (1 + alpha - lam), c2], method="Radau", t_eval=ts, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(res.x[1], c2 * np.exp(-lam * ts), rtol=1e-7)
    closed = c1 * np.exp(-ts) + c2 / (1 + alpha - lam) * np.exp((alpha - lam) * ts)  # (5.70)
    np.testing.assert_allclose(res.x[0], closed, rtol=1e-7, atol=1e-12)
    # distance to the DAE solution c1 e^{-t} (the others differ by a multiple of e^{-t})
    gap = np.abs(res.x[0] - c1 * np.exp(-ts))
    if lam > alpha:
        assert gap[-1] < gap[0] * np.exp(-(lam - alpha) * T) * 1.0001
    else:
        assert gap[-1] > gap[0] * np.exp((alpha - lam) * T) * 0.9999


def _decay_ratios(p, lam, lam_integral, method):
    c = complete(p.dae, "alternative", lam=lam, t_span=p.t_span)
    t0 = p.t_span[0]
    x0 = p.x0 + 1e-3 * np.linspace(1.0, -0.5, p.dae.n)
    ts = t0 + np.arange(0.0, 3.0)
    res = solve_completion(c, (t0, ts[-1]), x0, method=method, t_eval=ts, rtol=1e-12, atol=1e-15)
    assert res.success, res.message
    ratio = res.residual[1:] / res.residual[:-1]
    expected = np.exp(-np.diff([lam_integral(s) for s in ts]))
    return ratio, expected


@pytest.mark.parametrize("name, method", [
    ("example1", "DOP853"), ("example3", "DOP853"), ("example4", "DOP853"), ("example5", "DOP853"),
    ("stiff_index1", "Radau"), ("rotating3", "DOP853"), ("rotating4", "DOP853"),
])
def test_alternative_residual_decays_like_exp_minus_integral(name, method):
    assert name in TV_PROBLEMS
    p = TV_PROBLEMS[name]()
    ratio, expected = _decay_ratios(p, 1.0, lambda s: s, method)
    np.testing.assert_allclose(ratio, expected, rtol=1e-6)
    # time-varying rate lam = 1 + 0.5 sin t: int = t - 0.5 cos t
    ratio, expected = _decay_ratios(p, 1 + sympy.sin(t) / 2, lambda s: s - 0.5 * np.cos(s), method)
    np.testing.assert_allclose(ratio, expected, rtol=1e-6)


@pytest.mark.parametrize("method, lam", [("alternative", 3.0), ("stabilized", 3.0)])
def test_theorem9_bound_with_vanishing_delta(method, lam):
    """d(y(t), M(t)) <= c0 exp(-int lam + t + k(t)), e^{-k} <= delta(t) -> 0 (Example 4)."""
    p = gallery.thesis_example4(t_span=(0.0, 4.0))
    c = complete(p.dae, method, lam=lam, t_span=p.t_span)
    ts = np.linspace(0, 4, 17)
    y0 = p.x0 + 0.1
    res = solve_completion(c, (0, 4), y0, method="Radau", t_eval=ts, rtol=1e-11, atol=1e-14)
    alt = complete(p.dae, "alternative", lam=lam, t_span=p.t_span)
    deltas = []
    for s in ts:
        fac = alt._evaluate(s)[0]
        A = fac.jets.J[0][0][:1, :1]
        Z1 = np.linalg.svd(A @ fac.T2[0], full_matrices=False)[0]
        deltas.append(np.linalg.svd(np.vstack([Z1.T @ A, fac.C[0]]), compute_uv=False).min())
    deltas = np.array(deltas)
    np.testing.assert_allclose(deltas, np.exp(-2 * ts), rtol=1e-10)  # delta(t) = e^{-2t} -> 0
    k = -np.log(deltas)
    dist = np.abs(res.x[0] - p.exact(ts)[0])  # M(t) is the single point e^{2t} f
    c0 = np.linalg.norm(c.constraint_residual(0.0, y0))
    bound = c0 * np.exp(-lam * ts + ts + k)
    assert np.all(dist <= bound * (1 + 1e-8))
    assert dist[-1] < dist[0]  # lam = 3 > 2 pulls it in (thesis Example 4)


def test_solvability_decided_by_array_not_pencil():
    # det(sA + B) == 1 for all s and t, but not uniquely solvable (ERRATA 6).
    A = sympy.Matrix([[-t, t**2], [-1, t]])
    dae = LinearDAE(A, np.eye(2))
    s = sympy.Symbol("s")
    assert sympy.simplify((s * A + sympy.eye(2)).det()) == 1
    with pytest.raises(IndexDeterminationError, match="not uniquely solvable"):
        check_solvability(dae, (0.0, 1.0))
    with pytest.raises(IndexDeterminationError):
        complete(dae, "alternative", lam=1.0, t_span=(0.0, 1.0))
    # singular pencil for every t, yet a unique solution (x2 = f2 - f1', x1 = f1 + t x2)
    A2, B2 = sympy.Matrix([[0, 0], [1, -t]]), sympy.Matrix([[1, -t], [0, 0]])
    assert sympy.simplify((s * A2 + B2).det()) == 0
    f = [sympy.sin(t), sympy.cos(t)]
    dae2 = LinearDAE(A2, B2, f)
    assert check_solvability(dae2, (0.0, 1.0)).k == 2
    c = complete(dae2, "alternative", lam=1.0, t_span=(0.0, 1.0))
    s0 = 0.6
    x2 = np.cos(s0) - np.cos(s0)  # f2 - f1' = 0
    x = np.array([np.sin(s0) + s0 * x2, x2])
    xdot = np.array([np.cos(s0), 0.0])
    np.testing.assert_allclose(c.rhs(s0, x), xdot, atol=1e-12)


def _rank_change_dae():
    """a(t) x2' + x2 = 0 with a = 0 for t <= 1 and (t - 1)^4 after: index 1, then an ODE."""
    def A(s, d):
        if s <= 1.0:
            return np.zeros((2, 2)) + np.diag([1.0, 0.0]) * (d == 0)
        from math import factorial
        coef = factorial(4) / factorial(4 - d) * (s - 1) ** (4 - d) if d <= 4 else 0.0
        return np.diag([1.0 if d == 0 else 0.0, coef])

    return LinearDAE(A, lambda s, d: np.eye(2) * (d == 0), lambda s, d: np.array([np.sin(s + d * np.pi / 2), 0.0]))


def test_rank_change_during_integration_fails_clearly():
    dae = _rank_change_dae()
    c = complete(dae, "alternative", lam=1.0, t_span=(0.0, 0.9))
    res = solve_completion(c, (0.0, 2.0), [0.0, 0.0])
    assert not res.success and res.status == -2
    assert "t=1.0" in res.message and ("changes at" in res.message or "not 1-full" in res.message)


def test_lam_not_positive_on_interval():
    p = gallery.thesis_example3()
    with pytest.raises(ValueError, match=r"`lam` must be positive .* lam\(2\.0\d*\) = "):
        complete(p.dae, "alternative", lam=1 - t / 2, t_span=(0.0, 3.0))
    c = complete(p.dae, "alternative", lam=1 - t / 2)  # checked at t = 0 only: the interval is not known yet
    with pytest.raises(ValueError, match=r"`lam` must be positive .* lam\(2\.0\d*\) = "):
        solve_completion(c, (0.0, 3.0), p.x0)  # refused before the run, which knows its interval


def test_evaluations_at_one_time_share_one_factorization(monkeypatch):
    import lsc._setup as mod

    p = gallery.rotating_canonical(3)
    c = complete(p.dae, "alternative", lam=1.0, t_span=p.t_span)
    calls = []
    original = mod.factors_at

    def counting(completion, t, *args, **kwargs):
        calls.append(t)
        return original(completion, t, *args, **kwargs)

    monkeypatch.setattr(mod, "factors_at", counting)
    x = p.exact(1.7)
    c.rhs(1.7, x)
    c.matrices(1.7)
    c.constraint_residual(1.7, x)
    c.project(1.7, x)
    c.jac(1.7, x)
    assert calls == [1.7]


def test_given_k_is_checked_over_the_interval():
    p = gallery.thesis_example1()
    with pytest.raises(IndexDeterminationError, match="with k=1 the derivative array does not determine x' at"):
        check_solvability(p.dae, p.t_span, k=1)
    with pytest.raises(IndexDeterminationError, match="k=1"):
        complete(p.dae, "standard", k=1, t_span=p.t_span)
    report = check_solvability(p.dae, p.t_span, k=3)
    assert report.k == 3 and report.pointwise_index is None
    # Theorem 5 holds pointwise too: the standard LSC with k = 3 equals the one with k = 2
    c2 = complete(p.dae, "standard", t_span=p.t_span)
    c3 = complete(p.dae, "standard", k=3, t_span=p.t_span)
    for s in (-0.6, 0.0, 0.9):
        np.testing.assert_allclose(c3.matrices(s)[0], c2.matrices(s)[0], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(c3.matrices(s)[1], c2.matrices(s)[1], rtol=1e-10, atol=1e-10)


def test_residual_decay_covers_every_time_varying_problem():
    marks = test_alternative_residual_decays_like_exp_minus_integral.pytestmark
    names = {args[0] for m in marks if m.name == "parametrize" for args in m.args[1]}
    assert names == set(TV_PROBLEMS)
