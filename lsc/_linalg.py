"""Rank decisions, made once and in one place.

Every rank in lsc (index determination, null spaces, pseudo-inverses) is
decided here, from singular values, with the same relative threshold
``rcond * sigma_max``. A decision whose margin is small is reported with a
`RankDecisionWarning` instead of being taken silently.

The band of a close call, `RANK_MARGIN` (a singular value within a factor 100
of the threshold), is the one every fast path of `lsc._factors` leaves to the
SVD (`close_call`): the structured set-up, the block-column QR, the stacked
evaluation at many times. The trial shifts of a pencil (`TRIAL_SHIFTS`) and
the 1-fullness bound (`ONE_FULL_TOL`) live here for the same reason.
"""

import math
import warnings

import numpy as np

from ._exceptions import RankDecisionWarning

__all__ = ["RANK_MARGIN", "ONE_FULL_TOL", "TRIAL_SHIFTS", "close_call", "close_calls", "default_rcond", "norm2_if_above",
           "numerical_rank", "ranks_many", "validate_rcond"]

# A singular value within this factor of the threshold is a close call.
RANK_MARGIN = 100.0
# A derivative array is 1-full when null(J) has no x' component; beyond this sine of the angle between null(J)
# and {x' = 0} it is not.
ONE_FULL_TOL = float(np.sqrt(np.finfo(float).eps))
# Shifts mu of a pencil (B + mu A), in units of ||B|| / ||A|| (its natural scale): a regular pencil is singular at
# no more than n of them, so the first one that is well conditioned serves.
TRIAL_SHIFTS = (0.7317, -1.3641, 2.2713, -0.4127)
_EPS = float(np.finfo(float).eps)


def close_calls(values, tol):
    """Which of `values` lie within `RANK_MARGIN` of the threshold `tol`: a rank decision there is a close call."""
    return (values > tol / RANK_MARGIN) & (values < tol * RANK_MARGIN)


def close_call(values, tol):
    """Whether any of `values` (along the last axis) lies within `RANK_MARGIN` of the threshold `tol`."""
    return np.any(close_calls(np.asarray(values), np.asarray(tol)), axis=-1)


def norm2_if_above(X, tol):
    """``||X||_2`` when it may exceed `tol`; the cheaper Frobenius norm (an upper bound) otherwise."""
    frobenius = np.sqrt(np.einsum("ij,ij->", X, X))
    return frobenius if frobenius <= tol else np.linalg.norm(X, 2)


def rank_margin(s, rank, rcond):
    """``min(s_r / tol, tol / s_(r+1))`` for singular values `s`, the rank `rank` and ``tol = rcond s_1``.

    Below 1 the numerical rank is not `rank`; below `RANK_MARGIN` the decision is a close call. Infinite
    for a zero matrix (no rank decision).
    """
    tol = rcond * (s[0] if s.size else 0.0)
    if tol == 0.0:
        return math.inf
    margin = math.inf
    if rank > 0:
        margin = min(margin, s[rank - 1] / tol)
    if rank < s.size and s[rank] > 0.0:
        margin = min(margin, tol / s[rank])
    return float(margin)


def default_rcond(shape):
    """Default relative rank threshold for a matrix of the given shape.

    ``max(shape) * eps * 1e3``: numpy's ``matrix_rank`` uses
    ``max(shape) * eps``; the extra factor 1e3 absorbs the rounding of the
    products of binomials and λ powers that fill a derivative array.
    """
    return max(shape) * _EPS * 1e3


def validate_rcond(rcond):
    if rcond is None:
        return None
    if isinstance(rcond, bool) or not np.isscalar(rcond):
        raise TypeError(f"`rcond` must be None or a float in (0, 1); found {rcond!r}.")
    rcond = float(rcond)
    if not (0.0 < rcond < 1.0):
        raise ValueError(f"`rcond` must be None or a float in (0, 1); found {rcond!r}.")
    return rcond


def numerical_rank(s, shape, rcond=None, what="matrix", warn=True, scale=None):
    """Rank from singular values `s` (descending) with relative threshold.

    Parameters
    ----------
    s : ndarray
        Singular values, largest first.
    shape : tuple
        Shape of the matrix they came from (for the default threshold).
    rcond : float, optional
        Relative threshold; singular values ``> rcond * s[0]`` count.
    what : str
        Description used in the warning.
    warn : bool
        Emit `RankDecisionWarning` on a close call.
    scale : float, optional
        Reference singular value (default ``s[0]``). Give the largest singular
        value of a larger matrix to compare ranks of a matrix and its
        submatrix with one absolute threshold.
    """
    scale = (s[0] if s.size else 0.0) if scale is None else scale
    if s.size == 0 or scale == 0.0:
        return 0
    if rcond is None:
        rcond = default_rcond(shape)
    tol = rcond * scale
    rank = int(np.count_nonzero(s > tol))
    # s is sorted: a close call has a neighbour of the threshold within the margin. Checking
    # those two values first keeps this O(1) in the (frequent) time-varying evaluations.
    if warn and ((rank < s.size and s[rank] > tol / RANK_MARGIN) or (rank > 0 and s[rank - 1] < tol * RANK_MARGIN)):
        close = close_calls(s, tol)
        if np.any(close):
            warnings.warn(
                f"rank of the {what} decided with a small margin: singular values "
                f"{np.array2string(s[close] / scale, precision=2)} (relative to the largest) lie within a "
                f"factor {RANK_MARGIN:g} of rcond={rcond:.2e}; the rank taken is {rank}.",
                RankDecisionWarning,
                stacklevel=3,
            )
    return rank


def ranks_many(s, shape, rcond):
    """`numerical_rank` of each row of singular values `s` (m, p); -1 where it would warn (a close call).

    The same threshold ``rcond * s[0]`` and close-call test, for all rows at once: a row marked -1 is left to
    the one-at-a-time path, which decides and warns.
    """
    if s.shape[1] == 0:
        return np.zeros(s.shape[0], dtype=int)
    rcond = default_rcond(shape) if rcond is None else rcond
    tol = rcond * s[:, :1]
    ranks = np.count_nonzero(s > tol, axis=1)
    return np.where(close_call(s, tol) | (s[:, 0] == 0.0), -1, ranks)
