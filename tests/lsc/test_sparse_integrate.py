"""Integrating sparse completions: Rodas4 with sparse step solves, explicit methods through the operator."""
import numpy as np
import pytest

import lsc
from lsc import gallery
from lsc._sparse_integrate import Rodas4


def _rel_err(res, p):
    return np.abs(res.x - p.exact(res.t)).max() / np.abs(p.exact(res.t)).max()


def test_stiff_stokes_auto_takes_rodas4():
    p = gallery.stokes_ind2(8)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    res = lsc.solve_completion(c, p.t_span, p.x0, rtol=1e-6, atol=1e-8, t_eval=np.linspace(0, 1, 11))
    assert res.success and res.method == "Rodas4" and "method='auto' chose 'Rodas4'" in res.message
    assert _rel_err(res, p) < 1e-5
    assert 1 <= res.nlu < 12  # factorizations reused across steps
    scale = abs(c.structure.C).sum(axis=1).max() * np.abs(res.x).max()  # the rows hold 1/h^3 entries
    assert res.residual.max() < 1e-6 * scale


def test_non_stiff_chain_auto_takes_dop853():
    p = gallery.msd_ind3(30)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    res = lsc.solve_completion(c, p.t_span, p.x0, rtol=1e-8, atol=1e-10)
    assert res.success and res.method == "DOP853" and "method='auto' chose 'DOP853'" in res.message
    assert _rel_err(res, p) < 1e-6


def test_constraint_residual_decays_like_exp_minus_lam_t():
    """From an inconsistent start every constraint row decays by exp(-lam) per unit time, within 2 %."""
    p = gallery.msd_ind3(40)
    lam = 1.5
    c = lsc.complete(p.dae, "alternative", lam=lam)
    x0 = p.x0 + 0.1 * np.random.default_rng(0).standard_normal(p.dae.n)
    res = lsc.solve_completion(c, (0.0, 1.0), x0, rtol=1e-8, atol=1e-10, t_eval=[0.0, 1.0])
    r0, r1 = c.constraint_residual(0.0, res.x[:, 0]), c.constraint_residual(1.0, res.x[:, 1])
    np.testing.assert_allclose(r1 / r0, np.exp(-lam), rtol=0.02)
    np.testing.assert_allclose(np.linalg.norm(r1) / np.linalg.norm(r0), np.exp(-lam), rtol=1e-5)


def test_rodas4_is_fourth_order():
    """Fixed steps (max_step = first_step on the step-size grid, tolerances that accept every step): the error
    falls like h^4."""
    p = gallery.msd_ind3(10, t_span=(0.0, 2.0))
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    errs = []
    for k in (3, 4, 5):
        h = 2.0 ** -k
        res = lsc.solve_completion(c, p.t_span, p.x0, method="Rodas4", first_step=h, max_step=h, rtol=1e3, atol=1e3)
        assert res.t.size == 2 ** (k + 1) + 1
        errs.append(np.abs(res.x[:, -1] - p.exact(p.t_span[1])).max())
    slopes = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(slopes > 3.6), slopes


def test_dense_output_and_t_eval():
    p = gallery.stokes_ind2(6)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    res = lsc.solve_completion(c, p.t_span, p.x0, method="Rodas4", rtol=1e-7, atol=1e-9, dense_output=True)
    mid = 0.5 * (res.t[1:] + res.t[:-1])
    assert np.abs(res.sol(mid) - p.exact(mid)).max() < 1e-5 * np.abs(p.exact(mid)).max()
    te = np.linspace(0.1, 0.9, 5)
    res2 = lsc.solve_completion(c, p.t_span, p.x0, method="Rodas4", rtol=1e-7, atol=1e-9, t_eval=te)
    np.testing.assert_array_equal(res2.t, te)
    assert np.abs(res2.x - p.exact(te)).max() < 1e-5 * np.abs(p.exact(te)).max()


def test_failing_forcing_gives_success_false_with_the_partial_run():
    p = gallery.stokes_ind2(4)
    f = p.dae.f.fn

    def u(t, d):
        if t > 0.5:
            raise RuntimeError("sensor lost")
        return f.u(t) if d == 0 else f.u.jet(t, d)[d]

    dae = lsc.LinearDAE(p.dae.A_sparse, p.dae.B_sparse, lsc.InputForcing(f.input_map, u))
    c = lsc.complete(dae, "alternative", lam=1.0)
    for method in ("Rodas4", "RK45"):
        res = lsc.solve_completion(c, p.t_span, p.x0, method=method, rtol=1e-6)
        assert not res.success and "sensor lost" in res.message
        assert res.t.size >= 1 and res.t[-1] <= 0.5


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(method="Radau"), "'Rodas4' is the implicit method"),
    (dict(method="CVODE"), "must be one of"),
    (dict(t_span=(1.0, 0.0)), "runs backward"),
    (dict(rtol=0.0), "rtol"),
])
def test_refusals(kwargs, fragment):
    p = gallery.msd_ind3(5)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    t_span = kwargs.pop("t_span", p.t_span)
    with pytest.raises(ValueError, match=None) as info:
        lsc.solve_completion(c, t_span, p.x0, **kwargs)
    assert fragment in str(info.value)


def test_rodas4_needs_the_completion():
    with pytest.raises(TypeError, match="needs `completion`"):
        Rodas4(lambda t, y: -y, 0.0, np.ones(2), 1.0)


def test_project_start():
    p = gallery.rcl_ladder(10, "voltage")
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    x0 = p.x0 + 0.3
    res = lsc.solve_completion(c, (0.0, 1.0), x0, project=True, rtol=1e-8, atol=1e-10)
    assert res.success and res.residual[0] < 1e-10


def test_auto_judges_stiffness_by_decay_not_magnitude():
    """The triple chain's modes oscillate (-0.2 +- 6.3i): magnitude x length ~ 60-100, decay x length ~ 2;
    an explicit method resolves them at a fraction of Rodas4's cost."""
    p = gallery.triple_chain(6)
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    res = lsc.solve_completion(c, p.t_span, p.x0, rtol=1e-6, atol=1e-9)
    assert res.success and res.method == "DOP853"
    assert _rel_err(res, p) < 1e-4
