"""Rotating canonical forms: time-varying orthogonal transformations with exact jets."""

import numpy as np

from .._problem import LinearDAE
from .._timefunc import JetCallable
from .._validate import check_k
from ._base import Problem
from ._canonical import _shift_blocks, _Sinusoids
from ._jets import _constant_jet, _jet_matmul, _last_values
from ._state_space import _canonical_state_space

class _RotationJet:
    """Jet of ``R(t) = prod_i R_(i, i+1)(rate_i t)``: plane rotations, exact derivatives.

    A rotation by ``w t`` in the plane of columns ``(i, j)`` multiplies
    ``u = col_i - 1j col_j`` by ``exp(1j w t)``; by the Leibniz rule the jet of
    the product is ``T @ (jet of u)`` with the lower triangular
    ``T[d, p] = binom(d, p) (1j w)^(d - p) exp(1j w t)``. The factors of ``T``
    that do not depend on t are kept per order.
    """

    def __init__(self, n, rates):
        self.n, self.rates = n, list(rates)
        self._bases = {}

    def _base(self, m):
        base = self._bases.get(m)
        if base is None:
            from math import comb

            d = np.arange(m)
            lag = np.subtract.outer(d, d)
            binom = np.array([[comb(a, b) if b <= a else 0 for b in range(m)] for a in range(m)], dtype=float)
            base = self._bases[m] = [binom * (1j * w) ** lag.clip(0) for w in self.rates]
        return base

    def __call__(self, t, order):
        n = self.n
        R = np.zeros((order + 1, n, n))
        R[0] = np.eye(n)
        for i, (w, base) in enumerate(zip(self.rates, self._base(order + 1))):
            j = (i + 1) % n
            u = (base * np.exp(1j * w * t)) @ (R[:, :, i] - 1j * R[:, :, j])
            R[:, :, i], R[:, :, j] = u.real, -u.imag
        return R


def rotating_canonical(index=3, omega=1.0, t_span=(0.0, 5.0)):
    """A canonical form turned by time-varying orthogonal transformations.

    ``y1' + C y1 = h1`` (a damped oscillator, eigenvalues ``-0.5 +- 1j``) and
    ``N y2' + y2 = h2`` with one chain of length `index`; equations and
    unknowns rotated by ``P(t)``, ``Q(t)`` (products of plane rotations at
    rates proportional to `omega`)::

        A(t) = P E Q^T,   B(t) = P (Ab - E Q^T Q') Q^T,   x = Q(t) y

    so that ``A x' + B x = P (E y' + Ab y)`` exactly and the index is
    `index` at every t. The exact solution is manufactured (sinusoidal
    ``y*``, ``f = P (E y*' + Ab y*)``). Constraint directions rotate at
    about `omega` rad per unit time. Coefficients are callables ``h(t, d)``
    computed from exact jets (products of rotations by the Leibniz rule), so
    every derivative is exact to rounding.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import gallery
    >>> p = gallery.rotating_canonical(4)
    >>> p.index, p.dae.n, p.dae.is_constant
    (4, 6, False)
    >>> bool(np.allclose(p.dae.residual(1.2, p.exact(1.2), p.exact(1.2, 1)), 0, atol=1e-12))
    True
    """
    index = check_k(index, "index")
    if index < 1:
        raise ValueError(f"`index` must be >= 1; found {index}.")
    n = 2 + index
    E = np.zeros((n, n))
    E[:2, :2] = np.eye(2)
    E[2:, 2:] = _shift_blocks((index,))
    Ab = np.zeros((n, n))
    Ab[:2, :2] = [[0.5, 1.0], [-1.0, 0.5]]
    Ab[2:, 2:] = np.eye(index)
    rates = [omega * r for r in (1.0, 0.7, 1.3, 0.9, 1.1, 0.6, 1.2, 0.8)[: n - 1]]
    y_star = _Sinusoids(amp=np.ones(n), omega=1 + 0.3 * np.arange(n), phase=np.arange(n, dtype=float), offset=0.5 * np.ones(n))

    # A, B and f at one t all need P and Q: compute each jet once per t (the deepest order asked).
    P_jet = _last_values(_RotationJet(n, rates))
    Q_jet = _last_values(_RotationJet(n, rates[::-1]))

    def transpose(X):
        return np.transpose(X, (0, 2, 1))

    def A_jet(t, order):
        # Q to one order more, as B_jet will ask at this t: one rotation jet per t, not two
        Q = Q_jet(t, order + 1)[: order + 1]
        # E is constant: P E needs no Leibniz sum
        return _jet_matmul(P_jet(t, order) @ E, transpose(Q))

    def B_jet(t, order):
        Q = Q_jet(t, order + 1)
        # Q[1:] is the jet of Q' (one order shorter than Q).
        inner = _constant_jet(Ab, order) - E @ _jet_matmul(transpose(Q[:-1]), Q[1:])
        return _jet_matmul(_jet_matmul(P_jet(t, order), inner), transpose(Q[:-1]))

    def f_jet(t, order):
        y = y_star.jet(t, order + 1)
        h = y[1:] @ E.T + y[:-1] @ Ab.T
        return _jet_matmul(P_jet(t, order), h)

    def exact(ts, d):
        return np.array([_jet_matmul(Q_jet(t, d), y_star.jet(t, d))[d] for t in ts]).T

    A = JetCallable(A_jet)
    B = JetCallable(B_jet)
    f = JetCallable(f_jet)
    problem = Problem(
        f"rotating_canonical(index={index}, omega={omega:g})", LinearDAE(A, B, f), t_span, exact, index, None, (index,),
    )
    problem.state_space = _canonical_state_space(problem, 2, E, Ab, None, None, index, P_jet=P_jet, Q_jet=Q_jet)
    return problem
