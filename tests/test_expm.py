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
