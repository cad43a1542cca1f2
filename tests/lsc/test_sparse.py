"""The sparse set-up of the alternative completion (lsc._sparse): structure, equality with the dense one, refusals."""
import warnings

import numpy as np
import pytest
import scipy.sparse as sp

import lsc
from lsc import gallery
from lsc._problem import equilibration
from lsc._sparse_problem import DENSE_MAX, sparse_equilibration

LAM = 2.0


def _dense_twin(dae):
    """The same DAE with dense arrays (the forcing object shared)."""
    return lsc.LinearDAE(dae.A_sparse.toarray(), dae.B_sparse.toarray(), dae.f.fn if dae.f is not None else None)


def _balanced_dense(dae, lam, setup, t=None):
    """The dense completion's G (and g(t) when `t` is given), computed on the time-rescaled twin.

    ``s`` (a power of two) brings ``||A||`` to ``||B||``: the twin ``(s A) y' + B y = f(tau / s)``
    has ``y(tau) = x(tau / s)``, and its alternative completion with ``lam / s`` gives ``x' = s G_y x + s g_y(s t)``.
    The dense arrays' rank decisions and rounding depend on ``||B|| / ||A||`` (Stokes: ``1 / h^2``), the completion
    does not (the same ``Z1`` and constraint manifold; the row equilibration is checked to be the same).
    """
    A, B = dae.A_sparse.toarray(), dae.B_sparse.toarray()
    s = 2.0 ** np.round(np.log2(np.linalg.norm(B, 2) / np.linalg.norm(A, 2)))
    f = dae.f
    forcing = None if (t is None or f is None) else (lambda tau, d: f.jet(tau / s, d)[d] / s**d)
    twin = lsc.LinearDAE(s * A, B, forcing)
    r0, r1 = equilibration(lsc.LinearDAE(A, B))[0], equilibration(twin)[0]
    assert (r0 is None and r1 is None) or np.array_equal(r0, r1)
    comp = lsc.complete(twin, "alternative", lam=lam / s, setup=setup)
    G = s * comp.jac(0.0, None)
    return G if t is None else (G, s * comp.matrices(s * t)[1])


FAMILIES = {
    "msd_ind3": lambda: gallery.msd_ind3(12),
    "stokes_ind2": lambda: gallery.stokes_ind2(4),
    "triple_chain": lambda: gallery.triple_chain(6),
    "triple_chain_tv": lambda: gallery.triple_chain(5, "tv2"),
    "rcl_voltage": lambda: gallery.rcl_ladder(8, "voltage"),
    "rcl_current": lambda: gallery.rcl_ladder(9, "current"),
    "chain_ode": lambda: gallery.triple_chain(4, "none"),
}


@pytest.fixture(params=sorted(FAMILIES))
def family(request):
    return FAMILIES[request.param]()


def test_structure_and_index(family):
    c = lsc.complete(family.dae, "alternative", lam=LAM)
    assert isinstance(c, lsc.SparseCompletion) and c.setup == "sparse"
    assert c.index == family.index == c.k
    assert c.n_constraints == family.dae.n - family.n_finite
    assert len(c.structure.level_sizes) == family.index


def test_contains_the_exact_solution(family):
    c = lsc.complete(family.dae, "alternative", lam=LAM)
    for t in (0.0, 0.37, 1.9):
        xdot = family.exact(t, 1)
        np.testing.assert_allclose(c.rhs(t, family.exact(t)), xdot, rtol=0, atol=1e-11 * (1 + np.abs(xdot).max()))
        np.testing.assert_allclose(c.constraint_residual(t, family.exact(t)), 0, atol=1e-11)


def test_equals_the_dense_completion(family):
    """G applied to random vectors and the forcing g(t) against the dense library's alternative completion."""
    dae = family.dae
    c = lsc.complete(dae, "alternative", lam=LAM)
    G = _balanced_dense(dae, LAM, "auto")
    V = np.random.default_rng(0).standard_normal((dae.n, 4))
    err = np.abs(c.operator() @ V - G @ V).max() / (np.abs(G).max() * np.abs(V).max())
    assert err < 1e-10, err
    dense = lsc.complete(_dense_twin(dae), "alternative", lam=LAM)
    for t in (0.2, 1.3):
        g = dense.matrices(t)[1]
        np.testing.assert_allclose(c.forcing(t), g, rtol=0, atol=1e-10 * (1 + np.abs(g).max()) * max(1, np.abs(G).max()))


def test_added_dynamics_are_minus_lam_without_jordan_blocks(family):
    c = lsc.complete(family.dae, "alternative", lam=LAM)
    G = c.operator() @ np.eye(c.n)
    a = c.n_constraints
    # rank(G + lam I) = n - a exactly when -lam is a semisimple eigenvalue of multiplicity a
    s = np.linalg.svd(G + LAM * np.eye(c.n), compute_uv=False)
    assert np.sum(s < 1e-9 * s[0]) == a
    # along the completion, every constraint residual obeys c' = -lam c
    x = np.random.default_rng(1).standard_normal(c.n)
    C = c.structure.C
    scale = np.abs(C @ x).max(initial=1.0) * max(1, np.abs(G).max())
    np.testing.assert_allclose(C @ (G @ x), -LAM * (C @ x), atol=1e-10 * scale)


def test_project_is_the_nearest_consistent_point(family):
    dae = family.dae
    c = lsc.complete(dae, "alternative", lam=LAM)
    x = family.exact(0.4) + 1e-2 * np.random.default_rng(2).standard_normal(dae.n)
    y = c.project(0.4, x)
    np.testing.assert_allclose(c.constraint_residual(0.4, y), 0, atol=1e-11)
    if c.n_constraints and dae.n <= 60:
        dense = lsc.complete(_dense_twin(dae), "alternative", lam=LAM)
        np.testing.assert_allclose(y, dense.project(0.4, x), atol=1e-9)


def test_step_solver_inverts_I_minus_cG(family):
    c = lsc.complete(family.dae, "alternative", lam=LAM)
    G = c.operator() @ np.eye(c.n)
    r = np.random.default_rng(3).standard_normal(c.n)
    for step in (1e-3, 0.7):
        k = c.step_solver(step).solve(r)
        np.testing.assert_allclose(k - step * (G @ k), r, atol=1e-10 * (1 + step * np.abs(G).max()))


def test_equilibration_matches_the_dense_rules():
    rng = np.random.default_rng(4)
    for trial in range(12):
        n = 7
        A = sp.random(n, n, density=0.4, random_state=trial, format="csr")
        B = sp.random(n, n, density=0.5, random_state=trial + 100, format="csr") + sp.identity(n)
        rs, cs = 10.0 ** rng.uniform(-6, 6, n), 10.0 ** rng.uniform(-6, 6, n) if trial % 2 else np.ones(n)
        A, B = sp.diags(rs) @ A @ sp.diags(cs), sp.diags(rs) @ B @ sp.diags(cs)
        r_dense, c_dense = equilibration(lsc.LinearDAE(A.toarray(), B.toarray()))
        r_sparse, c_sparse = sparse_equilibration(sp.csr_matrix(A), sp.csr_matrix(B))
        for u, v in ((r_dense, r_sparse), (c_dense, c_sparse)):
            assert (u is None and v is None) or np.array_equal(u, v)


def test_row_equilibration_is_reproduced():
    """Velocity equations multiplied by 1e6: the dense path equilibrates rows, which changes the least-squares
    metric; the sparse one weighs the residual with the same row scales and agrees."""
    p = gallery.msd_ind3(8)
    d = np.r_[np.ones(8), np.full(8, 1e6), 1.0]
    f = p.dae.f.fn
    dae = lsc.LinearDAE(sp.diags(d) @ p.dae.A_sparse, sp.diags(d) @ p.dae.B_sparse,
                        lsc.InputForcing(d[:, None] * f.input_map, f.u))
    c = lsc.complete(dae, "alternative", lam=LAM)
    assert c.row_scales is not None and np.ptp(np.log2(c.row_scales)) > 20
    G = lsc.complete(_dense_twin(dae), "alternative", lam=LAM).jac(0.0, None)
    V = np.random.default_rng(5).standard_normal((dae.n, 3))
    assert np.abs(c.operator() @ V - G @ V).max() / (np.abs(G).max() * np.abs(V).max()) < 1e-10
    np.testing.assert_allclose(c.rhs(0.3, p.exact(0.3)), p.exact(0.3, 1), atol=1e-10)
    # other weights within the velocity equations give another completion: this comparison can fail
    c.row_scales = c.row_scales * np.r_[np.ones(8), 2.0 ** np.arange(8), 1.0]
    c._build()
    assert np.abs(c.operator() @ V - G @ V).max() / (np.abs(G).max() * np.abs(V).max()) > 1e-6


def test_non_diagonal_E_takes_the_saddle_point_matrix():
    """A consistent (tridiagonal) mass matrix: the least-squares system is factorized whole, E^-1 by sparse LU."""
    g = 10
    M = sp.diags([np.full(g - 1, 10.0), np.full(g, 100.0), np.full(g - 1, 10.0)], [-1, 0, 1], format="csr")
    K = sp.diags([np.full(g - 1, 2.0), np.full(g, -6.0), np.full(g - 1, 2.0)], [-1, 0, 1], format="csr")
    D = 2.5 * K
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, g - 1])), shape=(1, g))
    from lsc.gallery._chains import _mechanical_descriptor

    desc = _mechanical_descriptor(M, K, D, G)
    f = lsc.InputForcing(np.r_[np.zeros(g), np.ones(g), 0.0][:, None], [1.0])
    dae = lsc.LinearDAE(desc.E, -desc.A, f)
    c = lsc.complete(dae, "alternative", lam=LAM)
    assert "kkt" in c.factorizations and c.structure.E_diag is None
    dense = lsc.complete(_dense_twin(dae), "alternative", lam=LAM)
    V = np.random.default_rng(6).standard_normal((dae.n, 3))
    Gd = dense.jac(0.0, None)
    assert np.abs(c.operator() @ V - Gd @ V).max() / (np.abs(Gd).max() * np.abs(V).max()) < 1e-10
    np.testing.assert_allclose(c.forcing(0.5), dense.matrices(0.5)[1], atol=1e-10)
    r = np.random.default_rng(7).standard_normal(dae.n)
    k = c.step_solver(0.3).solve(r)
    np.testing.assert_allclose(k - 0.3 * (Gd @ k), r, atol=1e-10 * np.abs(Gd).max())


@pytest.mark.parametrize("forcing", ["dense input map", "sparse input map", "callable"])
def test_one_application_in_any_order_and_with_any_forcing(forcing):
    """msd_ind3 with its equations and unknowns shuffled (the differential unknowns not first) and its forcing as a
    dense or sparse input map or a plain callable: ``G x + g``, ``g``, ``g'`` and ``G`` on a batch of vectors agree
    with the dense library's alternative completion of the same DAE."""
    p = gallery.msd_ind3(12)
    n, fn = p.dae.n, p.dae.f.fn
    rng = np.random.default_rng(11)
    pr, pc = rng.permutation(n), rng.permutation(n)
    A, B = p.dae.A_sparse[pr][:, pc], p.dae.B_sparse[pr][:, pc]
    U = fn.input_map[pr]
    f = {"dense input map": lsc.InputForcing(U, fn.u),
         "sparse input map": lsc.InputForcing(sp.csr_matrix(U), fn.u),
         "callable": lambda t, d: U @ fn.u.jet(t, d)[d]}[forcing]
    dae = lsc.LinearDAE(A, B, f)
    c = lsc.complete(dae, "alternative", lam=LAM)
    assert not np.array_equal(c.structure.diff_cols, np.arange(c.structure.diff_cols.size))
    dense = lsc.complete(lsc.LinearDAE(A.toarray(), B.toarray(), f), "alternative", lam=LAM)
    G = dense.jac(0.0, None)
    scale = np.abs(G).max()
    V = rng.standard_normal((n, 3))
    assert np.abs(c.operator() @ V - G @ V).max() <= 1e-10 * scale * np.abs(V).max()
    x = p.exact(0.4)[pc] + 1e-2 * rng.standard_normal(n)
    for t in (0.4, 1.7):
        g = dense.matrices(t)[1]
        size = scale * (1 + np.abs(x).max() + np.abs(g).max())
        np.testing.assert_allclose(c.rhs(t, x), G @ x + g, rtol=0, atol=1e-10 * size)
        X = np.column_stack([x, 2 * x])
        np.testing.assert_allclose(c.rhs(t, X), G @ X + g[:, None], rtol=0, atol=2e-10 * size)
        np.testing.assert_allclose(c.forcing(t), g, rtol=0, atol=1e-10 * size)
    # g' against a central difference of g (its third derivative is O(1): the difference is good to ~1e-8)
    dg = (c.forcing(1.0 + 1e-4) - c.forcing(1.0 - 1e-4)) / 2e-4
    np.testing.assert_allclose(c.forcing(1.0, 1), dg, rtol=0, atol=1e-6 * (1 + np.abs(dg).max()))
    # on the exact solution (permuted) the completion is the exact derivative
    xs, dxs = p.exact(0.9)[pc], p.exact(0.9, 1)[pc]
    np.testing.assert_allclose(c.rhs(0.9, xs), dxs, rtol=0, atol=1e-11 * (1 + np.abs(dxs).max()))


def _not_semi_explicit(n):
    """``x_i' + x_i + x_(i-1) / 2 = 0`` (i < n - 1) and ``x_0' + x_(n-1) + x_(n-2) / 2 = 0``: index 1, but ``A`` has
    no zero row (its last row repeats the first), so it is not of the form [[E, 0], [0, 0]]."""
    rows = np.r_[np.arange(n - 1), n - 1]
    cols = np.r_[np.arange(n - 1), 0]
    A = sp.csr_matrix((np.ones(n), (rows, cols)), shape=(n, n))
    return lsc.LinearDAE(A, sp.identity(n, format="csr") + sp.diags(np.full(n - 1, 0.5), -1))


def test_unrecognised_structure_small_goes_dense_with_a_note():
    dae = _not_semi_explicit(6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = lsc.complete(dae, "alternative", lam=LAM)
    assert isinstance(c, lsc.AlternativeCompletion)
    assert "sparse set-up declined" in c.setup_note and "nonzero rows" in c.setup_note
    with pytest.raises(lsc.SparseStructureError, match="semi-explicit"):
        lsc.complete(dae, "alternative", lam=LAM, setup="sparse")


def test_unrecognised_structure_large_is_refused():
    dae = _not_semi_explicit(DENSE_MAX + 5)
    with pytest.raises(lsc.SparseStructureError, match="does not recognise"):
        lsc.complete(dae, "alternative", lam=LAM)


def test_large_sparse_problem_is_never_densified():
    p = gallery.msd_ind3(DENSE_MAX, projectors=False)
    assert p.dae.n > DENSE_MAX
    with pytest.raises(ValueError, match="refused for a sparse DAE"):
        lsc.complete(p.dae, "alternative", lam=LAM, setup="dense")
    with pytest.raises(ValueError, match="'alternative' completion only"):
        lsc.complete(p.dae, "standard")
    with pytest.raises(ValueError, match="scipy.sparse matrix with n = "):
        p.dae.A(0.0)


def test_small_sparse_problem_may_go_dense_explicitly():
    p = gallery.msd_ind3(6)
    c = lsc.complete(p.dae, "stabilized", lam=LAM)
    assert isinstance(c, lsc.StabilizedCompletion) and "'alternative' completion only" in c.setup_note
    d = lsc.complete(p.dae, "alternative", lam=LAM, setup="dense")
    assert isinstance(d, lsc.AlternativeCompletion)


@pytest.mark.parametrize("make, fragment", [
    # a singular E block
    (lambda: lsc.LinearDAE(sp.csr_matrix(np.array([[1.0, 1.0, 0], [1.0, 1.0, 0], [0, 0, 0]])), sp.identity(3)),
     "E (the block of A"),
    # two algebraic equations whose parts on the algebraic unknowns are dependent (a hidden constraint their
    # difference would reveal): not reduced here
    (lambda: lsc.LinearDAE(sp.diags([1.0, 1.0, 0.0, 0.0]).tocsr(),
                           sp.csr_matrix(np.array([[1.0, 0, 1, 0], [0, 1, 0, 1], [1, 0, 1, 0], [0, 1, 2, 0.0]]))),
     "depend on each other"),
    # an equation 0 = f(t) on no unknown
    (lambda: lsc.LinearDAE(sp.diags([1.0, 0.0]).tocsr(), sp.csr_matrix(np.array([[1.0, 0.0], [0.0, 0.0]]))),
     "is zero"),
])
def test_structure_refusals(make, fragment):
    with pytest.raises(lsc.SparseStructureError, match=None) as info:
        lsc.complete(make(), "alternative", lam=LAM, setup="sparse")
    assert fragment in str(info.value)


def test_singular_constraints_are_refused():
    """Hessenberg index 2 with B_a E^-1 B_(d,a) singular (two identical constraint rows): not solvable, and not
    taken by the sparse set-up."""
    A = sp.diags([1.0, 1.0, 1.0, 0.0, 0.0]).tocsr()
    B = sp.lil_matrix((5, 5))
    B[0, 3] = B[1, 4] = 1.0
    B[3, 0] = B[4, 0] = 1.0
    B[2, 2] = 1.0
    with pytest.raises(lsc.SparseStructureError, match="singular"):
        lsc.complete(lsc.LinearDAE(A, B.tocsr()), "alternative", lam=LAM, setup="sparse")
    with pytest.raises(lsc.IndexDeterminationError):  # the dense path, for this small n: not solvable
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            lsc.complete(lsc.LinearDAE(A, B.tocsr()), "alternative", lam=LAM)


def test_k_and_lam_arguments():
    p = gallery.msd_ind3(5)
    assert lsc.complete(p.dae, "alternative", lam=LAM, k=5).k == 5
    with pytest.raises(lsc.IndexDeterminationError, match="below the differentiation index 3"):
        lsc.complete(p.dae, "alternative", lam=LAM, k=2)
    with pytest.raises(ValueError, match="positive constant"):
        lsc.complete(p.dae, "alternative", lam=lambda t, d: 1.0)
    with pytest.raises(ValueError, match="positive finite"):
        lsc.complete(p.dae, "alternative", lam=-1.0)


def test_dense_dae_on_request():
    """setup='sparse' converts a dense constant DAE."""
    p = gallery.mechanical()
    c = lsc.complete(p.dae, "alternative", lam=LAM, setup="sparse")
    assert isinstance(c, lsc.SparseCompletion)
    for t in (0.0, 1.1):
        np.testing.assert_allclose(c.rhs(t, p.exact(t)), p.exact(t, 1), atol=1e-10)


def test_maps_and_batch_rhs():
    p = gallery.stokes_ind2(3)
    c = lsc.complete(p.dae, "alternative", lam=LAM)
    m = c.maps(0.5)
    fjet = p.dae.f_jet(0.5, m.order).ravel()
    X = np.column_stack([p.exact(0.5), p.exact(0.5) + 1.0])
    np.testing.assert_allclose(c.rhs(0.5, X)[:, 0], m.G @ X[:, 0] + m.forcing(fjet)[0], atol=1e-11)
    np.testing.assert_allclose(c.rhs(0.5, X)[:, 1], c.rhs(0.5, X[:, 1]), atol=1e-11)
    np.testing.assert_allclose(m.C @ p.exact(0.5) - m.Wc @ fjet, 0, atol=1e-11)
    R = c.constraint_residual(np.array([0.5, 0.5]), X)
    np.testing.assert_allclose(R[:, 0], 0, atol=1e-11)
    np.testing.assert_allclose(R[:, 1], m.C @ np.ones(c.n), atol=1e-11)


def test_public_contract_maps_equal_the_dense_maps(family):
    """`maps` and `lam_affine` of the sparse completion against the dense library's `CompletionMaps`/`LamAffine`."""
    dae = family.dae
    c = lsc.complete(dae, "alternative", lam=LAM)
    assert "sparse factorizations" in c.setup_note and c.structure.describe() in c.setup_note
    ts = np.array([0.2, 1.3])
    m = c.maps(ts)
    assert isinstance(m, lsc.CompletionMaps) and m.method == "alternative"
    assert m.order == c.k + 1 and m.k == c.k and np.array_equal(m.t, ts) and np.all(m.lam == LAM)
    dense = lsc.complete(_dense_twin(dae), "alternative", lam=LAM)
    dm = dense.maps(ts)
    assert dm.order == m.order and m.W.shape == dm.W.shape[1:] and m.Wc.shape[1] == dm.Wc.shape[2]
    G = _balanced_dense(dae, LAM, "auto")
    I = np.eye(dae.n)
    assert np.abs(m.G @ I - G).max() <= 1e-10 * np.abs(G).max()
    # the forcing map on random jets and on the DAE's own (dense g is as accurate as the existing comparison's)
    V = np.random.default_rng(2).standard_normal((m.W.shape[1], 3))
    scale = max(1.0, np.abs(G).max())
    assert np.abs(m.W @ V - dm.W[0] @ V).max() <= 1e-9 * scale * np.abs(dm.W[0] @ V).max(initial=1.0)
    fjets = np.array([dae.f_jet(t, m.order) for t in ts])
    np.testing.assert_allclose(m.forcing(fjets), dm.forcing(fjets), rtol=0,
                               atol=1e-10 * scale * (1 + np.abs(dm.forcing(fjets)).max()))
    # the constraint rows: the dense ones' row space, and zero on the exact solution with their forcing map
    a = c.n_constraints
    C = m.C.toarray()
    assert np.linalg.matrix_rank(np.vstack([C, dm.C[0]]), tol=1e-8 * np.abs(C).max(initial=1.0)) == a == dm.C.shape[1]
    for t, fjet in zip(ts, fjets):
        x = family.exact(t)
        np.testing.assert_allclose(m.C @ x - m.Wc @ fjet.ravel(), 0, atol=1e-11 * (1 + np.abs(x).max()))
    # the nearest consistent point through C^+ is `project`'s
    x = family.exact(0.2) + 1e-3
    np.testing.assert_allclose(x - m.C_pinv @ c.constraint_residual(0.2, x), c.project(0.2, x), atol=1e-12)
    # lam_affine: the split reproduces the maps at another rate, and the dense split
    aff = c.lam_affine(ts)
    assert aff.residual < 1e-12 and isinstance(aff.maps, lsc.CompletionMaps)
    G7 = lsc.complete(dae, "alternative", lam=7.0).operator() @ I
    assert np.abs(aff.G0 @ I + 7.0 * (aff.G1 @ I) - G7).max() <= 1e-11 * np.abs(G7).max()
    daff = dense.lam_affine(0.2)
    for M, D in ((aff.W0, daff.W0[0]), (aff.W1, daff.W1[0])):
        assert np.abs(M @ V - D @ V).max() <= 1e-9 * scale * np.abs(D @ V).max(initial=1.0)


def test_solve_dae_takes_the_sparse_path():
    p = gallery.msd_ind3(40)
    res = lsc.solve_dae(p.dae, (0.0, 1.0), p.exact(0.0), lam=LAM, rtol=1e-8, atol=1e-10, t_eval=[0.0, 0.5, 1.0])
    assert res.success and res.method == "DOP853", res.message
    np.testing.assert_allclose(res.x, p.exact(res.t), atol=1e-6 * np.abs(p.exact(res.t)).max())


def test_exact_steps_refuse_a_sparse_operator():
    c = lsc.complete(gallery.msd_ind3(20).dae, "alternative", lam=LAM)
    with pytest.raises(TypeError, match="LinearOperator of shape"):
        lsc.ExactPropagator(c.maps().G, 2)
