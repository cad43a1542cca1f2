"""Containers and manufactured solutions for the gallery's large sparse benchmark models."""

import numpy as np
import scipy.sparse

from .._problem import LinearDAE
from .._sparse_problem import InputForcing
from .._timefunc import JetCallable
from ._base import Problem


class Descriptor:
    """A descriptor system ``E x' = A x + B u``, ``y = C x`` (the M-M.E.S.S. / Kunkel-Mehrmann convention).

    lsc writes DAEs as ``A x' + B x = f``: `dae` converts with
    ``A_lsc = E``, ``B_lsc = -A`` and ``f = B u(t)``.

    Attributes
    ----------
    E, A : scipy.sparse.csr_matrix, shape (n, n)
    B : scipy.sparse.csr_matrix, shape (n, m) or None
    C : scipy.sparse.csr_matrix, shape (p, n) or None
    """

    def __init__(self, E, A, B=None, C=None):
        self.E, self.A = scipy.sparse.csr_matrix(E, dtype=float), scipy.sparse.csr_matrix(A, dtype=float)
        self.B = None if B is None else scipy.sparse.csr_matrix(B, dtype=float)
        self.C = None if C is None else scipy.sparse.csr_matrix(C, dtype=float)

    @property
    def n(self):
        return self.E.shape[0]

    def dae(self, u=None):
        """The lsc DAE ``E x' - A x = B u(t)`` (``u``: inputs as for `lsc.InputForcing`; None: unforced)."""
        if u is None:
            return LinearDAE(self.E, -self.A)
        if self.B is None:
            raise ValueError("`u` given but the descriptor system has no input matrix B.")
        return LinearDAE(self.E, -self.A, InputForcing(self.B, u))

    def __repr__(self):
        m = 0 if self.B is None else self.B.shape[1]
        p = 0 if self.C is None else self.C.shape[0]
        return f"Descriptor(n={self.n}, inputs={m}, outputs={p}, nnz(E)={self.E.nnz}, nnz(A)={self.A.nnz})"


class Sinusoids:
    """``phi_k(t) = alpha_k sin(omega_k t + theta_k)``: scalar functions with every derivative exact."""

    def __init__(self, alpha, omega, theta):
        self.alpha, self.omega, self.theta = (np.asarray(v, dtype=float) for v in (alpha, omega, theta))

    def jet(self, t, order):
        """Derivatives ``0..order`` at times `t` (scalar or (s,)): shape ``(order + 1, m)`` or ``(order + 1, m, s)``."""
        t = np.asarray(t, dtype=float)
        d = np.arange(order + 1).reshape((-1, 1) + (1,) * t.ndim)
        om, al, th = (v.reshape((1, -1) + (1,) * t.ndim) for v in (self.omega, self.alpha, self.theta))
        return al * om**d * np.sin(om * t + th + d * np.pi / 2)

    def derivative(self):
        """The sinusoids ``phi_k'``."""
        return Sinusoids(self.alpha * self.omega, self.omega, self.theta + np.pi / 2)


class SparseProblem(Problem):
    """A large sparse gallery model with a manufactured exact solution.

    ``x*(t) = V phi(t)`` for fixed vectors ``V`` (n x m) and sinusoids
    ``phi``; the forcing ``f = A x*' + B x*`` is an `lsc.InputForcing` with
    the input map ``[A V, B V]``, so it costs O(n m) per evaluation and every
    derivative is exact.

    Attributes
    ----------
    descriptor : Descriptor
        The model as published (``E x' = A x + B u``, ``y = C x``), for
        users who drive it with their own inputs (``descriptor.dae(u)``).
    n_finite : int
        Dimension of the finite spectrum (deflating subspace of the finite
        eigenvalues): ``n`` minus the number of constraints.
    projectors : dict
        What is known in closed form: ``'Pr'``, ``'Pl'`` (spectral projectors
        onto the right/left deflating subspaces of the finite eigenvalues,
        sparse matrices or LinearOperators) where the construction gives them.
    finite_eigenvalues : None
        Not computed for these sizes.
    """

    def __init__(self, name, descriptor, V, phi, t_span, index, jordan_blocks, n_finite, projectors=None):
        A, B = descriptor.E, -descriptor.A
        V = np.asarray(V, dtype=float)
        dphi = phi.derivative()
        forcing = InputForcing(np.hstack([np.asarray(A @ V), np.asarray(B @ V)]),
                               JetCallable(lambda t, order: np.concatenate(
                                   [dphi.jet(t, order), phi.jet(t, order)], axis=1)))
        dae = LinearDAE(A, B, forcing)
        self.V, self.phi = V, phi

        def exact(ts, d):
            return V @ phi.jet(ts, d)[d]

        super().__init__(name, dae, t_span, exact, index, None, jordan_blocks)
        self.descriptor = descriptor
        self.n_finite = int(n_finite)
        self.projectors = {} if projectors is None else projectors

    def __repr__(self):
        return f"SparseProblem({self.name!r}, n={self.dae.n}, index={self.index}, n_finite={self.n_finite})"


def project_out(S, G):
    """``S - G^T (G G^T)^-1 G S``: columns of `S` moved into null(G) (G: few sparse rows)."""
    G = scipy.sparse.csr_matrix(G)
    GG = (G @ G.T).toarray()
    return S - G.T @ np.linalg.solve(GG, np.asarray(G @ S))


def default_phi(m, seed=0):
    """m sinusoids with frequencies in [0.5, 2] and phases in [0, 2 pi) (a fixed seed)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.5, 2.0, m), rng.uniform(0.0, 2 * np.pi, m)
