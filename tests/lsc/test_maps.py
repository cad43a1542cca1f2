"""The completion's public contract: `Completion.maps` and `Completion.lam_affine` against its own evaluations.

`maps(t)` must be the completion that `matrices`, `rhs`, `constraint_residual` and `project` evaluate, in the
DAE's own unknowns, equations and time, at one time or many (stacked or not); `lam_affine(t)` must split it
in ``lam`` as completions built at other rates do (independent factorizations).
"""

import numpy as np
import pytest
import sympy

from lsc import JetCallable, LinearDAE, complete, gallery

METHODS = [("standard", None), ("stabilized", 2.0), ("alternative", 1.5)]


def _column_scaled():
    """nilpotent_chain(3) in the unknowns y = x / D with D = 2^-12 on one column: column equilibration is used."""
    p = gallery.nilpotent_chain(3, seed=0)
    D = np.ones(p.dae.n)
    D[1] = 2.0 ** -12
    return LinearDAE(p.dae.A.value * D, p.dae.B.value * D, JetCallable(lambda s, order: p.dae.f_jet(s, order)))


def _time_scaled():
    """random_pencil (index 3) written in microseconds: the completion is computed in its own unit of time."""
    p = gallery.random_pencil(n=10, blocks=(3,), seed=0)
    f, s = p.dae.f, 2.0 ** -20
    return LinearDAE(s * p.dae.A(0.0), p.dae.B(0.0),
                     JetCallable(lambda t, order: f.jet(t / s, order) / s ** np.arange(order + 1)[:, None]))


PROBLEMS = {
    "chain3": (lambda: gallery.nilpotent_chain(3).dae, (0.0, 1.0)),
    "column_scaled": (_column_scaled, (0.0, 1.0)),
    "time_scaled": (_time_scaled, (0.0, 2.0 ** -19)),
    "rotating": (lambda: gallery.rotating_canonical(3).dae, (0.0, 5.0)),
    "moving_pencil_30": (lambda: gallery.moving_pencil(n=30, blocks=(3, 2), seed=1).dae, (0.0, 1.0)),
}


def rel(X, Y):
    return float(np.abs(X - Y).max() / max(np.abs(Y).max(), 1e-300))


@pytest.mark.parametrize("method, lam", METHODS)
@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_maps_are_the_completion_evaluated(name, method, lam):
    make, (a, b) = PROBLEMS[name]
    dae = make()
    if lam is not None and name == "time_scaled":
        lam = lam / 2.0 ** -20  # a rate in the problem's own unit of time
    c = complete(dae, method, lam=lam)
    ts = np.linspace(a, b, 4)
    maps = c.maps(ts)
    assert maps.G.shape == (4, c.n, c.n) and maps.W.shape == (4, c.n, c.n * (c.order + 1))
    assert maps.C.shape == (4, c.n_constraints, c.n) and maps.order == c.order and maps.method == method
    x = np.cos(np.arange(c.n) + 1.0)
    for i, t in enumerate(ts):
        fjet = dae.f_jet(t, c.order).reshape(-1)
        G, g = c.matrices(t)
        assert rel(maps.G[i], G) < 1e-12
        assert rel(maps.forcing(fjet)[i], g) < 1e-11  # (one jet: applied at every time)
        # the constraint basis is unique up to a rotation (two factorizations at one time may differ by one):
        # the residual's norm and the projection do not depend on it
        residual = maps.C[i] @ x - maps.Wc[i] @ fjet
        norm = np.linalg.norm(c.constraint_residual(t, x))
        assert abs(np.linalg.norm(residual) - norm) <= 1e-10 * (1 + norm)
        projected = x - maps.C_pinv[i] @ residual
        assert np.abs(projected - c.project(t, x)).max() <= 1e-9 * (1 + np.abs(x).max())


@pytest.mark.parametrize("method, lam", METHODS)
def test_maps_at_many_times_equal_maps_one_at_a_time(method, lam):
    # rotating_canonical(3): 24 rows, the times are factorized together (stacked SVDs)
    p = gallery.rotating_canonical(3)
    c = complete(p.dae, method, lam=lam)
    ts = np.linspace(*p.t_span, 9)
    many = c.maps(ts)
    for i, t in enumerate(ts):
        one = complete(p.dae, method, lam=lam).maps(t)
        for name in ("G", "W"):
            assert rel(getattr(many, name)[i], getattr(one, name)[0]) < 1e-12, name
        C, Cs = many.C[i], one.C[0]  # the constraint basis is unique up to a rotation
        assert rel(C.T @ C, Cs.T @ Cs) < 1e-12 and rel(C.T @ many.Wc[i], Cs.T @ one.Wc[0]) < 1e-12


@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_lam_affine_splits_the_alternative_completion_as_other_rates_complete_it(name):
    make, (a, b) = PROBLEMS[name]
    dae = make()
    unit = 2.0 ** -20 if name == "time_scaled" else 1.0
    c = complete(dae, "alternative", lam=1.5 / unit)
    ts = np.linspace(a, b, 3)
    split = c.lam_affine(ts)
    assert split.residual < 1e-12
    for rate in (0.05, 3.0, 40.0):
        other = complete(dae, "alternative", lam=rate / unit).maps(ts)
        for M0, M1, M in ((split.G0, split.G1, other.G), (split.W0, split.W1, other.W)):
            assert rel(M0 + rate / unit * M1, M) < 1e-9, rate
    assert rel(split.maps.G, c.maps(ts).G) < 1e-12


def test_lam_affine_of_the_standard_completion_has_no_lam_part():
    c = complete(gallery.nilpotent_chain(3).dae, "standard")
    split = c.lam_affine()
    assert not np.any(split.G1) and not np.any(split.W1) and np.array_equal(split.G0, c.maps().G)


@pytest.mark.parametrize("time_varying", [False, True])
def test_lam_affine_refuses_the_stabilized_completion(time_varying):
    dae = gallery.rotating_canonical(2).dae if time_varying else gallery.nilpotent_chain(3).dae
    c = complete(dae, "stabilized", lam=2.0)
    with pytest.raises(ValueError, match="not affine in lambda"):
        c.lam_affine(0.3)


def test_maps_refuse_times_that_are_not_times():
    c = complete(gallery.nilpotent_chain(2).dae, "alternative", lam=1.0)
    with pytest.raises(ValueError, match="`t` must be finite"):
        c.maps([0.0, np.nan])
    with pytest.raises(TypeError, match="`t` must be a real number"):
        c.maps("0.5")
    with pytest.raises(ValueError, match="1-D"):
        c.maps(np.zeros((2, 2)))


def test_a_time_varying_rate_is_reported_at_each_time():
    t = sympy.Symbol("t")
    c = complete(gallery.nilpotent_chain(2).dae, "alternative", lam=2 + sympy.sin(t))
    maps = c.maps([0.0, 1.0])
    np.testing.assert_allclose(maps.lam, [2.0, 2.0 + np.sin(1.0)], rtol=1e-15)
    split = c.lam_affine([0.0, 1.0])
    np.testing.assert_allclose(split.G0 + maps.lam[:, None, None] * split.G1, maps.G, atol=1e-12)
