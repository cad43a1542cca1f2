"""A sparse completion's forcing and its public maps (`SparseCompletion.maps`, `SparseCompletion.lam_affine`).

The forcing enters the least-squares data of `lsc._sparse` as ``W f_d`` (the differential rows) and the
constraint rows' target ``-lam (C x - cg) + cg'`` with ``cg = sum_i Gamma_i f^(i)``; ``lam`` enters only
there, so the completion is exactly affine in it. The maps are operators applied through the set-up's
factorizations (``G`` is never formed).
"""

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ._maps import CompletionMaps, LamAffine
from ._sparse_lu import factorize
from ._sparse_problem import input_forcing_of

__all__ = ["SparseCompletionMaps", "constraint_forcing", "forcing_jet", "forcing_terms", "jet_terms", "operators",
           "setup_forcing", "sparse_lam_affine", "sparse_maps"]


def setup_forcing(comp):
    """The forcing's contributions, mapped once: ``W f_d`` (when `comp` has no `DiagonalApply`) and
    ``cg = sum Gamma_i f^(i)``."""
    s, f = comp.structure, comp.dae.f
    comp._order = s.index  # cg' needs f^(index)
    comp._input = input_forcing_of(comp.dae) if f is not None else None
    if comp._input is not None:
        Bu = comp._input.input_map
        if comp.structure.E_diag is None:  # a diagonal E adds E^-1 B_u u through lsc._sparse_apply instead
            comp._Wu = comp._W @ Bu[s.diff_rows]
        comp._Gu = [_small_dense(g @ Bu) for g in s.Gamma]


# A constraint rows' input map (a x m) with at most this many entries is kept dense: a product with it is then one
# BLAS call, where a sparse product's dispatch costs more than the arithmetic of a few rows.
_SMALL = 2**16


def _small_dense(M):
    if scipy.sparse.issparse(M) and M.shape[0] * M.shape[1] <= _SMALL:
        return M.toarray()
    return M


def forcing_jet(comp, t, d=0):
    """``(kind, jet)``: the input's jet ``('input', [u; u'; ...])`` or the forcing's ``('f', [f; f'; ...])`` up
    to the order the constraint rows' ``cg^(d+1)`` needs; None without forcing."""
    if comp.dae.f is None:
        return None
    order = comp._order + d
    if comp._input is not None:
        return "input", comp._input.u.jet(t, order)
    return "f", comp.dae.f.jet(t, order)


def constraint_forcing(comp, jet, d=0):
    """``(cg^(d), cg^(d+1))`` from a `forcing_jet`."""
    a = comp.structure.n_constraints
    if jet is None:
        return np.zeros(a), np.zeros(a)
    kind, J = jet
    maps = comp._Gu if kind == "input" else comp.structure.Gamma
    cg = sum((np.asarray(G @ J[i + d]).ravel() for i, G in enumerate(maps)), np.zeros(a))
    dcg = sum((np.asarray(G @ J[i + d + 1]).ravel() for i, G in enumerate(maps)), np.zeros(a))
    return cg, dcg


def forcing_terms(comp, t, d=0):
    """``(W f_d^(d), cg^(d), cg^(d+1))`` at `t`: the forcing parts of the least-squares data."""
    s = comp.structure
    jet = forcing_jet(comp, t, d)
    if jet is None:
        a = s.n_constraints
        return np.zeros(s.diff_rows.size), np.zeros(a), np.zeros(a)
    cg, dcg = constraint_forcing(comp, jet, d)
    kind, J = jet
    if kind == "input":
        rhs = (np.asarray(comp._Wu @ J[d]).ravel() if comp.structure.E_diag is None
               else comp._times_W(np.asarray(comp._input.input_map[s.diff_rows] @ J[d]).ravel()))
    else:
        rhs = comp._times_W(J[d][s.diff_rows])
    return rhs, cg, dcg


def jet_terms(comp, v):
    """``(W f_d, cg, cg')`` of forcing jets ``v = [f; f'; ...; f^(p)]`` (shape (n (p + 1),) or (n (p + 1), r))."""
    s = comp.structure
    F = v.reshape((comp.order + 1, comp.n) + v.shape[1:])
    a = s.n_constraints
    rhs = comp._times_W(F[0][s.diff_rows])
    cg = sum((G @ F[i] for i, G in enumerate(s.Gamma)), np.zeros((a,) + v.shape[1:]))
    dcg = sum((G @ F[i + 1] for i, G in enumerate(s.Gamma)), np.zeros((a,) + v.shape[1:]))
    return rhs, cg, dcg

def operators(comp, lam):
    """``(G, W)`` at the rate `lam` as LinearOperators (``W`` on the forcing jet ``[f; ...; f^(p)]``)."""
    s, n, w = comp.structure, comp.n, comp.n * (comp.order + 1)

    def G(x):
        if comp._apply is not None:
            return comp._apply.apply(x, lam)
        return comp._solve(-comp._times_W(comp._B_d @ x), -lam * (s.C @ x))

    def W(v):
        rhs, cg, dcg = jet_terms(comp, v)
        return comp._solve(rhs, lam * cg + dcg)

    return (scipy.sparse.linalg.LinearOperator((n, n), matvec=G, matmat=G, dtype=float),
            scipy.sparse.linalg.LinearOperator((n, w), matvec=W, matmat=W, dtype=float))

def sparse_maps(comp, ts, lam=None):
    G, W = operators(comp, comp.lam)
    s, p = comp.structure, comp.order
    blocks = list(s.Gamma) + [scipy.sparse.csr_matrix((s.n_constraints, comp.n))] * (p + 1 - len(s.Gamma))
    Wc = scipy.sparse.hstack(blocks, format="csr")
    return SparseCompletionMaps(ts, G, W, s.C, Wc, p, comp.k, np.full(ts.shape, comp.lam), comp.method)


def sparse_lam_affine(comp, ts, rtol):
    """`SparseCompletion.lam_affine` at the times `ts`."""
    G0, W0 = operators(comp, 0.0)
    s, n, w = comp.structure, comp.n, comp.n * (comp.order + 1)

    def G1(x):
        return comp._solve(np.zeros((s.diff_rows.size,) + x.shape[1:]), -(s.C @ x))

    def W1(v):
        return comp._solve(np.zeros((s.diff_rows.size,) + v.shape[1:]), jet_terms(comp, v)[1])

    G1 = scipy.sparse.linalg.LinearOperator((n, n), matvec=G1, matmat=G1, dtype=float)
    W1 = scipy.sparse.linalg.LinearOperator((n, w), matvec=W1, matmat=W1, dtype=float)
    rng = np.random.default_rng(0)
    x, v = rng.standard_normal(n), rng.standard_normal(w)
    residual, rates = 0.0, (0.3, 7.0, comp.lam)
    for rate in rates:
        G, W = operators(comp, rate)
        for M0, M1, M, y in ((G0, G1, G, x), (W0, W1, W, v)):
            a, b, ref = M0 @ y, M1 @ y, M @ y
            size = max(np.abs(ref).max(initial=0.0), 1.0, np.abs(a).max(initial=0.0) + rate * np.abs(b).max(initial=0.0))
            residual = max(residual, float(np.abs(a + rate * b - ref).max(initial=0.0) / size))
    if not residual <= rtol:
        raise ValueError(f"the sparse completion is not affine in lambda here (relative misfit {residual:.1e}): "
                         "its factorizations are too ill-conditioned to split it")
    return LamAffine(G0, G1, W0, W1, residual, rates, sparse_maps(comp, ts))


class SparseCompletionMaps(CompletionMaps):
    """`CompletionMaps` of a sparse completion (`SparseCompletion.maps`): operators and sparse matrices.

    ``G`` (n x n) and ``W`` (n x n (p + 1)) are LinearOperators, ``C`` and
    ``Wc`` sparse matrices, the same at every time and without the leading
    time axis (constant coefficients); ``t`` and ``lam`` have it. `forcing`
    and `C_pinv` work as for dense maps, without forming an n x n array.
    """

    def forcing(self, fjet):
        """``g = W fjet`` at each time from the forcing jets `fjet`, shape (m, p + 1, n) or (p + 1, n): (m, n)."""
        fjet = np.asarray(fjet, dtype=float).reshape(-1, self.W.shape[1])
        return (self.W @ fjet.T).T

    @property
    def C_pinv(self):
        """``C^+`` as a LinearOperator (n x a): ``C^T (C C^T)^-1`` through one sparse factorization."""
        if self._C_pinv is None:
            C = self.C
            gram = factorize(scipy.sparse.csc_matrix(C @ C.T), "C C^T (the constraint rows' Gram matrix)")

            def apply(c):
                return C.T @ gram.solve(c)

            self._C_pinv = scipy.sparse.linalg.LinearOperator((C.shape[1], C.shape[0]), matvec=apply, matmat=apply,
                                                              dtype=float)
        return self._C_pinv

    def __repr__(self):
        return (f"SparseCompletionMaps(method={self.method!r}, times={self.t.size}, n={self.G.shape[0]}, "
                f"constraints={self.C.shape[0]}, order={self.order})")
