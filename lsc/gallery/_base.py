"""The gallery's containers: a problem with its exact solution and its hand-derived peers."""

import numpy as np

class Problem:
    """A gallery DAE with its exact solution.

    Attributes
    ----------
    name : str
    dae : LinearDAE
    t_span : tuple of float
    x0 : ndarray, shape (n,)
        Consistent initial value ``exact(t_span[0])``.
    index : int
        Differentiation index.
    finite_eigenvalues : ndarray or None
        Finite eigenvalues of the pencil (roots of ``det(mu A + B)``); None
        for time-varying coefficients, where they decide nothing.
    jordan_blocks : tuple of int
        Sizes of the nilpotent chains (Jordan blocks at infinity), largest
        first (of the canonical form the problem was built from).
    state_space : StateSpace or None
        The peers a user would write by hand instead of completing the DAE:
        the reduced ODE and an index-1 DAE form (for benchmarks); None where
        the gallery does not derive them.
    """

    def __init__(self, name, dae, t_span, exact, index, finite_eigenvalues, jordan_blocks):
        self.name = name
        self.dae = dae
        self.t_span = t_span
        self._exact = exact
        self.index = index
        if finite_eigenvalues is None:
            self.finite_eigenvalues = None
        else:
            self.finite_eigenvalues = np.sort_complex(np.asarray(finite_eigenvalues, dtype=complex))
            if np.all(self.finite_eigenvalues.imag == 0):
                self.finite_eigenvalues = self.finite_eigenvalues.real
        self.jordan_blocks = tuple(sorted(jordan_blocks, reverse=True))
        self.x0 = self.exact(t_span[0])
        self.state_space = None

    def exact(self, t, d=0):
        """The d-th derivative of the exact solution: shape (n,) or (n, m) for t of shape (m,)."""
        t_arr = np.asarray(t, dtype=float)
        out = self._exact(np.atleast_1d(t_arr), d)
        return out[:, 0] if t_arr.ndim == 0 else out

    def __repr__(self):
        return f"Problem({self.name!r}, n={self.dae.n}, index={self.index}, t_span={self.t_span})"


class StateSpace:
    """The hand-derived alternatives to completing a gallery DAE.

    What a user who knows the problem's structure would integrate instead:

    - the *reduced ODE* ``y' = rhs(t, y)`` of the dynamic part only (its
      dimension is the number of finite eigenvalues), with the algebraic
      part computed from the forcing and its derivatives, and
      ``x = output(t, y)``;
    - an *index-1 DAE* ``residual(t, x, x') = 0`` in the original unknowns:
      the dynamic equations plus the hidden constraints written out, for a
      DAE solver such as SUNDIALS IDA.

    Attributes
    ----------
    y0 : ndarray, shape (d,)
        Reduced state at ``t_span[0]`` (of the exact solution).
    rhs : callable ``rhs(t, y) -> (d,)``
    jac : ndarray or callable ``jac(t, y) -> (d, d)``
    output : callable ``output(t, y) -> (n,)``
        The full unknown ``x`` from the reduced state.
    residual : callable ``residual(t, x, xp) -> (n,)``
    residual_jac : callable ``residual_jac(t, x, xp, cj) -> (n, n)``
        ``d residual / dx + cj d residual / dxp``.
    algebraic : list of int
        Components of ``x`` whose derivative does not appear in `residual`.
    """

    def __init__(self, y0, rhs, jac, output, residual, residual_jac, algebraic=()):
        self.y0 = np.asarray(y0, dtype=float)
        self.rhs, self.jac, self.output = rhs, jac, output
        self.residual, self.residual_jac = residual, residual_jac
        self.algebraic = list(algebraic)
