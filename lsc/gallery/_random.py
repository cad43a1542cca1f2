"""Random pencils: constant ones of a given Kronecker structure, and moving ones (time-varying)."""

import numpy as np

from .._exceptions import DimensionError
from .._problem import LinearDAE
from .._timefunc import JetCallable
from .._validate import check_k
from ._base import Problem
from ._canonical import _canonical_problem, _conditioned, _real_block, _shift_blocks, _Sinusoids
from ._jets import _constant_jet, _jet_matmul, _last_values

def random_pencil(n=12, blocks=(3, 2), spectrum=None, seed=0, cond=10.0, t_span=(0.0, 5.0)):
    """A seeded random regular pencil with prescribed structure.

    ``A = P E Q^-1``, ``B = P Ab Q^-1`` with ``E = diag(I_d, N)``,
    ``Ab = diag(C, I_a)``: ``N`` has Jordan chains of the sizes in `blocks`
    (the index is their maximum) and ``-C`` has eigenvalues `spectrum`.
    ``P`` and ``Q`` are random with condition number `cond`.

    Parameters
    ----------
    n : int
        Size, at least ``sum(blocks)``; scales to n = 400 and beyond.
    blocks : tuple of int
        Nilpotent chain lengths.
    spectrum : array_like, optional
        Finite eigenvalues, ``d = n - sum(blocks)`` of them (complex ones in
        conjugate pairs). Default: ``d`` seeded values in [-2, -0.1].
    seed : int
    cond : float
        Condition number of ``P`` and ``Q``.
    t_span : pair of float

    Examples
    --------
    >>> from lsc import gallery
    >>> p = gallery.random_pencil(n=8, blocks=(2, 2, 1), spectrum=[-1, -2, -3])
    >>> p.index, p.jordan_blocks, p.finite_eigenvalues.tolist()
    (2, (2, 2, 1), [-3.0, -2.0, -1.0])
    """
    blocks = tuple(check_k(b, "blocks[i]") for b in blocks)
    if any(b < 1 for b in blocks):
        raise ValueError(f"`blocks` must be positive chain lengths; found {blocks}.")
    a = sum(blocks)
    if n < a:
        raise ValueError(f"`n` must be at least sum(blocks)={a}; found {n}.")
    rng = np.random.default_rng(seed)
    d = n - a
    if spectrum is None:
        spectrum = -rng.uniform(0.1, 2.0, d)
    spectrum = np.asarray(spectrum, dtype=complex)
    if spectrum.shape != (d,):
        raise DimensionError(f"`spectrum` must hold n - sum(blocks) values: expected ({d},), got {spectrum.shape}.")
    P = _conditioned(rng, n, cond)
    Q = _conditioned(rng, n, cond)
    return _canonical_problem(f"random_pencil(n={n}, blocks={blocks}, seed={seed})", spectrum, blocks, P, Q, t_span, seed)


def moving_pencil(n=10, blocks=(3,), seed=0, rate=0.5, t_span=(0.0, 1.0)):
    """A random regular pencil moved by time-varying transformations; scales in n.

    ``A(t) = P E Q^-1``, ``B(t) = P (Ab - E Q^-1 Q') Q^-1`` with
    ``P(t) = P0 (I + t L)``, ``Q(t) = Q0 (I + t K)`` (``||K|| = ||L|| = rate``,
    so both stay invertible for ``|t| < 1/rate``) and the canonical
    ``E = diag(I, N)``, ``Ab = diag(C, I)`` of `random_pencil`. Then
    ``A x' + B x = P (E y' + Ab y)`` for ``x = Q y`` exactly, the index is
    ``max(blocks)`` at every t, and the exact solution is manufactured from
    sinusoidal ``y*``. Derivatives are exact jets (``Q^-1`` by the recursion
    ``R^(d) = -d R Q' R^(d-1)``), cheap enough that a completion's cost is
    what gets measured.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import gallery
    >>> p = gallery.moving_pencil(n=8, blocks=(3, 1))
    >>> p.index, p.dae.is_constant
    (3, False)
    >>> bool(np.allclose(p.dae.residual(0.4, p.exact(0.4), p.exact(0.4, 1)), 0, atol=1e-10))
    True
    """
    blocks = tuple(check_k(b, "blocks[i]") for b in blocks)
    a = sum(blocks)
    if n < a or any(b < 1 for b in blocks):
        raise ValueError(f"`blocks` must be positive chain lengths summing to at most n={n}; found {blocks}.")
    rng = np.random.default_rng(seed)
    d = n - a
    E = np.zeros((n, n))
    E[:d, :d] = np.eye(d)
    E[d:, d:] = _shift_blocks(blocks)
    Ab = np.zeros((n, n))
    Ab[:d, :d] = -_real_block(-rng.uniform(0.1, 2.0, d))
    Ab[d:, d:] = np.eye(a)
    P0, Q0 = _conditioned(rng, n, 5.0), _conditioned(rng, n, 5.0)

    def scaled(M):
        return rate * M / np.linalg.norm(M, 2)

    L, K = scaled(rng.standard_normal((n, n))), scaled(rng.standard_normal((n, n)))
    y_star = _Sinusoids(amp=rng.uniform(0.5, 1.5, n), omega=rng.uniform(0.5, 2.0, n), phase=rng.uniform(0, 2 * np.pi, n),
                        offset=rng.uniform(-1, 1, n))

    def linear_jet(M0, M1, t, order):
        out = np.zeros((order + 1, n, n))
        out[0] = M0 + t * M1
        if order:
            out[1] = M1
        return out

    P0L, Q0K = P0 @ L, Q0 @ K  # constant: formed once, not per evaluation

    @_last_values  # A, B and f all need it at each t
    def P_jet(t, order):
        return linear_jet(P0, P0L, t, order)

    def Q_jet(t, order):
        return linear_jet(Q0, Q0K, t, order)

    @_last_values  # A and B both need it at each t
    def Qinv_jet(t, order):
        R0 = np.linalg.inv(Q0 + t * Q0K)
        out = np.zeros((order + 1, n, n))
        out[0] = R0
        step = R0 @ Q0K
        for j in range(1, order + 1):
            out[j] = -j * step @ out[j - 1]
        return out

    def A_jet(t, order):
        return _jet_matmul(P_jet(t, order), E @ Qinv_jet(t, order))

    def B_jet(t, order):
        R = Qinv_jet(t, order)
        Qd = np.zeros((order + 1, n, n))
        Qd[0] = Q0K
        inner = _constant_jet(Ab, order) - E @ _jet_matmul(R, Qd)
        return _jet_matmul(_jet_matmul(P_jet(t, order), inner), R)


    def f_jet(t, order):
        y = y_star.jet(t, order + 1)
        return _jet_matmul(P_jet(t, order), y[1:] @ E.T + y[:-1] @ Ab.T)

    def exact(ts, deriv):
        return np.array([_jet_matmul(Q_jet(t, deriv), y_star.jet(t, deriv))[deriv] for t in ts]).T

    dae = LinearDAE(JetCallable(A_jet), JetCallable(B_jet), JetCallable(f_jet))
    return Problem(f"moving_pencil(n={n}, blocks={blocks}, seed={seed})", dae, t_span, exact, max(blocks), None, blocks)
