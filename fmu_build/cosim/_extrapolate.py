"""Extrapolation of the coupling values over a macro step, and the band a step's produced values must stay in.

At a communication point ``t_n`` the master knows each coupling value at the last ``p + 1`` points and,
from a source that declares ``maxOutputDerivativeOrder``, its derivatives at ``t_n``. The input over the
step is the Taylor polynomial ``P(t_n + s) = sum_j c_j s^j / j!`` whose coefficients ``c_j`` are the
derivatives of the interpolating polynomial through the history (orders ``1..p``), replaced by the
source's own derivatives where it gives them and they are trusted, and only those beyond ``p``.
"""

import math

import numpy as np

from ._graph import _weights


def taylor(jet, H, top):
    """``sum_{j <= top} jet[j] H^j / j!`` (rows of ``jet`` beyond ``top`` ignored)."""
    out = jet[0].copy()
    for j in range(1, min(top, len(jet) - 1) + 1):
        out += jet[j] * H ** j / math.factorial(j)
    return out


class History:
    """Coupling values, output derivatives and watched recorded values at the last ``p + 1`` points."""

    def __init__(self, p, nder):
        self.p, self.nder = p, nder
        self.t, self.v, self.d, self.x = [], [], [], []
        self._weights = {}  # (nodes, at, order) -> interpolation weights, for the points of one step

    def weights(self, nodes, at, order):
        key = (tuple(nodes), at, order)
        if key not in self._weights:
            if len(self._weights) > 64:
                self._weights.clear()
            self._weights[key] = _weights(nodes, at, order)
        return self._weights[key]

    def push(self, t, value, derivs, extras):
        self.t.append(t)
        self.v.append(value.copy())
        self.d.append(derivs)
        self.x.append(extras.copy())
        keep = self.p + 1
        del self.t[:-keep], self.v[:-keep], self.d[:-keep], self.x[:-keep]

    def restart(self):
        """Forget every point but the newest (after a jump: the points before it describe another signal)."""
        del self.t[:-1], self.v[:-1], self.d[:-1], self.x[:-1]

    @property
    def degree(self):
        """Degree of the polynomial through the history (lower while it is short)."""
        return min(self.p, len(self.t) - 1)

    def jet(self, t_start, trusted, extra_point=None):
        """Value and derivatives ``1..nder`` of every slot at ``t_start``: ``(jet, has, exact)``.

        Orders up to ``p`` come from the polynomial through the history (+ ``extra_point``, a
        ``(t, values, derivs)`` appended for interpolation; 0 beyond its degree while it is short); a
        source's derivatives replace them where ``trusted`` (a mask over slots), and are the only ones
        known beyond ``p``. ``has``: what is sent; ``exact``: the source's derivatives among them.
        """
        p, nder = self.p, self.nder
        ts, vs, ds = list(self.t), list(self.v), list(self.d)
        if extra_point is not None:
            ts, vs, ds = ((a + [b])[-(p + 1):] for a, b in zip((ts, vs, ds), extra_point))
        V = np.array(vs)
        nslots = V.shape[1]
        jet = np.zeros((nder + 1, nslots))
        has = np.zeros((nder + 1, nslots), dtype=bool)
        has[:p + 1] = True
        exact = np.zeros((nder + 1, nslots), dtype=bool)
        jet[0] = V[-1] if len(ts) == 1 or t_start == ts[-1] else np.asarray(self.weights(ts, t_start, 0)) @ V
        at = next((i for i in range(len(ts) - 1, -1, -1) if ts[i] == t_start and ds[i] is not None), len(ts) - 1)
        last = ds[at]
        for j in range(1, nder + 1):
            jet[j] = self.weights(ts, t_start, j) @ V if len(ts) > j else 0.0
            if last is None:
                continue
            # exact derivatives where the source gives them: at the step start if known there,
            # else at the newest point, Taylor-shifted
            known = np.isfinite(last[j - 1]) & trusted
            if known.any():
                shift = np.zeros(nslots)
                for m in range(j, nder + 1):
                    dm = np.where(np.isfinite(last[m - 1]) & trusted, last[m - 1], 0.0)
                    shift += dm * (t_start - ts[at]) ** (m - j) / math.factorial(m - j)
                jet[j] = np.where(known, shift, jet[j])
                has[j] |= known
                exact[j] = known
        return jet, has, exact

    def higher_orders(self, t_start, trusted, upto):
        """Derivative orders beyond the sources' own, where a source's highest order ``m`` is trusted at every
        point of the history: the derivatives of the polynomial through those values of ``y^(m)`` at
        ``t_start`` (orders ``m + 1 .. m + degree``, exact for a polynomial ``y^(m)`` of that degree); NaN
        elsewhere. Rows ``0..upto``."""
        out = np.full((upto + 1, len(self.v[-1])), np.nan)
        if len(self.t) < 2 or any(d is None for d in self.d):
            return out
        D = np.array(self.d)  # points x orders x slots
        known = np.isfinite(D).all(axis=0) & trusted
        for s in np.flatnonzero(known.any(axis=0)):
            m = int(np.flatnonzero(known[:, s]).max()) + 1
            for j in range(m + 1, min(upto, m + len(self.t) - 1) + 1):
                out[j, s] = self.weights(self.t, t_start, j - m) @ D[:, m - 1, s]
        return out

    def extrapolate_extras(self, t_end):
        """The watched recorded values extrapolated to ``t_end`` by the polynomial through their history."""
        q = self.degree
        return np.asarray(self.weights(self.t[-(q + 1):], t_end, 0)) @ np.array(self.x[-(q + 1):])


class Band:
    """What the consumers of each slot were told about a step ``[t, t + H]``, and how far the values the
    step produced lie from it (the defect; docs/cosimulation.md, 'Step control').

    ``tops[s]``: the input-derivative orders the consumers of slot ``s`` received (0: the value only,
    held over the step); the band of degree ``T`` is the Taylor polynomial of the jet to order ``T``.
    ``jet``/``has``: what was sent (the trusted derivatives of the sources among them: ``exact``);
    ``values_jet``: the same from the values alone; ``degree``: that of the polynomial through the
    history, so that an order ``j`` is backed by data where ``j <= degree`` or ``exact[j]``.
    """

    def __init__(self, tops, jet, has, exact, values_jet, degree, H):
        self.tops, self.jet, self.has, self.exact, self.values_jet, self.H = tops, jet, has, exact, values_jet, H
        self.known = (np.arange(len(jet))[:, None] <= degree) | exact

    def defects(self, produced, jet=None):
        """Per slot the largest ``|produced - band_T(H)|`` over the degrees ``T`` its consumers received."""
        jet = self.jet if jet is None else jet
        out = np.zeros(len(produced))
        for top in sorted({T for ts in self.tops for T in ts}):
            mask = np.array([top in ts for ts in self.tops], dtype=bool)
            out = np.where(mask, np.maximum(out, np.abs(produced - taylor(jet, self.H, top))), out)
        return out

    def orders(self):
        """Per slot the order of its defect: one more than the lowest degree its consumers received that
        is backed by known coefficients (a held value: 1)."""
        known = np.cumprod(self.known, axis=0).sum(axis=0) - 1  # highest j with every order <= j known
        return np.array([1 + min(min(T, int(k)) for T in ts) if ts else 1 for ts, k in zip(self.tops, known)])
