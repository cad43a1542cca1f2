"""Canonical chains: Kronecker canonical forms with manufactured sinusoidal solutions."""

import numpy as np

from .._problem import LinearDAE
from .._timefunc import JetCallable
from .._validate import check_k
from ._base import Problem
from ._state_space import _canonical_state_space

class _Sinusoids:
    """``y_j(t) = a_j sin(w_j t + p_j) + b_j`` with exact derivatives, vectorized."""

    def __init__(self, amp, omega, phase, offset):
        self.amp, self.omega, self.phase, self.offset = (np.asarray(v, dtype=float) for v in (amp, omega, phase, offset))

    def jet(self, t, order):
        """``y, y', ..., y^(order)`` at a scalar t in one call, shape (order + 1, n)."""
        d = np.arange(order + 1)[:, None]
        out = (self.amp * self.omega**d) * np.sin(self.omega * float(t) + self.phase + d * (np.pi / 2))
        out[0] += self.offset
        return out

    def __call__(self, t, d):
        t = np.asarray(t, dtype=float)
        arg = np.multiply.outer(self.omega, t) + (self.phase + d * np.pi / 2)[..., None] if t.ndim else self.omega * t + self.phase + d * np.pi / 2
        scale = self.amp * self.omega**d
        if t.ndim:
            out = scale[:, None] * np.sin(arg)
            if d == 0:
                out += self.offset[:, None]
        else:
            out = scale * np.sin(arg)
            if d == 0:
                out = out + self.offset
        return out


def _shift_blocks(blocks):
    """Block-diagonal nilpotent matrix with single Jordan chains of the given sizes."""
    a = sum(blocks)
    N = np.zeros((a, a))
    start = 0
    for b in blocks:
        N[start : start + b, start : start + b] = np.eye(b, k=1)
        start += b
    return N


def _real_block(spectrum):
    """A real matrix whose eigenvalues are `spectrum` (conjugate pairs as 2x2 blocks)."""
    spectrum = list(np.asarray(spectrum, dtype=complex))
    d = len(spectrum)
    M = np.zeros((d, d))
    i = 0
    used = [False] * d
    for j, mu in enumerate(spectrum):
        if used[j]:
            continue
        used[j] = True
        if abs(mu.imag) == 0:
            M[i, i] = mu.real
            i += 1
        else:
            partner = next((m for m in range(j + 1, d) if not used[m] and np.isclose(spectrum[m], np.conj(mu))), None)
            if partner is None:
                raise ValueError(f"`spectrum` must list complex eigenvalues in conjugate pairs; {mu} has no partner.")
            used[partner] = True
            M[i : i + 2, i : i + 2] = [[mu.real, mu.imag], [-mu.imag, mu.real]]
            i += 2
    return M


def _conditioned(rng, n, cond):
    """A random n x n matrix with singular values log-spaced in [1, cond]."""
    U = np.linalg.qr(rng.standard_normal((n, n)))[0]
    V = np.linalg.qr(rng.standard_normal((n, n)))[0]
    return U @ np.diag(np.logspace(0, np.log10(cond), n)) @ V


def _canonical_problem(name, spectrum, blocks, P, Q, t_span, seed):
    """``P (E y' + Ab y) = f``, ``x = Q y``, with a manufactured sinusoidal ``y*``."""
    spectrum = np.asarray(spectrum, dtype=complex)
    d, a = len(spectrum), sum(blocks)
    n = d + a
    E = np.zeros((n, n))
    Ab = np.zeros((n, n))
    E[:d, :d] = np.eye(d)
    E[d:, d:] = _shift_blocks(blocks)
    # Homogeneous ODE part y1' = -C y1: eigenvalues of -C are `spectrum`.
    Ab[:d, :d] = -_real_block(spectrum)
    Ab[d:, d:] = np.eye(a)
    P = np.eye(n) if P is None else P
    Q = np.eye(n) if Q is None else Q
    Q_inv = np.linalg.inv(Q)
    A = P @ E @ Q_inv
    B = P @ Ab @ Q_inv
    rng = np.random.default_rng(seed)
    y_star = _Sinusoids(
        amp=rng.uniform(0.5, 1.5, n), omega=rng.uniform(0.5, 2.0, n), phase=rng.uniform(0, 2 * np.pi, n),
        offset=rng.uniform(-1, 1, n),
    )
    PE, PAb = P @ E, P @ Ab

    def f_jet(t, order):  # all derivatives in one call: a completion asks for k + 1 of them per step
        y = y_star.jet(t, order + 1)
        return y[1:] @ PE.T + y[:-1] @ PAb.T

    def exact(t, deriv):
        return Q @ y_star(t, deriv)

    dae = LinearDAE(A, B, JetCallable(f_jet))
    index = max(blocks) if blocks else 0
    problem = Problem(name, dae, t_span, exact, index, spectrum, blocks)
    if d and a:
        problem.state_space = _canonical_state_space(problem, d, E, Ab, P, Q, index)
    return problem


def nilpotent_chain(index, ode_dim=2, seed=None, t_span=(0.0, 5.0)):
    """A nilpotent chain of length `index` beside a small ODE part.

    ``N y2' + y2 = f2`` with ``N`` a single shift of size `index` (so the
    differentiation index is `index`), plus ``y1' = -C y1 + f1`` of size
    `ode_dim` with eigenvalues ``-0.5 +- 1j`` (or ``-0.5`` when
    ``ode_dim == 1``).

    Parameters
    ----------
    index : int
        1 to 6 (or more).
    ode_dim : int, optional
        0, 1 or 2.
    seed : int, optional
        None: the canonical form itself. An int: mix equations and unknowns
        with a seeded orthogonal ``P`` and a ``Q`` of condition number 10.
    t_span : pair of float, optional

    Examples
    --------
    >>> from lsc import gallery, differentiation_index
    >>> p = gallery.nilpotent_chain(4, seed=0)
    >>> differentiation_index(p.dae) == p.index == 4
    True
    """
    index = check_k(index, "index")
    if index < 1:
        raise ValueError(f"`index` must be >= 1 for a nilpotent chain; found {index}.")
    spectra = {0: [], 1: [-0.5], 2: [-0.5 + 1j, -0.5 - 1j]}
    if ode_dim not in spectra:
        raise ValueError(f"`ode_dim` must be 0, 1 or 2; found {ode_dim!r}.")
    n = ode_dim + index
    P = Q = None
    if seed is not None:
        rng = np.random.default_rng(seed)
        P = np.linalg.qr(rng.standard_normal((n, n)))[0]
        Q = _conditioned(rng, n, 10.0)
    return _canonical_problem(f"nilpotent_chain(index={index})", spectra[ode_dim], (index,), P, Q, t_span, seed or 0)
