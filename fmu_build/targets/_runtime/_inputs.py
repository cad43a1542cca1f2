"""Input signals: an input and its derivatives estimated from the values a master sets."""

import math

import numpy as np

_FACTORIALS = np.array([float(math.factorial(j)) for j in range(32)])
_DIFFERENTIATORS = {}  # normalized node times -> matrix from values to scaled derivatives at the last node


def _differentiator(nodes):
    """``D`` with ``D @ values = [j! c_j]``, ``c`` the coefficients of the polynomial through (nodes, values)."""
    D = _DIFFERENTIATORS.get(nodes)
    if D is None:
        if len(_DIFFERENTIATORS) > 64:  # variable step sizes: keep the table small
            _DIFFERENTIATORS.clear()
        V = np.vander(np.array(nodes), len(nodes), increasing=True)
        factorials = np.array([math.factorial(j) for j in range(len(nodes))], dtype=float)
        D = _DIFFERENTIATORS[nodes] = factorials[:, None] * np.linalg.inv(V)
    return D


class _InputSignal:
    """Estimates of an input and its derivatives from the values received.

    pythonfmu cannot receive input derivatives, so they are estimated: the
    polynomial through the last ``degree + 1`` (time, value) pairs received
    at communication points gives the input and its derivatives, and is
    extrapolated over the step being taken. With communication step h the
    j-th derivative has error O(h^(degree + 1 - j)) for a smooth input;
    ``degree`` is the highest derivative the completion uses plus 2. Only
    derivatives the completion can use are estimated (``order``: the highest
    one; 0 means only the value is used; -1 that the input is never used);
    `taylor` gives every derivative of the polynomial (exact stepping).

    The polynomial is kept as its derivatives at the last point received,
    from the values by one small matrix that depends only on the node times
    relative to the last step (rounded to 11 digits, so that masters' step
    jitter shares one matrix): equally spaced points cost one product.
    """

    def __init__(self, order, start, order_max):
        self.order, self.order_max = order, order_max
        self.history = []  # (t, value), increasing t
        self.value = start
        self.degree = order + 2 if order >= 0 else 0  # order -1: the input is never used
        self._derivs = None  # derivatives 0..deg of the polynomial at _t0
        self._jet_at = (None, None)  # (t, jet): A, B and f read the same jet at one time

    def record(self, t):
        self._jet_at = (None, None)
        if self.history and t <= self.history[-1][0]:
            # a repeated or earlier time (rollback handled by the snapshot): replace
            self.history = [h for h in self.history if h[0] < t]
        self.history.append((t, self.value))
        del self.history[: -(self.degree + 1)]
        history = self.history
        self._t0 = t0 = history[-1][0]
        if len(history) == 1:
            self._derivs = np.array([history[-1][1]])
            return
        scale = t0 - history[-2][0]
        nodes = tuple(round((h[0] - t0) / scale, 11) for h in history[:-1]) + (0.0,)
        D = _differentiator(nodes)
        self._derivs = (D @ np.array([h[1] for h in history])) / scale ** np.arange(len(history))

    def _at(self, t, top):
        """Derivatives 0..top of the polynomial at t."""
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
