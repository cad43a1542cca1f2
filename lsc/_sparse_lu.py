"""Sparse LU factorizations for the sparse set-up: one place that chooses the solver and judges singularity.

SciPy's SuperLU (`scipy.sparse.linalg.splu`, COLAMD ordering) is used: on
the saddle-point and step matrices of the benchmark families it was the
fastest of the direct solvers installable from PyPI without system
libraries that was measured (examples/bench_sparse.py ``--solvers``,
docs/reference/benchmarks.md), and it needs no dependency beyond SciPy.
"""

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

__all__ = ["SINGULAR_RCOND", "SparseLU", "factorize"]

# A matrix whose reciprocal condition number (1-norm estimate) is below this is treated as singular:
# solves through it would have no correct digit to speak of.
SINGULAR_RCOND = 1e-13


class SparseLU:
    """``M = P L U Q`` of a square sparse matrix; `solve` takes vectors or matrices (columns)."""

    def __init__(self, M, what):
        self.what = what
        self.shape = M.shape
        M = scipy.sparse.csc_matrix(M)
        self._norm1 = float(abs(M).sum(axis=0).max()) if M.nnz else 0.0
        try:
            self._lu = scipy.sparse.linalg.splu(M, permc_spec="COLAMD")
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise np.linalg.LinAlgError(f"{what} is singular ({exc}).") from None
        self.nnz = self._lu.L.nnz + self._lu.U.nnz

    def solve(self, b, trans="N"):
        """``M^-1 b`` (``trans='T'``: ``M^-T b``)."""
        b = np.asarray(b, dtype=float)
        if b.size == 0:
            return np.zeros(b.shape)
        return self._lu.solve(b, trans=trans)

    def rcond(self):
        """An estimate of ``1 / (||M||_1 ||M^-1||_1)`` (a few solves, `scipy.sparse.linalg.onenormest`)."""
        n = self.shape[0]
        if n == 0:
            return 1.0
        if n <= 4:
            inv = self.solve(np.eye(n))
            return 1.0 / (self._norm1 * np.abs(inv).sum(axis=0).max())
        op = scipy.sparse.linalg.LinearOperator(
            self.shape, matvec=self.solve, rmatvec=lambda v: self.solve(v, trans="T"),
            matmat=self.solve, rmatmat=lambda V: self.solve(V, trans="T"), dtype=float)
        inv_norm = scipy.sparse.linalg.onenormest(op)
        return 1.0 / (self._norm1 * inv_norm) if inv_norm > 0 else np.inf

    def check(self, rcond=None):
        """Raise LinAlgError when the matrix is singular to working precision; return the rcond estimate."""
        rc = self.rcond()
        tol = SINGULAR_RCOND if rcond is None else rcond
        if not rc > tol:
            raise np.linalg.LinAlgError(f"{self.what} is singular to working precision (reciprocal condition "
                                        f"{rc:.1e} <= {tol:.1e}).")
        return rc


class DiagonalSolver:
    """The `SparseLU` interface for a diagonal matrix."""

    def __init__(self, d, what):
        self.what, self.shape, self.d = what, (d.size, d.size), np.asarray(d, dtype=float)
        self.nnz = d.size
        if np.any(self.d == 0.0):
            raise np.linalg.LinAlgError(f"{what} is singular (a zero diagonal entry).")
        self._inv = 1.0 / self.d

    def solve(self, b, trans="N"):
        b = np.asarray(b, dtype=float)
        return b * (self._inv if b.ndim == 1 else self._inv[:, None])

    def rcond(self):
        a = np.abs(self.d)
        return float(a.min() / a.max()) if a.size else 1.0

    check = SparseLU.check


def diagonal_of(M):
    """The diagonal of sparse `M` when `M` is diagonal, else None."""
    M = scipy.sparse.coo_matrix(M)
    if M.shape[0] != M.shape[1] or np.any(M.row != M.col):
        return None
    d = np.zeros(M.shape[0])
    np.add.at(d, M.row, M.data)
    return d


def factorize(M, what):
    """A solver for square sparse `M`: diagonal when it is, SuperLU otherwise (LinAlgError when singular)."""
    d = diagonal_of(M)
    return DiagonalSolver(d, what) if d is not None else SparseLU(M, what)
