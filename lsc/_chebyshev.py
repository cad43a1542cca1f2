"""Piecewise Chebyshev interpolants of a time-varying completion's ``G(t)``, ``g(t)``.

A time-varying completion costs one factorization of the derivative array
(and the coefficients' derivatives to order k + 1) per evaluation, and an
ODE solver evaluates it at every stage of every step: hundreds to thousands
of times on one interval, more at tight tolerances. ``G`` and ``g`` are as
smooth as the coefficients, so a few dozen evaluations at Chebyshev points
determine them on a piece of the interval to any accuracy; the solver then
evaluates polynomials (one ``cos`` and one matrix product per call).

Construction is adaptive, as in Chebfun: on a piece, interpolate at the
``m + 1`` Chebyshev extreme points for ``m = 8, 16, ..., 128`` (nested: each
degree reuses the previous values) and accept the first degree whose last
three coefficients are below ``tol`` relative to the largest value of ``G``
(and, separately, of ``g``); if 128 is not enough, halve the piece. A piece
that is still unresolved at 1e-6 of the interval's length (a jump in the
forcing, say), or left when the budget of evaluations is spent, is
evaluated pointwise, so the interpolant is never silently wrong by more than
its tolerance.
"""

import bisect

import numpy as np
import scipy.fft

__all__ = []

_DEGREES = (8, 16, 32, 64, 128)
_MIN_PIECE = 1e-6  # of the interval's length


class EvaluationFailed(Exception):
    """Evaluating the completion at a Chebyshev point raised `exc` (a ValueError)."""

    def __init__(self, t, exc):
        super().__init__(str(exc))
        self.t, self.exc = t, exc


def _extreme_points(m):
    """``cos(pi j / m)``, j = 0..m (from +1 to -1), with exact symmetry."""
    return np.sin(np.pi * (m - 2 * np.arange(m + 1)) / (2 * m))


def _coefficients(values):
    """Chebyshev coefficients of the interpolant through values at `_extreme_points`."""
    m = values.shape[0] - 1
    c = scipy.fft.dct(values, type=1, axis=0) / m
    c[0] /= 2
    c[m] /= 2
    return c


class ChebyshevCoefficients:
    """``G(t)``, ``g(t)`` of a completion on ``[a, b]``, piecewise Chebyshev to `tol`.

    Parameters
    ----------
    completion : Completion
        A time-varying completion.
    t_span : pair of float
    tol : float
        Relative accuracy of ``G`` (to ``max |G|``) and of ``g`` (to
        ``max |g|``) over the interval.
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
    """

    def __init__(self, completion, t_span, tol, max_evaluations=500):
        self.completion = completion
        self.n = completion.n
        self._nn = self.n * self.n  # G's entries come first in a sample, g's after them
        self.tol = tol
        a, b = sorted(map(float, t_span))
        self.evaluations = 0
        self._values = {}  # every evaluation, by time: nested degrees and neighbouring pieces share them
        self._scale = np.zeros(2)
        todo, done = [(a, b)], []
        while todo:
            lo, hi = todo.pop()
            if self.evaluations >= max_evaluations:  # not smooth enough (or noisy) to pay off: pointwise
                done.append((lo, hi, None))
                continue
            coef = self._fit(lo, hi)
            if coef is not None or hi - lo <= _MIN_PIECE * (b - a):
                done.append((lo, hi, coef))
            else:
                mid = 0.5 * (lo + hi)
                todo += [(mid, hi), (lo, mid)]
        done.sort(key=lambda piece: piece[0])
        self._breaks = [piece[0] for piece in done[1:]]
        self._pieces = done
        self.pieces = [(lo, hi, None if coef is None else coef.shape[0] - 1) for lo, hi, coef in done]
        self._ks = {}
        self._values = None  # only needed while fitting
        self._last = (None, None, None)

    def _sample(self, t):
        v = self._values.get(t)
        if v is None:
            try:
                G, g = self.completion.matrices(t)
            except ValueError as exc:  # a forcing that is not finite, a rank that changes: reported by the caller
                raise EvaluationFailed(t, exc) from exc
            v = self._values[t] = np.concatenate([G.ravel(), g])
            self.evaluations += 1
            nn = self._nn
            self._scale = np.maximum(self._scale, [np.abs(v[:nn]).max(initial=0.0), np.abs(v[nn:]).max(initial=0.0)])
        return v

    def _fit(self, lo, hi):
        nn = self._nn
        for m in _DEGREES:
            ts = 0.5 * (hi + lo) + 0.5 * (hi - lo) * _extreme_points(m)
            ts[0], ts[-1] = hi, lo
            coef = _coefficients(np.array([self._sample(float(t)) for t in ts]))
            tail = np.abs(coef[-3:])
            # The scale is the largest value seen so far on the whole interval, which only grows:
            # a piece accepted early is judged against a scale no larger than the final one.
            G_ok = tail[:, :nn].max(initial=0.0) <= self.tol * self._scale[0]
            g_ok = tail[:, nn:].max(initial=0.0) <= self.tol * self._scale[1]
            if G_ok and g_ok:
                return coef
        return None

    def matrices(self, t):
        """``(G, g)`` at `t`, from the interpolant (pointwise outside it or on unresolved pieces)."""
        t = float(t)
        if t == self._last[0]:
            return self._last[1], self._last[2]
        lo, hi, coef = self._pieces[bisect.bisect_right(self._breaks, t)]
        if coef is None or not lo - 1e-12 * (hi - lo) <= t <= hi + 1e-12 * (hi - lo):
            G, g = self.completion.matrices(t)
        else:
            m = coef.shape[0] - 1
            k = self._ks.get(m)
            if k is None:
                k = self._ks[m] = np.arange(m + 1)
            s = min(1.0, max(-1.0, (2.0 * t - lo - hi) / (hi - lo)))
            v = np.cos(k * np.arccos(s)) @ coef
            G, g = v[: self._nn].reshape(self.n, self.n), v[self._nn :]
        self._last = (t, G, g)
        return G, g

    def rhs(self, t, x):
        G, g = self.matrices(t)
        return G @ x + g

    def jac(self, t, x):
        return self.matrices(t)[0]

    def describe(self):
        degrees = [d for _, _, d in self.pieces if d is not None]
        pointwise = len(self.pieces) - len(degrees)
        text = (f"G(t), g(t) interpolated to {self.tol:.0e} on {len(self.pieces)} piece(s), degree "
                f"{min(degrees, default=0)}-{max(degrees, default=0)}, from {self.evaluations} evaluations")
        if pointwise:
            text += f"; {pointwise} unresolved piece(s) evaluated pointwise"
        return text
