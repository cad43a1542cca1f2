"""Rank decisions, made once and in one place.

Every rank in lsc (index determination, null spaces, pseudo-inverses) is
decided here, from singular values, with the same relative threshold
``rcond * sigma_max``. A decision whose margin is small is reported with a
`RankDecisionWarning` instead of being taken silently.
"""

import warnings

import numpy as np

from ._exceptions import RankDecisionWarning

__all__ = ["default_rcond", "numerical_rank", "validate_rcond"]

# A singular value within this factor of the threshold is a close call.
_MARGIN = 100.0
_EPS = float(np.finfo(float).eps)


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
    if warn and ((rank < s.size and s[rank] > tol / _MARGIN) or (rank > 0 and s[rank - 1] < tol * _MARGIN)):
        close = (s > tol / _MARGIN) & (s < tol * _MARGIN)
        if np.any(close):
            warnings.warn(
                f"rank of the {what} decided with a small margin: singular values "
                f"{np.array2string(s[close] / scale, precision=2)} (relative to the largest) lie within a "
                f"factor {_MARGIN:g} of rcond={rcond:.2e}; the rank taken is {rank}.",
                RankDecisionWarning,
                stacklevel=3,
            )
    return rank
