"""Chebyshev interpolation of a time-varying completion's G(t), g(t) (solve_completion's `interpolate`)."""
import numpy as np
import pytest

from lsc import LinearDAE, complete, gallery, solve_completion
from lsc._chebyshev import ChebyshevCoefficients


def _off_node_times(t_span, m=157):
    a, b = t_span
    return a + (b - a) * (np.arange(1, m) + 0.37) / m  # irrational-ish offsets: never a Chebyshev point


_PROBLEMS = {
    "rotating3": lambda: gallery.rotating_canonical(3), "stiff_index1": lambda: gallery.stiff_index1(100.0),
    "moving_pencil": lambda: gallery.moving_pencil(8), "thesis1": gallery.thesis_example1,
    "thesis4": gallery.thesis_example4, "thesis5": gallery.thesis_example5,
}


def _largest_errors(c, cheb, t_span):
    """Largest errors of the interpolant against pointwise evaluation, relative to the documented scales."""
    errors_G, errors_g, scale_G, scale_g = [], [], 1.0 / (t_span[1] - t_span[0]), 0.0
    for t in _off_node_times(t_span):
        G, g = c.matrices(t)
        Gi, gi = cheb.matrices(t)
        errors_G.append(np.abs(Gi - G).max())
        errors_g.append(np.abs(gi - g).max())
        scale_G, scale_g = max(scale_G, np.abs(G).max()), max(scale_g, np.abs(g).max())
    return max(errors_G) / scale_G, max(errors_g) / scale_g if scale_g else max(errors_g)


@pytest.mark.parametrize("name", list(_PROBLEMS))
@pytest.mark.parametrize("method, lam", [("standard", None), ("stabilized", 2.0), ("alternative", 1.0)])
@pytest.mark.parametrize("tol", [1e-6, 1e-10])
def test_interpolant_meets_its_tolerance(name, method, lam, tol):
    p = _PROBLEMS[name]()
    c = complete(p.dae, method, lam=lam, t_span=p.t_span)
    cheb = ChebyshevCoefficients(c, p.t_span, tol)
    error_G, error_g = _largest_errors(c, cheb, p.t_span)
    # Relative to the scales, as documented (G's at least 1 / length); 10x for the tail-coefficient
    # estimate and the ~1e-12 rounding noise of the pointwise evaluation itself (measured: at most 3e-11).
    assert error_G <= max(10 * tol, 1e-10)
    assert error_g <= max(10 * tol, 1e-10)
    assert all(degree is not None for _, _, degree in cheb.pieces), cheb.pieces  # smooth: nothing pointwise


@pytest.mark.parametrize("tol", [1e-7, 1e-9, 1e-12])
def test_rotating_canonical_in_fewer_evaluations_at_its_tolerance(tol):
    # The coefficients decay geometrically (about 0.12 decades per degree on the whole interval) and
    # need degree 73 at 1e-7, 94 at 1e-9, 127 at 1e-12: doubling 8, 16, ..., 128 took 129 values at
    # the first two and 319 at the last (128 failed, then each half); the degree predicted from the
    # decay takes a multiple of 32 (96 at 1e-7) or pieces sized for it.
    p = gallery.rotating_canonical(3)
    c = complete(p.dae, "alternative", lam=1.0)
    cheb = ChebyshevCoefficients(c, p.t_span, tol)
    assert cheb.evaluations <= {1e-7: 104, 1e-9: 129, 1e-12: 240}[tol], cheb.pieces
    error_G, error_g = _largest_errors(c, cheb, p.t_span)
    assert error_G <= max(10 * tol, 1e-10) and error_g <= max(10 * tol, 1e-10)


def test_a_vanishing_G_is_judged_against_a_rate_not_its_rounding():
    # thesis example 4, stabilized with lam = 2: G = -(lam - 2) = 0, computed as ~1e-17. Relative to
    # its own largest entry that rounding never converges (every piece was left pointwise, 510
    # evaluations); relative to 1 / length it is resolved at once.
    p = gallery.thesis_example4()
    c = complete(p.dae, "stabilized", lam=2.0, t_span=p.t_span)
    cheb = ChebyshevCoefficients(c, p.t_span, 1e-9)
    assert cheb.evaluations <= 33 and all(degree is not None for _, _, degree in cheb.pieces), cheb.pieces
    res = solve_completion(c, p.t_span, p.x0, method="Radau", t_eval=np.linspace(*p.t_span, 11), rtol=1e-8,
                           atol=1e-10)
    assert res.success and "pointwise" not in res.message, res.message
    exact = p.exact(res.t)
    np.testing.assert_allclose(res.x, exact, rtol=0, atol=1e-6 * (1 + np.abs(exact).max()))


@pytest.mark.parametrize("name", ["rotating3", "stiff_index1", "moving_pencil"])
@pytest.mark.parametrize("solver", ["DOP853", "Radau"])
def test_default_interpolation_keeps_the_pointwise_runs_error(name, solver):
    # interpolate=None interpolates to 1e-3 rtol: the run's error against the exact solution is that
    # of the run evaluating the completion at every stage (to 10% and 1e-2 rtol). At 1e-2 rtol it is
    # not: DOP853 on stiff_index1 (stability-limited steps) reaches 1.4e-3 at rtol 1e-4, not 3.5e-4.
    p = _PROBLEMS[name]()
    c = complete(p.dae, "alternative", lam=1.0, t_span=p.t_span)
    ts = np.linspace(*p.t_span, 21)
    exact = p.exact(ts)
    for rtol in (1e-4, 1e-6, 1e-8):
        errors = {}
        for flag in (None, False):
            res = solve_completion(c, p.t_span, p.x0, method=solver, t_eval=ts, rtol=rtol, atol=1e-2 * rtol,
                                   interpolate=flag)
            assert res.success, res.message
            errors[flag] = np.max(np.abs(res.x - exact) / (1 + np.abs(exact)))
            assert (f"interpolated to {1e-3 * rtol:.0e}" in res.message) == (flag is None), res.message
        assert errors[None] <= 1.1 * errors[False] + 1e-2 * rtol, (rtol, errors)


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
