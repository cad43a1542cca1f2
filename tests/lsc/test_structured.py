"""The structured constant-coefficient set-up against the dense one (SVDs of the whole derivative array)."""
import tracemalloc
import warnings

import numpy as np
import pytest

from lsc import IndexDeterminationError, LinearDAE, RankDecisionWarning, complete, differentiation_index, gallery
from lsc._derivative_array import array_jets
from lsc._factors import Decline
from lsc._structured import structured_array, structured_index

from tests.support.problems import CONSTANT_PROBLEMS, METHOD_LAMS

# Stated tolerance: the structured and dense set-ups agree to this, relative to the largest entry.
TOL = 1e-10

PENCILS = [(n, blocks, seed) for n, blocks, seed in [
    (5, (3, 2), 0), (6, (1,), 1), (8, (2, 2, 1), 2), (12, (4,), 3), (20, (3, 3, 1, 1), 4), (30, (5, 1), 5),
    (40, (2, 1, 1, 1), 6),
]]


def rel(X, Y):
    return np.abs(X - Y).max() / max(np.abs(X).max(), 1e-300) if X.size else 0.0


def assert_same_setup(dae, method, lam, **kw):
    dense = complete(dae, method, lam=lam, setup="dense", **kw)
    fast = complete(dae, method, lam=lam, **kw)
    assert (dense.setup, fast.setup) == ("dense", "structured"), fast.setup_note
    assert (fast.k, fast.n_constraints, fast._rank) == (dense.k, dense.n_constraints, dense._rank)
    md, mf = dense.maps(), fast.maps()
    assert rel(md.G[0], mf.G[0]) < TOL
    assert rel(md.W[0], mf.W[0]) < TOL
    # The constraint basis is unique up to a rotation: compare what does not depend on it.
    C, Cs = md.C[0], mf.C[0]
    assert rel(C.T @ C, Cs.T @ Cs) < TOL
    assert rel(C.T @ md.Wc[0], Cs.T @ mf.Wc[0]) < TOL
    return dense, fast


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
@pytest.mark.parametrize("name", sorted(CONSTANT_PROBLEMS))
def test_gallery_structured_equals_dense(name, method, lam):
    assert_same_setup(CONSTANT_PROBLEMS[name]().dae, method, lam)


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
@pytest.mark.parametrize("n, blocks, seed", PENCILS)
def test_random_pencils_structured_equals_dense(n, blocks, seed, method, lam):
    p = gallery.random_pencil(n=n, blocks=blocks, seed=seed)
    assert_same_setup(p.dae, method, lam)


@pytest.mark.stress
@pytest.mark.parametrize("method, lam", METHOD_LAMS)
@pytest.mark.parametrize("n, blocks, seed", [(120, (3, 2), 8), (200, (3, 1, 1), 9)])
def test_larger_random_pencils_structured_equals_dense(n, blocks, seed, method, lam):
    p = gallery.random_pencil(n=n, blocks=blocks, seed=seed)
    assert_same_setup(p.dae, method, lam)


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
def test_k_above_index_structured_equals_dense(method, lam):
    p = gallery.random_pencil(n=10, blocks=(2, 1), seed=3)
    assert_same_setup(p.dae, method, lam, k=4)


def test_structured_array_is_what_it_claims():
    """Z2 spans the left null space of J; X J = [I, 0...] makes P the first rows of J^+ (checked on J itself)."""
    p = gallery.random_pencil(n=15, blocks=(3, 1, 1), seed=4)
    s = structured_array(p.dae.A(0.0), p.dae.B(0.0))
    J = array_jets(p.dae, s.k, 0.0).J[0]
    np.testing.assert_allclose(s.Z2.T @ s.Z2, np.eye(s.a), atol=1e-13)
    assert np.abs(s.Z2.T @ J).max() < 1e-12 * np.abs(J).max()
    np.testing.assert_allclose(s.first_rows, np.linalg.pinv(J)[: s.n], atol=1e-11 * np.abs(s.first_rows).max())


@pytest.mark.parametrize("index", range(0, 6))
def test_structured_index_equals_dense_index(index):
    p = gallery.nilpotent_chain(index, seed=index) if index else gallery.random_pencil(n=5, blocks=(), seed=0)
    assert structured_index(p.dae.A(0.0), p.dae.B(0.0)) == differentiation_index(p.dae) == index


def test_singular_pencil_refused_as_before():
    """No shift makes B + mu A invertible: the dense path decides, with its message."""
    dae = LinearDAE([[1.0, 0.0], [0.0, 0.0]], [[1.0, 0.0], [0.0, 0.0]])
    with pytest.raises(Decline, match="singular"):
        structured_array(dae.A(0.0), dae.B(0.0))
    with pytest.raises(IndexDeterminationError, match="singular"):
        complete(dae, "alternative", lam=1.0)


def test_k_below_index_refused_as_before():
    dae = gallery.nilpotent_chain(3).dae
    with pytest.raises(IndexDeterminationError, match="`k`=2 is too small"):
        complete(dae, "standard", k=2)


def test_close_rank_decision_falls_back_to_dense():
    """A singular value of A within the warning margin of the threshold: the structured path does not decide it."""
    delta = 2e-13  # default threshold for A (k = 0, [J F] 3 x 6) is 6 eps 1e3 = 1.3e-12
    dae = LinearDAE(np.diag([1.0, 1.0, delta]), np.eye(3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RankDecisionWarning)
        c = complete(dae, "alternative", lam=1.0)
    assert c.setup == "dense"
    assert "close call" in c.setup_note


def test_setup_keyword_is_checked():
    with pytest.raises(ValueError, match="`setup` must be 'auto' or 'dense'; found 'fast'"):
        complete(gallery.nilpotent_chain(2).dae, "standard", setup="fast")


def test_time_varying_uses_dense_setup():
    c = complete(gallery.moving_pencil(n=6, blocks=(2,)).dae, "alternative", lam=1.0, t_span=(0.0, 0.5))
    assert c.setup == "dense"


def test_exact_solution_and_memory_at_n_300():
    """The exact solution solves the structured completion; no derivative-array-sized ((k+1) n)^2 buffer."""
    n = 300
    p = gallery.random_pencil(n=n, blocks=(3, 2), seed=9)
    tracemalloc.start()
    c = complete(p.dae, "alternative", lam=2.0)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert c.setup == "structured" and c.k == 3
    for t in (0.0, 0.7, 2.1):
        xd = p.exact(t, 1)
        assert np.linalg.norm(c.rhs(t, p.exact(t)) - xd) < 1e-8 * np.linalg.norm(xd)
    # one dense J of k = 3 alone is (4 n)^2 doubles (the dense set-up holds J, U, V and [J, F]); the
    # structured one holds n x (k + 1) n blocks and the forcing map, n x (k + 2) n
    assert peak < (4 * n) ** 2 * 8, peak / ((4 * n) ** 2 * 8)


@pytest.mark.parametrize("rcond", [1e-9, 1e-6])
def test_explicit_rcond_structured_equals_dense(rcond):
    p = gallery.random_pencil(n=10, blocks=(3, 2), seed=1)
    for method, lam in METHOD_LAMS:
        assert_same_setup(p.dae, method, lam, rcond=rcond)


def test_zero_A_falls_back_and_is_completed_as_before():
    c = complete(LinearDAE(np.zeros((3, 3)), np.eye(3)), "alternative", lam=1.0)
    assert (c.setup, c.k) == ("dense", 1)
    assert "A is zero" in c.setup_note
    np.testing.assert_allclose(c.maps().G[0], -np.eye(3), atol=1e-14)


def test_user_subclass_keeps_the_dense_factors():
    """A Completion subclass with its own `_maps` gets the dense factors its contract promises."""
    from lsc import Completion

    class Seen(Completion):
        method = "seen"

        def _maps(self, fac, lam):
            P = fac.first_rows
            return -P @ fac.jets.F[0], P @ fac.jets.L[0]

    p = gallery.random_pencil(n=8, blocks=(2, 1), seed=2)
    c = complete(p.dae, Seen)
    assert c.setup == "dense"
    np.testing.assert_allclose(c.maps().G, complete(p.dae, "standard").maps().G, atol=1e-12)


def test_badly_scaled_rows_structured_equals_dense():
    """Row equilibration happens before either set-up: both see the same equations."""
    p = gallery.random_pencil(n=12, blocks=(3, 2), seed=3)
    D = np.diag(np.logspace(-4, 4, 12))
    dae = LinearDAE(D @ p.dae.A(0.0), D @ p.dae.B(0.0))
    for method, lam in METHOD_LAMS:
        assert_same_setup(dae, method, lam)


def test_singular_shifts_fall_back_to_dense():
    """cond(P), cond(Q) = 1e4: B + mu A is ill conditioned at every trial shift (reciprocal condition ~1e-8,
    far below the 1e-6 the structured path needs); it declines and the result is the dense one."""
    p = gallery.random_pencil(n=12, blocks=(3, 2), seed=3, cond=1e4)
    c = complete(p.dae, "alternative", lam=2.0)
    assert c.setup == "dense" and "ill conditioned at every trial shift" in c.setup_note
    np.testing.assert_array_equal(c.maps().G, complete(p.dae, "alternative", lam=2.0, setup="dense").maps().G)


@pytest.mark.parametrize("cond", [3e2, 1e3])
def test_a_close_call_either_way_gives_the_dense_answer(cond):
    """cond(P), cond(Q) = 3e2 or 1e3: a staircase level's smallest singular value lies near the edge of the
    close-call margin, so whether the structured path declines depends on the BLAS kernel's rounding (at 1e3
    it declines on some OpenBLAS kernels and decides on others). What must not depend on it: a decline is
    the dense result itself, a decision agrees with it, and either solves the DAE's exact solution."""
    p = gallery.random_pencil(n=12, blocks=(3, 2), seed=3, cond=cond)
    dense = complete(p.dae, "alternative", lam=2.0, setup="dense")
    c = complete(p.dae, "alternative", lam=2.0)
    if c.setup == "dense":
        assert "close call" in c.setup_note, c.setup_note
        np.testing.assert_array_equal(c.maps().G, dense.maps().G)
    else:
        assert c.setup == "structured"
        assert (c.k, c.n_constraints, c._rank) == (dense.k, dense.n_constraints, dense._rank)
        assert rel(dense.maps().G, c.maps().G) < 1e-9  # measured up to 1.7e-11 on five kernels
    for t in (0.0, 0.7, 2.1):
        xd = p.exact(t, 1)
        assert np.linalg.norm(c.rhs(t, p.exact(t)) - xd) < 1e-8 * np.linalg.norm(xd)  # measured up to 2.3e-10


@pytest.mark.parametrize("method, lam", METHOD_LAMS)
def test_a_problem_without_constraints_is_set_up_structured(method, lam):
    """An ODE written as a DAE (invertible A: no constraints, a = 0): empty constraint maps, no reshape of zero rows."""
    dense, fast = assert_same_setup(LinearDAE([[2.0, 0.0], [1.0, 1.0]], [[0.0, -1.0], [1.0, 0.5]]), method, lam)
    assert fast.n_constraints == 0 and fast.maps().Wc.shape[1] == 0
