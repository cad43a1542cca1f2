"""examples/bench_peers.py: the peers' runs reproduce exact solutions, and the drift it reports follows theory.

The benchmark's own functions run on small problems with one repeat (no timing is asserted):
each peer must reach the exact solution at a tight tolerance (so a wrong translation of the
DAE, a wrong start of CasADi's reduced DAE or a wrong map back to the original unknowns
fails here), and the constraint drift from a start off the manifold must decay as each
method's theory says: ``exp(-lam t)`` for lsc's alternative completion, the double pole
``(1 + lam t) exp(-lam t)``-type decay for CasADi's Baumgarte correction of a position
constraint, and no decay without it.
"""
import importlib.util
import math

import numpy as np
import pytest

from lsc import gallery

from tests.support import ROOT


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_peers", ROOT / "examples" / "bench_peers.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _needs(bench, what):
    if what == "casadi" and bench.ca is None:
        pytest.skip("casadi is not installed (pip install -e '.[bench]')")
    if what == "ida" and bench.IDA is None:
        pytest.skip("scikit-sundae is not installed (pip install -e '.[cvode]')")


def _wp(bench, section, p, peers):
    return bench.work_precision(section, p, peers, [1e-8], repeats=1)


def test_casadi_reaches_the_exact_solution(bench):
    _needs(bench, "casadi")
    for p in (gallery.prescribed_path(), gallery.mechanical(), gallery.thesis_example1(),
              bench.with_array_forcing(gallery.nilpotent_chain(2))):
        # pole -lam with the algebraic variables out of IDAS's error test: with them in, IDAS misses tol 1e-8 on
        # prescribed_path by 3x (a property of IDAS on the corrected DAE, measured by the benchmark, not asserted here)
        peers = [bench.LscPeer(p), bench.CasadiPeer(p, 0.0), bench.CasadiPeer(p, -bench.LAM, True)]
        assert [pe.index for pe in peers[1:]] == [p.index, p.index]  # Pantelides finds the index
        rows = _wp(bench, "casadi", p, peers)
        assert {r["family"] for r in rows} == {"lsc", "CasADi"}
        for r in rows:
            assert r["success"], r
            # tol 1e-8 (atol 1e-10): every peer within 1e-5 of the exact solution, on the constraints to 1e-6
            assert r["err"] < 1e-5, (p.name, r["family"], r["peer"], r["method"], r["err"])
            assert r["drift_max"] < 1e-6, (p.name, r["family"], r["peer"], r["method"], r["drift_max"])
            assert r["setup"] > 0 and r["time"] > 0


def test_casadi_cannot_reduce_a_mixed_pencil(bench):
    """Pantelides works on the sparsity pattern: a pencil mixed by dense P, Q looks like an implicit ODE to it."""
    _needs(bench, "casadi")
    p = bench.with_array_forcing(gallery.nilpotent_chain(3, seed=0))
    peer = bench.CasadiPeer(p, -bench.LAM)
    assert peer.index == 1  # structural index: 1, the true index is 3
    row = _wp(bench, "casadi", p, [peer])[0]
    assert not (row["success"] and row["err"] < 1e-3), row  # it must not come out as a solved problem


def test_drift_off_the_manifold_follows_each_method(bench):
    """The position constraint e = q1 - q2 - r(t) of `mechanical` after the benchmark's start off the manifold.

    The start moves (q1, q2) by (DELTA, -DELTA), so e(0) = 2 DELTA; CasADi's reduced DAE keeps q' as states
    of their own, started from the exact solution, so e'(0) = 0 there. Theory for e(t):
    lsc's alternative completion ``e(0) exp(-lam t)`` (every constraint decays at lam, no Jordan block);
    CasADi without correction ``e'' = 0``: ``e(0)`` for ever; with ``baumgarte_pole = -lam``, applied twice to a
    constraint differentiated twice, ``(d/dt + lam)^2 e = 0``: ``e(0) (1 + lam t) exp(-lam t)``.
    """
    _needs(bench, "casadi")
    lam = bench.LAM
    p = gallery.mechanical()
    peers = [(bench.LscPeer(p), "expm"), (bench.CasadiPeer(p, 0.0), "IDAS"), (bench.CasadiPeer(p, -lam, True), "IDAS")]
    t = np.linspace(*p.t_span, 201)
    r = p.exact(t)[0] - p.exact(t)[1]
    e0 = 2 * bench.DELTA
    theory = {"lsc": e0 * np.exp(-lam * t), "pole=0": np.full_like(t, e0),
              "pole=-2, suppress_algebraic": e0 * (1 + lam * t) * np.exp(-lam * t)}
    for (peer, method), key in zip(peers, theory):
        x0 = p.x0 + bench.DELTA * (-1.0) ** np.arange(p.dae.n)
        out = peer.run(method, t, x0, 1e-10, 1e-12)
        assert out.success, out.message
        e = out.x[0] - out.x[1] - r
        early = t <= 3.0  # where e is far above the tolerance
        np.testing.assert_allclose(e[early], theory[key][early], rtol=1e-4, atol=1e-9, err_msg=key)
    # the benchmark's own drift rows: the same runs, measured with every constraint
    rows, _ = bench.off_manifold("casadi", p, peers, 1e-10)
    by_peer = {r["peer"]: r for r in rows}
    assert by_peer["pole=0"]["drift_end"] > 0.3 * by_peer["pole=0"]["drift_t0"]  # no decay without the pole
    for key in ("alternative λ=2", "pole=-2, suppress_algebraic"):
        assert by_peer[key]["drift_end"] < 1e-6 * by_peer[key]["drift_t0"], (key, by_peer[key]["drift_end"])


def test_ida_forms_reach_the_exact_solution(bench):
    _needs(bench, "ida")
    for p in (gallery.nilpotent_chain(1, seed=0), gallery.stiff_index1(1000.0), gallery.mechanical(),
              bench.with_array_forcing(gallery.nilpotent_chain(3, seed=0))):
        forms = (["DAE"] if p.index == 1 else []) + (["hand"] if p.state_space is not None else []) + \
            (["completion"] if p.dae.is_constant and p.index > 1 else [])
        peers = [bench.LscPeer(p)] + [bench.IdaPeer(p, form) for form in forms]
        rows = _wp(bench, "ida", p, peers)
        assert {r["peer"] for r in rows if r["family"] == "IDA"} == set(forms)
        for r in rows:
            assert r["success"], r
            assert r["err"] < 1e-5, (p.name, r["family"], r["peer"], r["method"], r["err"])


def test_equal_error_table_picks_the_fastest_run_reaching_each_level(bench):
    rows = [
        {"experiment": "work-precision", "problem": "P", "index": 3, "family": f, "peer": "x", "method": m, "rtol": tol,
         "time": time_, "err": err, "drift_max": 1e-9, "success": True, "load": 1.0}
        for f, m, tol, time_, err in [("lsc", "expm", 1e-6, 1.0, 1e-7), ("lsc", "CVODE", 1e-6, 0.5, 1e-5),
                                      ("CasADi", "IDAS", 1e-6, 2.0, 1e-7), ("CasADi", "IDAS", 1e-4, 0.1, 1e-4)]
    ]
    assert bench.fastest(rows, 1e-6, problem="P", family="lsc")["method"] == "expm"
    assert bench.fastest(rows, 1e-4, problem="P", family="lsc")["method"] == "CVODE"
    lines = bench.equal_error_table(rows, "CasADi", (1e-4, 1e-6, 1e-8))
    assert "| 5 | " in lines[2] and "| 0.5 | " in lines[3]  # 0.5 / 0.1 at 1e-4; 1.0 / 2.0 at 1e-6
    assert len(lines) == 4  # no run reaches 1e-8: no row
