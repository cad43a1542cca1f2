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
pressure Laplacian for Stokes, 2 x 2 for ``msd_ind3``). Nothing n x n is
dense, and no derivative array is formed.
"""

import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from ._completion import SETUPS, AlternativeCompletion
from ._exceptions import DimensionError, IndexDeterminationError
from ._linalg import validate_rcond
from ._sparse_integrate import solve_sparse
from ._sparse_lu import DiagonalSolver, diagonal_of, factorize
from ._sparse_problem import DENSE_MAX, SparseLinearDAE, input_forcing_of, is_sparse_dae, sparse_equilibration
from ._sparse_structure import HessenbergForm, SparseStructureError, cols, hessenberg_form, rows
from ._timefunc import TimeFunction, _shape_str
from ._validate import check_k, check_lam_value

__all__ = ["HessenbergForm", "SparseCompletion", "SparseStructureError", "complete_sparse", "hessenberg_form"]


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
        self.n_constraints = s.n_constraints
        r, _ = sparse_equilibration(A, B)  # column scales cancel from the completion (docs/guide/sparse.md)
        self.row_scales = r
        self._build()
        self._setup_forcing()
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
        except np.linalg.LinAlgError as exc:
            raise IndexDeterminationError(
                f"{exc} The constraints of this DAE ({s.describe()}) do not determine x' uniquely: it is not "
                "uniquely solvable, or its constraint rows are dependent."
            ) from None

    def _setup_forcing(self):
        """The forcing's contributions, mapped once: ``W f_d`` and ``cg = sum Gamma_i f^(i)``."""
        s, f = self.structure, self.dae.f
        self._order = s.index  # cg' needs f^(index)
        self._input = input_forcing_of(self.dae) if f is not None else None
        if self._input is not None:
            Bu = self._input.input_map
            Bu_d = Bu[s.diff_rows]
            self._Wu = self._W @ Bu_d
            self._Gu = [g @ Bu for g in s.Gamma]

    def _forcing_terms(self, t, d=0):
        """``(W f_d^(d), cg^(d), cg^(d+1))`` at `t`: the forcing parts of the least-squares data."""
        s, f = self.structure, self.dae.f
        a = s.n_constraints
        if f is None:
            return np.zeros(s.diff_rows.size), np.zeros(a), np.zeros(a)
        order = self._order + d
        if self._input is not None:
            U = self._input.u.jet(t, order)
            rhs = np.asarray(self._Wu @ U[d]).ravel()
            cg = sum((np.asarray(G @ U[i + d]).ravel() for i, G in enumerate(self._Gu)), np.zeros(a))
            dcg = sum((np.asarray(G @ U[i + d + 1]).ravel() for i, G in enumerate(self._Gu)), np.zeros(a))
            return rhs, cg, dcg
        F = f.jet(t, order)
        rhs = self._W @ F[d][s.diff_rows]
        cg = sum((G @ F[i + d] for i, G in enumerate(s.Gamma)), np.zeros(a))
        dcg = sum((G @ F[i + d + 1] for i, G in enumerate(s.Gamma)), np.zeros(a))
        return rhs, cg, dcg

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
        return self._solve(-self._times_W(self._B_d @ x), -self.lam * (self.structure.C @ x))

    def rhs(self, t, x):
        """Right-hand side ``G x + g(t)`` in `scipy.integrate.solve_ivp` form (x: (n,) or (n, m))."""
        x = np.asarray(x, dtype=float)
        rhs_f, cg, dcg = self._forcing_terms(float(t))
        if x.ndim == 2:
            rhs_f, cg, dcg = rhs_f[:, None], cg[:, None], dcg[:, None]
        rhs_d = rhs_f - self._times_W(self._B_d @ x)
        h = -self.lam * (self.structure.C @ x - cg) + dcg
        return self._solve(rhs_d, h)

    def forcing(self, t, d=0):
        """``g^(d)(t)``: the d-th derivative of the completion's forcing ``g`` (exact, from f's jets)."""
        rhs_f, cg, dcg = self._forcing_terms(float(t), d)
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

    def maps(self, t):
        """What a consumer needs at `t`: ``G`` (LinearOperator), ``g``, the constraint rows ``C`` and ``cg``."""
        return SparseMaps(G=self.operator(), g=self.forcing(t), C=self.structure.C, cg=self._cg(t))

    # -- constraints ------------------------------------------------------------------------------------------
    def _cg(self, t):
        return self._forcing_terms(float(t))[1]

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
        """Integrate ``x' = G x + g(t)``: `lsc.solve_completion` (which calls this) for a sparse completion.

        ``method``: 'auto' (default) estimates the fastest decay rate of
        ``G`` (ARPACK, the eigenvalues of largest magnitude) and takes
        'Rodas4' when that rate times the interval exceeds 100, 'DOP853'
        otherwise; 'Rodas4' (stiff:
        a Rosenbrock method whose solves are sparse saddle-point solves,
        factorizations reused); or an explicit solve_ivp method ('RK23',
        'RK45', 'DOP853') through the operator. ``t_eval``,
        ``dense_output``, ``max_step``, ``first_step`` as for solve_ivp. The
        result's ``method`` and message say what ran and why; a failed run
        returns ``success=False`` with the reason and the trajectory computed
        before it.

        Returns
        -------
        CompletionResult
        """
        return solve_sparse(self, t_span, x0, method=method, t_eval=t_eval, rtol=rtol, atol=atol, project=project,
                            **options)

    @property
    def added_eigenvalue(self):
        """The eigenvalue of the added dynamics: ``-lam`` (no Jordan blocks)."""
        return -self.lam

    # -- implicit steps ---------------------------------------------------------------------------------------
    def step_solver(self, c):
        """A solver of ``(I - c G) k = r`` (``c > 0``), cached by `c` (`_StepSolver` states how it solves)."""
        c = float(c)
        hit = self._step_cache.get(c)
        if hit is not None:
            return hit
        solver = _StepSolver(self, c)
        self._step_cache[c] = solver
        while len(self._step_cache) > _STEP_CACHE:
            self._step_cache.pop(next(iter(self._step_cache)))
        return solver

    def __repr__(self):
        return (f"SparseCompletion(n={self.n}, k={self.k}, lam={self.lam:g}, constraints={self.n_constraints}, "
                f"{self.structure.describe()})")


_STEP_CACHE = 4


class _StepSolver:
    """``(I - c G)^-1`` (``c > 0``) through the set-up's Schur factorization and one sparse LU of the pencil
    ``A + c B`` (rows scaled).

    With ``v = (k - r) / c`` in the least-squares conditions
    ``H v_d + C_c^T mu = -W B_d k`` (``W = E^T R_d^2``, ``H = W E``) and
    ``C v = -lam C k``: a row ``i`` of level >= 1 is ``C_i = -C_p^d E^-1 B_d``
    (``p`` its parent), so ``C_i k = -lam C_p k + S_p mu`` with ``S = C_c H^-1 C_c^T``,
    and every constraint row gives ``(1 + c lam) C_i k = C_i r``. Hence

        S mu = m,   m_p = (C_i r + lam C_p r) / (1 + c lam)      (one row per parent)

        [E + c B_dd   c B_da] [k_d]   [E r_d - c W^-1 C_c^T mu   ]
        [B_ad         B_aa  ] [k_a] = [B_a r / (1 + c lam)       ]

    The second matrix is ``A + c B`` with its algebraic rows divided by
    ``c``: the DAE's own sparsity (for Stokes the implicit-Euler saddle
    point ``[[I - c L, c A12], [A12^T, 0]]``).
    """

    def __init__(self, comp, c):
        s = comp.structure
        self.comp, self.c = comp, c
        B_a = rows(comp.dae.B_sparse, s.alg_rows)
        P = scipy.sparse.bmat([[s.E + c * cols(s.B_d, s.diff_cols), c * cols(s.B_d, s.alg_cols)],
                               [cols(B_a, s.diff_cols), cols(B_a, s.alg_cols)]], format="csc")
        self.size = P.shape[0]
        self.lu = factorize(P, f"A + c B at c = {c:g} (the implicit step's matrix)")
        self.nnz = self.lu.nnz
        child = np.flatnonzero(s.parent >= 0)
        self._child, self._parent_pos = child, np.searchsorted(comp._cont, s.parent[child])

    def solve(self, r):
        comp, s, c = self.comp, self.comp.structure, self.c
        scale = 1.0 + c * comp.lam
        Cr = s.C @ r
        r_d, _ = comp._split(r)
        rhs_d = s.E @ r_d
        if comp._cont.size:
            m = np.empty(comp._cont.size)
            m[self._parent_pos] = (Cr[self._child] + comp.lam * Cr[s.parent[self._child]]) / scale
            rhs_d = rhs_d - c * self._times_W_inverse(comp._C_cT @ self._mu(m))
        sol = self.lu.solve(np.concatenate([rhs_d, Cr[: s.alg_rows.size] / scale]))
        nd = s.diff_cols.size
        return comp._join(sol[:nd], sol[nd:])

    def _mu(self, m):
        """``mu = S^-1 m`` (``S = C_c H^-1 C_c^T``), through the Schur factorization or the saddle-point one."""
        if self.comp._schur is not None:
            return self.comp._schur.solve(m)
        sol = self.comp._kkt.solve(np.concatenate([np.zeros(self.comp.structure.diff_cols.size), m]))
        return -sol[self.comp.structure.diff_cols.size:]

    def _times_W_inverse(self, v):
        if self.comp._w_diag is not None:
            return v / self.comp._w_diag
        # W^-1 = R_d^-2 E^-T
        return self.comp.structure.E_solver.solve(v, trans="T") / self.comp._W_weights


class SparseMaps:
    """A sparse completion's maps at one time: ``G`` (LinearOperator), ``g``, constraint rows ``C``, ``cg``."""

    def __init__(self, G, g, C, cg):
        self.G, self.g, self.C, self.cg = G, g, C, cg


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
