"""Hostile inputs for the structured constant-coefficient set-up: it must equal the dense one or decline.

Each test names the input class; the exact solutions come from manufactured forcing ``f = A x*' + B x*``
(``x*`` sinusoidal), which makes ``x*`` the solution of any regular pencil.
"""
import warnings

import numpy as np
import pytest

from lsc import IndexDeterminationError, LinearDAE, RankDecisionWarning, complete, gallery
from lsc import JetCallable
from lsc.gallery._canonical import _Sinusoids, _conditioned, _real_block, _shift_blocks

from tests.support.problems import METHOD_LAMS


def manufactured(A, B, seed=0):
    """``(dae, exact)``: forcing ``f = A x*' + B x*`` for a sinusoidal ``x*``, its exact solution."""
    n = A.shape[0]
    rng = np.random.default_rng(seed)
    y = _Sinusoids(amp=rng.uniform(0.5, 1.5, n), omega=rng.uniform(0.5, 2.0, n), phase=rng.uniform(0, 6.28, n),
                   offset=rng.uniform(-1, 1, n))

    def f_jet(t, order):
        j = y.jet(t, order + 1)
        return j[1:] @ A.T + j[:-1] @ B.T

    return LinearDAE(A, B, JetCallable(f_jet)), lambda t, d=0: y.jet(t, d)[d]


def weierstrass(n, blocks, seed=0, cond=10.0):
    """``(A, B) = (P E Q^-1, P Ab Q^-1)``, E = diag(I, N) with chains `blocks`, finite eigenvalues in [-2, -0.1]."""
    rng = np.random.default_rng(seed)
    a = sum(blocks)
    d = n - a
    E, Ab = np.zeros((n, n)), np.zeros((n, n))
    E[:d, :d], E[d:, d:] = np.eye(d), _shift_blocks(blocks)
    Ab[:d, :d], Ab[d:, d:] = -_real_block(-rng.uniform(0.1, 2.0, d)), np.eye(a)
    P, Q = _conditioned(rng, n, cond), _conditioned(rng, n, cond)
    Qi = np.linalg.inv(Q)
    return P @ E @ Qi, P @ Ab @ Qi


def quiet_complete(dae, method, lam, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RankDecisionWarning)
        return complete(dae, method, lam=lam, **kw)


def exact_error(c, exact, times=(0.0, 0.7, 2.1)):
    return max(np.linalg.norm(c.rhs(t, exact(t)) - exact(t, 1)) / np.linalg.norm(exact(t, 1)) for t in times)


def assert_as_dense(dae, method, lam, tol=1e-8, **kw):
    """The default set-up gives the dense path's k, constraint count and G (relative `tol`), or refuses as it does."""
    try:
        dense = quiet_complete(dae, method, lam, setup="dense", **kw)
    except IndexDeterminationError:
        with pytest.raises(IndexDeterminationError):
            quiet_complete(dae, method, lam, **kw)
        return None, None
    fast = quiet_complete(dae, method, lam, **kw)
    assert (fast.k, fast.n_constraints) == (dense.k, dense.n_constraints), (fast.setup, fast.setup_note)
    Gf, Gd = fast.maps().G[0], dense.maps().G[0]
    assert np.abs(Gf - Gd).max() <= tol * np.abs(Gd).max(), (fast.setup, fast.setup_note)
    return dense, fast


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
def test_rcond_below_rounding_does_not_make_a_singular_A_invertible(method, lam):
    """rcond = 1e-300: A's rounding-level pivots are not rank; the index-3 pencil is not an ODE (index 0)."""
    p = gallery.random_pencil(n=10, blocks=(3, 2), seed=1)
    assert_as_dense(p.dae, method, lam, rcond=1e-300)


def test_tiny_A_against_B_has_the_dense_index():
    """1e-300 x' + x = f: A's rank is decided against the whole array (as the dense path does), not against A alone."""
    assert_as_dense(LinearDAE([[1e-300]], [[1.0]]), "standard", None)


@pytest.mark.parametrize("scale", [1e-13, 1e-8])
def test_small_A_chain_has_the_dense_index(scale):
    """scale * N x' + x = f, N a 3x3 shift: the dense arrays drop the scale**j terms below rcond; so must the index."""
    assert_as_dense(LinearDAE(scale * np.eye(3, k=1), np.eye(3)), "alternative", 2.0)


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
@pytest.mark.parametrize("scale", [1e-2, 1e2, 1e3])
def test_unbalanced_pencil_is_as_dense_or_as_accurate(scale, method, lam):
    """A scaled by 1e-2 / 1e2 / 1e3 against B (index 3): the dense path's index, refusal, or at least its accuracy."""
    A, B = weierstrass(10, (3, 2), seed=1)
    dae, exact = manufactured(scale * A, B)
    try:
        dense = quiet_complete(dae, method, lam, setup="dense")
    except IndexDeterminationError:
        with pytest.raises(IndexDeterminationError):
            quiet_complete(dae, method, lam)
        return
    fast = quiet_complete(dae, method, lam)
    assert fast.k == dense.k, (fast.setup, fast.setup_note)
    assert exact_error(fast, exact) <= max(10 * exact_error(dense, exact), 1e-10), (fast.setup, fast.setup_note)


@pytest.mark.parametrize("lam", [1e4, 1e5])
def test_stabilized_with_a_large_rate_is_as_accurate_as_dense(lam):
    """lam up to 1e5 on an index-3 pencil: the exact solution's defect grows like lam^2 eps on both set-ups; the
    structured one stays within 10 times the dense one."""
    p = gallery.random_pencil(n=10, blocks=(3, 2), seed=1)
    dense = complete(p.dae, "stabilized", lam=lam, setup="dense")
    fast = complete(p.dae, "stabilized", lam=lam)
    assert fast.setup == "structured"
    assert exact_error(fast, p.exact) <= max(10 * exact_error(dense, p.exact), 1e-10)


@pytest.mark.xfail(strict=True, reason="stabilized LSC at lam = 1e6 (index 3): the residual feedback K is formed "
                   "from D^-T Z2 with entries lam^3; neither set-up keeps the added eigenvalues at -lam")
@pytest.mark.parametrize("setup", ["dense", "auto"])
def test_stabilized_at_lam_1e6_keeps_its_spectrum(setup):
    p = gallery.random_pencil(n=10, blocks=(3, 2), seed=1)
    lam = 1e6
    ev = np.linalg.eigvals(complete(p.dae, "stabilized", lam=lam, setup=setup).maps().G[0])
    added = ev[np.abs(ev + lam) < 1e-2 * lam]
    assert added.size == 5 and np.all(ev.real < 0)


def test_overflowing_scales_refused_as_dense():
    """A = 1e200 N, B = 1e-200 I: B_mu^-1 A overflows; the dense path's refusal (IndexDeterminationError), not a
    LinAlgError from a staircase of infs."""
    dae = LinearDAE(1e200 * np.eye(3, k=1), 1e-200 * np.eye(3))
    with pytest.raises(IndexDeterminationError):
        quiet_complete(dae, "standard", None, setup="dense")
    with pytest.raises(IndexDeterminationError):
        quiet_complete(dae, "standard", None)


def test_finite_eigenvalue_at_the_first_trial_shift():
    """A finite eigenvalue placed exactly at the first trial shift (B + mu A singular there): the next shift
    is taken and the completion equals the dense one."""
    from lsc._linalg import TRIAL_SHIFTS

    lam0 = 1.0
    for _ in range(40):  # fixed point: the shift scales with ||B||_1 / ||A||_1, which moves with the eigenvalue
        p = gallery.random_pencil(n=10, blocks=(3, 2), spectrum=[-0.5, -1.0, -1.5, -2.0, lam0], seed=0)
        A, B = p.dae.A(0.0), p.dae.B(0.0)
        lam0 = TRIAL_SHIFTS[0] * np.linalg.norm(B, 1) / np.linalg.norm(A, 1)
    assert np.min(np.abs(np.linalg.eigvals(B + lam0 * A))) < 1e-12 * np.linalg.norm(B, 1)
    for method, lam in METHOD_LAMS:
        dense, fast = assert_as_dense(p.dae, method, lam, tol=1e-10)
        assert fast.setup == "structured" and abs(fast._factors0.shift - lam0) > 0.1 * abs(lam0)
        assert exact_error(fast, p.exact) < 1e-11


@pytest.mark.parametrize("scale, k", [(0.3, 13), (0.1, 9)])
def test_k_far_above_the_index_on_a_mildly_unbalanced_pencil(scale, k):
    """k = 9 or 13 on an index-3 pencil with ||A|| / ||B|| = 0.07 or 0.2: the dense array with k differentiations
    is scaled by that ratio to the power 2k; the default set-up gives the dense G or refuses with it."""
    A, B = weierstrass(10, (3, 2), seed=1)
    dae, _ = manufactured(scale * A, B)
    assert_as_dense(dae, "alternative", 2.0, k=k)
