"""The gallery's sparse benchmark models: published constructions, closed forms, the descriptor reader."""
import os

import numpy as np
import pytest
import scipy.io
import scipy.linalg
import scipy.sparse as sp

import lsc
from lsc import gallery

SMALL = {
    "msd_ind3": lambda: gallery.msd_ind3(9),
    "stokes_ind2": lambda: gallery.stokes_ind2(4, 3),
    "triple_chain": lambda: gallery.triple_chain(6),
    "triple_chain_tv": lambda: gallery.triple_chain(5, "tv"),
    "rcl_voltage": lambda: gallery.rcl_ladder(7, "voltage"),
    "rcl_current": lambda: gallery.rcl_ladder(7, "current"),
}


@pytest.fixture(params=sorted(SMALL))
def model(request):
    return SMALL[request.param]()


def test_exact_solution_solves_the_dae(model):
    for t in (0.0, 0.8, 2.5):
        x, xdot = model.exact(t), model.exact(t, 1)
        np.testing.assert_allclose(model.dae.residual(t, x, xdot), 0, atol=1e-11 * (1 + np.abs(xdot).max()))


def test_exact_derivatives_are_derivatives(model):
    h, t = 1e-5, 0.6
    for d in (0, 1, 2):
        fd = (model.exact(t + h, d) - model.exact(t - h, d)) / (2 * h)
        np.testing.assert_allclose(fd, model.exact(t, d + 1), rtol=1e-7, atol=1e-7)


def test_finite_spectrum_dimension(model):
    """The finite eigenvalues of the pencil (E, A), counted by a dense QZ: n_finite, and the index's Jordan blocks."""
    E, A = model.descriptor.E.toarray(), model.descriptor.A.toarray()
    alpha, beta = scipy.linalg.eigvals(A, E, homogeneous_eigvals=True)
    finite = np.abs(beta) > 1e-8 * np.abs(alpha)
    assert np.count_nonzero(finite) == model.n_finite
    assert sum(model.jordan_blocks) == model.dae.n - model.n_finite


def test_descriptor_convention(model):
    """lsc's DAE is E x' - A x = f: A_lsc = E, B_lsc = -A."""
    assert abs(model.dae.A_sparse - model.descriptor.E).max() == 0
    assert abs(model.dae.B_sparse + model.descriptor.A).max() == 0


def test_msd_ind3_published_matrices():
    """Mehrmann and Stykel's defaults: masses 100, springs 2 (4 to the ground at both ends), dampers 5 (10)."""
    p = gallery.msd_ind3(4)
    d = p.descriptor
    g = 4
    M = d.E.toarray()[g:2 * g, g:2 * g]
    K = d.A.toarray()[g:2 * g, :g]
    D = d.A.toarray()[g:2 * g, g:2 * g]
    np.testing.assert_array_equal(M, 100 * np.eye(4))
    # the ends have one neighbour less and a stronger tie to the ground: every diagonal entry is the same
    np.testing.assert_array_equal(K, [[-6, 2, 0, 0], [2, -6, 2, 0], [0, 2, -6, 2], [0, 0, 2, -6]])
    np.testing.assert_array_equal(D, [[-15, 5, 0, 0], [5, -15, 5, 0], [0, 5, -15, 5], [0, 0, 5, -15]])
    np.testing.assert_array_equal(d.A.toarray()[2 * g, :g], [1, 0, 0, -1])
    np.testing.assert_array_equal(d.A.toarray()[g:2 * g, 2 * g], [-1, 0, 0, 1])
    np.testing.assert_array_equal(d.B.toarray().ravel(), np.eye(9)[g])
    assert p.dae.n == 2 * g + 1 and p.n_finite == p.dae.n - 3


@pytest.mark.parametrize("make", [lambda: gallery.msd_ind3(7), lambda: gallery.triple_chain(6),
                                  lambda: gallery.triple_chain(5, "tv2"), lambda: gallery.stokes_ind2(3, 4)])
def test_spectral_projectors(make):
    """Pr, Pl: idempotent, of rank n_finite, Pl E = E Pr and Pl A = A Pr, and range(Pr) is the solution manifold
    of the unforced DAE (the completion's constraint rows vanish on it)."""
    p = make()
    n = p.dae.n
    dense = (lambda P: P.toarray()) if sp.issparse(p.projectors["Pr"]) else (lambda P: P @ np.eye(n))
    Pr, Pl = dense(p.projectors["Pr"]), dense(p.projectors["Pl"])
    E, A = p.descriptor.E.toarray(), p.descriptor.A.toarray()
    for P in (Pr, Pl):
        np.testing.assert_allclose(P @ P, P, atol=1e-10 * np.abs(P).max())
        assert np.linalg.matrix_rank(P, tol=1e-8 * np.abs(P).max()) == p.n_finite
    np.testing.assert_allclose(Pl @ E, E @ Pr, atol=1e-10 * np.abs(E).max() * np.abs(Pr).max())
    np.testing.assert_allclose(Pl @ A, A @ Pr, atol=1e-10 * np.abs(A).max() * np.abs(Pr).max())
    c = lsc.complete(lsc.LinearDAE(p.dae.A_sparse, p.dae.B_sparse), "alternative", lam=1.0)
    np.testing.assert_allclose(c.structure.C @ Pr, 0, atol=1e-10 * np.abs(c.structure.C).max() * np.abs(Pr).max())


def test_stokes_published_matrices():
    """nx = ny = 2: two horizontal and two vertical velocities, three pressures; A11 = -8 I (one direction each)."""
    d = gallery.stokes_descriptor(2, 2)
    expected_A12 = -np.array([[-2, 2, 0], [0, 0, -2], [-2, 0, 2], [0, -2, 0]], dtype=float)
    A = d.A.toarray()
    np.testing.assert_array_equal(A[:4, :4], -8 * np.eye(4))
    np.testing.assert_array_equal(A[:4, 4:], expected_A12)
    np.testing.assert_array_equal(A[4:, :4], expected_A12.T)
    np.testing.assert_array_equal(d.E.toarray(), np.diag([1.0] * 4 + [0.0] * 3))


def test_stokes_velocity_is_divergence_free_and_inputs_local():
    p = gallery.stokes_ind2(10, 8, inputs=2, outputs=2)
    nv = 9 * 8 + 7 * 10
    div = p.descriptor.A[nv:, :nv]
    for t in (0.0, 0.4):
        assert np.abs(div @ p.exact(t)[:nv]).max() < 1e-10 * np.abs(p.exact(t)[:nv]).max()
    B = p.descriptor.B.toarray()
    assert np.count_nonzero(B[:9 * 8, 0]) > 0 and np.count_nonzero(B[9 * 8:nv, 0]) == 0
    assert np.count_nonzero(B[9 * 8:nv, 1]) > 0 and np.all(B[nv:] == 0)
    C = p.descriptor.C.toarray()
    assert np.all(C[:, nv:] == 0) and C[0].sum() > 0


def test_rcl_ladder_structure():
    v = gallery.rcl_ladder(5, "voltage", R=0.5, L=2.0, C=3.0, G=0.1)
    A, B = v.dae.A_sparse.toarray(), v.dae.B_sparse.toarray()
    np.testing.assert_array_equal(np.diag(A), [3.0] * 5 + [2.0] * 4 + [0.0])
    np.testing.assert_array_equal(B[9], np.eye(10)[0])  # e_1 = v(t)
    np.testing.assert_array_equal(B[5, :], np.r_[-1.0, 1.0, 0, 0, 0, 0.5, 0, 0, 0, 0])  # L i' + R i = e_1 - e_2
    i = gallery.rcl_ladder(5, "current")
    assert np.count_nonzero(np.diag(i.dae.A_sparse.toarray())[:5]) == 3


def test_triple_chain_constraints():
    p = gallery.triple_chain(4)
    G = -p.descriptor.A.toarray()[2 * 13:, :13]
    assert G.shape == (6, 13)
    np.testing.assert_array_equal(np.abs(G).sum(axis=1), 2 * np.ones(6))
    with pytest.raises(ValueError, match="even"):
        gallery.triple_chain(5)
    with pytest.raises(ValueError, match="odd"):
        gallery.triple_chain(4, "tv")
    with pytest.raises(ValueError, match="must be one of"):
        gallery.triple_chain(4, "rigid")


def test_read_descriptor_mat_and_matrix_market(tmp_path):
    p = gallery.msd_ind3(6, projectors=False)
    d = p.descriptor
    mat = tmp_path / "sys.mat"
    scipy.io.savemat(mat, {"e": d.E, "A": d.A, "b": d.B, "C": d.C})
    for X in "EABC":
        scipy.io.mmwrite(str(tmp_path / f"sys.{X}"), getattr(d, X))
    got = [gallery.read_descriptor(mat), gallery.read_descriptor(str(tmp_path / "sys")),
           gallery.read_descriptor({"A": str(tmp_path / "sys.A.mtx"), "E": d.E})]
    for r in got:
        assert abs(r.A - d.A).max() == 0 and abs(r.E - d.E).max() == 0
    assert got[2].B is None and got[0].B.shape == (13, 1)
    dae = got[0].dae(u=[2.0])
    np.testing.assert_allclose(dae.f(0.0), 2.0 * d.B.toarray().ravel())
    ode = gallery.read_descriptor({"A": -sp.identity(3)})
    assert abs(ode.E - sp.identity(3)).max() == 0


@pytest.mark.parametrize("source, error, fragment", [
    ({"E": sp.identity(3)}, ValueError, "no matrix A"),
    ({"A": sp.identity(3), "E": sp.identity(4)}, ValueError, "must have A's shape"),
    ({"A": sp.identity(3), "B": np.ones((4, 1))}, ValueError, "n = 3 rows"),
    ({"A": sp.identity(3), "C": np.ones((1, 4))}, ValueError, "n = 3 columns"),
    ({"A": np.array([[1.0, np.nan], [0, 1]])}, ValueError, "NaN"),
    ({"Q": sp.identity(3)}, ValueError, "keys must be among"),
])
def test_read_descriptor_refuses(source, error, fragment):
    with pytest.raises(error, match=None) as info:
        gallery.read_descriptor(source)
    assert fragment in str(info.value)


def test_read_descriptor_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        gallery.read_descriptor(tmp_path / "none.mat")
    with pytest.raises(ValueError, match="no matrix A"):
        gallery.read_descriptor(tmp_path / "none")
