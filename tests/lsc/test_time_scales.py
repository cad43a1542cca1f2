"""Problems written in other time units: a pencil scaled by a time unit, a horizon of microseconds or
one that starts at t = 1e6 are the same problems, and are solved (or refused) as such.

A DAE ``A x' + B x = f`` in the time ``t = s tau`` is ``(A / s) x_tau' + B x = f``: scaling ``A`` by ``s``
(or ``B`` by ``1/s``) is a change of time unit, so ``(s A, B, f(t / s))`` has the exact solution
``x(t / s)``. Its index, its solvability and (to rounding) its solution cannot depend on ``s``.
"""
import warnings

import numpy as np
import pytest
import sympy

from lsc import IndexDeterminationError, LinearDAE, check_solvability, complete, differentiation_index, gallery
from lsc import solve_completion
from lsc._chebyshev import ChebyshevCoefficients
from lsc import JetCallable

T = sympy.Symbol("t")


def time_scaled_pencil(blocks, s, seed=0):
    """``(dae, exact, p)``: `gallery.random_pencil` (n = 10) in the time unit ``s``: ``(s A, B, f(t / s))``."""
    p = gallery.random_pencil(n=10, blocks=blocks, seed=seed)
    f = p.dae.f
    dae = LinearDAE(s * p.dae.A(0.0), p.dae.B(0.0),
                    JetCallable(lambda t, order: f.jet(t / s, order) / s ** np.arange(order + 1)[:, None]))
    return dae, (lambda ts: p.exact(np.asarray(ts) / s)), p


SCALED = [((3,), 1e-2), ((3, 2), 1e-2), ((2,), 1e-3), ((3,), 1e4), ((3, 2), 1e4), ((4, 1), 1e-2), ((3,), 2.0**-20)]


@pytest.mark.parametrize("blocks, s", SCALED, ids=[f"{b}-{s:g}" for b, s in SCALED])
def test_the_index_of_a_time_scaled_pencil_is_the_pencils(blocks, s):
    dae, _, p = time_scaled_pencil(blocks, s)
    assert differentiation_index(dae) == p.index
    assert check_solvability(dae, (0.0, 2.0 * s)).k == p.index


@pytest.mark.parametrize("method", ["standard", "stabilized", "alternative"])
@pytest.mark.parametrize("blocks, s", SCALED, ids=[f"{b}-{s:g}" for b, s in SCALED])
def test_a_time_scaled_pencil_is_solved_like_the_pencil(blocks, s, method):
    """Radau at rtol 1e-10 over two of the pencil's time units: relative error below 1e-7 (it was 0.46 at
    s = 0.01 with a RankDecisionWarning, 'not solvable' at s = 1e4)."""
    dae, exact, p = time_scaled_pencil(blocks, s)
    c = complete(dae, method, lam=None if method == "standard" else 2.0 / s)
    assert c.k == p.index
    ts = np.linspace(0.0, 2.0 * s, 11)
    res = solve_completion(c, (0.0, 2.0 * s), exact(0.0), method="Radau", t_eval=ts, rtol=1e-10, atol=1e-12)
    assert res.success, res.message
    X = exact(ts)
    assert np.abs(res.x - X).max() / np.abs(X).max() < 1e-7
    if method != "standard":  # the added dynamics decay at lam (in the given unit), whatever the unit
        assert c.added_eigenvalue == pytest.approx(-2.0 / s)


def test_a_time_scaled_pencil_has_the_pencils_completion():
    """The alternative completion is exactly invariant under a change of time unit: ``G_s = G / s``."""
    p = gallery.random_pencil(n=10, blocks=(3,), seed=0)
    G = complete(p.dae, "alternative", lam=2.0).matrices(0.0)[0]
    for s in (2.0**-7, 1e-2, 1e4):
        Gs = complete(LinearDAE(s * p.dae.A(0.0), p.dae.B(0.0)), "alternative", lam=2.0 / s).matrices(0.0)[0]
        assert np.abs(Gs * s - G).max() <= 1e-9 * np.abs(G).max()


# -- time-varying: Rot2 (index 2, a constraint that rotates) ------------------------------------------
ROT2_A = sympy.Matrix([[1, 0, 0], [0, 1, 0], [0, 0, 0]])
ROT2_B = sympy.Matrix([[0, 0, -sympy.cos(T)], [0, 0, -sympy.sin(T)], [sympy.cos(T), sympy.sin(T), 0]])
ROT2_X = sympy.Matrix([sympy.cos(2 * T) + 1, sympy.sin(T), sympy.exp(-T / 4)])


def rot2(eps=1.0):
    """Rot2 in the time unit `eps`: ``(eps A(t/eps), B(t/eps), f(t/eps))``, exact ``x(t/eps)``."""
    sub = {T: T / eps}
    f = ROT2_A * ROT2_X.diff(T) + ROT2_B * ROT2_X
    dae = LinearDAE(eps * ROT2_A.subs(sub), ROT2_B.subs(sub), f.subs(sub))
    x = sympy.lambdify(T, ROT2_X.subs(sub), "numpy")
    return dae, lambda ts: np.array([np.array(x(s), dtype=float).ravel() for s in np.atleast_1d(ts)]).T


@pytest.mark.parametrize("eps", [1e-6, 1e-3, 1e3])
def test_a_time_scaled_time_varying_problem_is_solved(eps):
    """On [0, 2 eps] it is Rot2 on [0, 2] (refused as 'not solvable' at eps = 1e-6 and 1e-3)."""
    dae, exact = rot2(eps)
    span = (0.0, 2.0 * eps)
    assert check_solvability(dae, span).k == 2
    c = complete(dae, "alternative", lam=2.0 / eps, t_span=span)
    ts = np.linspace(*span, 11)
    res = solve_completion(c, span, exact(0.0)[:, 0], method="DOP853", t_eval=ts, rtol=1e-10, atol=1e-12)
    assert res.success, res.message
    assert np.abs(res.x - exact(ts)).max() < 1e-8


def _noise_free_evaluations():
    dae, _ = rot2()
    return ChebyshevCoefficients(complete(dae, "alternative", lam=2.0, t_span=(0.0, 2.0)), (0.0, 2.0), 1e-12).evaluations


@pytest.mark.parametrize("t0", [1e5, 1e6, 1e8])
def test_a_late_start_costs_what_an_early_one_does(t0):
    """The same coefficients on [t0, t0 + 2]: time itself is known to eps t0 there, so the interpolant is
    asked no more than that (relative to the horizon's length); it was degree 128 at 1e5, pointwise (553
    evaluations) at 1e6 and 236 s at 1e8. The solution keeps its accuracy (to the time's rounding)."""
    dae, exact = rot2()
    span = (t0, t0 + 2.0)
    c = complete(dae, "alternative", lam=2.0, t_span=span)
    cheb = ChebyshevCoefficients(c, span, 1e-12)
    assert all(d is not None for _, _, d in cheb.pieces), cheb.describe()
    assert cheb.evaluations <= 2 * _noise_free_evaluations(), cheb.describe()
    ts = np.linspace(*span, 7)
    res = solve_completion(c, span, exact(t0)[:, 0], method="DOP853", t_eval=ts, rtol=1e-10, atol=1e-12)
    assert res.success, res.message
    assert np.abs(res.x - exact(ts)).max() < 1e-9 + 1e3 * np.finfo(float).eps * t0
