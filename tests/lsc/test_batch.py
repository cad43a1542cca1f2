"""The stacked evaluation of a time-varying completion (lsc._setup.factors_many) equals the per-time path."""

import warnings

import numpy as np
import pytest

import lsc
from lsc import gallery
from lsc import JetCallable
from lsc._chebyshev import ChebyshevCoefficients, EvaluationFailed
from lsc._setup import stackable as batchable, stacked


def matrices_many(c, ts):
    """``[(G, g) or None]``: the times the stacked factors decide."""
    return [None if r is None else (r[0], r[1][:, 0]) for r in stacked(c, ts)]


def _problems():
    return ([gallery.rotating_canonical(i) for i in (1, 2, 3, 4)] + [gallery.moving_pencil(n) for n in (10, 20)]
            + [gallery.stiff_index1()] + [getattr(gallery, f"thesis_example{i}")() for i in (1, 3, 4, 5)])


@pytest.mark.parametrize("method", ["standard", "stabilized", "alternative"])
@pytest.mark.parametrize("index", range(11))
def test_stacked_equals_per_time(method, index):
    p = _problems()[index]
    c = lsc.complete(p.dae, method, lam=None if method == "standard" else 1.0, t_span=p.t_span)
    a, b = p.t_span
    ts = [float(t) for t in a + (b - a) * np.random.default_rng(index).random(17)]
    many = matrices_many(c, ts)
    assert (sum(r is not None for r in many) == len(ts)) == batchable(c)
    for t, res in zip(ts, many):
        if res is None:
            continue
        c._cache.clear()
        G, g = c.matrices(t)
        assert np.abs(res[0] - G).max() <= 1e-12 * np.abs(G).max()
        assert np.abs(res[1] - g).max() <= 1e-12 * max(np.abs(g).max(), 1e-300)


def test_stacked_path_taken_on_rotating_canonical():
    # n = 6, k = 3: 24 rows, under WARM_MIN_ROWS: all three completions are stacked; 120 rows are not
    p = gallery.rotating_canonical(3)
    assert batchable(lsc.complete(p.dae, "alternative", lam=1.0))
    assert batchable(lsc.complete(p.dae, "standard"))
    assert batchable(lsc.complete(p.dae, "stabilized", lam=1.0))
    q = gallery.moving_pencil(n=30, blocks=(3, 2), seed=1)
    assert not batchable(lsc.complete(q.dae, "alternative", lam=1.0, k=3))


def test_interpolant_unchanged_by_stacking(monkeypatch):
    p = gallery.rotating_canonical(3)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    fast = ChebyshevCoefficients(c, p.t_span, 1e-8)
    monkeypatch.setattr("lsc._setup.stackable", lambda comp: False)
    slow = ChebyshevCoefficients(c, p.t_span, 1e-8)
    assert fast.evaluations == slow.evaluations and fast.pieces == slow.pieces
    for t in np.linspace(*p.t_span, 23):
        G1, g1 = fast.matrices(t)
        G2, g2 = slow.matrices(t)
        assert np.abs(G1 - G2).max() <= 1e-12 * np.abs(G2).max()
        assert np.abs(g1 - g2).max() <= 1e-12 * np.abs(g2).max()


def test_rank_change_left_to_per_time_path():
    # a rank other than the completion's: no time is stacked, and the per-time path refuses (as without stacking)
    p = gallery.rotating_canonical(3)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    c._rank += 1
    assert matrices_many(c, [0.5, 1.0, 1.5]) == [None, None, None]
    with pytest.raises(lsc.IndexDeterminationError, match="changes at t=1.0"):
        c.matrices(1.0)
    with pytest.raises(EvaluationFailed, match="changes at t=5.0"):  # the first Chebyshev point, as unstacked
        ChebyshevCoefficients(c, p.t_span, 1e-6)


def test_failing_coefficient_left_to_per_time_path():
    # f not finite from t = 2.5 on: the other times are stacked, the failing one is refused by the per-time path
    p = gallery.rotating_canonical(3)
    inner = p.dae.f.fn

    def f_jet(t, order):
        out = inner.jet(t, order)
        return out * np.nan if t >= 2.5 else out

    dae = lsc.LinearDAE(p.dae.A.fn, p.dae.B.fn, JetCallable(f_jet))
    c = lsc.complete(dae, "alternative", lam=1.0)
    ts = [0.5, 1.0, 2.7, 4.0]
    many = matrices_many(c, ts)
    assert [r is None for r in many] == [False, False, True, True]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.allclose(many[1][0], c.matrices(1.0)[0], rtol=1e-12, atol=0)
    with pytest.raises(ValueError, match="non-finite"):
        c.matrices(2.7)


def test_vectorized_ranks_equal_numerical_rank():
    # the stacked rank decisions are numerical_rank's, and every close call (a warning) is left out (-1)
    from lsc._linalg import numerical_rank, ranks_many as _ranks

    rng = np.random.default_rng(3)
    tol = 1e-10  # rcond; relative singular values at, around and far from it
    rows = [np.sort(np.concatenate([[1.0], 10.0 ** rng.uniform(-16, 0, 5), [tol * f]]))[::-1]
            for f in (1e-3, 0.02, 0.5, 2.0, 50.0, 1e3, 1.0)] + [np.zeros(7)]
    s = np.array(rows)
    got = _ranks(s, (7, 7), tol)
    for row, rank in zip(s, got):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            expected = numerical_rank(row, (7, 7), tol)
        if caught or row[0] == 0.0:
            assert rank == -1
        else:
            assert rank == expected
    assert set(got[:6]) > {-1}  # some decisions are clear-cut, some are close calls


def test_a_subclass_with_its_own_maps_is_never_stacked():
    # the stacked formulas are the built-in ones: a subclass overriding `_maps` got them at most Chebyshev points
    # (G off by 3.8 of 7.6) and a run reported success with a final state 9.5 off
    from lsc._chebyshev import ChebyshevCoefficients
    from lsc._completion import StandardCompletion

    class Doubled(StandardCompletion):
        def _maps(self, fac, lam):
            G, g = super()._maps(fac, lam)
            return 2.0 * G, 2.0 * g

    p = gallery.rotating_canonical(3)
    c = Doubled(p.dae)
    assert not batchable(c)
    ch = ChebyshevCoefficients(c, (0.0, 5.0), 1e-9)
    G, g = ch.matrices(1.234)
    G0, g0 = lsc.complete(p.dae, "standard").matrices(1.234)
    np.testing.assert_allclose(G, 2.0 * G0, rtol=1e-8, atol=1e-8 * np.abs(G0).max())
    np.testing.assert_allclose(g, 2.0 * g0, rtol=1e-8, atol=1e-8 * np.abs(g0).max())
