"""Where a time-varying completion stops: the first time of a run at which it cannot be evaluated clearly.

A time-varying DAE can be solvable on most of an interval and not at one time
inside it: the derivative array loses rank there (``(1 - 2 t^2) x2 = f2`` at
``t = 1/sqrt(2)``), or a coefficient is not finite. Near such a time the rank
decisions become close calls (`RankDecisionWarning`) and the solution may
have a pole, so an integrator that runs into it takes ever smaller steps, each
a factorization of the array. `find_stop` locates the time once, before the
run: from a time where evaluating the completion failed, or from the pieces
the interpolant could not resolve (`lsc._chebyshev`), it finds by bisection
the last time before which every evaluation is clear (no exception, no close
call) to the rounding of ``t``, and, where the rank of the array really
drops, the time it does (the minimum of the rank margin). The run then ends
there, with the trajectory before it.
"""

import math
import warnings

import numpy as np
import scipy.linalg

from ._derivative_array import array_jets
from ._exceptions import RankDecisionWarning
from ._linalg import RANK_MARGIN, default_rcond, rank_margin as linalg_rank_margin

__all__ = []

_EPS = float(np.finfo(float).eps)
_SCAN = 33  # times of the coarse scan for the first failure below a known one


class Stop:
    """The end of what can be integrated: `t_clear` (last clear time), `t_bad` (first failing one), why.

    `t_singular` is the time the derivative array loses rank (None when it does not: a forcing that is not
    finite, say); `message` says all of it.
    """

    def __init__(self, t_clear, t_bad, reason, t_singular=None, k=None):
        self.t_clear, self.t_bad, self.reason, self.t_singular, self.k = t_clear, t_bad, reason, t_singular, k

    @property
    def message(self):
        if self.t_singular is not None:
            return (f"the DAE is not uniquely solvable at t={self.t_singular!r}: the derivative array (k={self.k}) "
                    f"loses rank there, so the completion cannot be evaluated from t={self.t_bad!r} on ({self.reason})")
        return f"the completion cannot be evaluated from t={self.t_bad!r} on: {self.reason}"


def clear(completion, t):
    """None when the completion evaluates at `t` without an error or a close rank call; else the reason."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RankDecisionWarning)
        try:
            completion.matrices(t)
        except (ValueError, ArithmeticError, RankDecisionWarning) as exc:
            return str(exc)
    return None


def rank_margin(completion, t):
    """The factor by which the rank of the standard array at `t` clears its threshold.

    ``min(s_r / tol, tol / s_(r+1))`` for the completion's rank ``r`` and the threshold ``tol = rcond s_1``:
    below 1 the rank is not ``r``, below `RANK_MARGIN` the decision is a close call. Infinite where the
    coefficients cannot be evaluated (that is no rank decision).
    """
    try:
        J = array_jets(completion._eq, completion.k, t).J[0]
    except (ValueError, ArithmeticError):
        return math.inf
    if not np.all(np.isfinite(J)):
        return math.inf
    s = scipy.linalg.svdvals(J)
    return linalg_rank_margin(s, completion._rank, completion.rcond or default_rcond(J.shape))


def _resolution(a, b):
    """The distance below which two times between `a` and `b` are told apart no more (a few ulps)."""
    return 4.0 * _EPS * max(abs(a), abs(b), abs(b - a))


def _bisect(completion, good, bad, reason):
    """``(t_clear, t_bad, reason)``: `good` and `bad` brought together to the rounding of t."""
    while abs(bad - good) > _resolution(good, bad):
        mid = 0.5 * (good + bad)
        if mid in (good, bad):
            break
        why = clear(completion, mid)
        if why is None:
            good = mid
        else:
            bad, reason = mid, why
    return good, bad, reason


def _first_bad_below(completion, t0, t_bad):
    """A failing time at most `t_bad` and the clear time before it on a scan from `t0` (or None, None)."""
    previous = t0
    for t in np.linspace(t0, t_bad, _SCAN)[1:]:
        why = clear(completion, float(t))
        if why is not None:
            return previous, float(t), why
        previous = float(t)
    return None, None, None


def _minimum_margin(completion, lo, hi):
    """``(t, margin)``: where the rank margin is smallest on ``[lo, hi]``.

    The margin is not unimodal on a long piece (the largest singular value moves too), so a scan of
    `_SCAN` times picks the smallest, and bounded Brent refines it between its neighbours: a simple zero
    of the smallest singular value kept is a V in the margin, found to the rounding of t.
    """
    a, b = min(lo, hi), max(lo, hi)
    if b - a <= _resolution(a, b):
        return lo, rank_margin(completion, lo)
    grid = np.linspace(a, b, _SCAN)
    values = [rank_margin(completion, float(t)) for t in grid]
    i = int(np.argmin(values))
    t, margin = _golden(lambda t: rank_margin(completion, t), float(grid[max(i - 1, 0)]),
                        float(grid[min(i + 1, _SCAN - 1)]))
    return (t, margin) if margin <= values[i] else (float(grid[i]), float(values[i]))


def _golden(fun, a, b):
    """Golden-section search for the minimum of `fun` on ``[a, b]``, down to the rounding of t.

    (scipy's bounded Brent stops at sqrt(eps) |t|, 1e-8 here: a singular value that vanishes like
    ``c |t - t_s|`` is 1e-8 c there, not below the rank threshold.)
    """
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = fun(c), fun(d)
    while abs(b - a) > _resolution(a, b):
        if fc <= fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            if c in (a, d):
                break
            fc = fun(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            if d in (b, c):
                break
            fd = fun(d)
    return (c, fc) if fc <= fd else (d, fd)


def _singular_time(completion, t_bad, t_far, length, direction):
    """The time past `t_bad` (towards `t_far`) where the array's rank margin is smallest, if it falls below 1.

    The search reaches to `t_far` and at least 1e-6 of the run's `length` past `t_bad`: a close call starts
    ``RANK_MARGIN rcond / c`` before a simple zero of slope ``c`` of the smallest singular value kept.
    """
    width = max(abs(t_far - t_bad), 1e-6 * length, 1e3 * _resolution(t_bad, t_far))
    t, margin = _minimum_margin(completion, t_bad, t_bad + direction * width)
    return t if margin < 1.0 else None


def find_stop(completion, t0, t1, failed_at=None, unresolved=()):
    """The `Stop` of a run from `t0` towards `t1`, or None when nothing fails.

    `failed_at`: a time where evaluating the completion failed; `unresolved`: pieces ``(lo, hi)`` that an
    interpolant could not resolve (a singularity may hide inside; it need not fail at any point sampled).
    The earliest failure found (in the direction of the run) wins.
    """
    if clear(completion, t0) is not None:
        return None  # the run fails at its start: the integration reports that itself
    direction = 1.0 if t1 >= t0 else -1.0
    candidates = []  # (good, bad, reason, far)
    if failed_at is not None:
        good, bad, why = _first_bad_below(completion, t0, failed_at)
        if bad is not None:
            candidates.append((good, bad, why, failed_at))
    for lo, hi in sorted(unresolved, key=lambda piece: direction * piece[0]):
        start, end = (lo, hi) if direction > 0 else (hi, lo)
        if candidates and direction * (start - candidates[0][1]) >= 0:
            break
        why = clear(completion, end)
        if why is not None:
            good, bad = start, end
        else:
            t, margin = _minimum_margin(completion, start, end)
            why = clear(completion, t) if margin < RANK_MARGIN else None
            if why is None:
                continue
            good, bad = start, t
        if clear(completion, good) is not None:
            good, bad, why = _first_bad_below(completion, t0, bad)
            if bad is None:
                continue
        candidates.append((good, bad, why, end))
        break
    if not candidates:
        return None
    good, bad, why, far = min(candidates, key=lambda c: direction * c[1])
    t_clear, t_bad, reason = _bisect(completion, good, bad, why)
    return Stop(t_clear, t_bad, reason, _singular_time(completion, t_bad, far, abs(t1 - t0), direction), completion.k)
