"""The three completions' maps ``x' = G x + W``, each written once: for any backend and any number of times.

Each function takes the factors of the standard derivative array at ``m`` times (`lsc._factors.Factors`)
and the stabilization rate's jets there, and returns ``(G, W)`` of shapes (m, n, n) and (m, n, w): ``W`` is
the forcing map on the jet ``[f; f'; ...]`` or the forcing's value (``w = 1``), as the factors hold it. A
time the factors leave undecided (several times at once, `Factors.strict` False) holds NaN. Factors at one
time with the jets of several rates (``lam`` of shape (r, k + 1)) give the maps at each rate (leading axis r).
"""

import numpy as np
import scipy.linalg

from ._derivative_array import stabilization_jets
from ._factors import swap

__all__ = ["alternative_maps", "stabilized_maps", "standard_maps"]


def standard_maps(fac):
    """The least squares completion (thesis ch. 2): ``x' = V^T J^+ (-F x + g)``."""
    P = fac.first_rows
    return -fac.times_F(P, 0), fac.times_L(P, 0)


def stabilized_maps(fac, lam):
    """The least squares completion of the array with ``D = d/dt + lam``: the standard one plus ``K c``.

    `lam`: the rate's jets to order k at each time, shape (m, k + 1). The stabilized array is
    ``(Lam kron I)`` times the standard one, row for row (`stabilization_jets`), so by thesis Theorem 8
    ``x' = [standard LSC] + K c`` with ``K = Y0 D^-1 (M^+)^T``, ``M = D^-T Z2``, ``Y0 = V^T J^+`` and ``c``
    the constraint residual (see `lsc.StabilizedCompletion`): no SVD of ``D J``, whose rows scale like
    ``lam^i``.
    """
    G, W = standard_maps(fac)
    n, k = fac.n, fac.k
    Z2 = fac.Z2
    m, N, a = Z2.shape
    eye = np.eye(k + 1)
    Lam_inv = np.stack([scipy.linalg.solve_triangular(stabilization_jets(k, 0, lj)[0], eye, lower=True,
                                                      unit_diagonal=True) for lj in lam])
    r = max(m, len(lam))  # the times, or one time at several rates
    # M = (Lam^-T kron I) Z2 and Y0 (Lam^-1 kron I), block by block.
    M = np.einsum("...ji,...jba->...iba", Lam_inv, Z2.reshape(m, k + 1, n, a)).reshape(r, N, a)
    Y0_Dinv = np.einsum("...aib,...ij->...ajb", fac.first_rows.reshape(m, n, k + 1, n), Lam_inv).reshape(r, n, N)
    Qm, Rm = np.linalg.qr(M)
    K = swap(np.linalg.solve(Rm, swap(Y0_Dinv @ Qm)))
    return G + K @ fac.C, W - K @ fac.cg


def alternative_maps(fac, lam, rcond):
    """The index-one form with the constraints differentiated as ``c' = -lam c`` (thesis ch. 4, 6).

    ``c' = (Z2^T)' (F x - g) + Z2^T (F' x + F x' - g') = -lam c`` with ``(Z2^T)' = -Z2^T J' J^+`` (ERRATA
    item 4: never a difference of computed bases), so ``(Z2^T)' (F x - g) = -Y (F x - g)``, ``Y = Z2^T J'
    J^+`` (zero for constant coefficients). `lam`: the rate's jets at each time (its value is used).
    """
    lam0 = np.asarray(lam, dtype=float)[:, :1, None]
    C, cg = fac.constraint_rows(0)
    C1, L1 = fac.constraint_rows(1)
    G_c = -lam0 * C - C1
    W_c = lam0 * cg + L1
    drift = fac.basis_drift()
    if drift is not None:
        G_c, W_c = G_c + drift[0], W_c - drift[1]
    G, W, _ = fac.index_one_solve(G_c, W_c, rcond)
    return G, W
