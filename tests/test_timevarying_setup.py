"""The time-varying set-up's warm-started LU of J against the SVD at every time.

`lsc._dense_factors._Factors._warm` replaces the SVD of the standard derivative
array by one LU warm-started from the null spaces at the last time; these
tests pin that its completion equals the SVD path's (all three methods), that
it is actually taken, that its rank checks fall back to the SVD (and so keep
the SVD path's refusals), and that a run against an exact solution is unchanged.
"""

import numpy as np
import pytest

import lsc
from lsc import gallery

METHODS = [("standard", None), ("stabilized", 2.0), ("alternative", 1.0)]


@pytest.fixture(scope="module")
def pencil():
    return gallery.moving_pencil(n=30, blocks=(3, 2), seed=1)  # J has 120 rows: the warm path applies


@pytest.mark.parametrize("method, lam", METHODS)
def test_warm_equals_svd(pencil, method, lam):
    warm = lsc.complete(pencil.dae, method, lam=lam)
    dense = lsc.complete(pencil.dae, method, lam=lam)
    dense.warm_start = False
    used = 0
    for t in np.linspace(*pencil.t_span, 6):
        Gw, gw = warm.matrices(t)
        Gd, gd = dense.matrices(t)
        used += warm._cache[float(t)][0].warm
        assert not dense._cache[float(t)][0].warm
        np.testing.assert_allclose(Gw, Gd, rtol=0, atol=1e-10 * np.abs(Gd).max())
        np.testing.assert_allclose(gw, gd, rtol=0, atol=1e-10 * max(np.abs(gd).max(), 1.0))
        x = pencil.exact(t)
        np.testing.assert_allclose(warm.constraint_residual(t, x), dense.constraint_residual(t, x), atol=1e-10)
    assert used == 5  # every time after the first


def _against_svd(pencil, c, t):
    d = lsc.complete(pencil.dae, "alternative", lam=1.0)
    d.warm_start = False
    (G, g), (Gd, gd) = c.matrices(t), d.matrices(t)
    np.testing.assert_allclose(G, Gd, rtol=0, atol=1e-10 * np.abs(Gd).max())
    np.testing.assert_allclose(g, gd, rtol=0, atol=1e-10 * max(np.abs(gd).max(), 1.0))


def test_any_regular_reference_gives_the_same_completion(pencil):
    # range(M^-1 Z2_ref) is the new null space exactly whenever M is regular, however far the reference
    c = lsc.complete(pencil.dae, "alternative", lam=1.0)
    c.matrices(0.1)
    c._last_factors.N = np.roll(c._last_factors.N, 7, axis=0)
    _against_svd(pencil, c, 0.2)
    assert c._cache[0.2][0].warm


def test_singular_warm_start_falls_back_to_svd(pencil):
    from lsc._derivative_array import array_jets

    c = lsc.complete(pencil.dae, "alternative", lam=1.0)
    c.matrices(0.1)
    ref = c._last_factors
    J = array_jets(c._eq, c.k, 0.2, None, 1).J[0]
    # a right basis orthogonal to J's null space at 0.2: M = J + s Z2 N^T is singular there
    ref.N = np.linalg.svd(J)[2][: ref.N.shape[1]].T
    _against_svd(pencil, c, 0.2)
    assert not c._cache[0.2][0].warm


def test_small_arrays_keep_the_svd():
    p = gallery.rotating_canonical(3)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    c.matrices(0.1), c.matrices(0.2)
    assert c._last_factors is None and not c._cache[0.2][0].warm


def test_run_against_exact_solution(pencil):
    c = lsc.complete(pencil.dae, "alternative", lam=1.0)
    t_eval = np.linspace(*pencil.t_span, 11)
    res = lsc.solve_completion(c, pencil.t_span, pencil.x0, method="DOP853", t_eval=t_eval, rtol=1e-10, atol=1e-12)
    assert res.success
    X = pencil.exact(t_eval)
    assert np.max(np.abs(res.x - X) / (1 + np.abs(X))) < 1e-7
