"""What a completion is at given times, as matrices: the public contract every consumer reads.

`Completion.maps` returns a `CompletionMaps`; `Completion.lam_affine` a `LamAffine`. Both hold the
completion in the DAE's own unknowns, equations and unit of time (the equilibration of
`lsc._problem.balance` undone), with a leading time axis ``m`` (one time is ``m = 1``).
"""

import numpy as np

__all__ = ["CompletionMaps", "LamAffine"]


def pinv_rows(C, svd=None):
    """``C^+`` of each matrix of a stack of full-row-rank ``C`` (m, a, n), from its SVD (`svd`, if computed
    already): shape (m, n, a)."""
    U, s, Vt = np.linalg.svd(C, full_matrices=False) if svd is None else svd
    a = s.shape[-1]
    return (np.swapaxes(Vt[..., :a, :], -1, -2) / s[..., None, :]) @ np.swapaxes(U, -1, -2)


class CompletionMaps:
    """A completion ``x' = G x + g(t)`` at ``m`` times, as matrices acting on the forcing's jet.

    With ``fjet = [f; f'; ...; f^(p)]`` (the DAE's forcing and its derivatives at a time, stacked by
    derivative order; ``p`` = `order`):

    - the completion is ``x' = G x + W fjet``,
    - the constraint residual is ``c = C x - Wc fjet`` (``c = Z2^T (F x - g)``, zero exactly on the
      solution manifold; `Completion.constraint_residual`).

    A sparse completion's maps (`lsc.SparseCompletion.maps`, a subclass) hold ``G`` and ``W`` as
    `scipy.sparse.linalg.LinearOperator` and ``C``, ``Wc`` as sparse matrices, without the leading time
    axis (constant coefficients); `forcing` and `C_pinv` work the same.

    Attributes
    ----------
    t : ndarray, shape (m,)
        The times.
    G : ndarray, shape (m, n, n)
    W : ndarray, shape (m, n, n (p + 1))
        The forcing map.
    C : ndarray, shape (m, a, n)
        The constraints' rows (``a`` = `Completion.n_constraints`).
    Wc : ndarray, shape (m, a, n (p + 1))
        The constraints' forcing map.
    order : int
        ``p``: the highest derivative of ``f`` the maps act on (``k`` plus one for the alternative
        completion).
    k : int
        Differentiations of the derivative array.
    lam : ndarray, shape (m,), or None
        The stabilization rate at each time (None for the standard completion).
    method : str

    Examples
    --------
    >>> import numpy as np, sympy
    >>> from lsc import LinearDAE, complete
    >>> t = sympy.Symbol("t")
    >>> c = complete(LinearDAE([[0, 1], [0, 0]], np.eye(2), [0, sympy.sin(t)]), "alternative", lam=2.0)
    >>> m = c.maps([0.5, 1.0])
    >>> m.G.shape, m.W.shape, m.order
    ((2, 2, 2), (2, 2, 8), 3)
    >>> x = np.array([-np.cos(0.5), np.sin(0.5)])
    >>> bool(np.allclose(m.G[0] @ x + m.forcing(c.dae.f_jet(0.5, m.order))[0], c.rhs(0.5, x)))
    True
    """

    def __init__(self, t, G, W, C, Wc, order, k, lam, method):
        self.t, self.G, self.W, self.C, self.Wc = t, G, W, C, Wc
        self.order, self.k, self.lam, self.method = order, k, lam, method
        self._C_pinv = None

    @property
    def C_pinv(self):
        """``C^+``, shape (m, n, a): the nearest consistent point to ``x`` is ``x - C^+ c``."""
        if self._C_pinv is None:
            self._C_pinv = pinv_rows(self.C)
        return self._C_pinv

    def forcing(self, fjet):
        """``g = W fjet`` at each time from the forcing jets `fjet`, shape (m, p + 1, n) or (p + 1, n)."""
        fjet = np.asarray(fjet, dtype=float).reshape(-1, self.W.shape[2])
        return (self.W @ fjet[..., None])[..., 0]

    def __repr__(self):
        return (f"CompletionMaps(method={self.method!r}, times={self.t.size}, n={self.G.shape[1]}, "
                f"constraints={self.C.shape[1]}, order={self.order})")


class LamAffine:
    """A completion's maps split as ``G = G0 + lam G1``, ``W = W0 + lam W1`` (`Completion.lam_affine`).

    Attributes
    ----------
    G0, G1 : ndarray, shape (m, n, n)
    W0, W1 : ndarray, shape (m, n, n (p + 1))
        As `CompletionMaps.W`: maps acting on the forcing jet ``[f; f'; ...; f^(p)]``.
    residual : float
        The largest misfit of ``G0 + lam G1`` (and of ``W``) against the maps computed at the rates
        checked, relative to the size of the terms at that rate.
    rates : tuple of float
        The rates checked: 0.3 and 7 in the DAE's own unit of time (the fit's are 1 and 2), and the
        completion's own.
    maps : CompletionMaps
        The completion at its own rate (the same factors).

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import complete, gallery
    >>> c = complete(gallery.prescribed_path().dae, "alternative", lam=3.0)
    >>> a = c.lam_affine()
    >>> G7 = complete(gallery.prescribed_path().dae, "alternative", lam=7.0).maps().G
    >>> bool(np.allclose(a.G0 + 7.0 * a.G1, G7, atol=1e-10 * np.abs(G7).max()))
    True
    """

    def __init__(self, G0, G1, W0, W1, residual, rates, maps):
        self.G0, self.G1, self.W0, self.W1 = G0, G1, W0, W1
        self.residual, self.rates, self.maps = residual, rates, maps

    def __repr__(self):
        return f"LamAffine(times={self.G0.shape[0]}, residual={self.residual:.1e})"
