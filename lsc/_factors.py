"""The standard derivative array's factors: one protocol, the backends behind it, and how fast paths fall back.

Every completion is computed from a few quantities of the standard derivative array ``J w = -F x + g``
(`lsc._derivative_array`): the constraints ``c = Z2^T (F x - g)`` (``Z2`` an orthonormal basis of the left
null space of ``J``), the first ``n`` rows of ``J^+`` and products with ``F``, its time derivative and the
forcing map. `Factors` states what a backend provides; the three completions' maps (`lsc._methods`) use
nothing else, so they are written once, for every backend and for any number of times at once (a leading
axis ``m`` on every array; one time is ``m = 1``).

Backends (each a `Factors`):

- `lsc._structured.StructuredFactors`: constant coefficients, from n-sized blocks of the pencil;
- `lsc._dense_factors.DenseFactors`: the SVD of ``J`` at one time or at many times stacked; at one time of
  a time-varying array of 100 rows or more, a LU warm-started from the last time factorized, or the
  block-column QR of `lsc._structured_tv` when asked.

`lsc._setup` chooses among them, in that one place, and records why (`Completion.setup`,
`Completion.setup_note`).

Fast paths and their fallbacks (the protocol of every "try the fast path, else fall back" in lsc): a fast
path returns what the path below it would (the same rank decisions, the same completion to rounding) or it
declines; it never warns or refuses itself. At one time it declines by raising `Decline` with the reason; at
many times it leaves the times it cannot decide out. The caller then takes the path below. The last path,
the SVD of ``J`` at one time, decides, warns (`RankDecisionWarning`) or refuses (`IndexDeterminationError`),
and every decision within `lsc._linalg.RANK_MARGIN` of its threshold is left to it. The chains:

1. constant coefficients, at construction: structured set-up -> SVD (`setup_note` says why it declined);
2. a time-varying array at one time: block-column QR (``Completion.block_qr``) -> LU warm-started from the
   last time factorized (``Completion.warm_start``) -> SVD;
3. many times at once (an interpolant's points, `Completion.maps`): the SVDs stacked -> chain 2 at each time
   left out;
4. integration (`lsc.solve_completion`): Chebyshev interpolants of ``G(t)``, ``g(t)`` -> pointwise
   evaluation on the pieces they cannot resolve (`lsc._chebyshev`) -> where the completion cannot be
   evaluated clearly, the run ends before that time with the trajectory computed (`lsc._singular`).
"""

import numpy as np

from ._exceptions import IndexDeterminationError
from ._linalg import numerical_rank, ranks_many
from ._maps import pinv_rows

__all__ = ["Decline", "Factors"]


class Decline(Exception):
    """A fast path cannot decide this problem as safely as the path below it (the message says why)."""


def swap(X):
    """The transpose of the last two axes (of every matrix of a stack)."""
    return np.swapaxes(X, -1, -2)


class Factors:
    """The standard derivative array of a DAE factorized at ``m`` times: what a backend provides.

    The numbered contract (every array has the leading axis ``m``; ``N = (k + 1) n``):

    1. ``n``, ``k``, ``q`` (time derivatives of the array held beyond ``J`` itself: the alternative
       completion needs ``q = 1``), ``t`` (shape (m,)), ``rank`` of ``J`` (the same at every time),
       ``strict`` (True: a rank decision that fails raises; False: the time is marked and left out) and
       ``kind`` (the backend's name).
    2. ``C``, shape (m, a, n): the constraint rows ``Z2^T F``; ``A0``, ``B0``: the coefficients.
    3. The forcing, as values or as a map: `fstack` None makes every forcing quantity a map acting on the
       jet ``[f; f'; ...; f^(k+q)]`` (``w = (k + q + 1) n`` columns), an array (m, k + q + 1, n) of those
       jets makes it values (``w = 1``). This base class provides, from ``Lam`` (`stabilization_jets`),
       ``times_L(X, d)`` (``X`` of shape (m, r, N) times the d-th derivative of the forcing map: (m, r, w)),
       ``f0`` (``f`` itself, broadcastable to (m, n, w)) and ``cg = times_L(Z2^T, 0)``.
    4. ``times_F(X, d)``: ``X F^(d)``, shape (m, r, n), for ``d <= q``.
    5. ``constraint_rows(d)``: ``(Z2^T F^(d), Z2^T L^(d))``, the constraints differentiated with the basis
       held fixed (this base class forms them from ``Z2``).
    6. ``basis_drift()``: ``(Y F, Y L)`` with ``Y = Z2^T J' J^+``, what the basis's own motion adds to
       ``(Z2^T)' (F x - g)``, or None where ``J' = 0`` (this base class: None).
    7. ``index_one_solve(G_c, W_c, rcond)``: ``(G, W, ok)`` of ``[Z1^T A; C] x' = [Z1^T (f - B x);
       G_c x + W_c]`` (``Z1`` spans ``range(A T2)``, ``T2`` the null space of ``C``); ``ok`` (m,) marks the
       times decided (this base class: dense SVDs at every time). At one time, ``G_c`` and ``W_c`` may hold
       several right-hand sides along the leading axis (the maps at several rates): the result does too.

    Dense capability, optional: ``Z2`` (m, N, a) and ``first_rows`` (m, n, N), the first ``n`` rows of
    ``J^+``. The standard and stabilized completions need them; the alternative one needs only 1-7, so a
    backend that applies operators without forming these (a sparse one) can serve it. The index-one solve
    (7) is linear in its right-hand side's columns: the ``n`` columns of ``G_c`` give ``G`` (`Completion.maps`),
    the one column ``G_c x + W_c`` gives ``x'`` itself (`Completion.rhs`), so a matrix-free backend solves for
    the columns it is asked for and need not form an ``n x n`` matrix.

    This base class also derives, from ``C``, ``n_constraints`` and, at one time, ``T2`` and ``C_pinv``.
    """

    kind = None
    strict = True
    q = 0
    fstack = None

    def _forcing(self, Lam, fstack):
        """Set the forcing (item 3) from `Lam` and the jets `fstack` (None: maps)."""
        self.Lam, self.fstack = Lam, fstack
        self._C_svd = self._cg = None
        if fstack is not None:
            m, N = fstack.shape[0], (self.k + 1) * self.n
            self._Lg = np.einsum("dij,mjn->mdin", Lam, fstack).reshape(m, self.q + 1, N)

    @property
    def n_constraints(self):
        return self.C.shape[1]

    @property
    def f0(self):
        if self.fstack is None:
            return np.eye(self.n, (self.k + self.q + 1) * self.n)[None]
        return self.fstack[:, 0, :, None]

    @property
    def cg(self):
        if self._cg is None:
            self._cg = self.times_L(swap(self.Z2), 0)
        return self._cg

    def times_L(self, X, d):
        if self.fstack is not None:
            return X @ self._Lg[:, d, :, None]
        m, r = X.shape[:2]
        out = np.einsum("ij,mric->mrjc", self.Lam[d], X.reshape(m, r, self.k + 1, self.n))
        return out.reshape(m, r, out.shape[2] * self.n)  # explicit: r = 0 (no constraints) cannot infer -1

    def constraint_rows(self, d):
        if d == 0:
            return self.C, self.cg
        Z2t = swap(self.Z2)
        return self.times_F(Z2t, d), self.times_L(Z2t, d)

    def basis_drift(self):
        return None

    # -- the constraint matrix's SVD: T2, C_pinv and the index-one system --------------------------------
    def scale_columns(self, c):
        """``C`` in the unknowns ``x = diag(c) y`` of a column-equilibrated DAE (`lsc._problem.balance`) given back
        in ``x``: ``C_y y = C_y diag(c)^-1 x``."""
        self.C = self.C / c
        self._C_svd = None

    def _constraint_svd(self):
        """``(Uc, sc, Vct, ok)`` of ``C`` at every time; dependent constraints ([J, F] not of full row rank) are
        refused (strict) or marked."""
        if self._C_svd is None:
            a = self.n_constraints
            Uc, sc, Vct = np.linalg.svd(self.C)
            if self.strict:
                for i, t in enumerate(self.t.tolist()):
                    rank_C = numerical_rank(sc[i], self.C.shape[1:], None, what="constraint matrix Z2^T F")
                    if rank_C != a:
                        raise IndexDeterminationError(
                            f"the constraints Z2^T F x = Z2^T g are dependent (rank {rank_C} < {a}) at t={t!r}: "
                            "[J, F] does not have full row rank, so the DAE is not solvable.")
                ok = np.ones(len(self.t), dtype=bool)
            else:
                ok = ranks_many(sc, self.C.shape[1:], None) == a
            self._C_svd = Uc, sc, Vct, ok
        return self._C_svd

    @property
    def T2(self):
        """Orthonormal bases of the homogeneous manifolds ``{x : C x = 0}`` (thesis T2), shape (m, n, n - a)."""
        Uc, sc, Vct, _ = self._constraint_svd()
        return swap(Vct[:, sc.shape[1]:])

    @property
    def C_pinv(self):
        """Pseudo-inverses of ``C``, shape (m, n, a)."""
        return pinv_rows(self.C, self._constraint_svd()[:3])

    def index_one_solve(self, G_c, W_c, rcond):
        n, A = self.n, self.A0
        ok = self._constraint_svd()[3].copy()
        AT2 = A @ self.T2
        Z1, s1, _ = np.linalg.svd(AT2, full_matrices=False)
        if self.strict:
            for i, t in enumerate(self.t.tolist()):
                if numerical_rank(s1[i], AT2.shape[1:], rcond, what="A T2") < AT2.shape[2]:
                    raise IndexDeterminationError(f"A T2 is rank deficient at t={t!r}: the DAE is not solvable.")
        else:
            ok &= ranks_many(s1, AT2.shape[1:], rcond) == AT2.shape[2]
        Z1t = swap(Z1)
        M = np.concatenate([Z1t @ A, self.C], axis=1)
        top_G, top_W = -(Z1t @ self.B0), Z1t @ self.f0
        blocks = [top_G, G_c, top_W, W_c]
        if G_c.shape[0] != top_G.shape[0]:  # one time, several rates (`Completion.lam_affine`): broadcast
            lead = (max(G_c.shape[0], top_G.shape[0]),)
            blocks = [np.broadcast_to(X, lead + X.shape[1:]) for X in blocks]
            ok = np.broadcast_to(ok, lead)
        # one LU for both right-hand sides, at the times decided
        rhs = np.concatenate([np.concatenate(blocks[:2], axis=1), np.concatenate(blocks[2:], axis=1)], axis=2)
        if np.all(ok):
            sol = np.linalg.solve(M, rhs)
        else:
            sol = np.full(rhs.shape, np.nan)
            if np.any(ok):
                sol[ok] = np.linalg.solve(M[ok], rhs[ok])
        return sol[..., :n], sol[..., n:], ok
