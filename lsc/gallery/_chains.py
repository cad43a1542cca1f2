"""Constrained mass-spring-damper chains of any size (index 3): Stykel's ``msd_ind3`` and the triple chain.

Both are the first-order descriptor form of ``M p'' = K p + D p' - G^T mu + B2 u``,
``G p = 0`` used by M-M.E.S.S.::

    E = [[I, 0, 0],      A = [[0, I,  0  ],
         [0, M, 0],           [K, D, -G^T],
         [0, 0, 0]]           [G, 0,  0  ]]

(``K``, ``D`` negative semidefinite), written from the published
constructions (references in each function).
"""

import numpy as np
import scipy.sparse as sp

from ._sparse_base import Descriptor, Sinusoids, SparseProblem, default_phi, project_out


def _mechanical_descriptor(M, K, D, G, B2=None, C1=None):
    """The first-order descriptor system of a constrained second-order one (blocks as in the module docstring)."""
    g, na = M.shape[0], G.shape[0]
    Z = None
    E = sp.bmat([[sp.identity(g), Z, Z], [Z, M, Z], [Z, Z, sp.csr_matrix((na, na))]], format="csr")
    A = sp.bmat([[sp.csr_matrix((g, g)), sp.identity(g), Z], [K, D, -G.T], [G, Z, sp.csr_matrix((na, na))]],
                format="csr")
    n = 2 * g + na
    B = None if B2 is None else sp.vstack([sp.csr_matrix((g, B2.shape[1])), B2, sp.csr_matrix((na, B2.shape[1]))])
    C = None if C1 is None else sp.hstack([C1, sp.csr_matrix((C1.shape[0], n - g))])
    return Descriptor(E, A, B, C)


def _mechanical_projectors(M, K, D, G):
    """The spectral projectors ``Pr``, ``Pl`` of the finite eigenvalues in closed form (Stykel's formulas).

    With ``S = G M^-1 G^T``, ``Pi = I - M^-1 G^T S^-1 G`` (the M-orthogonal projector onto null(G)),
    as in M-M.E.S.S.'s msd_ind3 for a constraint matrix of any number of rows.
    """
    g, na = M.shape[0], G.shape[0]
    iM = sp.diags(1.0 / M.diagonal())
    S_inv = np.linalg.inv((G @ iM @ G.T).toarray())
    GG1 = sp.csr_matrix(iM @ G.T @ S_inv)  # M^-1 G^T S^-1
    GG2 = sp.csr_matrix(S_inv @ G.toarray()) if na else sp.csr_matrix((0, g))  # S^-1 G (few rows)
    Pi = sp.identity(g, format="csr") - GG1 @ G
    Zg, Za = sp.csr_matrix((g, g)), sp.csr_matrix((na, na))
    Pr = sp.bmat([[Pi, Zg, sp.csr_matrix((g, na))],
                  [-Pi @ iM @ D @ GG1 @ G, Pi, sp.csr_matrix((g, na))],
                  [GG2 @ iM @ (K @ Pi - D @ Pi @ iM @ D @ iM @ G.T @ GG2), GG2 @ iM @ D @ Pi, Za]], format="csr")
    Pl = sp.bmat([[Pi, Zg, -Pi @ iM @ D @ GG1],
                  [-M @ Pi @ iM @ D @ GG1 @ G, M @ Pi @ iM, -M @ Pi @ iM @ (K + D @ Pi @ iM @ D) @ GG1],
                  [sp.csr_matrix((na, g)), sp.csr_matrix((na, g)), Za]], format="csr")
    return {"Pr": Pr, "Pl": Pl}


def _chain_problem(name, M, K, D, G, B2, C1, t_span, seed, projectors):
    """A manufactured motion ``p*`` with ``G p* = 0`` (so the constraint rows are unforced), ``v* = p*'``."""
    g, na = M.shape[0], G.shape[0]
    desc = _mechanical_descriptor(M, K, D, G, B2, C1)
    s = np.linspace(0.0, 1.0, g)
    shapes = np.column_stack([np.sin(np.pi * s), np.cos(2 * np.pi * s), s * (1 - s) + 0.25])
    shapes = project_out(shapes, G)
    omega, theta = default_phi(3 + na, seed)
    m = shapes.shape[1]
    pos = Sinusoids(np.ones(m), omega[:m], theta[:m])
    vel = pos.derivative()
    mult = Sinusoids(np.full(na, 0.5), omega[m:], theta[m:])
    phi = Sinusoids(np.concatenate([pos.alpha, vel.alpha, mult.alpha]),
                    np.concatenate([pos.omega, vel.omega, mult.omega]),
                    np.concatenate([pos.theta, vel.theta, mult.theta]))
    n = 2 * g + na
    V = np.zeros((n, 2 * m + na))
    V[:g, :m] = shapes
    V[g:2 * g, m:2 * m] = shapes
    V[2 * g:, 2 * m:] = np.eye(na)
    proj = _mechanical_projectors(M, K, D, G) if projectors else None
    return SparseProblem(name, desc, V, phi, t_span, 3, (3,) * na, n - 3 * na, proj)


def msd_ind3(g, masses=None, k1=None, k2=None, d1=None, d2=None, t_span=(0.0, 10.0), seed=0, projectors=True):
    """Stykel's damped mass-spring chain with a holonomic constraint: index 3, ``n = 2 g + 1``.

    ``g`` masses ``m_i`` in a row, neighbours joined by springs ``k1`` and
    dampers ``d1``, each tied to the ground by a spring ``k2`` and a damper
    ``d2``; a rigid bar holds the first and the last mass together
    (``G = [1, 0, ..., 0, -1]``). Defaults as published (Mehrmann and
    Stykel 2005; M-M.E.S.S. ``msd_ind3``): masses 100, ``k1 = 2``,
    ``k2 = 2`` (4 at both ends), ``d1 = 5``, ``d2 = 5`` (10 at both ends).
    The descriptor keeps the published input (a force on the first mass)
    and outputs (positions of masses 1, 2 and ``g - 1``).

    The DAE's forcing is manufactured: the exact solution moves the masses
    along three smooth shapes with ``G p = 0``, velocities ``p'`` and a
    sinusoidal multiplier, so only the velocity rows are forced.

    Parameters
    ----------
    g : int
        Number of masses (at least 3).
    masses, k1, k2, d1, d2 : array_like, optional
        Lengths ``g``, ``g - 1``, ``g``, ``g - 1``, ``g`` (positive).
    t_span : pair of float
    seed : int
        Frequencies and phases of the manufactured motion.
    projectors : bool
        Build the spectral projectors ``Pr``, ``Pl`` (sparse, closed form).

    Returns
    -------
    SparseProblem
        ``index = 3``, ``n_finite = n - 3``, ``jordan_blocks = (3,)``.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import gallery
    >>> p = gallery.msd_ind3(100)
    >>> p.dae.n, p.index, p.n_finite
    (201, 3, 198)
    >>> Pr = p.projectors["Pr"]
    >>> x = np.random.default_rng(0).standard_normal(p.dae.n)
    >>> bool(np.allclose(Pr @ (Pr @ x), Pr @ x))
    True
    """
    g = _check_count("g", g, 3)
    masses = _positive("masses", 100.0 * np.ones(g) if masses is None else masses, g)
    k1 = _positive("k1", 2.0 * np.ones(g - 1) if k1 is None else k1, g - 1)
    k2 = _positive("k2", np.r_[4.0, 2.0 * np.ones(g - 2), 4.0] if k2 is None else k2, g)
    d1 = _positive("d1", 5.0 * np.ones(g - 1) if d1 is None else d1, g - 1)
    d2 = _positive("d2", np.r_[10.0, 5.0 * np.ones(g - 2), 10.0] if d2 is None else d2, g)
    M = sp.diags(masses, format="csr")
    K = _chain_matrix(k1, k2)
    D = _chain_matrix(d1, d2)
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, g - 1])), shape=(1, g))
    B2 = sp.csr_matrix(([1.0], ([0], [0])), shape=(g, 1))
    C1 = sp.csr_matrix((np.ones(3), ([0, 1, 2], [0, 1, g - 2])), shape=(3, g))
    return _chain_problem("msd_ind3", M, K, D, G, B2, C1, t_span, seed, projectors)


def _chain_matrix(offdiag, ground):
    """``tridiag(c, -(c_left + c_right + ground), c)``: springs (or dampers) along a chain and to the ground."""
    c = np.asarray(offdiag, dtype=float)
    diag = -(np.r_[0.0, c] + np.asarray(ground, dtype=float) + np.r_[c, 0.0])
    return sp.diags([c, diag, c], [-1, 0, 1], format="csr")


TRIPLE_CHAIN_CONSTRAINTS = ("truhar_veselic", "tv", "tv2", "none")


def triple_chain(n1, constraints="truhar_veselic", alpha=0.01, beta=None, v=5.0, t_span=(0.0, 10.0), seed=0,
                 projectors=True):
    """The triple chain oscillator of Truhar and Veselic, with holonomic constraints: index 3.

    Three chains of ``n1`` masses (1, 2, 3; springs 10, 20, 1) joined to one
    mass 10 (spring 50 to the ground); Rayleigh damping
    ``alpha M + beta K`` plus three dampers of viscosity ``v`` (Truhar and
    Veselic 2009, M-M.E.S.S. ``triplechain_MSD``). The constraints are those
    of Saak and Voigt's variants in M-M.E.S.S. (``BT_DAE3_SO``):

    - ``'truhar_veselic'`` (``n1`` even): six rows, the ends of each half of
      each chain move together (``p_1 = p_(n1/2)``, ``p_(n1/2+1) = p_n1``, ...);
    - ``'tv'`` (``n1`` odd): three rows, the mean of first, middle and last
      mass of each chain is held at zero;
    - ``'tv2'`` (``n1`` odd): three rows, ``-p_first + 2 p_middle - p_last = 0``;
    - ``'none'``: no constraint (an ODE in descriptor form, index 0).

    ``n = 2 (3 n1 + 1) + rows``. The forcing is manufactured as in
    `msd_ind3`; the descriptor's input pushes every mass (the ``B`` of the
    'truhar_veselic' variant), the output sums the positions.

    Examples
    --------
    >>> from lsc import gallery
    >>> p = gallery.triple_chain(20)
    >>> p.dae.n, p.index, p.jordan_blocks
    (128, 3, (3, 3, 3, 3, 3, 3))
    """
    n1 = _check_count("n1", n1, 4)
    if constraints not in TRIPLE_CHAIN_CONSTRAINTS:
        raise ValueError(f"`constraints` must be one of {TRIPLE_CHAIN_CONSTRAINTS}; found {constraints!r}.")
    beta = alpha if beta is None else beta
    nv = 3 * n1 + 1
    masses = np.r_[np.full(n1, 1.0), np.full(n1, 2.0), np.full(n1, 3.0), 10.0]
    M = sp.diags(masses, format="csr")
    # stiffness (M-M.E.S.S. triplechain_MSD, positive semidefinite; the descriptor uses -K)
    K1 = sp.diags([-np.ones(n1 - 1), 2 * np.ones(n1), -np.ones(n1 - 1)], [-1, 0, 1])
    ks = (10.0, 20.0, 1.0)
    ends = [(i + 1) * n1 - 1 for i in range(3)]  # the last mass of each chain, tied to the joint mass
    ties = sp.csr_matrix((np.r_[[-k for k in ks], [-k for k in ks], sum(ks) + 50.0],
                          (np.r_[ends, [nv - 1] * 3, nv - 1], np.r_[[nv - 1] * 3, ends, nv - 1])), shape=(nv, nv))
    K = (sp.block_diag([k * K1 for k in ks] + [sp.csr_matrix((1, 1))]) + ties).tocsr()
    dampers = np.zeros(nv)
    dampers[[0, n1 - 1, 2 * n1]] = v
    Dm = (alpha * M + beta * K + sp.diags(dampers)).tocsr()
    G = _triple_constraints(constraints, n1, nv)
    B2 = sp.csr_matrix(np.ones((nv, 1)))
    C1 = sp.csr_matrix(np.ones((1, nv)))
    if G.shape[0] == 0:
        desc = _mechanical_descriptor(M, -K, -Dm, G, B2, C1)
        return _unconstrained_chain(desc, M, t_span, seed)
    return _chain_problem(f"triple_chain_{constraints}", M, -K, -Dm, G, B2, C1, t_span, seed, projectors)


def _triple_constraints(kind, n1, nv):
    if kind == "none":
        return sp.csr_matrix((0, nv))
    if kind == "truhar_veselic":
        if n1 % 2:
            raise ValueError(f"`n1` must be even for constraints='truhar_veselic'; found {n1}.")
        h = n1 // 2
        pairs = [(c * n1, c * n1 + h - 1) for c in range(3)] + [(c * n1 + h, c * n1 + n1 - 1) for c in range(3)]
        pairs = [pairs[0], pairs[3], pairs[1], pairs[4], pairs[2], pairs[5]]
        rows = np.repeat(np.arange(6), 2)
        cols = np.array(pairs).ravel()
        vals = np.tile([1.0, -1.0], 6)
        return sp.csr_matrix((vals, (rows, cols)), shape=(6, nv))
    if n1 % 2 == 0:
        raise ValueError(f"`n1` must be odd for constraints={kind!r}; found {n1}.")
    mid = (n1 + 1) // 2 - 1
    w = [1 / 3, 1 / 3, 1 / 3] if kind == "tv" else [-1.0, 2.0, -1.0]
    rows, cols, vals = [], [], []
    for c in range(3):
        for j, wj in zip((c * n1, c * n1 + mid, c * n1 + n1 - 1), w):
            rows.append(c)
            cols.append(j)
            vals.append(wj)
    return sp.csr_matrix((vals, (rows, cols)), shape=(3, nv))


def _unconstrained_chain(desc, M, t_span, seed):
    g = M.shape[0]
    s = np.linspace(0.0, 1.0, g)
    shapes = np.column_stack([np.sin(np.pi * s), np.cos(2 * np.pi * s)])
    omega, theta = default_phi(2, seed)
    pos = Sinusoids(np.ones(2), omega, theta)
    vel = pos.derivative()
    phi = Sinusoids(np.r_[pos.alpha, vel.alpha], np.r_[pos.omega, vel.omega], np.r_[pos.theta, vel.theta])
    V = np.zeros((2 * g, 4))
    V[:g, :2] = shapes
    V[g:, 2:] = shapes
    return SparseProblem("triple_chain_none", desc, V, phi, t_span, 0, (), 2 * g)


def _check_count(name, value, minimum):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"`{name}` must be an int >= {minimum}; found {value!r}.")
    return int(value)


def _positive(name, values, size):
    values = np.asarray(values, dtype=float)
    if values.shape != (size,):
        raise ValueError(f"`{name}` must have shape ({size},); found {values.shape}.")
    if not np.all(np.isfinite(values) & (values > 0)):
        raise ValueError(f"`{name}` must be positive and finite.")
    return values
