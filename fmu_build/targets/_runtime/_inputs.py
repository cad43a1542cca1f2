"""Input signals: an input and its derivatives estimated from the values a master sets.

The estimator (the native FMUs run the same one, ``templates/inputs.c``):

* every received value is kept twice: the newest ``degree + 1`` values as
  they are, and all values of the last ``window`` seconds as weighted sums
  (for each window of LEVELS, the moments of ``NBINS + 1`` bins of a
  ``NBINS``-th of it; a value weighs the time since the value before it);
* ``E_I``, the polynomial of degree ``degree`` through the newest values,
  is exact for exact samples of a smooth input (error O(h^(degree + 1 - j))
  in the j-th derivative for values h apart);
* ``E_S``, a least-squares polynomial of degree ``degree - 1`` over a
  window, weighted by ``(1 - x^2)^2`` on the window mapped to [-1, 1],
  averages what the newest values cannot tell apart: a host that
  interpolates a table linearly and steps below its spacing sends points
  on straight segments, and ``E_I`` would differentiate their kinks;
* ``E_I`` is taken where it agrees with ``E_S`` within ``MARGIN`` times
  ``E_S``'s own uncertainty, for every derivative the completion uses; the
  uncertainty of order j is the larger change of that derivative when the
  fit's degree goes up by one and by two. Otherwise ``E_I``'s derivatives up
  to the last order that agrees (with all below it), ``E_S``'s above;
* ``E_S`` is the fit over the window, among ``window`` times LEVELS, whose
  highest derivative used is the least uncertain (another one than
  ``window`` only where ``SWITCH`` times less uncertain);
* while the values span less than the window and three consecutive ones
  lie on a straight line (a host interpolating a table between its rows),
  the degree is ``floor((degree + 1) span / window)``: derivatives the
  span cannot support are zero (guessed), not differentiated kinks.

The estimate is kept as the Taylor coefficients of its polynomial at the
newest value's time, with the value received there as its constant term.
"""

import functools
import math

import numpy as np

NBINS = 8  # complete bins per window (the window's bins hold every value received in it)
LEVELS = (0.5, 1.0, 2.0)  # the windows tried, in units of `window`
_MIDDLE = LEVELS.index(1.0)
TAPER = 2  # weight (1 - x^2)^TAPER on the window mapped to [-1, 1]: no end of the window is a kink
MARGIN = 3.0  # E_I is taken within MARGIN times E_S's uncertainty
AGREE = 1e-8  # E_I and E_S this close (relative) agree whatever the fit's uncertainty (rounding tells no more)
SWITCH = 3.0  # another window than `window` only where its uncertainty is this many times less
MAX_DEGREE = 8

_FACTORIALS = np.array([float(math.factorial(j)) for j in range(32)])
_EPS = np.finfo(float).eps


@functools.lru_cache(maxsize=None)
def _shift_pattern(size):
    power = np.subtract.outer(np.arange(size), np.arange(size))  # m - j
    return np.maximum(power, 0), power >= 0


def _shift(s, size):
    """``S`` with ``d @ S`` the derivatives 0..size-1 at t + s of a polynomial whose derivatives at t are ``d``."""
    power, upper = _shift_pattern(size)
    return np.where(upper, float(s) ** power / _FACTORIALS[power], 0.0)


@functools.lru_cache(maxsize=None)
def _chebyshev_at_one(size):
    """``D[a, j] = T_a^(j)(1)``, a, j < size (read only)."""
    D = np.zeros((size, size))
    for a in range(size):
        v = 1.0
        for j in range(size):
            D[a, j] = v
            v *= (a * a - j * j) / (2 * j + 1)
    return D


_LOCAL = {}  # size -> G with T_a^(p)(alpha) / p! = sum_j G[p, j, a] alpha^j


def _chebyshev_local(alpha, beta, size):
    """``B[..., a, p] = T_a^(p)(alpha) beta^p / p!`` (T_a(alpha + beta s) = sum_p B[a, p] s^p) for arrays alpha, beta.

    From the monomial coefficients of T_a (integers, summing in absolute value to less than 3^a: the rounding
    stays below 1e-12 relative for |alpha| <= 1 and a <= 10)."""
    G = _LOCAL.get(size)
    if G is None:
        C = np.zeros((size, size))  # T_a(x) = sum_c C[a, c] x^c
        C[0, 0] = 1.0
        if size > 1:
            C[1, 1] = 1.0
        for a in range(1, size - 1):
            C[a + 1, 1:] = 2.0 * C[a, :-1]
            C[a + 1] -= C[a - 1]
        G = np.zeros((size, size, size))
        for p in range(size):
            for j in range(size - p):
                G[p, j] = C[:, p + j] * math.comb(p + j, p)
        G = _LOCAL[size] = G
    alpha = np.asarray(alpha, dtype=float)
    powers = alpha[..., None] ** np.arange(size)
    scale = np.asarray(beta, dtype=float)[..., None] ** np.arange(size)
    return np.einsum("...j,pja->...ap", powers, G) * scale[..., None, :]


class _SignalState:
    """The FMU state of an input's estimate (`_InputSignal`): saved as JSON-able data, checked, restored."""

    def state(self):
        """Everything the estimate depends on, as JSON-able lists and numbers."""
        return {"value": self.value, "history": [list(h) for h in self.history], "origin": self._origin,
                "first": self._first, "k": self._k.tolist(), "n": self._n.tolist(), "lo": self._lo.tolist(),
                "m": self._m.tolist(), "r": self._r.tolist()}

    def check(self, saved):
        """Why `saved` (from `state`) cannot be restored, or None."""
        def finite(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        malformed = "its input history is malformed"
        if not (isinstance(saved, dict) and finite(saved.get("value")) and isinstance(saved.get("history"), list)):
            return malformed
        history = saved["history"]
        if not (len(history) <= self.degree + 1
                and all(isinstance(h, list) and len(h) == 3 and all(finite(v) for v in h) for h in history)
                and all(a[0] < b[0] for a, b in zip(history, history[1:]))):
            return malformed
        if not history or self.order < 0:  # an input whose derivatives are not used keeps its last value only
            return None
        if not (finite(saved.get("origin")) and finite(saved.get("first"))):
            return malformed
        shapes = {"k": self._k.shape, "n": self._n.shape, "lo": self._lo.shape, "m": self._m.shape, "r": self._r.shape}
        for key, shape in shapes.items():
            try:
                array = np.array(saved.get(key), dtype=float)
            except (TypeError, ValueError):
                return malformed
            if array.shape != shape or not np.all(np.isfinite(array)):
                return malformed
        n = np.array(saved["n"], dtype=float)
        if np.any(n < 0) or np.any(n != np.round(n)):
            return malformed
        return None

    def restore(self, saved):
        """Restore a state `check` accepted (the estimate is recomputed from it, bit for bit)."""
        self.reset()
        self.value = saved["value"]
        self.history = [tuple(h) for h in saved["history"]]
        if not self.history:
            return
        if self.order < 0:
            self._t0, self._derivs = self.history[-1][0], np.array([self.history[-1][1]])
            return
        self._origin, self._first = saved["origin"], saved["first"]
        self._k = np.array(saved["k"], dtype=float)
        self._n = np.array(saved["n"], dtype=int)
        self._lo = np.array(saved["lo"], dtype=float)
        self._m = np.array(saved["m"], dtype=float)
        self._r = np.array(saved["r"], dtype=float)
        self._estimate()


class _InputSignal(_SignalState):
    """Estimates of an input and its derivatives from the values received.

    pythonfmu cannot receive input derivatives, so they are estimated (module
    docstring). Only derivatives the completion can use are estimated
    (``order``: the highest one; 0 means only the value is used; -1 that the
    input is never used); the polynomial's degree is ``order + 4`` (at most
    8); `taylor` gives every derivative of it (exact stepping), `jet` those
    the completion reads.

    Parameters
    ----------
    order : int
        Highest derivative of this input the completion uses (-1: none).
    start : float
        The input's start value.
    order_max : int
        Length - 1 of the jets `jet` returns.
    window : float
        Span (s) of the least-squares window, > 0.
    """

    def __init__(self, order, start, order_max, window=0.3):
        if not (isinstance(window, (int, float)) and math.isfinite(window) and window > 0):
            raise ValueError(f"`window` must be a finite number > 0; found {window!r}.")
        self.order, self.order_max, self.window = order, order_max, float(window)
        self.degree = min(order + 4, MAX_DEGREE) if order >= 0 else 0
        self.value = start
        self._nm = 2 * (self.degree + 2) + 2 * TAPER + 1  # time moments 0..nm-1 per bin
        self._nr = self.degree + 3 + 2 * TAPER  # value moments 0..nr-1 per bin
        self.reset()

    # -- the received values ---------------------------------------------
    def reset(self):
        """Forget every value received."""
        self.history = []  # the newest values (t, value, weight), increasing t
        self._origin = None  # time of bin 0 of every level
        self._first = None  # time of the first value since the last reset
        shape = (len(LEVELS), NBINS + 1)
        self._k = np.zeros(shape)  # each slot's bin index
        self._n = np.zeros(shape, dtype=int)  # values in it (0: empty)
        self._lo = np.zeros(shape)  # the earliest of their times
        self._m = np.zeros(shape + (self._nm,))  # sum of w s^p
        self._r = np.zeros(shape + (self._nr,))  # sum of w u s^p
        self._derivs = None  # derivatives of the estimate at _t0 (index 0: the value received there)
        self._t0 = None
        self._jet_at = (None, None)
        self._fits = {}  # level -> ((bin index, degree) it was made at, its fit): a function of the bins
        self._width_list = [self.window * level / NBINS for level in LEVELS]
        self._powers = np.arange(self._nm)

    def _widths(self):
        return self.window * np.array(LEVELS) / NBINS

    def _accumulate(self, t, u, w, sign):
        slots = NBINS + 1
        for level, width in enumerate(self._width_list):
            k = math.floor((t - self._origin) / width)
            slot = k % slots
            n = int(self._n[level, slot])
            if n > 0 and self._k[level, slot] != k:
                n = 0  # the slot holds a bin that left the window
            if n <= 0:
                if sign < 0:
                    continue
                self._m[level, slot] = 0.0
                self._r[level, slot] = 0.0
                self._k[level, slot] = k
                self._lo[level, slot] = t
            n += sign
            if n <= 0:
                self._n[level, slot] = 0
                self._m[level, slot] = 0.0
                self._r[level, slot] = 0.0
                continue
            self._n[level, slot] = n
            self._lo[level, slot] = min(self._lo[level, slot], t)
            powers = ((t - (self._origin + (k + 0.5) * width)) / width) ** self._powers
            self._m[level, slot] += (sign * w) * powers
            self._r[level, slot] += (sign * w * u) * powers[: self._nr]

    def record(self, t):
        """Take the current value as received at t (a repeated or earlier t replaces what came after).

        Returns whether the estimate changed as a function of time: False when its polynomial is exactly the
        one before (a constant input, or one never set), so that what was integrated with it stands.
        """
        before = (self._t0, self._derivs)
        self._record(t)
        return not self._same_polynomial(*before)

    def _same_polynomial(self, t0, derivs):
        """Whether the estimate is exactly the polynomial with Taylor coefficients `derivs` at `t0`."""
        if derivs is None or self._derivs is None:
            return False
        size = max(derivs.size, self._derivs.size)
        old, new = np.zeros(size), np.zeros(size)
        old[: derivs.size], new[: self._derivs.size] = derivs, self._derivs
        if not np.all(old[1:] == 0.0):  # shifted to the new time, only a constant is the same to the last bit
            s = self._t0 - t0
            w = s ** np.arange(size) / _FACTORIALS[:size]
            old = np.array([old[j:] @ w[: size - j] for j in range(size)])
        return bool(np.array_equal(old, new))

    def _record(self, t):
        self._jet_at = (None, None)
        u = float(self.value)
        if self.order < 0:
            self.history = [(t, u, 0.0)]
            self._t0, self._derivs = t, np.array([u])
            return
        if self.history and t < self.history[-1][0]:
            # an earlier time without a restored state: start again from the newest values before it
            kept = [h for h in self.history if h[0] < t]
            self.reset()
            for tk, uk, _ in kept:
                self.value = uk
                self._record(tk)
            self.value = u
        if self.history and t == self.history[-1][0]:  # the same step again: replace its value
            _, old, w = self.history.pop()
            self._accumulate(t, old, w, -1)
        else:
            w = t - self.history[-1][0] if self.history else 0.0
        if self._origin is None:
            self._origin = self._first = t
        self.history.append((t, u, w))
        del self.history[: -(self.degree + 1)]
        self._accumulate(t, u, w, 1)
        self._estimate()

    # -- the estimate ----------------------------------------------------
    def _interpolant(self, e):
        """Derivatives 0..e at the newest time of the polynomial through the newest e + 1 values."""
        pts = self.history[-(e + 1):]
        n = len(pts)
        out = np.zeros(e + 1)
        if n == 1:
            out[0] = pts[0][1]
            return out
        t0 = pts[-1][0]
        scale = t0 - pts[0][0]
        x = [(p[0] - t0) / scale for p in pts]
        # Newton's divided differences on the scaled nodes, then the Newton form's Taylor coefficients at 0
        # (plain floats: a handful of values, where numpy's calls would cost more than the arithmetic)
        dd = [p[1] for p in pts]
        for k in range(1, n):
            for m in range(n - 1, k - 1, -1):
                dd[m] = (dd[m] - dd[m - 1]) / (x[m] - x[m - k])
        coef = [0.0] * n
        coef[0] = dd[n - 1]
        for k in range(n - 2, -1, -1):  # Horner on (s - x_k): coef <- coef * (s - x_k) + dd[k]
            for m in range(n - 1, 0, -1):
                coef[m] = coef[m - 1] - x[k] * coef[m]
            coef[0] = dd[k] - x[k] * coef[0]
        out[:n] = np.array(coef) * _FACTORIALS[:n] / scale ** np.arange(n)
        return out

    def _straight(self):
        """True when three consecutive values of the newest lie on a straight line (to rounding): a host that
        interpolates a table linearly and steps below its spacing (the kinks at its rows cannot be told from
        the input's own curvature until the values span the windows)."""
        pts = self.history
        for (t0, u0, _), (t1, u1, _), (t2, u2, _) in zip(pts, pts[1:], pts[2:]):
            chord = (u0 * (t2 - t1) + u2 * (t1 - t0)) / (t2 - t0)
            if abs(u1 - chord) <= 64.0 * _EPS * (abs(u0) + abs(u1) + abs(u2)):
                return True
        return False

    def _least_squares(self, e, levels):
        """For each index into LEVELS in `levels`: (derivatives 0..e at the newest time, their uncertainties) of the
        fit of degree e over that window's complete bins, or None when they hold too few values.

        A fit depends on the complete bins only (the one being filled is left out: the taper gives the newest
        values little weight anyway), so it is made once per bin and kept; the newest time reads it shifted
        (its polynomial's Taylor shift, exact)."""
        t_ref = self.history[-1][0]
        widths = self._widths()
        k_refs = np.floor((t_ref - self._origin) / widths)
        todo = [level for level in levels if self._fits.get(level, (None,))[0] != (k_refs[level], e)]
        if todo:
            for level, fit in zip(todo, self._fit_levels(e, todo, k_refs[todo])):
                self._fits[level] = ((k_refs[level], e), fit)
        out = []
        for level in levels:
            fit = self._fits[level][1]
            if fit is None:
                out.append(None)
                continue
            t_end, fits = fit  # rows: the derivatives 0..q (zero beyond) of the fits of degree q = e, e + 1, e + 2
            at = fits @ _shift(t_ref - t_end, e + 3)[:, : e + 1]
            out.append((at[0], np.maximum(np.abs(at[1] - at[0]), np.abs(at[2] - at[1]))))
        return out

    def _fit_levels(self, e, levels, k_refs):
        """The fits of degree e, e + 1, e + 2 over the complete bins of each level: (end time, [derivatives 0..q
        of the fit of degree q there]) or None, all levels in one pass."""
        levels = np.asarray(levels)
        widths = self._widths()[levels]
        k, n = self._k[levels], self._n[levels]
        k_ref = np.asarray(k_refs)[:, None]
        inside = (n > 0) & (k >= k_ref - NBINS) & (k < k_ref)
        count = (n * inside).sum(axis=1)
        lo = np.where(inside, self._lo[levels], np.inf).min(axis=1)
        t_end = self._origin + k_ref[:, 0] * widths
        span = t_end - lo
        ok = (count >= e + 6) & (span > 0.0)
        out = [None] * len(levels)
        if not ok.any():
            return out
        span = np.where(ok, span, 1.0)[:, None]
        size = e + 3  # fits of degree e, e + 1 and e + 2
        alpha = np.where(inside, 2.0 * (self._origin + (k + 0.5) * widths[:, None] - t_end[:, None]) / span + 1.0, 0.0)
        beta = 2.0 * widths[:, None] / span
        # (1 - x^2)^2 with x = alpha + beta s: a polynomial of degree 4 in the bin's time s (zero outside the window)
        o0, o1, o2 = 1.0 - alpha * alpha, -2.0 * alpha * beta, -beta * beta + 0.0 * alpha
        taper = np.stack([o0 * o0, 2.0 * o0 * o1, o1 * o1 + 2.0 * o0 * o2, 2.0 * o1 * o2, o2 * o2], axis=-1) * inside[..., None]
        windows = np.lib.stride_tricks.sliding_window_view
        mt = np.einsum("lbpq,lbq->lbp", windows(self._m[levels], 5, axis=2)[:, :, : 2 * size - 1], taper)
        rt = np.einsum("lbpq,lbq->lbp", windows(self._r[levels], 5, axis=2)[:, :, :size], taper)
        B = _chebyshev_local(alpha, beta + 0.0 * alpha, size)
        H = mt[..., np.add.outer(np.arange(size), np.arange(size))]
        N = (B @ H @ np.swapaxes(B, -1, -2)).sum(axis=1)
        y = np.einsum("lbap,lbp->la", B, rt)
        for i in np.flatnonzero(ok):
            try:
                L = np.linalg.cholesky(N[i])
            except np.linalg.LinAlgError:
                continue
            if not np.all(np.diag(L) ** 2 > 1e-14 * np.diag(N[i]).max()):
                continue
            D = _chebyshev_at_one(size) * (2.0 / span[i, 0]) ** np.arange(size)
            z = np.linalg.solve(L, y[i])
            fits = np.zeros((3, size))
            for f, q in enumerate((e, e + 1, e + 2)):
                fits[f, : q + 1] = np.linalg.solve(L[: q + 1, : q + 1].T, z[: q + 1]) @ D[: q + 1, : q + 1]
            if np.all(np.isfinite(fits)):
                out[i] = (float(t_end[i]), fits)
        return out

    def _estimate(self):
        t_ref, u_ref = self.history[-1][0], self.history[-1][1]
        d = self.degree
        span = t_ref - self._first
        e = d
        ramp = self.window * LEVELS[-1]  # until the values span the longest window
        if span < ramp * (1 - 1e-12) and self._straight():
            e = min(d, int((d + 1) * span / ramp))
        estimate = self._interpolant(e)
        if e > 0:
            # the window whose highest derivative used is the least uncertain; another than `window` only where
            # SWITCH times less uncertain (the uncertainty is itself noisy: a window does not win by chance)
            es = min(e, d - 1)  # E_S: one degree less than E_I (more robust to what is not a polynomial)
            used = range(min(es, self.order) + 1)
            fits = self._least_squares(es, range(len(LEVELS)))
            fit, bound = fits[_MIDDLE], (fits[_MIDDLE][1][used[-1]] / SWITCH if fits[_MIDDLE] else np.inf)
            for level, other in enumerate(fits):
                if level != _MIDDLE and other is not None and other[1][used[-1]] < bound:
                    fit, bound = other, other[1][used[-1]]
            if fit is not None:
                # E_I up to the last order that agrees with E_S (the orders below it too); E_S above: exact
                # samples amplify their rounding in E_I's highest orders, where E_S is as good
                smooth, uncertainty = fit
                agree = 0
                while agree < len(used) and (abs(estimate[agree] - smooth[agree])
                                             <= MARGIN * uncertainty[agree]
                                             + AGREE * (abs(smooth[agree]) + abs(estimate[agree])) + 1e-13):
                    agree += 1
                if agree < len(used):
                    estimate = np.concatenate([estimate[:agree], smooth[agree:], np.zeros(e - es)])
        estimate = estimate.copy()
        estimate[0] = u_ref
        self._t0, self._derivs = t_ref, estimate

    def _at(self, t, top):
        """Derivatives 0..top of the estimate's polynomial at t."""
        out = np.zeros(top + 1)
        d = self._derivs
        if d is None:
            out[0] = self.value
            return out
        s = t - self._t0
        if s == 0.0:
            m = min(top + 1, d.size)
            out[:m] = d[:m]
            return out
        # Taylor shift: u^(j)(t0 + s) = sum_m d_(j+m) s^m / m!
        w = s ** np.arange(d.size) / _FACTORIALS[: d.size]
        for j in range(min(top + 1, d.size)):
            out[j] = d[j:] @ w[: d.size - j]
        return out

    def jet(self, t):
        """[u, u', ..., u^(order_max)] at t (zeros beyond the orders in use; read only)."""
        at, out = self._jet_at
        if at == t and self._derivs is not None:
            return out
        out = self._at(t, self.order_max)
        out[(min(self.order, self.order_max) + 1 if self.order >= 0 else 1):] = 0.0
        self._jet_at = (t, out)
        return out

    def taylor(self, t, top):
        """Every derivative 0..top of the extrapolation polynomial at t (zero beyond its degree)."""
        return self._at(t, top)
