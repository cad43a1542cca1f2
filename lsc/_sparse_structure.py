"""Recognising a semi-explicit DAE of Hessenberg form and its constraint rows, from sparse ``A`` and ``B``.

After permuting rows and columns, ``A = [[E, 0], [0, 0]]`` with ``E``
invertible: differential rows and unknowns ``d``, algebraic ones ``a``. The
constraints come from the Hessenberg recursion: level 0 is the algebraic
equations ``B_a x = f_a``; a row whose part on ``x_a`` is zero is
differentiated once more with ``x_d' = E^-1 (f_d - B_d x)`` substituted,

    C_(j+1) = -C_j^d E^-1 B_d,       cg_(j+1) = cg_j' - C_j^d E^-1 f_d,

and a row whose part on ``x_a`` is not zero is *terminal*. The stacked
``x_a`` parts of the terminal rows must form an invertible square matrix
``T``: then the terminal rows' derivatives give ``x_a'``. This covers
semi-explicit index 1 (``B_aa`` invertible), Hessenberg index 2
(``B_a E^-1 B_(d,a)`` invertible: Stokes, an RCL circuit with a loop of
capacitors and a voltage source) and index 3 (constrained mechanical
systems), and mixtures row by row. Every row is a combination of the
derivative array's equations that eliminates all derivatives, so the rows
span the same space as the dense set-up's ``Z2^T F`` (both have ``a`` rows:
the codimension of the solution manifold).
"""

import numpy as np
import scipy.sparse

from ._sparse_lu import diagonal_of, factorize

__all__ = ["MAX_LEVELS", "HessenbergForm", "SparseStructureError", "hessenberg_form"]

# Constraint levels (the differentiation index) the recursion follows before giving up.
MAX_LEVELS = 8
# A row's part on the algebraic unknowns counts as zero below this fraction of the row's norm (cancellation in
# the products C_j E^-1 B_d leaves rounding where the structure has none).
_ZERO_PART = 1e-13
# E^-1 applied to constraint rows by a sparse LU (non-diagonal E) gives dense rows: at most this many entries.
_DENSE_ROWS_LIMIT = 2**25


class SparseStructureError(ValueError):
    """The sparse set-up does not recognise the DAE's structure (the message says what it needs)."""


def rows(M, idx):
    """Rows `idx` of sparse `M` (an empty selection keeps the column count)."""
    return M[idx] if len(idx) else scipy.sparse.csr_matrix((0, M.shape[1]))


def cols(M, idx):
    """Columns `idx` of sparse `M`."""
    return M[:, idx] if len(idx) else scipy.sparse.csr_matrix((M.shape[0], 0))


def _row_norms(M):
    M = scipy.sparse.csr_matrix(M)
    return np.sqrt(np.asarray(M.multiply(M).sum(axis=1)).ravel())


def _scatter_columns(M, where, n):
    """``M P`` where ``P`` selects rows `where` of the identity: `M`'s column j becomes column ``where[j]``."""
    M = scipy.sparse.coo_matrix(M)
    return scipy.sparse.csr_matrix((M.data, (M.row, np.asarray(where)[M.col])), shape=(M.shape[0], n))


class HessenbergForm:
    """The semi-explicit structure of ``A x' + B x = f`` and its constraint rows.

    Attributes
    ----------
    n : int
    diff_rows, diff_cols, alg_rows, alg_cols : ndarray of int
        Differential rows/unknowns (where ``A`` is nonzero, ordered so that
        ``E = A[diff_rows][:, diff_cols]``) and algebraic ones.
    E : scipy.sparse.csr_matrix
        The invertible block of ``A``; ``E_diag`` its diagonal when diagonal (else None).
    B_d : scipy.sparse.csr_matrix
        The differential rows of ``B``.
    C : scipy.sparse.csr_matrix, shape (a, n)
        Constraint rows, level by level: ``C x = cg(t)`` on the solution manifold.
    Gamma : list of scipy.sparse.csr_matrix, each (a, n)
        ``cg(t) = sum_i Gamma[i] f^(i)(t)``.
    terminal : ndarray of bool, shape (a,)
        Rows whose part on the algebraic unknowns is nonzero (not differentiated further).
    T_solver
        Factorization of those rows' part on the algebraic unknowns (invertible).
    parent : ndarray of int, shape (a,)
        For a row of level >= 1, the row of the level before whose derivative it is; -1 on level 0.
    level_sizes : list of int
        Constraint rows per level.
    index : int
        Number of levels: the differentiation index.
    """

    def __init__(self, **fields):
        self.__dict__.update(fields)

    @property
    def n_constraints(self):
        return self.C.shape[0]

    def describe(self):
        """One line: the kind of structure, the equations, the constraint rows per level."""
        kinds = {0: "an ODE", 1: "semi-explicit index 1"}
        kind = kinds.get(self.index, f"Hessenberg index {self.index}")
        return (f"{kind}: {self.diff_rows.size} differential and {self.alg_rows.size} algebraic equations, "
                f"constraint rows per level {self.level_sizes}, E {'diagonal' if self.E_diag is not None else 'sparse'}")


def _split_A(A):
    """``(diff_rows, diff_cols, E, E_diag, E_solver)``: the nonzero rows and columns of `A` and its invertible block."""
    A = scipy.sparse.csr_matrix(A)
    A.eliminate_zeros()
    n = A.shape[0]
    diff_rows = np.flatnonzero(np.diff(A.indptr) > 0)
    diff_cols = np.flatnonzero(np.bincount(A.indices, minlength=n) > 0)
    if diff_rows.size != diff_cols.size:
        raise SparseStructureError(
            f"A has {diff_rows.size} nonzero rows but {diff_cols.size} nonzero columns: the sparse set-up needs a "
            "semi-explicit DAE, A = [[E, 0], [0, 0]] after permuting rows and columns with E square and invertible"
        )
    E = cols(rows(A, diff_rows), diff_cols).tocsr()
    if E.nnz == diff_rows.size and np.all(np.diff(E.indptr) == 1):  # a permuted diagonal: order the unknowns along it
        diff_cols = diff_cols[E.indices]
        E = cols(rows(A, diff_rows), diff_cols).tocsr()
    E_diag = diagonal_of(E)
    try:
        E_solver = factorize(E, "E (the block of A on the differential rows and unknowns)")
        E_solver.check()
    except np.linalg.LinAlgError as exc:
        raise SparseStructureError(f"{exc} The sparse set-up needs A = [[E, 0], [0, 0]] (permuted) with E "
                                   "invertible") from None
    return diff_rows, diff_cols, E, E_diag, E_solver


def _e_inverse_rows(Y_rows, E_solver, E_diag):
    """``Y E^-1`` for sparse rows ``Y`` (diagonal E: exact sparse; otherwise sparse LU solves, dense rows)."""
    if E_diag is not None:
        return scipy.sparse.csr_matrix(Y_rows @ scipy.sparse.diags(1.0 / E_diag))
    r, nd = Y_rows.shape
    if r * nd > _DENSE_ROWS_LIMIT:
        raise SparseStructureError(
            f"the constraint rows need E^-1 applied to {r} rows of length {nd}, which a non-diagonal E makes dense "
            f"({r * nd} entries > {_DENSE_ROWS_LIMIT}); the sparse set-up needs a diagonal E (lumped mass or "
            "capacitance matrices) for this many constraints"
        )
    Z = E_solver.solve(Y_rows.T.toarray(), trans="T").T  # exact zeros stay where no fill path reaches
    return scipy.sparse.csr_matrix(Z)


def _terminal_rows(C, alg_cols, level):
    """``(C, terminal)``: rows with a nonzero part on the algebraic unknowns; rounding there set to zero."""
    norms, part_norms = _row_norms(C), _row_norms(cols(C, alg_cols))
    if np.any(norms == 0.0):
        raise SparseStructureError(
            f"a constraint row of level {level} is zero (an equation 0 = f_i(t)): the DAE is not uniquely solvable, "
            "or not of Hessenberg form"
        )
    terminal = part_norms > _ZERO_PART * norms
    small = ~terminal & (part_norms > 0.0)
    if np.any(small):  # rounding on the algebraic unknowns: structurally zero there
        mask = np.zeros(C.shape[1], bool)
        mask[alg_cols] = True
        C = C.tocoo()
        keep = ~(np.isin(C.row, np.flatnonzero(small)) & mask[C.col])
        C = scipy.sparse.csr_matrix((C.data[keep], (C.row[keep], C.col[keep])), shape=C.shape)
    return C, terminal


def _levels(B, diff_rows, diff_cols, alg_rows, alg_cols, E_solver, E_diag, max_levels):
    """The recursion: lists of constraint rows, their forcing maps and terminal masks, level by level."""
    n = B.shape[0]
    B_d = rows(B, diff_rows).tocsr()
    C = rows(B, alg_rows).tocsr()  # level 0: the algebraic equations B_a x = f_a
    Gamma = [_scatter_columns(scipy.sparse.identity(alg_rows.size, format="csr"), alg_rows, n)]
    levels, gammas, terminals, parents = [], [], [], [np.full(C.shape[0], -1)]
    offset = 0
    while C.shape[0]:
        if len(levels) == max_levels:
            raise SparseStructureError(
                f"constraint rows keep vanishing on the algebraic unknowns after {max_levels} levels: the index "
                f"exceeds {max_levels} or the DAE is not of Hessenberg form"
            )
        C, terminal = _terminal_rows(C, alg_cols, len(levels))
        levels.append(C)
        gammas.append(Gamma)
        terminals.append(terminal)
        cont = np.flatnonzero(~terminal)
        if not cont.size:
            break
        parents.append(offset + cont)  # the next level's row j is the derivative of this level's row cont[j]
        offset += C.shape[0]
        Y = _e_inverse_rows(cols(rows(C, cont), diff_cols), E_solver, E_diag)
        Gamma = [-_scatter_columns(Y, diff_rows, n)] + [g[cont] for g in Gamma]
        C = scipy.sparse.csr_matrix(-(Y @ B_d))
        C.eliminate_zeros()
    return B_d, levels, gammas, terminals, np.concatenate(parents[: len(levels)]) if levels else np.zeros(0, int)


def hessenberg_form(A, B, max_levels=MAX_LEVELS):
    """The `HessenbergForm` of sparse ``A``, ``B``; `SparseStructureError` naming what is missing otherwise."""
    B = scipy.sparse.csr_matrix(B)
    n = B.shape[0]
    diff_rows, diff_cols, E, E_diag, E_solver = _split_A(A)
    in_d = np.zeros(n, bool)
    in_d[diff_rows] = True
    alg_rows = np.flatnonzero(~in_d)
    in_d[:] = False
    in_d[diff_cols] = True
    alg_cols = np.flatnonzero(~in_d)
    B_d, levels, gammas, terminals, parent = _levels(B, diff_rows, diff_cols, alg_rows, alg_cols, E_solver, E_diag,
                                             max_levels)
    index = len(levels)
    C = scipy.sparse.vstack(levels).tocsr() if levels else scipy.sparse.csr_matrix((0, n))
    terminal = np.concatenate(terminals) if terminals else np.zeros(0, bool)
    Gamma = [scipy.sparse.vstack([g[i] if i < len(g) else scipy.sparse.csr_matrix((lv.shape[0], n))
                                  for g, lv in zip(gammas, levels)]).tocsr() for i in range(index)]
    # each algebraic equation's chain ends in one terminal row: T = C[terminal][:, alg_cols] is square
    T = cols(rows(C, np.flatnonzero(terminal)), alg_cols)
    try:
        T_solver = factorize(T, "T (the terminal constraint rows on the algebraic unknowns)")
        T_solver.check()
    except np.linalg.LinAlgError:
        raise SparseStructureError(
            "the terminal constraint rows' parts on the algebraic unknowns (T) are singular: they depend on each "
            "other, so a combination of them is a further hidden constraint. The sparse set-up needs T invertible "
            "(Hessenberg form: B_aa invertible for index 1, B_a E^-1 B_(d,a) for index 2, "
            "B_a E^-1 B_(d,d) E^-1 B_(d,a) for index 3)"
        ) from None
    return HessenbergForm(n=n, diff_rows=diff_rows, diff_cols=diff_cols, alg_rows=alg_rows, alg_cols=alg_cols,
                          E=E, E_diag=E_diag, E_solver=E_solver, B_d=B_d, C=C, Gamma=Gamma, terminal=terminal, T_solver=T_solver, parent=parent,
                          level_sizes=[lv.shape[0] for lv in levels], index=index)
