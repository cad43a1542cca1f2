"""Sparse set-up of the alternative completion for semi-explicit DAEs of Hessenberg form.

The alternative completion (thesis ch. 4; `lsc.AlternativeCompletion`) is
``Z1^T (A x' + B x - f) = 0`` together with the constraints
``c = Z2^T (F x - g)`` differentiated as ``c' = -lam c``; ``Z1`` spans
``range(A T2)``, ``T2`` spans ``null(C)``, ``C = Z2^T F``. Two facts make it
computable with sparse factorizations:

1. ``Z1^T r = 0`` (``r = A x' + B x - f``) says ``r`` is orthogonal to
   ``A null(C)``, i.e. ``A^T r`` lies in ``range(C^T)``: ``x'`` is the
   solution of the equality-constrained least-squares problem
   ``min ||R (A x' + B x - f)||  s.t.  C x' = -lam (C x - cg) + cg'``
   (its optimality conditions). ``R`` holds the row scales the dense set-up
   equilibrates with (`lsc._problem.equilibration`); its column scales cancel.
2. Only the row space of ``C`` matters: any ``C~ = T C`` (``T`` invertible,
   the forcing rows ``cg~ = T cg`` with it) gives the same constraints and the
   same completion. For a semi-explicit DAE the rows are known structurally.

The structure recognised and the constraint rows are those of
`lsc._sparse_structure` (semi-explicit, Hessenberg form). With the rows that
vanish on the algebraic unknowns ``C_c`` (differentiated further), the
terminal rows ``[C_t^d, T]`` (``T`` invertible) and ``H = E^T R_d^2 E``:

    [H    C_c^T] [x_d']   [E^T R_d^2 (f_d - B_d x)]
    [C_c  0    ] [mu  ] = [h_c]                       x_a' = T^-1 (h_t - C_t^d x_d')

(``h = -lam (C~ x - cg~) + cg~'``; the terminal rows' multipliers vanish
because ``A``'s algebraic columns are zero). For diagonal ``E`` the first
system is solved through its Schur complement ``C_c H^-1 C_c^T`` (the
pressure Laplacian for Stokes, 2 x 2 for ``msd_ind3``), and one application is
one sparse product and updates on the constraints' support
(`lsc._sparse_apply`). Nothing n x n is dense, and no derivative array is formed.
"""

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ._completion import SETUPS, AlternativeCompletion
from ._exceptions import DimensionError, IndexDeterminationError
from ._linalg import validate_rcond
from ._sparse_apply import DiagonalApply
from ._sparse_maps import (SparseCompletionMaps, constraint_forcing, forcing_jet, forcing_terms, setup_forcing,
                           sparse_lam_affine, sparse_maps)
from ._sparse_step import step_solver
from ._sparse_lu import DiagonalSolver, diagonal_of, factorize
from ._sparse_problem import DENSE_MAX, SparseLinearDAE, input_forcing_of, is_sparse_dae, sparse_equilibration
from ._sparse_structure import HessenbergForm, SparseStructureError, cols, hessenberg_form, rows
from ._timefunc import TimeFunction, _shape_str
from ._validate import check_k, check_lam_value, check_times

__all__ = ["HessenbergForm", "SparseCompletion", "SparseCompletionMaps", "SparseStructureError", "complete_sparse",
           "hessenberg_form"]


class SparseCompletion:
    """The alternative completion ``x' = G x + g(t)`` of a sparse DAE, as an operator (``G`` never stored).

    Made by `lsc.complete` for a sparse DAE whose structure the sparse set-up
    recognises (see docs/guide/sparse.md). It has the alternative
    completion's dynamics: the constraint residual decays exactly like
    ``exp(-lam t)``, the added eigenvalues are ``-lam`` without Jordan
    blocks, and it equals `lsc.AlternativeCompletion` of the same DAE to
    rounding.

    Attributes
    ----------
    dae : SparseLinearDAE
    n, k, index : int
        Unknowns; differentiations (= the differentiation index).
    lam : float
    method : str
        'alternative'.
    setup : str
        'sparse'.
    setup_note : str
        Why the sparse set-up was taken: the structure recognised and the factorizations made.
    order : int
        ``p = k + 1``: the forcing jet ``[f; f'; ...; f^(p)]`` the maps (`maps`, `lam_affine`) act on, as for
        `lsc.AlternativeCompletion` (the blocks beyond the index are zero).
    n_constraints : int
        Number of constraint rows (the dimension of the added dynamics).
    structure : HessenbergForm
        What was recognised.
    factorizations : dict
        Name -> (rows, nonzeros of the factors) of each factorization made at set-up.
    """

    method = "alternative"
    uses_lam = True
    setup = "sparse"
    setup_note = None
    extra_order = 1

    def __init__(self, dae, lam, *, k=None, structure=None):
        if not is_sparse_dae(dae):
            raise TypeError(f"`dae` must be a sparse lsc.LinearDAE (scipy.sparse A, B); found {type(dae).__name__}.")
        if isinstance(lam, TimeFunction) or callable(lam):
            raise ValueError("`lam` must be a positive constant for the sparse set-up; a time-varying rate needs the "
                             "dense path (n <= 2000).")
        self.dae, self.n, self.lam = dae, dae.n, check_lam_value(lam)
        A, B = dae.A_sparse, dae.B_sparse
        s = self.structure = hessenberg_form(A, B) if structure is None else structure
        self.index = s.index
        if k is not None:
            k = check_k(k)
            if k < s.index:
                raise IndexDeterminationError(
                    f"`k`={k} is below the differentiation index {s.index} ({s.describe()}). Use k=None.")
        self.k = s.index if k is None else k  # k above the index spans the same constraints: the same completion
        self.order = self.k + 1  # the forcing jet the maps act on, as the dense alternative completion's
        self.n_constraints = s.n_constraints
        r, _ = sparse_equilibration(A, B)  # column scales cancel from the completion (docs/guide/sparse.md)
        self.row_scales = r
        self._build()
        made = ", ".join(f"{name} {size} x {size}" for name, (size, _) in self.factorizations.items())
        self.setup_note = (f"scipy.sparse coefficients, n = {self.n}: {s.describe()}; the alternative completion "
                           f"through sparse factorizations ({made}), G never formed")
        setup_forcing(self)
        self._step_cache = {}
        self._projector = None

    # -- set-up -----------------------------------------------------------------------------------------------
    def _build(self):
        s = self.structure
        d, a = s.diff_cols, s.alg_cols
        w = np.ones(s.diff_rows.size) if self.row_scales is None else self.row_scales[s.diff_rows] ** 2
        self._W = scipy.sparse.csr_matrix(s.E.T @ scipy.sparse.diags(w))  # E^T R_d^2
        self._w_diag = None if s.E_diag is None else s.E_diag * w  # W as a vector when E is diagonal
        self._W_weights = w
        self._H = scipy.sparse.csr_matrix(self._W @ s.E)
        self._B_d = s.B_d
        nd = d.size
        # unknowns ordered differential first (the usual case): slices instead of gathers and scatters
        self._ordered = bool(np.array_equal(d, np.arange(nd)) and np.array_equal(a, np.arange(nd, self.n)))
        cont, term = np.flatnonzero(~s.terminal), np.flatnonzero(s.terminal)
        self._cont, self._term = cont, term
        self._C_c = cols(rows(s.C, cont), d).tocsr()
        self._C_cT = self._C_c.T.tocsr()
        self._C_td = cols(rows(s.C, term), d).tocsr()
        self._T = cols(rows(s.C, term), a).tocsr()
        self.factorizations = {}
        H_diag = diagonal_of(self._H)
        try:
            if not cont.size:
                self._kkt, self._H_solver, self._schur = None, factorize(self._H, "E^T R^2 E"), None
            elif H_diag is not None:
                self._H_solver = DiagonalSolver(H_diag, "E^T R^2 E")
                S = scipy.sparse.csr_matrix(self._C_c @ scipy.sparse.diags(1.0 / H_diag) @ self._C_c.T)
                self._schur = factorize(S, "the constraint rows' Schur complement C_c H^-1 C_c^T")
                self._schur.check()
                self._kkt = None
                self.factorizations["schur"] = (S.shape[0], self._schur.nnz)
            else:
                K = scipy.sparse.bmat([[self._H, self._C_c.T], [self._C_c, None]], format="csc")
                self._kkt = factorize(K, "the least-squares saddle-point matrix [[H, C_c^T], [C_c, 0]]")
                self._kkt.check()
                self._H_solver = self._schur = None
                self.factorizations["kkt"] = (K.shape[0], self._kkt.nnz)
            self._T_solver = s.T_solver
            self.factorizations["terminal"] = (self._T.shape[0], self._T_solver.nnz)
            # diagonal E (lumped masses, capacitances; every benchmark family): one sparse product per application
            self._apply = DiagonalApply(self) if s.E_diag is not None else None
        except np.linalg.LinAlgError as exc:
            raise IndexDeterminationError(
                f"{exc} The constraints of this DAE ({s.describe()}) do not determine x' uniquely: it is not "
                "uniquely solvable, or its constraint rows are dependent."
            ) from None

    # -- the operator -----------------------------------------------------------------------------------------
    def _times_W(self, v):
        if self._w_diag is None:
            return self._W @ v
        return v * (self._w_diag if v.ndim == 1 else self._w_diag[:, None])

    def _split(self, x):
        """``(x_d, x_a)``: the differential and algebraic unknowns of `x`."""
        s = self.structure
        if self._ordered:
            nd = s.diff_cols.size
            return x[:nd], x[nd:]
        return x[s.diff_cols], x[s.alg_cols]

    def _join(self, v_d, v_a):
        if self._ordered:
            return np.concatenate([v_d, v_a])
        s = self.structure
        out = np.empty((self.n,) + v_d.shape[1:])
        out[s.diff_cols] = v_d
        out[s.alg_cols] = v_a
        return out

    def _solve(self, rhs_d, h):
        """``x'`` from the least-squares data: ``rhs_d = E^T R^2 (f_d - B_d x)``, ``h`` the constraint rows' target."""
        h_c, h_t = h[self._cont], h[self._term]
        if self._kkt is not None:
            sol = self._kkt.solve(np.concatenate([rhs_d, h_c]))
            v_d = sol[: rhs_d.shape[0]]
        elif self._schur is not None:
            y = self._H_solver.solve(rhs_d)
            mu = self._schur.solve(self._C_c @ y - h_c)
            v_d = y - self._H_solver.solve(self._C_cT @ mu)
        else:
            v_d = self._H_solver.solve(rhs_d)
        v_a = self._T_solver.solve(h_t - self._C_td @ v_d)
        return self._join(v_d, v_a)

    def _homogeneous(self, x):
        """``G x`` (x of shape (n,) or (n, m))."""
        if self._apply is not None:
            return self._apply.apply(x, self.lam)
        return self._solve(-self._times_W(self._B_d @ x), -self.lam * (self.structure.C @ x))

    def rhs(self, t, x):
        """Right-hand side ``G x + g(t)`` in `scipy.integrate.solve_ivp` form (x: (n,) or (n, m))."""
        x = np.asarray(x, dtype=float)
        if self._apply is not None:
            return self._apply.rhs(self, float(t), x)
        rhs_f, cg, dcg = forcing_terms(self, float(t))
        if x.ndim == 2:
            rhs_f, cg, dcg = rhs_f[:, None], cg[:, None], dcg[:, None]
        rhs_d = rhs_f - self._times_W(self._B_d @ x)
        h = -self.lam * (self.structure.C @ x - cg) + dcg
        return self._solve(rhs_d, h)

    def forcing(self, t, d=0):
        """``g^(d)(t)``: the d-th derivative of the completion's forcing ``g`` (exact, from f's jets)."""
        if self._apply is not None:
            return self._apply.forcing(self, float(t), d)
        rhs_f, cg, dcg = forcing_terms(self, float(t), d)
        return self._solve(rhs_f, self.lam * cg + dcg)

    def operator(self):
        """``G`` as a `scipy.sparse.linalg.LinearOperator` (each product: the set-up's factorizations)."""
        return scipy.sparse.linalg.LinearOperator((self.n, self.n), matvec=self._homogeneous,
                                                  matmat=self._homogeneous, dtype=float)

    def jac(self, t=None, x=None):
        """Jacobian ``G`` of `rhs`, as a LinearOperator (see `operator`)."""
        return self.operator()

    def matrices(self, t):
        """``(G, g)`` at `t`: ``G`` as a LinearOperator, ``g`` a vector."""
        return self.operator(), self.forcing(t)

    # -- the public contract (`lsc.CompletionMaps`, `lsc.LamAffine`) -------------------------------------------
    def maps(self, t=None):
        """The completion at the time(s) `t` as operators acting on ``x`` and the forcing's jet (`CompletionMaps`).

        `lsc.Completion.maps` with the sparse kinds of arrays (`SparseCompletionMaps`): ``G``, ``W`` are
        LinearOperators, ``C``, ``Wc`` sparse matrices, without the time axis that ``t`` (default 0) and ``lam`` have.

        Examples
        --------
        >>> import numpy as np
        >>> from lsc import complete, gallery
        >>> p = gallery.msd_ind3(50)
        >>> c = complete(p.dae, "alternative", lam=1.0)
        >>> m = c.maps([0.5, 1.0])
        >>> m.G.shape, m.W.shape, m.order
        ((101, 101), (101, 505), 4)
        >>> x = p.exact(0.5)
        >>> bool(np.allclose(m.G @ x + m.forcing(p.dae.f_jet(0.5, m.order))[0], c.rhs(0.5, x)))
        True
        """
        return sparse_maps(self, check_times("t", 0.0 if t is None else t))

    def lam_affine(self, t=None, rtol=1e-10):
        """The maps split as ``G = G0 + lam G1``, ``W = W0 + lam W1`` (`LamAffine`), as LinearOperators.

        Exact: ``lam`` enters only the constraint rows' target ``-lam (C x - cg) + cg'``. Checked on a random
        vector against the maps at the rates 0.3, 7 and the completion's own (`residual`, relative).

        Examples
        --------
        >>> import numpy as np
        >>> from lsc import complete, gallery
        >>> p = gallery.stokes_ind2(4)
        >>> a = complete(p.dae, "alternative", lam=3.0).lam_affine()
        >>> x = np.ones(p.dae.n)
        >>> G7 = complete(p.dae, "alternative", lam=7.0).operator()
        >>> bool(np.allclose(a.G0 @ x + 7.0 * (a.G1 @ x), G7 @ x)), a.residual < 1e-12
        (True, True)
        """
        return sparse_lam_affine(self, check_times("t", 0.0 if t is None else t), rtol)

    # -- constraints ------------------------------------------------------------------------------------------
    def _cg(self, t):
        return constraint_forcing(self, forcing_jet(self, float(t)))[0]

    def constraint_residual(self, t, x):
        """The constraint residual ``C x - cg(t)`` of the structural constraint rows.

        Zero exactly on the solution manifold, and along the completion it
        decays like ``exp(-lam t)`` component by component. The rows are
        those of the Hessenberg recursion (``G p``, ``G v``, ... for a
        mechanical system), an invertible transformation of the dense
        set-up's ``Z2^T (F x - g)``: same zero set and decay, other units.

        Parameters
        ----------
        t : float or ndarray, shape (m,)
        x : ndarray, shape (n,) or (n, m)
        """
        x = np.asarray(x, dtype=float)
        if x.shape[:1] != (self.n,) or x.ndim > 2:
            raise DimensionError(f"`x` has the wrong shape: expected ({self.n},) or ({self.n}, m), got "
                                 f"{_shape_str(x.shape)}.")
        if x.ndim == 1:
            return self.structure.C @ x - self._cg(t)
        t = np.broadcast_to(np.asarray(t, dtype=float), (x.shape[1],))
        CX = self.structure.C @ x
        if self.dae.f is None:
            return CX
        return CX - np.column_stack([self._cg(ti) for ti in t]) if x.shape[1] else CX

    def project(self, t, x):
        """The consistent point nearest to `x` (Euclidean): ``min ||y - x|| s.t. C y = cg(t)``."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n,):
            raise DimensionError(f"`x` has the wrong shape: expected ({self.n},), got {_shape_str(x.shape)}.")
        if self._projector is None:
            C = self.structure.C
            self._projector = factorize(scipy.sparse.csr_matrix(C @ C.T), "C C^T (the constraint rows' Gram matrix)")
        c = self.constraint_residual(t, x)
        return x - self.structure.C.T @ self._projector.solve(c)

    def solve(self, t_span, x0, *, method="auto", t_eval=None, rtol=1e-3, atol=1e-6, project=False, **options):
        """Integrate ``x' = G x + g(t)``: what `lsc.solve_completion` runs for a sparse completion.

        ``method``: 'auto' (DOP853, or Rodas4 when the fastest decay rate of ``G`` times the interval exceeds
        100), 'Rodas4' (stiff: its solves are sparse saddle-point solves) or 'RK23', 'RK45', 'DOP853' through
        the operator (docs/guide/sparse.md). Returns a `CompletionResult`; a failed run has ``success=False``.
        """
        from ._sparse_integrate import solve_sparse  # scipy.integrate only when integrating (not in an FMU)

        return solve_sparse(self, t_span, x0, method=method, t_eval=t_eval, rtol=rtol, atol=atol, project=project,
                            **options)

    def clear_cache(self):
        """As `lsc.Completion.clear_cache`: nothing to forget (the forcing is read afresh at every evaluation)."""

    @property
    def added_eigenvalue(self):
        """The eigenvalue of the added dynamics: ``-lam`` (no Jordan blocks)."""
        return -self.lam

    # -- implicit steps ---------------------------------------------------------------------------------------
    def step_solver(self, c):
        """A solver of ``(I - c G) k = r`` (``c > 0``), cached by `c` (`lsc._sparse_step.StepSolver` states how)."""
        return step_solver(self, c)

    def __repr__(self):
        return (f"SparseCompletion(n={self.n}, k={self.k}, lam={self.lam:g}, constraints={self.n_constraints}, "
                f"{self.structure.describe()})")


def complete_sparse(cls, dae, *, lam=None, k=None, rcond=None, t_span=None, setup="auto"):
    """`lsc.complete` for a sparse DAE (or ``setup='sparse'``): the sparse set-up, or the dense path when small.

    ``setup='auto'`` uses the sparse set-up when the method is 'alternative'
    and the structure is recognised; otherwise the dense path for
    ``n <= DENSE_MAX`` (``setup_note`` says why) and a ValueError naming what
    is needed beyond. ``setup='sparse'`` never falls back; ``setup='dense'``
    densifies up to `DENSE_MAX` only.
    """
    if setup not in ("auto", "dense", "sparse"):
        raise ValueError(f"`setup` must be 'auto', 'dense' or 'sparse'; found {setup!r}.")
    if not is_sparse_dae(dae):
        if not dae.is_constant:
            raise ValueError("setup='sparse' needs constant coefficients.")
        dae = SparseLinearDAE(scipy.sparse.csr_matrix(dae.A(0.0)), scipy.sparse.csr_matrix(dae.B(0.0)),
                              dae.f.fn if hasattr(dae.f, "fn") else dae.f)
    n = dae.n

    def dense(note):
        if n > DENSE_MAX:
            raise ValueError(f"{note}; the dense path is refused for a sparse DAE of n = {n} > {DENSE_MAX} unknowns.")
        comp = cls(dae, lam=lam, k=k, rcond=rcond, t_span=t_span, setup="auto")
        comp.setup_note = note + ("" if comp.setup_note is None else f"; {comp.setup_note}")
        return comp

    if setup == "dense":
        return dense("setup='dense' asked for")
    if cls is not AlternativeCompletion:
        note = (f"the sparse set-up gives the 'alternative' completion only (the {cls.method!r} one needs the "
                "minimum-norm solution of the whole derivative array)")
        if setup == "sparse":
            raise ValueError(note + ".")
        return dense(note)
    validate_rcond(rcond)  # the sparse set-up makes no rank decision with it: its factorizations check conditioning
    try:
        structure = hessenberg_form(dae.A_sparse, dae.B_sparse)
    except SparseStructureError as exc:
        if setup == "sparse" or n > DENSE_MAX:
            raise SparseStructureError(f"the sparse set-up does not recognise this DAE: {exc}.") from None
        return dense(f"sparse set-up declined: {exc}")
    return SparseCompletion(dae, lam, k=k, structure=structure)


SETUPS["sparse"] = complete_sparse
