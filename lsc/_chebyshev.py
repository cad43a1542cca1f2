"""Piecewise Chebyshev interpolants of a time-varying completion's ``G(t)``, ``g(t)``.

A time-varying completion costs one factorization of the derivative array
(and the coefficients' derivatives to order k + 1) per evaluation, and an
ODE solver evaluates it at every stage of every step: hundreds to thousands
of times on one interval, more at tight tolerances. ``G`` and ``g`` are as
smooth as the coefficients, so a few dozen evaluations at Chebyshev points
determine them on a piece of the interval to any accuracy; the solver then
evaluates polynomials (one ``cos`` and one matrix product per call).

On a piece, the interpolant through the ``m + 1`` Chebyshev extreme points
is accepted when its last three coefficients are below ``tol`` relative to
the scale of ``G`` (its largest entry, and at least ``1 / (b - a)``: an
error ``tol / (b - a)`` in a rate moves the solution by about ``tol`` of
itself over the interval, and a ``G`` that vanishes to rounding needs no
more) and, separately, of ``g`` (its largest entry).

The evaluations are what costs. ``G`` and ``g`` are analytic but not entire
(a completion is rational in the coefficients' values, with complex
singularities at some distance ``d`` from the real axis), so their
coefficients decay like ``rho^-j``, ``rho`` fixed by ``d`` and the piece's
half-length (Trefethen, *Approximation Theory and Approximation Practice*,
ch. 8), and one long piece needs fewer values than several short ones. The
first piece is the whole interval at degrees 8, 16, 32 (a cheap ``G``,
``g`` stops there). When that fails, the decay predicts the degree needed,
and the next degree is the least multiple of the current one that is
predicted to be enough (the values of degree ``m`` are among those of any
multiple of ``m``: 32 may go to 96 where doubling would take 128), up to
128. Beyond that the interval is split into pieces sized, from left to
right as a step-size controller would, for about `_TARGET` degrees by the
slowest decay seen so far, each started at its predicted degree.

The times of a degree are known before any of them is evaluated: they are
evaluated together (the linear algebra of all of them stacked, each rank
decided as at one time: chain 3 of `lsc._factors`), and a time that needs a
decision of its own is evaluated alone.

`chebyshev_points` and `chebyshev_coefficients` are the two pieces every
piecewise Chebyshev table in the project is built from (the native FMU's
tables too): the points of a piece, placed from its ends, and the
interpolant through the values at the times actually sampled.

A piece that is still unresolved at 1e-6 of the interval's length (a jump in
the forcing, say), or left when the budget of evaluations is spent, is
evaluated pointwise, so the interpolant is never silently wrong by more than
its tolerance.
"""

import bisect
import math

import numpy as np

from ._setup import stacked

__all__ = ["chebyshev_coefficients", "chebyshev_points"]

_FIRST_DEGREE = 8  # the whole interval at 8 and 16 first: most smooth G, g stop there
_PROBE = 32  # the first piece doubles up to this degree, whatever the prediction
_MAX_DEGREE = 128
_TARGET = 32  # the degree pieces are sized for: samples per unit length vary little from 16 to 64
_MARGIN = 1.05  # a degree chosen from a prediction: the predicted one x 1.05 + 1 (+ 2 from a neighbour)
_MIN_PIECE = 1e-6  # of the interval's length


class EvaluationFailed(Exception):
    """Evaluating the completion at a Chebyshev point raised `exc` (a ValueError)."""

    def __init__(self, t, exc):
        super().__init__(str(exc))
        self.t, self.exc = t, exc


def _extreme_points(m):
    """``cos(pi j / m)``, j = 0..m (from +1 to -1), with exact symmetry."""
    return np.sin(np.pi * (m - 2 * np.arange(m + 1)) / (2 * m))


def chebyshev_points(m, interval=None):
    """The ``m + 1`` Chebyshev extreme points, from the right end to the left.

    Parameters
    ----------
    m : int
        The degree (at least 1).
    interval : pair of float, optional
        ``(lo, hi)``; default ``(-1, 1)``, where the points ``cos(pi j / m)`` are exactly symmetric. On an
        interval the ends are exactly ``hi`` and ``lo`` and the inner points are rounded to doubles.

    Returns
    -------
    ndarray, shape (m + 1,)

    Examples
    --------
    >>> from lsc import chebyshev_points
    >>> chebyshev_points(2).tolist(), chebyshev_points(2, (0.0, 4.0)).tolist()
    ([1.0, 0.0, -1.0], [4.0, 2.0, 0.0])
    """
    x = _extreme_points(m)
    if interval is None:
        return x
    lo, hi = map(float, interval)
    ts = 0.5 * (hi + lo) + 0.5 * (hi - lo) * x
    ts[0], ts[-1] = hi, lo
    return ts


def _coefficients(values):
    """Chebyshev coefficients of the interpolant through values at `_extreme_points`."""
    import scipy.fft  # here, not at import: the FMUs lsc builds load no scipy beyond scipy.linalg

    m = values.shape[0] - 1
    c = scipy.fft.dct(values, type=1, axis=0) / m
    c[0] /= 2
    c[m] /= 2
    return c


def _positions(ts, lo, hi):
    """Where the times `ts` lie on ``[lo, hi]`` mapped to [-1, 1], to rounding relative to the piece's length.

    ``t - lo`` and ``hi - t`` are exact (Sterbenz) for t in the piece, so the result holds no rounding of
    ``|t|`` itself: with ``2 t - lo - hi`` a piece of length 2 at t = 1e8 would place its points 1e-8 off.
    """
    ts = np.asarray(ts, dtype=float)
    return np.clip(((ts - lo) - (hi - ts)) / (hi - lo), -1.0, 1.0)


def chebyshev_coefficients(values, times=None, interval=None):
    """Chebyshev coefficients of the polynomial through `values` at the extreme points of degree m.

    Parameters
    ----------
    values : ndarray, shape (m + 1, ...)
        Values at the points of `chebyshev_points` (first axis), any number of entries each.
    times, interval : ndarray and pair of float, optional
        The times actually sampled on ``interval = (lo, hi)``. The inner points on an interval are rounded
        to doubles: near t = 1e5 on a piece of length 2 they are off by ~1e-11 of the piece, and the DCT
        (exact at the points themselves) would read that as noise in the values, ~1e-11 of their rate,
        which no degree resolves. Iterative refinement of the DCT solves the interpolation at the times
        sampled (it contracts by about ``m^2`` times their offset, 2e-4 at t = 1e8 and degree 128).

    Returns
    -------
    ndarray, shape (m + 1, ...)
        ``c`` with ``p(x) = sum_j c[j] T_j(x)``, ``x`` in [-1, 1] across the interval.

    Examples
    --------
    ``(t - t0)^2`` on ``[t0, t0 + 2]`` is ``(x + 1)^2 = 1.5 T_0 + 2 T_1 + 0.5 T_2``. At ``t0 = 1e8`` the
    points are rounded to doubles: a DCT alone reads that as coefficients of 1e-8 up to degree 8.

    >>> import numpy as np
    >>> from lsc import chebyshev_coefficients, chebyshev_points
    >>> ts = chebyshev_points(8, (1e8, 1e8 + 2.0))
    >>> c = chebyshev_coefficients((ts - 1e8) ** 2, ts, (1e8, 1e8 + 2.0))
    >>> np.round(c[:3], 12).tolist(), bool(np.abs(c[3:]).max() < 1e-14)
    ([1.5, 2.0, 0.5], True)
    >>> bool(np.abs(chebyshev_coefficients((ts - 1e8) ** 2)[3:]).max() > 1e-10)
    True
    """
    values = np.asarray(values, dtype=float)
    c = _coefficients(values)
    if times is None:
        return c
    x = _positions(times, *interval)
    m = values.shape[0] - 1
    if np.array_equal(x, _extreme_points(m)):
        return c
    T = np.cos(np.outer(np.arccos(x), np.arange(m + 1)))
    size = np.abs(values).max(initial=0.0)
    flat = values.reshape(m + 1, -1)
    c = c.reshape(m + 1, -1)
    for _ in range(6):
        r = flat - T @ c
        if not np.abs(r).max(initial=0.0) > 1e-15 * size:
            break
        c = c + _coefficients(r)
    return c.reshape(values.shape)


class _Decay:
    """Geometric decay ``rho^-j`` of a piece's Chebyshev coefficients, as a singularity distance.

    `e` holds the coefficients' sizes relative to the scales (largest over the entries of ``G``
    and of ``g``), `tol` the level they must reach. ``rho`` is fitted on the second half of the
    envelope (``max e[j:]``), down to `tol` when the fit passed or to the tail when it did not:
    the first coefficients decay faster or slower than the asymptotic rate (an entire part, a
    few large modes), which a fit from degree 0 would extrapolate. A function analytic in the
    Bernstein ellipse of parameter ``rho`` around a piece of half-length ``h`` is analytic at
    distance ``d = h (rho - 1/rho) / 2`` from it, which gives ``rho``, and the degree, on a piece
    of any other length.
    """

    def __init__(self, e, tol, half_length, passed):
        envelope = np.maximum.accumulate(e[::-1])[::-1]
        above = np.nonzero(envelope > tol)[0]
        if not above.size:  # resolved at degree 0 (to tol): nothing to extrapolate
            self.log_ratio, self.distance = 0.0, math.inf
            return
        last = int(above[-1]) if passed else e.size - 1
        level = tol if passed else max(float(envelope[-3]), 1e-300)
        middle = last // 2
        drop = math.log(max(float(envelope[middle]), level) / level)
        rho = math.exp(drop / (last - middle)) if last > middle and drop > 0 else 1.0 + 1e-9
        # the level at degree 0 of that geometric decay: what the degree on another piece must bring down
        self.log_ratio = max(math.log(level / tol) + last * math.log(rho), 1e-9)
        self.distance = half_length * (rho - 1 / rho) / 2

    def degree(self, length):
        """Degree predicted to resolve a piece of `length`."""
        if self.log_ratio == 0.0 or self.distance == math.inf:
            return 1.0
        delta = 2 * self.distance / length
        return self.log_ratio / math.log(delta + math.sqrt(1 + delta * delta))

    def length_for(self, degree):
        """Length of a piece that `degree` is predicted to resolve."""
        if self.log_ratio == 0.0 or self.distance == math.inf:
            return math.inf
        rho = math.exp(self.log_ratio / degree)
        return 4 * self.distance / (rho - 1 / rho)


def _slower(decay, other):
    """The decay with the nearer singularity: the pieces that follow are sized and started from it."""
    return other if decay is None or other.distance < decay.distance else decay


class ChebyshevCoefficients:
    """``G(t)``, ``g(t)`` of a completion on ``[a, b]``, piecewise Chebyshev to `tol`.

    Parameters
    ----------
    completion : Completion
        A time-varying completion.
    t_span : pair of float
        The interval, of positive length.
    tol : float
        Relative accuracy of ``G`` (to ``max(max |G|, 1 / (b - a))``) and
        of ``g`` (to ``max |g|``) over the interval.
    max_evaluations : int
        Budget of the construction: pieces not resolved when it is spent
        are evaluated pointwise (rounding noise above `tol`, or a forcing
        that is not smooth, would otherwise split the interval forever).

    Attributes
    ----------
    evaluations : int
        Evaluations of the completion spent on the construction.
    pieces : list of (a, b, degree)
        The pieces; degree None where the completion is evaluated pointwise.

    Raises
    ------
    EvaluationFailed
        When evaluating the completion raises a ValueError (a forcing that
        is not finite, a rank that changes); it holds the time and the error.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import complete, gallery
    >>> p = gallery.rotating_canonical(3)
    >>> c = complete(p.dae, "alternative", lam=1.0)
    >>> cheb = ChebyshevCoefficients(c, p.t_span, 1e-8)
    >>> G, g = c.matrices(1.234)
    >>> bool(np.abs(cheb.matrices(1.234)[0] - G).max() < 1e-7 * np.abs(G).max())
    True
    """

    def __init__(self, completion, t_span, tol, max_evaluations=500):
        self.completion = completion
        self.n = completion.n
        self._nn = self.n * self.n  # G's entries come first in a sample, g's after them
        self.tol = tol
        a, b = sorted(map(float, t_span))
        if not b > a:
            raise ValueError(f"`t_span` must have positive length; found {t_span!r}.")
        self.evaluations = 0
        self._values = {}  # every evaluation, by time: nested degrees and neighbouring pieces share them
        # A rate's scale is at least 1 / (b - a): an error tol / (b - a) in G moves the solution by
        # about tol of itself over the interval, and a G that vanishes (to rounding) needs no more.
        self._scale = np.array([1.0 / (b - a), 0.0])
        done = self._sweep(a, b, max_evaluations)
        self.origin, self.end = a, b
        # pieces by their offsets from `origin` (exact: lo - a has no rounding for lo in [a / 2, 2 a]), so that
        # `matrices_local` places a time on them to the rounding of the offset, not of t itself
        self._breaks = [piece[0] - a for piece in done[1:]]
        self._local = [(lo - a, hi - a, coef) for lo, hi, coef in done]
        self._pieces = done
        self.pieces = [(lo, hi, None if coef is None else coef.shape[0] - 1) for lo, hi, coef in done]
        self._ks = {}
        self._values = None  # only needed while fitting
        self._last = (None, None, None)

    def _sweep(self, a, b, budget):
        """The pieces ``(lo, hi, coefficients or None)`` from `a` to `b`, sized from the decay seen so far."""
        done, lo, length, decay = [], a, b - a, None
        while lo < b:
            if self.evaluations >= budget:  # not smooth enough (or noisy) to pay off: pointwise
                done.append((lo, b, None))
                break
            rest = b - lo
            count = max(1, math.ceil(rest / length * (1 - 1e-9)))
            if count > 1 and rest / (count - 1) <= 1.2 * length:  # no sliver at the end
                count -= 1
            hi = b if count == 1 else lo + rest / count
            first = _FIRST_DEGREE if decay is None else min(_MAX_DEGREE, max(8, math.ceil(
                _MARGIN * decay.degree(hi - lo) + 2)))
            coef, decay_here = self._fit(lo, hi, first, probing=decay is None)
            if coef is not None:
                done.append((lo, hi, coef))
                decay = _slower(decay, decay_here)
                length, lo = min(decay.length_for(_TARGET), 2 * (hi - lo)), hi
            elif hi - lo <= _MIN_PIECE * (b - a):  # a jump or a kink: pointwise, then start afresh
                done.append((lo, hi, None))
                decay, lo, length = None, hi, b - hi  # the rest from a probe again
            else:  # wasted: shorter, and from the degree this decay predicts
                decay = _slower(decay, decay_here)
                length = min(max(decay.length_for(_TARGET), (hi - lo) / 8), (hi - lo) / 2)
        return done

    def _sample(self, t):
        v = self._values.get(t)
        if v is None:
            try:
                G, g = self.completion.matrices(t)
            except ValueError as exc:  # a forcing that is not finite, a rank that changes: reported by the caller
                raise EvaluationFailed(t, exc) from exc
            v = self._store(t, G, g)
        return v

    def _store(self, t, G, g):
        v = self._values[t] = np.concatenate([G.ravel(), g])
        self.evaluations += 1
        nn = self._nn
        self._scale = np.maximum(self._scale, [np.abs(v[:nn]).max(initial=0.0), np.abs(v[nn:]).max(initial=0.0)])
        return v

    def _sample_many(self, ts):
        """The values at `ts`; the new times evaluated together (stacked), any that leaves out one by one."""
        new = [t for t in dict.fromkeys(ts) if t not in self._values]
        for t, res in zip(new, stacked(self.completion, new)):
            if res is not None:
                self._store(t, res[0], res[1][:, 0])
        return np.array([self._sample(t) for t in ts])

    def _fit(self, lo, hi, m, probing):
        """``(coefficients or None, _Decay)`` on ``[lo, hi]``, from degree m up to multiples of it predicted to do.

        The scale is the largest value seen so far on the whole interval, which only grows: a piece
        accepted early is judged against a scale no larger than the final one.
        """
        nn = self._nn
        while True:
            ts = chebyshev_points(m, (lo, hi))
            coef = chebyshev_coefficients(self._sample_many([float(t) for t in ts]), ts, (lo, hi))
            size = np.abs(coef[:, :nn]).max(axis=1, initial=0.0) / self._scale[0]
            if self._scale[1] > 0:
                size = np.maximum(size, np.abs(coef[:, nn:]).max(axis=1, initial=0.0) / self._scale[1])
            passed = bool(size[-3:].max() <= self.tol)
            decay = _Decay(size, self.tol, 0.5 * (hi - lo), passed)
            if passed:
                return coef, decay
            if probing and m < _PROBE:  # 9 and 17 values predict little: 8, 16, 32 on the first piece
                m *= 2
                continue
            # The values of degree m are among those of any multiple of m: the next degree is the least
            # multiple that the decay predicts to be enough, if there is one. The first piece doubles
            # when there is none: from 64 values on, the prediction is reliable (the decay of the first
            # coefficients is rarely the asymptotic one), and this may be the only piece.
            target = m * max(2, math.ceil((_MARGIN * decay.degree(hi - lo) + 1) / m))
            if target > _MAX_DEGREE and probing and m < 2 * _PROBE:
                target = 2 * m
            if target > _MAX_DEGREE:
                return None, decay
            m = target

    def matrices(self, t):
        """``(G, g)`` at `t`, from the interpolant (pointwise outside it or on unresolved pieces)."""
        t = float(t)
        if not self.origin <= t <= self.end:
            return self.completion.matrices(t)
        return self.matrices_local(t - self.origin)

    def matrices_local(self, s):
        """``(G, g)`` at the time ``origin + s``, placed on the pieces by its offset `s` from `origin`.

        An integrator run in the offset ``s = t - origin`` (`lsc.solve_completion` does) has stage times
        exact to the rounding of ``s``: at ``t = 1e8`` the time itself is known to 1.5e-8 only, which
        DOP853 at rtol 1e-10 met with 300,000 evaluations where 239 do near t = 0.
        """
        s = float(s)
        if s == self._last[0]:
            return self._last[1], self._last[2]
        lo, hi, coef = self._local[bisect.bisect_right(self._breaks, s)]
        if coef is None or not lo - 1e-12 * (hi - lo) <= s <= hi + 1e-12 * (hi - lo):
            G, g = self.completion.matrices(self.origin + s)
        else:
            m = coef.shape[0] - 1
            k = self._ks.get(m)
            if k is None:
                k = self._ks[m] = np.arange(m + 1)
            x = min(1.0, max(-1.0, ((s - lo) - (hi - s)) / (hi - lo)))  # (see `_positions`)
            v = np.cos(k * np.arccos(x)) @ coef
            G, g = v[: self._nn].reshape(self.n, self.n), v[self._nn :]
        self._last = (s, G, g)
        return G, g

    def rhs(self, t, x):
        G, g = self.matrices(t)
        return G @ x + g

    def jac(self, t, x):
        return self.matrices(t)[0]

    def rhs_local(self, s, x):
        """`rhs` at ``origin + s`` (see `matrices_local`)."""
        G, g = self.matrices_local(s)
        return G @ x + g

    def jac_local(self, s, x):
        return self.matrices_local(s)[0]

    @property
    def unresolved(self):
        """The pieces ``(lo, hi)`` evaluated pointwise."""
        return [(lo, hi) for lo, hi, coef in self._pieces if coef is None]

    def describe(self):
        degrees = [d for _, _, d in self.pieces if d is not None]
        pointwise = len(self.pieces) - len(degrees)
        text = (f"G(t), g(t) interpolated to {self.tol:.0e} on {len(self.pieces)} piece(s), degree "
                f"{min(degrees, default=0)}-{max(degrees, default=0)}, from {self.evaluations} evaluations")
        if pointwise:
            text += f"; {pointwise} unresolved piece(s) evaluated pointwise"
        return text
