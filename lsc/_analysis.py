"""Spectral analysis of a constant-coefficient completion.

The solution manifold of the homogeneous DAE, ``S = {x : C x = 0}`` with
``C = Z2^T F``, is invariant under every completion's ``G``. So ``G`` splits:

- on ``S`` it reproduces the DAE's own dynamics: the finite eigenvalues of
  the pencil (the *kept* eigenvalues, ``eig(T2^T G T2)``);
- on the quotient ``R^n / S`` it acts as ``H = C G C^+`` (``C G = H C``):
  the *added* dynamics, which the constraint residual ``c = C x - ...``
  follows exactly (``c' = H c``).

The added eigenvalues form one cluster (0 or ``-lam``), usually defective.
``eigvals`` on a defective matrix scatters by ``eps^(1/size)`` (ERRATA item
5), so the cluster's value is taken from the trace (well conditioned) and its
Jordan structure from the ranks of the powers of ``H - mu I``.
"""

import numpy as np
import scipy.linalg

from ._completion import Completion

__all__ = ["eigenanalysis", "Eigenanalysis"]


class Eigenanalysis:
    """Result of `eigenanalysis`.

    Attributes
    ----------
    pencil : ndarray, shape (d,)
        Finite eigenvalues ``mu`` of the pencil (``det(mu A + B) = 0``),
        sorted; ``d = n - a`` is the dimension of the solution manifold.
    kept : ndarray, shape (d,)
        Eigenvalues of ``G`` on the manifold (sorted like `pencil`); equal to
        `pencil` for every completion.
    G : ndarray, shape (n,)
        ``numpy.linalg.eigvals(G)``, for information only: the defective
        added eigenvalues are scattered in it.
    added_value : float
        The eigenvalue of the added dynamics (``trace(H) / a``).
    added : ndarray, shape (a,)
        `added_value` repeated ``a`` times.
    jordan_blocks : tuple of int
        Sizes of the Jordan blocks of the added eigenvalue, largest first,
        decided by the staircase algorithm (`jordan_structure`); None when
        no structure is exact within the backward error `rtol`.
    nilpotency_residual : float
        ``||(H - mu I)^a|| / ||H - mu I||^a``, or ``||H - mu I|| / ||H||`` when
        ``H = mu I`` to rounding. For information: for very non-normal ``H``
        the powers sink into rounding noise, which is why the structure is
        decided without them.
    H : ndarray, shape (a, a)
        The added dynamics in constraint coordinates.
    decision_gap : float
        How clearly `jordan_blocks` was decided: the smallest ratio between
        a singular value counted as nonzero and one counted as zero (see
        `jordan_structure`). Above ~1e2 the structure is unambiguous.
    """

    def __init__(self, pencil, kept, G, added_value, a, jordan_blocks, nilpotency_residual, H, decision_gap):
        self.pencil = pencil
        self.kept = kept
        self.G = G
        self.added_value = added_value
        self.added = np.full(a, added_value)
        self.jordan_blocks = jordan_blocks
        self.nilpotency_residual = nilpotency_residual
        self.H = H
        self.decision_gap = decision_gap

    def __repr__(self):
        return (
            f"Eigenanalysis(pencil={np.array2string(self.pencil, precision=4)}, "
            f"added_value={self.added_value:.6g}, jordan_blocks={self.jordan_blocks})"
        )


# Staircase singular values above this (relative) are never taken as zero.
_ZERO_CAP = 1e-6


def _sort(ev):
    return ev[np.lexsort((ev.imag, ev.real))]


def pencil_finite_eigenvalues(A, B, d):
    """The `d` finite eigenvalues ``mu`` with ``det(mu A + B) = 0``.

    QZ returns ``(alpha, beta)`` pairs; infinite eigenvalues of index ``nu``
    come out with ``|beta| ~ eps^(1/nu)`` instead of 0, so the `d` pairs with
    the largest ``|beta| / |(alpha, beta)|`` are the finite ones (``d`` is
    known from the derivative array).
    """
    if d == 0:
        return np.zeros(0)
    w = scipy.linalg.eigvals(-B, A, homogeneous_eigvals=True)
    alpha, beta = w[0], w[1]
    weight = np.abs(beta) / np.hypot(np.abs(alpha), np.abs(beta))
    idx = np.argsort(-weight)[:d]
    ev = alpha[idx] / beta[idx]
    if np.all(np.abs(ev.imag) <= 1e-12 * np.maximum(1.0, np.abs(ev))):
        ev = ev.real
    return _sort(ev)


def _match(reference, values):
    """Reorder `values` to sit next to the closest entries of `reference`."""
    values = list(values)
    out = []
    for r in reference:
        j = int(np.argmin([abs(v - r) for v in values]))
        out.append(values.pop(j))
    return np.array(out)


def jordan_structure(M, rtol):
    """Jordan block sizes of a nilpotent `M` by the staircase algorithm.

    The Weyr characteristic ``w_j`` (the number of blocks of size ``>= j``)
    is found by deflating null spaces with orthogonal similarities
    (Kublanovskaya; Van Dooren): with ``V`` an orthonormal basis whose first
    ``w_1`` vectors span ``null(M)``, ``V^T M V = [[0, *], [0, M2]]`` and
    ``w_2 = dim null(M2)``, and so on. No powers of `M` are formed: the
    added dynamics of the stabilized LSC are very non-normal (entries grow
    like ``lam^(size-1)``), so ``||M^j||`` can fall far below ``||M||^j`` and
    into the rounding noise, while every staircase decision is taken at the
    scale of ``||M||``.

    Each null-space dimension is decided at the largest gap in the
    singular values (relative to ``||M||``) among those below `rtol`: the
    accuracy of a computed completion varies with its conditioning, so a
    fixed threshold would be too strict for some and too loose for others.

    Returns
    -------
    sizes : tuple of int or None
        Largest first; None when some block has no singular value below
        `rtol` (`M` is not nilpotent at that accuracy) or the deflation was
        inconsistent.
    gap : float
        The smallest ratio, over all steps, between the smallest singular
        value kept and the largest one counted as zero: how clear the
        decisions were.
    backward_error : float
        Relative size of the perturbation the deflation discarded: `sizes`
        is exactly the structure of a matrix within ``backward_error *
        ||M||`` of `M`.
    """
    scale = np.linalg.norm(M, 2)
    weyr = []
    gap = np.inf
    discarded = 0.0
    R = M
    while R.shape[0] > 0:
        _, s, Vt = scipy.linalg.svd(R)
        s = s / scale
        above = np.concatenate([[1.0], s[:-1]])
        ratios = above / np.maximum(s, np.finfo(float).tiny)
        # Candidates for the first zero singular value: small enough. M is
        # nilpotent, so every trailing block must have at least one.
        candidates = [i for i in range(s.size) if s[i] <= rtol]
        if not candidates:
            return None, 0.0, np.inf
        rank = max(candidates, key=lambda i: ratios[i])
        gap = min(gap, ratios[rank])
        discarded += float(np.sqrt(np.sum(s[rank:] ** 2)))
        nullity = s.size - rank
        weyr.append(nullity)
        # Basis: null space first, then the rest; keep the trailing block.
        V = np.vstack([Vt[rank:], Vt[:rank]]).T
        R = (V.T @ R @ V)[nullity:, nullity:]
    if any(later > earlier for earlier, later in zip(weyr, weyr[1:])):
        # A Weyr characteristic never increases: the deflation was swamped by rounding.
        return None, 0.0, discarded
    sizes = []
    for j in range(len(weyr), 0, -1):
        exactly = weyr[j - 1] - (weyr[j] if j < len(weyr) else 0)
        sizes += [j] * exactly
    return tuple(sizes), gap, discarded


def eigenanalysis(completion, rtol=1e-10):
    """Kept and added eigenvalues of a constant-coefficient completion.

    Parameters
    ----------
    completion : Completion
        Built by `complete` from a DAE with constant coefficients.
    rtol : float, optional
        Largest relative backward error accepted for `jordan_blocks`: the
        structure reported is exact for a matrix within ``rtol * ||M||`` of
        the computed ``M = H - mu I``, or None is reported. The stabilized
        LSC's added part is non-normal like ``lam^(size-1)``, so for long
        chains with large ``lam`` its structure is not numerically
        decidable (seen: index 4 with lam = 45 gives backward error 1e-6).
        ``M`` counts as zero (no Jordan blocks) below ``1e-9`` times the
        scale of the completion.

    Returns
    -------
    Eigenanalysis

    Examples
    --------
    A nilpotent chain of length 3: the standard LSC adds eigenvalue 0 in one
    Jordan block of size 3, the alternative completion adds ``-lam`` three
    times in blocks of size 1.

    >>> import numpy as np
    >>> from lsc import LinearDAE, complete, eigenanalysis
    >>> dae = LinearDAE(np.eye(3, k=1), np.eye(3))
    >>> eigenanalysis(complete(dae, "standard")).jordan_blocks
    (3,)
    >>> e = eigenanalysis(complete(dae, "alternative", lam=5.0))
    >>> float(e.added_value), e.jordan_blocks
    (-5.0, (1, 1, 1))
    """
    if not isinstance(completion, Completion):
        raise TypeError(f"`completion` must be an lsc Completion; found {type(completion).__name__}.")
    if not completion.dae.is_constant:
        raise ValueError("`completion` must have constant coefficients: eigenvalues do not decide stability otherwise.")
    std = completion._std
    G, _ = completion.matrices(0.0)
    C, T2 = std.C[0], std.T2[0]
    a = C.shape[0]
    A, B = completion.dae.A(0.0), completion.dae.B(0.0)
    pencil = pencil_finite_eigenvalues(A, B, T2.shape[1])
    kept = _match(pencil, np.linalg.eigvals(T2.T @ G @ T2)) if T2.shape[1] else np.zeros(0)
    if a == 0:
        return Eigenanalysis(pencil, kept, np.linalg.eigvals(G), 0.0, 0, (), 0.0, np.zeros((0, 0)), np.inf)
    H = C @ G @ std.C_pinv[0]
    mu = float(np.trace(H).real) / a
    M = H - mu * np.eye(a)
    norm_M = np.linalg.norm(M, 2)
    # The scale H is computed at: G is built from J^+ F, so entries that
    # cancel to zero are left at rounding relative to ||F|| / sigma_min(J)
    # (the standard LSC of an index-1 DAE has H = 0, G may be 0 too).
    scale = max(np.linalg.norm(H, 2), np.linalg.norm(G, 2), abs(mu), std.rounding_scale / completion._scaling.sigma)
    if norm_M <= 1e-9 * scale:
        # H = mu I to rounding: a diagonal added part (no Jordan blocks).
        residual = norm_M / scale if scale else 0.0
        blocks, gap = (1,) * a, (scale / norm_M if norm_M else np.inf)
    else:
        residual = np.linalg.norm(np.linalg.matrix_power(M, a), 2) / norm_M**a
        blocks, gap, backward_error = jordan_structure(M, _ZERO_CAP)
        if backward_error > rtol:
            # Not exact for any matrix close to the computed one: an
            # undecided structure beats a wrong one.
            blocks = None
    return Eigenanalysis(pencil, kept, np.linalg.eigvals(G), mu, a, blocks, residual, H, gap)
