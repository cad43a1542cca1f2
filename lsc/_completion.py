"""ODE completions ``x' = G(t) x + g(t)`` of a linear DAE ``A x' + B x = f``.

Three methods (thesis chapters 2-6):

- ``'standard'``: the least squares completion (LSC), first block row of
  ``J^+ (-F x + g)`` for the standard derivative array. For constant
  coefficients the extra eigenvalues are 0; for time-varying ones the extra
  dynamics can be anything (thesis Example 3).
- ``'stabilized'``: the same on the array built with ``D = d/dt + lam``.
  Extra eigenvalues ``-lam``, in Jordan blocks as long as the nilpotent chains.
- ``'alternative'``: the index-one form ``Z1^T (A x' + B x - f) = 0`` with the
  constraints ``c = Z2^T (F x - g)`` differentiated as ``c' = -lam c``.
  Extra eigenvalues ``-lam`` with no Jordan blocks; for time-varying
  coefficients the residual decays exactly like ``exp(-int lam)``.

For constant coefficients every completion is computed once, at
construction: ``rhs`` then costs one matrix-vector product plus the forcing
``W @ [f; f'; ...]``. For time-varying ones the completion is computed at
each time it is asked for (one factorization of the derivative array), and the last few
times are cached so `matrices`, `rhs`, `constraint_residual` and `project`
at one time share one factorization.
"""

from collections import OrderedDict

import numpy as np
import scipy.linalg

from ._batch import alternative_maps, stabilized_maps, standard_maps
from ._dense_factors import WARM_MIN_ROWS, _Factors
from ._derivative_array import stabilization_jets
from ._exceptions import DimensionError, IndexDeterminationError
from ._forcing import Forcing
from ._index import check_solvability, determine_index, k_works
from ._linalg import validate_rcond
from ._problem import balance, check_dae, unscale_columns, varying_view
from ._rate import as_rate, lam_at
from ._structured import StructuredFactors, StructuredFallback
from ._threads import blas_threads
from ._timefunc import TimeFunction, _shape_str
from ._validate import check_k, check_t_span

__all__ = [
    "Completion",
    "StandardCompletion",
    "StabilizedCompletion",
    "AlternativeCompletion",
    "COMPLETIONS",
    "complete",
]

# The largest k - index accepted: measured on the gallery's constant problems (docs/reliability_library.md),
# the error stays at the k = index level up to index + 12 at least and grows beyond index + 15.
K_ABOVE_INDEX = 10
_CACHE_SIZE = 4


class Completion:
    """Base class of the ODE completions ``x' = G x + g(t)`` of a linear DAE.

    Use `complete` to build one. A subclass must provide (the numbered
    contract):

    1. ``method``: its key in `COMPLETIONS` (the class name, lower case,
       without ``Completion``).
    2. ``uses_lam``: True if the stabilization rate ``lam`` is required,
       False if it must be None.
    3. ``extra_order``: how many derivatives of the arrays beyond ``k`` it
       needs (the alternative completion differentiates the constraints once
       more: 1; the others 0).
    4. ``_maps(self, fac, t)``: from the standard array factors `fac` at `t`
       (a `_Factors`), return ``(G, W)``: ``x' = G x + W`` where ``W`` is
       built from ``fac.Lg`` and ``fac.f0`` only linearly, so it is the
       forcing map (constant coefficients) or the forcing value at `t`.
       The built-in methods use only ``fac.times_F``, ``fac.times_L`` and the
       basis attributes, so for constant coefficients they also accept a
       `lsc._structured.StructuredFactors` (no dense ``J``).
    5. ``added_eigenvalue``: the value theory assigns to the added dynamics
       of a constant-coefficient completion.

    Everything else (validation, index determination, evaluation, caching,
    ``rhs``, ``jac``, ``matrices``, ``constraint_residual``, ``project``)
    lives here, once.

    Attributes
    ----------
    dae : LinearDAE
        The DAE; for a time-varying ``lam`` on constant coefficients a copy
        of it with ``is_constant = False``, so every consumer evaluates the
        completion where it varies.
    n : int
        Number of unknowns.
    k : int
        Differentiations used (the differentiation index unless given).
    lam : float, TimeFunction or None
        Stabilization rate (a TimeFunction for time-varying rates).
    method : str
        Registry key.
    n_constraints : int
        Number of independent constraints (``a`` = corank of J): the
        dimension of the added dynamics.
    t_span : tuple or None
        Interval over which ``k`` was decided (time-varying DAEs).
    setup : {'structured', 'dense'}
        How the constant-coefficient set-up was computed (see `complete`).
    setup_note : str or None
        Why the structured set-up declined, when it did.
    """

    method = None
    uses_lam = False
    extra_order = 0
    # Time-varying, arrays of 100 rows and more: factor J by an LU warm-started from the last time's null spaces
    # (_Factors._warm); False forces the SVD at every time. `block_qr = True` tries the block-column QR
    # (lsc._structured_tv.BlockQR) first: 1.5x faster than the warm LU with one BLAS thread, not shown faster
    # with two (examples/bench_tv_factor.py), so not the default.
    warm_start = True
    block_qr = False
    _fastest_rate = None  # max |Re eig(G)| for constant coefficients, cached by lsc.stiffness_ratio
    _stacked_maps = None  # ``(st, times) -> (Gs, gs)`` on many times at once (lsc._batch), where defined

    def __init__(self, dae, *, lam=None, k=None, rcond=None, t_span=None, setup="auto"):
        check_dae(dae)
        self.dae = dae
        self.n = dae.n
        self.rcond = validate_rcond(rcond)
        self.t_span = None if t_span is None else check_t_span(t_span)
        self._t_ref = 0.0 if self.t_span is None else min(self.t_span)
        self.lam = self._check_lam(lam)
        if dae.is_constant and isinstance(self.lam, TimeFunction):
            # G(t) follows lam(t): evaluate it where it is asked for, like time-varying coefficients.
            self.dae = dae = varying_view(dae)
        # Badly scaled rows, unknowns (x = diag(c) y) and a pencil written in a time unit far from its rate
        # (t = sigma tau) are equilibrated once (constant scales, so the solutions map one to one); the arrays
        # (dense or structured) are built from the equilibrated DAE, and `_unscaled` maps what they give back.
        self._scaling = balance(dae, self._t_ref)
        self._row_scales, self._col_scales, self._sigma = self._scaling.r, self._scaling.c, self._scaling.sigma
        self._eq = self._scaling.apply(dae)
        self.setup, self.setup_note, self._structured = self._check_setup(setup), None, None
        self.k = self._structured_k(k) if self.setup == "structured" else self._check_k(k)
        self._order = self.k + self.extra_order
        self._cache = OrderedDict()
        self._last_factors = None
        if dae.is_constant:
            fac, (G, W) = self._constant_maps()
            self._std = fac
            self._rank = fac.rank
            self._G, self._W, self._W_c = self._unscaled(fac, G, W)
            self._setup_forcing()
        else:
            fac = self._factors(self._t_ref, check=False)
            self._rank = fac.rank
        self.n_constraints = fac.C.shape[0]

    # -- set-up (constant coefficients) --------------------------------------
    def _check_setup(self, setup):
        if setup not in ("auto", "dense"):
            raise ValueError(f"`setup` must be 'auto' or 'dense'; found {setup!r}.")
        # a user's subclass may read the dense factors (`fac.jets`) in its `_maps`: it keeps them
        return "structured" if setup == "auto" and self.dae.is_constant and self._builtin_maps() else "dense"

    def _builtin_maps(self):
        """Whether `_maps` is the library's own: only then may the structured or stacked set-ups stand in for it."""
        return type(self)._maps in (StandardCompletion._maps, StabilizedCompletion._maps, AlternativeCompletion._maps)

    def _structured_k(self, k):
        """k from the structured set-up (lsc._structured); on a declined problem the dense path decides."""
        t, eq = self._t_ref, self._eq  # the equilibrated equations, as the dense path uses them
        k = None if k is None else check_k(k)
        try:
            fac = StructuredFactors(eq.A(t), eq.B(t), k, self.extra_order, self.rcond)
        except StructuredFallback as exc:
            self.setup, self.setup_note = "dense", f"structured set-up declined: {exc}"
            return self._check_k(k)
        if k is not None and k > K_ABOVE_INDEX and k > fac.index + K_ABOVE_INDEX:
            return self._check_k(k)  # the dense path's refusal, with its message
        self._structured = fac
        return fac.k

    def _constant_maps(self):
        """``(fac, (G, W))`` at construction; a structured set-up that declines here hands over to the dense one."""
        fac = self._structured
        if fac is not None:
            try:
                return fac, self._maps(fac, self._t_ref)
            except StructuredFallback as exc:
                self.setup, self.setup_note = "dense", f"structured set-up declined: {exc}"
        fac = _Factors(self._eq, self.k, self._t_ref, self.extra_order, self.rcond)
        return fac, self._maps(fac, self._t_ref)

    # -- validation ---------------------------------------------------------
    def _check_lam(self, lam):
        if not self.uses_lam:
            if lam is not None:
                raise ValueError(
                    f"`lam` must be None for the {self.method!r} completion, which has no stabilization; found {lam!r}."
                )
            return None
        if lam is None:
            raise ValueError(
                f"`lam` is required for the {self.method!r} completion: a positive finite rate "
                "(e.g. lam=1.0), a sympy expression in t or a callable lam(t, d); found None."
            )
        lam = as_rate(lam)
        if isinstance(lam, TimeFunction):
            self._check_rate_on([self._t_ref] if self.t_span is None else self.t_span, lam)
        return lam

    def _check_rate_on(self, t_span, lam=None):
        """Refuse a time-varying rate that is not positive at 101 points of `t_span` (or at one time)."""
        lam = self.lam if lam is None else lam
        if not isinstance(lam, TimeFunction):
            return
        times = np.linspace(t_span[0], t_span[-1], 101 if len(t_span) == 2 else 1)
        for t in times:
            lam_at(lam, float(t))

    def _check_k(self, k):
        dae, t = self.dae, self._t_ref
        if k is None:
            if not dae.is_constant and self.t_span is not None:
                return check_solvability(dae, self.t_span, rcond=self.rcond).k
            k, _ = determine_index(dae, t, 10, self.rcond)
            return k
        k = check_k(k)
        if not dae.is_constant and self.t_span is not None:
            check_solvability(dae, self.t_span, k=k, rcond=self.rcond)
        else:
            ok, ranks, nxt = k_works(dae, k, t, self.rcond)
            if not ok:
                raise IndexDeterminationError(
                    f"`k`={k} is too small at t={t:g}: the derivative array does not determine x' "
                    f"({ranks}; next: {nxt}). Use k=None for the differentiation index."
                )
        if k > K_ABOVE_INDEX:
            index, _ = determine_index(dae, t, k, self.rcond)
            if k > index + K_ABOVE_INDEX:
                raise ValueError(
                    f"`k`={k} is {k - index} above the differentiation index {index} (at t={t:g}); at most "
                    f"index + {K_ABOVE_INDEX} = {index + K_ABOVE_INDEX} is accepted. More differentiations gain "
                    "nothing in exact arithmetic (the solutions are those of k = index), but the derivative "
                    "array's entries grow like binomial coefficients and f's derivatives of order up to k + 1, "
                    "so rounding grows: "
                    "on gallery.prescribed_path (index 3) the error is 8e-9 up to k = 15, then 7e-8 at k = 18, "
                    "4e-3 at k = 28 and 2 at k = 33. Use k=None."
                )
        return k

    # -- evaluation ---------------------------------------------------------
    def _factors(self, t, check=True):
        """The standard-array factors at `t`, with the forcing as values at `t`."""
        fstack = self._eq.f_jet(t, self._order).reshape(-1)
        # Warm start from the factors last computed (a nearby time, for a solver or an interpolant's
        # nested points); the first and any doubtful time take the SVD.
        ref = self._last_factors if check and self.warm_start else None
        fac = _Factors(self._eq, self.k, t, self.extra_order, self.rcond, fmap=fstack,
                       expected_rank=self._rank if check else None, reference=ref,
                       block=self.block_qr and self.warm_start)
        if check and fac.Z2.shape[0] >= WARM_MIN_ROWS:
            self._last_factors = fac
        return fac

    def _evaluate(self, t):
        """``(fac, G, g)`` at `t` for a time-varying completion, cached."""
        t = float(t)
        hit = self._cache.get(t)
        if hit is not None:
            self._cache.move_to_end(t)
            return hit
        fac = self._factors(t)
        G, g, _ = self._unscaled(fac, *self._maps(fac, t))
        self._cache[t] = (fac, G, g)
        if len(self._cache) > _CACHE_SIZE:
            self._cache.popitem(last=False)
        return self._cache[t]

    def _lam_jet(self, t, order=0):
        """The rate's derivatives ``0..order`` at `t` in the equilibrated DAE's time ``tau = t / sigma``."""
        jet = lam_at(self.lam, t, order)
        return jet if self._sigma == 1.0 else jet * self._sigma ** np.arange(1.0, order + 2)

    def _unscaled(self, fac, G, W):
        """``(G, W, W_c)`` in the given unknowns, equations and time from the equilibrated DAE's (`_eq`).

        ``W`` is the forcing map on the equilibrated jet ``[f~; f~'; ...]`` (constant coefficients; then ``W_c``
        is the constraints' map ``fac.cg`` on the given jet) or the forcing's value (time-varying; ``W_c`` None).
        With ``x = diag(c) y`` and ``t = sigma tau``: ``x' = diag(c) (G_y diag(c)^-1 x + g_y) / sigma``, and the
        equilibrated jet is the given one times `lsc._problem.Scaling.fstack_scales`.
        """
        if self._col_scales is not None:
            G, W = unscale_columns(fac, G, W, self._col_scales)
        W_c = None
        if np.ndim(W) == 2:
            W_c = fac.cg
            if self._row_scales is not None or self._sigma != 1.0:  # (no copies of the wide maps when not needed)
                columns = self._scaling.fstack_scales(self.n, self._order)
                W, W_c = W * columns, W_c * columns
        if self._sigma != 1.0:
            G, W = G / self._sigma, W / self._sigma
        return G, W, W_c

    # -- forcing (constant coefficients) -------------------------------------
    def _setup_forcing(self):
        f = self.dae.f
        if f is None:
            self._g_const = np.zeros(self.n)
            self._c_const = np.zeros(self._W_c.shape[0])
        elif f.is_constant:
            fstack = f.jet(0.0, self._order).reshape(-1)
            self._g_const = self._W @ fstack
            self._c_const = self._W_c @ fstack
        else:
            self._g_const = None
            self._c_const = None
            self._forcing = Forcing(self._W, f, self._order)  # g(t) compiled once (lsc._forcing)

    def _fstack(self, t):
        return self.dae.f.jet(t, self._order).reshape(-1)

    # -- public evaluation --------------------------------------------------
    def matrices(self, t):
        """``(G, g)`` with ``x' = G x + g`` at time `t`.

        Returns
        -------
        G : ndarray, shape (n, n)
        g : ndarray, shape (n,)
        """
        if not self.dae.is_constant:
            _, G, g = self._evaluate(t)
            return G, g
        if self._g_const is not None:
            return self._G, self._g_const
        return self._G, self._forcing.value(t)

    def rhs(self, t, x):
        """Right-hand side ``G x + g(t)`` in `scipy.integrate.solve_ivp` form."""
        if self.dae.is_constant:
            if self._g_const is not None:
                return self._G @ x + self._g_const
            return self._G @ x + self._forcing.value(t)
        _, G, g = self._evaluate(t)
        return G @ x + g

    def jac(self, t, x):
        """Jacobian ``G(t)`` of `rhs`."""
        if self.dae.is_constant:
            return self._G
        return self._evaluate(t)[1]

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
        if x.ndim == 2:
            t = np.broadcast_to(np.asarray(t, dtype=float), (x.shape[1],))
            if self.dae.is_constant and self._c_const is not None:
                return self._std.C @ x - self._c_const[:, None]
            return np.column_stack([self.constraint_residual(ti, xi) for ti, xi in zip(t, x.T)]) if x.shape[1] else np.zeros((self.n_constraints, 0))
        if self.dae.is_constant:
            cg = self._c_const if self._c_const is not None else self._W_c @ self._fstack(t)
            return self._std.C @ x - cg
        fac = self._evaluate(t)[0]
        return fac.C @ x - fac.cg

    def project(self, t, x):
        """The consistent point nearest to `x` (least squares) at time `t`.

        Solves ``min ||y - x||`` subject to ``Z2^T (F y - g(t)) = 0``.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n,):
            raise DimensionError(f"`x` has the wrong shape: expected ({self.n},), got {_shape_str(x.shape)}.")
        fac = self._std if self.dae.is_constant else self._evaluate(t)[0]
        return x - fac.C_pinv @ self.constraint_residual(t, x)

    @property
    def added_eigenvalue(self):
        """The eigenvalue theory assigns to the added dynamics (constant coefficients)."""
        if self.lam is None:
            return 0.0
        if isinstance(self.lam, TimeFunction):
            raise ValueError("`added_eigenvalue` needs a constant `lam`.")
        return -self.lam

    def __repr__(self):
        if self.lam is None:
            lam = ""
        elif isinstance(self.lam, TimeFunction):
            lam = ", lam=lam(t)"
        else:
            lam = f", lam={self.lam:g}"
        return f"{type(self).__name__}(n={self.n}, k={self.k}{lam}, constraints={self.n_constraints})"

    def _maps(self, fac, t):  # pragma: no cover - abstract
        raise NotImplementedError


class StandardCompletion(Completion):
    """Least squares completion of the standard derivative array (thesis ch. 2).

    ``x' = V^T J^+ (-F x + g)``. For constant coefficients the added
    eigenvalues are 0, in Jordan blocks as long as the nilpotent chains
    (thesis Lemma 1): off the manifold, solutions drift polynomially. For
    time-varying coefficients the added dynamics can be anything (thesis
    Example 3).
    """

    method = "standard"
    uses_lam = False

    def _maps(self, fac, t):
        P = fac.first_rows
        return -fac.times_F(P, 0), fac.times_L(P, 0)

    def _stacked_maps(self, st, times):
        return standard_maps(st)


class StabilizedCompletion(StandardCompletion):
    """Least squares completion of the stabilized array ``D = d/dt + lam`` (ch. 3, 5).

    For constant coefficients the added eigenvalues are ``-lam``, in Jordan
    blocks as long as the nilpotent chains, so off-manifold solutions decay
    like a polynomial times ``exp(-lam t)``. ``lam`` may vary with time
    (thesis ch. 5); the product rule of ERRATA item 1 is applied.

    Notes
    -----
    The stabilized array is ``(Lam kron I)`` times the standard one, row for
    row, with ``Lam`` unit lower triangular (`stabilization_jets`; for
    time-varying ``lam`` it holds the rate's derivatives). Writing the LSC
    ``V^T (D J)^+ D (-F x + g)`` through thesis Theorem 8 gives, exactly,

    ``x' = [standard LSC] + K c``,  ``K = Y0 D^-1 (M^+)^T``,  ``M = D^-T Z2``,

    with ``Y0 = V^T J^+`` and ``c = Z2^T (F x - g)`` the constraint
    residual: stabilization is a feedback of the residual. This avoids the
    SVD of ``D J``, whose rows scale like ``lam^i``: against a 60-digit
    reference (index 3, n = 8) the relative error in ``G`` is 5e-7 at
    lam = 100 where the SVD of ``D J`` gives 2e-3, and 4e-3 at lam = 1000
    where it gives no digit right.
    """

    method = "stabilized"
    uses_lam = True

    def _maps(self, fac, t):
        G, W = super()._maps(fac, t)
        n, k = self.n, self.k
        N, a = fac.Z2.shape
        Lam = stabilization_jets(k, 0, self._lam_jet(t, k))[0]
        Lam_inv = scipy.linalg.solve_triangular(Lam, np.eye(k + 1), lower=True, unit_diagonal=True)
        # M = (Lam^-T kron I) Z2 and Y0 (Lam^-1 kron I), block by block.
        M = np.einsum("ji,jba->iba", Lam_inv, fac.Z2.reshape(k + 1, n, a)).reshape(N, a)
        Y0_Dinv = np.einsum("aib,ij->ajb", fac.first_rows.reshape(n, k + 1, n), Lam_inv).reshape(n, N)
        Qm, Rm = scipy.linalg.qr(M, mode="economic")
        K = scipy.linalg.solve_triangular(Rm, (Y0_Dinv @ Qm).T, lower=False).T
        return G + K @ fac.C, W - K @ fac.cg

    def _stacked_maps(self, st, times):
        return stabilized_maps(st, [stabilization_jets(self.k, 0, self._lam_jet(t, self.k))[0] for t in times])


class AlternativeCompletion(Completion):
    """Index-one form with stabilized constraints (thesis ch. 4, 6; ERRATA 2, 4).

    ``Z1^T (A x' + B x - f) = 0`` together with ``c' = -lam c`` for the
    constraints ``c = Z2^T (F x - g)``. ``Z1`` is an orthonormal basis of the
    range of ``A T2``, ``T2`` of the null space of ``Z2^T F``. The added
    eigenvalues are exactly ``-lam`` with no Jordan blocks, and for
    time-varying coefficients and rates the residual decays exactly like
    ``exp(-int lam)``. The derivative of the basis is never obtained by
    differencing: ``(Z2^T)' = -Z2^T J' J^+`` with ``J'`` from the analytic
    derivatives of the coefficients (ERRATA item 4).
    """

    method = "alternative"
    uses_lam = True
    extra_order = 1

    def _maps(self, fac, t):
        Z2, C = fac.Z2, fac.C
        # c' = (Z2^T)' (F x - g) + Z2^T (F' x + F x' - g') = -lam c, with
        # (Z2^T)' = -Z2^T J' J^+, so (Z2^T)' (F x - g) = -Y (F x - g); Y = 0 for constant coefficients.
        lam = self._lam_jet(t)[0]
        G_c = -lam * C - fac.times_F(Z2.T, 1)
        W_c = lam * fac.cg + fac.times_L(Z2.T, 1)
        if fac.has_Jd:
            Y = fac.times_pinv(Z2.T @ fac.jets.J[1])
            G_c, W_c = G_c + fac.times_F(Y, 0), W_c - fac.times_L(Y, 0)
        return fac.index_one_solve(G_c, W_c, self.rcond, t)

    def _stacked_maps(self, st, times):
        return alternative_maps(st, [self._lam_jet(t)[0] for t in times], self.rcond, times)


# Set-ups for DAEs the classes above do not take whole: lsc._sparse registers 'sparse' (scipy.sparse DAEs) on import.
SETUPS = {}

COMPLETIONS = {
    "standard": StandardCompletion,
    "stabilized": StabilizedCompletion,
    "alternative": AlternativeCompletion,
}


def complete(dae, method, *, lam=None, k=None, rcond=None, t_span=None, setup="auto"):
    """Complete a linear DAE to an ODE ``x' = G(t) x + g(t)``.

    Parameters
    ----------
    dae : LinearDAE
        The system ``A x' + B x = f(t)``.
    method : {'standard', 'stabilized', 'alternative'} or Completion subclass
        See `COMPLETIONS`.
    lam : float, sympy expression or callable, optional
        Stabilization rate, required for 'stabilized' and 'alternative' and
        None for 'standard': a positive finite constant, a sympy expression
        in ``t`` or a callable ``lam(t, d)`` returning the d-th derivative.
        A time-varying rate must stay positive; it is checked on `t_span`
        (101 points) and wherever the completion is evaluated.
    k : int, optional
        Number of differentiations; None means the differentiation index.
        A larger ``k`` is allowed up to the index plus `K_ABOVE_INDEX` (10)
        (for the standard LSC it changes nothing, thesis Theorem 5); beyond
        that rounding errors grow with ``k`` and a ValueError says so.
    rcond : float, optional
        Relative threshold for every rank decision.
    t_span : pair of float, optional
        Interval of use. For time-varying coefficients ``k`` is then decided
        over the interval (`check_solvability`): the index can be lower at
        isolated times (thesis Example 1 is 1-full with k = 1 at t = 0 only).
        Without it ``k`` is decided at t = 0. Either way, every evaluation
        checks that the array keeps its rank and stays 1-full, and raises
        `IndexDeterminationError` naming the time otherwise.
    setup : {'auto', 'dense', 'sparse'}, optional
        For constant coefficients, 'auto' computes the index, the ranks and
        the completion from n-sized blocks of the pencil (a shift, a
        staircase of null spaces, bordered LU solves; `lsc._structured`)
        instead of SVDs of the whole derivative arrays, and falls back to
        the dense path when a rank decision there is a close call or no
        shift makes ``B + mu A`` well conditioned (`Completion.setup_note`
        says why). 'dense' always uses the SVDs. Time-varying completions
        are always dense. For a DAE with scipy.sparse ``A``, ``B``, 'auto'
        uses the sparse set-up (`lsc.SparseCompletion`, 'alternative' only,
        semi-explicit DAEs of Hessenberg form; docs/guide/sparse.md) and the
        dense path only up to n = 2,000; 'sparse' asks for the sparse
        set-up (a dense constant DAE is converted) and never falls back.

    Returns
    -------
    Completion

    Notes
    -----
    When the norms of the rows of ``[A, B]`` (at the start of `t_span`, or
    t = 0) spread by more than 1024, the equations are multiplied by powers
    of two that equilibrate them before any rank decision: the solutions,
    the DAE's eigenvalues and the added eigenvalues ``-lam`` do not change,
    the standard and stabilized LSC's least-squares metric does (see
    docs/reliability_library.md). The unknowns are scaled likewise, and a
    pencil whose rate (``||B|| / ||A||``, and the rates its coefficients
    vary at) is off 1 by more than 4 is completed in its own unit of time
    (a power of two), then mapped back exactly
    (`lsc._problem.balance`). A time-varying ``lam`` makes the
    completion time-varying even for constant ``A`` and ``B``.

    Examples
    --------
    The index-2 system ``x2' + x1 = 0, x2 = sin t``; the alternative
    completion contains its exact solution ``x = (-cos t, sin t)``:

    >>> import numpy as np, sympy
    >>> from lsc import LinearDAE, complete
    >>> t = sympy.Symbol("t")
    >>> dae = LinearDAE([[0, 1], [0, 0]], np.eye(2), [0, sympy.sin(t)])
    >>> c = complete(dae, "alternative", lam=2.0)
    >>> c.k, c.n_constraints, c.setup
    (2, 2, 'structured')
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
    with blas_threads():  # the set-up's BLAS threads are chosen (lsc._threads), not inherited
        if setup == "sparse" or getattr(dae, "is_sparse", False):  # scipy.sparse coefficients: lsc._sparse decides
            return SETUPS["sparse"](cls, dae, lam=lam, k=k, rcond=rcond, t_span=t_span, setup=setup)
        return cls(dae, lam=lam, k=k, rcond=rcond, t_span=t_span, setup=setup)
