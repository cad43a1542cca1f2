"""A time-varying completion's ``G(t)``, ``g(t)`` at many times at once, its linear algebra stacked.

An interpolant's set-up (`lsc._chebyshev`) knows all the times of a level
in advance. For derivative arrays of a few dozen rows, evaluating the
completion at one time costs far more in Python and per-call LAPACK
overhead than in arithmetic; here the coefficients' jets are taken time by
time (they are the user's callables), and the SVDs, products and solves of
all times are done on stacked ``(m, rows, cols)`` arrays, by the same
formulas as `lsc._dense_factors._Factors` and the completions' ``_maps``.

Every rank decision is the per-time one: `numerical_rank` on each time's
singular values. A time whose rank is not the completion's, whose decision
is a close call (a warning), which is not 1-full, or whose coefficients
raise, is left out (None): the caller evaluates it by the per-time path,
which decides, warns or refuses exactly as it always does. Column
equilibration and arrays of `WARM_MIN_ROWS` rows or more (factored by a
warm-started LU) take the per-time path entirely.
"""

import numpy as np
import scipy.linalg

from ._dense_factors import _ONE_FULL_TOL, WARM_MIN_ROWS, _norm2_if_above
from ._derivative_array import stabilization_jets, stacked_arrays
from ._linalg import _MARGIN, default_rcond

__all__ = []


def _t(X):
    return np.swapaxes(X, -1, -2)


def _ranks(s, shape, rcond):
    """`numerical_rank` of each row of singular values `s` (m, p); -1 where it would warn (a close call).

    The same threshold ``rcond * s[0]`` and close-call test, for all times at once: a time marked -1 is
    left to the per-time path, which decides and warns.
    """
    if s.shape[1] == 0:
        return np.zeros(s.shape[0], dtype=int)
    rcond = default_rcond(shape) if rcond is None else rcond
    tol = rcond * s[:, :1]
    ranks = np.count_nonzero(s > tol, axis=1)
    close = np.any((s > tol / _MARGIN) & (s < tol * _MARGIN), axis=1) | (s[:, 0] == 0.0)
    return np.where(close, -1, ranks)


def batchable(completion):
    """Whether `matrices_many` may stack `completion`'s evaluations."""
    n = completion.n
    # a subclass's own `_maps` is evaluated as it is written, never replaced by the built-in stacked formulas
    return (getattr(completion, "_stacked_maps", None) is not None and completion._builtin_maps()
            and not completion.dae.is_constant
            and completion._col_scales is None and completion._rank is not None
            and 0 < completion._rank < (completion.k + 1) * n < WARM_MIN_ROWS)


def matrices_many(completion, ts):
    """``[(G, g) or None for t in ts]``; None where the per-time path must evaluate (and decide)."""
    out = [None] * len(ts)
    if not batchable(completion) or len(ts) < 2:
        return out
    eq, k, q, n, rcond = completion._eq, completion.k, completion.extra_order, completion.n, completion.rcond
    N, r = (k + 1) * n, completion._rank
    order = k + q
    kept, fstacks, A, B = [], [], [], []
    for i, t in enumerate(ts):
        try:  # in the per-time path's order: the forcing's jet, then the coefficients'
            fstack = eq.f_jet(t, completion._order).reshape(-1, n)
            Aj, Bj = eq.A.jet(t, order), eq.B.jet(t, order)
        except Exception:  # noqa: BLE001 - the per-time path raises it, with its message
            continue
        kept.append(i)
        fstacks.append(fstack)
        A.append(Aj)
        B.append(Bj)
    if len(kept) < 2:
        return out
    J, F = stacked_arrays(np.array(A), np.array(B), k, q)
    U, s, Vt = np.linalg.svd(J[:, 0])
    ok = _ranks(s, (N, N), rcond) == r
    if r < N:  # 1-fullness: the null space of J must not move x' (as `_Factors._svd`)
        ok &= [_norm2_if_above(Vt[j, r:, :n], _ONE_FULL_TOL) <= _ONE_FULL_TOL for j in range(len(kept))]
    good = np.nonzero(ok)[0]
    if len(good) < 2:
        return out
    fs = np.array(fstacks)[good]  # (m, k + q + 1, n)
    Lam = stabilization_jets(k, q, None)
    Lg = np.einsum("dij,mjn->mdin", Lam, fs).reshape(len(good), q + 1, N)
    st = _Stack(n, r, U[good], s[good], Vt[good], J[good], F[good], Lg, fs[:, 0])
    times = [ts[kept[j]] for j in good]
    try:
        res = completion._stacked_maps(st, times)
    except (np.linalg.LinAlgError, ValueError):  # the per-time path decides, and says why
        return out
    sigma = completion._sigma  # the equilibrated DAE's unit of time (lsc._problem.balance): G, g per unit of t
    for j, G, g in zip(good, *res) if res is not None else ():
        if G is not None:
            out[kept[j]] = (G, g) if sigma == 1.0 else (G / sigma, g / sigma)
    return out


class _Stack:
    """What `_Factors` provides, for m times at once (the SVD path; rank `r` at every time)."""

    def __init__(self, n, r, U, s, Vt, J, F, Lg, f0):
        self.n, self.r, self.U, self.s, self.Vt, self.J, self.F, self.Lg, self.f0 = n, r, U, s, Vt, J, F, Lg, f0
        self.Z2 = U[:, :, r:]
        self.A0, self.B0 = J[:, 0, :n, :n], F[:, 0, :n]
        self.C = _t(self.Z2) @ F[:, 0]
        self.cg = (_t(self.Z2) @ Lg[:, 0, :, None])[..., 0]

    @property
    def first_rows(self):
        r, n = self.r, self.n
        return (_t(self.Vt[:, :r, :n]) / self.s[:, None, :r]) @ _t(self.U[:, :, :r])

    def times_pinv(self, X):
        r = self.r
        return ((X @ _t(self.Vt[:, :r])) / self.s[:, None, :r]) @ _t(self.U[:, :, :r])


def standard_maps(st):
    """The standard completion's ``(G, g)`` at every time of `st`."""
    P = st.first_rows
    return -(P @ st.F[:, 0]), (P @ st.Lg[:, 0, :, None])[..., 0]


def stabilized_maps(st, Lams):
    """The stabilized completion's ``(G, g)``: the standard one plus ``K c`` (`StabilizedCompletion._maps`).

    `Lams`: ``stabilization_jets(k, 0, lam jet)[0]`` at each time (unit lower triangular).
    """
    G, g = standard_maps(st)
    m, (N, a), n = len(Lams), st.Z2.shape[1:], st.n
    k1 = N // n
    Lam_inv = np.stack([scipy.linalg.solve_triangular(L, np.eye(k1), lower=True, unit_diagonal=True) for L in Lams])
    M = np.einsum("mji,mjba->miba", Lam_inv, st.Z2.reshape(m, k1, n, a)).reshape(m, N, a)
    Y0_Dinv = np.einsum("maib,mij->majb", st.first_rows.reshape(m, n, k1, n), Lam_inv).reshape(m, n, N)
    Qm, Rm = np.linalg.qr(M)
    K = _t(np.linalg.solve(Rm, _t(Y0_Dinv @ Qm)))
    return G + K @ st.C, g - (K @ st.cg[:, :, None])[..., 0]


def alternative_maps(st, lam, rcond, times):
    """The alternative completion's ``(G, g)`` (None where a rank decision is left to the per-time path)."""
    n, Z2t = st.n, _t(st.Z2)
    a = Z2t.shape[1]
    lam = np.asarray(lam, dtype=float)
    G_c = -lam[:, None, None] * st.C - Z2t @ st.F[:, 1]
    W_c = lam[:, None] * st.cg + (Z2t @ st.Lg[:, 1, :, None])[..., 0]
    has_Jd = np.any(st.J[:, 1] != 0, axis=(1, 2))
    if np.any(has_Jd):
        # (Z2^T)' (F x - g) with (Z2^T)' = -Z2^T J' J^+; J' = 0 at a time adds exact zeros there
        Y = st.times_pinv(Z2t @ st.J[:, 1])
        G_c = G_c + Y @ st.F[:, 0]
        W_c = W_c - (Y @ st.Lg[:, 0, :, None])[..., 0]
    # T2: null space of C (lsc._structured.constraint_svd), then Z1: range of A T2 (index_one_solve)
    _, sc, Vct = np.linalg.svd(st.C)
    T2 = _t(Vct[:, a:])
    AT2 = st.A0 @ T2
    Z1, s1, _ = np.linalg.svd(AT2, full_matrices=False)
    ok = (_ranks(sc, st.C.shape[1:], None) == a) & (_ranks(s1, AT2.shape[1:], rcond) == AT2.shape[2])
    Z1t = _t(Z1)
    M = np.concatenate([Z1t @ st.A0, st.C], axis=1)
    G_num = np.concatenate([-(Z1t @ st.B0), G_c], axis=1)
    W_num = np.concatenate([(Z1t @ st.f0[:, :, None])[..., 0], W_c], axis=1)
    idx = np.nonzero(ok)[0]
    G, g = [None] * len(times), [None] * len(times)
    if idx.size:
        sol = np.linalg.solve(M[idx], np.concatenate([G_num, W_num[:, :, None]], axis=2)[idx])
        for j, x in zip(idx, sol):
            G[j], g[j] = x[:, :n], x[:, n]
    return G, g
