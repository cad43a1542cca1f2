"""ODE completions ``x' = G x + g(t)`` of a linear DAE ``A x' + B x = f``.

Three methods (thesis chapters 2-4):

- ``'standard'``: the least squares completion (LSC), first block row of
  ``J^+ (-F x + g)`` for the standard derivative array. Extra eigenvalues 0.
- ``'stabilized'``: the same on the array built with ``D = d/dt + lam``.
  Extra eigenvalues ``-lam``, in Jordan blocks as long as the nilpotent chains.
- ``'alternative'``: the index-one form ``Z1^T (A x' + B x - f) = 0`` with the
  constraints ``c = Z2^T (F x - g)`` differentiated as ``c' = -lam c``.
  Extra eigenvalues ``-lam`` with no Jordan blocks.

For constant coefficients every completion is computed once, at
construction: ``rhs`` then costs one matrix-vector product plus the forcing
``W @ [f; f'; ...]`` (itself one product, or nothing for constant ``f``).
"""

import numpy as np
import scipy.linalg

from ._derivative_array import array_jets, lam_jet, stabilization_jets
from ._exceptions import IndexDeterminationError
from ._index import array_ranks, determine_index
from ._linalg import numerical_rank, validate_rcond
from ._timefunc import _shape_str
from ._validate import check_dae, check_k, check_lam_value, check_time
from ._exceptions import DimensionError

__all__ = [
    "Completion",
    "StandardCompletion",
    "StabilizedCompletion",
    "AlternativeCompletion",
    "COMPLETIONS",
    "complete",
]


class _StandardFactors:
    """The standard derivative array at one time and its SVD.

    Shared by all three methods: the constraints ``c = Z2^T (F x - g)`` are
    always those of the *standard* array, so residuals of different methods
    compare.
    """

    def __init__(self, dae, k, t, q, rcond):
        n = dae.n
        self.jets = array_jets(dae, k, t, None, q)
        J = self.jets.J[0]
        self.U, self.s, self.Vt = scipy.linalg.svd(J)
        self.rank = numerical_rank(self.s, J.shape, rcond, what=f"derivative array J (k={k}, t={t:g})")
        self.Z2 = self.U[:, self.rank :]
        # C = Z2^T F: the constraint matrix, full row rank a by (A4).
        self.C = self.Z2.T @ self.jets.F[0]
        a = self.C.shape[0]
        Uc, sc, Vct = scipy.linalg.svd(self.C)
        rank_C = numerical_rank(sc, self.C.shape, rcond, what="constraint matrix Z2^T F")
        if rank_C != a:
            raise IndexDeterminationError(
                f"the constraints Z2^T F x = Z2^T g are dependent (rank {rank_C} < {a}) at t={t:g}: "
                "[J, F] does not have full row rank, so the DAE is not solvable."
            )
        # Orthonormal basis of the homogeneous manifold {x : C x = 0} (thesis T2).
        self.T2 = Vct[a:].T
        self.C_pinv = (Vct[:a].T / sc) @ Uc.T
        self.n = n

    def pinv_rows(self, n=None):
        """The first `n` rows of ``J^+`` (all rows if None)."""
        return _pinv_rows(self.U, self.s, self.Vt, self.rank, n)


def _pinv_rows(U, s, Vt, rank, n=None):
    """First `n` rows of the pseudo-inverse truncated at `rank`, from an SVD.

    The first block row is all a completion needs (thesis ``V^T J^+``), so
    the full pseudo-inverse is never formed.
    """
    V = Vt[:rank].T if n is None else Vt[:rank, :n].T
    return (V / s[:rank]) @ U[:, :rank].T


class Completion:
    """Base class of the ODE completions ``x' = G x + g(t)`` of a linear DAE.

    Use `complete` to build one. A subclass must provide (the numbered
    contract):

    1. ``method``: its key in `COMPLETIONS` (the class name, lower case,
       without ``Completion``).
    2. ``uses_lam``: True if the stabilization rate ``lam`` is required,
       False if it must be None.
    3. ``extra_order``: how many derivatives of ``f`` beyond ``k`` its
       forcing needs (the alternative completion differentiates the
       constraints once more: 1; the others 0).
    4. ``_maps(self, std, t)``: from the standard array factors `std` at `t`,
       return ``(G, W)`` with ``x' = G x + W @ fstack`` where
       ``fstack = [f, f', ..., f^(k + extra_order)]`` stacked, shape
       ``((k + extra_order + 1) n,)``.
    5. ``added_eigenvalue``: the value theory assigns to the added dynamics
       (0 for the standard LSC, ``-lam`` for the stabilized ones).

    Everything else (validation, index determination, ``rhs``, ``jac``,
    ``matrices``, ``constraint_residual``, ``project``) lives here, once.

    Attributes
    ----------
    dae : LinearDAE
    n : int
        Number of unknowns.
    k : int
        Differentiations used (the differentiation index unless given).
    lam : float or None
        Stabilization rate.
    method : str
        Registry key.
    n_constraints : int
        Number of independent constraints (``a`` = corank of J): the
        dimension of the added dynamics.
    """

    method = None
    uses_lam = False
    extra_order = 0

    def __init__(self, dae, *, lam=None, k=None, rcond=None):
        check_dae(dae)
        self.dae = dae
        self.n = dae.n
        self.lam = self._check_lam(lam)
        self.rcond = validate_rcond(rcond)
        if not dae.is_constant:
            raise NotImplementedError("completions of time-varying DAEs are not supported yet.")
        self.k = self._check_k(k)
        self._t_ref = 0.0
        self._std = _StandardFactors(dae, self.k, self._t_ref, self.extra_order, self.rcond)
        self.n_constraints = self._std.C.shape[0]
        self._order = self.k + self.extra_order
        G, W = self._maps(self._std, self._t_ref)
        self._G = G
        self._W = W
        self._W_c = self._std.Z2.T @ self._std.jets.L[0]
        self._setup_forcing()

    # -- validation ---------------------------------------------------------
    def _check_lam(self, lam):
        if self.uses_lam:
            if lam is None:
                raise ValueError(
                    f"`lam` is required for the {self.method!r} completion: a positive finite rate "
                    "(e.g. lam=1.0); found None."
                )
            return check_lam_value(lam)
        if lam is not None:
            raise ValueError(
                f"`lam` must be None for the {self.method!r} completion, which has no stabilization; found {lam!r}."
            )
        return None

    def _check_k(self, k):
        if k is None:
            k, _ = determine_index(self.dae, self._t_ref_default(), 10, self.rcond)
            return k
        k = check_k(k)
        t = self._t_ref_default()
        ranks = array_ranks(self.dae, k, t, self.rcond)
        nxt = array_ranks(self.dae, k + 1, t, self.rcond)
        if not (ranks.one_full and ranks.full_row_rank and nxt.corank == ranks.corank):
            raise IndexDeterminationError(
                f"`k`={k} is too small: the derivative array does not determine x' "
                f"({ranks}; next: {nxt}). Use k=None for the differentiation index."
            )
        return k

    @staticmethod
    def _t_ref_default():
        return 0.0

    # -- forcing ------------------------------------------------------------
    def _setup_forcing(self):
        f = self.dae.f
        n = self.n
        if f is None:
            self._g_const = np.zeros(n)
            self._c_const = np.zeros(self.n_constraints)
        elif f.is_constant:
            fstack = f.jet(0.0, self._order).reshape(-1)
            self._g_const = self._W @ fstack
            self._c_const = self._W_c @ fstack
        else:
            self._g_const = None
            self._c_const = None

    def _fstack(self, t):
        return self.dae.f.jet(t, self._order).reshape(-1)

    def forcing(self, t):
        """The forcing ``g(t)`` of ``x' = G x + g(t)``, shape (n,)."""
        if self._g_const is not None:
            return self._g_const
        return self._W @ self._fstack(t)

    # -- public evaluation --------------------------------------------------
    def matrices(self, t):
        """``(G, g)`` with ``x' = G x + g`` at time `t`.

        Returns
        -------
        G : ndarray, shape (n, n)
        g : ndarray, shape (n,)
        """
        return self._G, self.forcing(t)

    def rhs(self, t, x):
        """Right-hand side ``G x + g(t)`` in `scipy.integrate.solve_ivp` form."""
        if self._g_const is not None:
            return self._G @ x + self._g_const
        return self._G @ x + self._W @ self.dae.f.jet(t, self._order).reshape(-1)

    def jac(self, t, x):
        """Jacobian ``G`` of `rhs` (constant for constant coefficients)."""
        return self._G

    def constraint_residual(self, t, x):
        """The constraint residual ``c = Z2^T (F x - g(t))``.

        Zero exactly on the solution manifold. ``Z2`` is an orthonormal basis
        of the left null space of the *standard* derivative array, so the
        residuals of the three methods are comparable.

        Parameters
        ----------
        t : float or ndarray, shape (m,)
        x : ndarray, shape (n,) or (n, m)

        Returns
        -------
        ndarray, shape (a,) or (a, m)
        """
        x = np.asarray(x, dtype=float)
        if x.shape[:1] != (self.n,) or x.ndim > 2:
            raise DimensionError(f"`x` has the wrong shape: expected ({self.n},) or ({self.n}, m), got {_shape_str(x.shape)}.")
        c = self._std.C @ x
        if self._c_const is not None:
            return c - (self._c_const if x.ndim == 1 else self._c_const[:, None])
        if x.ndim == 1:
            return c - self._W_c @ self._fstack(t)
        t = np.broadcast_to(np.asarray(t, dtype=float), (x.shape[1],))
        cg = np.column_stack([self._W_c @ self._fstack(ti) for ti in t])
        return c - cg

    def project(self, t, x):
        """The consistent point nearest to `x` (least squares) at time `t`.

        Solves ``min ||y - x||`` subject to ``Z2^T (F y - g(t)) = 0``.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n,):
            raise DimensionError(f"`x` has the wrong shape: expected ({self.n},), got {_shape_str(x.shape)}.")
        return x - self._std.C_pinv @ self.constraint_residual(t, x)

    @property
    def added_eigenvalue(self):
        """The eigenvalue theory assigns to the added dynamics."""
        return 0.0 if self.lam is None else -self.lam

    def __repr__(self):
        lam = "" if self.lam is None else f", lam={self.lam:g}"
        return f"{type(self).__name__}(n={self.n}, k={self.k}{lam}, constraints={self.n_constraints})"

    def _maps(self, std, t):  # pragma: no cover - abstract
        raise NotImplementedError


class StandardCompletion(Completion):
    """Least squares completion of the standard derivative array (thesis ch. 2).

    ``x' = V^T J^+ (-F x + g)``. For constant coefficients the added
    eigenvalues are 0, in Jordan blocks as long as the nilpotent chains
    (thesis Lemma 1): off the manifold, solutions drift polynomially.
    """

    method = "standard"
    uses_lam = False

    def _maps(self, std, t):
        P = std.pinv_rows(self.n)
        return -P @ std.jets.F[0], P @ std.jets.L[0]


class StabilizedCompletion(StandardCompletion):
    """Least squares completion of the stabilized array ``D = d/dt + lam`` (ch. 3).

    The added eigenvalues are ``-lam``, in Jordan blocks as long as the
    nilpotent chains, so off-manifold solutions decay like a polynomial times
    ``exp(-lam t)``.

    Notes
    -----
    The stabilized array is ``(Lam kron I)`` times the standard one, with
    ``Lam`` unit lower triangular (`stabilization_jets`). Writing the LSC
    ``V^T (D J)^+ D (-F x + g)`` through thesis Theorem 8 gives, exactly,

    ``x' = [standard LSC] + K c``,  ``K = Y0 D^-1 (M^+)^T``,  ``M = D^-T Z2``,

    with ``Y0 = V^T J^+`` and ``c = Z2^T (F x - g)`` the constraint
    residual: stabilization is a feedback of the residual. This avoids the
    SVD of ``D J``, whose rows scale like ``lam^i``: against a 60-digit
    reference (index 3, n = 8) the relative error in ``G`` is 5e-7 at
    lam = 100 where the SVD of ``D J`` gives 2e-3, and 4e-3 at lam = 1000
    where it gives none correct.
    """

    method = "stabilized"
    uses_lam = True

    def _maps(self, std, t):
        G, W = super()._maps(std, t)
        n, k = self.n, self.k
        N, a = std.Z2.shape
        Lam = stabilization_jets(k, 0, lam_jet(self.lam, t, k))[0]
        Lam_inv = scipy.linalg.solve_triangular(Lam, np.eye(k + 1), lower=True, unit_diagonal=True)
        # M = (Lam^-T kron I) Z2 and Y0 (Lam^-1 kron I), block by block.
        M = np.einsum("ji,jba->iba", Lam_inv, std.Z2.reshape(k + 1, n, a)).reshape(N, a)
        Y0_Dinv = np.einsum("aib,ij->ajb", std.pinv_rows(n).reshape(n, k + 1, n), Lam_inv).reshape(n, N)
        Qm, Rm = scipy.linalg.qr(M, mode="economic")
        K = scipy.linalg.solve_triangular(Rm, (Y0_Dinv @ Qm).T, lower=False).T
        # c = C x - Z2^T L fstack
        return G + K @ std.C, W - K @ (std.Z2.T @ std.jets.L[0])


class AlternativeCompletion(Completion):
    """Index-one form with stabilized constraints (thesis ch. 4, ERRATA 2 and 4).

    ``Z1^T (A x' + B x - f) = 0`` together with ``c' = -lam c`` for the
    constraints ``c = Z2^T (F x - g)``. ``Z1`` is an orthonormal basis of the
    range of ``A T2``, ``T2`` of the null space of ``Z2^T F``. The added
    eigenvalues are exactly ``-lam`` with no Jordan blocks: the constraint
    residual decays exactly like ``exp(-lam t)``.
    """

    method = "alternative"
    uses_lam = True
    extra_order = 1

    def _maps(self, std, t):
        n, k = self.n, self.k
        jets = std.jets
        A = jets.J[0][:n, :n]
        B = jets.F[0][:n]
        Z2, C = std.Z2, std.C
        AT2 = A @ std.T2
        Z1, s1, _ = scipy.linalg.svd(AT2, full_matrices=False)
        if numerical_rank(s1, AT2.shape, self.rcond, what="A T2") < AT2.shape[1]:
            raise IndexDeterminationError(f"A T2 is rank deficient at t={t:g}: the DAE is not solvable.")
        M = np.vstack([Z1.T @ A, C])
        width = (k + 2) * n
        # c' = Z2'^T (F x - g) + Z2^T (F' x + F x' - g') with (Z2^T)' = -Z2^T J' J^+
        # (ERRATA item 4): no differencing of a computed basis. J' = 0 for
        # constant coefficients.
        Jd = jets.J[1]
        if np.any(Jd):
            Y = Z2.T @ Jd @ std.pinv_rows()
        else:
            Y = np.zeros((Z2.shape[1], jets.J.shape[1]))
        lam = self.lam
        G_num = np.vstack([-Z1.T @ B, -lam * C + Y @ jets.F[0] - Z2.T @ jets.F[1]])
        E0 = np.zeros((n, width))
        E0[:, :n] = np.eye(n)
        W_num = np.vstack([Z1.T @ E0, (lam * Z2.T - Y) @ jets.L[0] + Z2.T @ jets.L[1]])
        lu = scipy.linalg.lu_factor(M)
        return scipy.linalg.lu_solve(lu, G_num), scipy.linalg.lu_solve(lu, W_num)


COMPLETIONS = {
    "standard": StandardCompletion,
    "stabilized": StabilizedCompletion,
    "alternative": AlternativeCompletion,
}


def complete(dae, method, *, lam=None, k=None, rcond=None):
    """Complete a linear DAE to an ODE ``x' = G x + g(t)``.

    Parameters
    ----------
    dae : LinearDAE
        The system ``A x' + B x = f(t)``.
    method : {'standard', 'stabilized', 'alternative'} or Completion subclass
        See `COMPLETIONS`.
    lam : float, optional
        Stabilization rate, required (positive, finite) for 'stabilized' and
        'alternative', and must be None for 'standard'.
    k : int, optional
        Number of differentiations; None means the differentiation index.
        A larger ``k`` is allowed (for the standard LSC it changes nothing,
        thesis Theorem 5).
    rcond : float, optional
        Relative threshold for every rank decision.

    Returns
    -------
    Completion

    Examples
    --------
    The index-2 system ``x2' + x1 = 0, x2 = sin t``; the alternative
    completion contains its exact solution ``x = (-cos t, sin t)``:

    >>> import numpy as np, sympy
    >>> from lsc import LinearDAE, complete
    >>> t = sympy.Symbol("t")
    >>> dae = LinearDAE([[0, 1], [0, 0]], np.eye(2), [0, sympy.sin(t)])
    >>> c = complete(dae, "alternative", lam=2.0)
    >>> c.k, c.n_constraints
    (2, 2)
    >>> x = np.array([-np.cos(0.5), np.sin(0.5)])
    >>> np.allclose(c.rhs(0.5, x), [np.sin(0.5), np.cos(0.5)])
    True
    """
    if isinstance(method, type) and issubclass(method, Completion) and method is not Completion:
        cls = method
    elif isinstance(method, str) and method in COMPLETIONS:
        cls = COMPLETIONS[method]
    else:
        raise ValueError(f"`method` must be one of {set(COMPLETIONS)} or a Completion subclass; found {method!r}.")
    return cls(dae, lam=lam, k=k, rcond=rcond)
