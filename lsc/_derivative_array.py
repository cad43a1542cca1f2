"""The derivative array ``J w = -F x + g`` of a linear DAE.

Row block ``i`` (``i = 0..k``) is ``D^i (A x' + B x - f) = 0`` with
``D = d/dt`` (standard) or ``D = d/dt + lam`` (stabilized). Because
``D(u v) = (D u) v + u v'``, the coefficient of ``x^(m)`` (``m >= 1``) in row
block ``i`` is ``C(i, m-1) D^(i-m+1) A + C(i, m) D^(i-m) B``; ``F`` has blocks
``D^i B`` and ``g`` has blocks ``D^i f`` (thesis (1.13), (3.4), (5.5) and
ERRATA item 1).

Everything is computed on *jets* (arrays of derivatives), which makes the
same code exact for constant and time-varying coefficients and for constant
and time-varying ``lam``. The forcing ``g`` is linear in ``f, f', ...``, so it
is also produced as a matrix ``L`` with ``g = L @ [f; f'; ...; f^(p)]``: a
constant-coefficient completion then evaluates its forcing with one
matrix-vector product.
"""

from math import comb

import numpy as np

from ._problem import check_dae
from ._rate import as_rate, lam_at, lam_jet
from ._validate import check_k, check_time

__all__ = ["DerivativeArray", "derivative_array"]


def _jet_times(a, u):
    """Jet of the product ``a u`` (``a`` scalar jet, ``u`` any jet), Leibniz rule."""
    length = min(len(a), len(u))
    out = np.zeros((length,) + u.shape[1:])
    for m in range(length):
        for j in range(m + 1):
            if a[j] != 0.0:
                out[m] += comb(m, j) * a[j] * u[m - j]
    return out


def _apply_D(u, lam_jet):
    """Jet of ``D u`` (one order shorter than ``u``)."""
    if lam_jet is None:
        return u[1:]
    return u[1:] + _jet_times(lam_jet, u[:-1])


def _powers(jet, k, lam_jet):
    """``[jet of D^0 u, jet of D^1 u, ..., jet of D^k u]``."""
    out = [jet]
    for _ in range(k):
        out.append(_apply_D(out[-1], lam_jet))
    return out


def stabilization_jets(k, q, lj):
    """Scalar coefficients of stabilized differentiation, and q derivatives.

    ``D^i u = sum_j Lam[0][i, j] u^(j)`` for any u (``i = 0..k``), so the
    stabilized array is ``(Lam[0] kron I)`` times the standard one, row for
    row; ``Lam[0]`` is unit lower triangular (binomials times powers of
    ``lam`` for constant ``lam``, thesis (3.5)). Shape
    ``(q + 1, k + 1, k + q + 1)``: ``Lam[d]`` is the d-th time derivative.
    Found by letting D act on the jet of unit vectors: entry m of the jet
    of ``u`` is the selector of ``u^(m)``.
    """
    p = k + q
    selectors = np.eye(p + 1)[:, None, :]
    powers = _powers(selectors, k, lj)
    Lam = np.zeros((q + 1, k + 1, p + 1))
    for i in range(k + 1):
        Lam[:, i] = powers[i][: q + 1, 0]
    return Lam


class _ArrayJets:
    """Derivatives ``0..q`` of J, F and of the forcing map L of one array, at one time or at several.

    ``J[d]`` is the d-th time derivative of J (shape ``lead + (N, N)``, N = (k+1) n, ``lead`` the times'
    axes: none for one time), ``F[d]`` of F (``lead + (N, n)``) and ``L[d]`` of the forcing map
    (N, (k+q+1) n): the d-th derivative of ``g`` is ``L[d] @ fstack`` with ``fstack = [f, f', ...,
    f^(k+q)]``. ``Lam`` is `stabilization_jets`.

    ``L[d]`` is ``Lam[d] kron I_n``: it is formed (lazily) only where the map
    itself is wanted; applying it to values, `forcing`, needs no dense matrix.
    """

    def __init__(self, J, F, Lam, k, q, n):
        self.J, self.F, self.Lam, self.k, self.q, self.n = J, F, Lam, k, q, n
        self._L = None

    @property
    def L(self):
        if self._L is None:
            self._L = np.stack([np.kron(self.Lam[d], np.eye(self.n)) for d in range(self.q + 1)])
        return self._L

    def forcing(self, fstack):
        """``[L[d] @ fstack for d = 0..q]``, shape (q + 1, N), without forming ``L``."""
        blocks = fstack.reshape(-1, self.n)
        return np.einsum("dij,jn->din", self.Lam, blocks).reshape(self.q + 1, -1)


def array_jets(dae, k, t, lam=None, q=0):
    """Build the derivative array with k differentiations and its first q derivatives."""
    order = k + q
    return assembled_jets(dae.A.jet(t, order), dae.B.jet(t, order), k, q, lam_jet(lam, t, order))


def assembled_jets(A, B, k, q, lj=None):
    """The `_ArrayJets` of coefficients given by their jets `A`, `B` to order ``k + q``.

    The jets have the derivative order first and may hold several times after it: shape
    ``(k + q + 1,) + lead + (n, n)``; ``J[d]`` and ``F[d]`` then have the same ``lead`` axes (the one
    assembly for one time and for the stacked evaluation at many times, `lsc._dense_factors`).
    """
    n = A.shape[-1]
    lead = A.shape[1:-2]
    A_pow = _powers(A, k, lj)
    B_pow = _powers(B, k, lj)
    Lam = stabilization_jets(k, q, lj)
    N = (k + 1) * n
    J = np.zeros((q + 1,) + lead + (N, N))
    F = np.zeros((q + 1,) + lead + (N, n))
    for i in range(k + 1):
        rows = slice(i * n, (i + 1) * n)
        F[..., rows, :] = B_pow[i][: q + 1]
        for m in range(1, i + 2):
            block = comb(i, m - 1) * A_pow[i - m + 1][: q + 1]
            if m <= i:
                block = block + comb(i, m) * B_pow[i - m][: q + 1]
            J[..., rows, (m - 1) * n : m * n] = block
    return _ArrayJets(J, F, Lam, k, q, n)


class DerivativeArray:
    """The derivative array ``J w = -F x + g`` at one time.

    Attributes
    ----------
    J : ndarray, shape ((k+1) n, (k+1) n)
        Jacobian with respect to ``w = [x', x'', ..., x^(k+1)]``.
    F : ndarray, shape ((k+1) n, n)
        Coefficient of ``x``.
    g : ndarray, shape ((k+1) n,)
        Forcing ``[f, D f, ..., D^k f]``.
    k : int
        Number of differentiations.
    t : float
        Time at which the array was evaluated.
    lam : float or None
        Stabilization rate (None: standard differentiation).
    """

    def __init__(self, J, F, g, k, t, lam):
        self.J, self.F, self.g, self.k, self.t, self.lam = J, F, g, k, t, lam

    def __repr__(self):
        return f"DerivativeArray(k={self.k}, t={self.t!r}, lam={self.lam!r}, J.shape={self.J.shape})"


def derivative_array(dae, k, t=0.0, lam=None):
    """The derivative array of `dae` with `k` differentiations at time `t`.

    Parameters
    ----------
    dae : LinearDAE
        The system ``A x' + B x = f``.
    k : int
        Number of differentiations (``k >= 0``); the array has ``k + 1``
        block rows.
    t : float, optional
        Time at which to evaluate (irrelevant for constant data).
    lam : float, sympy expression or callable, optional
        If given, differentiate with ``D = d/dt + lam`` (stabilized array);
        a time-varying ``lam(t)`` enters through the product rule.

    Returns
    -------
    DerivativeArray
        With ``J``, ``F``, ``g`` such that ``J w = -F x + g`` for every
        solution, ``w = [x', ..., x^(k+1)]``.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import LinearDAE, derivative_array
    >>> dae = LinearDAE([[0, 1], [0, 0]], np.eye(2))
    >>> arr = derivative_array(dae, 1, lam=2.0)
    >>> arr.J
    array([[0., 1., 0., 0.],
           [0., 0., 0., 0.],
           [1., 2., 0., 1.],
           [0., 1., 0., 0.]])
    """
    check_dae(dae)
    k = check_k(k)
    t = check_time("t", t)
    if lam is not None:
        lam = as_rate(lam)
        lam_at(lam, t)
    jets = array_jets(dae, k, t, lam)
    fstack = dae.f_jet(t, k).reshape(-1)
    return DerivativeArray(jets.J[0], jets.F[0], jets.forcing(fstack)[0], k, t, lam)
