"""Exact stepping with the matrix exponential (`method='expm'`, lsc._expm)."""

import numpy as np
import pytest
import sympy

from lsc import LinearDAE, complete, gallery, solve_completion

t = sympy.Symbol("t")


def _polynomial_chain():
    f = sympy.Matrix([t**2, 1 + t, t**3 / 6])
    N = sympy.Matrix(3, 3, lambda i, j: 1 if j == i + 1 else 0)
    x = sum(((-1) ** i * N**i * f.diff(t, i) for i in range(3)), sympy.zeros(3, 1))
    exact = sympy.lambdify(t, list(x))
    return LinearDAE(np.eye(3, k=1), np.eye(3), list(f)), lambda s: np.array(exact(s), dtype=float)


def test_different_steps_never_share_an_exponential():
    # Output intervals 0.1 and 0.1000003: the propagation is exact for this cubic forcing, so the
    # only error possible is a wrong exponential. Sharing exp(0.1 G) for the second step gives
    # an error of about 3e-7 * |x'|; distinct exponentials give rounding only.
    dae, exact = _polynomial_chain()
    c = complete(dae, "alternative", lam=1.0)
    ts = np.array([0.0, 0.1, 0.2000003, 0.3000003, 0.30000031])
    res = solve_completion(c, (0.0, ts[-1]), exact(0.0), method="expm", t_eval=ts, taylor_degree=3, max_step=1.0)
    np.testing.assert_allclose(res.x, np.array([exact(s) for s in ts]).T, rtol=0, atol=1e-12)


def _manufactured(xs):
    """``A x' + B x = f`` (index 3, one dynamic state) whose solution is the sympy vector `xs`."""
    A = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, 0, 0, 0]], dtype=float)
    B = np.eye(4)
    B[0, 1] = 1.0  # the dynamic state is driven by the chain
    x = sympy.Matrix(xs)
    f = sympy.Matrix(A) * x.diff(t) + sympy.Matrix(B) * x
    exact = sympy.lambdify(t, list(x), "numpy")
    return LinearDAE(A, B, list(f)), lambda s: np.array([np.broadcast_to(v, np.shape(s)) for v in exact(s)], dtype=float)


SMOOTH = [sympy.sin(2 * t), sympy.cos(t) * sympy.exp(-t / 3), sympy.cos(3 * t), sympy.exp(-t)]


@pytest.mark.parametrize("method, lam", [("standard", None), ("stabilized", 2.0), ("alternative", 1.0)])
@pytest.mark.parametrize("tol", [1e-4, 1e-7, 1e-10])
@pytest.mark.parametrize("grid", ["dense", "coarse", "uneven"])
def test_expm_meets_the_requested_tolerance(method, lam, tol, grid):
    # No taylor_degree, no max_step: both chosen from rtol/atol, whatever the output grid.
    dae, exact = _manufactured(SMOOTH)
    c = complete(dae, method, lam=lam)
    T = 10.0
    ts = {"dense": np.linspace(0.0, T, 2001), "coarse": np.linspace(0.0, T, 6),
          "uneven": np.sort(np.r_[0.0, T, np.random.default_rng(0).uniform(0.0, T, 40)])}[grid]
    res = solve_completion(c, (0.0, T), exact(0.0), method="expm", t_eval=ts, rtol=tol, atol=tol)
    X = exact(ts)
    scaled = np.abs(res.x - X) / (tol + tol * np.abs(X))
    assert res.success and scaled.max() < 1.0, (scaled.max(), res.message)
    # the step follows the accuracy asked for, not the grid: a looser tolerance takes fewer steps
    assert "taylor_degree=" in res.message


@pytest.mark.parametrize("q", [2, 5])
def test_expm_given_taylor_degree_gets_its_step_from_the_tolerance(q):
    dae, exact = _manufactured(SMOOTH)
    c = complete(dae, "alternative", lam=1.0)
    ts = np.linspace(0.0, 5.0, 11)
    for tol in (1e-6, 1e-9):
        res = solve_completion(c, (0.0, 5.0), exact(0.0), method="expm", t_eval=ts, rtol=tol, atol=tol,
                               taylor_degree=q)
        X = exact(ts)
        assert np.max(np.abs(res.x - X) / (tol + tol * np.abs(X))) < 1.0
        assert f"taylor_degree={q}" in res.message


def test_expm_steps_fewer_for_looser_tolerances():
    dae, exact = _manufactured(SMOOTH)
    c = complete(dae, "alternative", lam=1.0)
    ts = np.linspace(0.0, 10.0, 2001)
    steps = [int(solve_completion(c, (0.0, 10.0), exact(0.0), method="expm", t_eval=ts, rtol=tol, atol=tol)
                 .message.split(":")[1].split()[0]) for tol in (1e-4, 1e-10)]
    assert steps[0] < steps[1] < 2000, steps


def test_expm_dense_output_takes_one_exponential(monkeypatch):
    import scipy.linalg

    calls = []
    real = scipy.linalg.expm
    monkeypatch.setattr(scipy.linalg, "expm", lambda M: calls.append(M.shape) or real(M))
    dae, exact = _manufactured(SMOOTH)
    c = complete(dae, "alternative", lam=1.0)
    ts = np.linspace(0.0, 10.0, 2001)
    res = solve_completion(c, (0.0, 10.0), exact(0.0), method="expm", t_eval=ts, rtol=1e-9, atol=1e-9)
    assert len(calls) == 1
    assert np.max(np.abs(res.x - exact(ts))) < 1e-8


def test_expm_grid_not_starting_at_t0():
    dae, exact = _manufactured(SMOOTH)
    c = complete(dae, "stabilized", lam=2.0)
    ts = np.linspace(0.37, 4.0, 300)
    res = solve_completion(c, (0.0, 4.0), exact(0.0), method="expm", t_eval=ts, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.x, exact(ts), rtol=0, atol=1e-8)


def test_expm_callable_forcing_vectorized_and_not():
    # The same forcing as a numpy callable (accepts array t) and a math one (does not): same result.
    import math

    dae, exact = _manufactured([sympy.sin(t), sympy.cos(t), sympy.sin(2 * t), sympy.exp(-t)])
    f_sym = sympy.Matrix(dae.f.expr)
    derivs = [sympy.lambdify(t, list(f_sym.diff(t, d)), "numpy") for d in range(12)]
    derivs_math = [sympy.lambdify(t, list(f_sym.diff(t, d)), "math") for d in range(12)]
    A, B = dae.A(0.0), dae.B(0.0)

    def f_numpy(s, d):
        return np.array([np.broadcast_to(v, np.shape(s)) for v in derivs[d](s)], dtype=float)

    def f_math(s, d):
        return [float(v) for v in derivs_math[d](float(s))]

    ts = np.linspace(0.0, 3.0, 101)
    results = []
    for f in (f_numpy, f_math):
        c = complete(LinearDAE(A, B, f), "alternative", lam=1.0)
        results.append(solve_completion(c, (0.0, 3.0), exact(0.0), method="expm", t_eval=ts, rtol=1e-9, atol=1e-9).x)
        assert c._g._callable_vectorizes is (f is f_numpy)
    np.testing.assert_allclose(results[0], results[1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(results[0], exact(ts), rtol=0, atol=1e-8)


@pytest.mark.parametrize("grid", ["default", "uniform", "irregular"])
def test_expm_dense_output_is_the_propagator_from_the_last_step_point(grid):
    """``sol(t)`` steps exactly from the step point before t: as accurate as the output points."""
    dae, exact = _manufactured(SMOOTH)
    c = complete(dae, "alternative", lam=1.0)
    t_eval = {"default": None, "uniform": np.linspace(0.0, 4.0, 9), "irregular": [0.0, 0.3, 2.9, 3.0]}[grid]
    res = solve_completion(c, (0.0, 4.0), exact(0.0), method="expm", t_eval=t_eval, dense_output=True,
                           rtol=1e-10, atol=1e-10)
    ts = np.sort(np.random.default_rng(1).uniform(0.0, 4.0, 25))
    np.testing.assert_allclose(res.sol(ts), exact(ts), rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.sol(res.t), res.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.sol(4.0), exact(4.0), rtol=0, atol=1e-8)
    assert res.sol(1.5).shape == (dae.n,)


def test_expm_dense_output_backward():
    p = gallery.prescribed_path()
    c = complete(p.dae, "standard")
    res = solve_completion(c, (2.0, 0.0), p.exact(2.0), method="expm", dense_output=True, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.sol([1.7, 0.2]), p.exact(np.array([1.7, 0.2])), rtol=0, atol=1e-7)


def test_exact_propagator_on_the_jet_of_f_is_the_step_on_the_jet_of_g():
    # K = Psi Wbig: a step on [f; ...; f^(p+q)] equals the step on g's Taylor jet [g; ...; g^(q)] = Wbig fjet
    from lsc import ExactPropagator

    p = gallery.prescribed_path()
    c = complete(p.dae, "alternative", lam=2.0)
    maps, q, h = c.maps(), 3, 0.07
    fjet = p.dae.f_jet(0.4, maps.order + q).reshape(-1)
    on_f = ExactPropagator(maps.G[0], q, W=maps.W[0])
    Phi, K = on_f.step_matrices(h)
    u = c._g.jets(np.array([0.4]), q).reshape(-1)  # [g; g'; ...; g^(q)] at 0.4 from the compiled forcing
    x = p.exact(0.4) + 0.01
    expected = ExactPropagator(maps.G[0], q).step(x, u, h)
    np.testing.assert_allclose(Phi @ x + K @ fjet, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert on_f.n_exponentials == 1 and on_f.step_matrices(h, cache=False)[0].shape == Phi.shape
