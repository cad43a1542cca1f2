import numpy as np
import pytest

from lsc import complete, differentiation_index, gallery


def test_exact_solution_satisfies_dae(problem):
    for t in np.linspace(*problem.t_span, 9):
        r = problem.dae.residual(t, problem.exact(t), problem.exact(t, 1))
        scale = 1 + np.abs(problem.exact(t)).max() + np.abs(problem.exact(t, 1)).max()
        np.testing.assert_allclose(r, 0, atol=1e-12 * scale * np.abs(problem.dae.A(0)).max())


def test_declared_index(problem):
    assert differentiation_index(problem.dae) == problem.index


def test_x0_is_consistent(problem):
    c = complete(problem.dae, "standard")
    np.testing.assert_allclose(c.constraint_residual(problem.t_span[0], problem.x0), 0, atol=1e-10)


def test_exact_vectorized_matches_pointwise(problem):
    ts = np.linspace(*problem.t_span, 4)
    X = problem.exact(ts, 2)
    assert X.shape == (problem.dae.n, 4)
    for j, t in enumerate(ts):
        np.testing.assert_allclose(X[:, j], problem.exact(t, 2), rtol=1e-14, atol=1e-14)


def test_exact_derivative_is_derivative():
    # Central difference of exact(t) against exact(t, 1): catches a wrong
    # derivative formula in the gallery itself.
    for p in (gallery.random_pencil(n=6, blocks=(2,), seed=3), gallery.mechanical()):
        h, t = 1e-5, 0.7
        fd = (p.exact(t + h) - p.exact(t - h)) / (2 * h)
        np.testing.assert_allclose(fd, p.exact(t, 1), rtol=1e-8, atol=1e-8)


def test_random_pencil_scales():
    p = gallery.random_pencil(n=200, blocks=(4, 3, 3), seed=0)
    assert p.dae.n == 200 and p.index == 4
    assert p.finite_eigenvalues.shape == (190,)


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(n=3, blocks=(3, 2)), "at least sum(blocks)=5"),
    (dict(n=5, blocks=(0,)), "positive chain lengths"),
    (dict(n=6, blocks=(2,), spectrum=[1.0]), "expected (4,)"),
    (dict(n=6, blocks=(2,), spectrum=[1j, 2, 3, 4]), "conjugate pairs"),
])
def test_random_pencil_rejects(kwargs, fragment):
    with pytest.raises(ValueError, match=None) as info:
        gallery.random_pencil(**kwargs)
    assert fragment in str(info.value)


@pytest.mark.parametrize("make", [
    lambda: gallery.nilpotent_chain(1, seed=0), lambda: gallery.nilpotent_chain(4, seed=0),
    lambda: gallery.random_pencil(n=10, blocks=(3, 2)), lambda: gallery.rotating_canonical(3, omega=2.0),
    lambda: gallery.stiff_index1(100.0),
])
def test_state_space_peers_reproduce_the_exact_solution(make):
    # The hand-derived peers of the work-precision benchmark: the reduced ODE
    # integrated tightly gives x*, x* zeroes the index-1 residual, and
    # residual_jac is its derivative (central differences, error ~h^2).
    from scipy.integrate import solve_ivp

    p = make()
    ss = p.state_space
    t = np.linspace(*p.t_span, 11)
    sol = solve_ivp(ss.rhs, p.t_span, ss.y0, t_eval=t, method="Radau", jac=ss.jac, rtol=1e-11, atol=1e-13)
    X = np.array([ss.output(ti, yi) for ti, yi in zip(sol.t, sol.y.T)]).T
    np.testing.assert_allclose(X, p.exact(t), atol=1e-9)
    for ti in t[::3]:
        x, xp = p.exact(ti), p.exact(ti, 1)
        np.testing.assert_allclose(ss.residual(ti, x, xp), 0, atol=1e-12)
        h, cj = 1e-6, 7.0
        fd = np.array([(ss.residual(ti, x + h * e, xp + cj * h * e) - ss.residual(ti, x - h * e, xp - cj * h * e)) / (2 * h)
                       for e in np.eye(p.dae.n)]).T
        np.testing.assert_allclose(fd, ss.residual_jac(ti, x, xp, cj), atol=1e-7 * (1 + np.abs(fd).max()))
