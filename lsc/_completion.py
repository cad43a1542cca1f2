"""ODE completions ``x' = G(t) x + g(t)`` of a linear DAE ``A x' + B x = f``.

Three methods (thesis chapters 2-6), their maps written once in `lsc._methods`:

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
each time it is asked for (one factorization of the derivative array,
`lsc._setup`), and the last few times are cached so `matrices`, `rhs`,
`constraint_residual` and `project` at one time share one factorization.
"""

from collections import OrderedDict

import numpy as np

from . import _setup
from ._exceptions import DimensionError
from ._forcing import forcing_of
from ._linalg import validate_rcond
from ._maps import CompletionMaps, LamAffine
from ._methods import alternative_maps, stabilized_maps, standard_maps
from ._problem import balance, check_dae, varying_view
from ._rate import check_rate, lam_at
from ._threads import blas_threads
from ._timefunc import TimeFunction, _shape_str
from ._validate import check_t_span, check_times

__all__ = ["Completion", "StandardCompletion", "StabilizedCompletion", "AlternativeCompletion", "COMPLETIONS",
           "complete"]

_CACHE_SIZE = 4
# `lam_affine`: rates of order one in the DAE's own unit of time (`lsc._problem.balance`), whatever the completion's
# rate: from rates lam and 2 lam, (G(2 lam) - G(lam)) / lam cancels all digits for lam near 1e-12 and amplifies
# G0's rounding for lam near 1e12
_FIT_RATES, _CHECK_RATES = (1.0, 2.0), (0.3, 7.0)


class Completion:
    """Base class of the ODE completions ``x' = G x + g(t)`` of a linear DAE.

    Use `complete` to build one. A subclass must provide (the numbered contract):

    1. ``method``: its key in `COMPLETIONS` (the class name, lower case, without ``Completion``).
    2. ``uses_lam``: True if the stabilization rate ``lam`` is required, False if it must be None.
    3. ``extra_order``: derivatives of the arrays beyond ``k`` it needs (1 for the alternative completion).
    4. ``_maps(self, fac, lam)``: from the factors `fac` of the standard array at ``m`` times (the
       `lsc._factors.Factors` protocol) and the rate's jets ``lam`` there (shape (m, k + 1), in the
       equilibrated DAE's time; None without a rate), return ``(G, W)``, shapes (m, n, n) and (m, n, w):
       ``x' = G x + W``, ``W`` linear in the forcing quantities (``fac.times_L``, ``fac.cg``, ``fac.f0``),
       so the forcing map or its value, as `fac` holds it. A subclass's own ``_maps`` gets the dense
       factors at one time (`lsc._dense_factors.DenseFactors`, which also hold the array's jets).
    5. ``added_eigenvalue``: the value theory assigns to the added dynamics (constant coefficients).

    Attributes
    ----------
    dae : LinearDAE
        The DAE; for a time-varying ``lam`` on constant coefficients a copy of it with
        ``is_constant = False``, so every consumer evaluates the completion where it varies.
    n, k, order : int
        Unknowns; differentiations (the index unless given); the highest derivative of ``f`` used.
    lam : float, TimeFunction or None
        Stabilization rate.
    method : str
        Registry key.
    n_constraints : int
        Number of independent constraints (the corank of J): the dimension of the added dynamics.
    t_span : tuple or None
        Interval over which ``k`` was decided (time-varying DAEs).
    setup : {'structured', 'dense'}
        How the set-up was computed (`lsc._setup`); ``setup_note``: why the structured one declined.
    """

    method = None
    uses_lam = False
    extra_order = 0
    # Time-varying, arrays of 100 rows and more: factor J by an LU warm-started from the last time's null spaces;
    # False forces the SVD at every time. `block_qr = True` tries the block-column QR (lsc._structured_tv) first:
    # 1.5x faster than the warm LU with one BLAS thread, not shown faster with two (examples/bench_tv_factor.py).
    warm_start = True
    block_qr = False
    _fastest_rate = None  # max |Re eig(G)| for constant coefficients, cached by lsc.stiffness_ratio

    def __init__(self, dae, *, lam=None, k=None, rcond=None, t_span=None, setup="auto"):
        check_dae(dae)
        self.dae, self.n = dae, dae.n
        self.rcond = validate_rcond(rcond)
        self.t_span = None if t_span is None else check_t_span(t_span)
        self._t_ref = 0.0 if self.t_span is None else min(self.t_span)
        self.lam = check_rate(lam, self.uses_lam, self.method, self.t_span or [self._t_ref])
        if dae.is_constant and isinstance(self.lam, TimeFunction):
            # G(t) follows lam(t): evaluate it where it is asked for, like time-varying coefficients.
            self.dae = dae = varying_view(dae)
        # Badly scaled rows, unknowns (x = diag(c) y) and a pencil written in a time unit far from its rate
        # (t = sigma tau) are equilibrated once (constant scales, so the solutions map one to one); the factors
        # are those of the equilibrated DAE, and `_given` maps what they give back.
        self._scaling = balance(dae, self._t_ref)
        self._eq = self._scaling.apply(dae)
        self._cache, self._last_factors = OrderedDict(), None
        # only the library's own maps may be computed by the structured or stacked set-ups (`lsc._setup`): a
        # subclass's own `_maps` may read the dense factors' jets
        self._builtin = type(self)._maps in (StandardCompletion._maps, StabilizedCompletion._maps,
                                             AlternativeCompletion._maps)
        self.k, fac, maps, self.setup, self.setup_note = _setup.setup(self, setup, k)
        self.order = self.k + self.extra_order
        self._rank, self.n_constraints = fac.rank, fac.n_constraints
        if dae.is_constant:
            self._factors0, (self._std, Wc) = fac, self._given_factors(fac)
            G, W = self._given(*maps, fac)
            self._G, self._W, self._Wc = G[0], W[0], Wc[0]
            self._g = forcing_of(self._W, dae.f, self.order)  # compiled once (lsc._forcing)
            self._g_const = self._g.g if self._g.is_constant else None
            self._c_const = None if self._g_const is None else self._Wc @ self._fjet(0.0)

    # -- the equilibrated DAE's factors and maps in the given unknowns, equations and time (`Scaling`) --------
    def _given(self, G, W, fac):
        return self._scaling.maps_given(G, W, self.n, self.order, fac.fstack is None)

    def _given_factors(self, fac):
        return self._scaling.factors_given(fac, self.n, self.order)

    def _lam_jets(self, ts, k=None, value=None):
        """The rate's derivatives ``0..k`` at `ts` in the equilibrated time ``tau = t / sigma``, shape (m, k + 1);
        `value`: a constant rate instead of the completion's."""
        if self.lam is None and value is None:
            return None
        k = self.k if k is None else k
        jets = np.zeros((len(ts), k + 1))
        if value is None and isinstance(self.lam, TimeFunction):
            jets[:] = [lam_at(self.lam, float(t), k) for t in ts]
        else:  # a constant rate (checked positive when given)
            jets[:, 0] = self.lam if value is None else value
        sigma = self._scaling.sigma
        return jets if sigma == 1.0 else jets * sigma ** np.arange(1.0, k + 2)

    def _fjet(self, t):
        return self.dae.f_jet(t, self.order).reshape(-1)

    # -- evaluation (time-varying) ------------------------------------------------------------------------
    def _evaluate(self, t):
        """``(factors, G, g)`` at `t` for a time-varying completion (factors in the given unknowns), cached."""
        t = float(t)
        hit = self._cache.get(t)
        if hit is not None:
            self._cache.move_to_end(t)
            return hit
        fstack = self._eq.f_jet(t, self.order)  # the forcing first: its errors are reported before the array's
        fac = _setup.factors_at(self, t, fstack)
        G, g = self._given(*self._maps(fac, self._lam_jets(fac.t)), fac)
        hit = self._cache[t] = (self._given_factors(fac)[0], G[0], g[0, :, 0])
        if len(self._cache) > _CACHE_SIZE:
            self._cache.popitem(last=False)
        return hit

    def _maps_at(self, ts):
        """``(G, W, C, Wc)`` stacked over the times `ts` (time-varying): the stacked factors where `lsc._setup`
        may use them, one time at a time elsewhere."""
        out = _setup.stacked(self, ts, values=False)
        for i, t in enumerate(ts):
            if out[i] is None:
                fac = _setup.factors_at(self, float(t))
                G, W = self._given(*self._maps(fac, self._lam_jets(fac.t)), fac)
                given, Wc = self._given_factors(fac)
                out[i] = (G[0], W[0], given.C[0], Wc[0])
        n, w, a = self.n, self.n * (self.order + 1), self.n_constraints
        empty = (np.zeros((0, n, n)), np.zeros((0, n, w)), np.zeros((0, a, n)), np.zeros((0, a, w)))
        return [np.array(X) for X in zip(*out)] if out else empty

    # -- public evaluation ----------------------------------------------------------------------------------
    def maps(self, t=None):
        """The completion at the time(s) `t` as matrices acting on the forcing's jet (`CompletionMaps`).

        Parameters
        ----------
        t : float or array_like, shape (m,), optional
            Times (default: the start of `t_span`, or 0). The result has a leading axis of length m (1 for a
            single time). Constant coefficients give the same matrices at every time.

        Returns
        -------
        CompletionMaps
            ``G``, the forcing map ``W``, the constraint rows ``C`` and their forcing map ``Wc``, in the DAE's
            own unknowns, equations and unit of time.

        Examples
        --------
        >>> import numpy as np
        >>> from lsc import complete, gallery
        >>> p = gallery.rotating_canonical(2)
        >>> c = complete(p.dae, "alternative", lam=1.0)
        >>> m = c.maps(np.linspace(0.0, 1.0, 5))
        >>> m.G.shape[0], bool(np.allclose(m.G[2], c.matrices(0.5)[0]))
        (5, True)
        """
        ts = check_times("t", self._t_ref if t is None else t)
        lam = None if self.lam is None else np.array([float(lam_at(self.lam, t)[0]) for t in ts])
        if self.dae.is_constant:
            parts = [np.broadcast_to(X, (ts.size,) + X.shape) for X in (self._G, self._W, self._std.C[0], self._Wc)]
        else:
            parts = self._maps_at(ts)
        return CompletionMaps(ts, *parts, self.order, self.k, lam, self.method)

    def lam_affine(self, t=None, rtol=1e-10):
        """The maps split as ``G = G0 + lam G1``, ``W = W0 + lam W1`` at the time(s) `t` (`LamAffine`).

        Fitted at the rates 1 and 2 (in the DAE's own unit of time, see `complete`) from the factors of the
        completion's own array (the alternative completion is affine in a constant ``lam``; the standard one
        has ``G1 = W1 = 0``), and checked against the maps at the rates 0.3, 7 and the completion's own,
        relative to the size of the terms at each.

        Parameters
        ----------
        t : float or array_like, shape (m,), optional
            Times, as for `maps`.
        rtol : float, optional
            The largest misfit accepted (the split is exact up to rounding where it holds).

        Returns
        -------
        LamAffine

        Raises
        ------
        ValueError
            When the misfit exceeds `rtol` (the stabilized completion is not affine in ``lam``).

        Examples
        --------
        >>> import numpy as np
        >>> from lsc import complete, gallery
        >>> c = complete(gallery.nilpotent_chain(3).dae, "alternative", lam=5.0)
        >>> a = c.lam_affine()
        >>> bool(np.allclose(a.G0 + 5.0 * a.G1, c.maps().G)), a.residual < 1e-12
        (True, True)
        """
        return _lam_affine(self, check_times("t", self._t_ref if t is None else t), rtol)

    def matrices(self, t):
        """``(G, g)`` with ``x' = G x + g`` at time `t`: shapes (n, n) and (n,)."""
        if not self.dae.is_constant:
            _, G, g = self._evaluate(t)
            return G, g
        return self._G, (self._g_const if self._g_const is not None else self._g.value(t))

    def rhs(self, t, x):
        """Right-hand side ``G x + g(t)`` in `scipy.integrate.solve_ivp` form."""
        if self.dae.is_constant:
            return self._G @ x + (self._g_const if self._g_const is not None else self._g.value(t))
        _, G, g = self._evaluate(t)
        return G @ x + g

    def jac(self, t, x):
        """Jacobian ``G(t)`` of `rhs`."""
        return self._G if self.dae.is_constant else self._evaluate(t)[1]

    def constraint_residual(self, t, x):
        """The constraint residual ``c = Z2^T (F x - g(t))``: zero exactly on the solution manifold.

        ``Z2`` is an orthonormal basis of the left null space of the *standard* derivative array, so the
        residuals of the three methods are comparable. `t`: a time or (with `x` of shape (n, m)) m times;
        returns shape (a,) or (a, m).
        """
        x = np.asarray(x, dtype=float)
        if x.shape[:1] != (self.n,) or x.ndim > 2:
            raise DimensionError(f"`x` has the wrong shape: expected ({self.n},) or ({self.n}, m), got {_shape_str(x.shape)}.")
        if x.ndim == 2:
            t = np.broadcast_to(np.asarray(t, dtype=float), (x.shape[1],))
            if self.dae.is_constant and self._c_const is not None:
                return self._std.C[0] @ x - self._c_const[:, None]
            return np.column_stack([self.constraint_residual(ti, xi) for ti, xi in zip(t, x.T)]) if x.shape[1] \
                else np.zeros((self.n_constraints, 0))
        if self.dae.is_constant:
            cg = self._c_const if self._c_const is not None else self._Wc @ self._fjet(t)
            return self._std.C[0] @ x - cg
        fac = self._evaluate(t)[0]
        return fac.C[0] @ x - fac.cg[0, :, 0]

    def project(self, t, x):
        """The consistent point nearest to `x` (least squares) at time `t`: ``min ||y - x||`` subject to
        ``Z2^T (F y - g(t)) = 0``."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n,):
            raise DimensionError(f"`x` has the wrong shape: expected ({self.n},), got {_shape_str(x.shape)}.")
        fac = self._std if self.dae.is_constant else self._evaluate(t)[0]
        return x - fac.C_pinv[0] @ self.constraint_residual(t, x)

    def clear_cache(self):
        """Forget the evaluations kept for the last few times (time-varying completions).

        Call it when the coefficients a completion reads changed behind its back (a callable coefficient
        whose inputs were set anew): the next evaluation at a time computes it afresh.

        Examples
        --------
        >>> import numpy as np
        >>> from lsc import JetCallable, LinearDAE, complete
        >>> gain = [1.0]  # a coefficient read from outside: x2 = gain sin t
        >>> f = JetCallable(lambda t, order: np.array([[0.0, gain[0] * np.sin(t + d * np.pi / 2)]
        ...                                            for d in range(order + 1)]))
        >>> c = complete(LinearDAE([[0, 1], [0, 0]], np.eye(2), f), "alternative", lam=1.0)
        >>> g1 = c.matrices(0.5)[1]
        >>> gain[0] = 2.0
        >>> c.clear_cache()
        >>> bool(np.allclose(c.matrices(0.5)[1], 2 * g1))
        True
        """
        self._cache.clear()

    @property
    def added_eigenvalue(self):
        """The eigenvalue theory assigns to the added dynamics (constant coefficients)."""
        if self.lam is None:
            return 0.0
        if isinstance(self.lam, TimeFunction):
            raise ValueError("`added_eigenvalue` needs a constant `lam`.")
        return -self.lam

    def __repr__(self):
        lam = "" if self.lam is None else ", lam=lam(t)" if isinstance(self.lam, TimeFunction) else f", lam={self.lam:g}"
        return f"{type(self).__name__}(n={self.n}, k={self.k}{lam}, constraints={self.n_constraints})"

    def _maps(self, fac, lam):  # pragma: no cover - abstract
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

    def _maps(self, fac, lam):
        return standard_maps(fac)


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

    def _maps(self, fac, lam):
        return stabilized_maps(fac, lam)


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

    def _maps(self, fac, lam):
        return alternative_maps(fac, lam, self.rcond)


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
        at times sampled over the interval (`check_solvability` with
        ``between=False``): the index can be lower at isolated times (thesis
        Example 1 is 1-full with k = 1 at t = 0 only). A rank drop between the
        samples is not looked for here: a run that reaches it ends there
        (`solve_completion`); ``check_solvability(dae, t_span)`` finds it.
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


def _lam_affine(c, ts, rtol):
    """`Completion.lam_affine` at the times `ts`."""
    if not c.uses_lam:
        maps = c.maps(ts)
        return LamAffine(maps.G, np.zeros_like(maps.G), maps.W, np.zeros_like(maps.W), 0.0, (), maps)
    facs = [c._factors0] if c.dae.is_constant else [_setup.factors_at(c, float(t)) for t in ts]
    unit = c._scaling.sigma  # the DAE's own unit of time: rates r / unit are of order one there
    rates = [r / unit for r in _FIT_RATES + _CHECK_RATES]
    # at each time, the maps at the rates of the fit and the checks and at the completion's own rate, from one
    # factorization and one evaluation of the maps (the rates along the leading axis)
    parts = []
    for f in facs:
        jets = np.concatenate([c._lam_jets(f.t, value=r) for r in rates] + [c._lam_jets(f.t)])
        parts.append(c._given(*c._maps(f, jets), f))
    G, W = (np.broadcast_to(np.stack(X), (ts.size,) + X[0].shape) for X in zip(*parts))  # (m, rates + 1, ...)
    if c.dae.is_constant:
        maps = c.maps(ts)
    else:
        given = [c._given_factors(f) for f in facs]
        maps = CompletionMaps(ts, G[:, -1], W[:, -1], np.concatenate([g.C for g, _ in given]),
                              np.concatenate([Wc for _, Wc in given]), c.order, c.k,
                              np.array([float(lam_at(c.lam, t)[0]) for t in ts]), c.method)
    G1, W1 = (G[:, 1] - G[:, 0]) / (rates[1] - rates[0]), (W[:, 1] - W[:, 0]) / (rates[1] - rates[0])
    G0, W0 = G[:, 0] - rates[0] * G1, W[:, 0] - rates[0] * W1
    checks = [(rates[i], G[:, i], W[:, i]) for i in (2, 3)]
    residual = 0.0
    for rate, Gr, Wr in checks + [(maps.lam, maps.G, maps.W)]:
        rate = np.broadcast_to(rate, ts.shape)
        for name, M0, M1, M in (("G", G0, G1, Gr), ("W", W0, W1, Wr)):
            # relative to the size of the terms at that rate: at lam = 1e12 the lam G1 part is all of G
            size = [np.abs(X).max(axis=(1, 2), initial=0.0) for X in (M, M0, M1)]
            err = np.abs(M0 + rate[:, None, None] * M1 - M).max(axis=(1, 2), initial=0.0) / np.maximum(
                np.maximum(size[0], 1.0), size[1] + rate * size[2])
            residual = max(residual, float(np.max(err)))
            if not np.all(err <= rtol):
                i = int(np.argmin(err <= rtol))
                raise ValueError(f"{name}(lambda) of the {c.method} completion is not affine in lambda here "
                                 f"(relative misfit {float(err[i]):.1e} at lambda = {float(rate[i]):g}, "
                                 f"t = {float(ts[i]):g})")
    return LamAffine(G0, G1, W0, W1, residual, tuple(rates[2:]) + tuple(sorted(set(maps.lam.tolist()))), maps)
