"""Completions against exact solutions and the thesis theorems."""
import numpy as np
import scipy.linalg
import pytest

from lsc import COMPLETIONS, IndexDeterminationError, LinearDAE, complete, gallery

from tests.support.problems import METHOD_LAMS


def test_registry_keys_match_class_names():
    for key, cls in COMPLETIONS.items():
        assert cls.__name__ == key.capitalize() + "Completion"
        assert cls.method == key


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
def test_contains_exact_solution(problem, method, lam):
    """Every completion contains the DAE's solutions: G x*(t) + g(t) = x*'(t)."""
    c = complete(problem.dae, method, lam=lam)
    for t in np.linspace(*problem.t_span, 6):
        G, g = c.matrices(t)
        expected = problem.exact(t, 1)
        np.testing.assert_allclose(G @ problem.exact(t) + g, expected, rtol=1e-9, atol=1e-9 * (1 + np.abs(expected).max()))
        np.testing.assert_allclose(c.rhs(t, problem.exact(t)), G @ problem.exact(t) + g, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
def test_constraint_residual_zero_on_manifold_only(problem, method, lam):
    c = complete(problem.dae, method, lam=lam)
    t = 1.3
    assert np.linalg.norm(c.constraint_residual(t, problem.exact(t))) < 1e-10
    if c.n_constraints:
        assert np.linalg.norm(c.constraint_residual(t, problem.exact(t) + 0.1)) > 1e-3


def test_residuals_of_the_three_methods_agree(problem):
    x = problem.exact(0.5) + np.linspace(-0.2, 0.3, problem.dae.n)
    res = [complete(problem.dae, m, lam=l).constraint_residual(0.5, x) for m, l in METHOD_LAMS]
    np.testing.assert_allclose(res[1], res[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res[2], res[0], rtol=1e-12, atol=1e-12)


def test_project_returns_nearest_consistent_point(problem):
    c = complete(problem.dae, "standard")
    t = 0.9
    rng = np.random.default_rng(0)
    x = problem.exact(t) + 0.1 * rng.standard_normal(problem.dae.n)
    y = c.project(t, x)
    assert np.linalg.norm(c.constraint_residual(t, y)) < 1e-10
    # nearest: the correction is orthogonal to the manifold's tangent space
    T2 = scipy.linalg.null_space(c.maps(t).C[0])  # the manifold's tangent space
    np.testing.assert_allclose(T2.T @ (x - y), 0, atol=1e-10)
    # projecting twice changes nothing
    np.testing.assert_allclose(c.project(t, y), y, atol=1e-12)


@pytest.mark.parametrize("name", ["chain3", "pencil-3-2", "mechanical"])
def test_theorem5_extra_differentiations_leave_standard_unchanged(name):
    from tests.support.problems import CONSTANT_PROBLEMS

    p = CONSTANT_PROBLEMS[name]()
    base = complete(p.dae, "standard")
    for extra in (1, 2):
        more = complete(p.dae, "standard", k=base.k + extra)
        for t in (0.0, 1.7):
            G0, g0 = base.matrices(t)
            G1, g1 = more.matrices(t)
            np.testing.assert_allclose(G1, G0, rtol=1e-9, atol=1e-9 * np.abs(G0).max())
            np.testing.assert_allclose(g1, g0, rtol=1e-9, atol=1e-9 * (1 + np.abs(g0).max()))


def test_theorem6_orthogonal_P_and_similarity_Q():
    p = gallery.random_pencil(n=9, blocks=(3, 2), seed=7)
    A, B = p.dae.A(0.0), p.dae.B(0.0)
    rng = np.random.default_rng(1)
    P = np.linalg.qr(rng.standard_normal((9, 9)))[0]
    Q = rng.standard_normal((9, 9)) + 3 * np.eye(9)
    G = complete(LinearDAE(A, B), "standard").matrices(0.0)[0]
    G_P = complete(LinearDAE(P @ A, P @ B), "standard").matrices(0.0)[0]
    np.testing.assert_allclose(G_P, G, rtol=1e-9, atol=1e-9 * np.abs(G).max())
    G_PQ = complete(LinearDAE(P @ A @ Q, P @ B @ Q), "standard").matrices(0.0)[0]
    np.testing.assert_allclose(G_PQ, np.linalg.solve(Q, G @ Q), rtol=1e-8, atol=1e-8 * np.abs(G_PQ).max())
    # A non-orthogonal left factor does change the LSC (the theorem needs P orthogonal).
    S = np.diag(np.linspace(1, 5, 9))
    G_S = complete(LinearDAE(S @ A, S @ B), "standard").matrices(0.0)[0]
    assert np.abs(G_S - G).max() > 1e-3


def test_k_below_index_is_refused():
    p = gallery.nilpotent_chain(3)
    with pytest.raises(IndexDeterminationError, match="`k`=2 is too small"):
        complete(p.dae, "standard", k=2)


def test_constant_forcing_and_no_forcing():
    A, B = np.eye(3, k=1), np.eye(3)
    for f in (None, [1.0, 2.0, 3.0]):
        c = complete(LinearDAE(A, B, f), "alternative", lam=1.0)
        x_star = np.zeros(3) if f is None else np.linalg.solve(B, f)  # N x' + x = const -> x = const
        np.testing.assert_allclose(c.rhs(0.3, x_star), 0, atol=1e-13)
        np.testing.assert_allclose(c.constraint_residual(0.3, x_star), 0, atol=1e-13)


def test_callable_and_sympy_forcing_agree():
    import sympy

    t = sympy.Symbol("t")
    A, B = np.eye(3, k=1), np.eye(3)
    expr = [sympy.sin(t), sympy.cos(2 * t), t**3]
    derivs = [sympy.lambdify(t, [sympy.diff(e, t, d) for e in expr]) for d in range(5)]
    c1 = complete(LinearDAE(A, B, expr), "stabilized", lam=1.5)
    c2 = complete(LinearDAE(A, B, lambda s, d: np.array(derivs[d](s), dtype=float)), "stabilized", lam=1.5)
    np.testing.assert_allclose(c2.matrices(0.8)[1], c1.matrices(0.8)[1], rtol=1e-13)
