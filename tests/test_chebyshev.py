"""Chebyshev interpolation of a time-varying completion's G(t), g(t) (solve_completion's `interpolate`)."""
import numpy as np
import pytest

from lsc import LinearDAE, complete, gallery, solve_completion
from lsc._chebyshev import ChebyshevCoefficients


def _off_node_times(t_span, m=157):
    a, b = t_span
    return a + (b - a) * (np.arange(1, m) + 0.37) / m  # irrational-ish offsets: never a Chebyshev point


@pytest.mark.parametrize("make", [lambda: gallery.rotating_canonical(3), lambda: gallery.stiff_index1(100.0),
                                  lambda: gallery.moving_pencil(8)], ids=["rotating3", "stiff_index1", "moving_pencil"])
@pytest.mark.parametrize("method, lam", [("standard", None), ("stabilized", 2.0), ("alternative", 1.0)])
@pytest.mark.parametrize("tol", [1e-6, 1e-10])
def test_interpolant_meets_its_tolerance(make, method, lam, tol):
    p = make()
    c = complete(p.dae, method, lam=lam)
    cheb = ChebyshevCoefficients(c, p.t_span, tol)
    errors_G, errors_g, scale_G, scale_g = [], [], 0.0, 0.0
    for t in _off_node_times(p.t_span):
        G, g = c.matrices(t)
        Gi, gi = cheb.matrices(t)
        errors_G.append(np.abs(Gi - G).max())
        errors_g.append(np.abs(gi - g).max())
        scale_G, scale_g = max(scale_G, np.abs(G).max()), max(scale_g, np.abs(g).max())
    # Relative to the largest entries, as documented; 10x for the tail-coefficient estimate and
    # the ~1e-12 rounding noise of the pointwise evaluation itself (measured: at most 3e-11 relative).
    assert max(errors_G) <= max(10 * tol, 1e-10) * scale_G
    assert max(errors_g) <= max(10 * tol, 1e-10) * scale_g


def test_interpolated_and_pointwise_runs_agree_with_the_exact_solution():
    p = gallery.rotating_canonical(3)
    c = complete(p.dae, "alternative", lam=1.0)
    ts = np.linspace(*p.t_span, 21)
    runs = {flag: solve_completion(c, p.t_span, p.x0, method="DOP853", t_eval=ts, rtol=1e-10, atol=1e-12,
                                   interpolate=flag) for flag in (None, False)}
    exact = p.exact(ts)
    for flag, res in runs.items():
        assert res.success, res.message
        np.testing.assert_allclose(res.x, exact, rtol=0, atol=1e-8 * (1 + np.abs(exact).max()))
    assert "interpolated to 1e-13" not in runs[None].message  # the accuracy is floored at 1e-12
    assert "interpolated to 1e-12" in runs[None].message and "interpolated" not in runs[False].message
    np.testing.assert_allclose(runs[None].x, runs[False].x, rtol=0, atol=1e-9)


def test_interpolation_costs_fewer_evaluations_than_the_solver_stages():
    # the point of it: the completion (one SVD of the array each) is evaluated at the
    # Chebyshev points only, not at every stage
    p = gallery.rotating_canonical(3)
    c = complete(p.dae, "alternative", lam=1.0)
    calls = []
    matrices = c.matrices
    c.matrices = lambda t: calls.append(t) or matrices(t)
    res = solve_completion(c, p.t_span, p.x0, method="DOP853", rtol=1e-8, atol=1e-10)
    assert res.success
    assert len(calls) < res.nfev / 2, (len(calls), res.nfev)


def _kinked_dae(kink=1.3):
    # x1' = f(t), x2 = x1 with |t - kink| in the forcing: G, g are not smooth at the kink
    def f(t, d):
        value = [abs(t - kink), np.sign(t - kink), 0.0, 0.0, 0.0][d]
        return np.array([value, 0.0])

    def A(t, d):  # constant, but given as a function: the completion is a time-varying one
        return np.diag([1.0, 0.0]) if d == 0 else np.zeros((2, 2))

    return LinearDAE(A, [[0.0, 0.0], [-1.0, 1.0]], f)


def test_a_kink_is_resolved_by_splitting_or_left_pointwise():
    dae = _kinked_dae()
    c = complete(dae, "alternative", lam=1.0)
    cheb = ChebyshevCoefficients(c, (0.0, 3.0), 1e-10)
    assert cheb.evaluations <= 500 + 128 + 1  # the budget (one fit may finish past it)
    assert any(degree is None for _, _, degree in cheb.pieces)  # the kink piece is pointwise
    for t in _off_node_times((0.0, 3.0)):
        np.testing.assert_allclose(cheb.matrices(t)[1], c.matrices(t)[1], rtol=0, atol=1e-9)
    exact = lambda t: 0.5 * (t - 1.3) * np.abs(t - 1.3) - 0.5 * 1.3**2 * -1  # noqa: E731  x1 with x1(0) = 0
    x0 = np.array([exact(0.0)] * 2)
    res = solve_completion(c, (0.0, 3.0), x0, method="DOP853", t_eval=[3.0], rtol=1e-10, atol=1e-12)
    assert res.success and "pointwise" in res.message
    np.testing.assert_allclose(res.x[:, -1], exact(3.0), rtol=1e-8)


@pytest.mark.parametrize("bad", [0.0, 1.5, "yes", -1e-3])
def test_bad_interpolate_is_refused(bad):
    p = gallery.thesis_example3()
    c = complete(p.dae, "alternative", lam=1.0)
    with pytest.raises(ValueError, match="`interpolate` must be None, True, False or a relative accuracy"):
        solve_completion(c, p.t_span, p.x0, interpolate=bad)


def test_bad_interpolate_is_refused_for_every_method():
    # checked before dispatching, so 'expm' (which never interpolates) refuses it too
    p = gallery.nilpotent_chain(2)
    c = complete(p.dae, "alternative", lam=1.0)
    with pytest.raises(ValueError, match="`interpolate` must be None, True, False or a relative accuracy"):
        solve_completion(c, p.t_span, p.x0, method="expm", interpolate=2.0)
