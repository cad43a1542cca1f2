"""The implicit step's linear solve ``(I - c G) k = r`` of a sparse completion (`SparseCompletion.step_solver`)."""

import numpy as np
import scipy.sparse

from ._sparse_lu import factorize
from ._sparse_structure import cols, rows

__all__ = ["StepSolver", "step_solver"]


def step_solver(comp, c):
    """A `StepSolver` of ``(I - c G) k = r`` (``c > 0``), the last `_STEP_CACHE` kept by `c` in ``comp._step_cache``."""
    c = float(c)
    hit = comp._step_cache.get(c)
    if hit is not None:
        return hit
    solver = StepSolver(comp, c)
    comp._step_cache[c] = solver
    while len(comp._step_cache) > _STEP_CACHE:
        comp._step_cache.pop(next(iter(comp._step_cache)))
    return solver


_STEP_CACHE = 4


class StepSolver:
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
