"""The standard derivative array factorized densely: an SVD at one time or at many, a warm LU or a block QR at one.

`DenseFactors` is the `lsc._factors.Factors` backend for any coefficients. `DenseFactors.at` factorizes the
array at one time: by an SVD of ``J`` (which also decides the rank and checks 1-fullness) or, for
time-varying arrays of 100 rows and more, when asked (``block``), by a pivoted QR found block column by
block column (`lsc._structured_tv.BlockQR`, ``O(k^2 n^3)``) or, at a time near one already factorized, by
one LU of ``J`` bordered by the old null spaces (`DenseFactors._warm`). Both prove their rank decisions and
decline on any doubt, so the SVD's decisions, warnings and refusals stay. `DenseFactors.many` stacks the
SVDs of many times (an interpolant's points are known in advance, and for arrays of a few dozen rows one
time costs far more in per-call overhead than in arithmetic) and leaves out every time whose rank decision
is a close call, is not the completion's or is not 1-full: the caller factorizes those one at a time.
"""

import numpy as np
import scipy.linalg

from ._derivative_array import assembled_jets
from ._exceptions import IndexDeterminationError
from ._factors import Decline, Factors, swap
from ._linalg import ONE_FULL_TOL, default_rcond, norm2_if_above, numerical_rank, ranks_many
from ._structured_tv import BlockQR

__all__ = ["DenseFactors", "WARM_MIN_ROWS"]

# Block-column QR or warm-started LU instead of the SVD of J (time-varying): only from this many rows of J on
# (below, the SVD is cheaper: 45 us against 490 us for the block QR at 20 rows), and for the LU with this
# safety factor on every rank test. Below it, many times are stacked instead.
WARM_MIN_ROWS = 100
_WARM_MARGIN = 10.0


class DenseFactors(Factors):
    """The standard derivative array at ``m`` times, factorized (`lsc._factors.Factors`).

    Made by `at` (one time) or `many`. At one time ``left`` and ``right`` hold the orthonormal bases of the
    left and right null spaces of ``J`` (a later time's warm start reads them), ``warm`` says whether the
    warm-started LU was used and ``block`` holds the `BlockQR` when that was (``block_note``: why it declined).
    """

    def __init__(self, jets, t, rcond, fstack, strict):
        self.jets, self.n, self.k, self.q, self.rcond, self.strict = jets, jets.n, jets.k, jets.q, rcond, strict
        self.t = np.asarray(t, dtype=float)
        self.J, self.F = jets.J, jets.F  # (q + 1, m, N, N), (q + 1, m, N, n)
        n = self.n
        self.A0, self.B0 = self.J[0][:, :n, :n], self.F[0][:, :n]
        self._forcing(jets.Lam, fstack)
        self.warm, self.block, self.block_note, self.kind = False, None, None, "svd"
        self._first_rows = None

    @classmethod
    def at(cls, dae, k, t, q, rcond, fstack=None, expected_rank=None, reference=None, block=False):
        """The factors at one time `t` (`fstack`: the forcing jet there, or None for maps).

        Raises `IndexDeterminationError` when the rank is not `expected_rank` or the array is not 1-full;
        warns (`RankDecisionWarning`) on a close call.
        """
        order = k + q
        jets = assembled_jets(dae.A.jet(t, order)[:, None], dae.B.jet(t, order)[:, None], k, q)
        fac = cls(jets, [float(t)], rcond, None if fstack is None else fstack.reshape(1, order + 1, -1), True)
        J = jets.J[0, 0]
        if not (block and J.shape[0] >= WARM_MIN_ROWS and fac._block_qr(J, rcond, expected_rank)):
            if reference is None or not fac._warm(J, reference, rcond):
                fac._svd(J, expected_rank)
        fac.C = swap(fac.Z2) @ fac.F[0]
        return fac

    @classmethod
    def many(cls, A, B, k, q, ts, rcond, rank, fstacks=None):
        """``(factors, kept)``: the factors at the times `kept` (indices into `ts`) whose rank is clearly `rank`.

        `A`, `B`: the coefficients' jets to order ``k + q`` at every time, shape (k + q + 1, m, n, n);
        `fstacks` (m, k + q + 1, n) or None. ``factors`` is None when fewer than two times are kept.
        """
        jets = assembled_jets(A, B, k, q)
        n, N = A.shape[-1], jets.J.shape[-1]
        U, s, Vt = np.linalg.svd(jets.J[0])
        ok = ranks_many(s, (N, N), rcond) == rank
        if rank < N:  # 1-fullness: the null space of J must not move x' (as `_svd`)
            ok &= [norm2_if_above(Vt[j, rank:, :n], ONE_FULL_TOL) <= ONE_FULL_TOL for j in range(len(ts))]
        kept = np.nonzero(ok)[0]
        if kept.size < 2:
            return None, kept
        jets.J, jets.F = jets.J[:, kept], jets.F[:, kept]
        fac = cls(jets, np.asarray(ts, dtype=float)[kept], rcond, None if fstacks is None else fstacks[kept], False)
        fac.U, fac.s, fac.Vt, fac.rank = U[kept], s[kept], Vt[kept], rank
        fac.C = swap(fac.Z2) @ fac.F[0]
        return fac, kept

    # -- the factorizations at one time ------------------------------------------------------------------
    def _svd(self, J, expected_rank):
        n, k, t = self.n, self.k, float(self.t[0])
        # numpy's svd (LAPACK gesdd, like scipy's) has a fraction of scipy's call overhead, which
        # dominates a time-varying rhs for arrays of a few dozen rows; the jets are finite (checked).
        U, s, Vt = np.linalg.svd(J)
        self.rank = numerical_rank(s, J.shape, self.rcond, what=f"derivative array J (k={k}, t={t:g})")
        if expected_rank is not None and self.rank != expected_rank:
            raise IndexDeterminationError(
                f"the rank of the derivative array (k={k}) changes at t={t!r}: {self.rank} instead of "
                f"{expected_rank}. The DAE is not solvable with constant rank here (thesis (A3)); "
                "the completion would jump."
            )
        # 1-fullness: the null space of J must not move x' (x' unique).
        null_x = norm2_if_above(Vt[self.rank :, :n], ONE_FULL_TOL) if self.rank < J.shape[1] else 0.0
        if null_x > ONE_FULL_TOL:
            raise IndexDeterminationError(
                f"the derivative array with k={k} differentiations does not determine x' at t={t!r} "
                f"(not 1-full: its null space moves x' by {null_x:.1e}). Pass t_span to `complete` so k "
                "is decided over the interval, or a larger k."
            )
        self.U, self.s, self.Vt = U[None], s[None], Vt[None]
        self.left, self.right = U[:, self.rank :], Vt[self.rank :].T
        self.scale = s[0] if s.size else 0.0

    def _block_qr(self, J, rcond, expected_rank):
        """Null spaces and ``J^+`` from the block-column QR (`lsc._structured_tv.BlockQR`); False when it declines.

        It declines (`block_note` says why) whenever a rank decision or 1-fullness is not proven clear-cut,
        and when the rank differs from `expected_rank`: the caller's SVD then decides, warns or refuses.
        """
        try:
            fac = BlockQR(J, self.n, rcond)
        except Decline as exc:
            self.block_note = str(exc)
            return False
        if expected_rank is not None and fac.rank != expected_rank:
            self.block_note = f"rank {fac.rank} instead of {expected_rank}"
            return False
        self.block, self.rank, self.left, self.right, self.scale = fac, fac.rank, fac.Z2, fac.N, fac.scale
        self.kind = "block-qr"
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
        if J.shape[0] != J.shape[1] or ref.right.shape[1] != ref.left.shape[1] or ref.rank == 0:
            return False
        s = ref.scale
        try:
            Z2, N = ref.left, ref.right
            lu = scipy.linalg.lu_factor(J + s * (Z2 @ N.T), check_finite=False)
            N = np.linalg.qr(scipy.linalg.lu_solve(lu, Z2, check_finite=False))[0]
            Z2 = np.linalg.qr(scipy.linalg.lu_solve(lu, ref.right, trans=1, check_finite=False))[0]
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
                or norm2_if_above(N[: self.n].T, ONE_FULL_TOL) > ONE_FULL_TOL):
            return False
        self._lu, self.left, self.right, self.scale = lu, Z2, N, s
        self.rank, self.warm, self.kind = ref.rank, True, "warm-lu"
        return True

    # -- the protocol ------------------------------------------------------------------------------------
    @property
    def Z2(self):
        if self.kind == "svd":
            return self.U[:, :, self.rank :]
        return self.left[None]

    def times_F(self, X, d):
        """``X @ F^(d)``."""
        return X @ self.F[d]

    @property
    def first_rows(self):
        """The first n rows of ``J^+`` (thesis ``V^T J^+``); never the whole, formed once."""
        if self._first_rows is None:
            r, n = self.rank, self.n
            if self.kind == "block-qr":
                self._first_rows = self.block.first_rows[None]
            elif self.kind == "warm-lu":
                E = np.eye(self._lu[0].shape[0], n)
                Y = scipy.linalg.lu_solve(self._lu, E, trans=1, check_finite=False).T
                self._first_rows = (Y - (self.right[:n] / self.scale) @ self.left.T)[None]
            else:
                self._first_rows = (swap(self.Vt[:, :r, :n]) / self.s[:, None, :r]) @ swap(self.U[:, :, :r])
        return self._first_rows

    def times_pinv(self, X):
        """``X @ J^+``, X of shape (m, p, N)."""
        r = self.rank
        if self.kind == "block-qr":
            return self.block.times_pinv(X[0])[None]
        if self.kind == "warm-lu":
            XM = scipy.linalg.lu_solve(self._lu, X[0].T, trans=1, check_finite=False).T
            return (XM - ((X[0] @ self.right) / self.scale) @ self.left.T)[None]
        return ((X @ swap(self.Vt[:, :r])) / self.s[:, None, :r]) @ swap(self.U[:, :, :r])

    def basis_drift(self):
        if self.q < 1 or not np.any(self.J[1]):
            return None
        Y = self.times_pinv(swap(self.Z2) @ self.J[1])
        return self.times_F(Y, 0), self.times_L(Y, 0)

    @property
    def rounding_scale(self):
        """``||F|| / sigma_min(J)`` (one time, SVD): entries of ``G = J^+ F`` that cancel are left at rounding
        relative to it."""
        return np.linalg.norm(self.F[0][0], 2) / self.s[0, self.rank - 1]
