"""The compiled forcing of constant-coefficient completions (lsc._g) against the jet path."""

import numpy as np
import pytest
import sympy

from lsc import LinearDAE, complete, gallery

t = sympy.Symbol("t")


def _dae():
    p = gallery.random_pencil(n=6, blocks=(3, 2), seed=2)
    f = [sympy.sin(2 * t), 0, sympy.exp(-t / 3) * sympy.cos(t), 1 / (2 + sympy.sin(t)), t**2, sympy.sqrt(1 + t**2)]
    return LinearDAE(p.dae.A(0.0), p.dae.B(0.0), f)


@pytest.mark.parametrize("method, lam", [("standard", None), ("stabilized", 3.0), ("alternative", 1.0)])
def test_compiled_forcing_matches_the_jet_path(method, lam):
    dae = _dae()
    c = complete(dae, method, lam=lam)
    p, n = c.order, c.n
    G, W = c.maps().G[0], c.maps().W[0]
    ts = np.linspace(-1.0, 4.0, 23)
    x = np.linspace(-1.0, 1.0, n)
    for s in ts:
        jet = W @ dae.f.jet(s, p).reshape(-1)
        scale = 1.0 + np.abs(jet).max()
        np.testing.assert_allclose(c.rhs(s, x), G @ x + jet, rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(c.matrices(s)[1], jet, rtol=0, atol=1e-13 * scale)
    q = 4
    jets = c._g.jets(ts, q)
    assert jets.shape == (q + 1, n, ts.size)
    for i, s in enumerate(ts):
        fj = dae.f.jet(s, p + q)
        for j in range(q + 1):
            ref = W @ fj[j : j + p + 1].reshape(-1)
            np.testing.assert_allclose(jets[j, :, i], ref, rtol=0, atol=1e-13 * (1.0 + np.abs(ref).max()))


def test_compiled_forcing_uses_only_the_derivatives_W_needs():
    dae = _dae()
    c = complete(dae, "alternative", lam=1.0)
    used, W = c._g._cols0, c.maps().W[0]
    # the zero component of f and columns W does not touch are never compiled
    assert np.all(np.any(W[:, used] != 0.0, axis=0))
    assert not np.any(used % dae.n == 1)
    assert used.size < W.shape[1]


def test_compiled_forcing_reports_non_finite_values():
    dae = LinearDAE(np.eye(2, k=1), np.eye(2), [0, 1 / (1 - t)])
    c = complete(dae, "alternative", lam=1.0)
    c.rhs(0.5, np.zeros(2))
    with pytest.raises(ValueError, match="cannot be evaluated at t=1.0.*ZeroDivisionError"):
        c.rhs(1.0, np.zeros(2))
    with pytest.raises(ValueError, match="not finite"):
        c._g.jets(np.array([0.0, 1.0]), 2)


def test_expm_evaluates_a_jet_forcing_over_arrays_of_times():
    from lsc import solve_completion
    from lsc import JetCallable

    calls = []

    def jet(t, order):  # x1 = sin t through an index-2 chain; accepts a scalar or an array of times
        calls.append(np.ndim(t))
        t = np.asarray(t, dtype=float)
        d = np.arange(order + 1).reshape((-1,) + (1,) * t.ndim)
        s = np.sin(t + d * np.pi / 2)
        return np.stack([np.zeros_like(s), s], axis=1)  # (order + 1, 2) or (order + 1, 2, m)

    dae = LinearDAE(np.eye(2, k=1), np.eye(2), JetCallable(jet))
    c = complete(dae, "alternative", lam=1.0)
    ts = np.linspace(0.0, 10.0, 51)
    calls.clear()
    res = solve_completion(c, (0.0, 10.0), np.array([-1.0, 0.0]), method="expm", t_eval=ts, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(res.x[1], np.sin(ts), atol=1e-7)
    np.testing.assert_allclose(res.x[0], -np.cos(ts), atol=1e-7)
    # one call per array of times (the step-size sampling, the step starts), not one per time
    assert len(calls) <= 10, f"{len(calls)} calls, {calls.count(0)} of them with a single time"
