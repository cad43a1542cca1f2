"""A rank-revealing QR of a time-varying derivative array, block column by block column.

The standard derivative array ``J`` (``k + 1`` block rows and columns of size
``n``) is block lower triangular: block row ``i`` touches block columns
``0..i`` only, with ``A`` on the diagonal. Sweeping the block columns from the
last to the first, each step sees one n-sized column block ``S_j`` (block row
``j`` on top of the ``d_j`` rows left over by the steps before it, ``d_j`` at
most the corank ``a``):

1. a QR with column pivoting ``S_j Pi_j = Q_j R_j`` decides its rank ``r_j``:
   the smallest ``r_j`` whose trailing ``R_j[r_j:, r_j:]`` (dropped, ``Delta``)
   is negligible;
2. ``Q_j^T`` turns the step's rows into ``r_j`` pivot rows, which no later
   step touches, and ``n + d_j - r_j`` rows left over for block columns
   ``0..j-1``.

After block column 0 the ``a`` rows left over are (up to ``Delta``) zero rows
of ``Q^T J``: their coefficients are an orthonormal basis ``Z2`` of the left
null space. Altogether ``Q^T J Pi = [[U_p, U_f], [0, 0]] + Delta`` with
``U_p`` upper triangular: a pivoted QR of ``J`` found with block operations of
cost ``O(k^2 n^3)`` (the dense SVD and LU are ``O(k^3 n^3)``). The steps of
block column 0 give the first rows of ``J^+`` directly: those pivot rows read
``q_0^T J = [R_0 Pi_0^T, 0, ..., 0]``, so ``X = Pi_0 R_0^-1 q_0^T`` solves
``X J = [I, 0, ...]``, and since ``q_0`` is orthogonal to ``Z2``, ``X`` is
already ``[I, 0, ...] J^+`` when ``J`` is 1-full (``r_0 = n``).

Rank decisions have the dense path's meaning (``rcond`` relative to
``sigma_max(J)``) and are *proven*, not assumed: ``||Delta||_F`` bounds the
singular values the decomposition discards and a triangular condition
estimate of ``U_p`` bounds the smallest one it keeps from below (with the
safety factors of the warm-started LU). Only when both lie farther than
``RANK_MARGIN`` from the threshold, the array is 1-full and the angle of its null
space to ``{x' = 0}`` is provably below the dense test's, is the result used:
otherwise `lsc._factors.Decline` says why and the caller takes the SVD, which
decides, warns or refuses as it always does.
"""

import numpy as np
import scipy.linalg
from scipy.linalg import lapack

from ._factors import Decline
from ._linalg import ONE_FULL_TOL, RANK_MARGIN, default_rcond

__all__ = ["BlockQR"]

# Safety factor on the triangular condition estimate (LAPACK's estimate of ||U^-1||_1 is a lower bound,
# rarely off by more than 3), as for the warm-started LU.
_EST_MARGIN = 10.0


def _sigma_max_bounds(J):
    """``(lower, upper)`` bounds of ``||J||_2``: three power steps from the largest column, and the Frobenius norm."""
    col = np.einsum("ij,ij->j", J, J)
    fro = float(np.sqrt(col.sum()))
    if fro == 0.0:
        return 0.0, 0.0
    v = J[:, int(np.argmax(col))].copy()
    lower = float(np.sqrt(col.max()))
    for _ in range(3):
        w = J.T @ v
        nw = np.linalg.norm(w)
        if nw == 0.0:
            break
        v = J @ (w / nw)
        lower = max(lower, float(np.linalg.norm(v)))
    return lower, fro


class BlockQR:
    """``Q^T J Pi = [[U_p, U_f], [0, 0]] + Delta`` of a block lower triangular array, by block columns.

    Parameters
    ----------
    J : ndarray, shape ((k+1) n, (k+1) n)
        The standard derivative array (`lsc._derivative_array.array_jets`).
    n : int
    rcond : float or None
        Relative rank threshold, as for the dense path.

    Attributes
    ----------
    rank : int
    Z2 : ndarray, shape (N, a)
        Orthonormal basis of the left null space.
    first_rows : ndarray, shape (n, N)
        ``[I, 0, ...] J^+``.

    Raises Decline when a rank decision is not proven clear-cut or
    ``J`` is not 1-full.
    """

    def __init__(self, J, n, rcond=None):
        N = J.shape[0]
        if J.shape != (N, N) or N % n:
            raise Decline(f"J of shape {J.shape} is not square in blocks of {n}")
        k = N // n - 1
        s_lo, s_hi = _sigma_max_bounds(J)
        if s_lo == 0.0:
            raise Decline("J is zero")
        rc = default_rcond(J.shape) if rcond is None else rcond
        budget2 = (rc * s_lo / RANK_MARGIN) ** 2 / (k + 1)  # each step's share of ||Delta||_F^2
        T = np.empty((N, N))    # Q^T J, pivot rows in step order (block column k first); rows >= rank unused
        Qt = np.zeros((N, N))   # Q^T: the same rows' coefficients of J's rows, the a null rows last
        E = np.zeros((0, N))    # rows left over, their entries in block columns 0..j
        coef = np.zeros((0, N))  # their coefficients
        pcols, fcols, row, delta2 = [], [], 0, 0.0
        for j in range(k, -1, -1):
            cols = slice(j * n, (j + 1) * n)
            d = E.shape[0]
            S = np.vstack([J[cols, cols], E[:, cols]]) if d else J[cols, cols]
            Q, R, piv = scipy.linalg.qr(S, pivoting=True, check_finite=False)
            trailing = np.cumsum(np.einsum("ij,ij->i", R, R)[::-1])[::-1]  # ||R[r:, r:]||_F^2 (R upper trapezoidal)
            trailing = np.append(trailing, 0.0)
            r = int(np.argmax(trailing[: n + 1] <= budget2))
            delta2 += trailing[r]
            QtR = Q.T[:, :n] @ J[cols, : j * n]  # the step's rows in block columns 0..j-1
            if d:
                QtR += Q.T[:, n:] @ E[:, : j * n]
            T[row : row + r, : j * n] = QtR[:r]
            T[row : row + r, j * n :] = 0.0
            T[row : row + r, j * n + piv] = R[:r]
            Qt[row : row + r, cols] = Q.T[:r, :n]
            coef_new = np.zeros((n + d - r, N))
            coef_new[:, cols] = Q.T[r:, :n]
            if d:
                Qt[row : row + r] += Q.T[:r, n:] @ coef
                coef_new += Q.T[r:, n:] @ coef
            pcols.append(j * n + piv[:r])
            fcols.append(j * n + piv[r:])
            E, coef, row = QtR[r:], coef_new, row + r
            if j == 0:
                r0, piv0, R0 = r, piv, R[:r, :r]
        self.rank, self.n, self.k = row, n, k
        self.Z2 = coef.T
        if r0 < n:
            raise Decline(f"block column 0 has rank {r0} < n: J is not 1-full, or nearly so")
        self._pcols, self._fcols = np.concatenate(pcols), np.concatenate(fcols)
        self._Up = T[:row, self._pcols]
        self._Uf = T[:row, self._fcols]
        self.delta, self.scale = np.sqrt(delta2), s_lo
        self._check(rc, s_lo, s_hi)
        self._Qt_p, self._piv0, self._R0 = Qt[:row], piv0, R0
        self._N = None

    def _check(self, rc, s_lo, s_hi):
        """Prove the rank decisions: ``sigma_(r+1)(J) <= ||Delta||_F`` well below the threshold, ``sigma_r(J) >=
        sigma_min(U_p) - ||Delta||`` well above it, and the null space's angle to ``{x' = 0}`` below the dense test's."""
        Up, rank, delta = self._Up, self.rank, self.delta
        if rank:
            anorm = np.abs(Up).sum(axis=0).max()
            rcu, info = lapack.dtrcon(Up.T, norm="I", uplo="L", diag="N")  # Up.T: Fortran order, no copy
            if info != 0 or rcu <= 0.0:
                raise Decline("the kept triangular factor is singular")
            # ||U^-1||_2 <= sqrt(rank) ||U^-1||_1, and the estimate of ||U^-1||_1 is a lower bound
            sigma_low = 1.0 / (_EST_MARGIN * np.sqrt(rank) / (rcu * anorm)) - delta
        else:
            sigma_low = np.inf
        if not delta * RANK_MARGIN <= rc * s_lo:
            raise Decline(f"the discarded part ({delta:.1e}) is not clearly below the threshold")
        if not sigma_low > RANK_MARGIN * rc * s_hi:
            raise Decline(f"the smallest kept singular value (>= {sigma_low:.1e}) is not clearly above the "
                                     f"threshold ({rc * s_hi:.1e})")
        if delta > 0.0 and not delta / sigma_low * _EST_MARGIN < ONE_FULL_TOL:
            raise Decline("1-fullness is not clear-cut")

    @property
    def first_rows(self):
        """``[I, 0, ...] J^+ = Pi_0 R_0^-1 q_0^T`` (n x N)."""
        n = self.n
        Y = scipy.linalg.solve_triangular(self._R0, self._Qt_p[-n:], check_finite=False)
        X = np.empty_like(Y)
        X[self._piv0] = Y
        return X

    @property
    def N(self):
        """Orthonormal basis of the right null space, ``Pi [-U_p^-1 U_f; I]`` orthonormalized."""
        if self._N is None:
            size = self._Qt_p.shape[1]
            Nn = np.zeros((size, self._fcols.size))
            Nn[self._pcols] = -scipy.linalg.solve_triangular(self._Up, self._Uf, check_finite=False)
            Nn[self._fcols] = np.eye(self._fcols.size)
            self._N = np.linalg.qr(Nn)[0] if Nn.shape[1] else Nn
        return self._N

    def times_pinv(self, X):
        """``X J^+ = (X P_row) Pi [U_p^-1; 0] Q_p^T``, ``P_row`` the projector onto range(J^T)."""
        X = np.asarray(X, dtype=float)
        N = self.N
        Y = X - (X @ N) @ N.T if N.shape[1] else X
        Z = scipy.linalg.solve_triangular(self._Up, Y[:, self._pcols].T, trans="T", check_finite=False).T
        return Z @ self._Qt_p
