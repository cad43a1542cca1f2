"""Differentiation index: the smallest k whose derivative array determines x'."""

import numpy as np
import scipy.linalg

from ._derivative_array import array_jets
from ._exceptions import IndexDeterminationError
from ._linalg import TRIAL_SHIFTS, default_rcond, numerical_rank, rank_margin, validate_rcond
from ._problem import balance, check_dae
from ._validate import check_k, check_t_span, check_time

__all__ = ["differentiation_index", "check_solvability", "ArrayRanks", "SolvabilityReport"]

# The largest k - index accepted: measured on the gallery's constant problems (docs/reliability_library.md),
# the error stays at the k = index level up to index + 12 at least and grows beyond index + 15.
K_ABOVE_INDEX = 10


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

    def __init__(self, k, rank_J, rank_J_w, rank_JF, rows, n, singular_values=None):
        self.k, self.rank_J, self.rank_J_w, self.rank_JF, self.rows, self.n = k, rank_J, rank_J_w, rank_JF, rows, n
        self._s = singular_values  # of J: for constant coefficients they are those of the next array's J[:, n:]

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


def array_ranks(dae, k, t, rcond, previous=None, memo=None):
    """The ranks that decide 1-fullness and (A3)-(A4) for k differentiations.

    ``previous`` (the ranks for ``k - 1`` at the same time) saves one SVD
    for constant coefficients: ``J[:, n:]`` with ``k`` differentiations is
    ``J`` with ``k - 1`` below a zero block row (``D^i A`` vanishes for
    ``i > 0``), so it has the same singular values. ``memo`` (a dict) keeps
    the ranks per ``(k, t)`` across calls on the same DAE.
    """
    key = (k, float(t))
    if memo is not None and key in memo:
        return memo[key]
    n = dae.n
    jets = array_jets(dae, k, t)
    J, F = jets.J[0], jets.F[0]
    rows = J.shape[0]
    J, F = _equilibrated(dae, k, t, J, F)
    rcond = default_rcond(J.shape) if rcond is None else rcond
    s = scipy.linalg.svdvals(J)
    scale = s[0] if s.size else 0.0
    r = numerical_rank(s, J.shape, rcond, what=f"derivative array J (k={k})")
    if k == 0:
        s_w = np.zeros(0)
    elif dae.is_constant and previous is not None and previous.k == k - 1 and previous._s is not None:
        s_w = previous._s
    else:
        s_w = scipy.linalg.svdvals(J[:, n:])
    r_w = numerical_rank(s_w, J.shape, rcond, what=f"derivative array J[:, n:] (k={k})", scale=scale)
    JF = np.hstack([J, F])
    s_jf = scipy.linalg.svdvals(JF)
    r_jf = numerical_rank(s_jf, JF.shape, rcond, what=f"[J, F] (k={k})")
    ranks = ArrayRanks(k, r, r_w, r_jf, rows, n, singular_values=s)
    if memo is not None:
        memo[key] = ranks
    return ranks


def _equilibrated(dae, k, t, J, F, at=None):
    """``J``, ``F`` of the equilibrated DAE (`lsc._problem.balance`): the same ranks, told apart in floating point.

    Rows ``r``: ``diag(r)`` on every block row. Unknowns ``x = diag(c) y``: ``diag(c)`` on every block column.
    Time ``t = sigma tau``: the array in ``tau`` is the given one with block row i times ``sigma^i`` and block
    column m (the derivative ``x^(m+1)``) times ``sigma^-(m+1)``; ``F``'s block row i times ``sigma^i``.
    The scaling is that at `t`, or at the time `at` (fixed scales: a row whose coefficients vanish is not
    rescaled away).
    """
    scaling = balance(dae, t if at is None else at)
    if scaling.identity:
        return J, F
    n = dae.n
    rows = scaling.fstack_scales(n, k)  # sigma^i r in block row i
    c = np.ones(n) if scaling.c is None else scaling.c
    columns = np.kron(scaling.sigma ** -np.arange(1.0, k + 2), c)
    return rows[:, None] * J * columns, rows[:, None] * F * c


def pencil_is_regular(dae, rcond=None):
    """True when ``det(s A + B)`` is not identically zero (constant coefficients).

    Tested at two scaled pseudo-random points ``s``: a regular pencil is
    singular at no more than n points, so both being rank-deficient means
    the pencil is singular.
    """
    eq = balance(dae).apply(dae)
    A, B = eq.A(0.0), eq.B(0.0)
    scale = (np.linalg.norm(B, 2) or 1.0) / (np.linalg.norm(A, 2) or 1.0)
    for s in TRIAL_SHIFTS[:2]:
        M = s * scale * A + B
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


def k_works(dae, k, t, rcond, ranks=None, memo=None):
    """Whether ``k`` differentiations determine ``x'`` at ``t``: ``(ok, ranks, next_ranks)``.

    The one criterion used everywhere: the array with ``k`` differentiations
    is 1-full and ``[J, F]`` has full row rank, and the array with ``k + 1``
    keeps the corank and full row rank (thesis (A3)-(A4) for k and k+1).
    ``next_ranks`` is None when the first part already fails.
    """
    ranks = ranks if ranks is not None else array_ranks(dae, k, t, rcond, memo=memo)
    if not (ranks.full_row_rank and ranks.one_full):
        return False, ranks, None
    nxt = array_ranks(dae, k + 1, t, rcond, previous=ranks, memo=memo)
    return nxt.full_row_rank and nxt.corank == ranks.corank, ranks, nxt


def determine_index(dae, t, kmax, rcond, memo=None):
    """``(k, ranks)`` with the ranks for each k tried; raises on failure."""
    tried = []
    ranks_next = None
    for k in range(kmax + 1):
        if ranks_next is None and tried:
            # k - 1 failed before its next array was formed: J[:, n:] here is J there
            ranks_next = array_ranks(dae, k, t, rcond, previous=tried[-1], memo=memo)
        ok, ranks, ranks_next = k_works(dae, k, t, rcond, ranks=ranks_next, memo=memo)
        tried.append(ranks)
        if ok:
            return k, tried
        if not ranks.full_row_rank:
            break
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


class SolvabilityReport:
    """Result of `check_solvability`.

    Attributes
    ----------
    k : int
        Differentiations that work at every sampled time (the largest
        pointwise index).
    times : ndarray
        The sampled times.
    pointwise_index : ndarray of int or None
        The index found at each sampled time (None when ``k`` was given).
    ranks : list of ArrayRanks
        The ranks of the array with `k` differentiations at each time.
    """

    def __init__(self, k, times, pointwise_index, ranks):
        self.k, self.times, self.pointwise_index, self.ranks = k, times, pointwise_index, ranks

    def __repr__(self):
        return (
            f"SolvabilityReport(k={self.k}, {self.times.size} times in [{self.times[0]:g}, {self.times[-1]:g}], "
            f"pointwise index {'given k' if self.pointwise_index is None else sorted(set(self.pointwise_index.tolist()))}, "
            f"corank {self.ranks[0].corank})"
        )


_DIPS = 4  # local minima of the sampled rank margin searched (the smallest first)


def _array_margin(dae, k, rank, rcond, t, at):
    """``min(s_r / tol, tol / s_(r+1))`` of ``J`` at `t` equilibrated as at `at`, for the rank `rank`: below 1,
    not that rank.

    Infinite where the coefficients cannot be evaluated (that is no rank decision).
    """
    try:
        jets = array_jets(dae, k, t)
        J, _ = _equilibrated(dae, k, t, jets.J[0], jets.F[0], at=at)
    except (ValueError, ArithmeticError):
        return np.inf
    if not np.all(np.isfinite(J)):
        return np.inf
    return rank_margin(scipy.linalg.svdvals(J), rank, default_rcond(J.shape) if rcond is None else rcond)


def _rank_drop(dae, k, times, ranks, rcond):
    """A time between the sampled `times` where the rank of ``J`` (k differentiations) drops, or None.

    A simple zero of the smallest kept singular value is a V in the rank margin, invisible at samples on
    either side of it; each local minimum of the sampled margin is searched between its neighbours, with the
    equilibration of the sample fixed (rescaled at each time, a row whose coefficients vanish would keep its
    norm and hide the drop).
    """
    from ._singular import _golden  # (lsc._singular imports nothing of this module)

    rank = ranks[0].rank_J
    shape = ((k + 1) * dae.n, (k + 1) * dae.n)
    rc = default_rcond(shape) if rcond is None else rcond
    margins = [np.inf if r._s is None else rank_margin(r._s, rank, rc) for r in ranks]
    margins = [_array_margin(dae, k, rank, rcond, float(t), float(t)) if m == np.inf else m
               for t, m in zip(times, margins)]
    last = len(times) - 1
    dips = [i for i in range(last + 1)
            if (i == 0 or margins[i] <= margins[i - 1]) and (i == last or margins[i] <= margins[i + 1])]
    drops = []
    for i in sorted(dips, key=lambda i: margins[i])[:_DIPS]:
        lo, hi = float(times[max(i - 1, 0)]), float(times[min(i + 1, last)])
        at = float(times[i])
        t, margin = _golden(lambda t: _array_margin(dae, k, rank, rcond, t, at), lo, hi)
        if margin < 1.0:
            drops.append(float(t))
    return min(drops, key=lambda t: abs(t - times[0])) if drops else None  # the first one a run meets


def sample_times(t_span, samples=21):
    """Equally spaced times over `t_span`, plus t = 0 when inside (coefficients often degenerate there)."""
    t0, t1 = t_span
    times = np.linspace(t0, t1, samples)
    if 0.0 not in times and min(t0, t1) < 0.0 < max(t0, t1):
        times = np.sort(np.append(times, 0.0))
    return times


def check_solvability(dae, t_span, *, k=None, kmax=10, rcond=None, samples=21, between=True):
    """Decide unique solvability of a linear DAE over an interval.

    Solvability is decided by the derivative array, not by the pencil
    (ERRATA item 6): for time-varying coefficients a regular pencil
    (``det(s A(t) + B(t)) != 0``) does not imply unique solvability, and a
    singular one does not exclude it. At each of `samples` equally spaced
    times the index is determined; then ``k`` = the largest of them must
    work at every sampled time (`k_works`: 1-full, (A4), the same corank
    with ``k + 1``), with the same corank everywhere (thesis (A3), constant
    rank).

    Parameters
    ----------
    dae : LinearDAE
    t_span : pair of float
    k : int, optional
        Check this number of differentiations instead of determining the
        index (`SolvabilityReport.pointwise_index` is then None).
    kmax : int, optional
    rcond : float, optional
    samples : int, optional
        Number of sampled times (at least 2), both ends included.
    between : bool, optional
        Also look between the sampled times for a time where the rank of
        ``J`` drops (default True): where the rank margin of ``J`` (its
        smallest kept singular value over the threshold) has a local minimum
        at the samples, a golden-section search finds the minimum to the
        rounding of t, and a margin below 1 there is refused, naming the
        time. ``(0.95 - t) x2 = f2`` sampled at 0, 0.05, ..., 1 loses rank at
        t = 0.95 only. `lsc.complete` with `t_span` checks the samples only:
        a run that reaches such a time ends there (`solve_completion`).

    Returns
    -------
    SolvabilityReport

    Raises
    ------
    IndexDeterminationError
        Naming the times where no k works, where ``k`` does not determine
        ``x'`` or where the rank changes (at a sampled time or, with
        `between`, between them).

    Examples
    --------
    Thesis Example 1 is 1-full with k = 1 at t = 0 only; over the interval
    it needs k = 2:

    >>> import numpy as np, sympy
    >>> from lsc import LinearDAE, check_solvability
    >>> t = sympy.Symbol("t")
    >>> dae = LinearDAE(sympy.Matrix([[0, t], [0, 0]]), -np.eye(2))
    >>> report = check_solvability(dae, (-1.0, 1.0))
    >>> report.k, sorted(set(report.pointwise_index.tolist()))
    (2, [1, 2])

    A coefficient that vanishes between the sampled times:

    >>> singular = LinearDAE(np.diag([1.0, 0.0]), sympy.Matrix([[1, -1], [0, 0.93 - t]]))
    >>> check_solvability(singular, (0.0, 1.0))
    Traceback (most recent call last):
    ...
    lsc._exceptions.IndexDeterminationError: `dae` is not uniquely solvable on (0.0, 1.0): with k=1 the derivative array J loses rank at t=0.93...
    """
    check_dae(dae)
    t0, t1 = check_t_span(t_span)
    kmax = check_k(kmax, "kmax")
    rcond = validate_rcond(rcond)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 2:
        raise ValueError(f"`samples` must be an int >= 2; found {samples!r}.")
    if not isinstance(between, (bool, np.bool_)):
        raise TypeError(f"`between` must be a bool; found {type(between).__name__}.")
    times = sample_times((t0, t1), samples)
    index = None
    memo = {}  # the ranks found while determining the index are those k_works checks below
    if k is None:
        index, failures = [], []
        for t in times:
            try:
                index.append(determine_index(dae, float(t), kmax, rcond, memo=memo)[0])
            except IndexDeterminationError as exc:
                failures.append(f"t={t:g}: {str(exc).splitlines()[0]}")
        if failures:
            raise IndexDeterminationError(
                f"`dae` is not uniquely solvable on {tuple(t_span)}: no k <= {kmax} works at "
                f"{len(failures)} of {times.size} sampled times:\n  " + "\n  ".join(failures)
            )
        k = max(index)
    else:
        k = check_k(k)
    checks = [k_works(dae, k, float(t), rcond, memo=memo) for t in times]
    bad = [f"t={t:g}: {r}" + ("" if nxt is None else f"; next: {nxt}") for t, (ok, r, nxt) in zip(times, checks) if not ok]
    if bad:
        raise IndexDeterminationError(f"with k={k} the derivative array does not determine x' at:\n  " + "\n  ".join(bad))
    ranks = [r for _, r, _ in checks]
    coranks = [r.corank for r in ranks]
    if len(set(coranks)) > 1:
        typical = max(set(coranks), key=coranks.count)
        where = [f"t={t:g} (corank {c})" for t, c in zip(times, coranks) if c != typical]
        raise IndexDeterminationError(
            f"with k={k} the rank of the derivative array is not constant on {tuple(t_span)} "
            f"(corank {typical} elsewhere): " + ", ".join(where)
        )
    drop = _rank_drop(dae, k, times, ranks, rcond) if between and not dae.is_constant else None
    if drop is not None:
        raise IndexDeterminationError(
            f"`dae` is not uniquely solvable on {tuple(t_span)}: with k={k} the derivative array J loses rank at "
            f"t={drop:.12g} (between the sampled times: its smallest kept singular value vanishes there)"
        )
    return SolvabilityReport(k, times, None if index is None else np.array(index), ranks)


def decide_k(dae, k, t, t_span, rcond):
    """The differentiations a completion uses: the index (`k` None) or `k` checked, at `t` or over `t_span`.

    For time-varying coefficients with `t_span`, over the interval (`check_solvability`); otherwise at `t`.
    A `k` too small is refused, and one more than `K_ABOVE_INDEX` above the index (rounding grows with it).
    """
    if k is None:
        if not dae.is_constant and t_span is not None:
            return check_solvability(dae, t_span, rcond=rcond, between=False).k
        return determine_index(dae, t, 10, rcond)[0]
    k = check_k(k)
    if not dae.is_constant and t_span is not None:
        check_solvability(dae, t_span, k=k, rcond=rcond, between=False)
    else:
        ok, ranks, nxt = k_works(dae, k, t, rcond)
        if not ok:
            raise IndexDeterminationError(
                f"`k`={k} is too small at t={t:g}: the derivative array does not determine x' "
                f"({ranks}; next: {nxt}). Use k=None for the differentiation index."
            )
    if k > K_ABOVE_INDEX:
        index, _ = determine_index(dae, t, k, rcond)
        if k > index + K_ABOVE_INDEX:
            raise ValueError(
                f"`k`={k} is {k - index} above the differentiation index {index} (at t={t:g}); at most "
                f"index + {K_ABOVE_INDEX} = {index + K_ABOVE_INDEX} is accepted. More differentiations gain "
                "nothing in exact arithmetic (the solutions are those of k = index), but the derivative "
                "array's entries grow like binomial coefficients and f's derivatives of order up to k + 1, "
                "so rounding grows: "
                "on gallery.prescribed_path (index 3) the error is 8e-9 up to k = 15, then 7e-8 at k = 18, "
                "4e-3 at k = 28 and 2 at k = 33. Use k=None."
            )
    return k
