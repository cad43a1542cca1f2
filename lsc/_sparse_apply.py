"""One application of a sparse completion ``x' = G x + g(t)`` when ``E`` is diagonal: one sparse product.

With ``E`` diagonal, ``H = E^T R_d^2 E`` is diagonal and ``H^-1 E^T R_d^2 = E^-1``: the least-squares data
of `lsc._sparse` reduce to ``y = E^-1 (f_d - B_d x)``, corrected on the constraint rows' support only,

    x_d' = y - H^-1 C_c^T mu,    S mu = C_c y - h_c,    x_a' = T^-1 (h_t - C_t^d x_d')

(``S = C_c H^-1 C_c^T``, ``h = -lam (C x - cg) + cg'``). The matrix ``-E^-1 B_d`` is formed once with its rows
at the differential unknowns' places (``G_d``, n x n, empty rows on the algebraic unknowns), so the n-vector
``x'`` comes out of one sparse product; the forcing ``E^-1 f_d`` is added in place (an input map's
``E^-1 B_u`` is precomputed, column-major, so that BLAS streams it once), and the corrections touch only the
rows where ``H^-1 C_c^T`` and ``T`` act: a few for a mechanical chain with a few constraints. An application
is thus a fixed number of passes over ``x`` and the nonzeros, with no temporaries of size n other than
the result (memory traffic, not arithmetic, is what an application at n = 10^6 costs).
"""

import numpy as np
import scipy.linalg.blas
import scipy.sparse

from ._sparse_maps import constraint_forcing, forcing_jet
from ._sparse_problem import input_forcing_of
from ._sparse_structure import rows

__all__ = ["DiagonalApply"]

# An input map's E^-1 B_u is kept dense (column-major) when more than this fraction of its rows is nonzero;
# otherwise only its nonzero rows are kept and added by an index update.
_DENSE_ROWS = 0.5


def _on_rows(M, where, n):
    """Sparse `M` (r x c) as an n x c CSR matrix whose row ``where[i]`` is `M`'s row i (other rows empty)."""
    M = scipy.sparse.csr_matrix(M)
    where = np.asarray(where)
    if where.size == n and np.array_equal(where, np.arange(n)):
        return M
    if np.array_equal(where, np.arange(where.size)):  # the usual order: differential unknowns first
        indptr = np.concatenate([M.indptr, np.full(n - where.size, M.indptr[-1], dtype=M.indptr.dtype)])
        return scipy.sparse.csr_matrix((M.data, M.indices, indptr), shape=(n, M.shape[1]))
    M = M.tocoo()
    return scipy.sparse.csr_matrix((M.data, (where[M.row], M.col)), shape=(n, M.shape[1]))


def _drop_columns(M, drop, n):
    """Sparse `M` with the entries in the columns `drop` removed (shape kept), as CSR."""
    M = scipy.sparse.coo_matrix(M)
    mask = np.zeros(n, bool)
    mask[drop] = True
    keep = ~mask[M.col]
    return scipy.sparse.csr_matrix((M.data[keep], (M.row[keep], M.col[keep])), shape=M.shape)


class _RowBlock:
    """``M`` (n x c): ``add_to(Y, v)`` does ``Y += M v``, touching only `M`'s nonzero rows when they are few.

    A sparse `M` keeps its nonzero rows. A dense `M` whose nonzero rows are more than `_DENSE_ROWS` of all is
    kept whole and column-major (``full``): BLAS adds ``M v`` in place, streaming `M` once, where an index
    update would gather and scatter ``Y``.
    """

    def __init__(self, M, n):
        if scipy.sparse.issparse(M):
            M = scipy.sparse.csr_matrix(M)
            self.rows = np.flatnonzero(np.diff(M.indptr))
            self.full = self.rows.size == n
            self.block = M if self.full else M[self.rows]
            return
        M = np.asarray(M, dtype=float)
        nonzero = np.zeros(n, bool)
        for j in range(M.shape[1]):  # column by column: no n x c temporary
            nonzero |= M[:, j] != 0.0
        self.rows = np.flatnonzero(nonzero)
        self.full = self.rows.size > _DENSE_ROWS * n
        if self.full:
            self.rows = np.arange(n)
        self.block = np.asfortranarray(M) if self.full else np.asfortranarray(M[self.rows])

    def add_to(self, Y, v, sign=1.0):
        if not self.rows.size:
            return Y
        if self.full and Y.ndim == 1 and v.ndim == 1 and isinstance(self.block, np.ndarray):
            # Y += sign * M v in place: BLAS streams the column-major M once, no temporary of size n
            return scipy.linalg.blas.dgemv(sign, self.block, np.asarray(v, dtype=float), beta=1.0, y=Y,
                                           overwrite_y=True)
        w = sign * (self.block @ v)
        if Y.ndim == 2 and w.ndim == 1:
            w = w[:, None]
        if self.full:
            Y += w
        else:
            Y[self.rows] += w
        return Y


class DiagonalApply:
    """``G x + g`` of a `SparseCompletion` with diagonal ``E`` and the Schur-complement solve (or no
    constraint rows to continue): one sparse product ``G_d x`` and updates on the constraints' support.

    Parameters
    ----------
    comp : SparseCompletion
        After its factorizations (``_schur``, ``_H_solver``, the structure's ``T_solver``).
    """

    def __init__(self, comp):
        s, n = comp.structure, comp.n
        d, a = s.diff_cols, s.alg_cols
        self.n, self.alg_cols = n, a
        self._einv = 1.0 / s.E_diag
        # G_d = -E^-1 B_d with its rows at the differential unknowns (B_d's rows scaled in one pass)
        B_d = scipy.sparse.csr_matrix(s.B_d)
        scaled = scipy.sparse.csr_matrix((B_d.data * np.repeat(-self._einv, np.diff(B_d.indptr)), B_d.indices,
                                          B_d.indptr), shape=B_d.shape)
        self.G_d = _on_rows(scaled, d, n)
        self.G_d.sort_indices()
        self.C = s.C
        self._cont, self._term = comp._cont, comp._term
        self._schur = comp._schur
        if comp._cont.size:
            # the non-terminal rows vanish on x_a (lsc._sparse_structure): they act on the differential places
            self.C_c = _drop_columns(rows(s.C, comp._cont), a, n)
            h_inv = 1.0 / comp._H_solver.d
            self.P = _RowBlock(_on_rows(scipy.sparse.diags(h_inv) @ comp._C_cT, d, n), n)  # H^-1 C_c^T
        # the terminal rows' part on x_d: x_a' = T^-1 (h_t - C_t^d x_d')
        self.C_td = _drop_columns(rows(s.C, comp._term), a, n)
        self.T_solver = s.T_solver
        self.diff_rows, self.diff_cols = s.diff_rows, d
        self.input = None
        forcing = input_forcing_of(comp.dae)
        if forcing is not None:
            Bu = forcing.input_map
            if scipy.sparse.issparse(Bu):
                scaled = _on_rows(scipy.sparse.diags(self._einv) @ rows(Bu, s.diff_rows), d, n)
            else:
                scaled = _dense_on_rows(Bu, s.diff_rows, self._einv, d, n)
            self.input = _RowBlock(scaled, n)

    def add_forcing(self, Y, jet, d):
        """``Y += E^-1 f_d^(d)`` (scattered to the differential places) from the forcing's jet (`forcing_jet`)."""
        if jet is None:
            return Y
        kind, J = jet
        if kind == "input":
            return self.input.add_to(Y, J[d])
        f = J[d][self.diff_rows]
        f = f * (self._einv if f.ndim == 1 else self._einv[:, None])
        if Y.ndim == 2 and f.ndim == 1:
            f = f[:, None]
        Y[self.diff_cols] += f
        return Y

    def finish(self, Y, h):
        """``x'`` from ``Y = E^-1 (f_d - B_d x)`` (zero on x_a, modified in place) and the constraints' target `h`."""
        if self._cont.size:
            mu = self._schur.solve(self.C_c @ Y - h[self._cont])
            Y = self.P.add_to(Y, mu, -1.0)
        if self._term.size:
            Y[self.alg_cols] = self.T_solver.solve(h[self._term] - self.C_td @ Y)
        return Y

    def rhs(self, comp, t, x):
        """``G x + g(t)`` of `comp` (its rate and forcing)."""
        jet = forcing_jet(comp, t)
        return self.apply(x, comp.lam, jet, *constraint_forcing(comp, jet))

    def forcing(self, comp, t, d):
        """``g^(d)(t)`` of `comp`."""
        jet = forcing_jet(comp, t, d)
        cg, dcg = constraint_forcing(comp, jet, d)
        return self.finish(self.add_forcing(np.zeros(self.n), jet, d), comp.lam * cg + dcg)

    def apply(self, x, lam, jet=None, cg=None, dcg=None):
        """``G x + g`` (``jet=None``: ``G x``) at the rate `lam`; `x` of shape (n,) or (n, m)."""
        Y = self.G_d @ x
        if Y.dtype != np.float64 or not Y.flags.writeable:
            Y = np.array(Y, dtype=float)
        Y = self.add_forcing(Y, jet, 0)
        Cx = self.C @ x
        if cg is None:
            h = -lam * Cx
        else:
            if x.ndim == 2:
                cg, dcg = cg[:, None], dcg[:, None]
            h = -lam * (Cx - cg) + dcg
        return self.finish(Y, h)


def _dense_on_rows(M, take, scale, where, n):
    """``diag(scale) M[take]`` (dense `M`) as an n x c column-major array with row i at ``where[i]`` (others zero)."""
    out = np.zeros((n, M.shape[1]), order="F")
    take, where = _as_slice(take), _as_slice(where)  # the usual order: slices, not gathers and scatters
    if isinstance(where, slice):
        np.multiply(M[take], scale[:, None], out=out[where])  # one blocked pass from row- to column-major
    else:
        out[where] = M[take] * scale[:, None]
    return out


def _as_slice(idx):
    """`idx` as a slice when it is ``start, start + 1, ...``; else `idx`."""
    idx = np.asarray(idx)
    if idx.size and idx[-1] - idx[0] == idx.size - 1 and np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx
