"""The standard derivative array at one time, factorized: an SVD, a block-column QR, or an LU warm-started nearby.

Every completion reads the same few quantities of the standard array
``J w = -F x + g``: ``Z2`` (orthonormal basis of its left null space), the
constraint matrix ``C = Z2^T F`` and its forcing ``cg``, the first ``n`` rows
of ``J^+`` and products with ``F``, the forcing map and ``J^+``. `_Factors`
provides them from one SVD of ``J`` (which also decides the rank and checks
1-fullness) or, for time-varying arrays of 100 rows and more, when asked
(``block``), from a pivoted QR found block column by block column
(`lsc._structured_tv.BlockQR`, ``O(k^2 n^3)``) or, at a time near one
already factorized, from one LU of ``J`` bordered by the old null spaces
(`_Factors._warm`). Both prove their rank decisions and fall back to the SVD
on any doubt, so the SVD's decisions, warnings and refusals stay.
For constant coefficients `lsc._structured.StructuredFactors` offers the
same interface from n-sized blocks.
"""

import numpy as np
import scipy.linalg

from ._derivative_array import array_jets
from ._exceptions import IndexDeterminationError
from ._linalg import default_rcond, numerical_rank
from ._structured import ConstraintBasis, StructuredFallback
from ._structured_tv import BlockQR

# A derivative array is 1-full when null(J) has no x' component; beyond this
# sine of the angle between null(J) and {x' = 0} it is not.
_ONE_FULL_TOL = np.sqrt(np.finfo(float).eps)
# Block-column QR or warm-started LU instead of the SVD of J (time-varying): only from this many rows of J on
# (below, the SVD is cheaper: 45 us against 490 us for the block QR at 20 rows), and for the LU with this
# safety factor on every rank test.
WARM_MIN_ROWS = 100
_WARM_MARGIN = 10.0


def _norm2_if_above(X, tol):
    """``||X||_2`` when it may exceed `tol`; the cheaper Frobenius norm (an upper bound) otherwise."""
    frobenius = np.sqrt(np.einsum("ij,ij->", X, X))
    return frobenius if frobenius <= tol else np.linalg.norm(X, 2)


class _Factors(ConstraintBasis):
    """The standard derivative array at one time, factorized once.

    Shared by all three methods: the constraints ``c = Z2^T (F x - g)`` are
    always those of the *standard* array, so residuals of different methods
    compare.

    ``fmap`` selects what the forcing quantities are: None (constant
    coefficients) keeps them as matrices acting on
    ``fstack = [f, f', ..., f^(k+q)]``, so a completion yields the map
    ``W``; a vector ``fstack(t)`` turns them into values at ``t``.
    """

    def __init__(self, dae, k, t, q, rcond, fmap=None, expected_rank=None, reference=None, block=False):
        n = dae.n
        self.warm, self.block, self.block_note = False, None, None
        self.n, self.t = n, float(t)
        self.jets = jets = array_jets(dae, k, t, None, q)
        J = jets.J[0]
        if not (block and J.shape[0] >= WARM_MIN_ROWS and self._block_qr(J, rcond, expected_rank)):
            if reference is None or not self._warm(J, reference, rcond):
                self._svd(J, k, t, rcond, expected_rank)
        self.Z2 = self._Z2
        self.C = self.Z2.T @ jets.F[0]
        if fmap is None:
            self.Lg = jets.L
            self.f0 = np.eye(n, jets.L.shape[2])
        else:
            self.Lg = jets.forcing(fmap)
            self.f0 = fmap[:n]
        # Constraint residual c = C x - cg.
        self.cg = self.Z2.T @ self.Lg[0]
        self._C_svd = None
        self._first_rows = None
        self.A0, self.B0 = J[:n, :n], jets.F[0][:n]
        self.has_Jd = q >= 1 and bool(np.any(jets.J[1]))

    def _svd(self, J, k, t, rcond, expected_rank):
        n = self.n
        # numpy's svd (LAPACK gesdd, like scipy's) has a fraction of scipy's call overhead, which
        # dominates a time-varying rhs for arrays of a few dozen rows; the jets are finite (checked).
        self.U, self.s, self.Vt = np.linalg.svd(J)
        self.rank = numerical_rank(self.s, J.shape, rcond, what=f"derivative array J (k={k}, t={t:g})")
        if expected_rank is not None and self.rank != expected_rank:
            raise IndexDeterminationError(
                f"the rank of the derivative array (k={k}) changes at t={t!r}: {self.rank} instead of "
                f"{expected_rank}. The DAE is not solvable with constant rank here (thesis (A3)); "
                "the completion would jump."
            )
        # 1-fullness: the null space of J must not move x' (x' unique).
        null_x = _norm2_if_above(self.Vt[self.rank :, :n], _ONE_FULL_TOL) if self.rank < J.shape[1] else 0.0
        if null_x > _ONE_FULL_TOL:
            raise IndexDeterminationError(
                f"the derivative array with k={k} differentiations does not determine x' at t={t!r} "
                f"(not 1-full: its null space moves x' by {null_x:.1e}). Pass t_span to `complete` so k "
                "is decided over the interval, or a larger k."
            )
        self._Z2 = self.U[:, self.rank :]
        self.N = self.Vt[self.rank :].T
        self.scale = self.s[0] if self.s.size else 0.0

    def _block_qr(self, J, rcond, expected_rank):
        """Null spaces and ``J^+`` from the block-column QR (`lsc._structured_tv.BlockQR`); False when it declines.

        It declines (`block_note` says why) whenever a rank decision or 1-fullness is not proven clear-cut,
        and when the rank differs from `expected_rank`: the caller's SVD then decides, warns or refuses.
        """
        try:
            fac = BlockQR(J, self.n, rcond)
        except StructuredFallback as exc:
            self.block_note = str(exc)
            return False
        if expected_rank is not None and fac.rank != expected_rank:
            self.block_note = f"rank {fac.rank} instead of {expected_rank}"
            return False
        self.block, self.rank, self._Z2, self.N, self.scale = fac, fac.rank, fac.Z2, fac.N, fac.scale
        self.U = self.s = self.Vt = None
        return True

    def _warm(self, J, ref, rcond):
        """Null spaces and ``J^+`` from one LU, warm-started from `ref` (factors at a nearby time).

        For square ``J`` of rank r with orthonormal bases ``Z2`` (left) and
        ``N`` (right) of its null spaces, ``M = J + s Z2 N^T`` is regular and
        ``M^-1 = J^+ + N Z2^T / s``. With the bases of a nearby time, ``M``
        is still regular, and ``range(M^-1 Z2_ref)``, ``range(M^-T N_ref)``
        are exactly the new null spaces. The rank is verified, not assumed:
        ``||J N||`` and ``||Z2^T J||`` below the threshold (rank <= r), an
        estimate of ``||J^+||`` well above its inverse (rank >= r), and
        1-fullness; any doubt returns False and the caller takes the SVD,
        which decides (and refuses) exactly as without a reference.
        """
        if J.shape[0] != J.shape[1] or ref.N.shape[1] != ref._Z2.shape[1] or ref.rank == 0:
            return False
        s = ref.scale
        try:
            Z2, N = ref._Z2, ref.N
            lu = scipy.linalg.lu_factor(J + s * (Z2 @ N.T), check_finite=False)
            N = np.linalg.qr(scipy.linalg.lu_solve(lu, Z2, check_finite=False))[0]
            Z2 = np.linalg.qr(scipy.linalg.lu_solve(lu, ref.N, trans=1, check_finite=False))[0]
            M = J + s * (Z2 @ N.T)
            lu = scipy.linalg.lu_factor(M, check_finite=False)
        except (np.linalg.LinAlgError, ValueError):
            return False
        fro = np.sqrt(np.einsum("ij,ij->", J, J))  # ||J||_2 lies in [fro / sqrt(p), fro]
        rc_J = default_rcond(J.shape) if rcond is None else rcond
        anorm = np.abs(M).sum(axis=0).max()
        rc, info = scipy.linalg.lapack.dgecon(lu[0], anorm, norm="1")
        # ||J^+||_2 <= ||M^-1||_2 + 1/s <= sqrt(p) ||M^-1||_1 + 1/s; gecon's estimate of ||M^-1||_1 is a
        # lower bound (rarely off by more than 3), hence the margin on it too.
        pinv_bound = _WARM_MARGIN * np.sqrt(J.shape[0]) / (rc * anorm) + 1.0 / s if rc > 0 else np.inf
        if (info != 0 or not pinv_bound * rc_J * fro * _WARM_MARGIN < 1.0
                or np.linalg.norm(J @ N, 2) > rc_J * fro / np.sqrt(J.shape[0]) / _WARM_MARGIN
                or np.linalg.norm(Z2.T @ J, 2) > rc_J * fro / np.sqrt(J.shape[0]) / _WARM_MARGIN
                or _norm2_if_above(N[: self.n].T, _ONE_FULL_TOL) > _ONE_FULL_TOL):
            return False
        self._lu, self._Z2, self.N, self.scale = lu, Z2, N, s
        self.rank, self.warm = ref.rank, True
        self.U = self.s = self.Vt = None
        return True

    def times_F(self, X, d):
        """``X @ F^(d)``."""
        return X @ self.jets.F[d]

    @property
    def rounding_scale(self):
        """``||F|| / sigma_min(J)``: entries of ``G = J^+ F`` that cancel are left at rounding relative to it."""
        return np.linalg.norm(self.jets.F[0], 2) / self.s[self.rank - 1]

    def times_L(self, X, d):
        """``X @ Lg[d]``: the d-th derivative's forcing map (or value)."""
        return X @ self.Lg[d]

    @property
    def first_rows(self):
        """The first n rows of ``J^+`` (thesis ``V^T J^+``); never the whole, formed once."""
        if self._first_rows is None:
            r, n = self.rank, self.n
            if self.block is not None:
                self._first_rows = self.block.first_rows
                return self._first_rows
            if self.warm:
                E = np.eye(self._lu[0].shape[0], n)
                Y = scipy.linalg.lu_solve(self._lu, E, trans=1, check_finite=False).T
                self._first_rows = Y - (self.N[:n] / self.scale) @ self._Z2.T
                return self._first_rows
            self._first_rows = (self.Vt[:r, :n].T / self.s[:r]) @ self.U[:, :r].T
        return self._first_rows

    def times_pinv(self, X):
        """``X @ J^+`` from the SVD factors."""
        r = self.rank
        if self.block is not None:
            return self.block.times_pinv(X)
        if self.warm:
            XM = scipy.linalg.lu_solve(self._lu, np.asarray(X).T, trans=1, check_finite=False).T
            return XM - ((X @ self.N) / self.scale) @ self._Z2.T
        return ((X @ self.Vt[:r].T) / self.s[:r]) @ self.U[:, :r].T

    def index_one_solve(self, G_c, W_c, rcond, t):
        """``(G, W)`` from ``[Z1^T A; C] x' = [-Z1^T B x + Z1^T f; G_c x + W_c]``, Z1 an orthonormal basis of range(A T2)."""
        n, A = self.n, self.A0
        AT2 = A @ self.T2
        Z1, s1, _ = np.linalg.svd(AT2, full_matrices=False)
        if numerical_rank(s1, AT2.shape, rcond, what="A T2") < AT2.shape[1]:
            raise IndexDeterminationError(f"A T2 is rank deficient at t={t!r}: the DAE is not solvable.")
        M = np.vstack([Z1.T @ A, self.C])
        G_num = np.vstack([-Z1.T @ self.B0, G_c])
        W_num = np.concatenate([Z1.T @ self.f0, W_c], axis=0)
        # one LU for both right-hand sides (W_num is a matrix or, time-varying, a vector)
        sol = np.linalg.solve(M, np.column_stack([G_num, W_num]))
        return sol[:, :n], sol[:, n:].reshape(W_num.shape)
