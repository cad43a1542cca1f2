"""Structured set-up of a constant-coefficient completion: n-sized blocks, no derivative-array SVD.

For constant ``A, B`` the standard derivative array with ``k`` differentiations
is block lower bidiagonal (``A`` on the diagonal, ``B`` below). Everything a
completion needs from it is

- ``Z2``: an orthonormal basis of its left null space, and
- ``P``: the first ``n`` rows of ``J^+``.

If ``X`` is any matrix with ``X J = [I, 0, ..., 0]`` (it exists when ``J`` is
1-full), then ``P = X (I - Z2 Z2^T)``: for ``r`` in the range of ``J`` every
solution of ``J w = r`` has the same ``x'`` block, and ``J^+`` first projects
onto that range. Both ``X`` and ``Z2`` follow from the pencil:

1. A shift ``mu`` with ``B_mu = B + mu A`` well conditioned (LU). ``B_mu`` is
   ``B`` of the equation for ``y = exp(-mu t) x``, whose derivative array is
   ``(Lam kron I)`` times the one for ``x`` (rows) and a unit block-triangular
   change of the unknowns whose first block row is ``[I, 0, ...]``. So
   ``Z2 = orth((Lam^T kron I) Z2_y)`` and ``X = X_y (Lam kron I)``, with ``Lam``
   the ``stabilization_jets`` of the constant rate ``-mu``.
2. ``Mt = B_mu^-T A^T``. Its generalized null space (the left one of ``M``)
   is found level by level: level 1 is null(A^T), from a pivoted QR of
   ``A`` (the rank the dense path decides first, k = 0); level ``j + 1`` is
   ``{z : Mt z in N_j}``, decided on a small matrix (``Wl^T N_j``, ``Wl`` an
   orthonormal basis of range(Mt)^perp) and solved with one bordered LU of
   ``[[Mt, Wl], [N1^T, 0]]``. The number of levels is the index ``nu``;
   ``U_S`` (orthonormal, ``a`` columns) spans the space, ``X_SS = U_S^T Mt U_S``
   is nilpotent.
3. For the shifted array (``B_mu`` invertible) ``z_{j+1} = -Mt z_j``, so the
   left null space is spanned by the blocks ``U_S (-X_SS)^j``, ``j = 0..k``;
   and ``X_y`` has the blocks ``Y_0^T, ..., Y_k^T`` with
   ``Mt Y_0 = B_mu^-T - U_S Psi`` and ``Y_j = U_S (-X_SS)^(j-1) Psi``.

Cost: LUs of ``B_mu`` and of two bordered (n + a) matrices, one pivoted
QR of ``A``, solves and products of n-sized blocks; nothing of size
``((k+1) n)^2`` is formed. Rank decisions use ``rcond`` (default: the dense
path's default for the array of that level) relative to the largest pivot
of ``A`` or, on the small level matrices, to 1 (they hold cosines between
orthonormal bases). A decision within a factor ``RANK_MARGIN`` (100, the margin
of `RankDecisionWarning`) of the threshold, no shift that makes ``B + mu A``
well conditioned (singular or nearly singular pencils), k below the index
or an index-one system that is not clearly invertible is not decided here;
nor is what the dense arrays decide differently from the staircase: an
``rcond`` at rounding level, a rank of A that holds against ``||A||`` but
not against ``||B||``, ``||A||`` and ``||B||`` far apart (`_check_balance`)
and bases that miss the dense threshold (`_check_residuals`).
`lsc._factors.Decline` says why and the caller uses the dense path, which
decides, warns or refuses as it always does.
"""

from math import comb

import numpy as np
import scipy.linalg
from scipy.linalg import lapack

from ._derivative_array import stabilization_jets
from ._factors import Decline, Factors
from ._linalg import RANK_MARGIN, TRIAL_SHIFTS, close_call, default_rcond

__all__ = ["StructuredArray", "StructuredFactors", "structured_array"]

# B_mu is accepted when its reciprocal condition number (1-norm estimate) exceeds this.
_SHIFT_RCOND = 1e-6
_EPS = float(np.finfo(float).eps)


def _shift(A, B):
    """``(mu, lu)`` with ``B + mu A`` well conditioned, or `Decline`."""
    nA, nB = np.linalg.norm(A, 1), np.linalg.norm(B, 1)
    scale = (nB or 1.0) / (nA or 1.0)
    worst = None
    for s in TRIAL_SHIFTS:
        mu = s * scale
        Bm = B + mu * A
        lu, piv, info = lapack.dgetrf(Bm)
        if info == 0:
            rc, _ = lapack.dgecon(lu, np.linalg.norm(Bm, 1))
            if rc > _SHIFT_RCOND:
                return mu, (lu, piv)
            worst = rc
        else:
            worst = 0.0
    raise Decline(
        f"B + mu A is ill conditioned at every trial shift (reciprocal condition {worst:.1e}): the pencil is "
        "singular or nearly so"
    )


def _default_rcond(n, level):
    """The dense path's default for the array with `level` differentiations, ``[J, F]`` of shape (level+1) n x (level+2) n."""
    return default_rcond(((level + 1) * n, (level + 2) * n))


def _count_above(values, tol, what):
    """How many of `values` exceed `tol`; a close call (`lsc._linalg.close_call`) is left to the dense path."""
    if close_call(values, tol):
        raise Decline(f"the rank decision on {what} is a close call (within {RANK_MARGIN:g} of the threshold)")
    return int(np.count_nonzero(values > tol))


def _orth(X):
    return np.linalg.qr(X)[0] if X.shape[1] else X


def _solve_bordered(M, P, Q):
    """LU of the bordered matrix ``[[M, P], [Q^T, 0]]``."""
    a = P.shape[1]
    K = np.block([[M, P], [Q.T, np.zeros((a, a))]])
    return scipy.linalg.lu_factor(K, check_finite=False)


def _generalized_null_space(A, Bm, Mt, rcond, kmax, norm_B):
    """``(U_S, sizes, N1, Nr, Wl, lu)``: the generalized null space of ``Mt = B_mu^-T A^T``, left and right
    null(A), range(Mt)^perp (all orthonormal bases) and the LU of ``[[Mt, Wl], [N1^T, 0]]``.

    ``U_S`` is ordered by level: its first ``sizes[0]`` columns span level 1, the next ``sizes[1]`` complete
    level 2, and so on (``len(sizes)`` is the index), so ``U_S^T Mt U_S`` is block strictly upper triangular.

    Level 1 is null(Mt) = null(A^T), decided by a pivoted QR of ``A`` itself (the rank the dense path decides
    first, with the same threshold). Level j + 1 is ``{z : Mt z in N_j}``: ``Mt z = N_j c`` needs ``N_j c`` in
    range(Mt), i.e. ``c`` in the null space of ``Wl^T N_j`` (``Wl`` spans range(Mt)^perp = B_mu null(A)), a
    small matrix of cosines; ``z`` is then one solve with a bordered matrix factorized once.
    """
    n = A.shape[0]
    (qr, tau), R, piv = scipy.linalg.qr(A, mode="raw", pivoting=True)  # Q stays in Householder form
    d = np.abs(np.diag(R))
    if d.size == 0 or d[0] == 0.0:
        raise Decline("A is zero")
    tol0 = rcond if rcond is not None else _default_rcond(n, 0)
    r = _count_above(d / d[0], tol0, "A (k=0)")
    # From k = 1 on the dense arrays hold B too and decide A's rank against their largest singular value
    # (at least ||B||): a rank that only holds against ||A|| itself is not theirs.
    scale_J = max(d[0], norm_B)
    if _count_above(d / scale_J, rcond if rcond is not None else _default_rcond(n, 1), "A against the array (k=1)") != r:
        raise Decline(
            f"A's rank depends on its scale: {r} against ||A|| = {d[0]:.1e}, less against the derivative array "
            f"(||B|| = {norm_B:.1e})"
        )
    if r == n:
        empty = np.zeros((n, 0))
        return empty, [], empty, empty, empty, scipy.linalg.lu_factor(Mt, check_finite=False)
    N1, _, info = lapack.dormqr("L", "N", qr, tau, np.eye(n, n - r, -r), max(1, 64 * (n - r)))
    Nr = np.zeros((n, n - r))
    Nr[piv[:r]] = -scipy.linalg.solve_triangular(R[:r, :r], R[:r, r:])
    Nr[piv[r:]] = np.eye(n - r)
    Nr = _orth(Nr)
    Wl = _orth(Bm @ Nr)
    lu = _solve_bordered(Mt, Wl, N1)
    N, levels, U, sizes = N1, 1, N1, [N1.shape[1]]
    while True:
        if levels > kmax:
            raise Decline(f"the index exceeds kmax={kmax}")
        H = Wl.T @ N
        _, sv, Vh = np.linalg.svd(H)
        tol = rcond if rcond is not None else _default_rcond(n, levels)
        sv = np.concatenate([sv, np.zeros(N.shape[1] - sv.size)])
        rank = _count_above(sv, tol, f"level {levels + 1} of the staircase")
        c = Vh[rank:].T
        if N1.shape[1] + c.shape[1] == N.shape[1]:
            return U, sizes, N1, Nr, Wl, lu
        V = np.vstack([N @ c, np.zeros((N1.shape[1], c.shape[1]))])
        Z = scipy.linalg.lu_solve(lu, V, check_finite=False)[:n]
        N = _orth(np.hstack([N1, Z]))
        # the part of level j + 1 orthogonal to level j: new columns of the level-ordered basis
        grow = N.shape[1] - U.shape[1]
        new = np.linalg.svd(N - U @ (U.T @ N), full_matrices=False)[0][:, :grow]
        U = np.hstack([U, new])
        sizes.append(grow)
        levels += 1


def _lam(k, c):
    """``Lam[i, j] = C(i, j) c^(i - j)``: ``(d/dt + c)^i`` in terms of ``d^j/dt^j``."""
    Lam = np.zeros((k + 1, k + 1))
    for i in range(k + 1):
        for j in range(i + 1):
            Lam[i, j] = comb(i, j) * c ** (i - j)
    return Lam


class StructuredArray:
    """What a completion needs from the standard derivative array, found from n-sized blocks.

    Attributes
    ----------
    index : int
        The differentiation index (number of staircase levels).
    k : int
    n, a : int
        Unknowns and constraints (corank of J).
    Z2 : ndarray, shape ((k+1) n, a)
        Orthonormal basis of the left null space of J.
    first_rows : ndarray, shape (n, (k+1) n)
        The first n rows of ``J^+``.
    shift : float
        The shift ``mu`` used.
    """

    def __init__(self, index, k, n, Z2, first_rows, shift):
        self.index, self.k, self.n, self.Z2, self.first_rows, self.shift = index, k, n, Z2, first_rows, shift
        self.a = Z2.shape[1]


def _norm2(M, steps=12):
    """A lower estimate of ``||M||_2`` (power iteration from a fixed start; exact to a few % in practice)."""
    x = np.ones(M.shape[1]) + np.linspace(0.0, 1.0, M.shape[1])
    norm = 0.0
    for _ in range(steps):
        x /= np.linalg.norm(x)
        y = M @ x
        norm = max(norm, np.linalg.norm(y))
        x = M.T @ y
        if not np.any(x):
            break
    return norm


def _check_balance(norm_A, norm_B, k, n, rcond):
    """Decline when ``||A||`` and ``||B||`` are so far apart that the dense arrays' decisions depend on the ratio.

    The array of ``(s A, B)`` with k differentiations is ``diag(s^-i) J(A, B) diag(s^(j+1))``: its singular
    values move by up to ``s^(2k)`` while the staircase (cosines of bases, invariant under ``s``) does not,
    so the dense path decides a different index (small ``A``), refuses (large ``A``) or, for k above the
    index, computes a different G where the structured one would not. Measured on random pencils of index
    1..6 (cond 10, ``s`` from 1e-4 to 1e4, n = 12): the dense decisions changed only where
    ``m^(k + 2)``, ``m = max(||A||/||B||, ||B||/||A||)``, exceeded about ``1 / rcond``; this declines from
    ``m^max(2k, k + 2) = 1 / (rcond RANK_MARGIN^2)`` on.
    """
    tol = rcond if rcond is not None else _default_rcond(n, k)
    rho = norm_A / norm_B if norm_B else np.inf
    spread = max(rho, 1.0 / rho) if rho else np.inf
    power = max(2 * k, k + 2)
    if k and spread**power * tol * RANK_MARGIN**2 > 1.0:
        raise Decline(
            f"||A|| / ||B|| = {rho:.1e}: with k = {k} the dense arrays' rank decisions depend on that ratio "
            f"(its power {power} or that of its inverse reaches 1 / (rcond {RANK_MARGIN:g}^2), rcond = {tol:.1e})"
        )


def _pencil_reduction(A, B, rcond, kmax, k=None):
    """Shift, ``Mt = B_mu^-T A^T``, its generalized null space and ``(||A||, ||B||)`` (k: the differentiations
    that will be used, None for the index)."""
    n = A.shape[0]
    if rcond is not None and rcond < RANK_MARGIN * n * _EPS:
        raise Decline(
            f"rcond={rcond:.1e} is below the rounding level of n-sized blocks ({RANK_MARGIN * n * _EPS:.1e}): "
            "pivots there cannot be told from zero"
        )
    mu, lu = _shift(A, B)
    Mt = scipy.linalg.lu_solve(lu, A.T, trans=1)
    if not np.all(np.isfinite(Mt)):
        raise Decline("B_mu^-1 A overflows: A and B are too far apart in scale for n-sized blocks")
    norms = _norm2(A), _norm2(B)
    U_S, sizes, N1, Nr, Wl, lu_Mt = _generalized_null_space(A, B + mu * A, Mt, rcond, kmax, norms[1])
    _check_balance(*norms, len(sizes) if k is None else max(k, len(sizes)), n, rcond)
    return mu, lu, Mt, U_S, sizes, N1, Nr, Wl, lu_Mt, norms


def structured_index(A, B, rcond=None, kmax=10):
    """The differentiation index of a regular constant pencil (`Decline` when not clear-cut)."""
    return len(_pencil_reduction(np.asarray(A, float), np.asarray(B, float), rcond, kmax)[4])


def _check_residuals(A, B, Z2, P, k, norms, rcond):
    """Decline unless ``Z2^T J`` and ``P J - [I, 0, ...]`` are small against the dense threshold.

    The dense SVD keeps both at rounding level; a structured basis further from the array's null space than
    `RANK_MARGIN` below the rank threshold would be a basis the dense path does not compute (its completions then
    differ beyond rounding). Blockwise, ``J``'s block column m is ``A`` (row m) over ``B`` (row m + 1).
    """
    n, a = A.shape[0], Z2.shape[1]
    tol = (rcond if rcond is not None else _default_rcond(n, k)) / RANK_MARGIN
    scale = max(norms)  # <= ||J||_2
    Zb = Z2.reshape(k + 1, n, a)
    R = np.matmul(A.T, Zb)
    R[:-1] += np.matmul(B.T, Zb[1:])
    res = np.sqrt(np.einsum("mia,mia->", R, R)) / scale if a else 0.0
    if res > tol:
        raise Decline(
            f"the structured null space is not the dense one at its threshold: ||Z2^T J|| = {res:.1e} ||J|| "
            f"(rcond / {RANK_MARGIN:g} = {tol:.1e})"
        )
    v = np.cos(np.arange((k + 1) * n * 2) * 0.7).reshape(k + 1, n, 2)  # fixed test vectors
    Jv = np.matmul(A, v)
    Jv[1:] += np.matmul(B, v[:-1])
    err = np.linalg.norm(P @ Jv.reshape(-1, 2) - v[0]) / (np.linalg.norm(P) * scale * np.linalg.norm(v))
    if err > tol:
        raise Decline(
            f"the structured first rows of J^+ do not invert J at the dense threshold: ||P J v - v_0|| = {err:.1e} "
            f"||P|| ||J|| ||v|| (rcond / {RANK_MARGIN:g} = {tol:.1e})"
        )


def structured_array(A, B, k=None, rcond=None, kmax=10):
    """The `StructuredArray` of ``A x' + B x = f`` with k (None: the index) differentiations.

    Raises `lsc._factors.Decline` when a rank decision is not clear-cut, no
    shift makes ``B + mu A`` well conditioned, or ``k`` is below the index
    (the dense path then refuses or decides).
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    n = A.shape[0]
    mu, lu, Mt, U_S, sizes, N1, Nr, Wl, lu_Mt, norms = _pencil_reduction(A, B, rcond, kmax, k)
    index = len(sizes)
    k = index if k is None else k
    if k < index:
        raise Decline(f"k={k} is below the index {index}")
    a = U_S.shape[1]
    Binv_T = scipy.linalg.lu_solve(lu, np.eye(n), trans=1)
    # Y_0 with Mt Y_0 = B_mu^-T - U_S Psi: Psi (least norm) puts the right side into range(Mt) = Wl^perp, then
    # the bordered LU of the staircase solves; Y_1 = B_mu^-T - Mt Y_0 = U_S Psi.
    Psi = np.linalg.lstsq(Wl.T @ U_S, Wl.T @ Binv_T, rcond=None)[0] if a else np.zeros((0, n))
    rhs = np.vstack([Binv_T - U_S @ Psi, np.zeros((Wl.shape[1], n))])
    del Binv_T
    sol = scipy.linalg.lu_solve(lu_Mt, rhs, check_finite=False)
    del rhs
    X_SS = U_S.T @ (Mt @ U_S)
    # Mt maps level j + 1 into levels <= j: in the level-ordered basis X_SS is block strictly upper triangular,
    # exactly nilpotent once the rounding below is dropped (U_S (-X_SS)^j = 0 from j = index on, as it must be)
    level = np.repeat(np.arange(len(sizes)), sizes)
    X_SS[level[:, None] >= level[None, :]] = 0.0
    Lam = _lam(k, -mu)
    # X = X_y (Lam kron I), block column j = sum_i Lam[i, j] Y_i^T, accumulated without stacking the Y_i
    X = np.zeros((n, k + 1, n))
    X += sol[:n].T[:, None, :] * Lam[0][None, :, None]
    Z = [U_S]
    step = np.eye(a)
    for i in range(1, k + 1):
        Yi_T = (step @ Psi).T @ U_S.T
        for j in range(i + 1):
            X[:, j] += Lam[i, j] * Yi_T
        step = step @ (-X_SS)
        Z.append(U_S @ step)
    X = X.reshape(n, (k + 1) * n)
    Zx = np.einsum("ji,jna->ina", Lam, np.stack(Z)).reshape((k + 1) * n, a)
    Z2 = _orth(Zx)
    XZ = X @ Z2
    for j in range(k + 1):  # first_rows = X (I - Z2 Z2^T), in place, one n x n block at a time
        X[:, j * n : (j + 1) * n] -= XZ @ Z2[j * n : (j + 1) * n].T
    first_rows = X
    _check_residuals(A, B, Z2, first_rows, k, norms, rcond)
    out = StructuredArray(index, k, n, Z2, first_rows, mu)
    out.null_A, out.left_null_A = Nr, N1
    return out


class StructuredFactors(Factors):
    """The standard derivative array's factors for constant ``A, B`` from a `StructuredArray` (one time, maps).

    The `lsc._factors.Factors` protocol without forming ``J``, ``F`` or the forcing map
    ``L = Lam kron I``: ``F = [B; 0; ...]`` and ``L`` act block by block, and the index-one system of the
    alternative completion is solved with a bordered LU (`index_one_solve`).
    """

    kind = "structured"

    def __init__(self, A, B, k, q, rcond, kmax=10):
        s = structured_array(A, B, k, rcond, kmax)
        n = s.n
        self.n, self.t, self.k, self.q, self.index, self.rcond = n, np.zeros(1), s.k, q, s.index, rcond
        self.rank = (s.k + 1) * n - s.a
        self.structured = s
        self.Z2, self.first_rows, self.shift = s.Z2[None], s.first_rows[None], s.shift
        self.A0, self.B0 = A[None], B[None]
        self._forcing(stabilization_jets(s.k, q, None), None)
        self.C = self.Z2[:, :n].transpose(0, 2, 1) @ B

    @property
    def rounding_scale(self):
        """``||B|| ||P||``, P the first rows of ``J^+``: what ``G`` is computed from (the dense factors'
        ``||F|| / sigma_min(J)`` without an SVD of ``J``)."""
        return np.linalg.norm(self.B0[0], 2) * np.linalg.norm(self.first_rows[0], 2)

    def times_F(self, X, d):
        """``X @ F^(d)`` with ``F = [B; 0; ...]`` (constant, so ``F' = 0``)."""
        if d:
            return np.zeros(X.shape[:2] + (self.n,))
        return X[..., : self.n] @ self.B0

    def index_one_solve(self, G_c, W_c, rcond):
        """``(G, W, ok)`` of the alternative completion from its constraint rows ``C x' = G_c x + W_c``.

        The dense path solves ``[Z1^T A; C] x' = [-Z1^T B x + Z1^T f; ...]`` with ``Z1`` an orthonormal
        basis of range(A T2). Equivalently, with ``Ws`` one of its orthogonal complement (dimension a),
        ``A x' + Ws m = f - B x``, ``C x' = ...`` (``m`` absorbs the part of the equations ``Z1^T`` drops): one
        LU of a bordered (n + a) matrix, no SVD. ``Ws`` = {u : A^T u in range(C^T)}: ``A^T u = C^T b``
        with ``b`` in null((null A)^T C^T), solved with A^T bordered by its null spaces.
        """
        n, A, C = self.n, self.A0[0], self.C[0]
        s = self.structured
        Nr, N1 = s.null_A, s.left_null_A
        a1 = N1.shape[1]
        if a1:
            _, sv, Vh = np.linalg.svd(Nr.T @ C.T)
            sv = np.concatenate([sv, np.zeros(C.shape[0] - sv.size)])
            rank = _count_above(sv / max(sv[0], 1.0), rcond if rcond is not None else default_rcond(C.shape), "A T2")
            beta = Vh[rank:].T
            lu = _solve_bordered(A.T, Nr, N1)
            U = scipy.linalg.lu_solve(lu, np.vstack([C.T @ beta, np.zeros((a1, beta.shape[1]))]), check_finite=False)[:n]
            Ws = _orth(np.hstack([N1, U]))
        else:
            Ws = np.zeros((n, 0))
        if Ws.shape[1] != C.shape[0]:
            raise Decline(f"A T2 does not have corank {C.shape[0]}")
        K = np.block([[A, Ws], [C, np.zeros((C.shape[0], Ws.shape[1]))]])
        lu, piv, info = lapack.dgetrf(K)
        rc, _ = lapack.dgecon(lu, np.linalg.norm(K, 1))
        tol = rcond if rcond is not None else default_rcond(K.shape)
        if info != 0 or not rc / K.shape[0] > tol * RANK_MARGIN:
            raise Decline("the index-one system [A, Ws; C, 0] is not clearly invertible")
        S = scipy.linalg.lu_solve((lu, piv), np.eye(K.shape[0]), check_finite=False)[:n]
        S11, S12 = S[:, :n], S[:, n:]
        G = -S11 @ self.B0 + S12 @ G_c
        W = S12 @ W_c
        W[..., :n] += S11  # f0 = [I, 0, ...]
        return G, W, np.ones(G.shape[0], dtype=bool)
