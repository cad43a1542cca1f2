"""`solve_completion(method='CVODE')`: SUNDIALS CVODE through scikit-sundae (optional)."""

import sys

import numpy as np
import pytest
import sympy

from lsc import LinearDAE, complete, gallery, solve_completion

pytest.importorskip("sksundae")


def _scaled_error(res, p, rtol, atol):
    X = p.exact(res.t)
    return np.max(np.abs(res.x - X) / (atol + rtol * np.abs(X)))


@pytest.mark.parametrize("problem", [
    lambda: gallery.nilpotent_chain(3, seed=0),
    lambda: gallery.random_pencil(n=10, blocks=(3, 2), seed=1),
    lambda: gallery.stiff_index1(100.0),
    lambda: gallery.rotating_canonical(3),
])
@pytest.mark.parametrize("rtol", [1e-6, 1e-9])
def test_cvode_against_exact_solutions(problem, rtol):
    p = problem()
    c = complete(p.dae, "alternative", lam=1.0, t_span=None if p.dae.is_constant else p.t_span)
    ts = np.linspace(*p.t_span, 41)
    res = solve_completion(c, p.t_span, p.x0, method="CVODE", t_eval=ts, rtol=rtol, atol=1e-2 * rtol)
    assert res.success, res.message
    np.testing.assert_array_equal(res.t, ts)
    # CVODE controls the local error; its global error is a bounded multiple of the tolerance
    # (measured 160-1060 here, as for IDA on the same problems)
    assert _scaled_error(res, p, rtol, 1e-2 * rtol) < 3000.0


def test_cvode_stiff_completion_large_lam():
    p = gallery.nilpotent_chain(3, seed=0)
    c = complete(p.dae, "alternative", lam=1e6)
    res = solve_completion(c, p.t_span, p.x0, method="CVODE", t_eval=[p.t_span[1]], rtol=1e-8, atol=1e-10)
    assert res.success and res.nfev < 5000, (res.nfev, res.message)  # an explicit method needs ~1e7
    assert np.max(np.abs(res.x[:, -1] - p.exact(p.t_span[1]))) < 1e-5
    assert res.t.tolist() == [p.t_span[1]]


def test_cvode_solver_steps_without_t_eval():
    p = gallery.nilpotent_chain(2, seed=0)
    c = complete(p.dae, "stabilized", lam=2.0)
    res = solve_completion(c, p.t_span, p.x0, method="CVODE", rtol=1e-8, atol=1e-10, cvode_method="Adams")
    assert res.success and res.t[0] == p.t_span[0] and res.t[-1] == p.t_span[1] and res.t.size > 5
    assert _scaled_error(res, p, 1e-8, 1e-10) < 3000.0


def test_cvode_forcing_failure_keeps_the_trajectory():
    t = sympy.Symbol("t")
    dae = LinearDAE(np.eye(2, k=1), np.eye(2), [0, sympy.sqrt(1 - t)])
    c = complete(dae, "alternative", lam=1.0)
    ts = np.linspace(0.0, 2.0, 21)
    res = solve_completion(c, (0.0, 2.0), [0.5, 1.0], method="CVODE", t_eval=ts, interpolate=False)
    assert not res.success and "t=" in res.message
    assert 0 < res.t.size < ts.size and res.t[-1] <= 1.0


def test_cvode_bad_option():
    p = gallery.nilpotent_chain(2, seed=0)
    with pytest.raises(TypeError, match="method='CVODE' takes the options"):
        solve_completion(complete(p.dae, "standard"), p.t_span, p.x0, method="CVODE", dense_output=True)


def test_cvode_missing_package_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "sksundae.cvode", None)
    p = gallery.nilpotent_chain(2, seed=0)
    with pytest.raises(ImportError, match="pip install scikit-sundae"):
        solve_completion(complete(p.dae, "standard"), p.t_span, p.x0, method="CVODE")
