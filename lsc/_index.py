"""Differentiation index: the smallest k whose derivative array determines x'."""

import numpy as np
import scipy.linalg

from ._derivative_array import array_jets
from ._exceptions import IndexDeterminationError
from ._linalg import default_rcond, numerical_rank, validate_rcond
from ._validate import check_dae, check_k, check_time

__all__ = ["differentiation_index", "ArrayRanks"]


class ArrayRanks:
    """Ranks of the standard derivative array with k differentiations.

    Attributes
    ----------
    k : int
    rank_J : int
        Rank of ``J``.
    rank_J_w : int
        Rank of ``J`` without its first block column (the ``x'`` columns).
    rank_JF : int
        Rank of ``[J, F]``; full row rank is thesis assumption (A4).
    rows : int
        Number of rows ``(k+1) n``.
    n : int
    """

    def __init__(self, k, rank_J, rank_J_w, rank_JF, rows, n):
        self.k, self.rank_J, self.rank_J_w, self.rank_JF, self.rows, self.n = k, rank_J, rank_J_w, rank_JF, rows, n

    @property
    def one_full(self):
        """True when ``J`` is 1-full with respect to ``x'``."""
        return self.rank_J - self.rank_J_w == self.n

    @property
    def full_row_rank(self):
        """True when ``[J, F]`` has full row rank (assumption (A4))."""
        return self.rank_JF == self.rows

    @property
    def corank(self):
        return self.rows - self.rank_J

    def __str__(self):
        return (
            f"k={self.k}: rank J={self.rank_J}, rank J[:, n:]={self.rank_J_w} "
            f"(1-full: {'yes' if self.one_full else 'no'}), rank [J F]={self.rank_JF} of {self.rows} rows"
        )


def array_ranks(dae, k, t, rcond):
    """The ranks that decide 1-fullness and (A3)-(A4) for k differentiations."""
    n = dae.n
    jets = array_jets(dae, k, t)
    J, F = jets.J[0], jets.F[0]
    rows = J.shape[0]
    rcond = default_rcond(J.shape) if rcond is None else rcond
    s = scipy.linalg.svdvals(J)
    scale = s[0] if s.size else 0.0
    r = numerical_rank(s, J.shape, rcond, what=f"derivative array J (k={k})")
    s_w = scipy.linalg.svdvals(J[:, n:]) if k > 0 else np.zeros(0)
    r_w = numerical_rank(s_w, J.shape, rcond, what=f"derivative array J[:, n:] (k={k})", scale=scale)
    JF = np.hstack([J, F])
    s_jf = scipy.linalg.svdvals(JF)
    r_jf = numerical_rank(s_jf, JF.shape, rcond, what=f"[J, F] (k={k})")
    return ArrayRanks(k, r, r_w, r_jf, rows, n)


def pencil_is_regular(dae, rcond=None):
    """True when ``det(s A + B)`` is not identically zero (constant coefficients).

    Tested at two scaled pseudo-random points ``s``: a regular pencil is
    singular at no more than n points, so both being rank-deficient means
    the pencil is singular.
    """
    A, B = dae.A(0.0), dae.B(0.0)
    scale = (np.linalg.norm(B, 2) or 1.0) / (np.linalg.norm(A, 2) or 1.0)
    for s in (0.7317 * scale, -1.3641 * scale):
        M = s * A + B
        sv = scipy.linalg.svdvals(M)
        if numerical_rank(sv, M.shape, rcond, warn=False) == dae.n:
            return True
    return False


def differentiation_index(dae, t=0.0, kmax=10, rcond=None):
    """The differentiation index of a linear DAE.

    The smallest ``k`` for which the derivative array ``J`` with ``k``
    differentiations is 1-full with respect to ``x'`` (``x'`` is uniquely
    determined by ``J w = -F x + g``), ``[J, F]`` has full row rank (thesis
    assumption (A4)) and the corank of ``J`` does not change from ``k`` to
    ``k + 1`` (constant rank, (A3)). Ranks are decided from singular values
    with the relative threshold `rcond`.

    Parameters
    ----------
    dae : LinearDAE
    t : float, optional
        Time at which the arrays are evaluated.
    kmax : int, optional
        Largest ``k`` tried.
    rcond : float, optional
        Relative rank threshold (default ``max(shape) * eps * 1e3``).

    Returns
    -------
    int
        The index (0 for an implicit ODE with invertible ``A``).

    Raises
    ------
    IndexDeterminationError
        When no ``k <= kmax`` works; the message lists the ``k`` tried and the
        ranks found, and says when the pencil is singular.

    Examples
    --------
    A chain ``N x' + x = 0`` with ``N`` a 3x3 shift has index 3:

    >>> import numpy as np
    >>> from lsc import LinearDAE, differentiation_index
    >>> differentiation_index(LinearDAE(np.eye(3, k=1), np.eye(3)))
    3
    """
    check_dae(dae)
    t = check_time("t", t)
    kmax = check_k(kmax, "kmax")
    rcond = validate_rcond(rcond)
    k, _ = determine_index(dae, t, kmax, rcond)
    return k


def determine_index(dae, t, kmax, rcond):
    """``(k, ranks)`` with the ranks for each k tried; raises on failure."""
    tried = []
    ranks_next = None
    for k in range(kmax + 1):
        ranks = ranks_next if ranks_next is not None else array_ranks(dae, k, t, rcond)
        ranks_next = None
        tried.append(ranks)
        if not ranks.full_row_rank:
            break
        if ranks.one_full:
            ranks_next = array_ranks(dae, k + 1, t, rcond)
            if ranks_next.corank == ranks.corank and ranks_next.full_row_rank:
                return k, tried
    lines = "\n  ".join(str(r) for r in tried)
    if dae.is_constant and not pencil_is_regular(dae, rcond):
        raise IndexDeterminationError(
            "`dae` is not uniquely solvable: its pencil s*A + B is singular (det(s*A + B) = 0 for all s), "
            f"so no derivative array determines x'. Ranks found:\n  {lines}"
        )
    if not tried[-1].full_row_rank:
        raise IndexDeterminationError(
            "`dae` is not solvable: [J, F] lost full row rank (thesis assumption (A4)), so its equations are "
            f"inconsistent or redundant. Ranks found:\n  {lines}"
        )
    raise IndexDeterminationError(
        f"no k in 0..{kmax} gives a derivative array that is 1-full with respect to x' "
        f"(the index exceeds kmax={kmax}, or the DAE is not solvable); ranks found:\n  {lines}"
    )
