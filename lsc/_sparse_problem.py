"""Sparse linear DAEs ``A x' + B x = f(t)``: scipy.sparse constant coefficients, forcing from an input map.

`SparseLinearDAE` is what `LinearDAE` returns when ``A`` or ``B`` is a
scipy.sparse matrix. It keeps the coefficients sparse (CSR) and never forms
an n x n array behind the user's back: the dense path reads ``dae.A(t)``
only up to `DENSE_MAX` unknowns (an explicit, documented densification) and
is refused beyond. `InputForcing` is the forcing ``f(t) = B_u u(t)`` of a
(sparse or dense) input map, whose structure the sparse set-up uses.
"""

import numbers

import numpy as np
import scipy.sparse

from ._exceptions import DimensionError
from ._problem import ROW_SPREAD, LinearDAE
from ._timefunc import TimeFunction, _shape_str, as_time_function
from ._validate import check_state

__all__ = ["DENSE_MAX", "InputForcing", "SparseLinearDAE", "is_sparse_dae", "sparse_equilibration"]

# Largest n for which a sparse DAE may be handed to the dense path (dae.A(t) as an array). The dense set-up
# forms the derivative array, (k + 2) n x (k + 1) n: at n = 2,000 and index 3 that is 80 x 10^6 entries
# (640 MB) and its SVD; the structured set-up peaks at 460 MiB there. Beyond, the dense path is refused.
DENSE_MAX = 2000


def is_sparse_dae(dae):
    """Whether `dae` holds scipy.sparse coefficients (a `SparseLinearDAE`)."""
    return isinstance(dae, SparseLinearDAE)


def _as_csr(name, value, n=None):
    """`value` (scipy.sparse or array_like, real, finite, square) as a CSR matrix of float64."""
    if callable(value) or isinstance(value, TimeFunction):
        raise TypeError(
            f"`{name}` must be a constant matrix when the other coefficient is scipy.sparse: sparse DAEs have "
            f"constant coefficients; found {type(value).__name__}."
        )
    if scipy.sparse.issparse(value):
        if np.iscomplexobj(value.data):
            raise TypeError(f"`{name}` must be real; complex coefficients are not supported.")
        M = scipy.sparse.csr_matrix(value, dtype=float)
    else:
        arr = np.asarray(value)
        if arr.dtype == object or arr.dtype.kind not in "biuf":
            raise TypeError(f"`{name}` must be a real scipy.sparse matrix or array_like; found {type(value).__name__}.")
        M = scipy.sparse.csr_matrix(arr.astype(float))
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise DimensionError(f"`{name}` must be a square matrix: expected (n, n), got {_shape_str(M.shape)}.")
    if n is not None and M.shape != (n, n):
        raise DimensionError(f"`A` and `B` must have the same shape: expected B of shape {_shape_str((n, n))}, "
                             f"got {_shape_str(M.shape)}.")
    if not np.all(np.isfinite(M.data)):
        raise ValueError(f"`{name}` must be finite; found NaN or inf entries.")
    M.sum_duplicates()
    M.eliminate_zeros()
    return M


class SparseCoefficient(TimeFunction):
    """A constant scipy.sparse coefficient. As a `TimeFunction` it is dense, and only up to `DENSE_MAX`.

    ``jet`` (what the dense path reads) returns the dense array for ``n <= DENSE_MAX`` and raises a
    ValueError naming the sparse set-up beyond: nothing densifies a large model silently.
    """

    is_constant = True

    def __init__(self, name, matrix):
        super().__init__(name, matrix.shape)
        self.sparse = matrix

    def jet(self, t, order):
        n = self.shape[0]
        if n > DENSE_MAX:
            raise ValueError(
                f"`{self.name}` is a scipy.sparse matrix with n = {n} > {DENSE_MAX} unknowns: the dense set-up "
                f"would form n x n arrays ({8 * n * n / 2**30:.3g} GiB each) and the derivative array. Use "
                "lsc.complete(dae, 'alternative', lam=...) (the sparse set-up, for semi-explicit DAEs of "
                "Hessenberg form) or pass a dense array for a small model."
            )
        out = np.zeros((order + 1,) + self.shape)
        out[0] = self.sparse.toarray()
        return out


class InputForcing:
    """The forcing ``f(t) = B_u u(t)`` of an input map ``B_u`` (n x m, sparse or dense) and inputs ``u(t)``.

    Pass it as ``f`` to `LinearDAE`. It is a callable ``f(t, d)`` (the d-th
    derivative ``B_u u^(d)(t)``) with a ``jet`` method, so every path of lsc
    accepts it; the sparse set-up also maps ``B_u`` once through the
    completion, so an evaluation costs O(n m) instead of a pass over n-vectors
    per derivative.

    Parameters
    ----------
    input_map : scipy.sparse matrix or array_like, shape (n, m)
        Real, finite.
    u : array_like, sympy expression or callable
        The inputs, shape ``(m,)``: constant, sympy in ``t``, or a callable
        ``u(t, d)`` returning the d-th derivative (see `LinearDAE`'s ``f``).

    Examples
    --------
    A mass pushed by ``u(t) = sin t``: ``x1' - x2 = 0, x2' = u``.

    >>> import numpy as np, scipy.sparse as sp, sympy
    >>> from lsc import InputForcing, LinearDAE
    >>> t = sympy.Symbol("t")
    >>> f = InputForcing(sp.csr_matrix([[0.0], [1.0]]), [sympy.sin(t)])
    >>> dae = LinearDAE(sp.identity(2), sp.csr_matrix([[0.0, -1.0], [0.0, 0.0]]), f)
    >>> f(0.0, 1)
    array([0., 1.])
    """

    def __init__(self, input_map, u):
        if scipy.sparse.issparse(input_map):
            M = scipy.sparse.csr_matrix(input_map, dtype=float)
            data = M.data
        else:
            M = np.asarray(input_map)
            if M.dtype == object or M.dtype.kind not in "biuf":
                raise TypeError(f"`input_map` must be a real scipy.sparse matrix or array_like; found "
                                f"{type(input_map).__name__}.")
            M = M.astype(float)
            data = M
        if M.ndim != 2:
            raise DimensionError(f"`input_map` must be a matrix: expected (n, m), got {_shape_str(M.shape)}.")
        if not np.all(np.isfinite(data)):
            raise ValueError("`input_map` must be finite; found NaN or inf entries.")
        self.input_map = M
        self.n, self.m = M.shape
        self.u = as_time_function("u", u, (self.m,))

    def jet(self, t, order):
        """``B_u u^(d)(t)`` for ``d = 0..order``, shape ``(order + 1, n)``."""
        U = self.u.jet(t, order)  # (order + 1, m)
        return np.asarray(self.input_map @ U.T).T.reshape(order + 1, self.n)

    def __call__(self, t, d):
        return self.jet(t, d)[d]

    def __repr__(self):
        kind = "sparse" if scipy.sparse.issparse(self.input_map) else "dense"
        return f"InputForcing(n={self.n}, m={self.m}, {kind} input map)"


def input_forcing_of(dae):
    """The `InputForcing` behind ``dae.f``, or None."""
    fn = getattr(dae.f, "fn", None)
    return fn if isinstance(fn, InputForcing) else None


class SparseLinearDAE(LinearDAE):
    """A linear DAE ``A x' + B x = f(t)`` with constant scipy.sparse ``A`` and ``B``.

    Made by `LinearDAE` when ``A`` or ``B`` is a scipy.sparse matrix (an
    array given with it is made sparse too). ``f`` is as for `LinearDAE`,
    or an `InputForcing`.

    Attributes
    ----------
    A_sparse, B_sparse : scipy.sparse.csr_matrix
        The coefficients.
    A, B : TimeFunction
        Dense views for the dense path, for ``n <= DENSE_MAX`` only.
    is_sparse : bool
        True.
    """

    is_sparse = True

    def __init__(self, A, B, f=None):
        A = _as_csr("A", A)
        B = _as_csr("B", B, A.shape[0])
        self.n = n = A.shape[0]
        self.A_sparse, self.B_sparse = A, B
        self.A, self.B = SparseCoefficient("A", A), SparseCoefficient("B", B)
        if isinstance(f, InputForcing) and f.n != n:
            raise DimensionError(f"`f`'s input map must have n = {n} rows: expected ({n}, m), got "
                                 f"{_shape_str(f.input_map.shape)}.")
        self.f = None if f is None else as_time_function("f", f, (n,))
        self.is_constant = True

    def __repr__(self):
        forcing = "none" if self.f is None else ("input map" if input_forcing_of(self) else
                                                 type(self.f).__name__.replace("Function", "").lower())
        return (f"LinearDAE(n={self.n}, sparse constant coefficients (nnz A = {self.A_sparse.nnz}, "
                f"B = {self.B_sparse.nnz}), forcing={forcing})")

    def residual(self, t, x, xdot):
        """The residual ``A xdot + B x - f(t)`` (sparse products)."""
        x = check_state("x", x, self.n)
        xdot = check_state("xdot", xdot, self.n)
        r = self.A_sparse @ xdot + self.B_sparse @ x
        if self.f is not None:
            r = r - self.f(t)
        return r


LinearDAE._sparse_class = SparseLinearDAE


# -- equilibration, as lsc._problem.equilibration does it on dense arrays --------------------------------------

# Magnitudes whose squares (and sums of up to 1e12 squares) stay finite and normal in double precision.
_SAFE_SQUARE = 1e150


def _norms(M, axis):
    """2-norms of the rows (axis=1) or columns (axis=0) of sparse `M`, without overflow near 1e308.

    When every nonzero magnitude lies in [1e-150, 1e150] the squares neither overflow nor underflow and are
    summed by one sparse product; otherwise each row's (column's) entries are divided by its largest
    magnitude before they are squared (segment by segment on the compressed arrays).
    """
    M = scipy.sparse.csr_matrix(M) if axis == 1 else scipy.sparse.csc_matrix(M)
    M.sum_duplicates()
    data, lengths = np.abs(M.data), np.diff(M.indptr)
    if not data.size:
        return np.zeros(lengths.size)
    if data.max() <= _SAFE_SQUARE and np.min(data, where=data > 0.0, initial=np.inf) >= 1.0 / _SAFE_SQUARE:
        squares = type(M)((data * data, M.indices, M.indptr), shape=M.shape)
        if axis == 0:
            squares = squares.T  # CSR: each column a row
        return np.sqrt(squares @ np.ones(squares.shape[1]))
    nonempty = lengths > 0
    starts = M.indptr[:-1][nonempty]
    big = np.zeros(lengths.size)
    if starts.size:
        big[nonempty] = np.maximum.reduceat(data, starts)
    unit = np.where(big > 0.0, big, 1.0)
    scaled = data * np.repeat(1.0 / unit, lengths)
    squares = np.zeros(lengths.size)
    if starts.size:
        squares[nonempty] = np.add.reduceat(scaled * scaled, starts)
    return np.sqrt(squares) * big


def _spread(values):
    nonzero = np.abs(values[values != 0.0])
    with np.errstate(over="ignore"):
        return nonzero.max() / nonzero.min() if nonzero.size else 1.0


def _power_of_two_scales(norms):
    scales = np.ones(norms.shape)
    nonzero = norms > 0.0
    scales[nonzero] = 2.0 ** -np.round(np.log2(norms[nonzero]))
    return scales


def _row_scales(A, B):
    norms = _norms(scipy.sparse.hstack([A, B]), axis=1)
    return _power_of_two_scales(norms) if _spread(norms) > ROW_SPREAD else np.ones(A.shape[0])


def _column_scales(A, B):
    norms = _norms(scipy.sparse.vstack([A, B]), axis=0)
    return _power_of_two_scales(norms) if _spread(norms) > ROW_SPREAD else np.ones(A.shape[1])


def _scaled(M, r, c):
    """``diag(r) M diag(c)`` as CSR, scaling the nonzeros in place of two sparse products."""
    M = scipy.sparse.csr_matrix(M)
    data = M.data * np.repeat(r, np.diff(M.indptr)) * c[M.indices]
    return scipy.sparse.csr_matrix((data, M.indices.copy(), M.indptr.copy()), shape=M.shape)


def sparse_equilibration(A, B):
    """``(r, c)``: the row and column scales `lsc._problem.equilibration` chooses, from sparse ``A``, ``B``.

    The same rules (row norms of ``[A, B]`` spread beyond `ROW_SPREAD`, then columns, the two orders
    compared by the spread of the scaled entries), on the nonzeros only. Each is None when not needed.
    """
    n = A.shape[0]
    ones = np.ones(n)
    r = _row_scales(A, B)
    Ar, Br = _scaled(A, r, ones), _scaled(B, r, ones)
    if _spread(_norms(scipy.sparse.vstack([Ar, Br]), axis=0)) <= ROW_SPREAD:
        return (None if np.all(r == 1.0) else r), None
    candidates = [(r, _column_scales(Ar, Br))]
    c = _column_scales(A, B)
    candidates.append((_row_scales(_scaled(A, ones, c), _scaled(B, ones, c)), c))

    def spread(rc):
        S = scipy.sparse.hstack([_scaled(A, rc[0], rc[1]), _scaled(B, rc[0], rc[1])]).tocsr()
        return _spread(S.data)

    r, c = min(candidates, key=spread)
    return (None if np.all(r == 1.0) else r), (None if np.all(c == 1.0) else c)


def check_dense_size(n, what):
    """Refuse handing an n-unknown sparse problem to a dense computation beyond `DENSE_MAX`."""
    if isinstance(n, numbers.Integral) and n > DENSE_MAX:
        raise ValueError(f"{what} needs dense n x n arrays; n = {n} exceeds the limit {DENSE_MAX} for sparse problems.")
